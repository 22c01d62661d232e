"""Scenario files: TOML -> frozen, strictly validated objects."""
from __future__ import annotations

from fdi_sim.scenario.loader import Scenario, from_dict, load, loads
from fdi_sim.scenario.schema import ScenarioModel

__all__ = ["Scenario", "ScenarioModel", "from_dict", "load", "loads"]

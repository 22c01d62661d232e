"""Session fixtures of the detector tests: the default model schedules of both aircraft.

Built once per session with the linearizer (real JSBSim trims and Jacobians) without the doublet
validation and without the FGLinearization cross-check, which a design test does not need
(F-16 20 points and DHC-6 30 points in a few seconds together).
"""
from __future__ import annotations

import pytest

from fdi_sim.linear.grid import default_grid_path, load_grid
from fdi_sim.linear.linearize import linearize_grid
from fdi_sim.linear.schedule import ModelSchedule

#: the aircraft with a default grid
AIRCRAFT: tuple[str, ...] = ("f16", "DHC6")


@pytest.fixture(scope="session")
def default_schedules() -> dict[str, ModelSchedule]:
    """``aircraft -> ModelSchedule`` of ``aircraft/<name>/grid.toml``, unvalidated."""
    return {ac: linearize_grid(load_grid(default_grid_path(ac), ac), validate=False, check_fglin=False)
            for ac in AIRCRAFT}

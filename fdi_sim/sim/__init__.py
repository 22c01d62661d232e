"""The simulation loop: wires aircraft, sensors, pilot (and later faults and the FDI bank) to the log."""
from __future__ import annotations

from fdi_sim.sim.run import run, RunResult, RunSummary

__all__ = ["RunResult", "RunSummary", "run"]

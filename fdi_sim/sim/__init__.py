"""The simulation loop: flies one scenario (aircraft, sensors, pilot, faults) with the FDI bank it is
given (``run(sc, bank_builder=...)``; ``fdi_sim.training.fly`` builds the scenario's bank)."""
from __future__ import annotations

from fdi_sim.sim.run import RunResult, RunSummary, run

__all__ = ["RunResult", "RunSummary", "run"]

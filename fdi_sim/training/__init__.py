"""Above the loop: fault-free training flights, calibrations, the cache, and designing a scenario's bank.

- :func:`fly`: fly a scenario with its bank (``fdi-sim run``, a study's runs);
- :mod:`fdi_sim.training.build`: :func:`~fdi_sim.training.build.build_bank` and each member's design;
- :mod:`fdi_sim.training.thresholds`: members' thresholds from training flights or a study's file;
- :mod:`fdi_sim.training.flights`: the fault-free training flights;
- :mod:`fdi_sim.training.gust`: kalman-gust-v1's calibration; :mod:`fdi_sim.training.schedule`:
  its gain schedule;
- :mod:`fdi_sim.training.cache`: the calibration cache on disk.
"""
from __future__ import annotations

from fdi_sim.training.build import build_bank, fly

__all__ = ["build_bank", "fly"]

"""Registered detectors: the parity, observer and kinematic families keep their own catalogue
files; the engine-gauge check registers itself."""
from __future__ import annotations

import importlib

for _mod in ("fdi_sim.detectors.catalogue_parity", "fdi_sim.detectors.catalogue_observers", "fdi_sim.detectors.catalogue_kinematic",
             "fdi_sim.detectors.engine_gauges"):
    try:
        importlib.import_module(_mod)
    except ModuleNotFoundError as exc:  # a family not landed yet registers nothing
        if exc.name != _mod:
            raise

"""Registered detectors: the parity family and the observer family keep their own catalogue files."""
from __future__ import annotations

import importlib

for _mod in ("fdi_sim.detectors.catalogue_parity", "fdi_sim.detectors.catalogue_observers", "fdi_sim.detectors.catalogue_kinematic"):
    try:
        importlib.import_module(_mod)
    except ModuleNotFoundError as exc:  # a family not landed yet registers nothing
        if exc.name != _mod:
            raise

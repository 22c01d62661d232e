"""Tests of fdi_sim.review (a package, so its conftest is not the module `conftest` that tests/faults imports from)."""

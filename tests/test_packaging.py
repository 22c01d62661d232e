"""The per-aircraft data ships with the package: fdi_sim/_aircraft is the repository's aircraft/
folder, and the package-data glob of pyproject.toml covers every data file in it."""
from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

import fdi_sim
from fdi_sim.data import AIRCRAFT_DATA

ROOT = Path(__file__).resolve().parents[1]


def test_package_data_link_and_glob_cover_aircraft_data() -> None:
    assert AIRCRAFT_DATA.resolve() == (ROOT / "aircraft").resolve()
    assert AIRCRAFT_DATA.parent == Path(fdi_sim.__file__).resolve().parent
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["fdi_sim"]
    files = [p.relative_to(ROOT / "aircraft").as_posix() for p in (ROOT / "aircraft").rglob("*") if p.is_file()]
    assert files
    missing = [f for f in files if not any(fnmatch.fnmatch(f"_aircraft/{f}", g) for g in globs)]
    assert not missing, f"not packaged: {missing}"

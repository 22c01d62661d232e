"""Where fdi-sim's per-aircraft data lives (autopilot gains, sensor suites, grids, icing tables).

The data is kept at the top of the repository in ``aircraft/<name>/``; ``fdi_sim/_aircraft`` is a
link to it, and wheels carry the files there (``package-data``), so the same path works from a
source checkout, an editable install and a regular ``pip install``.
"""
from __future__ import annotations

from pathlib import Path

#: folder with one sub-folder of TOML files per aircraft (``f16``, ``DHC6``)
AIRCRAFT_DATA: Path = Path(__file__).resolve().parent / "_aircraft"


def aircraft_base(aircraft: str) -> str:
    """The aircraft whose data and signal tables ``aircraft`` uses (``"DHC6..."`` variants share the DHC-6's)."""
    return "DHC6" if aircraft.startswith("DHC6") else aircraft


def aircraft_file(aircraft: str, name: str) -> Path:
    """``aircraft/<aircraft>/<name>`` (``"DHC6..."`` variants share the DHC-6 folder)."""
    return AIRCRAFT_DATA / aircraft_base(aircraft) / name


#: the package's folder (its data: ``_aircraft``, ``_scenarios``, ``_bench``)
PACKAGE: Path = Path(__file__).resolve().parent


def shown_path(path: Path | str) -> str:
    """``path`` as logs and notes show it: the package's own files as ``fdi_sim/<path in the package>``
    (``fdi_sim/_aircraft/<aircraft>/<file>``, ``fdi_sim/_bench/fdi-bench-v1.toml``), any other file as
    given (a user's own). A log must not depend on where the package was checked out or installed: the
    same seed gives the same log on every machine."""
    p = Path(path)
    for root, shown in ((AIRCRAFT_DATA, "fdi_sim/_aircraft"), (PACKAGE / "_scenarios", "fdi_sim/_scenarios"),
                        (PACKAGE, "fdi_sim")):  # the linked data folders first: they resolve outside the package
        try:
            return (Path(shown) / p.relative_to(root)).as_posix()
        except ValueError:
            continue
    return str(p)

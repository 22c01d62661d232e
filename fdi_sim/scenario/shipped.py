"""The scenarios and studies shipped with fdi-sim, found the same way in a checkout and a wheel.

The files are kept at the top of the repository in ``scenarios/`` (studies in
``scenarios/studies/``); ``fdi_sim/_scenarios`` is a link to it and wheels carry the files there
(``package-data``), as ``fdi_sim/_aircraft`` does for the aircraft data (:mod:`fdi_sim.data`).
So :func:`shipped_dir` never depends on where the command runs or on a repository checkout.

Listing reads each file with :mod:`tomllib` only (no validation, no heavy imports): a file that
does not parse is still listed, with the reason as its description.
"""
from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from fdi_sim.errors import ScenarioError

#: the folder prefix the README and the docs write shipped files with (``scenarios/x.toml``)
REPO_PREFIX = "scenarios"


def shipped_dir() -> Path:
    """The folder of shipped scenario files; its ``studies/`` sub-folder holds the study files."""
    return Path(__file__).resolve().parents[1] / "_scenarios"


@dataclass(frozen=True)
class ShippedFile:
    """One shipped scenario or study file.

    Attributes
    ----------
    name : str
        The file's stem, which :func:`resolve` accepts in place of the path.
    kind : {"scenario", "study"}
    aircraft : str
        The scenario's ``aircraft``; for a study, its base scenario's (``"?"`` if unknown).
    description : str
        The first line of the file's ``description`` (or why the file cannot be read).
    path : pathlib.Path
        The file, inside :func:`shipped_dir`.
    """

    name: str
    kind: Literal["scenario", "study"]
    aircraft: str
    description: str
    path: Path


def _read(path: Path) -> tuple[dict[str, object], str]:
    """The file's table and ``""``, or ``{}`` and why it cannot be read."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8")), ""
    except (ValueError, OSError) as exc:  # TOMLDecodeError and UnicodeDecodeError are ValueErrors
        return {}, f"(unreadable: {exc})"


def _first_line(data: dict[str, object]) -> str:
    return next(iter(str(data.get("description", "")).strip().splitlines()), "")


def list_scenarios() -> list[ShippedFile]:
    """The shipped scenarios (``scenarios/*.toml``), by name."""
    out = []
    for p in sorted(shipped_dir().glob("*.toml")):
        data, bad = _read(p)
        out.append(ShippedFile(p.stem, "scenario", str(data.get("aircraft", "?")), bad or _first_line(data), p))
    return out


def list_studies() -> list[ShippedFile]:
    """The shipped studies (any ``scenarios/studies/*.toml``), by name; aircraft from the base scenario."""
    out = []
    for p in sorted((shipped_dir() / "studies").glob("*.toml")):
        data, bad = _read(p)
        aircraft = "?"
        ref = data.get("scenario")
        if isinstance(ref, str) and ref:
            base = p.parent / ref if ref.endswith(".toml") else shipped_dir() / f"{ref}.toml"
            aircraft = str(_read(base)[0].get("aircraft", "?"))
        out.append(ShippedFile(p.stem, "study", aircraft, bad or _first_line(data), p))
    return out


def resolve(name_or_path: str | Path) -> Path:
    """A scenario or study file from a path, a shipped name, or a README-style ``scenarios/...`` path.

    In order: a path that exists is returned as given; a bare name (``f16_pitch_gyro_bias``,
    ``.toml`` optional) is a shipped scenario, else a shipped study; ``scenarios/<rest>`` is
    ``<rest>`` inside :func:`shipped_dir`, so the README's commands work outside a checkout.

    Raises
    ------
    ScenarioError
        Neither a file nor a shipped name; the fix gives the closest shipped name.
    """
    p = Path(name_or_path)
    if p.exists():
        return p
    ref = str(name_or_path)
    if "/" not in ref and "\\" not in ref:
        stem = ref.removesuffix(".toml")
        for f in (*list_scenarios(), *list_studies()):  # a scenario wins over a study of the same name
            if f.name == stem:
                return f.path
    elif p.parts[0] == REPO_PREFIX and len(p.parts) > 1:
        q = shipped_dir().joinpath(*p.parts[1:])
        if q.is_file():
            return q
    names = [f.name for f in (*list_scenarios(), *list_studies())]
    close = difflib.get_close_matches(p.stem, names, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    raise ScenarioError(ref, "", "no such file, nor a shipped scenario or study of that name",
                        f"{hint}`fdi-sim scenarios` lists the shipped ones")

"""The shipped scenarios and studies reach a wheel install: a wheel is built from a copy of the
checkout and installed for real, and `fdi-sim scenarios`, run from outside the checkout against the
installed package, lists every shipped file by a path that exists and loads."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from fdi_sim.errors import ScenarioError
from fdi_sim.scenario.shipped import list_scenarios, list_studies, resolve, shipped_dir

ROOT = Path(__file__).resolve().parents[1]
#: a study added to the copy before the build, so the studies/ glob is checked before any is shipped
EXTRA_STUDY = """kind = "study"
name = "zz_wheel_check"
description = "added by tests/test_shipped.py to the copy that is built"
scenario = "dhc6_cruise_doublets"
runs = 2
duration_s = 10.0
"""
#: loads each listed file with the installed package; prints where fdi_sim came from and what loaded
LOAD = """
import json, sys
import fdi_sim
from fdi_sim.scenario import load
from fdi_sim.scenario.shipped import resolve
from fdi_sim.study.spec import load_study
rows = json.loads(sys.argv[1])
for kind, path in rows:
    (load_study if kind == "study" else load)(path)
print(json.dumps({"package": fdi_sim.__file__, "loaded": len(rows),
                  "resolved": str(resolve("f16_pitch_gyro_bias"))}))
"""


def _setuptools_is_new_enough() -> bool:
    """The venv's setuptools can build this pyproject.toml (PEP 639 ``license = "MIT"`` needs 77)."""
    try:
        return int(version("setuptools").split(".")[0]) >= 77
    except Exception:  # noqa: BLE001 - not installed, or an odd version string: build isolated
        return False


def _copy_checkout(dst: Path) -> None:
    """What the wheel is built from (a copy, so the build writes no build/ or egg-info in the checkout)."""
    dst.mkdir()
    for f in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / f, dst / f)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for d in ("fdi_sim", "aircraft", "scenarios"):
        shutil.copytree(ROOT / d, dst / d, symlinks=True, ignore=ignore)  # keeps fdi_sim/_scenarios a link
    (dst / "scenarios" / "studies").mkdir(exist_ok=True)
    (dst / "scenarios" / "studies" / "zz_wheel_check.toml").write_text(EXTRA_STUDY)


def test_wheel_install_lists_and_loads_shipped_files(tmp_path: Path) -> None:
    src, wheels, site, away = tmp_path / "src", tmp_path / "wheels", tmp_path / "site", tmp_path / "away"
    _copy_checkout(src)
    away.mkdir()
    build = [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(wheels)]
    if _setuptools_is_new_enough():
        build.append("--no-build-isolation")
    subprocess.run(build, check=True, timeout=180)
    (whl,) = wheels.glob("fdi_sim-*.whl")
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--target", str(site),
                    str(whl)], check=True, timeout=120)

    # the installed copy, not the checkout: PYTHONPATH comes before the venv's editable finder
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "scenarios"], cwd=away, env=env, check=True,
                         capture_output=True, text=True, timeout=120).stdout
    header, *lines = out.splitlines()
    assert header.split() == ["name", "aircraft", "kind", "path", "description"]
    rows = {}
    for line in lines:
        name, aircraft, kind, path, _desc = (line.split(None, 4) + [""])[:5]
        rows[name] = (aircraft, kind, Path(path))

    expected = {p.stem: "scenario" for p in (ROOT / "scenarios").glob("*.toml")}
    expected |= {p.stem: "study" for p in (ROOT / "scenarios" / "studies").glob("*.toml")}
    expected["zz_wheel_check"] = "study"
    assert {n: r[1] for n, r in rows.items()} == expected
    assert rows["zz_wheel_check"][0] == "DHC6"  # a study's aircraft is its base scenario's
    installed = site / "fdi_sim" / "_scenarios"
    for name, (_ac, kind, path) in rows.items():
        assert path.is_file() and not path.is_symlink(), path
        assert path.parent in (installed, installed / "studies"), path

    got = json.loads(subprocess.run(
        [sys.executable, "-c", LOAD, json.dumps([[k, str(p)] for _a, k, p in rows.values()])], cwd=away, env=env,
        check=True, capture_output=True, text=True, timeout=120).stdout)
    assert Path(got["package"]).parent == site / "fdi_sim"
    assert got["loaded"] == len(rows)
    assert Path(got["resolved"]) == installed / "f16_pitch_gyro_bias.toml"
    # the Foxglove layout and the DHC-6 thresholds file ship too, byte for byte
    for rel in ("review/foxglove/fdi-sim-layout.json",):
        assert (site / "fdi_sim" / rel).read_bytes() == (ROOT / "fdi_sim" / rel).read_bytes(), rel
    assert (site / "fdi_sim" / "_aircraft" / "DHC6" / "fdi_thresholds.toml").read_bytes() == (
        ROOT / "aircraft" / "DHC6" / "fdi_thresholds.toml").read_bytes()


def test_listing_in_checkout_matches_the_folder() -> None:
    assert shipped_dir().resolve() == (ROOT / "scenarios").resolve()
    assert [f.path.name for f in list_scenarios()] == sorted(p.name for p in (ROOT / "scenarios").glob("*.toml"))
    assert [f.path.name for f in list_studies()] == sorted(
        p.name for p in (ROOT / "scenarios" / "studies").glob("*.toml"))
    assert all(f.kind == "scenario" and f.aircraft in ("f16", "DHC6") and f.description for f in list_scenarios())


def test_resolve(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # outside the checkout: scenarios/... is the shipped folder
    shipped = shipped_dir() / "f16_pitch_gyro_bias.toml"
    assert resolve("f16_pitch_gyro_bias") == shipped
    assert resolve("f16_pitch_gyro_bias.toml") == shipped
    assert resolve("scenarios/f16_pitch_gyro_bias.toml") == shipped
    own = tmp_path / "scenarios" / "f16_pitch_gyro_bias.toml"  # a file that exists wins over the shipped one
    own.parent.mkdir()
    own.write_text("")
    assert resolve("scenarios/f16_pitch_gyro_bias.toml") == Path("scenarios/f16_pitch_gyro_bias.toml")
    with pytest.raises(ScenarioError, match="did you mean 'f16_pitch_gyro_bias'"):
        resolve("f16_pitch_gyro_bais")
    with pytest.raises(ScenarioError, match="no such file"):
        resolve("scenarios/does_not_exist.toml")

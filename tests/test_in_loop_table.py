"""docs/in_loop.md (written by ``python docs/make_in_loop_table.py`` from docs/card/in_loop.json):
it covers every registered detector and every shipped fault scenario, carries its stamp, and the
markdown is what the JSON renders to. The bar of the every-detector issue (every shipped fault
caught and isolated by at least one seed method in the loop) is checked on it: not met yet.
"""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from fdi_sim import registry
from fdi_sim.scenario import load

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "docs" / "card" / "in_loop.json"


def _script():
    spec = importlib.util.spec_from_file_location("make_in_loop_table", ROOT / "docs" / "make_in_loop_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def data() -> dict:
    return json.loads(DATA.read_text())


def test_the_table_covers_every_detector_and_every_shipped_fault_scenario(data):
    assert data["detectors"] == registry.ids("detector"), "a detector was added or renamed: regenerate the table"
    shipped = sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml") if load(p).faults)
    assert sorted(s["scenario"] for s in data["scenarios"]) == shipped, "regenerate the table"
    for sc in data["scenarios"]:
        flown = {r["detector"] for r in sc["rows"]}
        skipped = {n.split(":", 1)[0] for n in sc.get("skipped", [])}
        assert flown | skipped == set(data["detectors"]) or sc["status"] == "error", sc["scenario"]


def test_the_markdown_is_the_json_rendered_with_its_stamp(data):
    md = (ROOT / "docs" / "in_loop.md").read_text()
    assert md == _script().render(data)
    assert md.startswith(f"<!-- {data['stamp']} -->") and "command: python docs/make_in_loop_table.py" in md


@pytest.mark.xfail(strict=True, reason="not met: beard-jones-v1 isolates 5 of the 10 shipped faults in the loop (the "
                   "F-16 aileron float, engine flameout and stuck elevator, the DHC-6 elevator loss and rudder "
                   "hard-over); the three sensor faults (DHC-6 airspeed drift and intermittent alpha, F-16 pitch-gyro "
                   "bias), the DHC-6 flameout and the tail icing are caught by no seed method: at the bank's 0.1 "
                   "alarms per flight hour split over 15 members their thresholds, set on fault-free flights in "
                   "turbulence, sit above what these faults do to their statistics, and the observer and parity "
                   "designs carry actuator hypotheses only (docs/in_loop.md, 'Why a method misses')")
def test_every_shipped_fault_is_caught_and_isolated_by_a_seed_method(data):
    seed = set(_script().SEED_METHODS)
    missing = [sc["scenario"] for sc in data["scenarios"]
               if not any(r["detector"] in seed and r["correct"] and not r["early"] for r in sc["rows"])]
    assert not missing, missing

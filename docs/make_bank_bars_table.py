"""The shipped fault scenarios flown with the default bank as shipped: the generated block
``bank-bars`` of docs/bank.md (what ``tests/sim/test_bank_bars.py`` checks, with the delays).

Each scenario is flown once (its own seed) with ``fdi_sim.training.fly``; the row gives where the
bank's design and thresholds came from (the atlas node, a study's file, or training flights), the
first correct isolation (detector, delay after the onset, hypothesis), the alarms outside the
fault and how the flight ended. The README's summary excerpt (block ``bank-summary``) is the
bank's part of the run summary of :data:`README_SCENARIO`, from the same flight.

    python docs/make_bank_bars_table.py
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.flightlog import read_log  # noqa: E402
from fdi_sim.scenario import load  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training import fly  # noqa: E402

SCENARIOS = sorted(p for p in (ROOT / "scenarios").glob("*.toml") if load(p).faults)
INPUTS = tuple(f"scenarios/{p.name}" for p in SCENARIOS) + (
    "aircraft", "fdi_sim/bank", "fdi_sim/decision", "fdi_sim/detectors", "fdi_sim/training", "fdi_sim/faults",
    "fdi_sim/sensors", "docs/make_bank_bars_table.py")
MD = ROOT / "docs" / "bank.md"
README = ROOT / "README.md"
#: the scenario whose run summary the README quotes
README_SCENARIO = "f16_pitch_gyro_bias"
_EXCERPT: dict[str, str] = {}


def _source(cal: dict) -> str:
    src = cal.get("source", "?")
    if src == "atlas" or "atlas" in cal:
        n = cal.get("atlas", {}).get("node", {})
        return f"atlas node {n.get('h_ft', 0):g} ft / {n.get('vc_kts', 0):g} kt"
    if src == "study":
        return f"study file ({cal.get('study')})"
    return "training flights at its own point"


def row(path: Path) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        res = fly(load(path), tmp, progress=False)
        s = res.summary
        cal = json.loads(read_log(res.log_path).metadata["fdi"]["calibration"])
    if path.stem == README_SCENARIO:
        _EXCERPT["text"] = bank_excerpt(s.format())
    hits = [d for d in s.fdi_detections if d.detected_t_s is not None]
    right = sorted((d for d in hits if d.isolation_correct), key=lambda d: d.delay_s)
    if right:
        d = right[0]
        first = f"{d.detector}, {d.delay_s:.2f} s, {d.isolation}"
    elif hits:
        d = min(hits, key=lambda d: d.delay_s)
        first = f"detected by {d.detector} at {d.delay_s:.2f} s, isolated as {d.isolation} (no right isolation)"
    else:
        first = "not detected"
    return (f"| {path.stem} | {_source(cal)} | {first} | {len(s.fdi_false_alarms)} | {res.status} |")


def bank_excerpt(summary: str, keep: int = 2) -> str:
    """The bank's part of a run summary: its first line, the first ``keep`` detection lines, the
    reconfigurations and the false alarms (other detection lines elided with ``...``, the bank's
    indented notes left out)."""
    lines = summary.splitlines()
    i0 = next(i for i, ln in enumerate(lines) if ln.startswith("fdi bank"))
    body = []
    det = 0
    for ln in lines[i0 + 1:]:
        if not ln.startswith("  "):
            break
        if ln.startswith("   "):  # the bank's notes (design, schedule points): not quoted
            continue
        if ln.strip().startswith(("reconfigured", "false alarms")):
            body.append(ln)
        elif det < keep:
            body.append(ln)
            det += 1
        elif det == keep:
            body.append("  ...")
            det += 1
    return "\n".join(["```text", lines[i0], *body, "```"])


def render() -> str:
    lines = ["| scenario | design and thresholds from | first right isolation (detector, delay after onset, "
             "hypothesis) | alarms outside the fault | flight |", "|---|---|---|---|---|"]
    for p in SCENARIOS:
        lines.append(row(p))
        print(lines[-1], file=sys.stderr, flush=True)
    lines.append("")
    lines.append("One flight per scenario, its own seed (the thresholds came from other seeds). `f16_stuck_elevator` "
                 "departs by design; icing has no hypothesis in any bank.")
    return "\n".join(lines)


def main() -> int:
    stamp = make_stamp("bank-bars", "python docs/make_bank_bars_table.py", INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, render()))
    print(f"wrote the bank-bars block of {MD}")
    stamp = make_stamp("bank-summary", "python docs/make_bank_bars_table.py", INPUTS)
    README.write_text(replace_block(README.read_text(), stamp, _EXCERPT["text"]))
    print(f"wrote the bank-summary block of {README}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""What not telling the bank the turbulence costs in detection: every shipped fault scenario flown
twice with the default bank, its own seed, (a) as a user gets it (``[fdi.design]`` left out:
designed at the scenario's own turbulence level) and (b) as the envelope studies fly it, not told
the level (``point = "grid"``, moderate turbulence, no wind, noise scale 1: thresholds calibrated in
moderate air and raised by the bank's own turbulence estimate in rougher air). Per scenario, the
scenario's level and the first right isolation of each: the generated block ``detection-cost`` of
docs/bank.md.

    python docs/make_detection_cost_table.py
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.scenario import load  # noqa: E402
from fdi_sim.scenario.loader import from_dict  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training import fly  # noqa: E402

SCENARIOS = sorted(p for p in (ROOT / "scenarios").glob("*.toml") if load(p).faults)
NOT_TOLD = {"point": "grid", "turbulence": "moderate", "wind_speed_kts": 0.0, "noise_scale": 1.0}
INPUTS = tuple(f"scenarios/{p.name}" for p in SCENARIOS) + (
    "aircraft", "fdi_sim/bank", "fdi_sim/decision", "fdi_sim/detectors", "fdi_sim/training", "fdi_sim/faults",
    "fdi_sim/sensors", "docs/make_detection_cost_table.py")
MD = ROOT / "docs" / "bank.md"


def first_right(path: Path, design: dict | None) -> str:
    sc = load(path)
    if design is not None:
        d = json.loads(sc.to_json())
        d["fdi"] = {**d.get("fdi", {}), "design": design}
        sc = from_dict(d, source=f"{path} (not told the turbulence)")
    with tempfile.TemporaryDirectory() as tmp:
        s = fly(sc, tmp, progress=False).summary
    hits = [d for d in s.fdi_detections if d.detected_t_s is not None]
    right = sorted((d for d in hits if d.isolation_correct), key=lambda d: d.delay_s)
    fa = f"; {len(s.fdi_false_alarms)} alarms outside the fault" if s.fdi_false_alarms else ""
    if right:
        return f"{right[0].detector} {right[0].delay_s:.2f} s{fa}"
    if hits:
        d = min(hits, key=lambda d: d.delay_s)
        return f"detected {d.delay_s:.2f} s ({d.detector}), not isolated{fa}"
    return f"not detected{fa}"


def main() -> int:
    lines = ["| scenario | turbulence | designed at its level (as shipped) | designed at moderate, not told |",
             "|---|---|---|---|"]
    for p in SCENARIOS:
        lines.append(f"| {p.stem} | {load(p).model.atmosphere.turbulence} | {first_right(p, None)} | "
                     f"{first_right(p, NOT_TOLD)} |")
        print(lines[-1], file=sys.stderr, flush=True)
    lines += ["", "First right isolation: detector and delay after the onset. One flight per scenario and design, "
              "the scenario's own seed."]
    stamp = make_stamp("detection-cost", "python docs/make_detection_cost_table.py", INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, "\n".join(lines)))
    print(f"wrote the detection-cost block of {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

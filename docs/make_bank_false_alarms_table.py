"""The default bank on fault-free flights at the shipped scenarios' points, on seeds no design
decision saw: the generated block ``bank-false-alarms`` of docs/bank.md and the card
docs/card/bank_false_alarms.json, both stamped. Each point of
:data:`fdi_sim.study.bank_false_alarms.POINTS` flown with the held-out seeds of the ``bank-bar`` set
(301-308), 10 minutes, moderate turbulence, faults removed, the default bank as a user gets it
(:func:`fdi_sim.study.bank_false_alarms.study_point`); every alarm episode is a false alarm.

    python docs/make_bank_false_alarms_table.py
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.decision.intervals import poisson_rate_interval  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.study.bank_false_alarms import HELD_OUT_SEEDS, POINTS, study_point  # noqa: E402

MD = ROOT / "docs" / "bank.md"
CARD = ROOT / "docs" / "card" / "bank_false_alarms.json"
COMMAND = "python docs/make_bank_false_alarms_table.py"
INPUTS = tuple(f"scenarios/{n}.toml" for names in POINTS.values() for n in names) + (
    "aircraft", "fdi_sim/bank", "fdi_sim/decision", "fdi_sim/detectors", "fdi_sim/training", "fdi_sim/sensors",
    "fdi_sim/study/bank_false_alarms.py", "docs/make_bank_false_alarms_table.py")
DURATION_S = 600.0


def _rate(n: int, h: float) -> str:
    lo, hi = poisson_rate_interval(n, h)
    return f"{n / h:.3g} [{lo:.3g}, {hi:.3g}]"


def main() -> int:
    t0 = time.perf_counter()
    rows = []
    for names in POINTS.values():
        for name in names:
            rows.append(study_point(name, HELD_OUT_SEEDS[:8], DURATION_S, progress=False))
            r = rows[-1]
            print(f"{name}: {r.false_alarms} in {r.flight_h:.2f} h {r.statuses} ({time.perf_counter() - t0:.0f} s)",
                  file=sys.stderr, flush=True)
    lines = ["| scenario | flights | hours | alarms | per hour, 95 % | design | members |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.scenario} | {r.flights} | {r.flight_h:.2f} | {r.false_alarms} | "
                     f"{_rate(r.false_alarms, r.flight_h)} | {r.design_far_per_h:g} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(r.by_detector.items())) or '-'} |")
    n, h = sum(r.false_alarms for r in rows), sum(r.flight_h for r in rows)
    lines.append(f"| all | {sum(r.flights for r in rows)} | {h:.2f} | {n} | {_rate(n, h)} | "
                 f"{rows[0].design_far_per_h:g} | |")
    lines += ["", f"Seeds {HELD_OUT_SEEDS[0]}-{HELD_OUT_SEEDS[7]}, {DURATION_S:g} s each, moderate turbulence; "
              f"{time.perf_counter() - t0:.0f} s to fly."]
    stamp = make_stamp("bank-false-alarms", COMMAND, INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, "\n".join(lines)))
    CARD.write_text(json.dumps({"stamp": asdict(stamp), "points": [asdict(r) for r in rows]}, indent=1) + "\n")
    print(f"wrote the bank-false-alarms block of {MD} and {CARD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Write docs/detectors.md: every registered detector on held-out fault-free flights and on every
shipped fault scenario (protocol in fdi_sim/study/card.py).

    python docs/make_detector_card.py                  # the card: the bank's training flights and target
    python docs/make_detector_card.py --quick          # fewer, shorter flights at a looser target, to try it
    python docs/make_detector_card.py --part faults    # only the fault scenarios (or --part conditions)
Results go to docs/card/conditions.json (the fault-free conditions) and docs/card/faults.json (the
fault scenarios), each with a "stamp" (fdi_sim.stamp) made when its flights start: the command (its
arguments but --workers, which changes no number), the code its numbers depend on (INPUTS) and its
digest. The markdown and figures are made from the JSON (--render, fdi_sim.review.detector_card):
each table is a generated block carrying the stamp of the card its numbers come from.

The card trains like the bank (fdi_sim.training.flights: DEFAULT_TRAINING_FLIGHTS fault-free
flights of DEFAULT_TRAINING_S at the per-sample target DEFAULT_TARGET; ``--quick``: QUICK). Its
run time, cold (training flights) or warm (the calibration cache), is in the log that
docs/regenerate.py writes beside its output.
"""
from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.training.flights import DEFAULT_TARGET, DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S  # noqa: E402

OUT = DOCS / "card"
#: --quick: training flights, their length [s] and the per-sample target, to try the card (not shipped)
QUICK = (6, 120.0, 1e-3)
FAULT_SCENARIOS = ("f16_stuck_elevator", "f16_pitch_gyro_bias", "f16_aileron_float", "f16_engine_flameout",
                   "dhc6_airspeed_drift", "dhc6_intermittent_aoa", "dhc6_rudder_hardover", "dhc6_engine_flameout",
                   "dhc6_elevator_loss", "dhc6_tail_icing")
#: what the numbers depend on besides the scenarios flown (the detectors, their designs and decisions,
#: the training flights, the faults and sensors, the card's protocol and seeds, this script; not the
#: renderer, fdi_sim/review/detector_card.py, which only formats them)
CODE = ("aircraft", "fdi_sim/detectors", "fdi_sim/decision", "fdi_sim/bank", "fdi_sim/training", "fdi_sim/faults",
        "fdi_sim/sensors", "fdi_sim/linear", "fdi_sim/offline", "fdi_sim/study/card.py", "fdi_sim/seeds.py",
        "docs/make_detector_card.py")
INPUTS = {"conditions": ("scenarios/f16_cruise_doublets.toml", "scenarios/dhc6_cruise_doublets.toml")
          + CODE,
          "faults": tuple(f"scenarios/{s}.toml" for s in FAULT_SCENARIOS) + CODE}


def _condition(args: tuple[str, str, int, float, float]) -> list[dict]:
    from fdi_sim.study import card

    ac, lvl, n, dur, target = args
    rows = card.condition_card(ac, lvl, card.detector_ids(), n_train=n, duration_s=dur, target=target,
                               say=lambda s: print(s, flush=True))
    return card.to_json(rows)


def _fault(args: tuple[str, int, float, float]) -> dict:
    from fdi_sim.study import card

    name, n, dur, target = args
    rows, traces, thr = card.fault_card(DOCS.parent / "scenarios" / f"{name}.toml", card.detector_ids(), n_train=n,
                                        duration_s=dur, target=target, say=lambda s: print(s, flush=True))
    keep = {k: {"t_s": [round(t, 3) for t in v.t_s.tolist()],
                "statistic": [None if x != x else float(f"{x:.4g}") for x in v.statistic], "threshold": thr[k]}
            for k, v in traces.items() if k == "kalman-gust-v1"}  # the figure's detector
    return {"scenario": name, "rows": card.to_json(rows), "traces": keep}


def _command(argv: list[str]) -> str:
    """The command that made these numbers: this script with its arguments but --workers."""
    args, skip = [], False
    for x in argv:
        if skip or x.startswith("--workers"):
            skip = x == "--workers"
            continue
        args.append(x)
    return " ".join(["python docs/make_detector_card.py", *args])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--part", choices=("all", "conditions", "faults"), default="all")
    p.add_argument("--render", action="store_true", help="only write the markdown and figures from docs/card/*.json")
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    n, dur, target = QUICK if a.quick else (DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S, DEFAULT_TARGET)
    OUT.mkdir(exist_ok=True)
    if not a.render:
        from dataclasses import asdict

        from fdi_sim.stamp import make_stamp

        command = _command(sys.argv[1:])
        stamps = {k: asdict(make_stamp(f"detector-card-{k}", command, v)) for k, v in INPUTS.items()}  # before flying
        with ProcessPoolExecutor(a.workers) as ex:
            if a.part in ("all", "conditions"):
                jobs = [(ac, lvl, n, dur, target) for ac in ("f16", "DHC6") for lvl in ("none", "light", "moderate")]
                rows = [r for res in ex.map(_condition, jobs) for r in res]
                (OUT / "conditions.json").write_text(json.dumps({"stamp": stamps["conditions"], "n_train": n,
                                                                 "duration_s": dur, "rows": rows}, indent=1))
            if a.part in ("all", "faults"):
                res = list(ex.map(_fault, [(s, n, dur, target) for s in FAULT_SCENARIOS]))
                (OUT / "faults.json").write_text(json.dumps({"stamp": stamps["faults"], "n_train": n, "duration_s": dur,
                                                             "results": res}))
    from fdi_sim.review.detector_card import render

    render(OUT, DOCS / "detectors.md", DOCS / "figures")
    return 0


if __name__ == "__main__":
    sys.exit(main())

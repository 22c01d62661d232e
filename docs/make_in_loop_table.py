"""Write docs/in_loop.md: every registered detector flown *in the loop* on every shipped fault scenario.

    python docs/make_in_loop_table.py              # every shipped fault scenario, 2 processes
    python docs/make_in_loop_table.py --render     # only the markdown, from docs/card/in_loop.json

Protocol: each shipped scenario that injects a fault is flown as shipped (its seed, turbulence,
maneuvers and fault), with a bank of every registered detector (``[fdi] bank = "none"`` and one
``[[detectors]]`` entry per registry id, default options) instead of its own bank. Thresholds are
trained the one way every member gets them (``fdi_sim.training.thresholds``): the bank's
``far_per_h`` (0.1 per flight hour) split over the 15 members, the k-of-n episode tail on the
scenario's fault-free training flights (its ``[fdi]`` calibration settings: 24 x 300 s unless it
says otherwise). Per detector and fault: the delay from onset to the first alarm (the bank's k-of-n
decision), the isolation reported (the most frequent hypothesis in the first second of alarm,
``fdi_sim.decision.outcome``) and whether an alarm episode began before the onset (after arming).
A cell reads ``1.35 s ok`` (detected, isolated right), ``1.35 s x q_radps`` (isolated wrong),
``1.35 s -`` (detected, not isolated), ``missed``; ``early`` marks an alarm before the onset.

docs/card/in_loop.json carries a "stamp" (:mod:`fdi_sim.stamp`, made before the flights start):
the command, the code the numbers depend on (:data:`INPUTS`) and its digest, the commit and the
package version. Each table of docs/in_loop.md is a generated block with that stamp (its id the
block's), so ``tests/test_generated_docs.py`` tells when the code changed under it; the head line
and the "Stamp:" line repeat it. ``--update`` keeps the card's old stamp (its digest, so the tables
stay stale if the code changed since: the rows not re-flown are the old code's) and adds the
re-flown scenarios and this run's commit to its ``commit``.

Run time (measured 2026-12-04, --workers 1, niced, on the 2-core machine with a study running, load
5-8): the first scenario (dhc6_airspeed_drift: training 24 x 300 s flights and every member's
threshold, then the flight) was not done after 8 min, so well over an hour for the ten; that run
was stopped and nothing was written. After SIGTERM the worker went on to the next scenario (the
simulator ends a flight "interrupted" on SIGTERM): stopping a run took SIGKILL on the worker's pid.
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

from fdi_sim.stamp import Stamp, generated_block, make_stamp

OUT = DOCS / "card" / "in_loop.json"
MD = DOCS / "in_loop.md"
#: the seed documents' methods (the others are the project's own: kalman-gust and the kinematic checks)
SEED_METHODS = ("parity-v1", "parity-robust-v1", "parity-stochastic-v1", "pca-v1", "beard-jones-v1",
                "lmi-detection-v1", "kalman-nis-v1", "kalman-tv-nis-v1", "kalman-mmae-v1", "adaptive-observer-v1")


def fault_scenarios() -> list[str]:
    from fdi_sim.scenario import load

    return sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml") if load(p).faults)


COMMAND = "python docs/make_in_loop_table.py"
#: what the numbers depend on: the scenarios flown, the aircraft, the detectors (which are
#: registered, their designs), the bank and its threshold training, the decision, the faults and
#: sensors, the linearization the designs start from, and this script
INPUTS = tuple(f"scenarios/{n}.toml" for n in fault_scenarios()) + (
    "aircraft", "fdi_sim/registry.py", "fdi_sim/detectors", "fdi_sim/bank", "fdi_sim/decision", "fdi_sim/training",
    "fdi_sim/faults", "fdi_sim/sensors", "fdi_sim/linear", "docs/make_in_loop_table.py")
UNSTAMPED = f"<!-- table: result, unstamped; regenerate: {COMMAND} -->"


def fly_one(name: str) -> dict:
    import tempfile

    from fdi_sim import registry
    from fdi_sim.scenario import from_dict, load
    from fdi_sim.training import fly

    sc = load(ROOT / "scenarios" / f"{name}.toml")
    d = json.loads(sc.to_json())
    ids = registry.ids("detector")
    d["detectors"] = [{"type": i} for i in ids]
    # a seed method that cannot be designed at this point is left out (the notes say why), not the whole table
    d["fdi"] = {**d.get("fdi", {}), "bank": "none", "thresholds": "trained", "on_design_failure": "skip"}
    sc2 = from_dict(d, source=f"{name}.toml (every registered detector in the loop)")
    print(f"{name}: flying with {len(ids)} detectors", flush=True)
    import numpy as np

    from fdi_sim.errors import FdiSimError
    from fdi_sim.flightlog import read_log

    with tempfile.TemporaryDirectory() as tmp:
        try:
            res = fly(sc2, tmp, progress=False)
        except FdiSimError as exc:  # the bank of every detector cannot be built here: the table says why
            print(f"{name}: error {exc}", flush=True)
            return {"scenario": name, "status": "error", "reason": str(exc), "t_end_s": 0.0, "rows": []}
        log = read_log(res.log_path)
        s = res.summary
        rows = []
        for det in s.fdi_detections:
            early = any(a.detector == det.detector and a.onset_t_s < det.onset_t_s for a in s.fdi_alarms)
            st = log.topics[f"/fdi/{det.detector}/statistic"]
            t, x = np.asarray(st.t_s, float), np.asarray(st["statistic"], float)
            ok = np.asarray(st["valid"], float) > 0.5
            thr = float(np.asarray(st["threshold"], float)[-1])

            def peak(a: float, b: float) -> float | None:
                m = ok & (t >= a) & (t < b) & np.isfinite(x)
                return float(x[m].max()) if m.any() else None

            t0 = det.onset_t_s
            rows.append({"fault": det.fault, "target": det.target, "detector": det.detector, "onset_t_s": t0,
                         "delay_s": det.delay_s, "isolation": det.isolation, "correct": det.isolation_correct,
                         "early": early, "threshold": thr, "peak_before": peak(sc.model.fdi.arm_s, t0),
                         "peak_after_10s": peak(t0, t0 + 10.0)})
    print(f"{name}: {s.status}, {len(rows)} rows", flush=True)
    skipped = [n for n in s.fdi_notes if ": skipped, " in n]
    return {"scenario": name, "status": s.status, "reason": s.reason, "t_end_s": s.t_end_s, "rows": rows,
            "skipped": skipped}


def _cell(r: dict) -> str:
    if r["delay_s"] is None:
        c = "missed"
    elif r["correct"]:
        c = f"{r['delay_s']:.2f} s ok"
    elif r["isolation"]:
        c = f"{r['delay_s']:.2f} s x {r['isolation']}"
    else:
        c = f"{r['delay_s']:.2f} s -"
    return c + (" (early)" if r["early"] else "")


def stamp_text(stamp: dict | str) -> str:
    """The stamp for the reader: version, commit, date and command (a card from before the stamp
    objects holds this text itself)."""
    if isinstance(stamp, str):
        return stamp
    return f"fdi-sim {stamp['version']} at commit {stamp['commit']}, {stamp['date']}; command: {stamp['command']}"


def _table(data: dict, block_id: str, table: list[str]) -> list[str]:
    """``table`` as the generated block ``block_id`` with the card's stamp (the marker line and the
    table when the card's stamp is the old text)."""
    d = data["stamp"]
    if not isinstance(d, dict):
        return [UNSTAMPED] + table
    st = Stamp(**{**d, "inputs": tuple(d["inputs"]), "id": block_id})
    return generated_block(st, "\n".join(table)).splitlines()


def render(data: dict) -> str:
    ids = data["detectors"]
    lines = [f"<!-- {data['stamp']} -->", "# Every detector in the loop, on every shipped fault scenario", "",
             "Generated by `python docs/make_in_loop_table.py` (protocol in its docstring): each shipped fault "
             "scenario flown as shipped with a bank of every registered detector, thresholds trained the same way "
             "for every member. A cell: delay from onset to the first alarm, then `ok` (isolated right), "
             "`x NAME` (isolated as NAME, wrong) or `-` (no isolation); `missed`; `(early)`: an alarm episode began "
             "before the onset.", "",
             "What these numbers are not: the shipped scenarios are development flights (looked at many times), "
             "one seed each, so a delay here is one flight's, with no interval, and no hold-out scenario is in this "
             "table. The design target is the bank's 0.1 alarm episodes per flight hour split over the members "
             "(0.0067 per h each); no false-alarm rate is measured here (a 60-120 s flight cannot show one).", "",
             f"Stamp: {stamp_text(data['stamp'])}", ""]
    seed = [i for i in ids if i in SEED_METHODS]
    own = [i for i in ids if i not in SEED_METHODS]
    for title, block_id, cols in (("Seed documents' methods", "in-loop-seed-methods", seed),
                                  ("The project's own members", "in-loop-own-members", own)):
        table = ["| scenario (fault) | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
        for sc in data["scenarios"]:
            by = {}
            for r in sc["rows"]:
                by.setdefault((r["fault"], r["target"]), {})[r["detector"]] = r
            for (fault, target), per in by.items():
                cells = [_cell(per[c]) if c in per else "" for c in cols]
                table.append(f"| {sc['scenario']} ({fault} on {target}, {sc['status']}) | " + " | ".join(cells) + " |")
        lines += [f"## {title}", ""] + _table(data, block_id, table) + [""]
    lines += ["## Why a method misses: its threshold against its statistic", "",
              "Per scenario and seed method, the threshold (set for the member's share of 0.1 alarm episodes "
              "per flight hour on the fault-free training flights), the statistic's peak between arming and the "
              "onset, and its peak in the 10 s after the onset (the statistic's own scale).", ""]
    table = ["| scenario | " + " | ".join(seed) + " |", "|---|" + "---|" * len(seed)]
    for sc in data["scenarios"]:
        per = {r["detector"]: r for r in sc["rows"]}
        def g(v):
            return "-" if v is None else f"{v:.3g}"
        cells = [f"{g(per[c].get('threshold'))} / {g(per[c].get('peak_before'))} / {g(per[c].get('peak_after_10s'))}"
                 if c in per else "" for c in seed]
        table.append(f"| {sc['scenario']} | " + " | ".join(cells) + " |")
    lines += _table(data, "in-loop-thresholds", table)
    lines += ["", "(threshold / peak before the onset / peak in the 10 s after it)", ""]
    skipped = [(sc["scenario"], n) for sc in data["scenarios"] for n in sc.get("skipped", [])]
    if skipped:
        lines += ["## Members left out because they cannot be designed at the scenario's point", ""]
        lines += [f"- {name}: {n}" for name, n in skipped] + [""]
    errors = [sc for sc in data["scenarios"] if sc["status"] == "error"]
    if errors:
        lines += ["## Scenarios where the bank of every detector could not be built", ""]
        lines += [f"- {sc['scenario']}: {sc['reason']}" for sc in errors] + [""]
    lines += ["## Which scenarios a seed method detects with no early alarm and isolates right", ""]
    for sc in data["scenarios"]:
        good = sorted({r["detector"] for r in sc["rows"] if r["detector"] in SEED_METHODS and r["correct"]
                       and not r["early"]})
        lines.append(f"- {sc['scenario']}: " + (", ".join(good) if good else "**none**"))
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--render", action="store_true")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--only", nargs="*", help="these scenarios only (a trial; not written to the docs)")
    p.add_argument("--update", nargs="*", help="fly these scenarios again and replace their rows in the JSON")
    a = p.parse_args()
    if not a.render:
        from fdi_sim import registry

        names = a.only or a.update or fault_scenarios()
        from dataclasses import asdict

        stamp = asdict(make_stamp("in-loop", COMMAND, INPUTS))  # the code as the flights start
        with ProcessPoolExecutor(a.workers) as ex:
            results = list(ex.map(fly_one, names))
        data = {"stamp": stamp, "detectors": registry.ids("detector"), "scenarios": results}
        if a.update:  # the others as they were, with the old stamp: its digest is the oldest rows' code
            card = json.loads(OUT.read_text())
            old = {sc["scenario"]: sc for sc in card["scenarios"]}
            old.update({sc["scenario"]: sc for sc in results})
            data["scenarios"] = [old[k] for k in sorted(old)]
            prev = card.get("stamp")
            if isinstance(prev, dict):
                data["stamp"] = {**prev, "commit": f"{prev['commit']}; rows of {', '.join(a.update)} re-flown at "
                                                   f"{stamp['commit']} ({stamp['date']}) with --update"}
            else:  # no digest to keep: a digest no code has, so the tables read stale until a whole run
                data["stamp"] = {**stamp, "inputs_sha256": "mixed-runs-regenerate",
                                 "commit": f"{stamp['commit']}; only {', '.join(a.update)} re-flown (--update)"}
        if a.only:
            print(render(data))
            return 0
        OUT.parent.mkdir(exist_ok=True)
        OUT.write_text(json.dumps(data, indent=1))
    data = json.loads(OUT.read_text())
    MD.write_text(render(data))
    print(f"wrote {MD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``fdi-sim study``: fly a Monte Carlo study (or resume one), then its statistics and report."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: Any) -> None:
    s = sub.add_parser("study", help="fly a Monte Carlo study on Dask (resumes an interrupted one), write its "
                       "results folder and report")
    s.add_argument("study", help="study TOML file (`fdi-sim scenarios` lists the shipped ones)")
    s.add_argument("--out", default=None, help="results folder (default: studies/<name>); the same folder resumes")
    s.add_argument("--workers", type=int, default=None, help="local cluster workers (default: the cores)")
    s.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)")
    s.add_argument("--runs", type=int, default=None, help="override the study's number of runs")
    s.add_argument("--duration", type=float, default=None, help="override duration_s of every run [s]")
    s.add_argument("--json", action="store_true", help="print the statistics as one JSON object on stdout")
    s.add_argument("--no-report", action="store_true", help="no HTML report")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--calibrate", default=None, metavar="OUT.toml",
                   help="after flying, calibrate each member's threshold to the bank's rate on half of the runs, check "
                   "it on the other half and write a thresholds file ([fdi] thresholds = \"OUT.toml\"; docs/study.md)")
    s.add_argument("--validate", default=None, nargs="?", const="", metavar="FILE.toml",
                   help="after flying, check the thresholds file the runs flew (or FILE.toml) on this fresh study "
                   "and write the result into the file's [validation] table (a study whose seed is in a validation "
                   "set of fdi_sim/seeds.py; docs/study.md)")
    s.add_argument("--target-per-h", type=float, default=None,
                   help="with --calibrate: the bank's target rate [1/flight hour] (default: the runs' far_per_h)")
    s.set_defaults(func=cmd_study)


def cmd_study(args: argparse.Namespace) -> int:
    from fdi_sim.study.execute import fly_study, load_records
    from fdi_sim.study.spec import load_study

    from fdi_sim.errors import ScenarioError
    from fdi_sim.scenario.shipped import resolve

    try:
        path = resolve(args.study)  # a path, or a shipped study's name
    except ScenarioError:
        path = args.study  # load_study names the file and the fix
    st = load_study(path)
    if args.runs is not None or args.duration is not None:
        st = st.with_overrides(runs=args.runs, duration_s=args.duration)
    out = Path(args.out) if args.out else Path("studies") / st.name
    if args.scheduler and args.workers:
        print("note: --workers is ignored with --scheduler (the cluster has its own workers)", file=sys.stderr)
    o = fly_study(st, out, workers=args.workers, scheduler=args.scheduler, progress=not args.quiet)
    if o.interrupted or not o.complete:
        why = "interrupted" if o.interrupted else f"{o.lost} run(s) lost with their workers"
        print(f"fdi-sim study: {why}: {o.done_before + o.flown} of {o.total} runs are in {out}; "
              f"run the same command to fly the other {o.total - o.done_before - o.flown}", file=sys.stderr)
        return 1
    recs = load_records(out)
    summary = summarize_folder(out, recs)
    if not args.no_report:
        from fdi_sim.study.report import write_report

        rescored = None
        if any(r.get("log") for r in recs):  # ROC and threshold figures from the stored statistics
            import numpy as np

            from fdi_sim.study.rescore import rescore

            from fdi_sim.errors import StudyError

            try:
                rescored = rescore(recs, out, np.geomspace(0.25, 4.0, 25))
            except StudyError as exc:  # e.g. the angle-magnitude rule: no re-scoring, the rest of the report
                print(f"note: no ROC or threshold figures ({exc})", file=sys.stderr)
        page = write_report(out / "report", recs, summary, rescored, study_dir=out)
        print(f"report     {page}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary, default=_jsonable))
    else:
        print(format_summary(summary, o))
    if args.calibrate:
        from fdi_sim.bank.thresholds_file import write_thresholds
        from fdi_sim.study.calibration import calibrate_study, format_thresholds

        t = calibrate_study(out, far_per_h=args.target_per_h)
        write_thresholds(t, args.calibrate)
        print(format_thresholds(t), file=sys.stderr if args.json else sys.stdout)
        print(f"thresholds {args.calibrate}", file=sys.stderr)
    if args.validate is not None:
        from fdi_sim.bank.thresholds_file import write_thresholds
        from fdi_sim.study.calibration import format_thresholds
        from fdi_sim.study.validation import validate_study
        from fdi_sim.training.thresholds import thresholds_source
        from fdi_sim.scenario import load

        target = Path(args.validate) if args.validate else \
            thresholds_source(load(out / "runs" / recs[0]["scenario"]))[0]
        t = validate_study(out, target)
        write_thresholds(t, target)
        print(format_thresholds(t), file=sys.stderr if args.json else sys.stdout)
        print(f"validated  {target}", file=sys.stderr)
    return 0


def summarize_folder(out: Path, recs: list[dict[str, Any]]) -> dict[str, Any]:
    """The statistics of a results folder, also written to ``results.json``."""
    from fdi_sim.study.execute import _write_atomic
    from fdi_sim.study.stats import summarize

    summary = summarize(recs)
    meta = json.loads((out / "study.json").read_text())
    summary = {"study": meta["name"], "identity": meta["identity"], **summary}
    _write_atomic(out / "results.json", json.dumps(summary, indent=1, default=_jsonable).encode())
    return summary


def _jsonable(x: Any) -> Any:
    import numpy as np

    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def _fmt(x: Any, spec: str = ".3g") -> str:
    return "-" if x is None else format(x, spec)


def format_summary(s: dict[str, Any], o: Any) -> str:
    lines = [f"study      {s.get('study')}: {s['runs']} runs, {s['flight_h']:.2f} flight h, statuses {s.get('statuses')}",
             f"this call  flew {o.flown} runs ({o.flight_h:.2f} flight h) in {o.wall_s:.0f} s"
             + (f", {o.flight_h / (o.wall_s / 3600.0):.0f} flight h per hour" if o.wall_s > 0 and o.flown else ""),
             f"{'detector':26} {'false':>5} {'per h':>8} {'95 % interval':>19} {'predicted':>9} {'P(detect)':>9} "
             f"{'95 % interval':>15} {'delay med':>9} {'p95':>6}"]
    for d in s["detectors"]:
        ci = d.get("far_per_h_ci") or (None, None)
        pci = d.get("p_detect_ci") or (None, None)
        lines.append(f"{d['id']:26} {d['false_alarms']:5d} {_fmt(d.get('far_per_h'), '8.3g')} "
                     f"[{_fmt(ci[0], '.3g')}, {_fmt(ci[1], '.3g')}]".ljust(0) + f" {_fmt(d.get('predicted_far_per_h'), '9.3g')} "
                     f"{_fmt(d.get('p_detect'), '9.3f')} [{_fmt(pci[0], '.3f')}, {_fmt(pci[1], '.3f')}] "
                     f"{_fmt(d.get('delay_s_median'), '9.2f')} {_fmt(d.get('delay_s_p95'), '6.2f')}")
    return "\n".join(lines)

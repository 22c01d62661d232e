"""``fdi-sim bench`` (run, score, leaderboard, list) and ``fdi-sim export``."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

# one JSON fallback for numpy values in both commands
from fdi_sim.bench.suite import LATEST
from fdi_sim.study.cli import _jsonable
from fdi_sim.study.spec import FULL_LOG_BYTES_PER_H
from fdi_sim.units import S_PER_H

#: the results of a benchmark run, written into its folder
RESULT_FILE = "bench.json"
#: one line per call that flew something: what it flew and how long it took (the benchmark's cost)
CALLS_FILE = "bench_calls.jsonl"


def record_call(out: Path, outcome: Any, workers: int | None, scheduler: str | None) -> None:
    """Append what a call flew to the folder's :data:`CALLS_FILE`: cases, flight hours, wall time (designs
    included), and the designs it needed with their wall time summed over the workers (a cold call, whose
    designs flew their training flights, told from a warm one)."""
    import datetime

    if not outcome.flown:
        return
    line = {"date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"), "flown": outcome.flown,
            "flight_h": outcome.flight_h, "wall_s": outcome.wall_s, "workers": workers, "scheduler": scheduler,
            "interrupted": outcome.interrupted, "designs": outcome.designs,
            "design_wall_s": round(outcome.design_wall_s, 1)}
    with open(out / CALLS_FILE, "a", encoding="utf-8") as f:
        f.write(json.dumps(line) + "\n")


def read_calls(out: Path) -> list[dict[str, Any]]:
    """The folder's calls that flew something (none for a folder flown before the log existed)."""
    try:
        return [json.loads(x) for x in (out / CALLS_FILE).read_text().splitlines() if x.strip()]
    except OSError:
        return []


def add_parser(sub: Any) -> None:
    b = sub.add_parser("bench", help="the frozen benchmark suite: fly and score detectors or banks, score external "
                       "methods, the leaderboard (docs/bench.md)")
    bs = b.add_subparsers(dest="bench_command", required=True)
    r = bs.add_parser("run", help="fly (or reuse) the suite's cases with a bank and score every member and the bank")
    r.add_argument("--suite", default=LATEST, help="a shipped suite version or a suite file")
    r.add_argument("--bank", default=None, choices=("default",), help="the aircraft's default bank (default when no "
                   "--detector is given)")
    r.add_argument("--detector", action="append", default=[], metavar="ID[:key=value,...]", help="a registered or "
                   "plugin detector with design options, flown beside the others with reconfiguration off (repeatable)")
    r.add_argument("--split", default=None, choices=("train", "validation", "test"), help="only this split's cases")
    r.add_argument("--group", action="append", default=[], metavar="PATTERN", help="only these groups (fnmatch "
                   "patterns; repeatable)")
    r.add_argument("--aircraft", default=None, help="only this aircraft's cases (f16, DHC6)")
    r.add_argument("--per-group", type=int, default=None, metavar="N", help="at most N cases per group and size")
    r.add_argument("--full-logs", action="store_true", help="keep the 120 Hz sensor, command and truth topics too "
                   f"(up to {FULL_LOG_BYTES_PER_H / 1e9:.1f} GB per flight hour: what `fdi-sim export` gives a learned "
                   "detector); a folder of its own")
    r.add_argument("--out", default=None, help="results folder (default: bench/<suite>.<bank>); the same folder "
                   "resumes and grows")
    r.add_argument("--workers", type=int, default=None, help="local cluster workers (default: the cores)")
    r.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    r.add_argument("--json", action="store_true", help="print the scores as one JSON object")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_run)
    s = bs.add_parser("score", help="score an external method's per-sample scores or alarms against an export")
    s.add_argument("--scores", required=True, help="Parquet or CSV: case, t_s, score and/or alarm, suite_hash")
    s.add_argument("--export", required=True, help="the export folder the method was scored on (`fdi-sim export`)")
    s.add_argument("--split", default="test", choices=("train", "validation", "test", "all"),
                   help="the cases the file must score (default: test)")
    s.add_argument("--threshold", type=float, default=None, help="alarm = score > X when the file has no alarm column")
    s.add_argument("--name", default="external", help="the method's name in the output")
    s.add_argument("--json", action="store_true", help="print the scores as one JSON object")
    s.set_defaults(func=cmd_score)
    lb = bs.add_parser("leaderboard", help="one table of every scored method of benchmark results folders")
    lb.add_argument("results", nargs="+", help="results folders of `fdi-sim bench run`")
    lb.add_argument("--split", default="all", help="the split to rank on (default: all)")
    lb.add_argument("--out", default=None, help="write the Markdown table here (and an .html beside it)")
    lb.set_defaults(func=cmd_leaderboard)
    ls = bs.add_parser("list", help="the suite's groups, cases, splits and flight hours, and its hash")
    ls.add_argument("--suite", default=LATEST)
    ls.set_defaults(func=cmd_list)
    e = sub.add_parser("export", help="a benchmark results folder as a labelled dataset (Parquet per topic, a uniform "
                       "grid, events, per-flight labels, the split)")
    e.add_argument("results", help="results folder of `fdi-sim bench run`")
    e.add_argument("--out", required=True, help="the dataset folder")
    e.add_argument("--quiet", action="store_true")
    e.set_defaults(func=cmd_export)


def cmd_list(args: argparse.Namespace) -> int:
    from fdi_sim.bench.suite import SPLITS, load_suite

    s = load_suite(args.suite)
    print(f"suite   {s.name}  hash {s.hash}\n        {len(s.cases)} cases, {s.flight_h():.1f} planned flight h")
    print(f"{'group':28} {'aircraft':8} {'cases':>5} {'h':>6}  " + " ".join(f"{x:>10}" for x in SPLITS) + "  fault / label")
    for g in s.model.groups:
        cs = [c for c in s.cases if c.group == g.name]
        what = (g.fault or {}).get("type", "") + (f" x {len(g.size.values)} sizes ({g.size.key})" if g.size else "")
        print(f"{g.name:28} {cs[0].aircraft:8} {len(cs):5d} {s.flight_h(tuple(cs)):6.1f}  "
              + " ".join(f"{sum(c.split == x for c in cs):10d}" for x in SPLITS) + f"  {what or g.negative or 'fault-free'}")
    return 0


def _out_dir(args: argparse.Namespace, suite: Any, bank: Any) -> Path:
    if args.out:
        return Path(args.out)
    return Path("bench") / f"{suite.name}.{bank.slug}"[:120]


def cmd_run(args: argparse.Namespace) -> int:
    from fdi_sim.bench.run import bench_bank, fly_bench, suite_study
    from fdi_sim.bench.score import score_folder
    from fdi_sim.bench.suite import load_suite
    from fdi_sim.study.execute import _write_atomic

    suite = load_suite(args.suite)
    bank = bench_bank(default=not args.detector, detector_ids=args.detector)
    cases = suite.select(split=args.split, groups=tuple(args.group), aircraft=args.aircraft, per_group=args.per_group)
    st = suite_study(suite, bank, cases, full_logs=args.full_logs)
    out = _out_dir(args, suite, bank)
    if not args.quiet:
        print(f"bench      {suite.name} ({suite.hash[:12]}), {bank.name}: {len(cases)} cases, "
              f"{suite.flight_h(cases):.1f} flight h -> {out}", file=sys.stderr)
    o = fly_bench(st, out, workers=args.workers, scheduler=args.scheduler, progress=not args.quiet)
    record_call(out, o, args.workers, args.scheduler)
    if o.interrupted or not o.complete:
        why = "interrupted" if o.interrupted else f"{o.lost} case(s) lost with their workers"
        print(f"fdi-sim bench run: {why}: {o.done_before + o.flown} of {o.total} cases are in {out}; run the same "
              f"command to fly the other {o.total - o.done_before - o.flown}", file=sys.stderr)
        return 1
    res = score_folder(st, out)
    d = res.to_dict() | {"selection": {"split": args.split, "groups": args.group, "aircraft": args.aircraft,
                                       "per_group": args.per_group},
                         "this_call": {"flown": o.flown, "flight_h": o.flight_h, "wall_s": o.wall_s}}
    _write_atomic(out / RESULT_FILE, json.dumps(d, indent=1, default=_jsonable).encode())
    if args.json:
        print(json.dumps(d, default=_jsonable))
    else:
        print(format_scores(d["scored"].get("all", {}), f"{suite.name} / {bank.name}: {res.cases} cases "
                            f"({len(res.departed)} departed, scored to the departure; {len(res.not_scored)} not scored), "
                            f"{res.flight_h:.2f} flight h scored"))
        if o.flown:
            print(f"this call flew {o.flown} cases ({o.flight_h:.2f} flight h) in {o.wall_s:.0f} s: "
                  f"{o.flight_h / (o.wall_s / S_PER_H):.0f} flight h per hour")
        print(f"results    {out / RESULT_FILE}")
    return 0


def cmd_score(args: argparse.Namespace) -> int:
    from fdi_sim.bench.export import read_scores, read_truths
    from fdi_sim.scoring import score_suite

    meta, truths = read_truths(args.export)
    if args.split != "all":
        truths = [t for t in truths if t.split == args.split]
    outs = read_scores(args.scores, truths, meta["suite_hash"], threshold=args.threshold)
    s = score_suite(truths, outs)
    d = {"suite": meta["suite"], "suite_hash": meta["suite_hash"], "split": args.split, "method": args.name, "scores": s}
    if args.json:
        print(json.dumps(d, default=_jsonable))
    else:
        print(format_scores({args.name: s}, f"{meta['suite']} / {args.split}: {len(truths)} cases"))
    return 0


def cmd_leaderboard(args: argparse.Namespace) -> int:
    from fdi_sim.bench.leaderboard import (
        leaderboard_html,
        leaderboard_markdown,
        leaderboard_rows,
    )

    rows = leaderboard_rows([Path(p) for p in args.results], args.split)
    md = leaderboard_markdown(rows)
    if args.out:
        p = Path(args.out)
        p.write_text(md + "\n")
        p.with_suffix(".html").write_text(leaderboard_html(rows))
        print(f"wrote {p} and {p.with_suffix('.html')}", file=sys.stderr)
    print(md)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from fdi_sim.bench.export import export

    o = export(args.results, args.out, progress=not args.quiet)
    print(f"export     {o.cases} cases ({o.skipped} interrupted or failed, left out), {o.topics} topics, {o.grid_rows} grid "
          f"rows, {o.bytes / 1e6:.1f} MB -> {o.out_dir}")
    return 0


def _f(x: Any, spec: str = ".3g") -> str:
    width = spec.split(".")[0]
    return "-".rjust(int(width) if width.isdigit() else 0) if x is None else format(x, spec)


def format_scores(scored: dict[str, dict[str, Any]], title: str) -> str:
    """A terminal table: one line per method."""
    lines = [title, (f"{'method':26} {'FA':>4} {'per h':>7} {'P(det)':>6} {'delay':>6} {'p95':>6} {'isol':>5} "
             f"{'ALFA P':>6} {'ALFA R':>6} {'t_ALFA':>6} {'evt F1':>6} {'AUROC':>6} {'AUPRC':>6}")]
    for m, s in scored.items():
        d, a, e, smp = s["detection"], s["alfa"], s["event"], s["sample"]
        lines.append(f"{m:26} {s['false_alarms']:4d} {_f(s['far_per_h'], '7.3f')} {_f(d['detected']['p'], '6.2f')} "
                     f"{_f(d['delay_s_median'], '6.2f')} {_f(d['delay_s_p95'], '6.2f')} {_f(d['isolation']['p'], '5.2f')} "
                     f"{_f(a['precision'], '6.2f')} {_f(a['recall'], '6.2f')} {_f(a['mean_detection_time_s'], '6.2f')} "
                     f"{_f(e['f1'], '6.2f')} {_f(smp['auroc'], '6.3f')} {_f(smp['auprc'], '6.3f')}")
    return "\n".join(lines)


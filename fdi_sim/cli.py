"""``fdi-sim``: run | detect | review | study | scenarios | plugins | info | verify | repair | linearize.

Exit codes: 0 success, 1 a run that diverged or was interrupted (or a log that `verify` finds
damaged), 2 bad input (one paragraph, no traceback).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any, Sequence

from fdi_sim import signals
from fdi_sim.errors import FdiSimError
from fdi_sim.threads import one_blas_thread


def _cmd_run(args: argparse.Namespace) -> int:
    from fdi_sim.scenario import load
    from fdi_sim.training import fly

    from fdi_sim.scenario.shipped import resolve

    sc = load(resolve(args.scenario))  # a path, or a shipped scenario's name
    if args.seed is not None:
        sc = sc.replace(seed=args.seed)
    if args.duration is not None:
        sc, dropped = sc.shortened(args.duration)
        if dropped:
            print(f"note: --duration {args.duration:g} s drops {dropped} maneuver/fault entries that start later",
                  file=sys.stderr)
    from fdi_sim.bank.members import bank_members

    bank_members(sc)  # an unknown or duplicate detector id is refused before anything flies
    res = fly(sc, args.out, log_path=args.log, progress=None if not args.quiet else False, force=args.force)
    print(res.summary.format())
    print(f"log        {res.log_path}")
    return 0 if res.status == "completed" else 1


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from fdi_sim.scenario.shipped import list_scenarios, list_studies, shipped_dir

    files = list_scenarios() + list_studies()
    # paths as the README writes them (scenarios/...) in a checkout whose scenarios/ is the shipped folder
    here = Path("scenarios")
    short = here.is_dir() and here.resolve() == shipped_dir().resolve()
    paths = [str(here / f.path.relative_to(shipped_dir()) if short else f.path) for f in files]
    wn = max([len("name"), *(len(f.name) for f in files)])
    wp = max([len("path"), *(len(p) for p in paths)])
    print(f"{'name':{wn}}  {'aircraft':8}  {'kind':8}  {'path':{wp}}  description")
    for f, path in zip(files, paths):
        print(f"{f.name:{wn}}  {f.aircraft:8}  {f.kind:8}  {path:{wp}}  {f.description}")
    return 0


def _cmd_plugins(args: argparse.Namespace) -> int:
    from fdi_sim import registry

    kind = None
    for spec in registry.all_plugins():
        if spec.kind != kind:
            kind = spec.kind
            print(f"[{kind}]")
        origin = "" if spec.origin == "fdi-sim" else f"  [plugin: {spec.origin}]"
        print(f"  {spec.id:26} {spec.summary}{origin}")
    broken = registry.broken_plugins()
    if broken:
        print("[refused plugins]")
        for b in broken:
            print(f"  {b.id:26} {b.kind} from {b.origin}: {b.reason}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from fdi_sim.flightlog import log_info

    if args.check:
        return _cmd_verify(args)
    print(log_info(args.log).format())
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from fdi_sim.flightlog import verify_log

    rep = verify_log(args.log)
    print(rep.format())
    return 0 if rep.ok else 1


def _cmd_repair(args: argparse.Namespace) -> int:
    from fdi_sim.flightlog import repair_log

    rep = repair_log(args.log, args.out)
    print(rep.format())
    return 0


def _cmd_detect(args: argparse.Namespace) -> int:
    from fdi_sim.detectors.spec import parse_detector_arg
    from fdi_sim.offline.detect import bank_specs, DEFAULT_RATE_HZ, detect_log, replay_bank, SCENARIO_BANK

    if args.bank in (SCENARIO_BANK, "default") and not args.detector:
        if args.out or args.rate_hz:
            from fdi_sim.errors import ScenarioError

            raise ScenarioError("--bank", args.bank, "an in-loop bank replays at its own rate into the report; --out "
                                "and --rate-hz do not apply", "leave them out, or give --detector for offline "
                                "detectors")
        rep, same = replay_bank(args.log, None if args.bank == SCENARIO_BANK else "default")
        if args.json:
            print(json.dumps({**json.loads(rep.to_json()), "identical_to_log": same}, indent=1))
        else:
            print(rep.format())
            for mid, ok in same.items():
                print(f"replay     {mid}: {'identical to' if ok else 'DIFFERS from'} the log's /fdi/{mid}/statistic")
        return 0 if all(same.values()) else 1  # a replay that differs from the in-loop topics
    specs = (bank_specs(args.bank) if args.bank else []) + [parse_detector_arg(d) for d in (args.detector or [])]
    rep, _ = detect_log(args.log, specs, rate_hz=args.rate_hz or DEFAULT_RATE_HZ, out=args.out)
    print(rep.to_json() if args.json else rep.format())
    return 0


def _cmd_review(args: argparse.Namespace) -> int:
    import time
    import webbrowser

    from fdi_sim.review.compare import compare_reviews
    from fdi_sim.review.figures import report_sections
    from fdi_sim.review.html_report import write_report
    from fdi_sim.review.run_review import open_log, review_flight_log

    paths = [args.log] + ([args.log2] if args.log2 else [])
    if len(paths) == 2 and Path(paths[0]).resolve() == Path(paths[1]).resolve():
        from fdi_sim.errors import ReviewError

        raise ReviewError(paths[1], "the same file as the first log", "give two different logs of one scenario")
    t0 = time.perf_counter()
    opened = [open_log(p) for p in paths]
    t1 = time.perf_counter()
    reviews = [review_flight_log(log, str(p), notes) for p, (log, notes) in zip(paths, opened)]
    logs = [log for log, _ in opened]
    comp = compare_reviews(reviews[0], reviews[1], tuple(logs)) if len(reviews) == 2 else None
    t2 = time.perf_counter()
    sections = report_sections(logs, ["A", "B"] if comp else [Path(paths[0]).stem])
    t3 = time.perf_counter()
    out = write_report(reviews, logs, args.out, sections=sections, changes=comp.scenario_changes if comp else ())
    t4 = time.perf_counter()
    if args.json:
        doc = comp.to_dict() if comp else reviews[0].to_dict()
        print(json.dumps({**doc, "report": str(out)}, indent=1))
    elif not args.quiet:
        print(comp.format() if comp else reviews[0].format())
    if not args.json:
        print(f"report       {out} ({out.stat().st_size / 1e6:.2f} MB)")
        print(f"took         {t4 - t0:.2f} s (read {t1 - t0:.2f}, metrics {t2 - t1:.2f}, figures {t3 - t2:.2f}, "
              f"write {t4 - t3:.2f})")
    if args.open:
        webbrowser.open(out.resolve().as_uri())
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fdi-sim", description="Aircraft fault detection and isolation testbed on JSBSim.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="fly a scenario file and write its MCAP log")
    r.add_argument("scenario", help="scenario TOML file")
    r.add_argument("--out", default="runs", help="output folder (default: runs)")
    r.add_argument("--log", default=None, help="exact log file path (overrides --out)")
    r.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    r.add_argument("--duration", type=float, default=None, help="override duration_s [s]")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--force", action="store_true", help="replace an existing --log file even if it is not an MCAP log")
    r.set_defaults(func=_cmd_run)
    s = sub.add_parser("scenarios", help="list the shipped scenarios")
    s.set_defaults(func=_cmd_scenarios)
    pl = sub.add_parser("plugins", help="list every registered plugin by id")
    pl.set_defaults(func=_cmd_plugins)
    i = sub.add_parser("info", help="summarize an MCAP log")
    i.add_argument("log")
    i.add_argument("--check", action="store_true", help="verify every CRC and index first (as `fdi-sim verify`)")
    i.set_defaults(func=_cmd_info)
    v = sub.add_parser("verify", help="check every CRC and index of a log; name what is damaged (exit 1 if so)")
    v.add_argument("log")
    v.set_defaults(func=_cmd_verify)
    d = sub.add_parser("detect", help="run registered detectors over a flight log (offline detection)")
    d.add_argument("log")
    d.add_argument("--detector", action="append", metavar="ID[:key=value,...]",
                   help="a registered detector id with design options (repeatable; `fdi-sim plugins`)")
    d.add_argument("--bank", default=None, help="'default': the default in-loop bank (docs/bank.md) replayed over the "
                   "log; 'scenario': the log's own in-loop bank, replayed and compared with its /fdi topics bit for "
                   "bit (exit 1 if they differ). With --detector, 'default' adds the offline detectors of "
                   "docs/detectors.md instead")
    d.add_argument("--rate-hz", type=float, default=None, help="detector rate [Hz], dividing the log's rate (default 20)")
    d.add_argument("--out", default=None, help="write the input's topics plus /fdi/... to this MCAP file")
    d.add_argument("--json", action="store_true", help="print the result as one JSON object")
    d.set_defaults(func=_cmd_detect)
    rv = sub.add_parser("review", help="review a run from its log (summary + self-contained HTML report); "
                        "two logs of one scenario: a comparison")
    rv.add_argument("log", help="MCAP log written by `fdi-sim run` (a cut-off one is read from a repaired copy)")
    rv.add_argument("log2", nargs="?", default=None, help="a second log of the same scenario: compare the two")
    rv.add_argument("--out", default=None, help="report path or folder (default: <stem>.review.html next to the "
                    "log; <stemA>_vs_<stemB>.review.html for two)")
    rv.add_argument("--open", action="store_true", help="open the report in the web browser")
    rv.add_argument("--json", action="store_true", help="print the review (or comparison) as JSON")
    rv.add_argument("--quiet", action="store_true", help="print only the report path and the time taken")
    rv.set_defaults(func=_cmd_review)
    rp = sub.add_parser("repair", help="rebuild a log cut off by a crash")
    rp.add_argument("log")
    rp.add_argument("--out", default=None, help="repaired file (default: <stem>.repaired.mcap)")
    rp.set_defaults(func=_cmd_repair)
    from fdi_sim.linear import cli as linear_cli  # light: imports its work when run

    linear_cli.add_parser(sub)
    from fdi_sim.study import cli as study_cli  # light: imports Dask when run

    study_cli.add_parser(sub)
    from fdi_sim.bench import cli as bench_cli  # light: imports Dask and pyarrow when run

    bench_cli.add_parser(sub)
    return p


def _stop(signum: int, _frame: object) -> None:
    # recorded first: the exception can be dropped (raised inside a weakref callback; fdi_sim.signals)
    signals.request(signals.REASONS[signum])
    raise KeyboardInterrupt  # SIGTERM ends a command like Ctrl-C (a run installs its own handler)


def _install_stop_handlers() -> dict[int, Any]:
    """SIGINT and SIGTERM -> :func:`_stop`; returns the handlers to restore (main thread only).

    A SIGINT that the process was started ignoring (a command run with ``&`` from a script) stays
    ignored: the Unix convention (a run's own handler still catches it during the flight).
    """
    if threading.current_thread() is not threading.main_thread():
        return {}
    before = {s: signal.getsignal(s) for s in signals.REASONS}
    for s in signals.REASONS:
        if not (s == signal.SIGINT and before[s] == signal.SIG_IGN):
            signal.signal(s, _stop)
    return before


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit code (0 ok, 1 diverged/interrupted/damaged, 2 bad input)."""
    signals.clear()  # a new command (main() is also called in-process, by tests and scripts)
    before = _install_stop_handlers()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        try:
            with one_blas_thread():  # designs equal to a study worker's, bit for bit (fdi_sim.threads)
                return int(args.func(args) or 0)
        except FdiSimError as exc:
            print(f"fdi-sim {args.command}: {exc}", file=sys.stderr)
            return 2
        except BrokenPipeError:
            return 0
    except KeyboardInterrupt as exc:  # before a run's flight (imports, trim) or in any other command
        return _interrupted(str(exc))
    except ImportError:
        if not signals.stop_requested():
            raise
        # the signal landed while a compiled module initialized, and its init turned the
        # KeyboardInterrupt into "ImportError: initialization failed" (measured: SIGTERM in scipy.fft's
        # pypocketfft, a fresh-clone make test under load): an interruption all the same
        return _interrupted("")
    finally:
        for s, h in before.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


#: set when main() caught a KeyboardInterrupt (see :func:`entry`)
_INTERRUPTED = False


def _interrupted(message: str) -> int:
    """Report an interruption before a run's flight: exit 1, no traceback (:func:`entry`)."""
    global _INTERRUPTED
    _INTERRUPTED = True
    print(f"fdi-sim: {message or 'interrupted'}", file=sys.stderr)
    return 1


def entry() -> None:
    """The ``fdi-sim`` console script: ``sys.exit(main())``, with one exception.

    A Ctrl-C that lands inside an extension module's import is remembered by CPython itself
    (``_PyRuntime.signals.unhandled_keyboard_interrupt``, set when code run through
    ``PyRun_*`` ends in KeyboardInterrupt) even after :func:`main` caught it, and the process
    then kills itself with SIGINT (exit -2) instead of exiting 1: seen in 3 of 16 runs
    interrupted 0.2-1.0 s after the start. After a caught interrupt, with the output flushed
    and nothing left to close (a run that had not started writes no log), exit directly.
    """
    rc = main()
    if _INTERRUPTED:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)
    sys.exit(rc)


if __name__ == "__main__":
    entry()

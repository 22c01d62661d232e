"""``fdi-sim linearize AIRCRAFT [--grid SPEC|FILE] [--out DIR] ...``: trim, linearize, validate, report.

Writes ``<out>/<aircraft>_schedule.npz`` (the model schedule), ``<out>/<aircraft>_linearize.md``
(the report) and ``<out>/<aircraft>_poles.png`` (the pole map). Bad input (unknown aircraft,
a grid point outside the envelope, an unreadable grid) exits with 2 and one paragraph, no
traceback. Untrimmable points are not errors: they are listed in the report with the reason.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from fdi_sim.errors import FdiSimError


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``linearize`` on the main parser's subparsers."""
    p = subparsers.add_parser(
        "linearize", help="trim a grid of operating points, linearize, validate, write a model schedule",
        description="Trim every point of a grid, linearize it (central differences about the trim, "
                    "FGLinearization cross-check for the F-16), validate against JSBSim with small doublets and "
                    "write a model schedule (.npz), a report (.md) and a pole map (.png).")
    p.add_argument("aircraft", help="f16 or DHC6")
    p.add_argument("--grid", default=None,
                   help="grid file (TOML) or spec 'h_ft=5000,10000;vt_kts=350:430:20[;flaps_deg=0,10][;icing_eta=0]' "
                        "(default: aircraft/<aircraft>/grid.toml)")
    p.add_argument("--out", default="runs/linearize", help="output folder (default: runs/linearize)")
    p.add_argument("--no-validate", action="store_true", help="skip the doublet validation (faster)")
    p.add_argument("--no-fglin", action="store_true", help="skip the FGLinearization cross-check")
    p.add_argument("--duration", type=float, default=None, help="validation run length [s] (default: grid file, 10)")
    p.add_argument("--quiet", action="store_true", help="no per-point progress")
    p.set_defaults(func=run)
    return p


def _fail(msg: str) -> int:
    print(f"fdi-sim linearize: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    """Run the command; 0 on success, 2 on bad input."""
    from fdi_sim.aircraft.model import AIRCRAFT  # here, not at import: every fdi-sim command builds this parser

    name = {k.lower(): k for k in AIRCRAFT}.get(str(args.aircraft).lower())
    if name is None:
        return _fail(f"unknown aircraft {args.aircraft!r}; known: {', '.join(AIRCRAFT)}.")
    if args.duration is not None and not args.duration > 0:
        return _fail(f"--duration {args.duration} must be positive (seconds of each validation run).")
    try:
        from fdi_sim.linear.grid import resolve_grid
        from fdi_sim.linear.linearize import linearize_grid
        from fdi_sim.linear.report import BAR, bar_entry, bar_method, format_report, method_label, worst_validation
        from fdi_sim.linear.validate import NRMSE_BAR

        grid = resolve_grid(args.grid, name)
        if args.duration is not None:
            grid = replace(grid, validation=replace(grid.validation, duration_s=args.duration))
        n = len(grid.points)
        print(f"linearizing {n} {name} points from {grid.source}", flush=True)
        t0 = time.perf_counter()

        def progress(i: int, total: int, pt: Any) -> None:
            if args.quiet:
                return
            v = bar_entry(pt, "step") or bar_entry(pt, "zoh") if pt.status == "ok" else None
            extra = f"bar: worst {v['worst_output']} {v['worst']:.1%}" if v else pt.reason
            per_point_s = (time.perf_counter() - t0) / i
            print(f"  [{i:3d}/{total}] {pt.op.label():42s} {pt.status:12s} {extra}  "
                  f"({per_point_s:.2f} s/point, ETA {per_point_s * (total - i):.0f} s)", flush=True)

        schedule = linearize_grid(grid, validate=not args.no_validate, check_fglin=False if args.no_fglin else None,
                                  progress=progress)
        out = Path(args.out)
        path = schedule.save(out / f"{name}_schedule.npz")
        fig = None
        if schedule.ok_points:
            from fdi_sim.review.linear_figures import pole_map

            fig = pole_map(schedule, out / f"{name}_poles.png")
        report = out / f"{name}_linearize.md"
        report.write_text(format_report(schedule, fig.name if fig else None))
    except FdiSimError as exc:
        return _fail(str(exc))
    except OSError as exc:
        return _fail(f"cannot write to {args.out}: {exc}")
    ok = len(schedule.ok_points)
    print(f"{ok}/{n} points linearized in {time.perf_counter() - t0:.1f} s "
          f"({n - ok} without a model; reasons in the report)")
    for meth in schedule.meta.get("validation", {}).get("methods", []):
        w = worst_validation(schedule, meth)
        if w:
            print(f"validation ({meth}, configured doublets): worst {w[1]} {w[2]:.1%} at {w[0]}")
    w = worst_validation(schedule, BAR)
    if w:
        n_pass = sum(bool((bar_entry(p, bar_method(schedule)) or {}).get("passed")) for p in schedule.ok_points)
        print(f"bar ({method_label(BAR, schedule)}): {n_pass}/{ok} points below {NRMSE_BAR * 100:g} %; worst {w[1]} {w[2]:.1%} at {w[0]}")
    print(f"schedule   {path}\nreport     {report}" + (f"\npole map   {fig}" if fig else ""))
    return 0

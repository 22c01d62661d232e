"""Time to linearize the default F-16 grid, with bare JSBSim steps in the same run for scale.

Plain script (not collected by pytest): ``.venv/bin/python tests/benchmarks/bench_linearize.py [--validate]``.

Prints, for the default grid (``aircraft/f16/grid.toml``):

1. bare ``FGFDMExec.run()`` cost per step on the trimmed F-16 (the unit of every speed bar),
2. the grid linearized by central differences only (trim + 35 evaluations per point: the centre
   and two per state, command and gust; ``fd`` also holds the pass-by-pass Jacobians of the step
   model, about 60 run_ic and 100 tiny passes per point),
3. the same with the FGLinearization cross-check (what ``fdi-sim linearize f16`` does by default),
4. with ``--validate`` also the 8 x 10 s doublet runs per point.

Wall-clock times on a shared machine: run twice and read the smaller numbers.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.linear.grid import default_grid_path, load_grid
from fdi_sim.linear.linearize import linearize_grid


def bare_steps_us(n: int = 20000) -> float:
    """Microseconds per bare JSBSim step of the trimmed F-16."""
    ac = Aircraft("f16")
    grid = load_grid(default_grid_path("f16"), "f16")
    trim(ac, grid.points[0])
    run = ac.fdm.run
    t0 = time.perf_counter()
    for _ in range(n):
        run()
    return (time.perf_counter() - t0) / n * 1e6


def timed_grid(validate: bool, check_fglin: bool) -> tuple[float, dict[str, float], int]:
    grid = load_grid(default_grid_path("f16"), "f16")
    t0 = time.perf_counter()
    s = linearize_grid(grid, validate=validate, check_fglin=check_fglin)
    wall = time.perf_counter() - t0
    parts: dict[str, float] = {}
    for p in s.ok_points:
        for k, v in p.info.get("timing_s", {}).items():
            parts[k] = parts.get(k, 0.0) + v
    return wall, parts, len(s.ok_points)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--validate", action="store_true", help="also time the doublet validation")
    args = ap.parse_args()
    us = bare_steps_us()
    print(f"bare JSBSim f16 step: {us:.1f} us ({1e6 / us:,.0f} steps/s)")
    cases = [("central differences only", False, False), ("+ FGLinearization check", False, True)]
    if args.validate:
        cases.append(("+ FGLinearization + validation", True, True))
    for label, val, fg in cases:
        wall, parts, n = timed_grid(val, fg)
        detail = ", ".join(f"{k} {v:.2f} s" for k, v in sorted(parts.items()))
        print(f"default f16 grid ({n} points), {label}: {wall:.2f} s = {wall / n * 1e3:.0f} ms/point "
              f"= {wall / (us * 1e-6):,.0f} bare steps ({detail})")
    print(f"numpy {np.__version__}")


if __name__ == "__main__":
    main()

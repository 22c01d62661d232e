"""Benchmark (on demand: `python tests/benchmarks/bench_bank.py`): the loop with the default FDI bank.

Issue 13's goal: the full loop with the default bank at >= 0.4 of bare JSBSim's step rate on both
aircraft, measured in the same process, with the log as `fdi-sim run` writes it (every 120 Hz
topic), with FDI topics only (``[log] per_step = false``), and as a Monte Carlo run writes it
(``study``: FDI topics without the residuals, what ``fdi_sim.study.spec`` gives a study's runs). Bare
JSBSim here is what bench_loop.py measures: one command write and one ``fly()`` per step, trimmed,
moderate turbulence. The bank's designs and thresholds come from the cache (the first run
calibrates). Then a profile of one full-log run: where the wall time of the loop goes. Never a
timed assertion in the suite.

The last row per aircraft is a bank of every registered detector (issue 23's cost of the whole
registry in the loop), as a study logs it. ``--study-only`` measures the study-mode rows only
(the default bank and every detector): ``python tests/benchmarks/bench_bank.py 300 --study-only``.
"""
from __future__ import annotations

import cProfile
import io
import pstats
import sys
import tempfile
import time

from fdi_sim.scenario import loads
from fdi_sim.training import fly

from bench_loop import bare_rate  # the same bare JSBSim loop as bench_loop measures

SC = """
name = "bench_bank_{ac}"
aircraft = "{ac}"
duration_s = {T}
seed = 1
[initial]
h_ft = {h}
{speed}
[atmosphere]
turbulence = "moderate"
[fdi]
bank = "{bank}"
block_s = {block_s}
log_residuals = {resid}
[log]
per_step = {per_step}
"""
CASES = {"f16": (10000.0, "vt_kts = 400.0"), "DHC6": (5000.0, "vc_kts = 120.0")}


def scenario(ac: str, T: float, bank: str, per_step: bool, block_s: float = 0.5, residuals: bool = True,
             detectors: tuple[str, ...] | None = None):
    """``bank = "every"``: a bank of every registered detector, or of ``detectors`` only (thresholds
    trained on four 60 s flights: only the cost is measured here)."""
    from fdi_sim import registry

    h, speed = CASES[ac]
    text = SC.format(ac=ac, T=T, h=h, speed=speed, bank="none" if bank == "every" else bank,
                     per_step=str(per_step).lower(), block_s=block_s, resid=str(residuals).lower())
    if bank == "every":
        text = text.replace("[fdi]\n", "[fdi]\ncalibration_flights = 4\ncalibration_duration_s = 60.0\non_design_failure = \"skip\"\n"
                            'thresholds = "trained"\n')
        ids = registry.ids("detector") if detectors is None else detectors
        text += "".join(f'\n[[detectors]]\ntype = "{i}"\n' for i in ids)
    return loads(text)


def loop_rate(sc, d: str) -> float:
    res = fly(sc, d, progress=False, force=True)
    return res.summary.steps / res.summary.wall_s


def best_rates(ac: str, sc, d: str, T: float, repeats: int) -> tuple[float, float]:
    """(bare JSBSim, the loop flying ``sc``) steps per second, best of ``repeats`` each, interleaved so
    that machine load hits both alike (the designs must be in the cache already)."""
    bare, loop = [], []
    for _ in range(repeats):
        bare.append(bare_rate(ac, sc, T))
        loop.append(loop_rate(sc, d))
    return max(bare), max(loop)


def main(T: float = 120.0, repeats: int = 3) -> None:
    print(f"{'aircraft':8} {'log':10} {'bank':8} {'block s':>7} {'bare steps/s':>13} {'loop steps/s':>13} {'ratio':>6} "
          f"{'overhead us/step':>17}")
    with tempfile.TemporaryDirectory() as d:
        for ac in CASES:
            # the last: as a Monte Carlo study logs (fdi_sim.study.spec: FDI topics, no residuals)
            cases = (("none", True, 0.5, True), ("default", True, 0.5, True), ("none", False, 0.5, True),
                     ("default", False, 0.5, True), ("default", False, 1.0, True), ("default", False, 0.5, False),
                     ("every", False, 0.5, False))
            if "--study-only" in sys.argv:  # the study-mode rows only: the default bank and every detector
                cases = tuple(c for c in cases if c[1] is False and c[3] is False)
            for bank, per_step, block, resid in cases:
                sc = scenario(ac, T, bank, per_step, block, resid)
                fly(scenario(ac, 2.0, bank, per_step, block, resid), d, progress=False, force=True)  # designs, compile
                b, lp = best_rates(ac, sc, d, T, repeats)
                log = "full" if per_step else ("fdi only" if resid else "study")
                print(f"{ac:8} {log:10} {bank:8} {block:7g} {b:13.0f} {lp:13.0f} {lp / b:6.2f} "
                      f"{1e6 / lp - 1e6 / b:17.1f}", flush=True)
        for ac in CASES if "--study-only" not in sys.argv else ():
            sc = scenario(ac, T, "default", True)
            prof = cProfile.Profile()
            prof.enable()
            fly(sc, d, progress=False, force=True)
            prof.disable()
            s = io.StringIO()
            pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(14)
            print(f"\n--- profile, {ac}, default bank, full log ({T:g} s): functions by own time ---")
            print("\n".join(line for line in s.getvalue().splitlines()[6:] if line.strip()))


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(float(args[0]) if args else 120.0)

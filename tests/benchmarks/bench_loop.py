"""Benchmark (run on demand: `make bench` or `python tests/benchmarks/bench_loop.py`).

Bare JSBSim steps per second against the full fdi-sim loop (sensors, pilot, divergence checks,
MCAP logging) in the same process, both aircraft, trimmed, moderate turbulence. Reports the
ratio loop/bare (the bar is >= 0.5) and the loop's own cost per step. Never a timed assertion in
the test suite. The loop's time includes the run's set-up (load, trim, log open/close).
"""
from __future__ import annotations

import tempfile
import time

from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from fdi_sim.scenario import loads
from fdi_sim.sim import run

SC = """
name = "bench_{ac}"
aircraft = "{ac}"
duration_s = {T}
seed = 1
[initial]
h_ft = {h}
{speed}
[atmosphere]
turbulence = "moderate"
"""
CASES = {"f16": (10000.0, "vt_kts = 400.0"), "DHC6": (5000.0, "vc_kts = 120.0")}


def bare_rate(ac_name: str, sc, T: float) -> float:
    ac = Aircraft(ac_name, sc.dt_s)
    trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 1)
    write = ac.command_writer()
    n = int(T / sc.dt_s)
    t0 = time.perf_counter()
    for _ in range(n):
        write(0.0, 0.0, 0.0, 0.3)  # the same command writes the loop does, nothing else
        ac.step()
    return n / (time.perf_counter() - t0)


def main(T: float = 120.0, repeats: int = 3) -> None:
    # overhead: what the loop adds to a JSBSim step (1/loop - 1/bare) [us/step]; less sensitive
    # than the ratio to how fast JSBSim itself runs on a loaded machine
    print(f"{'aircraft':8} {'bare steps/s':>13} {'loop steps/s':>13} {'ratio':>6} {'overhead us/step':>17}")
    for ac, (h, speed) in CASES.items():
        sc = loads(SC.format(ac=ac, T=T, h=h, speed=speed))
        bare, loop = [], []
        with tempfile.TemporaryDirectory() as d:
            for _ in range(repeats):  # interleaved so machine load hits both alike
                bare.append(bare_rate(ac, sc, T))
                res = run(sc, d, progress=False)
                loop.append(res.summary.steps / res.summary.wall_s)
        b, lp = max(bare), max(loop)
        print(f"{ac:8} {b:13.0f} {lp:13.0f} {lp / b:6.2f} {1e6 / lp - 1e6 / b:17.1f}")


def test_bench_loop() -> None:  # collected by `make bench` only (benchmarks/ is not in the default run)
    main(T=60.0, repeats=2)


if __name__ == "__main__":
    main()

"""Benchmark (on demand: `python tests/benchmarks/bench_split.py [duration_s] [repeats]`): where a
study-mode step goes.

Issues 13 and 14: the loop as a Monte Carlo study flies it (``check_study_logs.study_text``: the
default bank, no residuals, no per-step topics), both aircraft, against bare JSBSim in the same
process (``bench_loop.bare_rate``: the command writes and ``FGFDMExec.run`` only), interleaved,
best of ``repeats``. The same flight without the bank gives the bank's share (its blocks and its
statistics log); the per-step pieces of the fast path are timed alone on a trimmed aircraft
(calls of the live objects, a loop of 20,000, best of 3); ``rest`` is what the loop costs beyond
their sum (the loop's own lines, the divergence checks and statistics, and the pieces' extra cost
in the loop, where JSBSim's step has evicted their data from the caches). Everything is CPU time
of the process (``time.process_time``; the loop's per step from a ``T`` and a 60 s flight, so the
set-up cancels): on the shared machine wall time moves with the load by a factor of two. Run it on
another tree with ``PYTHONPATH=<tree>`` (the pieces use public calls only). Never a timed assertion in the suite.
"""
from __future__ import annotations

import math
import os
import sys
import tempfile
import time

import numpy as np
from check_study_logs import SCENARIOS, study_text

from fdi_sim import scenario
from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.sim.run import build_pilot, build_sensors

try:
    from fdi_sim.training import fly
except ImportError:  # a tree from before fdi_sim.training (bench_ab.py times an older commit's tree)
    from fdi_sim.sim import run as fly

N_CALLS = 20000


def _study_scenario(name: str, T: float, bank: bool = True):
    text = study_text(SCENARIOS / f"{name}.toml")
    text = text.replace(f"duration_s = {scenario.load(SCENARIOS / f'{name}.toml').duration_s}", f"duration_s = {T}", 1)
    if not bank:
        text = text.replace('bank = "default"', 'bank = "none"')
    return scenario.loads(text, source=str(SCENARIOS / f"{name}.toml"))


def _best_us(fn) -> float:
    best = math.inf
    for _ in range(3):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best / N_CALLS * 1e6


def pieces(sc) -> dict[str, float]:
    """Per-call cost [us] of the fast path's per-step pieces on a trimmed aircraft."""
    ac = Aircraft(sc.aircraft, sc.dt_s)
    tr = trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 1)
    sensors = build_sensors(sc, sc.dt_s)
    sensors.reset(np.random.default_rng(1))
    pilot = build_pilot(sc, tr, sensors.names)
    names = truth_signals(sc.aircraft)
    read, write = ac.list_reader(names), ac.command_writer()
    h_agl = ac.node("position/h-agl-ft").get_double_value
    x, y, u = np.empty(len(names)), np.empty(len(sensors.names)), np.empty(9)
    xl = read()
    x[:] = xl
    dt = sc.dt_s

    def f_read():
        for _ in range(N_CALLS):
            read()
            h_agl()

    def f_copy():
        for _ in range(N_CALLS):
            x[:] = xl

    def f_sensors():
        for k in range(N_CALLS):
            sensors.measure_into(k * dt, x, y)

    def f_pilot():
        for k in range(N_CALLS):
            pilot.step_into(k * dt, y, u)

    def f_write():
        for _ in range(N_CALLS):
            el, ai, ru, th, _, _, _, _, _ = u.tolist()
            write(el, ai, ru, th)

    return {"truth read (29 props + h_agl)": _best_us(f_read), "truth list -> array": _best_us(f_copy),
            "sensors (measure_into)": _best_us(f_sensors), "pilot (step_into)": _best_us(f_pilot),
            "commands (tolist + 4 writes)": _best_us(f_write)}


def _bare_us(sc, T: float) -> float:
    """``bench_loop.bare_rate`` in CPU time [us/step]."""
    ac = Aircraft(sc.aircraft, sc.dt_s)
    trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 1)
    write, n = ac.command_writer(), int(T / sc.dt_s)
    t0 = time.process_time()
    for _ in range(n):
        write(0.0, 0.0, 0.0, 0.3)
        ac.step()
    return 1e6 * (time.process_time() - t0) / n


def _loop_us(sc, short, d: str) -> float:
    """The loop's CPU time per step [us]: a long and a short flight, the set-up cancels."""
    c, n = [], []
    for s in (sc, short):
        t0 = time.process_time()
        r = fly(s, d, progress=False).summary
        c.append(time.process_time() - t0)
        n.append(r.steps)
    return 1e6 * (c[0] - c[1]) / (n[0] - n[1])


def main(T: float = 600.0, repeats: int = 3) -> None:
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} (2 cores)")
    for name in ("f16_cruise_doublets", "dhc6_cruise_doublets"):
        sc, sc_nobank = _study_scenario(name, T), _study_scenario(name, T, bank=False)
        bare, loop, nobank = [], [], []
        short, short_nobank = _study_scenario(name, 60.0), _study_scenario(name, 60.0, bank=False)
        with tempfile.TemporaryDirectory() as d:
            fly(short, d, progress=False)  # the design cached, the kernels loaded
            for _ in range(repeats):  # interleaved so machine load hits all alike
                bare.append(_bare_us(sc, min(T, 120.0)))
                loop.append(_loop_us(sc, short, d))
                nobank.append(_loop_us(sc_nobank, short_nobank, d))
        b, lp, nb = min(bare), min(loop), min(nobank)
        parts = {"JSBSim step (bare: writes + run)": b, **pieces(sc), "bank (blocks + statistics log)": lp - nb}
        parts["rest (loop lines, checks, statistics)"] = lp - sum(parts.values())
        print(f"\n{name} ({sc.aircraft}), study mode, {T:g} s, best of {repeats}: loop {lp:.1f} us/step = "
              f"{b / lp:.2f} of bare ({b:.1f} us/step, {1e6 / b / 120:.0f} x real time); without the bank "
              f"{nb:.1f} us/step = {b / nb:.2f} of bare")
        for k, v in parts.items():
            print(f"  {k:40} {v:6.2f} us/step  {v / b:5.2f} x bare")
    print(f"\nload average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main(*(float(sys.argv[1]),) if len(sys.argv) > 1 else (), *(int(sys.argv[2]),) if len(sys.argv) > 2 else ())

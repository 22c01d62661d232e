"""Benchmark (run on demand: `make bench` or `python tests/benchmarks/bench_loop.py`).

Bare JSBSim steps per second against the full fdi-sim loop (sensors, pilot, divergence checks,
MCAP logging) in the same process, both aircraft, trimmed, moderate turbulence. Reports the
ratio loop/bare (the bar is >= 0.5) and the loop's own cost per step. Never a timed assertion in
the test suite. The loop's time includes the run's set-up (load, trim, log open/close).

Then the per-step components on realistic inputs: a closed-loop flight of
``scenarios/<aircraft>_cruise_doublets.toml`` is recorded (the truth the sensors saw, the
measurements the pilot saw), and each implementation replays the whole flight from a reset,
interleaved, best of ``repeats``, minus the cost of the bare replay loop [us per call]: the Python
implementations of commit d97be8c (the test oracles ``tests/pilot/_reference_pilot.py`` and
``tests/sensors/_reference_sensors.py``), the compiled ones behind the list entry points
(``Pilot.step``, ``SensorSuite.step_list``) and the array entry points (``Pilot.step_into``,
``SensorSuite.measure_into``). Last, the first call of the compiled kernels in a fresh process,
with a cold numba cache (compiling) and a warm one (loading).
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.scenario import load, loads
from fdi_sim.training import fly

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
TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent


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


def _module(path: Path):
    """A test helper module by its path (the benchmarks are not a package)."""
    if path.stem in sys.modules:
        return sys.modules[path.stem]
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = mod
    spec.loader.exec_module(mod)
    return mod


def _per_call_us(calls: dict[str, tuple], repeats: int) -> dict[str, float]:
    """Best time per call [us] of each ``name: (reset, fn, inputs)``, interleaved over ``repeats``."""
    best = {name: np.inf for name in calls}
    for _ in range(repeats):
        for name, (reset, fn, inputs) in calls.items():
            reset()
            t0 = time.perf_counter()
            for args in inputs:
                fn(*args)
            best[name] = min(best[name], time.perf_counter() - t0)
    inputs = next(iter(calls.values()))[2]
    empty = np.inf
    for _ in range(repeats):  # the replay loop alone (iterating the inputs)
        t0 = time.perf_counter()
        for args in inputs:
            pass
        empty = min(empty, time.perf_counter() - t0)
    return {name: (b - empty) / len(inputs) * 1e6 for name, b in best.items()}


def components(aircraft: str, repeats: int = 7) -> dict[str, float]:
    """Per-call cost [us] of the pilot and the sensors, Python (d97be8c) and compiled, on a real flight."""
    flights = _module(TESTS / "pilot" / "_flights.py")
    ref_pilot = _module(TESTS / "pilot" / "_reference_pilot.py").ReferencePilot
    ref_suite = _module(TESTS / "sensors" / "_reference_sensors.py").ReferenceSuite
    from fdi_sim import registry
    from fdi_sim.sim.run import build_pilot, build_sensors

    f = flights.fly(load(REPO / "scenarios" / f"{aircraft.lower()}_cruise_doublets.toml"))
    sc, dt = f.sc, f.sc.dt_s
    suite = build_sensors(sc, dt)
    suite_py = ref_suite(suite.specs, truth_signals(sc.aircraft), dt)
    pilot = build_pilot(sc, f.tr, suite.names)
    pilot_py = ref_pilot(pilot.g, pilot.modes, pilot.trim,
                         [registry.get("maneuver", tid).factory(p) for tid, p in sc.maneuvers], suite.names, dt)
    t = f.t_s.tolist()
    x_list, y_list = list(zip(t, f.truth.tolist())), list(zip(t, f.pilot_in.tolist()))
    out_y, out_c = np.zeros(len(suite.names)), np.zeros(8)
    x_arr = [(ti, xi, out_y) for ti, xi in zip(t, f.truth)]
    y_arr = [(ti, yi, out_c) for ti, yi in zip(t, f.pilot_in)]

    def seeded(s):
        return lambda: s.reset(np.random.default_rng(f.sensor_seed))

    pilot_us = _per_call_us({"python (d97be8c) step": (pilot_py.reset, pilot_py.step, y_list),
                             "compiled step (list)": (pilot.reset, pilot.step, y_list),
                             "compiled step_into (array)": (pilot.reset, pilot.step_into, y_arr)}, repeats)
    sensor_us = _per_call_us({"python (d97be8c) step_list": (seeded(suite_py), suite_py.step_list, x_list),
                              "compiled step_list (list)": (seeded(suite), suite.step_list, x_list),
                              "compiled measure_into (array)": (seeded(suite), suite.measure_into, x_arr)}, repeats)
    return {**{f"pilot    {k}": v for k, v in pilot_us.items()}, **{f"sensors  {k}": v for k, v in sensor_us.items()}}


FIRST_CALL = """
import time
import numpy as np
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint
from fdi_sim.sensors import SensorSuite, load_suite
import scipy.linalg  # imported by any run (the trim); numba's first call imports it otherwise
names = truth_signals("DHC6")
s = SensorSuite(load_suite("DHC6"), names, 1 / 120)
p = Pilot(AutopilotGains.for_aircraft("DHC6"), AutopilotModes(),
          TrimPoint(0.0, 0.0, -0.07, 0.8, 0.05, 0.0, 0.0, 5000.0, 120.0), [], s.names, 1 / 120)
y, out = np.zeros(len(s.names)), np.zeros(8)
t0 = time.perf_counter()
s.measure_into(0.0, np.zeros(len(names)), y)
t1 = time.perf_counter()
p.step_into(0.0, y, out)
print(t1 - t0, time.perf_counter() - t1)
"""


def first_call_s() -> dict[str, tuple[float, float]]:
    """First-call time [s] of the sensor and pilot kernels in a fresh process, cold and warm cache."""
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=d)  # a cache of its own: the cold run really compiles
        out = {}
        for label in ("cold cache (compile)", "warm cache (load)"):
            r = subprocess.run([sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, env=env,
                               cwd=REPO, check=True)
            s_s, p_s = (float(v) for v in r.stdout.split())
            out[label] = (s_s, p_s)
    return out


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
                res = fly(sc, d, progress=False)
                loop.append(res.summary.steps / res.summary.wall_s)
        b, lp = max(bare), max(loop)
        print(f"{ac:8} {b:13.0f} {lp:13.0f} {lp / b:6.2f} {1e6 / lp - 1e6 / b:17.1f}")
    print()
    print("per call on a recorded cruise_doublets flight [us] (best of the replays, replay loop subtracted)")
    rows = {ac: components(ac) for ac in CASES}
    print(f"{'component':42}" + "".join(f"{ac:>8}" for ac in rows))
    for name in rows["f16"]:
        print(f"{name:42}" + "".join(f"{rows[ac][name]:8.2f}" for ac in rows))
    print()
    print("first call of the compiled kernels in a fresh process [s]   sensors   pilot")
    for label, (s_s, p_s) in first_call_s().items():
        print(f"  {label:56} {s_s:7.2f} {p_s:7.2f}")


def test_bench_loop() -> None:  # collected by `make bench` only (benchmarks/ is not in the default run)
    main(T=60.0, repeats=2)


if __name__ == "__main__":
    main()

"""Benchmark (on demand: `python tests/benchmarks/bench_floor.py`): the ceiling a loop driven from
Python can reach, against bare JSBSim in the same process.

Issue 14's throughput goal (1,000 flight hours of a fault-free F-16 study per wall-clock hour on 2
cores) needs the loop at about 0.89 of bare JSBSim on this machine (bare: about 560 flight h per
hour per core). The loop's JSBSim traffic alone, with nothing computed, is measured here: bare
steps (the four command writes and ``run()``), then the same steps with the loop's flat read of the
truth properties packed into its buffer (``run._loop``: one ``map`` of the node getter and one
``struct.pack_into``). Whatever the loop computes comes on top of the second figure, so its ratio
to the first is the ceiling of any loop that reads JSBSim through the Python binding (the binding
has no bulk read and no C API: ``jsbsim._jsbsim`` exports no ``__pyx_capi__``).
"""
from __future__ import annotations

import ctypes
import struct
import sys
import time

from bench_loop import CASES, SC

from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.scenario import loads


def floor(ac_name: str, n: int = 6000, repeats: int = 8) -> dict[str, float]:
    """Best time per step [us] of bare steps and of steps with the truth read, interleaved."""
    h, speed = CASES[ac_name]
    sc = loads(SC.format(ac=ac_name, T=60.0, h=h, speed=speed))
    ac = Aircraft(ac_name, sc.dt_s)
    trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 1)
    write, step = ac.command_writer(), ac.stepper()
    names = truth_signals(ac_name)
    read_flat, _ = ac.flat_reader(names, extra=("position/h-agl-ft",))
    n_flat = len(read_flat())
    buf = (ctypes.c_double * (len(names) + n_flat))()
    pack, at = struct.Struct(f"{n_flat}d").pack_into, 8 * len(names)

    def bare() -> None:
        for _ in range(n):
            write(0.0, 0.0, 0.0, 0.3)
            step()

    def reads() -> None:
        for _ in range(n):
            pack(buf, at, *read_flat())
            write(0.0, 0.0, 0.0, 0.3)
            step()

    best = {"bare": float("inf"), "reads": float("inf")}
    for _ in range(repeats):
        for name, fn in (("bare", bare), ("reads", reads)):
            t0 = time.perf_counter()
            fn()
            best[name] = min(best[name], (time.perf_counter() - t0) / n * 1e6)
    return {"flat_reads": float(n_flat), "bare_us": best["bare"], "reads_us": best["reads"],
            "ceiling": best["bare"] / best["reads"], "dt_s": sc.dt_s}


def main() -> None:
    for ac_name in CASES:
        f = floor(ac_name)
        per_core = 1.0 / (f["bare_us"] * 1e-6) * f["dt_s"]  # flight s per wall s = flight h per wall h
        print(f"{ac_name:5}: bare {f['bare_us']:.2f} us/step ({per_core:.0f} flight h per hour per core), with "
              f"the truth's {f['flat_reads']:.0f} property reads {f['reads_us']:.2f} us/step: ceiling "
              f"{f['ceiling']:.3f} of bare = {2 * per_core * f['ceiling']:.0f} flight h per hour on 2 cores "
              "with nothing else computed and perfect scaling")


if __name__ == "__main__":
    sys.exit(main())

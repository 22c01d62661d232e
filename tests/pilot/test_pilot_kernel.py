"""The compiled pilot (step and step_into) against the Python pilot it replaced, bit for bit.

The oracle is ``_reference_pilot.ReferencePilot``, the Python ``Pilot`` of commit d97be8c, whose
floats the logs hold. Inputs are real closed-loop flights (``_flights``): both aircraft, every
maneuver kind (doublet, 3-2-1-1 and pulse on all four axes, altitude and airspeed ramps, heading
changes, a turn with a heading change inside it), sensor faults (a dropout, a stuck vane), a stuck
elevator that drives the commands to their stops, and holds partly or all off.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba.core.caching import FunctionCache

import _flights
from _reference_pilot import ReferencePilot
from fdi_sim import registry
from fdi_sim.aircraft import TRUTH_SIGNALS
from fdi_sim.pilot import _kernels as K
from fdi_sim.pilot import maneuvers as m
from fdi_sim.pilot.autopilot import NEEDED, AutopilotGains, AutopilotModes, Pilot, TrimPoint
from fdi_sim.sim.run import build_pilot, build_sensors

REPO = Path(__file__).resolve().parents[2]


def _pilots(f: _flights.Flight) -> tuple[ReferencePilot, Pilot, Pilot]:
    """The Python pilot and two compiled ones, built as the run builds its pilot."""
    names = build_sensors(f.sc, f.sc.dt_s).names
    new_a, new_b = build_pilot(f.sc, f.tr, names), build_pilot(f.sc, f.tr, names)
    maneuvers = [registry.get("maneuver", tid).factory(p) for tid, p in f.sc.maneuvers]  # as build_pilot does
    ref = ReferencePilot(new_a.g, new_a.modes, new_a.trim, maneuvers, names, f.sc.dt_s)
    return ref, new_a, new_b


@pytest.mark.parametrize("name", list(_flights.FLIGHTS))
def test_step_and_step_into_equal_the_python_pilot_on_a_real_flight(name: str) -> None:
    f = _flights.flight(name)
    ref, by_list, by_array = _pilots(f)
    out = np.full(8, np.nan)
    for t_s, y in zip(f.t_s.tolist(), f.pilot_in):
        want = ref.step(t_s, y.tolist())
        got = by_list.step(t_s, y.tolist())
        by_array.step_into(t_s, y, out)
        assert got == want and type(got) is type(want) and all(type(v) is float for v in got[1:])
        assert out.tobytes() == np.array(want[1:]).tobytes(), t_s
    # the flight itself was flown with these floats (step() on lists in the loop)
    ref.reset()
    flown = [ref.step(t_s, y.tolist())[1:] for t_s, y in zip(f.t_s.tolist(), f.pilot_in)]
    assert np.array(flown).tobytes() == f.pilot_out.tobytes()
    assert ref.headings == by_list.headings == by_array.headings
    assert by_array.airspeed_estimate_kts == by_list.airspeed_estimate_kts


def test_the_flights_reach_every_branch() -> None:
    """The flights above are worth their time: stops, turns, ramps and protections all happen."""
    f = _flights.flight("dhc6_faults")
    c = f.pilot_out
    assert (c[:, 0] == 1.0).any() and (c[:, 3] == 1.0).any()  # elevator and throttle at a stop
    g = _flights.flight("f16_all_maneuvers").pilot_out
    assert (g[:, 7] == math.radians(-25.0)).any()  # the turn's bank
    assert len(np.unique(g[:, 6])) >= 4  # trim heading, two heading changes, the heading held after the turn
    assert np.ptp(g[:, 4]) == 500.0 and np.ptp(g[:, 5]) > 0.0  # both ramps
    held = np.diff(f.pilot_in, axis=0) == 0.0
    assert held.all(axis=0).sum() == 0 and held.mean() > 0.3  # lower-rate sensors hold between samples


def test_step_and_step_into_can_be_mixed() -> None:
    """One state behind both entry points: alternating them flies the same as either alone."""
    f = _flights.flight("dhc6_all_maneuvers")
    ref, p, _ = _pilots(f)
    out = np.zeros(8)
    for k, (t_s, y) in enumerate(zip(f.t_s.tolist(), f.pilot_in)):
        want = np.array(ref.step(t_s, y.tolist())[1:])
        if k % 3:
            p.step_into(t_s, y, out)
        else:
            out[:] = p.step(t_s, y)[1:]  # an array input this time
        assert out.tobytes() == want.tobytes()


def test_reset_replays_bit_for_bit() -> None:
    f = _flights.flight("f16_all_maneuvers")
    _, p, _ = _pilots(f)
    out, first, second = np.zeros(8), [], []
    for rows in (first, second):
        p.reset()
        for t_s, y in zip(f.t_s.tolist(), f.pilot_in):
            p.step_into(t_s, y, out)
            rows.append(out.copy())
    assert np.array(first).tobytes() == np.array(second).tobytes()


TRIM = TrimPoint(0.0, 0.0, -0.07, 0.8, 0.05, 0.0, 0.0, 5000.0, 120.0)
DT = 1.0 / 120.0


def test_nan_measurements_give_nan_where_the_python_pilot_does() -> None:
    """A NaN measurement (a log replay with gaps) takes the same branches as in Python floats
    (comparisons with NaN are false in both: the clips send a NaN command to a stop)."""
    mans = [m.turn(m.TurnParams(type="turn-v1", t_start_s=1.0, phi_deg=20.0, duration_s=1.0)),
            m.altitude(m.AltitudeParams(type="altitude-v1", t_start_s=0.5, h_ft=5200.0, rate_fps=40.0))]
    args = (AutopilotGains.for_aircraft("DHC6"), AutopilotModes(), TRIM, mans, TRUTH_SIGNALS, DT)
    ref, p = ReferencePilot(*args), Pilot(*args)
    rng = np.random.default_rng(9)
    base = np.zeros(len(TRUTH_SIGNALS))
    i = {n: TRUTH_SIGNALS.index(n) for n in NEEDED}
    base[i["h_ft"]], base[i["vc_kts"]], base[i["nz_g"]], base[i["v_north_fps"]] = 5000.0, 120.0, -1.0, 200.0
    out = np.zeros(8)
    saw_nan = False
    for k in range(480):
        y = base + rng.normal(size=len(base)) * 0.1
        if k % 50 < 10:
            y[i[NEEDED[k % len(NEEDED)]]] = np.nan
        want = np.array(ref.step(k * DT, y.tolist())[1:])
        p.step_into(k * DT, y, out)
        assert np.array_equal(out, want, equal_nan=True), k
        saw_nan |= bool(np.isnan(p._state).any())  # the clips turn a NaN command into a stop; the filters keep it
    assert saw_nan


def test_compiled_libm_and_modulo_equal_python() -> None:
    """numba's math.sin/cos/sqrt and float % are the interpreter's, bit for bit (no fastmath, same libm)."""

    @numba.njit
    def trig(x, out):
        for j in range(x.size):
            out[0, j] = math.sin(x[j])
            out[1, j] = math.cos(x[j])
            out[2, j] = math.sqrt(abs(x[j]))
            out[3, j] = (x[j] + math.pi) % K.TWO_PI - math.pi

    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(size=20000) * s for s in (0.01, 1.0, 10.0, 1e4)]
                       + [np.array([0.0, -0.0, math.pi, -math.pi, K.TWO_PI, -K.TWO_PI, 1e-300, 5e-324])])
    out = np.empty((4, x.size))
    trig(x, out)
    want = np.array([[math.sin(v) for v in x.tolist()], [math.cos(v) for v in x.tolist()],
                     [math.sqrt(abs(v)) for v in x.tolist()], [(v + math.pi) % K.TWO_PI - math.pi for v in x.tolist()]])
    assert out.tobytes() == want.tobytes()


def test_layout_matches_the_pilot() -> None:
    assert len(NEEDED) == K.N_NEEDED
    assert len(K.LAT_GAINS) == K.P_K_H - K.P_K_PSI and len(K.LON_GAINS) == K.P_ELEV0 - K.P_K_H
    assert set(K.LAT_GAINS + K.LON_GAINS) <= set(AutopilotGains.__dataclass_fields__)


def test_kernels_are_compiled_with_a_disk_cache() -> None:
    kernels = [v for v in vars(K).values() if isinstance(v, numba.core.registry.CPUDispatcher)]
    assert {k.py_func.__name__ for k in kernels} >= {"step", "_ramp_value", "_np_sign"}
    for kern in kernels:
        assert isinstance(kern._cache, FunctionCache), kern
        assert not kern.targetoptions.get("fastmath"), kern


def test_a_second_process_loads_the_kernel_from_the_cache(tmp_path: Path) -> None:
    """cache=True works: after one process compiled the step, the next one only loads it."""
    code = ("import numpy as np\n"
            "from fdi_sim.aircraft import TRUTH_SIGNALS\n"
            "from fdi_sim.pilot import _kernels as K\n"
            "from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint\n"
            "p = Pilot(AutopilotGains.for_aircraft('DHC6'), AutopilotModes(), "
            "TrimPoint(0.0, 0.0, -0.07, 0.8, 0.05, 0.0, 0.0, 5000.0, 120.0), [], TRUTH_SIGNALS, 1 / 120)\n"
            "p.step_into(0.0, np.zeros(len(TRUTH_SIGNALS)), np.zeros(8))\n"
            "print(sum(K.step.stats.cache_hits.values()), sum(K.step.stats.cache_misses.values()))\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))  # a cold cache of its own
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, env=env,
                           check=True).stdout.split() for _ in range(2)]
    assert runs == [["0", "1"], ["1", "0"]]  # compiled once, then loaded

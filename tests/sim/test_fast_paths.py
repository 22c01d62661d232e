"""The simulation loop's fast paths give the same floats as the general paths, bit for bit.

The loop reads the truth with :meth:`Aircraft.list_reader` and measures with
:meth:`SensorSuite.step_list` (Python floats, no numpy per step); the logs must not change for it.
Real JSBSim, short runs in moderate turbulence so that every signal moves.
"""
from __future__ import annotations

import struct

import numpy as np
import pytest

from fdi_sim.aircraft import SURFACE_SIGNALS, Aircraft, Atmosphere, trim
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.scenario import loads
from fdi_sim.sim.run import build_sensors

SC = """
name = "fast_paths_{ac}"
aircraft = "{ac}"
duration_s = 2.0
seed = 5
[initial]
h_ft = {h}
{speed}
[atmosphere]
turbulence = "moderate"
"""
CASES = {"f16": (10000.0, "vt_kts = 400.0"), "DHC6": (5000.0, "vc_kts = 120.0")}


def _scenario(name: str):
    h, speed = CASES[name]
    return loads(SC.format(ac=name, h=h, speed=speed))


def _bits(values) -> bytes:
    return struct.pack(f"<{len(values)}d", *values)


@pytest.mark.parametrize("name", list(CASES))
def test_list_reader_equals_reader_bit_for_bit(name: str) -> None:
    sc = _scenario(name)
    ac = Aircraft(name, sc.dt_s)
    trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 3)
    mixed = ("thrust_lbf", "h_ft", "thrust_lbf") + (("torque_1_ftlb", "thrust_lbf", "torque_0_ftlb") if name == "DHC6" else ())
    for names in (truth_signals(name), SURFACE_SIGNALS, mixed):  # summed and scaled signals among plain ones
        fast, slow = ac.list_reader(names), ac.reader(names)
        for _ in range(30):
            ac.step()
            got = fast()
            assert type(got) is list and len(got) == len(names)
            assert _bits(got) == slow().tobytes()
    if name == "DHC6":  # the summed signal really is the sum of both engines
        t0, t1 = ac["propulsion/engine[0]/thrust-lbs"], ac["propulsion/engine[1]/thrust-lbs"]
        assert ac.list_reader(("thrust_lbf",))()[0] == t0 + t1
        assert t0 > 0.0 and t1 > 0.0
        # the scaled signal: the gauge's torque is minus the propeller's reaction torque
        q0 = ac["propulsion/engine[0]/propeller-torque-ftlb"]
        assert ac.list_reader(("torque_0_ftlb",))()[0] == -q0 and -q0 > 0.0
    with pytest.raises(KeyError):
        ac.list_reader(("no_such_signal",))


@pytest.mark.parametrize("name", list(CASES))
def test_sensor_step_list_equals_step(name: str) -> None:
    sc = _scenario(name)
    a, b = build_sensors(sc, sc.dt_s), build_sensors(sc, sc.dt_s)
    a.reset(np.random.default_rng(11))
    b.reset(np.random.default_rng(11))
    rng = np.random.default_rng(2)
    n_truth = len(truth_signals(name))
    x0 = rng.normal(size=n_truth) * 100.0
    for k in range(300):  # past two noise blocks and every sensor's sample phase
        x = x0 + rng.normal(size=n_truth)
        y_slow = a.step(k * sc.dt_s, x).y
        y_fast = b.step_list(k * sc.dt_s, x.tolist())
        assert _bits(y_fast) == y_slow.tobytes()
        y_fast[:] = [np.nan] * len(y_fast)  # the caller owns the list: the held values are not touched
    assert _bits(b.step_list(300 * sc.dt_s, x0.tolist())) == a.step(300 * sc.dt_s, x0).y.tobytes()

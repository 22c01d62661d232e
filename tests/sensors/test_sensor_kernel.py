"""The compiled sensor suite (measure_into, step_list, step) against the Python suite it replaced.

The oracle is ``_reference_sensors.ReferenceSuite``, the Python ``SensorSuite`` of commit d97be8c,
whose floats the logs hold: same generator, same draws, same bytes. Inputs are the truth of real
closed-loop flights of both aircraft (``tests/pilot/_flights.py``), with the shipped suites' lower
rates (40 Hz air data, 60 Hz attitude, the DHC-6 engine gauges) and resolutions.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba.core.caching import FunctionCache

from _reference_sensors import ReferenceSuite
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.sensors import SensorSpec, SensorSuite
from fdi_sim.sensors import _kernels as K
from fdi_sim.sim.run import build_sensors



def _load_flights():
    """tests/pilot/_flights.py, shared with the pilot tests (one module: each flight flown once)."""
    if "_flights" in sys.modules:  # collected together with tests/pilot
        return sys.modules["_flights"]
    spec = importlib.util.spec_from_file_location("_flights", Path(__file__).resolve().parents[1] / "pilot" / "_flights.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["_flights"] = mod
    spec.loader.exec_module(mod)
    return mod


_flights = _load_flights()
FLIGHTS = ["f16_all_maneuvers", "dhc6_all_maneuvers", "dhc6_faults"]


def _suites(f, n: int = 3) -> tuple[ReferenceSuite, list[SensorSuite]]:
    new = [build_sensors(f.sc, f.sc.dt_s) for _ in range(n)]
    ref = ReferenceSuite(new[0].specs, truth_signals(f.sc.aircraft), f.sc.dt_s)
    for s in [ref, *new]:
        s.reset(np.random.default_rng(f.sensor_seed))
    return ref, new


@pytest.mark.parametrize("name", FLIGHTS)
def test_measure_into_step_list_and_step_equal_the_python_suite_on_a_real_flight(name: str) -> None:
    f = _flights.flight(name)
    ref, (by_array, by_list, by_step) = _suites(f)
    assert len({s.rate_hz for s in ref.specs}) > 1 and any(s.quantum for s in ref.specs)
    out = np.full(len(ref.names), np.nan)
    for t_s, x in zip(f.t_s.tolist(), f.truth):
        want = ref.step_list(t_s, x.tolist())
        by_array.measure_into(t_s, x, out)
        got = by_list.step_list(t_s, x.tolist())
        assert out.tobytes() == np.array(want).tobytes(), t_s
        assert got == want and all(type(v) is float for v in got)
        assert by_step.step(t_s, x).y.tobytes() == out.tobytes()
        out[:] = np.nan  # the caller owns out: the held values are the suite's own
    ref.reset(np.random.default_rng(f.sensor_seed))
    flown = [ref.step_list(t_s, x.tolist()) for t_s, x in zip(f.t_s.tolist(), f.truth)]
    assert np.array(flown).tobytes() == f.meas.tobytes()  # the flight's own measurements


def test_entry_points_can_be_mixed_and_steps_skipped() -> None:
    """One state behind every entry point; calls out of order (a jump ahead, a step back, a repeated
    step) draw the noise blocks at the same steps as the Python suite did."""
    f = _flights.flight("dhc6_all_maneuvers")
    ref, (s,) = _suites(f, 1)
    out = np.zeros(len(s.names))
    ks = list(range(0, 130)) + [130, 130, 700, 701, 702, 650, 10, 11, 12] + list(range(2000, 2300, 7))
    for j, k in enumerate(ks):
        t_s, x = float(f.t_s[k]), f.truth[k]
        want = np.array(ref.step_list(t_s, x.tolist()))
        if j % 3 == 0:
            s.measure_into(t_s, x, out)
        elif j % 3 == 1:
            out[:] = s.step_list(t_s, x.tolist())
        else:
            out[:] = s.step(t_s, x).y
        assert out.tobytes() == want.tobytes(), k


def test_other_draws_from_the_same_generator_interleave_as_before() -> None:
    """The suite draws only its biases at reset and one block at the first step outside the last one:
    a caller sharing the generator sees the same numbers as with the Python suite."""
    truth = ("a_ft", "b_ft", "c_ft")
    specs = [SensorSpec("a_ft", "x", 0.5, bias_std=1.0), SensorSpec("b_ft", "x", 0.1, rate_hz=40.0, quantum=0.25),
             SensorSpec("c_ft", "x", 2.0, rate_hz=10.0, quantum=1.0)]
    outs = []
    for cls in (ReferenceSuite, SensorSuite):
        rng = np.random.default_rng(21)
        s = cls(specs, truth, 1.0 / 120.0)
        s.reset(rng)
        rows, shared = [], []
        for k in range(400):
            shared.append(rng.standard_normal())  # someone else drawing every step
            rows.append(s.step_list(k / 120.0, [np.sin(k / 50.0) * 3.0, -0.1 * k, 0.003 * k]))
        outs.append((np.array(rows), np.array(shared)))
    assert outs[0][0].tobytes() == outs[1][0].tobytes() and outs[0][1].tobytes() == outs[1][1].tobytes()


def test_quantization_rounds_half_to_even_and_never_gives_minus_zero() -> None:
    """Python's round(): ties to even, and a value rounding to 0 is +0.0 (the int 0 has no sign)."""
    truth = ("a_ft",)
    specs = [SensorSpec("a_ft", "x", 0.0, rate_hz=100.0, quantum=0.5)]
    ref, new = ReferenceSuite(specs, truth, 0.01), SensorSuite(specs, truth, 0.01)
    values = [-0.1, -0.0, 0.0, 0.1, 0.125, -0.125, 0.25, -0.25, 0.75, -0.75, 1.25, -1.25, 1e15 + 0.25, -3.7]
    out = np.zeros(1)
    for k, v in enumerate(values):
        want = ref.step_list(k * 0.01, [v])
        new.measure_into(k * 0.01, np.array([v]), out)
        assert out.tobytes() == np.array(want).tobytes(), v
        if v in (-0.1, -0.0, -0.125):
            assert out[0] == 0.0 and not np.signbit(out[0])


def test_kernel_is_compiled_with_a_disk_cache() -> None:
    assert isinstance(K.measure, numba.core.registry.CPUDispatcher)
    assert isinstance(K.measure._cache, FunctionCache)
    assert not K.measure.targetoptions.get("fastmath")

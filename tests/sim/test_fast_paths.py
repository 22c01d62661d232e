"""The simulation loop's fast paths give the same floats as the general paths, bit for bit.

The loop reads the JSBSim properties flat (:meth:`Aircraft.flat_reader`) and its compiled core
(:mod:`fdi_sim.sim._core`) builds the truth, checks it and measures; faulty flights measure with
:meth:`SensorSuite.step_list` (Python floats); the logs must not change for either.
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


def _core_inputs(name: str, sc, names):
    """A trimmed aircraft's flat reads, the core's aux and a buffer laid out as the loop's."""
    from fdi_sim.sim import _core

    ac = Aircraft(name, sc.dt_s)
    trim(ac, sc.operating_point())
    ac.set_atmosphere(Atmosphere("moderate"), 3)
    read_flat, plan = ac.flat_reader(names, extra=("position/h-agl-ft",))
    n_flat = len(read_flat())
    lim = sc.model.limits
    aux = _core.make_aux(names, plan, n_flat, alpha_min_rad=np.radians(lim.alpha_min_deg),
                         alpha_max_rad=np.radians(lim.alpha_max_deg), phi_max_rad=np.radians(lim.phi_max_deg),
                         rate_max_radps=lim.rate_max_radps, vc_min_kts=lim.vc_min_kts, wind_north_fps=0.0,
                         wind_east_fps=0.0)
    return ac, read_flat, aux, np.zeros(len(names) + n_flat)


@pytest.mark.parametrize("name", list(CASES))
def test_core_truth_equals_list_reader_bit_for_bit(name: str) -> None:
    """The loop's compiled core builds from the flat property reads the truth list_reader gives
    (plain, summed and scaled signals), every step of a gusty flight."""
    from fdi_sim.sim import _core

    sc = _scenario(name)
    # the truth, then summed (DHC-6 thrust: both engines) and scaled signals among plain ones
    mixed = ("thrust_lbf", "h_ft") + (("torque_1_ftlb", "thrust_lbf", "torque_0_ftlb") if name == "DHC6" else ())
    names = truth_signals(name) + mixed
    ac, read_flat, aux, x = _core_inputs(name, sc, names)
    slow = ac.list_reader(names)
    scratch = np.zeros(1)
    n = len(names)
    for k in range(60):
        ac.step()
        x[n:] = read_flat()
        code = _core.step(_core.TRUTH, k * sc.dt_s, x, scratch, scratch, scratch.reshape(1, 1), scratch.reshape(1, 1),
                          scratch, scratch, aux)
        assert code == _core.OK
        assert x[:n].tobytes() == _bits(slow())
    _, plan = ac.flat_reader(mixed)
    if name == "DHC6":  # the combinations were there to check
        assert plan[0][1] - plan[0][0] == 2 and plan[2][2] == -1.0


def test_core_divergence_codes_and_messages() -> None:
    """Each divergence check of the core, on a trimmed DHC-6's truth with one value changed, gives
    its code and the loop's message; the checks run in the loop's order (non-finite first)."""
    from fdi_sim.sim import _core

    sc = _scenario("DHC6")
    names = truth_signals("DHC6")
    _, read_flat, aux, x = _core_inputs("DHC6", sc, names)
    n = len(names)
    flat = read_flat()
    idx = {nm: i for i, nm in enumerate(names)}
    scratch = np.zeros(1)

    def check(changes: dict) -> tuple[int, str | None]:
        x[n:] = flat
        for j, v in changes.items():
            x[n + j] = v
        code = _core.step(_core.TRUTH, 0.0, x, scratch, scratch, scratch.reshape(1, 1), scratch.reshape(1, 1),
                          scratch, scratch, aux)
        msg = None if code == _core.OK else _core.divergence_reason(code, x[:n].tolist(), names, sc.model.limits)
        return code, msg

    assert check({}) == (_core.OK, None)
    assert check({idx["q_radps"]: np.nan, len(flat) - 1: -5.0}) == (_core.NONFINITE, "non-finite state (q_radps)")
    assert check({len(flat) - 1: 0.0}) == (_core.GROUND, "ground impact")
    code, msg = check({idx["alpha_rad"]: np.radians(60.0)})
    assert code == _core.ALPHA and msg.startswith("alpha 60.0 deg outside")
    code, msg = check({idx["phi_rad"]: -np.radians(170.0)})
    assert code == _core.BANK and msg.startswith("bank -170.0 deg beyond")
    assert check({idx["r_radps"]: -9.0})[0] == _core.RATE
    code, msg = check({idx["vc_kts"]: 1.0})
    assert code == _core.AIRSPEED and msg.startswith("airspeed 1.0 kt below")


def test_core_cache_is_emptied_when_a_called_kernel_changes(tmp_path) -> None:
    """numba's cache misses changes in the other files' kernels the core calls: the stamp of their
    sources changes with them and a changed stamp empties the cache once."""
    from fdi_sim.sim import _core

    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("y = 2\n")
    s1 = _core.dependency_stamp((a, b))
    flushes = []
    stamp = tmp_path / "deps"
    assert _core._fresh_cache(stamp, s1, lambda: flushes.append(1)) and flushes == [1]  # no stamp yet
    assert not _core._fresh_cache(stamp, s1, lambda: flushes.append(1)) and flushes == [1]  # unchanged
    b.write_text("y = 3\n")
    s2 = _core.dependency_stamp((a, b))
    assert s2 != s1
    assert _core._fresh_cache(stamp, s2, lambda: flushes.append(1)) and flushes == [1, 1]
    assert stamp.read_text() == s2
    # the real one: the stamp beside the core's cache names the sensors' and the pilot's kernels
    assert {p.name for p in _core._DEPENDENCIES} == {"_kernels.py"} and len(_core._DEPENDENCIES) == 2


@pytest.mark.parametrize("name", sorted(CASES))
def test_training_rows_in_memory_equal_the_log_read_back(name: str, tmp_path) -> None:
    """A training flight's kept rows (``run(..., keep_rows=True)``, what calibrations train on) are
    the measurement and command topics the same flight logs to its MCAP file, bit for bit, times
    included; the file then holds no per-step topic."""
    from fdi_sim.flightlog import TOPIC_COMMANDS, TOPIC_SENSORS, TOPIC_TRUTH_STATE, read_log
    from fdi_sim.sim.run import run

    sc = _scenario(name)
    full = read_log(run(sc, log_path=tmp_path / "full.mcap", progress=False).log_path)
    kept = run(sc, log_path=tmp_path / "kept.mcap", progress=False, keep_rows=True)
    assert kept.status == "completed" and kept.rows is not None
    assert set(kept.rows.topics) == {TOPIC_SENSORS, TOPIC_COMMANDS}
    for topic in (TOPIC_SENSORS, TOPIC_COMMANDS):
        a, b = full.topics[topic], kept.rows.topics[topic]
        assert a.fields == b.fields and len(b) == int(round(sc.duration_s / sc.dt_s)) + 1
        assert a.data.tobytes() == b.data.tobytes()
        assert np.array_equal(a.log_time_ns, b.log_time_ns)
    assert TOPIC_TRUTH_STATE in full.topics and TOPIC_TRUTH_STATE not in read_log(kept.log_path).topics

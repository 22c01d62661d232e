"""The streaming kernel of kalman-gust-v1 against the detector's whole-flight path, on a real flight."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.catalogue_observers import make_gust_kalman
from fdi_sim.detectors.gust_kalman import analytic_calibration
from fdi_sim.detectors.gust_kalman_stream import GustKalmanStream
from fdi_sim.detectors.samples import log_samples
from fdi_sim.detectors.scheduled import GustKalmanSchedule
from fdi_sim.errors import DesignError
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import load
from fdi_sim.training import fly
from fdi_sim.training.flights import fault_free
from fdi_sim.training.models import model_for_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    sc = load(ROOT / "scenarios" / "f16_pitch_gyro_bias.toml")
    sc = fault_free(sc, 7, 30.0)
    data = __import__("json").loads(sc.to_json())
    data["faults"] = [{"type": "sensor-bias-v1", "target": "q_radps", "bias_degps": 0.5, "t_start_s": 15.0}]
    from fdi_sim.scenario.loader import from_dict

    sc = from_dict(data, source="test")
    lm = model_for_scenario(sc, 20.0)
    det = make_gust_kalman(lm.continuous(), rate_hz=20.0, sim_rate_hz=120.0, turbulence="light")
    # the design's own (analytic) calibration, lowered so that the bias and some turbulence alarm
    cal = replace(analytic_calibration(det.design, 1e-4), threshold=60.0)
    det = type(det)(det.design, cal)
    log = read_log(fly(sc, tmp_path_factory.mktemp("gk"), progress=False).log_path)
    return det, log_samples(log, det.design.model, 20.0)


def _outputs(N: int, p: int) -> dict[str, np.ndarray]:
    """The arrays GustKalmanStream.process writes, in its argument order."""
    return {"T": np.empty(N), "thr": np.empty(N), "valid": np.empty(N, bool), "hyp": np.empty(N, np.int64),
            "cos": np.empty(N), "point": np.empty(N, np.int64), "nu": np.empty((N, p)), "yhat": np.empty((N, p))}


def _go(stream: GustKalmanStream, s, blocks):
    N = s.n
    out = _outputs(N, stream.n_outputs)
    u, y = s.du + s.u0, s.dy + s.y0
    stream.reset()
    i = 0
    for b in blocks:
        sl = slice(i, min(N, i + int(b)))
        stream.process(u[sl], y[sl], s.valid[sl], *(out[k][sl] for k in out))
        i += int(b)
        if i >= N:
            break
    return out


def test_stream_equals_detector_run_and_is_chunk_invariant(flight):
    det, s = flight
    st = GustKalmanStream(GustKalmanSchedule.single(det.design, det.calibration))
    whole = _go(st, s, [s.n])
    ref = det.run(s)
    ok = np.isfinite(ref.statistic)
    assert np.array_equal(ok, whole["valid"])
    np.testing.assert_allclose(whole["T"][ok], ref.statistic[ok], rtol=1e-10)
    alarm = whole["valid"] & (whole["T"] > whole["thr"])
    assert np.array_equal(alarm, ref.alarm) and alarm.sum() > 20
    iso = [st.hypotheses[h] if a and h >= 0 else None for h, a in zip(whole["hyp"], alarm)]
    assert iso == list(ref.isolation)
    assert "q_radps" in iso  # the injected gyro bias is among the isolations
    # the estimate is the measurement minus the innovation, where measured
    y = s.dy + s.y0
    np.testing.assert_allclose((whole["yhat"] + whole["nu"])[s.valid], np.where(s.valid, y, 0)[s.valid], atol=1e-9)
    rng = np.random.default_rng(3)
    for blocks in ([1] * s.n, [5] * s.n, rng.integers(1, 12, size=s.n)):
        part = _go(st, s, blocks)
        for k in whole:
            assert np.array_equal(whole[k], part[k], equal_nan=True), k


def test_switching_between_identical_designs_changes_nothing(flight):
    """Bumpless transfer: two points with the same design; the switch moves nothing."""
    det, s = flight
    one = GustKalmanSchedule.single(det.design, det.calibration)
    h0, v0 = one.points[0]
    y = s.dy + s.y0
    vc = y[:, list(det.design.model.output_names).index("vc_kts")]
    # a boundary crossed by the flight's measured airspeed in turbulence
    two = GustKalmanSchedule(np.array([[h0, float(np.median(vc)) - 1.0], [h0, float(np.median(vc)) + 1.0]]),
                             np.array([2000.0, 1.0]), (det.design,) * 2, (det.calibration,) * 2, hysteresis=0.2)
    a, b = _go(GustKalmanStream(one), s, [s.n]), _go(GustKalmanStream(two), s, [7] * s.n)
    switches = int(np.count_nonzero(np.diff(b["point"])))
    assert switches >= 2  # the hysteresis lets it switch, but not on every sample
    assert switches < s.n // 4
    for k in ("T", "valid", "hyp", "nu", "yhat"):
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_one_structure_is_required(flight):
    det, _ = flight
    other = make_gust_kalman(model_for_scenario(load_dhc6(), 20.0).continuous(), rate_hz=20.0, sim_rate_hz=120.0,
                             turbulence="light")
    with pytest.raises(DesignError, match="share one structure"):
        GustKalmanSchedule(np.array([[1e4, 300.0], [5e3, 120.0]]), np.array([2000.0, 40.0]),
                           (det.design, other.design), (det.calibration, det.calibration))


def load_dhc6():
    return load(ROOT / "scenarios" / "dhc6_cruise_doublets.toml")


def test_schedule_follows_the_filter_when_the_scheduling_sensor_is_excluded(flight):
    """An excluded (reconfigured) vc no longer freezes the schedule: the filter's own prediction
    of vc schedules it (it keeps switching across a boundary at the median airspeed), and that
    prediction follows the measured airspeed it no longer sees."""
    det, s = flight
    y = s.dy + s.y0
    vc = y[:, list(det.design.model.output_names).index("vc_kts")]
    h0 = float(np.median(y[:, list(det.design.model.output_names).index("h_ft")]))
    two = GustKalmanSchedule(np.array([[h0, float(np.median(vc)) - 0.5], [h0, float(np.median(vc)) + 0.5]]),
                             np.array([2000.0, 1.0]), (det.design,) * 2, (det.calibration,) * 2, hysteresis=0.2)
    st = GustKalmanStream(two)
    a = _go(st, s, [s.n])
    i_vc = list(st.output_names).index("vc_kts")
    s2 = replace(s, valid=s.valid.copy())
    s2.valid[:, i_vc] = False
    b = _go(st, s2, [s.n])
    assert np.count_nonzero(np.diff(a["point"])) >= 1 and np.count_nonzero(np.diff(b["point"])) >= 1
    err = b["yhat"][:, i_vc] - vc
    assert np.sqrt(np.mean(err[40:] ** 2)) < 3.0, np.sqrt(np.mean(err[40:] ** 2))  # kt, after the filter's start


def _heading_as_2pi(design):
    """The same design with its trim heading read as 2 pi on (JSBSim's psi is in [0, 2 pi): a trim
    a hair left of north reads 6.2832 where the next node's reads 0.0)."""
    m = design.model
    x0 = np.asarray(m.x0, dtype=float).copy()
    y0 = np.asarray(m.y0, dtype=float).copy()
    x0[list(m.state_names).index("psi_rad")] += 2.0 * np.pi
    y0[list(m.output_names).index("psi_rad")] += 2.0 * np.pi
    return replace(design, model=replace(m, x0=x0, y0=y0))


def test_switching_to_a_trim_heading_read_as_2pi_changes_nothing(flight):
    """Bumpless transfer across two nodes whose trim headings are one angle written 0 and 2 pi:
    nothing moves (fdi-bench-v1's DHC-6 descents alarmed at 6,516 x the threshold at that switch
    before the heading's trim difference was wrapped)."""
    det, s = flight
    one = GustKalmanSchedule.single(det.design, det.calibration)
    h0, _ = one.points[0]
    y = s.dy + s.y0
    vc = y[:, list(det.design.model.output_names).index("vc_kts")]
    two = GustKalmanSchedule(np.array([[h0, float(np.median(vc)) - 1.0], [h0, float(np.median(vc)) + 1.0]]),
                             np.array([2000.0, 1.0]), (det.design, _heading_as_2pi(det.design)),
                             (det.calibration,) * 2, hysteresis=0.2)
    a, b = _go(GustKalmanStream(one), s, [s.n]), _go(GustKalmanStream(two), s, [7] * s.n)
    assert np.count_nonzero(np.diff(b["point"])) >= 2
    i_psi = list(det.design.model.output_names).index("psi_rad")
    for k in ("T", "valid", "hyp", "nu"):
        np.testing.assert_allclose(a[k], b[k], rtol=0, atol=1e-9, err_msg=k)
    # the estimate is the same heading, on either side of the circle
    d = (b["yhat"][:, i_psi] - a["yhat"][:, i_psi] + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(d)) < 1e-9


def _cyclic_heading(design):
    """The design with the heading exactly cyclic: the linearizer's finite differences leave couplings
    of ~1e-6 per rad from the heading to the other channels, which a state 2 pi off would show."""
    m = design.model
    A, C = np.asarray(m.A, dtype=float).copy(), np.asarray(m.C, dtype=float).copy()
    i_x = list(m.state_names).index("psi_rad")
    keep_a, keep_c = A[i_x, i_x], C[list(m.output_names).index("psi_rad"), i_x]
    A[:, i_x] = 0.0
    C[:, i_x] = 0.0
    A[i_x, i_x], C[list(m.output_names).index("psi_rad"), i_x] = keep_a, keep_c
    return replace(design, model=replace(m, A=A, C=C))


def test_a_heading_state_a_full_turn_on_changes_no_innovation(flight):
    """After an orbit the measured heading has wrapped; the filter's heading state is a deviation on
    the circle and its innovation the angle between them (a 2 pi spike before): a heading state a
    full turn on changes nothing, in the streaming kernel and in the whole-flight path alike."""
    from fdi_sim.detectors.gust_kalman import innovations

    det, s = flight
    design = _cyclic_heading(det.design)
    st = GustKalmanStream(GustKalmanSchedule.single(design, det.calibration))
    a = _go(st, s, [s.n])
    i_x = list(design.model.state_names).index("psi_rad")
    b = _outputs(s.n, st.n_outputs)
    st.reset()
    st._x[i_x] += 2.0 * np.pi  # the state a full orbit on
    st.process(s.du + s.u0, s.dy + s.y0, s.valid, *b.values())
    for k in ("T", "valid", "hyp", "nu"):
        np.testing.assert_allclose(a[k], b[k], rtol=1e-9, atol=1e-9, err_msg=k)
    assert -np.pi <= st._x[i_x] < np.pi
    # the whole-flight path: a measured heading a full turn on is the same innovation
    dy = s.dy.copy()
    dy[:, list(design.model.output_names).index("psi_rad")] += 2.0 * np.pi
    np.testing.assert_allclose(innovations(design, replace(s, dy=dy)), innovations(design, s), atol=1e-9)

"""Compiled streams of the seed detectors (parity window, directional observers, steady Kalman) against their ``step``.

Each detector is designed from the F-16 linear model of a real scenario (JSBSim trim and
linearization) or, for a Beard-Jones bank, a small observable model; samples are the model's own
simulated response with sensor noise and a fault half way. The stream must give the detector's
statistic (to rounding), validity and isolation, the same bits for any block size, never a valid
"no alarm" on a bad measurement, and recover afterwards.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdi_sim.detectors.beard_jones_filter import BeardJonesBank, BeardJonesFilter, plan_bank
from fdi_sim.detectors.catalogue_observers import make_kalman_tv
from fdi_sim.detectors.catalogue_parity import make_pca
from fdi_sim.detectors.directional_observer import DirectionalObserver
from fdi_sim.detectors.kalman import simulate_discrete
from fdi_sim.detectors.noise import suite_sensor_std
from fdi_sim.detectors.observer_stream import ObserverStream
from fdi_sim.detectors.seed_streams import compiled_stream
from fdi_sim.detectors.stream import BlockOutputs, StreamingDetector, stream_design_key
from fdi_sim.detectors.window_stream import WindowParityStream
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

CMD = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
N = 600  # 30 s at 20 Hz
T_FAULT = 300


@pytest.fixture(scope="module")
def lm():
    from fdi_sim.scenario.loader import load
    from fdi_sim.training.models import model_for_scenario

    return model_for_scenario(load("scenarios/f16_stuck_elevator.toml"), 20.0)


def _synthetic() -> LinearModel:
    """Observable 3-state model (Miller & Ribbens eq. 2.47, discretized), two faults whose output
    directions are parallel (a Beard-Jones bank of two filters), a held disturbance input, a heading."""
    A3 = np.array([[0.0, 3.0, 4.0], [1.0, 2.0, 3.0], [0.0, 2.0, 5.0]])
    B = np.column_stack([[1.0, -0.5, 0.5], [0.0, -1.0, 1.0], [0.2, 0.1, 0.3]])
    return LinearModel(A=np.eye(3) + 0.01 * (A3 - 10 * np.eye(3)), B=B, C=[[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                       D=np.zeros((2, 3)), dt_s=0.05, input_names=("a_cmd_norm", "b_cmd_norm", "w_gust_fps"),
                       output_names=("q_radps", "psi_rad"), input_kinds=("control", "control", "disturbance"),
                       u0=[0.1, -0.2, 0.5], y0=[0.01, 3.0])


SYN_CMD = ("a_cmd_norm", "b_cmd_norm", "other_cmd_norm")


def _flight(model: LinearModel, cmd: tuple[str, ...], seed: int, *, actuator: int | None = None,
            sensor: int | None = None, n: int = N, white: bool = False) -> tuple:
    """Absolute samples ``(t_s, u, y)`` of the discrete ``model`` with sensor noise: commands in
    ``model``'s logged-command order, a fault from ``T_FAULT`` on (an unlogged actuator offset, or
    a sensor bias of 8 noise sigma). Commands: a slow random walk, or ``white`` noise."""
    rng = np.random.default_rng(seed)
    std = suite_sensor_std(model)
    std = np.full(model.n_outputs, 1e-3) if std is None else std
    ctrl = [i for i, nm in enumerate(model.input_names) if nm in cmd]
    ud = np.zeros((n, model.n_inputs))
    e = rng.standard_normal((n, len(ctrl)))
    ud[:, ctrl] = 0.01 * (e if white else np.cumsum(e, axis=0) / math.sqrt(n))
    plant_u = ud.copy()
    if actuator is not None:
        plant_u[T_FAULT:, actuator] += 0.05
    run = simulate_discrete(model, plant_u, 1e-10 * np.eye(model.n_states), np.diag(std ** 2), rng)
    y = run.y.copy()
    if sensor is not None:
        y[T_FAULT:, sensor] += 8 * std[sensor]
    return np.arange(1, n + 1) / 20.0, ud[:, ctrl] + np.asarray(model.u0)[ctrl], y


def _reference(det, model, stream, t, u, y):
    """The detector's own ``step`` on the same samples (as :func:`fdi_sim.offline.detect.run_detector`):
    statistic, validity, isolation on alarm, and the scores (a directional filter's angles [rad])."""
    cols = [list(model.input_names).index(nm) for nm in stream.input_names]
    u_full = np.tile(np.asarray(model.u0, float), (len(t), 1))
    u_full[:, cols] = u
    y0 = np.asarray(model.y0, float)
    dy = y - y0
    for i, nm in enumerate(stream.output_names):
        if nm.startswith("psi") and nm.endswith("_rad"):
            dy[:, i] = (dy[:, i] + math.pi) % (2 * math.pi) - math.pi
    det.reset(np.random.default_rng(0))
    res = [det.step(float(t[j]), u_full[j], y0 + dy[j]) for j in range(len(t))]
    return (np.array([r.statistic for r in res]), np.array([bool(r.valid) for r in res]),
            [r.isolation if r.valid and r.alarm else None for r in res], [r.scores for r in res])


def _run(stream, t, u, y, ok=None, block: int | None = None) -> BlockOutputs:
    """Reset, then process in blocks of ``block`` samples (all at once if None)."""
    ok = np.ones(y.shape, bool) if ok is None else ok
    out = BlockOutputs.allocate(len(t), len(stream.residual_names))
    stream.reset()
    step = len(t) if block is None else block
    for a in range(0, len(t), step):
        b = min(a + step, len(t))
        view = BlockOutputs(out.statistic[a:b], out.threshold[a:b], out.valid[a:b], out.hypothesis[a:b],
                            out.point[a:b], out.residual[a:b], out.estimate[a:b], out.cosine[a:b])
        stream.process_block(t[a:b], u[a:b], y[a:b], ok[a:b], ok[a:b], view)
    return out


def _same(a: BlockOutputs, b: BlockOutputs) -> None:
    for f in ("statistic", "threshold", "valid", "hypothesis", "point", "residual", "cosine"):
        assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True), f


# --- the cases ----------------------------------------------------------------------------------
def _build(case: str, lm):
    """``(detector, design model, command names, flight)`` of a case."""
    from fdi_sim.detectors.spec import build_detector, DetectorSpec

    model = lm.model
    outs = list(model.output_names)
    q = outs.index("q_radps")
    if case == "parity-v1":
        return build_detector(DetectorSpec("parity-v1", {}), model), model, CMD, _flight(model, CMD, 1, sensor=q)
    if case == "parity-v1-isolating":
        det = build_detector(DetectorSpec("parity-v1", {"order_s": 2, "sensors": outs, "actuators": ["elevator_cmd_norm"]}),
                             model)
        return det, model, CMD, _flight(model, CMD, 2, sensor=q)
    if case == "parity-robust-v1":
        return build_detector(DetectorSpec("parity-robust-v1", {}), model), model, CMD, _flight(model, CMD, 3, sensor=q)
    if case == "parity-stochastic-v1":
        det = build_detector(DetectorSpec("parity-stochastic-v1", {"order_s": 1, "sensors": outs}), model)
        return det, model, CMD, _flight(model, CMD, 4, sensor=q)
    if case == "pca-v1":  # trained on simulated fault-free and faulty arrays (no flight log needed)
        _, u_tr, y_tr = _flight(model, CMD, 10, n=3000, white=True)
        _, u_q, y_q = _flight(model, CMD, 11, sensor=q, white=True)
        _, u_p, y_p = _flight(model, CMD, 12, sensor=outs.index("p_radps"), white=True)
        det = make_pca(model, u_tr, y_tr, window_L=2, fault_data={"q_radps": (u_q[T_FAULT:], y_q[T_FAULT:]),
                                                                 "p_radps": (u_p[T_FAULT:], y_p[T_FAULT:])})
        return det, model, CMD, _flight(model, CMD, 5, sensor=q, white=True)
    if case == "lmi-detection-v1":  # designed on the continuous model, run at 20 Hz
        cont = lm.continuous()
        det = build_detector(DetectorSpec("lmi-detection-v1", {"dt_s": 0.05}), cont)
        return det, cont, CMD, _flight(model, CMD, 6, actuator=0)
    if case.startswith("kalman-nis-v1"):
        params = {"": {}, ":bias": {"test": "bias", "window_n": 40},
                  ":whiteness": {"test": "whiteness", "window_n": 40, "n_lags": 3}}[case[len("kalman-nis-v1"):]]
        return (build_detector(DetectorSpec("kalman-nis-v1", params), model), model, CMD,
                _flight(model, CMD, 7, sensor=q))
    if case == "beard-jones-v1":  # the real aircraft if it designs, else the small model's bank
        try:
            return build_detector(DetectorSpec("beard-jones-v1", {}), model), model, CMD, _flight(model, CMD, 8, actuator=0)
        except DesignError:
            return _build("beard-jones-bank", lm)
    if case == "beard-jones-bank":  # two filters of the small model (parallel output directions)
        syn = _synthetic()
        det = build_detector(DetectorSpec("beard-jones-v1", {"sensor_std": 1e-3}), syn)
        assert isinstance(det, BeardJonesBank) and len(det.filters) == 2
        return det, syn, SYN_CMD, _flight(syn, SYN_CMD, 8, actuator=1)
    if case == "beard-jones-filter":  # one filter of the small model
        syn = _synthetic()
        det = build_detector(DetectorSpec("beard-jones-v1", {"faults": ["a_cmd_norm"], "sensor_std": 1e-3}), syn)
        assert isinstance(det, BeardJonesFilter)
        return det, syn, SYN_CMD, _flight(syn, SYN_CMD, 9, actuator=0)
    raise AssertionError(case)


CASES = ("parity-v1", "parity-v1-isolating", "parity-robust-v1", "parity-stochastic-v1", "pca-v1", "lmi-detection-v1",
         "kalman-nis-v1", "kalman-nis-v1:bias", "kalman-nis-v1:whiteness", "beard-jones-v1", "beard-jones-bank",
         "beard-jones-filter")
_BUILT: dict = {}


def _get(name: str, lm):
    if name not in _BUILT:
        _BUILT[name] = _build(name, lm)
    return _BUILT[name]


@pytest.fixture(params=CASES)
def case(request, lm):
    return (request.param, *_get(request.param, lm))


def test_stream_is_the_detector_step(case) -> None:
    name, det, model, cmd, (t, u, y) = case
    stream = compiled_stream(det, model, cmd, name)
    assert isinstance(stream, (WindowParityStream, ObserverStream)) and isinstance(stream, StreamingDetector)
    assert stream.id == name and stream.estimate_names == () and stream.independent is False
    assert stream.input_names == tuple(nm for nm in model.input_names if nm in cmd)
    assert stream.output_names == tuple(model.output_names) and stream.hypotheses == tuple(det.hypotheses)
    out = _run(stream, t, u, y)
    stat, valid, iso, angles = _reference(det, model, stream, t, u, y)
    thr = stream.threshold
    assert np.array_equal(out.valid, valid)
    assert np.all(out.threshold == thr) and np.all(out.point == 0)
    np.testing.assert_allclose(out.statistic[valid], stat[valid], rtol=1e-9, atol=0)
    assert np.array_equal(out.statistic[~valid], stat[~valid], equal_nan=True)  # 0 until the window is full
    alarm = valid & (stat > thr)
    assert alarm[:T_FAULT].mean() < 0.2 and alarm[T_FAULT:].mean() > 0.5  # the fault shows
    got = [stream.hypotheses[h] if h >= 0 else None for h in out.hypothesis]
    assert got == [iso[j] if alarm[j] else None for j in range(N)]
    if stream.fault_directions:
        assert np.all(np.isnan(out.cosine[~alarm])) and np.all((out.cosine[alarm] >= 0) & (out.cosine[alarm] <= 1))
        if isinstance(det, DirectionalObserver):  # the cosine of the smallest angle
            best = np.array([np.nanmin(a) for a in angles])
            np.testing.assert_allclose(out.cosine[alarm], np.cos(best[alarm]), rtol=1e-9)
    else:
        assert np.all(np.isnan(out.cosine))
    if det.hypotheses:
        assert any(g is not None for g in got[T_FAULT:])


def test_blocks_give_the_same_bits(case) -> None:
    name, det, model, cmd, (t, u, y) = case
    stream = compiled_stream(det, model, cmd, name)
    whole = _run(stream, t, u, y)
    for block in (1, 37):
        _same(_run(stream, t, u, y, block=block), whole)
    # reset restores: a second pass after more samples gives the same bits
    _same(_run(stream, t, u, y, block=100), whole)


def test_bad_measurements_are_never_a_valid_no_alarm(case) -> None:
    name, det, model, cmd, (t, u, y) = case
    stream = compiled_stream(det, model, cmd, name)
    clean = _run(stream, t, u, y)
    yb = y.copy()
    ok = np.ones(y.shape, bool)
    bad = np.zeros(N, bool)
    ok[100:104, 1] = False  # a dropout: NaN with ok False
    yb[100:104, 1] = np.nan
    ok[150, 0] = False  # excluded, the value finite
    yb[200, -1] = np.inf  # not finite, though flagged ok
    bad[[*range(100, 104), 150, 200]] = True
    ub = u.copy()
    ub[250, 0] = np.nan  # a non-finite command
    bad[250] = True
    out = _run(stream, t, ub, yb, ok)
    assert not out.valid[bad].any() and np.all(out.hypothesis[bad] == -1)
    assert not (out.valid & ~np.isfinite(out.statistic)).any()
    assert np.all(np.isfinite(out.statistic[out.valid]))
    if isinstance(stream, WindowParityStream):  # every parity window holding a bad sample is invalid
        tainted = np.convolve(bad, np.ones(stream.order_s + 1), mode="full")[:N] > 0
        assert not out.valid[tainted].any()
    else:  # a filter leaves the bad sample out (a Kalman window test: over its good samples)
        tainted = bad
    # afterwards: a window free of bad samples is the clean result exactly (parity), a filter converges back
    later = ~tainted & clean.valid
    later[:260] = False
    assert out.valid[later].all()
    if isinstance(stream, WindowParityStream):
        assert np.array_equal(out.statistic[later], clean.statistic[later])
    else:
        late = np.arange(N) >= 500
        np.testing.assert_allclose(out.statistic[late], clean.statistic[late], rtol=1e-6, atol=1e-9)
    _same(_run(stream, t, u, y), clean)  # reset after the bad flight


def test_contract_checker_passes(case) -> None:
    from fdi_sim.detectors.check import check_stream, contract_inputs

    name, det, model, cmd, _ = case
    stream = compiled_stream(det, model, cmd, name)
    assert check_stream(stream, contract_inputs(stream, model)) == []


def test_open_loop_update_on_a_bad_sample() -> None:
    """Without a measurement the filter makes its prediction ``xh+ = A xh + B du`` (Kalman, Beard-Jones)."""
    syn = _synthetic()
    t, u, y = _flight(syn, SYN_CMD, 20)
    for det in (BeardJonesFilter(plan_bank(syn, ["a_cmd_norm"])[0]), _kalman(syn)):
        md = det.design.model
        stream = ObserverStream(det, syn, SYN_CMD)
        _run(stream, t[:50], u[:50], y[:50])
        x = stream._xh[0].copy()
        du = np.r_[u[50] - syn.u0[:2], 0.0]
        out = BlockOutputs.allocate(1, len(stream.residual_names))
        ok = np.array([[True, False]])
        stream.process_block(t[50:51], u[50:51], np.array([[y[50, 0], np.nan]]), ok, ok, out)
        np.testing.assert_allclose(stream._xh[0], md.A @ x + md.B @ du, rtol=1e-13, atol=1e-15)
        assert not out.valid[0] and math.isnan(out.statistic[0]) and math.isnan(out.residual[0, 1])


def test_lmi_open_loop_is_the_plant_zoh(lm) -> None:
    """The LMI filter's plant prediction, recovered from its ZOH observer, is the ZOH of the model
    (checked against the continuous design model, or given the bank's discrete model)."""
    det, cont, cmd, (t, u, y) = _get("lmi-detection-v1", lm)
    plant = cont.discretize(0.05)
    for model in (lm.model, cont):
        stream = ObserverStream(det, model, cmd)
        assert stream.open_loop_exact == (True,)
        np.testing.assert_allclose(stream._Fo[0], np.hstack([plant.A, plant.B]), rtol=0,
                                   atol=1e-10 * np.abs(plant.A).max())
    _run(stream, t[:50], u[:50], y[:50])
    x = stream._xh[0].copy()
    out = BlockOutputs.allocate(1, len(stream.residual_names))
    ok = np.ones((1, y.shape[1]), bool)
    ok[0, 3] = False
    stream.process_block(t[50:51], u[50:51], y[50:51], ok, ok, out)
    cols = [cont.input_names.index(nm) for nm in stream.input_names]
    du = np.zeros(cont.n_inputs)
    du[cols] = u[50] - cont.u0[cols]
    np.testing.assert_allclose(stream._xh[0], plant.A @ x + plant.B @ du, rtol=1e-9, atol=1e-12)


def _kalman(model: LinearModel):
    from fdi_sim.detectors.catalogue_observers import make_kalman

    return make_kalman(model, sensor_std=[1e-3, 1e-3], process_std=1e-3)


@pytest.mark.parametrize("test", ["bias", "whiteness"])
def test_kalman_window_leaves_bad_samples_out(test: str) -> None:
    """A window holding bad samples: the statistic of its good innovations (Sidar eq. 10a, 10b)."""
    from fdi_sim.detectors.catalogue_observers import make_kalman

    syn, Nw, L = _synthetic(), 20, 3
    det = make_kalman(syn, sensor_std=[1e-3, 1e-3], process_std=1e-3, test=test, window_n=Nw, n_lags=L)
    stream = ObserverStream(det, syn, SYN_CMD)
    t, u, y = _flight(syn, SYN_CMD, 22)
    ok = np.ones(y.shape, bool)
    ok[[50, 53, 54], 1] = False
    out = _run(stream, t, u, np.where(ok, y, np.nan), ok)
    z = out.residual @ det._W.T  # the whitened innovations
    good = ok.all(axis=1)
    for j in range(Nw, 80):
        Z = np.where(good[j - Nw + 1:j + 1, None], z[j - Nw + 1:j + 1], 0.0)
        n = good[j - Nw + 1:j + 1].sum()
        want = (n * np.sum((Z.sum(axis=0) / n) ** 2) if test == "bias" else
                sum(np.sum((Z[l:].T @ Z[:-l]) ** 2) for l in range(1, L + 1)) / n)
        if good[j]:
            assert out.valid[j] and out.statistic[j] == pytest.approx(want, rel=1e-9)
        else:
            assert not out.valid[j] and math.isnan(out.statistic[j])


def test_heading_deviation_is_wrapped() -> None:
    syn = _synthetic()
    t, u, y = _flight(syn, SYN_CMD, 21)
    stream = ObserverStream(_kalman(syn), syn, SYN_CMD)
    turned = y.copy()
    turned[:, 1] += 2 * math.pi * np.where(np.arange(N) % 2, 1, -1)  # the same heading, a turn apart
    a, b = _run(stream, t, u, y), _run(stream, t, u, turned)
    np.testing.assert_allclose(b.statistic, a.statistic, rtol=1e-6)


def test_design_key_and_threshold(lm) -> None:
    from fdi_sim.detectors.spec import build_detector, DetectorSpec

    model = lm.model
    k = [stream_design_key(compiled_stream(build_detector(DetectorSpec("parity-v1", p), model), model, CMD, "x"))
         for p in ({}, {}, {"order_s": 1})]
    assert k[0] == k[1] != k[2]
    det = build_detector(DetectorSpec("kalman-nis-v1", {}), model)
    s = compiled_stream(det, model, CMD, "kalman-nis-v1")
    key = s.design_key()
    assert s.threshold == pytest.approx(det.threshold)
    s.set_threshold(5.0)
    assert s.threshold == 5.0 and s.design_key() == key
    assert s.design_key() != compiled_stream(build_detector(DetectorSpec("kalman-nis-v1", {"test": "bias"}), model),
                                             model, CMD, "b").design_key()
    t, u, y = _flight(model, CMD, 30)
    assert np.all(_run(s, t, u, y).threshold == 5.0)


def test_uncovered_detectors_get_none(lm) -> None:
    assert compiled_stream(make_kalman_tv(lm.model), lm.model, CMD, "kalman-tv-nis-v1") is None
    assert compiled_stream(object(), lm.model, CMD, "x") is None

"""The time convention and the log-to-samples adaptor (``fdi_sim.detectors.samples``).

The pairing test flies real JSBSim (F-16, calm air, no turn-on biases, an elevator doublet) and
checks that the convention's pairs predict the flight better than the same commands shifted by
one sample either way, for the step model and for the paired ZOH model, at 120 Hz and 20 Hz.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.samples import (
    SampleError, decimation, log_samples, pair_samples, paired_model, samples_from_arrays,
)
from fdi_sim.flightlog import read_log
from fdi_sim.linear.grid import parse_grid_spec
from fdi_sim.linear.linearize import linearize_grid
from fdi_sim.scenario import loads
from fdi_sim.training import fly

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def calm_flight(tmp_path_factory: pytest.TempPathFactory):
    text = (REPO / "scenarios" / "f16_cruise_doublets.toml").read_text()
    text = text.replace('turbulence = "moderate"', 'turbulence = "none"').replace(
        'suite = "default"', 'suite = "default"\nbiases = false')
    sc, _ = loads(text).shortened(12.0)
    res = fly(sc, tmp_path_factory.mktemp("calm"), progress=False)
    sched = linearize_grid(parse_grid_spec("h_ft=10000;vt_kts=400", "f16"), validate=False)
    return read_log(res.log_path), sched, sc.operating_point()


def _open_loop_rms(model, s, shift: int, names=("q_radps", "nz_g")) -> np.ndarray:
    """rms of dy - (linear model driven by du rolled by `shift` samples), 4 s < t < 11 s (the doublet)."""
    ci = [i for i, k in enumerate(model.input_kinds) if k == "control"]
    A, B, C, D = model.A, model.B[:, ci], model.C, model.D[:, ci]
    du = np.roll(s.du, shift, axis=0)
    x = np.zeros(A.shape[0])
    yhat = np.empty_like(s.dy)
    for j in range(s.n):  # the standard form: y_j = C x_j + D u_j, x_{j+1} = A x_j + B u_j
        yhat[j] = C @ x + D @ du[j]
        x = A @ x + B @ du[j]
    w = (s.t_s > 4.0) & (s.t_s < 11.0)
    cols = [s.output_names.index(n) for n in names]
    return np.sqrt(np.mean((s.dy - yhat)[w][:, cols] ** 2, axis=0))


@pytest.mark.parametrize("rate_hz,method", [(20, "step"), (20, "zoh"), (120, "zoh")])
def test_pairing_beats_a_one_sample_shift(calm_flight, rate_hz: int, method: str) -> None:
    log, sched, op = calm_flight
    model = paired_model(sched.model_at(op, dt_s=1.0 / rate_hz, method=method).model, 120.0)
    s = log_samples(log, model, rate_hz)
    right = _open_loop_rms(model, s, 0)
    for shift in (-1, 1):
        wrong = _open_loop_rms(model, s, shift)
        # q and nz: the one-sample shift is worse by at least 15 % on one of them, never better by > 5 %
        assert np.max(wrong / right) > 1.15, (shift, right, wrong)
        assert np.all(wrong / right > 0.95), (shift, right, wrong)


def test_unpaired_zoh_model_is_measurably_worse(calm_flight) -> None:
    """Without :func:`paired_model` a ZOH model at 20 Hz is one sample late (q error about 3 times)."""
    log, sched, op = calm_flight
    zoh = sched.model_at(op, dt_s=1.0 / 20, method="zoh").model
    s = log_samples(log, zoh, 20)
    assert _open_loop_rms(zoh, s, 0)[0] > 2.0 * _open_loop_rms(paired_model(zoh, 120.0), s, 0)[0]


def test_samples_follow_the_convention_on_arrays() -> None:
    """Row k holds (u_k, y_k); sample j = (mean u rows (j-1)n .. jn-1, y row jn)."""
    K, n = 13, 3
    u = np.arange(K, dtype=float)[:, None] * np.array([[1.0, 10.0]])
    y = np.arange(K, dtype=float)[:, None] * np.array([[1.0, -1.0]])
    rows, um = pair_samples(u, y, n)
    assert rows.tolist() == [3, 6, 9, 12]
    assert um[:, 0].tolist() == [1.0, 4.0, 7.0, 10.0]  # mean of 0,1,2 / 3,4,5 / ...

    class M:  # the minimum a model provides to the adaptor
        input_names = ("a_cmd_norm", "gust_fps")
        input_kinds = ("control", "disturbance")
        output_names = ("psi_rad", "q_radps")
        u0 = np.array([0.5, 0.0])
        y0 = np.array([2 * np.pi - 0.01, 0.0])

    yy = np.column_stack([np.full(K, 0.02), np.arange(K) * 0.1, np.zeros(K)])
    valid = np.ones((K, 3), dtype=bool)
    valid[6, 1] = False  # a dropout of q at row 6
    s = samples_from_arrays(120.0, ("a_cmd_norm", "x"), np.column_stack([u[:, 0], u[:, 1]]),
                            ("psi_rad", "q_radps", "extra"), yy, M(), 40.0, valid=valid,
                            sensor_rates_hz={"psi_rad": 20.0})
    assert s.input_names == ("a_cmd_norm",)  # the disturbance column is not a logged command
    assert s.du[:, 0].tolist() == [0.5, 3.5, 6.5, 9.5]
    assert s.t_s.tolist() == pytest.approx([3 / 120, 6 / 120, 9 / 120, 12 / 120])
    assert s.output("psi_rad") == pytest.approx([0.03] * 4)  # 0.02 - (2 pi - 0.01), wrapped
    assert s.valid[:, 1].tolist() == [True, False, True, True]
    assert s.output("q_radps")[1] == 0.0  # an invalid value never enters arithmetic
    assert s.fresh[:, 0].tolist() == [False, True, False, True]  # a 20 Hz sensor at rows 6 and 12


def test_bad_rates_and_missing_signals_are_named(calm_flight) -> None:
    log, sched, op = calm_flight
    model = sched.model_at(op, dt_s=1.0 / 20).model
    with pytest.raises(SampleError, match="does not divide the simulation rate 120 Hz; use one of 120, 60, 40"):
        decimation(120.0, 50.0)
    with pytest.raises(SampleError, match="positive"):
        decimation(120.0, 0.0)
    from dataclasses import replace

    odd = replace(model, output_names=model.output_names[:-1] + ("egt_degc",))
    with pytest.raises(SampleError, match="no measurement 'egt_degc' on /sensors/measurements"):
        log_samples(log, odd, 20)
    at_sim_rate = sched.model_at(op, dt_s=1.0 / 120).model
    assert np.array_equal(paired_model(at_sim_rate, 120.0).C, at_sim_rate.C)  # n = 1: as it is
    paired = paired_model(model, 120.0)  # n = 6: (A, B, C A, C B + D)
    assert np.allclose(paired.C, model.C @ model.A, rtol=0, atol=1e-12)
    assert np.allclose(paired.D, model.C @ model.B + model.D, rtol=0, atol=1e-12)
    assert paired_model(paired, 120.0) is paired  # pairing twice changes nothing
    with pytest.raises(SampleError, match="continuous"):
        paired_model(sched.model_at(op, dt_s=1.0 / 20).model.__class__(
            **{**{f: getattr(model, f) for f in ("A", "B", "C", "D", "state_names", "input_names", "output_names",
                                                  "input_kinds", "x0", "u0", "y0")}, "dt_s": 0.0}), 120.0)

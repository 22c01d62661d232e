"""Balanced truncation (fdi_sim.linear.transform.reduce, SLICOT AB09MD via slycot).

The step model of JSBSim's 120 Hz step has 71-84 states (shift registers, AB3 history); the
detectors want a few. Checked here: the Hankel-norm error bound of balanced truncation
(||G - G_r||_inf <= 2 sum of the discarded Hankel singular values), integrators kept exactly,
and on JSBSim the F-16's reduced step model validating as well as the full one.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft
from fdi_sim.errors import DesignError
from fdi_sim.linear.grid import default_grid_path, load_grid
from fdi_sim.linear.linearize import linearize
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.transform import discretize, reduce
from fdi_sim.linear.validate import compare, default_doublets, fly_doublets
from fdi_sim.operating_point import OperatingPoint


def _freq_gain(m: LinearModel, w: np.ndarray) -> np.ndarray:
    """Largest singular value of G(e^{jw dt}) - or G(jw) - on a frequency grid."""
    out = []
    for wk in w:
        z = np.exp(1j * wk * m.dt_s) if m.is_discrete else 1j * wk
        G = m.C @ np.linalg.solve(z * np.eye(m.n_states) - m.A, m.B) + m.D
        out.append(G)
    return np.array(out)


@pytest.mark.parametrize("discrete", [True, False])
def test_error_is_within_the_hankel_bound_and_integrators_stay(discrete: bool) -> None:
    rng = np.random.default_rng(4)
    n, mi, p = 12, 2, 3
    poles = -np.geomspace(0.05, 40.0, n - 1)
    A = np.diag(np.r_[0.0, poles])  # one integrator (a heading-like state)
    T = rng.normal(size=(n, n))
    A = T @ A @ np.linalg.inv(T)
    B, C, D = rng.normal(size=(n, mi)), rng.normal(size=(p, n)), rng.normal(size=(p, mi))
    m = LinearModel(A=A, B=B, C=C, D=D, input_names=("u0_norm", "u1_norm"), output_names=("y0_ft", "y1_rad", "y2_g"))
    if discrete:
        m = discretize(m, 0.01)
    su, sy = np.array([0.5, 2.0]), np.array([3.0, 0.1, 1.0])
    r = reduce(m, 6, input_scale=su, output_scale=sy)
    assert r.n_states == 6 and r.state_names[0] == "bal0" and r.meta["reduced"]["from_states"] == n
    assert r.meta["reduced"]["unstable_kept"] == 1
    z_int = 1.0 if discrete else 0.0
    assert np.min(np.abs(np.linalg.eigvals(r.A) - z_int)) < 1e-8  # the integrator, exactly
    hsv = np.array(r.meta["reduced"]["hankel_sv"])
    bound = 2.0 * np.sum(hsv[5:])  # 5 stable states kept of 11
    w = np.geomspace(1e-3, 0.99 * np.pi / m.dt_s if discrete else 1e3, 400)
    # the bound holds for the scaled error diag(1/sy) (G - G_r) diag(su); the integrator cancels
    E = (_freq_gain(m, w) - _freq_gain(r, w)) / sy[None, :, None] * su[None, None, :]
    err = np.max(np.linalg.svd(E, compute_uv=False))
    assert err <= bound * (1 + 1e-6) + 1e-9, (err, bound)
    assert err > 0.01 * bound  # and the truncation did remove something
    auto = reduce(m, input_scale=su, output_scale=sy, rel_tol=1e-3)
    assert auto.n_states == 1 + int(np.sum(hsv >= 1e-3 * hsv[0]))


@pytest.mark.parametrize("discrete", [True, False])
def test_modes_slower_than_the_split_are_kept_exactly(discrete: bool) -> None:
    """A stable 500 s mode is slower than ``keep_slower_than_s`` (100 s): kept as it is with the
    integrator, beside the fast part; at 1000 s it is balanced with the rest."""
    poles = np.array([0.0, -1.0 / 500.0, -0.5, -2.0, -8.0, -30.0])
    rng = np.random.default_rng(7)
    m = LinearModel(A=np.diag(poles), B=rng.normal(size=(6, 1)), C=rng.normal(size=(2, 6)), D=np.zeros((2, 1)))
    if discrete:
        m = discretize(m, 0.01)
    r = reduce(m, 4)
    assert r.meta["reduced"]["unstable_kept"] == 2 and len(r.meta["reduced"]["hankel_sv"]) == 4
    slow = np.exp(poles[:2] * 0.01) if discrete else poles[:2]
    eig = np.linalg.eigvals(r.A)
    assert all(np.min(np.abs(eig - z)) < 1e-9 for z in slow), eig
    assert reduce(m, 4, keep_slower_than_s=1000.0).meta["reduced"]["unstable_kept"] == 1


def test_bad_input() -> None:
    m = LinearModel(A=-np.eye(3), B=np.ones((3, 1)), C=np.ones((2, 3)), D=np.zeros((2, 1)))
    with pytest.raises(DesignError, match="between 1 and"):
        reduce(m, 0)
    with pytest.raises(DesignError, match="positive sizes"):
        reduce(m, 2, output_scale=[1.0])


@pytest.mark.parametrize("name, op", [("f16", OperatingPoint("f16", 5000.0, vt_kts=420.0)),
                                      ("DHC6", OperatingPoint("DHC6", 5000.0, vc_kts=120.0))])
def test_step_model_reduced_validates_like_the_full_one(name: str, op: OperatingPoint) -> None:
    """The step model (F-16 84 states, DHC-6 51) keeps its doublet-validation error with about 21
    balanced states at the default tolerance (scales: the doublet amplitudes and the response
    RMS). Measured: F-16 h_ft 1.60 % both; DHC-6 without the throttle run (no linear model holds
    that one) 1.93 % full, 1.92 % reduced. With 10 states the fast modes go."""
    ac = Aircraft(name)
    lp = linearize(ac, op, check_fglin=False)
    m = lp.model
    g = load_grid(default_grid_path(name), name)
    runs = fly_doublets(ac, lp.trim_state, default_doublets(m, g.validation), m.output_names, 10.0)
    full = discretize(m, ac.dt_s, method="step")
    su = np.array([g.validation.amplitudes[n] for n in m.input_names])
    sy = np.sqrt(np.mean(runs.dy**2, axis=(0, 1)))
    red = reduce(full, input_scale=su, output_scale=sy)

    def worst(md: LinearModel) -> float:
        return float(np.max(compare(md, runs).nrmse_without(("throttle_cmd_norm",))))

    # docs/linear.md: F-16 84 -> 21 states, 1.60 % both; DHC-6 51 -> 21, 1.93 % -> 1.92 %
    assert (full.n_states, red.n_states) == ({"f16": 84, "DHC6": 51}[name], 21)
    assert "lag_states" in full.meta and "lag_states" not in red.meta  # the shift registers are gone
    assert worst(full) == pytest.approx({"f16": 0.0160, "DHC6": 0.0193}[name], abs=5e-4)
    assert worst(red) < min(worst(full) + 0.002, 0.05), (worst(full), worst(red))
    assert worst(reduce(full, 10, input_scale=su, output_scale=sy)) > 0.5  # F-16: r_radps 99 %


def test_schedule_gives_reduced_models_scaled_by_its_validation(tmp_path) -> None:
    """``model_at(..., method="step", reduced=True)`` at 20 Hz: about 21 states whose doublet
    response matches the full lifted step model's; a schedule without validation has no scales."""
    from fdi_sim.linear.grid import parse_grid_spec
    from fdi_sim.linear.linearize import linearize_grid
    from fdi_sim.linear.schedule import ModelSchedule
    from fdi_sim.linear.validate import simulate_linear

    grid = parse_grid_spec("h_ft=5000;vt_kts=420", "f16")
    s = ModelSchedule.load(linearize_grid(grid, check_fglin=False).save(tmp_path / "s.npz"))
    op = OperatingPoint("f16", 5000.0, vt_kts=420.0)
    full = s.model_at(op, dt_s=0.05, method="step").model
    red = s.model_at(op, dt_s=0.05, method="step", reduced=True).model
    assert red.dt_s == pytest.approx(0.05) and red.n_states <= 25 < full.n_states
    U = np.zeros((200, full.n_inputs))
    U[10:30, full.input_names.index("rudder_cmd_norm")], U[30:50, full.input_names.index("rudder_cmd_norm")] = 0.01, -0.01
    y_full, y_red = simulate_linear(full, U), simulate_linear(red, U)
    i = full.output_names.index("r_radps")
    assert np.sqrt(np.mean((y_red[:, i] - y_full[:, i]) ** 2)) < 0.01 * np.sqrt(np.mean(y_full[:, i] ** 2))
    bare = linearize_grid(grid, validate=False, check_fglin=False)
    with pytest.raises(DesignError, match="without --no-validate"):
        bare.model_at(op, method="step", reduced=True)

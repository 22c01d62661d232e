"""LMI-optimal detection filter (Miller & Ribbens, App. B, Theorems 5.2.2 / 5.3.2) on the Twin Otter.

The Twin Otter model is ``twin_otter_longitudinal_interim()`` (in ``fdi_sim/papers/twin_otter_interim.py``):
an INTERIM hand-built model from the JSBSim derivatives of JSBSIM_NOTES.md sec. 4.3, to be replaced by
the linearizer's model. Every design takes the model as an argument.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from fdi_sim.detectors.base import Detector
from fdi_sim.detectors.beard_jones import angle_rad
from fdi_sim.detectors.lmi_filter import LmiDetectionFilter, design_lmi_filter, lmi_detection_gain
from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim
from fdi_sim.errors import DesignError

V_TWIN = np.diag([1.0, 0.002, 0.002, 0.002]) ** 2  # sensor noise intensities: 1 ft/s, 2 mrad, 2 mrad/s, 2 mrad
H_RADPS = 20.0
FAULT = "elevator_cmd_norm"


@pytest.fixture(scope="module")
def model():
    return twin_otter_longitudinal_interim()


@pytest.fixture(scope="module")
def ls_design(model):
    return design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, epsilon=1e-7, method="least-squares")


@pytest.fixture(scope="module")
def direct_design(model):
    return design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, method="direct")


def test_interim_model_matches_the_measured_modes(model) -> None:
    ev = np.linalg.eigvals(model.A)
    sp = ev[np.argmax(np.abs(ev))]
    ph = ev[np.argmin(np.abs(ev))]
    assert abs(sp.real + 2.26) < 0.01 and abs(abs(sp.imag) - 2.64) < 0.01  # JSBSIM_NOTES sec. 4.3
    assert abs(ph.real + 0.042) < 1e-4 and abs(abs(ph.imag) - 0.172) < 1e-4
    assert model.A[1, 1] == -1.22 and model.A[2, 1] == -8.8 and model.A[2, 2] == -3.29 and model.B[2, 0] == -1.99
    iced = twin_otter_longitudinal_interim(icing_eta=0.1)
    assert np.isclose(iced.B[2, 0] / model.B[2, 0], 1 - 0.148148)  # AllIce k_Cm_de = -1.48148


def _independent_checks(model, d) -> None:
    A, C = np.asarray(model.A), np.asarray(model.C)
    L = d.L
    ev = np.linalg.eigvals(A - L @ C)
    assert np.all(ev.real < 0) and np.all(ev.real >= -H_RADPS * (1 + 1e-6))  # poles within the bound (eq. 35)
    # ||S(jw)|| <= 1 (eq. 57), S = (I + C (jwI - A)^-1 L)^-1 by direct inversion, V-weighted
    Vh = np.sqrt(V_TWIN)
    for w in np.logspace(-3, 3, 300):
        T = np.eye(4) + C @ np.linalg.inv(1j * w * np.eye(4) - A) @ L
        S = np.linalg.inv(T)
        assert np.linalg.svd(np.linalg.inv(Vh) @ S @ Vh, compute_uv=False)[0] <= 1 + 1e-6
    # L is the Kalman gain of its implied process noise: scipy's ARE solution reproduces it
    Q = d.P @ C.T @ np.linalg.inv(V_TWIN) @ C @ d.P - A @ d.P - d.P @ A.T
    Q = 0.5 * (Q + Q.T)
    assert np.min(np.linalg.eigvalsh(Q)) >= -1e-6 * np.linalg.norm(Q, 2)
    P_are = sla.solve_continuous_are(A.T, C.T, Q + 1e-12 * np.eye(4), V_TWIN)
    L_are = P_are @ C.T @ np.linalg.inv(V_TWIN)
    assert np.linalg.norm(L_are - L) <= 1e-3 * np.linalg.norm(L)


def test_least_squares_theorem_5_2_2_on_twin_otter(model, ls_design) -> None:
    d = ls_design
    assert d.status == "optimal"
    _independent_checks(model, d)
    # alignment error, independently: closest real eigenvector of A - LC to the elevator direction
    f = model.B[:, 0]
    ev, vec = np.linalg.eig(model.A - d.L @ model.C)
    ang = min(np.degrees(angle_rad(vec[:, i].real, f)) for i in range(4) if abs(ev[i].imag) < 1e-9)
    assert abs(ang - d.alignment_error_deg) < 1e-6
    assert ang < 2.0  # the patent reports 1.3 deg for its least-squares variant (App. B, end of sec. 5.3)
    assert d.max_sensitivity <= 1.0


def test_direct_theorem_5_3_2_aligns_exactly(model, direct_design, ls_design) -> None:
    d = direct_design
    _independent_checks(model, d)
    assert d.alignment_error_deg < 1e-4
    lam = d.Lambda[0, 0]
    f = model.B[:, 0] / np.linalg.norm(model.B[:, 0])
    assert np.linalg.norm((model.A - d.L @ model.C) @ f - lam * f) < 1e-6 * abs(lam)
    # App. B, end of sec. 5.3: "the different values for the trace of P differed by only 0.04, and the
    # eigenvalues were also essentially the same" (the patent's Twin Otter; ours is the interim model)
    assert abs(np.trace(d.P) - np.trace(ls_design.P)) < 0.04
    assert np.allclose(np.sort(d.poles.real), np.sort(ls_design.poles.real), rtol=0.05)


def test_literal_theorem_5_2_2_can_lose_the_sensitivity_bound(model) -> None:
    # eq. 41-44 as printed, W free: at h = 10 the maximal P is no Riccati solution and ||S|| > 1;
    # the design refuses to return it
    with pytest.raises(DesignError, match=r"sigma\(S\)"):
        design_lmi_filter(model, FAULT, V_TWIN, 10.0, epsilon=1e-7, method="literal")
    d = design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, epsilon=1e-7, method="literal")
    _independent_checks(model, d)
    # the returned W satisfies eq. 42 in the model's coordinates: [[A P + P A' + G W G', P C'], [C P, V]] >= 0
    A, C, P = np.asarray(model.A), np.asarray(model.C), d.P
    ric = np.block([[A @ P + P @ A.T + d.W, P @ C.T], [C @ P, V_TWIN]])
    assert np.min(np.linalg.eigvalsh(0.5 * (ric + ric.T))) >= -1e-9 * np.linalg.norm(ric, 2)


def test_infeasible_lmi_is_reported_never_returned(model) -> None:
    with pytest.raises(DesignError, match="infeasible"):
        design_lmi_filter(model, FAULT, V_TWIN, 1.0, method="direct", )


def test_bad_inputs(model) -> None:
    A, C = np.asarray(model.A), np.asarray(model.C)
    x = np.asarray(model.B[:, [0]])
    with pytest.raises(DesignError, match="positive definite"):
        lmi_detection_gain(A, C, x, np.eye(4), -V_TWIN, 20.0)
    with pytest.raises(DesignError, match="h must be > 0"):
        lmi_detection_gain(A, C, x, np.eye(4), V_TWIN, 0.0)
    with pytest.raises(DesignError, match="continuous"):
        design_lmi_filter(model.discretize(0.01), FAULT, V_TWIN, 20.0)
    with pytest.raises(DesignError, match="not observable"):
        lmi_detection_gain(np.diag([-1.0, -2.0]), np.array([[1.0, 0.0]]), np.eye(2)[:, :1], np.eye(2), np.eye(1), 5.0)
    with pytest.raises(DesignError, match="k = 2"):
        lmi_detection_gain(A, C, np.eye(4)[:, :2], np.eye(4), V_TWIN, 20.0)


def test_runtime_filter_points_at_the_elevator(model, direct_design) -> None:
    dt = 1 / 120
    Rd = np.diag([0.1, 0.002, 0.002, 0.002]) ** 2  # per-sample sensor noise covariance
    filt = LmiDetectionFilter(model, direct_design, FAULT, dt, alpha=1e-3, Rd=Rd)
    assert isinstance(filt, Detector)
    filt.reset(np.random.default_rng(0))
    md = model.discretize(dt)
    x = np.zeros(4)
    res = []
    for k in range(480):
        t = k * dt
        u = np.array([0.05 * np.sin(2 * t), 0.0])
        uf = u + (np.array([0.1, 0.0]) if t >= 1.0 else 0.0)
        res.append(filt.step(t, u + model.u0, md.C @ x + model.y0))
        x = md.A @ x + md.B @ uf
    # ZOH-discretized continuous observer: before the fault the residual is small (not zero), well under the noise
    assert max(np.linalg.norm(r.r[1:]) for r in res if r.t_s < 1.0) < 0.1 * np.sqrt(Rd[1, 1])
    late = [r for r in res if r.t_s > 1.5]
    assert all(r.alarm for r in late) and {r.isolation for r in late} == {FAULT}
    assert max(r.scores[0] for r in late) < np.radians(3.0)


@pytest.mark.slow
def test_lmi_on_the_linearizer_model() -> None:
    """Same bar on the project linearizer's DHC-6 (5000 ft, 120 KIAS), longitudinal block, C = I."""
    from fdi_sim.aircraft.model import Aircraft
    from fdi_sim.linear.linearize import linearize
    from fdi_sim.linear.model import LinearModel
    from fdi_sim.operating_point import OperatingPoint

    lp = linearize(Aircraft("DHC6"), OperatingPoint("DHC6", h_ft=5000.0, vc_kts=120.0))
    full = lp.model
    names = ("vt_fps", "alpha_rad", "q_radps", "theta_rad")
    ix = [full.state_names.index(s) for s in names]
    A = full.A[np.ix_(ix, ix)]
    B = full.B[np.ix_(ix, [full.input_names.index(FAULT)])]
    m = LinearModel(A=A, B=B, C=np.eye(4), D=np.zeros((4, 1)), state_names=names, input_names=(FAULT,), output_names=names)
    d = design_lmi_filter(m, FAULT, V_TWIN, H_RADPS, epsilon=1e-7)
    _independent_checks(m, d)
    assert d.alignment_error_deg < 2.0  # measured 0.88 deg


def test_a_repeated_design_is_the_same_solution_read_only(model, ls_design, direct_design) -> None:
    """The solve is kept by its inputs (a study worker designs the same filter for every run of a
    point): the same inputs give the same design without a second solve, equal bit for bit to a
    fresh solve, and nobody can change it in place; other inputs are solved again."""
    import fdi_sim.detectors.lmi_filter as lf

    again = design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, epsilon=1e-7, method="least-squares")
    assert again is ls_design
    with pytest.raises(ValueError, match="read-only"):
        again.L[0, 0] = 0.0
    saved = dict(lf._GAIN_MEMO)
    lf._GAIN_MEMO.clear()
    try:
        fresh = design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, epsilon=1e-7, method="least-squares")
    finally:
        lf._GAIN_MEMO.clear()
        lf._GAIN_MEMO.update(saved)
    assert fresh is not ls_design
    for name in ("L", "P", "W", "A_cl", "poles"):
        assert np.array_equal(getattr(fresh, name), getattr(ls_design, name)), name
    other = design_lmi_filter(model, FAULT, V_TWIN, H_RADPS, method="direct")  # another method: its own solve
    assert other is direct_design and other is not ls_design

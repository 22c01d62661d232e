"""Robust parity on the JSBSim DHC-6, clean and iced (issue 5 bar; docs/parity.md, "DHC-6 on JSBSim").

Real JSBSim flights throughout. The default tests fly eleven flights of 40 s or less in calm air;
the slow test flies the whole study of the docs (two conditions, 88 two-minute flights each, and
20 fresh iced flights).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.linalg as sl
from scipy import stats

from fdi_sim.papers.dhc6_icing_flights import (
    LON_OUTPUTS,
    FlightPlan,
    StudyConfig,
    elevator_gearing,
    elevator_gearing_inverse,
    fly,
    fly_all,
    linearize_models,
    windows,
)
from fdi_sim.papers.dhc6_icing_study import (
    Relations,
    calibrate,
    choose_n_relations,
    evaluate,
    false_alarm_rate,
    robust_relations_with_offsets,
    run_study,
    statistics,
    trim_offset_window,
)
from fdi_sim.detectors.robust_parity import design_block, example_icing_models, robust_parity
from fdi_sim.flightlog import read_log

CALM = StudyConfig(turbulence="none", fault_bias_deg=0.25, duration_s=40.0, fault_start_s=15.0)


@pytest.fixture(scope="module")
def models():
    """Clean, eta 0.05 and eta 0.1 models of 5000 ft / 100 KIAS (about 0.2 s)."""
    return linearize_models(CALM)


@pytest.fixture(scope="module")
def calm_flights(tmp_path_factory):
    """2 training, 1 + 1 faulty and 3 x 2 fault-free 40 s flights in calm air (about 8 s)."""
    plan = FlightPlan(train=(1, 2), detect=(3,), test=(5, 6))
    return fly_all(CALM, plan, tmp_path_factory.mktemp("calm"))


# ---------------------------------------------------------------------------- no JSBSim
def test_gearing_is_the_dhc6_aerosurface_scale_and_inverts():
    """-0.454 rad at c = -1, +0.244 rad at c = +1, linear on each side, clipped beyond (Conventional Controls.xml)."""
    c = np.array([-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(elevator_gearing(c), [-0.454, -0.454, -0.227, 0, 0.122, 0.244, 0.244], atol=1e-15)
    d = np.linspace(-0.45, 0.24, 50)
    np.testing.assert_allclose(elevator_gearing(elevator_gearing_inverse(d)), d, atol=1e-15)


def test_offsets_zero_gives_robust_parity_and_large_offsets_are_nulled():
    """With m_q = 0 the design equals robust_parity (span and sigma); with large m_q the relations are
    orthogonal to every m_q, and ||P'T||^2 is the sum of the p smallest eigenvalues of T T' built by hand
    (numpy eigvalsh, independent of the SVD)."""
    ms = example_icing_models()
    noise = dict(input_sqrt=np.diag([0.05, 0.1]), disturbance_sqrt=np.array([[2.0]]),
                 measurement_sqrt=np.diag([0.05, 5e-4, 5e-4, 5e-4, 0.02]))
    scales = dict(output_scale=np.diag(noise["measurement_sqrt"]), input_scale=np.array([0.05, 0.1]))
    M = np.eye(4)
    N = 3 * 5 + 3 * 2
    ref = robust_parity(ms, 2, 4, None, M, "known", **noise, **scales)
    zero = robust_relations_with_offsets(ms, 2, 4, [np.zeros(N)] * 3, state_sqrt=M, **noise, **scales)
    assert np.max(sl.subspace_angles(ref.P, zero.P)) < 1e-8
    np.testing.assert_allclose(zero.sigma_sq[:6], ref.sigma_sq[:6], rtol=1e-9, atol=1e-20)
    rng = np.random.default_rng(3)
    offs = [np.zeros(N)] + [1e3 * rng.standard_normal(N) for _ in range(2)]
    rel = robust_relations_with_offsets(ms, 2, 4, offs, state_sqrt=M, **noise, **scales)
    scale = np.concatenate([np.tile(scales["output_scale"], 3), np.tile(scales["input_scale"], 3)])
    U = rel.P * scale[:, None]  # orthonormal relations in scaled units
    np.testing.assert_allclose(U.T @ U, np.eye(4), atol=1e-10)
    for m in offs[1:]:
        assert np.linalg.norm(U.T @ (m / scale)) < 1e-6 * np.linalg.norm(m / scale)
    TT = sum((design_block(q, 2, M, "known", **noise) @ design_block(q, 2, M, "known", **noise).T + np.outer(m, m)) / 3
             for q, m in zip(ms, offs))
    TT = TT / np.outer(scale, scale)
    assert np.sum((U.T @ TT) * U.T) == pytest.approx(np.sum(np.linalg.eigvalsh(TT)[:4]), rel=1e-6)


def test_statistic_is_the_moving_average_chi_square():
    """t(k) = ||sqrt(n) mean(z(k-n+1..k))||^2 with z the whitened residual, checked by a direct loop."""
    rng = np.random.default_rng(4)
    P = rng.standard_normal((6, 2))
    X = rng.standard_normal((50, 6))
    rel = Relations("x", P)
    cal = calibrate(rel, rng.standard_normal((400, 6)))
    z = (X @ P - cal.mean) @ cal.whiten.T
    t = statistics(rel, cal, X, 5)
    for k in range(50):
        zz = z[max(0, k - 4): k + 1]
        assert t[k] == pytest.approx(len(zz) * np.sum(zz.mean(0) ** 2), rel=1e-10)
    r_train = rng.standard_normal((4000, 6)) @ P
    cal = calibrate(rel, rng.standard_normal((4000, 6)))
    np.testing.assert_allclose(np.cov(((r_train - cal.mean) @ cal.whiten.T).T), np.eye(2), atol=0.1)


def test_false_alarm_counting_and_intervals():
    """Rates, onsets and the exact Poisson interval checked with scipy.stats.poisson at its ends."""
    t = [np.array([0, 2, 2, 0, 2, 0, 0, 0.0]), np.array([2, 0, 0, 0.0])]
    fa = false_alarm_rate(t, 1.0, 0.05, np.random.default_rng(5), n_boot=2000)
    assert fa.rate == pytest.approx(4 / 12)
    np.testing.assert_allclose(fa.per_flight, [3 / 8, 1 / 4])
    k = 3  # onsets: two in the first flight, one at the start of the second
    assert fa.hours == pytest.approx(12 * 0.05 / 3600)
    assert fa.onsets_per_hour == pytest.approx(k / fa.hours)
    lo, hi = fa.onsets_ci[0] * fa.hours, fa.onsets_ci[1] * fa.hours
    assert stats.poisson.sf(k - 1, lo) == pytest.approx(0.025, rel=1e-6)  # P(X >= k | lo)
    assert stats.poisson.cdf(k, hi) == pytest.approx(0.025, rel=1e-6)     # P(X <= k | hi)
    assert 0.25 <= fa.ci[0] <= fa.rate <= fa.ci[1] <= 0.375


# ---------------------------------------------------------------------------- JSBSim
def test_models_share_signals_and_convert_the_elevator_column(models):
    """Same signals for every eta; the elevator column is the command column divided by 0.244 rad
    (the slope the linearizer differenced: every trim has c > 0); u0 is g(pitch trim)."""
    assert models.etas == (0.0, 0.05, 0.1)
    assert [m.output_names for m in models.lon] == [LON_OUTPUTS] * 3
    assert all(0.0 < c < 0.1 for c in models.pitch_trim_cmd_norm)
    assert models.pitch_trim_cmd_norm[2] > models.pitch_trim_cmd_norm[0] + 0.04  # iced: 0.057 against 0.012
    for m_full, m, pt in zip(models.full, models.lon, models.pitch_trim_cmd_norm):
        k = m.meta["elevator_slope_rad_per_norm"]
        assert k == pytest.approx(0.244, rel=1e-9)
        assert m.u0[0] == pytest.approx(pt * 0.244, rel=1e-9)
        c = m_full.discretize(CALM.dt_s)  # same ZOH on the full model: the lon states' rows, elevator column
        xs = [m_full.state_names.index(s) for s in m.state_names]
        ys = [m_full.output_names.index(o) for o in m.output_names]
        j = m_full.input_names.index("elevator_cmd_norm")
        np.testing.assert_allclose(m.D[:, 0] * k, m_full.D[ys, j], atol=1e-12)
        # truncating the lateral states changes the discrete column only through the weak coupling
        np.testing.assert_allclose(m.B[:, 0] * k, c.B[xs, j], rtol=0.02, atol=1e-6)
    assert np.max(np.abs(models.lon[2].A - models.lon[0].A)) > 1e-3  # icing changes the dynamics


def test_log_gives_gearing_and_pitch_trim_exactly(models, tmp_path):
    """On a real iced flight with an elevator bias from t = 3 s: the pitch trim read from the log is
    the linearizer's eta 0.1 trim, and surface = g(cmd + trim) before the fault, + bias after."""
    cfg = dataclasses.replace(CALM, duration_s=6.0, fault_start_s=3.0, fault_bias_deg=1.0)
    fs = fly(cfg, 0.1, 11, True, tmp_path)
    assert fs.pitch_trim_cmd_norm == pytest.approx(models.pitch_trim_cmd_norm[2], abs=1e-6)  # same trim, to its tolerance
    log = read_log(next(tmp_path.glob("*.mcap")))
    cmd = log.topics["/commands/pilot"]["elevator_cmd_norm"][:-1]
    surf = log.topics["/truth/surfaces"]
    err = surf["elevator_pos_rad"] - elevator_gearing(cmd + fs.pitch_trim_cmd_norm)
    before, after = surf.t_s < 3.0 - 1e-9, surf.t_s > 3.0 + 0.02
    assert np.max(np.abs(err[before])) < 1e-9
    # the bias law acts on the healthy position of the previous frame (docs/faults.md: one-frame lag)
    lagged = surf["elevator_pos_rad"][1:] - elevator_gearing(cmd[:-1] + fs.pitch_trim_cmd_norm)
    np.testing.assert_allclose(lagged[after[1:]], np.radians(1.0), atol=1e-9)
    assert fs.fault[fs.t_s >= 3.0].all() and not fs.fault[fs.t_s < 3.0].any()
    assert fs.y.shape == (len(fs.t_s), len(LON_OUTPUTS)) and np.allclose(np.diff(fs.t_s), CALM.dt_s)
    # calm air: the Earth-relative vt and alpha rebuilt from (u, v, w) are JSBSim's air-relative ones
    truth = log.topics["/truth/state"]
    k = np.searchsorted(truth.t_s, fs.t_s)
    np.testing.assert_allclose(fs.truth_x[:, 0], truth["vt_fps"][k], rtol=1e-9)
    np.testing.assert_allclose(fs.truth_x[:, 1], truth["alpha_rad"][k], atol=1e-9)


def test_iced_residual_shift_is_the_trim_offset(models, calm_flights):
    """Calm air, nominal relations: the mean residual on eta 0.1 flights (whitened on clean ones) is the
    linear models' trim offset W P' m_q within 15 % and far above its clean value, while its covariance
    stays that of clean flight; the robust relations with the iced trims (robust+trim) remove the shift.
    Checked here by hand from the windows, against the study's own diagnostic."""
    cfg = CALM
    clean = models.lon[0]
    res = evaluate(cfg, models, calm_flights, np.random.default_rng(6))
    m01 = trim_offset_window(models.lon[2], clean, cfg.order_s)
    shift = {}
    for name in ("nominal", "robust+trim"):
        rel, cal = res.relations[name], res.calibration[name]
        z = np.vstack([(windows(f, clean, cfg.order_s, cfg.skip_s)[0] @ rel.P - cal.mean) @ cal.whiten.T
                       for f in calm_flights["eta0.1"]])
        pred = (m01 @ rel.P) @ cal.whiten.T
        shift[name] = (np.sum(z.mean(0) ** 2), np.sum(pred**2), np.trace(np.cov(z.T)))
        d = res.shift[name]["eta0.1"]
        assert (d.measured, d.predicted, d.cov_trace) == pytest.approx(shift[name], rel=1e-9)
    measured, predicted, trace = shift["nominal"]
    assert measured > 20.0  # per window, in units of the clean residual's variance
    assert measured == pytest.approx(predicted, rel=0.15)
    assert res.shift["nominal"]["eta0"].measured < 0.05 * measured
    n = res.relations["nominal"].n_relations
    assert 0.7 * n < trace < 1.3 * n  # the dynamics change is not what alarms
    assert shift["robust+trim"][0] < 0.01 * measured and shift["robust+trim"][1] < 1e-3 * predicted


def test_calm_air_equal_detection_false_alarms(models, calm_flights):
    """The docs' calm-air result in small: at equal detection (0.9) of a 0.25 deg elevator bias on clean
    flights, nominal and Lou's robust relations alarm on nearly every eta 0.1 window, the robust relations
    with the iced trims on few."""
    res = evaluate(CALM, models, calm_flights, np.random.default_rng(7))
    key = ("fault_eta0", "eta0.1")
    for name, r in res.results.items():
        assert r.detection["fault_eta0"] == pytest.approx(0.9, abs=0.01), name
    nom, rob, trim = (res.results[n].false_alarms[key] for n in ("nominal", "robust", "robust+trim"))
    assert nom.rate > 0.9 and rob.rate > 0.9
    # robust+trim measurably below nominal. Since the DHC-6 engine gauges joined the sensor suite the
    # noise draws of a seed differ: seeds 5, 6 give 0.31 [0.20, 0.42]; 5-8 0.27, 7-8 0.23, 9-10 0.20
    # (nominal 1.0 everywhere), so the bound is the comparison, not a number of the old draws
    assert trim.ci[1] < 0.5 < nom.ci[0]


@pytest.mark.slow
def test_docs_study_numbers(tmp_path):
    """The full study of docs/parity.md (about 7 min): light turbulence with a 2 deg bias, calm air with a
    0.25 deg bias; thresholds for 0.9 detection on clean faulty flights. With p = 17 (fixed beforehand) no
    robust set is measurably better than the nominal one in light turbulence, and in calm air only the
    design with the iced trims is; with p chosen on the study's flights, Lou's robust relations are
    measurably better on 20 fresh iced flights than the nominal ones and than the clean-only control."""
    key = ("fault_eta0", "eta0.1")
    cfg = StudyConfig(turbulence="light", fault_bias_deg=2.0)
    ms = linearize_models(cfg)
    flights = fly_all(cfg, FlightPlan(), tmp_path / "light")
    light = evaluate(cfg, ms, flights, np.random.default_rng(2024))
    nom, rob, trim = (light.results[n].false_alarms[key] for n in ("nominal", "robust", "robust+trim"))
    assert 0.1 < nom.rate < 0.7  # an informative comparison: neither never nor always
    assert not rob.ci[1] < nom.ci[0] and not trim.ci[1] < nom.ci[0]  # neither robust set measurably lower
    rng = np.random.default_rng(2027)
    fresh = [fly(cfg, 0.1, seed, False, tmp_path / "fresh") for seed in range(9000, 9020)]
    test = {**flights, "eta0.1": fresh}
    nom_fresh = evaluate(cfg, ms, test, rng).results["nominal"].false_alarms[key]
    fa_fresh = {}
    for name in ("robust", "robust-clean"):
        p, _ = choose_n_relations(cfg, ms, flights, rng, name)
        fa_fresh[name] = evaluate(cfg, ms, test, rng, n_relations=p).results[name].false_alarms[key]
    assert fa_fresh["robust"].ci[1] < nom_fresh.ci[0]
    assert fa_fresh["robust"].ci[1] < fa_fresh["robust-clean"].ci[0]
    calm = run_study(StudyConfig(turbulence="none", fault_bias_deg=0.25), FlightPlan(), tmp_path / "calm",
                     np.random.default_rng(2025))
    nom, rob, trim = (calm.results[n].false_alarms[key] for n in ("nominal", "robust", "robust+trim"))
    assert nom.rate > 0.99 and rob.rate > 0.99
    # docs: robust+trim removes most calm-air alarms at p = 17, 0.176 [0.148, 0.207] (docs script; 0.206 upper
    # end with this test's bootstrap), re-measured after the engine gauges changed the DHC-6 noise draws
    # (0.104 [0.086, 0.125] before): below a quarter of the windows, and measurably below nominal
    assert trim.ci[1] < 0.25 < nom.ci[0]

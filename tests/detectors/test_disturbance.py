"""The detectors' turbulence model against JSBSim's own (fdi_sim.detectors.disturbance).

Flights: real JSBSim, trimmed with ``fdi_sim.aircraft.trim``, stepped at 120 Hz with the
integrators off (the aircraft held at its trim state, FGWinds running every step), no steady wind (JSBSim's wind azimuth ``psiw`` = 0: turbulence u is north, v east, w down). What is
read is what JSBSim applies: ``atmosphere/total-wind-{north,east,down}-fps`` and
``atmosphere/{p,q,r}-turb-rad_sec`` (body axes; turned back to local axes with the flown attitude,
since JSBSim forms them in local axes and applies ``Tl2b``).

Three checks per flight:

* one step of JSBSim's recursion: ``e = (xi[k] - a xi[k-1]) / b`` with ``a, b`` from our parameters
  at the airspeed JSBSim used (``Vt`` of the previous step) must be unit white noise: its variance
  within 5 sd of 1 (sd ``sqrt(2/N)``, N samples), and ``q, r`` must follow the high-pass of ``w, v``
  (deterministic in JSBSim) to 1 % rms;
* rms against the shaping filter's stationary prediction: for a process with autocorrelation
  ``exp(-|t|/tau)`` flown for ``T`` seconds the sample variance has relative sd ``sqrt(2 tau/T)``
  (``(2/T) int rho^2 dt``), the rms half that: tolerance 3 sd, ``3 sqrt(tau/(2T))`` (F-16 u: 8 % sd,
  DHC-6 u: 14 % sd at 200 s, i.e. 25 and 8 correlation times);
* 1/e time: the sample autocorrelation at the predicted 1/e lag has Bartlett's AR(1) variance
  ``[(1+phi^2)(1-phi^2k)/(1-phi^2) - 2k phi^2k] / N``; turned into time by the slope ``-1/(e tau)``:
  tolerance 3 sd.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from fdi_sim.aircraft.model import TURBULENCE_LEVELS
from fdi_sim.detectors.disturbance import (
    GUST_INPUTS, DisturbanceError, TURBULENCE_SETTINGS, augment_with_gusts, augment_with_sensor_biases,
    dryden_parameters, dryden_shaping_filter, euler_to_body, poe_sigma_fps,
)
from fdi_sim.linear.model import LinearModel
from fdi_sim.operating_point import OperatingPoint

DT_S = 1.0 / 120.0
POINTS = {"f16": OperatingPoint("f16", 10000.0, vt_kts=400.0), "DHC6": OperatingPoint("DHC6", 5000.0, vc_kts=120.0)}
PROPS = ("atmosphere/total-wind-north-fps", "atmosphere/total-wind-east-fps", "atmosphere/total-wind-down-fps",
         "atmosphere/p-turb-rad_sec", "atmosphere/q-turb-rad_sec", "atmosphere/r-turb-rad_sec",
         "attitude/phi-rad", "attitude/theta-rad", "attitude/psi-rad", "velocities/vt-fps", "position/h-sl-ft")


def fly(op: OperatingPoint, level: str, t_s: float, seed: int) -> tuple[np.ndarray, float]:
    """Gusts in local axes ``xi`` (N, 6), Vt and h (N, 2) flown, and the wing span [ft]."""
    ac = Aircraft(op.aircraft, DT_S)
    trim(ac, op)
    ac.set_atmosphere(Atmosphere(level), seed)
    # integrators off (code 0, "none"): the aircraft stays at its trim state while FGWinds runs every
    # step; open loop in moderate turbulence both aircraft depart within 200 s (NaN on the DHC-6),
    # and the gusts depend on the flight only through Vt, h and the attitude
    for kind in ("rate/rotational", "rate/translational", "position/rotational", "position/translational"):
        ac[f"simulation/integrator/{kind}"] = 0
    assert ac["atmosphere/turb-type"] == 3 and ac["atmosphere/turbulence/milspec/severity"] == TURBULENCE_SETTINGS[level][0]
    get = [ac.node(p).get_double_value for p in PROPS]
    n = int(round(t_s / DT_S))
    rec = np.empty((n + 1, len(PROPS)))
    rec[0] = [g() for g in get]
    for k in range(n):
        assert ac.step()
        rec[k + 1] = [g() for g in get]
    xi = rec[:, :6].copy()
    for k in range(n + 1):  # vTurbPQR = Tl2b [xi_p, xi_q, xi_r]: back to local axes
        xi[k, 3:] = euler_to_body(*rec[k, 6:9]).T @ rec[k, 3:6]
    span = ac["metrics/bw-ft"]
    return np.hstack([xi, rec[:, 9:11]]), span


def test_turbulence_levels_are_the_adapters() -> None:
    assert TURBULENCE_SETTINGS == TURBULENCE_LEVELS


def test_parameters_follow_jsbsims_formulas_by_hand() -> None:
    """Hand values from FGWinds: above 2000 ft the POE table, below the low-altitude laws."""
    p = dryden_parameters(10000.0, 675.0, "light", 30.0)
    assert p.sigma_u_fps == pytest.approx(6.7 + (10000 - 7500) / 7500 * (4.6 - 6.7))  # row 3, 7500..15000 ft
    assert p.L_u_ft == p.L_w_ft == 1750.0 and p.tau_u_s == pytest.approx(1750.0 / 675.0)
    assert p.sigma_p_radps == pytest.approx(1.9 / math.sqrt(1750.0 * 30.0) * p.sigma_w_fps)
    lo = dryden_parameters(500.0, 200.0, "moderate", 65.0)
    w20 = 30.0 * 1.6878098571
    assert lo.sigma_w_fps == pytest.approx(0.1 * w20, rel=1e-6)
    assert lo.L_u_ft == pytest.approx(500.0 / (0.177 + 0.000823 * 500.0) ** 1.2)
    mid = dryden_parameters(1500.0, 200.0, "moderate", 65.0)
    assert mid.L_w_ft == pytest.approx(1375.0)
    assert mid.sigma_u_fps == pytest.approx(0.1 * w20 + 0.5 * (poe_sigma_fps(4, 1500.0) - 0.1 * w20), rel=1e-6)
    assert poe_sigma_fps(4, 100.0) == 8.6 and poe_sigma_fps(4, 90000.0) == 0.0  # clamped as FGTable
    assert dryden_parameters(5000.0, 200.0, "none", 65.0).sigma_w_fps == 0.0
    with pytest.raises(DisturbanceError, match="unknown turbulence level"):
        dryden_parameters(5000.0, 200.0, "stormy", 65.0)


def _check_recursion(x: np.ndarray, span_ft: float, level: str) -> dict[str, float]:
    """Normalized one-step residuals of JSBSim's recursion with our parameters (variance per axis)."""
    V = x[:-1, 6]  # JSBSim's in.V: Vt of the previous step
    h = x[1:, 7]  # in.AltitudeASL: after this step's propagation
    pars = [dryden_parameters(hk, vk, level, span_ft) for hk, vk in zip(h, V)]
    out = {}
    for i, name, sig, tau, two in ((0, "u", "sigma_u_fps", "tau_u_s", 1), (1, "v", "sigma_v_fps", "tau_u_s", 2),
                                   (2, "w", "sigma_w_fps", "tau_w_s", 2), (3, "p", "sigma_p_radps", "tau_p_s", 1)):
        a = np.array([1 - two * DT_S / getattr(p, tau) for p in pars])
        b = np.array([getattr(p, sig) * math.sqrt(2 * two * DT_S / getattr(p, tau)) for p in pars])
        out[name] = float(np.var((x[1:, i] - a * x[:-1, i]) / b))
    for i, j, c, tau in ((4, 2, math.pi / 4 / span_ft, "tau_q_s"), (5, 1, math.pi / 3 / span_ft, "tau_r_s")):
        a = np.array([1 - DT_S / getattr(p, tau) for p in pars])
        err = x[1:, i] - a * x[:-1, i] - c * (x[1:, j] - x[:-1, j])
        out["qr"[i - 4]] = float(np.std(err) / np.std(x[:, i]))
    return out


def _acf_1e(x: np.ndarray, max_lag: int) -> float:
    """First lag [s] where the sample autocorrelation falls below 1/e (linear interpolation)."""
    x = x - x.mean()
    r = np.array([np.dot(x[: len(x) - k], x[k:]) for k in range(max_lag)]) / np.dot(x, x)
    k = int(np.argmax(r < 1 / math.e))
    return (k - 1 + (r[k - 1] - 1 / math.e) / (r[k - 1] - r[k])) * DT_S


def _bartlett_sd_s(tau_s: float, T_s: float) -> float:
    """sd [s] of the estimated 1/e time of an AR(1) with time constant tau flown T seconds."""
    phi, k, N = math.exp(-DT_S / tau_s), tau_s / DT_S, T_s / DT_S
    var = ((1 + phi**2) * (1 - phi ** (2 * k)) / (1 - phi**2) - 2 * k * phi ** (2 * k)) / N
    return math.sqrt(var) * tau_s * math.e  # d rho / dt = -rho / tau = -1 / (e tau) at t = tau


MEASURED: dict[tuple[str, str], dict[str, tuple[float, float, float, float]]] = {}


@pytest.mark.parametrize("level", ["light", "moderate"])
@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_flown_gusts_match_the_shaping_filter(aircraft: str, level: str) -> None:
    T_s = 200.0
    x, span = fly(POINTS[aircraft], level, T_s, seed=11)
    res = _check_recursion(x, span, level)
    tol_var = 5 * math.sqrt(2 / (len(x) - 1))
    for ax in "uvwp":
        assert abs(res[ax] - 1.0) < tol_var, (ax, res)
    # q, r: JSBSim's high-pass of w, v, deterministic; what is left (0.14 % rms on the F-16) is the
    # back-turn of the body rates with the attitude as read after the step
    assert res["q"] < 0.01 and res["r"] < 0.01, res
    p = dryden_parameters(float(np.mean(x[:, 7])), float(np.mean(x[:, 6])), level, span)
    st = dryden_shaping_filter(p).statistics()
    rows = {}
    for i, name in enumerate(st.names):
        rms_pred, t_pred = st.of(name)
        rms = float(np.sqrt(np.mean(x[:, i] ** 2)))
        t_meas = _acf_1e(x[:, i], int(4 * t_pred / DT_S) + 10)
        rows[name] = (rms, rms_pred, t_meas, t_pred)
        tau = t_pred if name[0] in "uvwp" else p.tau_w_s / 2  # q, r follow w, v: their slow part
        assert abs(rms / rms_pred - 1) < 3 * math.sqrt(tau / (2 * T_s)), (name, rms, rms_pred)
        if name[0] in "uvwp":  # first-order processes: Bartlett's variance applies
            assert abs(t_meas - t_pred) < 3 * _bartlett_sd_s(t_pred, T_s), (name, t_meas, t_pred)
    MEASURED[(aircraft, level)] = rows
    print(aircraft, level, {k: tuple(round(v, 4) for v in r) for k, r in rows.items()})


@pytest.mark.parametrize("h_ft", [800.0, 1500.0])
def test_low_altitude_laws_match_jsbsim(h_ft: float) -> None:
    """Below 2000 ft (the h <= 1000 law and the 1000-2000 ft blend): one-step residuals, 30 s."""
    x, span = fly(OperatingPoint("DHC6", h_ft, vc_kts=120.0), "moderate", 30.0, seed=3)
    res = _check_recursion(x, span, "moderate")
    tol_var = 5 * math.sqrt(2 / (len(x) - 1))
    for ax in "uvwp":
        assert abs(res[ax] - 1.0) < tol_var, (ax, res)


def test_sampled_filter_keeps_the_statistics() -> None:
    """At 20 Hz (6 simulation steps) the sampled process has the same covariance."""
    p = dryden_parameters(10000.0, 675.0, "moderate", 30.0)
    f1, f6 = dryden_shaping_filter(p), dryden_shaping_filter(p, dt_s=6 * DT_S)
    np.testing.assert_allclose(f6.stationary_covariance(), f1.stationary_covariance(), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(f6.A, np.linalg.matrix_power(f1.A, 6))
    with pytest.raises(DisturbanceError, match="whole multiple"):
        dryden_shaping_filter(p, dt_s=0.013)


def _toy_model() -> LinearModel:
    """A 2-state discrete model with the linearizer's gust columns (names as the linearizer's)."""
    names = ("alpha_rad", "q_radps")
    A = np.array([[0.99, 0.008], [-0.02, 0.98]])
    B = np.array([[0.001, 0.0, 0.0, 0.0, 1e-5, 0.0, 2e-5], [0.05, 0.0, 0.0, 0.0, 1e-4, 0.0, -3e-4]])
    C = np.array([[1.0, 0.0], [0.0, 1.0]])
    D = np.zeros((2, 7))
    D[0, 6] = -1.0 / 675.0  # alpha measured in the air: -w_gust / V
    return LinearModel(A=A, B=B, C=C, D=D, dt_s=DT_S, state_names=names, output_names=names,
                       input_names=("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
                       + GUST_INPUTS, input_kinds=("control",) * 4 + ("disturbance",) * 3)


def test_augmentation_structure() -> None:
    m = _toy_model()
    p = dryden_parameters(10000.0, 675.0, "light", 30.0)
    aug = augment_with_gusts(m, p)
    aug = augment_with_sensor_biases(aug, ["q_radps"], 0.002)
    am = aug.model
    assert am.n_states == 2 + 6 + 1 and am.state_names[-1] == "bias_q_radps"
    f = dryden_shaping_filter(p)
    iw = 2 + 2  # xi_w
    # the w gust drives the plant through the model's w column: x(k+1) += B_w xi_w (psi = theta = 0 here)
    np.testing.assert_allclose(am.A[:2, iw], m.B[:, 6])
    np.testing.assert_allclose(am.C[0, iw], m.D[0, 6])
    np.testing.assert_allclose(aug.Q[2:8, 2:8], f.B @ f.B.T)
    assert aug.P0[-1, -1] == pytest.approx(0.002**2) and aug.Q[-1, -1] == 0.0 and am.C[1, -1] == 1.0
    assert np.all(np.linalg.eigvalsh(aug.P0) >= -1e-12)
    assert "no rotational columns" in am.meta["disturbances"][0]
    with pytest.raises(DisturbanceError, match="no outputs"):
        augment_with_sensor_biases(m, ["nz_g"], 0.01)

"""Disturbance models for the detectors: JSBSim's own MIL-F-8785C turbulence and turn-on biases.

What JSBSim does (``src/models/atmosphere/FGWinds.cpp``, ``FGWinds::Turbulence``; identical in
v1.3.1, the v1.3.2 release branch and master, and checked against the installed 1.3.3 wheel by
``tests/detectors/test_disturbance.py``). fdi-sim sets ``atmosphere/turb-type = 3`` (``ttMilspec``),
``atmosphere/turbulence/milspec/severity`` (probability-of-exceedance row ``poe``) and
``.../windspeed_at_20ft_AGL-fps`` (``W20``) from :data:`TURBULENCE_SETTINGS`
(``fdi_sim.aircraft.model.set_atmosphere``).

Intensities and scale lengths, with ``h`` the altitude **above sea level** clipped at 10 ft and
``b`` the wing span (30 ft if the model has none)::

    h <= 1000 ft:  L_u = h / (0.177 + 0.000823 h)^1.2,  L_w = h,
                   sig_w = 0.1 W20,  sig_u = sig_w / (0.177 + 0.000823 h)^0.4
    h <= 2000 ft:  L_u = L_w = 1000 + (h - 1000) / 1000 * 750,
                   sig_u = sig_w = 0.1 W20 + (h - 1000) / 1000 * (POE(poe, h) - 0.1 W20)
    else:          L_u = L_w = 1750,  sig_u = sig_w = POE(poe, h)

``POE`` is MIL-F-8785C fig. 7 (:data:`POE_TABLE_FPS`), linear in altitude, clamped at the ends.
The lateral component uses ``sig_u`` and ``L_u`` (``L_v = L_u``, ``sig_v = sig_u``). Rotation::

    sig_p = 1.9 / sqrt(L_w b) sig_w,  L_p = sqrt(L_w b) / 2.6
    tau_u = L_u / V,  tau_w = L_w / V,  tau_p = L_p / V,  tau_q = 4 b / (pi V),  tau_r = 3 b / (pi V)

with ``V`` the true airspeed (``FGAuxiliary::GetVt`` of the previous step). ``ttMilspec`` is the
MIL-STD-1797A forward-Euler form of Yeager (1998), eqs. (30)-(35), at ``T`` = the simulation step,
with independent unit normal numbers ``nu``::

    xi_u[k] = (1 - T/tau_u)   xi_u[k-1] + sig_u sqrt(2 T/tau_u) nu_u
    xi_v[k] = (1 - 2 T/tau_u) xi_v[k-1] + sig_u sqrt(4 T/tau_u) nu_v
    xi_w[k] = (1 - 2 T/tau_w) xi_w[k-1] + sig_w sqrt(4 T/tau_w) nu_w
    xi_p[k] = (1 - T/tau_p)   xi_p[k-1] + sig_p sqrt(2 T/tau_p) nu_p
    xi_q[k] = (1 - T/tau_q)   xi_q[k-1] + pi / (4 b) (xi_w[k] - xi_w[k-1])
    xi_r[k] = (1 - T/tau_r)   xi_r[k-1] + pi / (3 b) (xi_v[k] - xi_v[k-1])

So all of u, v, w are *first-order* (v and w with time constant tau/2, not the second-order
Dryden v, w of the spec), and q, r are the high-passed w, v (``q_g = (s/V) / (1 + tau_q s) w_g``).
The velocities are then turned by the azimuth ``psiw`` the mean wind blows toward (0 without a
wind) and applied in local NED axes::

    turb_north = cos(psiw) xi_u + sin(psiw) xi_v,  turb_east = -sin(psiw) xi_u + cos(psiw) xi_v,
    turb_down = xi_w

(``atmosphere/total-wind-*-fps`` = wind + gust + turbulence), and the air-relative velocity is
``vAeroUVW = vUVW - Tl2b * vTotalWindNED`` (``FGAuxiliary``). The rates are turned the same way
and then treated as a *local-frame* vector: ``vTurbPQR = Tl2b [cos xi_p + sin xi_q,
-sin xi_p + cos xi_q, xi_r]`` (``atmosphere/p-turb-rad_sec`` etc., body axes), and enter as
``vAeroPQR = vPQR - vTurbPQR`` (``velocities/p-aero-rad_sec``): every aero damping term of both
aircraft *and* the F-16's FBW rate feedback read the aero rates, the gyros the inertial ones.

Our model (this module, pure numpy): :func:`dryden_parameters` reproduces the numbers,
:func:`dryden_shaping_filter` the recursion at the simulation step exactly (state ``xi``, four
unit white inputs), sampled at a multiple of the step when the detector runs slower
(``A^n``, ``sum A^i B B' A'^i``); :func:`rotational_turbulence_inputs` gives a continuous
linearizer model the columns of the aero rates; :func:`augment_with_gusts` appends the gust states
to a discrete model with the process-noise covariance of the white inputs; and
:func:`augment_with_sensor_biases` adds turn-on biases as random-constant states (chosen over
offset-insensitive residuals because it keeps every output usable and the bias estimate is itself
an isolation signal; over the flight's own baseline because it needs no training window).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import FdiSimError
from fdi_sim.linear.model import LinearModel
from fdi_sim.units import FPS_PER_KT

#: turbulence level -> (JSBSim ``milspec/severity`` row, wind at 20 ft [kt]); the same table as
#: ``fdi_sim.aircraft.model.TURBULENCE_LEVELS`` (copied: detectors do not import the adapter; a
#: test checks the two agree)
TURBULENCE_SETTINGS: dict[str, tuple[int, float]] = {
    "none": (0, 0.0),
    "light": (3, 15.0),
    "moderate": (4, 30.0),
    "severe": (6, 45.0),
}

#: altitudes of the columns of :data:`POE_TABLE_FPS` [ft]
POE_ALTITUDES_FT: NDArray[np.float64] = np.array(
    [500.0, 1750.0, 3750.0, 7500.0, 15000.0, 25000.0, 35000.0, 45000.0, 55000.0, 65000.0, 75000.0, 80000.0])
#: MIL-F-8785C fig. 7 as in ``FGWinds::FGWinds``: rms turbulence [ft/s], rows severity 1..7
POE_TABLE_FPS: NDArray[np.float64] = np.array([
    [3.2, 2.2, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [4.2, 3.6, 3.3, 1.6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [6.6, 6.9, 7.4, 6.7, 4.6, 2.7, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0],
    [8.6, 9.6, 10.6, 10.1, 8.0, 6.6, 5.0, 4.2, 2.7, 0.0, 0.0, 0.0],
    [11.8, 13.0, 16.0, 15.1, 11.6, 9.7, 8.1, 8.2, 7.9, 4.9, 3.2, 2.1],
    [15.6, 17.6, 23.0, 23.6, 22.1, 20.0, 16.0, 15.1, 12.1, 7.9, 6.2, 5.1],
    [18.7, 21.5, 28.4, 30.2, 30.7, 31.0, 25.2, 23.1, 17.5, 10.7, 8.4, 7.2],
])
#: JSBSim's default simulation step [s]
DT_SIM_S: float = 1.0 / 120.0
#: names of the gust filter's states (JSBSim's xi in wind axes) and of its white inputs
GUST_STATES: tuple[str, ...] = ("xi_u_fps", "xi_v_fps", "xi_w_fps", "xi_p_radps", "xi_q_radps", "xi_r_radps")
WHITE_INPUTS: tuple[str, ...] = ("nu_u", "nu_v", "nu_w", "nu_p")
#: outputs of the shaping filter (turbulence axes: u toward the mean wind's azimuth, w down)
GUST_OUTPUTS: tuple[str, ...] = ("u_g_fps", "v_g_fps", "w_g_fps", "p_g_radps", "q_g_radps", "r_g_radps")
#: the linearizer's gust columns (body axes at the trim attitude) and the rotational columns added
#: by :func:`rotational_turbulence_inputs`
GUST_INPUTS: tuple[str, ...] = ("u_gust_body_fps", "v_gust_body_fps", "w_gust_body_fps")
ROTATIONAL_INPUTS: tuple[str, ...] = ("p_turb_body_radps", "q_turb_body_radps", "r_turb_body_radps")
_RATES: tuple[str, ...] = ("p_radps", "q_radps", "r_radps")


class DisturbanceError(FdiSimError, ValueError):
    """A disturbance model cannot be built from these arguments (the message says why)."""


@dataclass(frozen=True)
class DrydenParameters:
    """JSBSim's MIL-F-8785C turbulence parameters at one altitude, airspeed and level.

    Attributes
    ----------
    h_ft : float
        Altitude above sea level used (clipped at 10 ft, as JSBSim) [ft].
    vt_fps : float
        True airspeed [ft/s].
    wingspan_ft : float
        Wing span ``b`` [ft].
    severity : int
        Probability-of-exceedance row (0 = off).
    w20_fps : float
        Wind speed at 20 ft [ft/s].
    sigma_u_fps, sigma_v_fps, sigma_w_fps : float
        Intensities [ft/s] (``sigma_v = sigma_u`` in JSBSim).
    L_u_ft, L_v_ft, L_w_ft : float
        Scale lengths [ft] (``L_v = L_u``).
    sigma_p_radps : float
        Roll-gust intensity ``1.9 / sqrt(L_w b) sigma_w`` [rad/s].
    L_p_ft : float
        Roll-gust scale length ``sqrt(L_w b) / 2.6`` [ft].
    tau_u_s, tau_w_s, tau_p_s, tau_q_s, tau_r_s : float
        ``L_u/V, L_w/V, L_p/V, 4b/(pi V), 3b/(pi V)`` [s].
    """

    h_ft: float
    vt_fps: float
    wingspan_ft: float
    severity: int
    w20_fps: float
    sigma_u_fps: float
    sigma_v_fps: float
    sigma_w_fps: float
    L_u_ft: float
    L_v_ft: float
    L_w_ft: float
    sigma_p_radps: float
    L_p_ft: float
    tau_u_s: float
    tau_w_s: float
    tau_p_s: float
    tau_q_s: float
    tau_r_s: float

    @property
    def active(self) -> bool:
        """True if JSBSim generates turbulence (severity > 0)."""
        return self.severity > 0


def poe_sigma_fps(severity: int, h_ft: float) -> float:
    """``POE_Table->GetValue(severity, h)``: MIL-F-8785C fig. 7, linear in altitude, clamped [ft/s]."""
    if not 1 <= severity <= POE_TABLE_FPS.shape[0]:
        raise DisturbanceError(f"turbulence severity {severity} is not a row of the POE table (1..7)")
    return float(np.interp(h_ft, POE_ALTITUDES_FT, POE_TABLE_FPS[severity - 1]))


def dryden_parameters(h_ft: float, vt_fps: float, turbulence: str, wingspan_ft: float, *,
                      severity: int | None = None, w20_fps: float | None = None) -> DrydenParameters:
    """JSBSim's ``ttMilspec`` intensities, scale lengths and time constants.

    Parameters
    ----------
    h_ft : float
        Altitude above sea level [ft] (JSBSim uses ASL, not AGL).
    vt_fps : float
        True airspeed [ft/s], > 0.
    turbulence : str
        A key of :data:`TURBULENCE_SETTINGS` (``none | light | moderate | severe``).
    wingspan_ft : float
        Wing span [ft] (``metrics/bw-ft``; 0 means JSBSim's 30 ft).
    severity, w20_fps : int, float, optional
        Override the level's severity row and wind at 20 ft [ft/s].

    Returns
    -------
    DrydenParameters
        With all intensities 0 when the level is ``none``.
    """
    if turbulence not in TURBULENCE_SETTINGS:
        raise DisturbanceError(f"unknown turbulence level {turbulence!r}; known: {', '.join(TURBULENCE_SETTINGS)}")
    if not vt_fps > 0:
        raise DisturbanceError(f"vt_fps must be > 0 (JSBSim divides by it), got {vt_fps}")
    poe, w20_kts = TURBULENCE_SETTINGS[turbulence]
    poe = poe if severity is None else int(severity)
    w20 = w20_kts * FPS_PER_KT if w20_fps is None else float(w20_fps)
    b = float(wingspan_ft) if wingspan_ft else 30.0  # FGWinds: if (b_w == 0.) b_w = 30.
    h = max(float(h_ft), 10.0)  # clip height functions at 10 ft
    if h <= 1000.0:
        L_u = h / (0.177 + 0.000823 * h) ** 1.2  # MIL-F-8785C fig. 10
        L_w = h
        sig_w = 0.1 * w20
        sig_u = sig_w / (0.177 + 0.000823 * h) ** 0.4  # fig. 11
    elif h <= 2000.0:
        L_u = L_w = 1000.0 + (h - 1000.0) / 1000.0 * 750.0  # linear between the low and high models
        poe_h = poe_sigma_fps(poe, h) if poe else 0.0
        sig_u = sig_w = 0.1 * w20 + (h - 1000.0) / 1000.0 * (poe_h - 0.1 * w20)
    else:
        L_u = L_w = 1750.0  # sec. 3.7.2.1
        sig_u = sig_w = poe_sigma_fps(poe, h) if poe else 0.0
    if poe == 0:
        sig_u = sig_w = 0.0
    V = float(vt_fps)
    sig_p = 1.9 / math.sqrt(L_w * b) * sig_w  # Yeager (1998) eq. (8)
    L_p = math.sqrt(L_w * b) / 2.6  # eq. (10)
    return DrydenParameters(
        h_ft=h, vt_fps=V, wingspan_ft=b, severity=poe, w20_fps=w20,
        sigma_u_fps=sig_u, sigma_v_fps=sig_u, sigma_w_fps=sig_w, L_u_ft=L_u, L_v_ft=L_u, L_w_ft=L_w,
        sigma_p_radps=sig_p, L_p_ft=L_p, tau_u_s=L_u / V, tau_w_s=L_w / V, tau_p_s=L_p / V,
        tau_q_s=4.0 * b / math.pi / V, tau_r_s=3.0 * b / math.pi / V,
    )


@dataclass(frozen=True, eq=False)
class ShapingFilter:
    """Discrete gust filter ``xi[k+1] = A xi[k] + B nu[k]``, ``g = C xi``, ``nu ~ N(0, I)``.

    Attributes
    ----------
    A, B, C : NDArray
        Shapes (6, 6), (6, 4) at the simulation step or (6, 6) sampled slower, (6, 6).
    dt_s : float
        Sample time [s].
    dt_sim_s : float
        JSBSim step the recursion is taken at [s]; ``dt_s`` is a whole multiple of it.
    state_names, input_names, output_names : tuple of str
        :data:`GUST_STATES`, :data:`WHITE_INPUTS`, :data:`GUST_OUTPUTS`.
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    dt_s: float
    dt_sim_s: float
    state_names: tuple[str, ...] = GUST_STATES
    input_names: tuple[str, ...] = WHITE_INPUTS
    output_names: tuple[str, ...] = GUST_OUTPUTS

    def __post_init__(self) -> None:
        for name in "ABC":
            M = np.array(getattr(self, name), dtype=float)
            M.setflags(write=False)
            object.__setattr__(self, name, M)

    def stationary_covariance(self) -> NDArray[np.float64]:
        """``P = A P A' + B B'`` of the states (doubling iteration)."""
        return _dlyap(self.A, self.B @ self.B.T)

    def statistics(self, max_lag_s: float = 60.0) -> "GustStatistics":
        """Predicted rms and 1/e correlation time of every output (see :class:`GustStatistics`)."""
        P = self.stationary_covariance()
        var = np.einsum("ij,jk,ik->i", self.C, P, self.C)
        n_lag = int(round(max_lag_s / self.dt_s))
        t_e = np.full(len(var), np.nan)
        M = P @ self.C.T  # E[xi(k) g(0)'] for k = 0
        prev = var.copy()
        for k in range(1, n_lag + 1):
            M = self.A @ M  # E[xi(k) g(0)'] = A^k P C'
            r = np.einsum("ij,ji->i", self.C, M)
            for i in np.flatnonzero(np.isnan(t_e) & (r < var / math.e) & (var > 0)):
                # linear interpolation of the crossing of var / e between lags k-1 and k
                frac = (prev[i] - var[i] / math.e) / (prev[i] - r[i])
                t_e[i] = (k - 1 + frac) * self.dt_s
            prev = r
            if not np.isnan(t_e[var > 0]).any():
                break
        return GustStatistics(self.output_names, np.sqrt(var), t_e)


@dataclass(frozen=True, eq=False)
class GustStatistics:
    """Second-order statistics of the gust outputs.

    Attributes
    ----------
    names : tuple of str
        Output names.
    rms : NDArray
        Root mean square per output [ft/s or rad/s].
    t_1e_s : NDArray
        First lag at which the autocorrelation falls below 1/e [s] (NaN for a zero output).
    """

    names: tuple[str, ...]
    rms: NDArray[np.float64]
    t_1e_s: NDArray[np.float64]

    def of(self, name: str) -> tuple[float, float]:
        """``(rms, t_1e_s)`` of one output."""
        i = self.names.index(name)
        return float(self.rms[i]), float(self.t_1e_s[i])


def _dlyap(A: NDArray[np.float64], Q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Solve ``P = A P A' + Q`` by doubling (``A`` stable): ``P = sum A^i Q A'^i``."""
    P, Ak = Q.copy(), A.copy()
    for _ in range(64):
        dP = Ak @ P @ Ak.T
        P = P + dP
        Ak = Ak @ Ak
        if np.max(np.abs(dP), initial=0.0) <= 1e-15 * max(np.max(np.abs(P)), 1e-300):
            break
    return 0.5 * (P + P.T)


def _jsbsim_step(p: DrydenParameters, T: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``A``, ``B`` of FGWinds' ttMilspec recursion at the step ``T`` [s] (eqs. 30-35 above)."""
    b = p.wingspan_ft
    a_u, a_v, a_w = 1.0 - T / p.tau_u_s, 1.0 - 2.0 * T / p.tau_u_s, 1.0 - 2.0 * T / p.tau_w_s
    a_p, a_q, a_r = 1.0 - T / p.tau_p_s, 1.0 - T / p.tau_q_s, 1.0 - T / p.tau_r_s
    if min(a_u, a_v, a_w, a_p, a_q, a_r) <= -1.0:
        raise DisturbanceError(f"step {T} s is too long for JSBSim's Euler turbulence recursion "
                               f"(tau_q {p.tau_q_s:.3g} s): it diverges")
    b_u = p.sigma_u_fps * math.sqrt(2.0 * T / p.tau_u_s)
    b_v = p.sigma_v_fps * math.sqrt(4.0 * T / p.tau_u_s)  # v uses tau_u (JSBSim)
    b_w = p.sigma_w_fps * math.sqrt(4.0 * T / p.tau_w_s)
    b_p = p.sigma_p_radps * math.sqrt(2.0 * T / p.tau_p_s)
    c_q, c_r = math.pi / (4.0 * b), math.pi / (3.0 * b)
    A = np.diag([a_u, a_v, a_w, a_p, a_q, a_r])
    # xi_q[k] = a_q xi_q[k-1] + c_q (xi_w[k] - xi_w[k-1]) with xi_w[k] - xi_w[k-1] = (a_w - 1) xi_w[k-1] + b_w nu_w
    A[4, 2] = c_q * (a_w - 1.0)
    A[5, 1] = c_r * (a_v - 1.0)
    B = np.zeros((6, 4))
    B[0, 0], B[1, 1], B[2, 2], B[3, 3] = b_u, b_v, b_w, b_p
    B[4, 2] = c_q * b_w
    B[5, 1] = c_r * b_v
    return A, B


def dryden_shaping_filter(params: DrydenParameters, vt_fps: float | None = None, dt_s: float = DT_SIM_S, *,
                          dt_sim_s: float = DT_SIM_S) -> ShapingFilter:
    """The gust states as JSBSim generates them, sampled every ``dt_s``.

    Parameters
    ----------
    params : DrydenParameters
        From :func:`dryden_parameters`.
    vt_fps : float, optional
        True airspeed [ft/s] for the time constants (default ``params.vt_fps``).
    dt_s : float
        Sample time of the filter [s]: a whole multiple ``n`` of ``dt_sim_s``.
    dt_sim_s : float
        JSBSim's step [s] (``Winds`` runs every step): the recursion is JSBSim's own at this
        step, ``A_n = A^n``, ``B_n B_n' = sum_{i<n} A^i B B' A'^i`` (the exact sampled process).

    Returns
    -------
    ShapingFilter
        Outputs ``u_g v_g w_g`` [ft/s] and ``p_g q_g r_g`` [rad/s] in turbulence axes; all zero
        (``A = I``-free: zero B) when the level is ``none``.
    """
    if vt_fps is not None and vt_fps != params.vt_fps:
        params = with_airspeed(params, vt_fps)
    n = dt_s / dt_sim_s
    if not (dt_s > 0 and dt_sim_s > 0 and abs(n - round(n)) < 1e-9 and round(n) >= 1):
        raise DisturbanceError(f"dt_s {dt_s} s must be a whole multiple of the simulation step {dt_sim_s} s")
    A1, B1 = _jsbsim_step(params, dt_sim_s)
    A, Q = np.eye(6), np.zeros((6, 6))
    for _ in range(int(round(n))):
        Q = A1 @ Q @ A1.T + B1 @ B1.T
        A = A1 @ A
    if round(n) == 1:
        return ShapingFilter(A=A, B=B1, C=np.eye(6), dt_s=float(dt_s), dt_sim_s=float(dt_sim_s))
    # sampled every n steps the noise of the n steps has full rank: B_n B_n' = Q, six inputs
    return ShapingFilter(A=A, B=_factor(Q), C=np.eye(6), dt_s=float(dt_s), dt_sim_s=float(dt_sim_s),
                         input_names=tuple(f"nu_{i}" for i in range(6)))


def with_airspeed(params: DrydenParameters, vt_fps: float) -> DrydenParameters:
    """The same turbulence at another true airspeed [ft/s]: only the time constants change."""
    if not vt_fps > 0:
        raise DisturbanceError(f"vt_fps must be > 0, got {vt_fps}")
    V, b = float(vt_fps), params.wingspan_ft
    return replace(params, vt_fps=V, tau_u_s=params.L_u_ft / V, tau_w_s=params.L_w_ft / V, tau_p_s=params.L_p_ft / V,
                   tau_q_s=4.0 * b / math.pi / V, tau_r_s=3.0 * b / math.pi / V)


def _factor(Q: NDArray[np.float64]) -> NDArray[np.float64]:
    """A square ``B`` with ``B B' = Q`` (symmetric square root; Q may be singular)."""
    lam, V = np.linalg.eigh(0.5 * (Q + Q.T))
    return V * np.sqrt(np.clip(lam, 0.0, None))


def euler_to_body(phi_rad: float, theta_rad: float, psi_rad: float) -> NDArray[np.float64]:
    """``Tl2b``: local NED to body axes for the 3-2-1 Euler angles [-]."""
    cf, sf, ct, st, cp, sp = (math.cos(phi_rad), math.sin(phi_rad), math.cos(theta_rad), math.sin(theta_rad),
                              math.cos(psi_rad), math.sin(psi_rad))
    return np.array([
        [ct * cp, ct * sp, -st],
        [sf * st * cp - cf * sp, sf * st * sp + cf * cp, sf * ct],
        [cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct],
    ])


def turbulence_to_ned(psiw_rad: float) -> NDArray[np.float64]:
    """JSBSim's turn of the turbulence vector by the wind azimuth ``psiw`` (FGWinds, as written) [-]."""
    c, s = math.cos(psiw_rad), math.sin(psiw_rad)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def gust_to_body(model: LinearModel, psiw_rad: float = 0.0) -> NDArray[np.float64]:
    """``(6, 6)`` map from the filter outputs to body-axis gust velocity and turbulence rate.

    Both the velocities (``Tl2b R(psiw)``, JSBSim's NED turbulence seen in body axes) and the rates
    (``Tl2b R(psiw)``, JSBSim's ``vTurbPQR``) use the trim attitude ``phi_rad theta_rad psi_rad``
    of ``model.x0``.
    """
    att = [model.x0[model.state_names.index(s)] if s in model.state_names else 0.0
           for s in ("phi_rad", "theta_rad", "psi_rad")]
    T = euler_to_body(*att) @ turbulence_to_ned(psiw_rad)
    M = np.zeros((6, 6))
    M[:3, :3] = T
    M[3:, 3:] = T
    return M


def rotational_turbulence_inputs(model: LinearModel) -> LinearModel:
    """Add the columns :data:`ROTATIONAL_INPUTS` to a continuous linearizer model.

    JSBSim's rotational turbulence changes only the aero rates (``vAeroPQR = vPQR - vTurbPQR``),
    which every aero and FCS term reads; the inertial rates enter the kinematics only. So the
    column of a turbulence rate is minus the *aero part* of the model's rate column:
    ``B_rot = -(A[:, pqr] - K)``, ``D_rot = -(C[:, pqr] - K_y)``, where ``K`` is the rigid-body
    kinematics at the trim (``alpha_dot``: ``dq`` 1, ``dp -u v/(u^2+w^2)``, ``dr -w v/(u^2+w^2)``;
    ``beta_dot``: ``dp w/(Vt cos beta)``, ``dr -u/(Vt cos beta)``; the Euler-angle rates; the
    inertial couplings of ``p_dot q_dot r_dot`` vanish at a trim with zero rates) and ``K_y`` is
    the gyros' identity. The linearizer cannot perturb ``vTurbPQR`` itself (read-only in JSBSim).

    Parameters
    ----------
    model : LinearModel
        Continuous (``dt_s == 0``) model in aero states (``vt_fps alpha_rad beta_rad p_radps ...``).

    Returns
    -------
    LinearModel
        The same model with three more disturbance columns and no step terms.
    """
    if model.is_discrete:
        raise DisturbanceError("rotational_turbulence_inputs needs the continuous linearizer model (dt_s == 0)")
    names = model.state_names
    need = ("vt_fps", "alpha_rad", "beta_rad") + _RATES + ("phi_rad", "theta_rad", "psi_rad")
    missing = [s for s in need if s not in names]
    if missing:
        raise DisturbanceError(f"rotational_turbulence_inputs needs the aero states; missing {missing}")
    if any(n in model.input_names for n in ROTATIONAL_INPUTS):
        raise DisturbanceError("the model already has the rotational turbulence columns")
    x0 = dict(zip(names, model.x0))
    vt, al, be, phi, th = (x0[s] for s in ("vt_fps", "alpha_rad", "beta_rad", "phi_rad", "theta_rad"))
    if max(abs(x0[s]) for s in _RATES) > 1e-3:
        raise DisturbanceError("rotational_turbulence_inputs assumes a trim with zero body rates "
                               "(the inertial couplings are not in the model)")
    u, v, w = vt * math.cos(al) * math.cos(be), vt * math.sin(be), vt * math.sin(al) * math.cos(be)
    K = np.zeros((model.n_states, 3))
    ia, ib = names.index("alpha_rad"), names.index("beta_rad")
    uw2 = u * u + w * w
    K[ia] = [-u * v / uw2, 1.0, -w * v / uw2]  # alpha = atan(w/u), u_dot = r v - q w, w_dot = q u - p v
    K[ib] = [w / (vt * math.cos(be)), 0.0, -u / (vt * math.cos(be))]  # v_dot = p w - r u
    K[names.index("phi_rad")] = [1.0, math.sin(phi) * math.tan(th), math.cos(phi) * math.tan(th)]
    K[names.index("theta_rad")] = [0.0, math.cos(phi), -math.sin(phi)]
    K[names.index("psi_rad")] = [0.0, math.sin(phi) / math.cos(th), math.cos(phi) / math.cos(th)]
    cols = [names.index(s) for s in _RATES]
    Ky = np.zeros((model.n_outputs, 3))
    for j, s in enumerate(_RATES):
        if s in model.output_names:
            Ky[model.output_names.index(s), j] = 1.0  # the gyros measure the inertial rate
    B_rot = -(model.A[:, cols] - K)
    D_rot = -(model.C[:, cols] - Ky)
    return LinearModel(
        A=model.A, B=np.hstack([model.B, B_rot]), C=model.C, D=np.hstack([model.D, D_rot]), dt_s=0.0,
        state_names=names, input_names=model.input_names + ROTATIONAL_INPUTS, output_names=model.output_names,
        input_kinds=model.input_kinds + ("disturbance",) * 3, x0=model.x0, u0=np.concatenate([model.u0, np.zeros(3)]),
        y0=model.y0, op=model.op, meta={**model.meta, "rotational_turbulence": "aero part of the rate columns"},
    )


@dataclass(frozen=True, eq=False)
class AugmentedModel:
    """A discrete model with disturbance states and the covariance of its white inputs.

    Attributes
    ----------
    model : LinearModel
        ``x_a = [x; d]``; its inputs are the original model's (disturbance columns now carried by
        the states are kept, for the user who knows them, e.g. a logged gust).
    Q : NDArray
        Process-noise covariance of ``x_a(k+1) = A x_a(k) + B u(k) + w(k)``, ``E[w w'] = Q``.
    P0 : NDArray
        Initial covariance of ``x_a``: zeros for the plant, the stationary (gusts) or turn-on
        (biases) covariance for the disturbance states.
    disturbance_states : tuple of str
        Names of the appended states.
    """

    model: LinearModel
    Q: NDArray[np.float64]
    P0: NDArray[np.float64]
    disturbance_states: tuple[str, ...] = field(default=())


def _as_augmented(model: LinearModel | AugmentedModel) -> AugmentedModel:
    if isinstance(model, AugmentedModel):
        return model
    n = model.n_states
    return AugmentedModel(model, np.zeros((n, n)), np.zeros((n, n)), ())


def _append(base: AugmentedModel, A_xd: NDArray[np.float64], A_dd: NDArray[np.float64], C_d: NDArray[np.float64],
            Q_dd: NDArray[np.float64], P0_dd: NDArray[np.float64], names: Sequence[str], note: str) -> AugmentedModel:
    m = base.model
    n, nd = m.n_states, A_dd.shape[0]
    A = np.block([[m.A, A_xd], [np.zeros((nd, n)), A_dd]])
    B = np.vstack([m.B, np.zeros((nd, m.n_inputs))])
    C = np.hstack([m.C, C_d])
    Q = np.zeros((n + nd, n + nd))
    Q[:n, :n], Q[n:, n:] = base.Q, Q_dd
    P0 = np.zeros((n + nd, n + nd))
    P0[:n, :n], P0[n:, n:] = base.P0, P0_dd
    new = LinearModel(A=A, B=B, C=C, D=m.D, dt_s=m.dt_s, state_names=m.state_names + tuple(names),
                      input_names=m.input_names, output_names=m.output_names, input_kinds=m.input_kinds,
                      x0=np.concatenate([m.x0, np.zeros(nd)]), u0=m.u0, y0=m.y0, op=m.op,
                      meta={**m.meta, "disturbances": [*m.meta.get("disturbances", []), note]})
    return AugmentedModel(new, Q, P0, base.disturbance_states + tuple(names))


def augment_with_gusts(model: LinearModel | AugmentedModel, params: DrydenParameters, *, psiw_rad: float = 0.0,
                       dt_sim_s: float = DT_SIM_S) -> AugmentedModel:
    """Append JSBSim's gust states to a discrete model.

    ``x(k+1) = A x + B_g M g(k) + ...``, ``g = C_f xi``, ``xi(k+1) = A_f xi(k) + B_f nu(k)``,
    ``y = C x + D_g M g``, where ``B_g, D_g`` are the model's columns :data:`GUST_INPUTS` and, if
    present, :data:`ROTATIONAL_INPUTS` (:func:`rotational_turbulence_inputs` before the
    discretization), and ``M`` = :func:`gust_to_body`. The gust is held over the step like any
    input column of the model. Without rotational columns the rotational turbulence is left out
    (``meta['disturbances']`` says so).

    Parameters
    ----------
    model : LinearModel or AugmentedModel
        Discrete model (``dt_s`` a multiple of ``dt_sim_s``) with the gust columns.
    params : DrydenParameters
        At the model's altitude and airspeed.
    psiw_rad : float
        Azimuth the mean wind blows toward [rad] (0 without wind, as JSBSim).
    dt_sim_s : float
        JSBSim's step [s].

    Returns
    -------
    AugmentedModel
        With states :data:`GUST_STATES`, ``Q = B_f B_f'`` on them and ``P0`` their stationary covariance.
    """
    base = _as_augmented(model)
    m = base.model
    if not m.is_discrete:
        raise DisturbanceError("augment_with_gusts needs a discrete model (discretize the linearizer model first)")
    missing = [g for g in GUST_INPUTS if g not in m.input_names]
    if missing:
        raise DisturbanceError(f"the model has no gust columns {missing}; it needs the linearizer's disturbance inputs")
    f = dryden_shaping_filter(params, dt_s=m.dt_s, dt_sim_s=dt_sim_s)
    M = gust_to_body(m, psiw_rad)
    has_rot = all(r in m.input_names for r in ROTATIONAL_INPUTS)
    cols = [m.input_names.index(g) for g in GUST_INPUTS + (ROTATIONAL_INPUTS if has_rot else ())]
    Mk = M if has_rot else M[:3]
    A_xd = m.B[:, cols] @ Mk @ f.C
    C_d = m.D[:, cols] @ Mk @ f.C
    note = "dryden gusts" + (" with rotational turbulence" if has_rot else " (no rotational columns: rates left out)")
    return _append(base, A_xd, f.A, C_d, f.B @ f.B.T, f.stationary_covariance(), GUST_STATES, note)


def augment_with_sensor_biases(model: LinearModel | AugmentedModel, outputs: Sequence[str],
                               sigma: Sequence[float] | float, *, drift_sigma: Sequence[float] | float = 0.0
                               ) -> AugmentedModel:
    """Append one random-constant bias state per named output (turn-on biases).

    ``b(k+1) = b(k) + w_b``, ``y += b``; ``P0 = diag(sigma^2)`` (the turn-on spread), ``Q =
    diag(drift_sigma^2)`` per step (0: a pure constant; a small value keeps a filter adaptive).

    Parameters
    ----------
    model : LinearModel or AugmentedModel
        Discrete model.
    outputs : sequence of str
        Output names that carry a bias (``q_radps``, ``nz_g``, ...).
    sigma : float or sequence of float
        Turn-on bias standard deviation per output [output units].
    drift_sigma : float or sequence of float
        Random-walk standard deviation per step [output units].
    """
    base = _as_augmented(model)
    m = base.model
    if not m.is_discrete:
        raise DisturbanceError("augment_with_sensor_biases needs a discrete model")
    unknown = [o for o in outputs if o not in m.output_names]
    if unknown:
        raise DisturbanceError(f"no outputs {unknown}; the model has {', '.join(m.output_names)}")
    k = len(outputs)
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), (k,))
    drift = np.broadcast_to(np.asarray(drift_sigma, dtype=float), (k,))
    C_d = np.zeros((m.n_outputs, k))
    for j, o in enumerate(outputs):
        C_d[m.output_names.index(o), j] = 1.0
    names = tuple(f"bias_{o}" for o in outputs)
    return _append(base, np.zeros((m.n_states, k)), np.eye(k), C_d, np.diag(drift ** 2), np.diag(sig ** 2), names,
                   f"turn-on biases on {', '.join(outputs)}")

"""The pilot's per-step arithmetic, compiled: maneuver tables and the autopilot laws in one call.

:class:`fdi_sim.pilot.autopilot.Pilot` packs everything it reads per step into one float64 array
``par`` (gains, trim, modes, measurement indexes, maneuver tables; layout in the ``P_*``
constants, built by :func:`pack_params`) and keeps its filter states in another, ``state``
(``S_*``; initial values set by ``Pilot.reset``). :func:`step` is then one compiled call with four
array arguments, about 0.45 us from Python, most of it numba's dispatch (the arithmetic is about
0.1 us), against about 4 us for the same laws in Python floats.

Bit identity. Every expression is the Python implementation's (commit d97be8c, kept as the oracle
``tests/pilot/_reference_pilot.py``) with its operations in the same order: IEEE ``+ - * /`` and
``sqrt`` round the same in both; ``math.sin``/``math.cos`` call the same libm (the tests check it on
real flights); no ``fastmath`` (it would allow reassociation and fused multiply-adds). Python's
``min``/``max``, ``np.sign`` and ``np.minimum``/``np.maximum`` are written out with their exact
semantics (signed zeros and NaN included); numba's float ``%`` is Python's. The maneuver table
rows that the Python pilot evaluated with numpy a block of 120 steps at a time are evaluated here
for the one step needed, with the same scalar operations, so the row of step ``k`` is the same
float whatever the block it fell in.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.units import G0_FPS2

# --- layout of ``par`` (read-only per step) ------------------------------------------------------
# lateral gains (AutopilotGains field names)
P_K_PSI, P_PHI_MAX, P_TAU_PHI, P_K_PHI, P_K_P, P_K_PHII, P_K_ABSBETA, P_K_R, P_K_BETA, P_TAU_WO = range(0, 10)
LAT_GAINS = ("k_psi", "phi_max_rad", "tau_phi_s", "k_phi", "k_p", "k_phii", "k_absbeta", "k_r", "k_beta", "tau_wo_s")
# longitudinal gains
(P_K_H, P_HDOT_MAX, P_HDOT_MIN, P_K_V, P_VDOT_MAX, P_K_TE_P, P_K_TE_I, P_K_EB_P, P_K_EB_I, P_W_SPEED, P_W_SPEED_SAT,
 P_TAU_SAT, P_V_BAND, P_V_LIM, P_TAU_VLIM, P_ALPHA_MAX, P_ALPHA_BAND, P_K_TURN, P_THETA_LIM, P_K_THETA, P_K_Q,
 P_TAU_WIND, P_TAU_V, P_ZETA_V, P_TAU_ACC, P_THR_MIN, P_THR_MAX) = range(10, 37)
LON_GAINS = ("k_h_per_s", "hdot_max_fps", "hdot_min_fps", "k_v_per_s", "vdot_max_fps2", "k_te_p_per_fps",
             "k_te_i_per_ft", "k_eb_p_rad_per_fps", "k_eb_i_rad_per_ft", "w_speed", "w_speed_sat", "tau_sat_s",
             "v_band_kt", "v_lim_kt", "tau_vlim_s", "alpha_max_rad", "alpha_band_rad", "k_turn_rad", "theta_lim_rad",
             "k_theta", "k_q", "tau_wind_s", "tau_v_s", "zeta_v", "tau_acc_s", "throttle_min_norm", "throttle_max_norm")
# trim commands [norm], trim pitch [rad], height [ft] and calibrated airspeed [kt]
P_ELEV0, P_AIL0, P_RUD0, P_THR0, P_THETA0, P_H0_FT, P_VC0_KTS = range(37, 44)
# energy scaling (Pilot.__init__): V_0 [ft/s], TAS per kt CAS [ft/s/kt], its slopes [ft/s/kt/ft, ft/s/kt/kt], V_0/g [s]
P_V0_FPS, P_FPS_PER_KCAS, P_R_H, P_R_V, P_KE_S = range(44, 49)
P_DT_S, P_LATERAL, P_ALTITUDE, P_AIRSPEED = range(49, 53)  # step [s]; engaged holds (1.0 / 0.0)
# offsets and counts of the maneuver tables appended after the measurement indexes
P_STICKS, P_N_STICKS, P_RAMPS, P_N_RAMPS, P_TURNS, P_N_TURNS, P_HEADINGS, P_N_HEADINGS = range(53, 61)
#: index into y of each NEEDED measurement (-1: missing, only allowed with every hold off)
P_IDX = 61
N_NEEDED = 17
P_FIXED = P_IDX + N_NEEDED
#: maneuver table rows: stick = [axis, n_pulses, (t0_s, t1_s, value) * n_pulses]; ramp = [channel
#: (0: h_ft, 1: vc_kts), t_start_s, target, rate, start value]; turn = [t_start_s, t_end_s, phi_rad];
#: heading change = [t_start_s, psi_rad]
RAMP_COLS, TURN_COLS, HEADING_COLS = 5, 3, 2

# --- layout of ``state`` -------------------------------------------------------------------------
(S_INT_E, S_INT_B, S_INT_PHI, S_R_WO, S_V_HAT, S_WIND_N, S_WIND_E, S_R_REF, S_ACC_BIAS, S_ACC_LP, S_SAT, S_VC_LP,
 S_ALPHA_LP, S_FIRST, S_PSI_HOLD, S_IN_TURN, S_PHI_CMD, S_HEAD0) = range(18)
N_STATE = 18

TWO_PI = 2.0 * math.pi


def pack_params(lat_gains: tuple, lon_gains: tuple, trim: tuple, scaling: tuple, dt_s: float, modes: tuple,
                idx: list[int], sticks: list[tuple], ramps: list[tuple], turns: list[tuple],
                headings: list[tuple]) -> NDArray[np.float64]:
    """The ``par`` array of :func:`step` (values as given, never recomputed).

    Parameters
    ----------
    lat_gains, lon_gains : tuple of float
        In the order of ``LAT_GAINS`` and ``LON_GAINS``.
    trim : tuple of float
        Elevator, aileron, rudder, throttle [norm], theta [rad], h [ft], vc [kt].
    scaling : tuple of float
        V_0 [ft/s], TAS per kt CAS [ft/s/kt], r_h, r_v, V_0 / g [s].
    dt_s : float
        Step [s].
    modes : tuple of bool
        Lateral, altitude, airspeed holds engaged.
    idx : list of int
        Index into ``y`` of each NEEDED measurement (-1: missing).
    sticks : list of (axis, [(t0_s, t1_s, value), ...])
    ramps, turns, headings : list of tuple
        Rows as in the layout comment, in evaluation order.
    """
    head = [0.0] * P_FIXED
    head[P_K_PSI:P_K_PSI + 10] = lat_gains
    head[P_K_H:P_K_H + 27] = lon_gains
    head[P_ELEV0:P_ELEV0 + 7] = trim
    head[P_V0_FPS:P_V0_FPS + 5] = scaling
    head[P_DT_S] = dt_s
    head[P_LATERAL], head[P_ALTITUDE], head[P_AIRSPEED] = (1.0 if m else 0.0 for m in modes)
    head[P_IDX:P_IDX + N_NEEDED] = [float(i) for i in idx]
    body: list[float] = []
    head[P_STICKS], head[P_N_STICKS] = P_FIXED + len(body), len(sticks)
    for axis, pulses in sticks:
        body += [float(axis), float(len(pulses))]
        for pulse in pulses:
            body += list(pulse)
    for off, cnt, rows in ((P_RAMPS, P_N_RAMPS, ramps), (P_TURNS, P_N_TURNS, turns),
                           (P_HEADINGS, P_N_HEADINGS, headings)):
        head[off], head[cnt] = P_FIXED + len(body), len(rows)
        for row in rows:
            body += list(row)
    return np.array(head + body, dtype=np.float64)


@numba.njit(cache=True)
def _np_sign(x: float) -> float:
    # numpy.sign: 1, -1, 0.0 for both zeros, NaN for NaN
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0 if x == 0.0 else x


@numba.njit(cache=True)
def _np_minimum(a: float, b: float) -> float:
    # numpy.minimum: NaN propagates; on a tie the second operand
    return a if (a < b or a != a) else b


@numba.njit(cache=True)
def _np_maximum(a: float, b: float) -> float:
    return a if (a > b or a != a) else b


@numba.njit(cache=True)
def _ramp_value(t_s: float, t_start_s: float, target: float, rate: float, start: float) -> float:
    # RefRamp.apply for t_s >= t_start_s: start + sign(step) min(|step|, rate max(t - t_start, 0))
    step = target - start
    return start + _np_sign(step) * _np_minimum(abs(step), rate * _np_maximum(t_s - t_start_s, 0.0))


@numba.njit(cache=True)
def step(t_s: float, y: NDArray[np.float64], out: NDArray[np.float64], state: NDArray[np.float64],
         par: NDArray[np.float64]) -> None:  # pragma: no cover (compiled)
    """One pilot step: writes ``out`` = (elevator, aileron, rudder, throttle [norm], h_ref [ft],
    vc_ref [kt], psi_ref [rad], phi_ref [rad]) and advances ``state``.

    Parameters
    ----------
    t_s : float
        Time [s].
    y : ndarray, float64
        Measurements in the pilot's ``measurement_names`` order.
    out : ndarray, float64, shape (8,)
    state, par : ndarray, float64
        Layouts in the module constants.
    """
    dt = par[P_DT_S]
    # --- maneuver table row of step k (Pilot._fill_block of d97be8c, one row) ------------------
    k = int(np.rint(t_s / dt))  # round(t_s / dt): ties to even, as Python's round
    t = float(k) * dt
    de = da = dr = dthr = 0.0  # elevator, aileron, rudder, throttle deflections [norm] (AXES order)
    o = int(par[P_STICKS])
    for _ in range(int(par[P_N_STICKS])):
        axis = int(par[o])
        n_p = int(par[o + 1])
        o += 2
        v = 0.0
        for _ in range(n_p):
            if par[o] <= t < par[o + 1]:
                v = par[o + 2]
            o += 3
        if axis == 0:  # tab[:, axis] += stick(t), stick by stick in scenario order
            de += v
        elif axis == 1:
            da += v
        elif axis == 2:
            dr += v
        else:
            dthr += v
    h_ref = par[P_H0_FT]
    vc_ref = par[P_VC0_KTS]
    hdot_ff = 0.0
    o = int(par[P_RAMPS])
    for _ in range(int(par[P_N_RAMPS])):
        ch, ts, target, rate, start = par[o], par[o + 1], par[o + 2], par[o + 3], par[o + 4]
        o += RAMP_COLS
        if t >= ts:
            if ch == 0.0:
                h_ref = _ramp_value(t, ts, target, rate, start)
                hdot_ff = _np_sign(target - start) * rate if abs(h_ref - target) > 1e-9 else 0.0
            else:
                vc_ref = _ramp_value(t, ts, target, rate, start)
    turn_phi = math.nan
    o = int(par[P_TURNS])
    for _ in range(int(par[P_N_TURNS])):
        if par[o] <= t < par[o + 1]:
            turn_phi = par[o + 2]
        o += TURN_COLS
    # --- references and holds (Pilot.step of d97be8c) -----------------------------------------
    lateral, altitude, airspeed = par[P_LATERAL] != 0.0, par[P_ALTITUDE] != 0.0, par[P_AIRSPEED] != 0.0
    h_m = hdot_m = vc_m = theta = q = phi = p = psi_m = r = nx = ny = nz = alpha_m = beta_m = vn = ve = vd = 0.0
    if lateral or altitude or airspeed:
        i = P_IDX
        h_m, hdot_m, vc_m = y[int(par[i])], y[int(par[i + 1])], y[int(par[i + 2])]
        theta, q, phi, p = y[int(par[i + 3])], y[int(par[i + 4])], y[int(par[i + 5])], y[int(par[i + 6])]
        psi_m, r, nx, ny, nz = y[int(par[i + 7])], y[int(par[i + 8])], y[int(par[i + 9])], y[int(par[i + 10])], y[int(par[i + 11])]
        alpha_m, beta_m = y[int(par[i + 12])], y[int(par[i + 13])]
        vn, ve, vd = y[int(par[i + 14])], y[int(par[i + 15])], y[int(par[i + 16])]
    elev, ail, rud, thr = par[P_ELEV0], par[P_AIL0], par[P_RUD0], par[P_THR0]
    phi_ref = 0.0
    psi_ref = state[S_PSI_HOLD]
    o = int(par[P_HEADINGS])
    for j in range(int(state[S_HEAD0]), int(par[P_N_HEADINGS])):  # the latest heading change started by now
        if t_s >= par[o + j * HEADING_COLS]:
            psi_ref = par[o + j * HEADING_COLS + 1]
    if lateral:
        if turn_phi == turn_phi:  # not NaN: in a turn
            state[S_IN_TURN] = 1.0
            phi_cmd = phi_ref = turn_phi
            state[S_PHI_CMD] = turn_phi
        else:
            if state[S_IN_TURN] != 0.0:  # leaving a turn: hold the heading reached
                state[S_IN_TURN] = 0.0
                state[S_PSI_HOLD] = psi_m
                # drop the heading changes started by now (sorted by start: a prefix of those left)
                j = int(state[S_HEAD0])
                while j < int(par[P_N_HEADINGS]) and not (par[o + j * HEADING_COLS] > t_s):
                    j += 1
                state[S_HEAD0] = j
                psi_ref = psi_m
            # wrap(psi_ref - psi_m) into [-pi, pi); numba's float % is Python's (fmod, sign of the divisor)
            e_psi = (psi_ref - psi_m + math.pi) % TWO_PI - math.pi
            phi_max = par[P_PHI_MAX]
            phi_raw = par[P_K_PSI] * e_psi  # sat(k_psi e_psi, phi_max)
            phi_raw = phi_raw if phi_raw < phi_max else phi_max
            phi_raw = phi_raw if phi_raw > -phi_max else -phi_max
            phi_cmd = state[S_PHI_CMD]
            phi_cmd += dt * (phi_raw - phi_cmd) / par[P_TAU_PHI]
            state[S_PHI_CMD] = phi_ref = phi_cmd
        e_phi = phi_cmd - phi
        int_phi = state[S_INT_PHI]
        ail += par[P_K_PHI] * e_phi - par[P_K_P] * p + par[P_K_PHII] * (int_phi + e_phi * dt)
        if par[P_K_ABSBETA] != 0.0:
            ail -= par[P_K_ABSBETA] * abs(beta_m)
        # anti-windup: the bank integral grows only inside the aileron stops or back toward them
        ail_u = ail + da
        if -1.0 < ail_u < 1.0 or (ail_u >= 1.0) == (e_phi < 0.0):
            state[S_INT_PHI] = int_phi + e_phi * dt
        # washout r_wo = r - x, x' = (r - x) / tau (Euler)
        r_wo_state = state[S_R_WO]
        r_wo = r - r_wo_state
        state[S_R_WO] = r_wo_state + dt * r_wo / par[P_TAU_WO]
        rud += par[P_K_R] * r_wo
        if par[P_K_BETA] != 0.0:
            rud -= par[P_K_BETA] * beta_m
    if altitude or airspeed:
        v0_fps, fps_per_kcas, r_h, r_v = par[P_V0_FPS], par[P_FPS_PER_KCAS], par[P_R_H], par[P_R_V]
        h0, vc0 = par[P_H0_FT], par[P_VC0_KTS]
        # acceleration along the flight path [ft/s^2], gamma from the baro climb rate
        sth, cth = math.sin(theta), math.cos(theta)
        cphi_m, sphi_m = math.cos(phi), math.sin(phi)
        nzl = cphi_m * nz + sphi_m * ny
        sg = hdot_m / v0_fps  # clipped to +-0.5: a faulty hdot cannot break it
        sg = sg if sg < 0.5 else 0.5
        sg = sg if sg > -0.5 else -0.5
        acc = G0_FPS2 * ((cth * nx + sth * nzl) * math.sqrt(1.0 - sg * sg) - (cth * nzl - sth * nx + 1.0) * sg)
        acc_bias = state[S_ACC_BIAS]
        acc -= acc_bias
        # wind [ft/s, NED]: GNSS ground velocity minus the air velocity rotated body -> NED
        vt_m = vc_m * (fps_per_kcas + r_h * (h_m - h0) + r_v * (vc_m - vc0))
        cb = math.cos(beta_m)
        u_a, v_a, w_a = vt_m * math.cos(alpha_m) * cb, vt_m * math.sin(beta_m), vt_m * math.sin(alpha_m) * cb
        x_h = u_a * cth + (v_a * sphi_m + w_a * cphi_m) * sth  # along the heading, level
        y_h = v_a * cphi_m - w_a * sphi_m                       # to the right of it, level
        cpsi, spsi = math.cos(psi_m), math.sin(psi_m)
        wn_m, we_m = vn - (x_h * cpsi - y_h * spsi), ve - (x_h * spsi + y_h * cpsi)
        first = state[S_FIRST] != 0.0
        if first:  # engagement: the wind estimate starts at the first sample
            wind_n, wind_e = wn_m, we_m
        else:
            wind_n, wind_e = state[S_WIND_N], state[S_WIND_E]
        tau_wind = par[P_TAU_WIND]
        wind_n += dt * (wn_m - wind_n) / tau_wind
        wind_e += dt * (we_m - wind_e) / tau_wind
        state[S_WIND_N], state[S_WIND_E] = wind_n, wind_e
        # airspeed relative to the estimated air mass [ft/s TAS]
        dn, de_ = vn - wind_n, ve - wind_e
        v_s = math.sqrt(dn * dn + de_ * de_ + vd * vd)
        v_hat = v_s if first else state[S_V_HAT]
        # second-order complementary filter: speed [ft/s TAS] and acceleration bias [ft/s^2]
        tau_v = par[P_TAU_V]
        e_f = v_s - v_hat
        v_hat += dt * (acc + 2.0 * par[P_ZETA_V] * e_f / tau_v)
        state[S_V_HAT] = v_hat
        state[S_ACC_BIAS] = acc_bias - dt * e_f / (tau_v * tau_v)
        acc_lp = state[S_ACC_LP]
        acc_lp += dt * (acc - acc_lp) / par[P_TAU_ACC]
        state[S_ACC_LP] = acc = acc_lp
        # protections' inputs: low-passed measured airspeed [kt] and angle of attack [rad]
        if first:
            state[S_FIRST] = 0.0
            alpha_lp = alpha_m
        else:
            alpha_lp = state[S_ALPHA_LP]
        tau_vlim = par[P_TAU_VLIM]
        vc_lp = state[S_VC_LP]
        vc_lp += dt * (vc_m - vc_lp) / tau_vlim
        alpha_lp += dt * (alpha_m - alpha_lp) / tau_vlim
        state[S_VC_LP], state[S_ALPHA_LP] = vc_lp, alpha_lp
        # energy-rate errors [ft/s]: potential (climb rate) and kinetic ((V_0/g) acceleration)
        pe = ke = 0.0
        if altitude:
            hdot_max, hdot_min = par[P_HDOT_MAX], par[P_HDOT_MIN]
            hdot_c = par[P_K_H] * (h_ref - h_m) + hdot_ff  # sat(k_h e_h + hdot_ff, hdot_min, hdot_max)
            hdot_c = hdot_c if hdot_c < hdot_max else hdot_max
            hdot_c = hdot_c if hdot_c > hdot_min else hdot_min
            pe = hdot_c - hdot_m
        if airspeed:
            r_ref = fps_per_kcas + r_h * (h_m - h0) + r_v * (vc_ref - vc0)
            state[S_R_REF] = r_ref
            e_v = r_ref * vc_ref - v_hat
            vdot_max = par[P_VDOT_MAX]
            vdot_c = par[P_K_V] * e_v  # sat(k_v e_v, vdot_max)
            vdot_c = vdot_c if vdot_c < vdot_max else vdot_max
            vdot_c = vdot_c if vdot_c > -vdot_max else -vdot_max
            ke = par[P_KE_S] * (vdot_c - acc)
            e_rate = pe + ke  # total energy rate error -> throttle
            int_e = state[S_INT_E]
            thr_u = thr + par[P_K_TE_P] * e_rate + par[P_K_TE_I] * (int_e + e_rate * dt)
            sat = 0.0
            if thr_u > par[P_THR_MAX]:  # anti-windup: integrate only away from the stop
                thr = par[P_THR_MAX]
                if e_rate < 0.0:
                    state[S_INT_E] = int_e + e_rate * dt
                else:
                    sat = 1.0
            elif thr_u < par[P_THR_MIN]:
                thr = par[P_THR_MIN]
                if e_rate > 0.0:
                    state[S_INT_E] = int_e + e_rate * dt
                else:
                    sat = 1.0
            else:
                thr = thr_u
                state[S_INT_E] = int_e + e_rate * dt
            state[S_SAT] += dt * (sat - state[S_SAT]) / par[P_TAU_SAT]
        if altitude:
            w_speed = par[P_W_SPEED]
            w_v = w_speed + state[S_SAT] * (par[P_W_SPEED_SAT] - w_speed)
            b_rate = (2.0 - w_v) * pe - w_v * ke if airspeed else pe  # energy balance rate error
            cphi = 0.5 if 0.5 > cphi_m else cphi_m  # max(cphi_m, 0.5)
            int_b = state[S_INT_B]
            dtheta = (par[P_K_EB_P] * b_rate + par[P_K_EB_I] * (int_b + b_rate * dt)
                      + par[P_K_TURN] * (1.0 / cphi - 1.0))
            # pitch limits about trim; the side that would make an over/underspeed worse fades out
            v_lim, v_band, theta_lim = par[P_V_LIM], par[P_V_BAND], par[P_THETA_LIM]
            over = (vc_lp - vc_ref - v_lim) / v_band
            under = (vc_ref - vc_lp - v_lim) / v_band
            over = 0.0 if 0.0 > over else over  # min(max(over, 0), 1)
            lim_dn = theta_lim * (1.0 - (1.0 if 1.0 < over else over))
            stall = (alpha_lp - par[P_ALPHA_MAX]) / par[P_ALPHA_BAND] + 1.0
            fade = stall if stall > under else under  # min(max(under, stall, 0), 1)
            fade = 0.0 if 0.0 > fade else fade
            lim_up = theta_lim * (1.0 - (1.0 if 1.0 < fade else fade))
            if dtheta > lim_up:
                dtheta = lim_up
                if b_rate < 0.0:
                    state[S_INT_B] = int_b + b_rate * dt
            elif dtheta < -lim_dn:
                dtheta = -lim_dn
                if b_rate > 0.0:
                    state[S_INT_B] = int_b + b_rate * dt
            else:
                state[S_INT_B] = int_b + b_rate * dt
            elev -= par[P_K_THETA] * (par[P_THETA0] + dtheta - theta) - par[P_K_Q] * q
    # commands clipped to [-1, 1] (throttle [0, 1]): max(lo, min(hi, v))
    el, ai, ru, th = elev + de, ail + da, rud + dr, thr + dthr
    el = el if el < 1.0 else 1.0
    ai = ai if ai < 1.0 else 1.0
    ru = ru if ru < 1.0 else 1.0
    th = th if th < 1.0 else 1.0
    out[0] = el if el > -1.0 else -1.0
    out[1] = ai if ai > -1.0 else -1.0
    out[2] = ru if ru > -1.0 else -1.0
    out[3] = th if th > 0.0 else 0.0
    out[4], out[5], out[6], out[7] = h_ref, vc_ref, psi_ref, phi_ref

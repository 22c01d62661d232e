"""The pilot as it was before the compiled kernel (commit d97be8c): the oracle of the kernel tests.

A verbatim copy of ``Pilot`` (``__init__``, ``reset``, ``_fill_block``, ``step``) in pure Python
floats, renamed ``ReferencePilot``. The compiled :class:`fdi_sim.pilot.autopilot.Pilot` must give
the same floats, bit for bit, on the same inputs. Do not "fix" this file: it is the definition of
the numbers the logs hold.
"""
from __future__ import annotations

import math
import operator
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.isa import vt_from_vc
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, PilotCommand, TrimPoint
from fdi_sim.pilot.maneuvers import AXES, HeadingChange, PulseTrain, RefRamp, Turn
from fdi_sim.units import FPS_PER_KT, G0_FPS2, RAD_PER_DEG

BLOCK_STEPS = 120
NEEDED = ("h_ft", "hdot_fps", "vc_kts", "theta_rad", "q_radps", "phi_rad", "p_radps", "psi_rad", "r_radps", "nx_g", "ny_g",
          "nz_g", "alpha_rad", "beta_rad", "v_north_fps", "v_east_fps", "v_down_fps")
_TWO_PI = 2.0 * math.pi
_TUPLE_NEW = tuple.__new__


class ReferencePilot:
    """Autopilot plus maneuver schedule; ``reset`` then ``step(t_s, y)`` every simulation step.

    Parameters
    ----------
    gains : AutopilotGains
    modes : AutopilotModes
    trim : TrimPoint
    maneuvers : sequence
        Built maneuver objects, in scenario order.
    measurement_names : sequence of str
        Order of the measurement vector ``y`` given to :meth:`step`.
    dt_s : float
        Step [s].
    """

    def __init__(self, gains: AutopilotGains, modes: AutopilotModes, trim: TrimPoint, maneuvers: Sequence[object],
                 measurement_names: Sequence[str], dt_s: float) -> None:
        missing = [n for n in NEEDED if n not in measurement_names]
        if missing and (modes.altitude or modes.airspeed or modes.lateral):
            raise ValueError(f"the autopilot needs the measurements {missing}")
        self.g, self.modes, self.trim, self.dt_s = gains, modes, trim, dt_s
        # one C-level gather of the measurements in NEEDED order per step (None: no hold engaged, some missing)
        self._gather = None if missing else operator.itemgetter(*(list(measurement_names).index(n) for n in NEEDED))
        self.sticks = [m for m in maneuvers if isinstance(m, PulseTrain)]
        self.ramps = sorted((m for m in maneuvers if isinstance(m, RefRamp)), key=lambda m: m.t_start_s)
        self._headings = tuple(sorted((m for m in maneuvers if isinstance(m, HeadingChange)), key=lambda m: m.t_start_s))
        self.turns = sorted((m for m in maneuvers if isinstance(m, Turn)), key=lambda m: m.t_start_s)
        # each ramp starts from the reference that the earlier ramps of its channel reached by then
        self._ramp_start: list[float] = []
        for r in self.ramps:
            start = trim.h_ft if r.channel == "h_ft" else trim.vc_kts
            for q, s in zip(self.ramps, self._ramp_start):
                if q.channel == r.channel:
                    start = q.value_at(r.t_start_s, s, start)
            self._ramp_start.append(start)
        # energy scaling from the trim point: true airspeed V_0 [ft/s]; TAS per kt of CAS [ft/s/kt]
        # linearized about the trim, r(h, vc) = r_0 + r_h (h - h_0) + r_v (vc - vc_0) (ISA, central
        # differences over +-500 ft and +-5 kt: within 0.25 % over +-3000 ft and +-30 kt)
        self._v0_fps = vt_from_vc(trim.h_ft, trim.vc_kts)[0] * FPS_PER_KT
        self._fps_per_kcas = self._v0_fps / trim.vc_kts
        dh, dv = 500.0, 5.0
        r = [[vt_from_vc(trim.h_ft + i * dh, trim.vc_kts + j * dv)[0] * FPS_PER_KT / (trim.vc_kts + j * dv)
              for j in (-1, 1)] for i in (-1, 1)]
        self._r_h = (r[1][0] + r[1][1] - r[0][0] - r[0][1]) / (4.0 * dh)
        self._r_v = (r[0][1] + r[1][1] - r[0][0] - r[1][0]) / (4.0 * dv)
        self._ke_s = self._v0_fps / G0_FPS2  # V_0 / g: kinetic energy height per ft/s of speed [s]
        # what step() reads every time, as tuples unpacked into locals there (the values, unchanged)
        g = gains
        self._modes = (modes.lateral, modes.altitude, modes.airspeed)
        self._trim_cmd = (trim.elevator_cmd_norm, trim.aileron_cmd_norm, trim.rudder_cmd_norm, trim.throttle_cmd_norm)
        self._g_lat = (g.k_psi, g.phi_max_rad, g.tau_phi_s, g.k_phi, g.k_p, g.k_phii, g.k_absbeta, g.k_r, g.k_beta,
                       g.tau_wo_s)
        self._g_lon = (g.k_h_per_s, g.hdot_max_fps, g.hdot_min_fps, g.k_v_per_s, g.vdot_max_fps2, g.k_te_p_per_fps,
                       g.k_te_i_per_ft, g.k_eb_p_rad_per_fps, g.k_eb_i_rad_per_ft, g.w_speed, g.w_speed_sat,
                       g.tau_sat_s, g.v_band_kt, g.v_lim_kt, g.tau_vlim_s, g.alpha_max_rad, g.alpha_band_rad,
                       g.k_turn_rad, g.theta_lim_rad, g.k_theta, g.k_q, g.tau_wind_s, g.tau_v_s, g.zeta_v,
                       g.tau_acc_s, g.throttle_min_norm, g.throttle_max_norm)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Clear integrators and filters (the pilot is deterministic; ``rng`` is unused)."""
        self._int_e = self._int_b = self._int_phi = 0.0
        self._r_wo_state = 0.0
        self._v_hat = self._fps_per_kcas * self.trim.vc_kts
        self._wind_n_fps = self._wind_e_fps = 0.0
        self._r_ref = self._fps_per_kcas  # TAS/CAS ratio at the reference speed and measured height
        self._acc_bias = 0.0
        self._acc_lp = 0.0
        self._sat = 0.0
        self._vc_lp = self.trim.vc_kts
        self._alpha_lp = 0.0
        self._first = True  # the angle-of-attack filter and the wind estimate start from the first measurement
        self._psi_hold = self.trim.psi_rad
        self._in_turn = False
        self._phi_cmd_rad = 0.0  # low-passed bank command [rad]
        self.headings = list(self._headings)  # heading changes still ahead (a turn exit drops past ones)
        self._block_start = -(10**9)
        self._rows: list[list[float]] = []

    @property
    def airspeed_estimate_kts(self) -> float:
        """The speed estimate relative to the estimated steady air mass, as calibrated airspeed [kt]."""
        return self._v_hat / self._r_ref

    @property
    def wind_estimate_fps(self) -> tuple[float, float]:
        """The estimated steady wind (north, east), the direction it blows to [ft/s]."""
        return self._wind_n_fps, self._wind_e_fps

    def _fill_block(self, k0: int) -> None:
        """Rows for steps k0 .. k0+BLOCK_STEPS-1: [de, da, dr, dt, h_ref, hdot_ff, vc_ref, turn_phi(or nan)]."""
        t = (k0 + np.arange(BLOCK_STEPS)) * self.dt_s
        tab = np.zeros((BLOCK_STEPS, 8))
        for m in self.sticks:
            tab[:, AXES.index(m.axis)] += m.stick(t)
        h = np.full_like(t, self.trim.h_ft)
        v = np.full_like(t, self.trim.vc_kts)
        hdot_ff = np.zeros_like(t)
        for r, s in zip(self.ramps, self._ramp_start):
            if r.channel == "h_ft":
                h_new = r.apply(t, h, s)
                moving = (t >= r.t_start_s) & (np.abs(h_new - r.target) > 1e-9)
                hdot_ff = np.where(t >= r.t_start_s, np.where(moving, np.sign(r.target - s) * r.rate, 0.0), hdot_ff)
                h = h_new
            else:
                v = r.apply(t, v, s)
        tab[:, 4], tab[:, 5], tab[:, 6] = h, hdot_ff, v
        turn_phi = np.full_like(t, np.nan)
        for tr in self.turns:
            turn_phi[(t >= tr.t_start_s) & (t < tr.t_start_s + tr.duration_s)] = tr.phi_deg * RAD_PER_DEG
        tab[:, 7] = turn_phi
        self._rows, self._block_start = tab.tolist(), k0  # Python floats: scalar maths per step stays cheap

    def step(self, t_s: float, y: NDArray[np.float64] | list[float]) -> PilotCommand:
        """Commands for time ``t_s`` [s] from the measurement vector ``y`` (array or list of floats).

        Hot path (once per simulation step): gains come from tuples unpacked into locals, filter
        states are read once into locals and stored back, and ``max(a, b)`` / ``min(a, b)`` are
        written as ``b if b > a else a`` / ``b if b < a else a``, which is exactly what the
        builtins compute for two arguments (signed zeros and NaN included). Every arithmetic
        expression is the law of the module docstring with its operations in the same order, so
        the commands are the same floats bit for bit. (With the arguments swapped the conditional
        would differ from the builtin for a NaN operand: the order is kept as the builtin's.)
        """
        k = int(round(t_s / self.dt_s))
        j = k - self._block_start
        if not 0 <= j < BLOCK_STEPS:
            self._fill_block(k)
            j = 0
        de, da, dr, dthr, h_ref, hdot_ff, vc_ref, turn_phi = self._rows[j]
        tr, dt = self.trim, self.dt_s
        lateral, altitude, airspeed = self._modes
        if lateral or altitude or airspeed:
            (h_m, hdot_m, vc_m, theta, q, phi, p, psi_m, r, nx, ny, nz, alpha_m, beta_m, vn, ve,
             vd) = self._gather(y if type(y) is list else y.tolist())  # NEEDED order
        elev, ail, rud, thr = self._trim_cmd
        phi_ref = 0.0
        psi_ref = self._psi_hold
        for hc in self.headings:  # the latest heading change started by now
            if t_s >= hc.t_start_s:
                psi_ref = hc.psi_deg * RAD_PER_DEG
        if lateral:
            k_psi, phi_max, tau_phi, k_phi, k_p, k_phii, k_absbeta, k_r, k_beta, tau_wo = self._g_lat
            if turn_phi == turn_phi:  # not NaN: in a turn
                self._in_turn = True
                phi_cmd = phi_ref = self._phi_cmd_rad = turn_phi
            else:
                if self._in_turn:  # leaving a turn: hold the heading reached
                    self._in_turn = False
                    self._psi_hold = psi_m
                    self.headings = [h for h in self.headings if h.t_start_s > t_s]
                    psi_ref = self._psi_hold
                e_psi = (psi_ref - psi_m + math.pi) % _TWO_PI - math.pi  # wrap(psi_ref - psi_m) into [-pi, pi)
                # phi_raw = sat(k_psi e_psi, phi_max)
                phi_raw = k_psi * e_psi
                phi_raw = phi_raw if phi_raw < phi_max else phi_max
                phi_raw = phi_raw if phi_raw > -phi_max else -phi_max
                phi_cmd = self._phi_cmd_rad
                phi_cmd += dt * (phi_raw - phi_cmd) / tau_phi
                self._phi_cmd_rad = phi_ref = phi_cmd
            e_phi = phi_cmd - phi
            int_phi = self._int_phi
            ail += k_phi * e_phi - k_p * p + k_phii * (int_phi + e_phi * dt)
            if k_absbeta:
                ail -= k_absbeta * abs(beta_m)
            # anti-windup: the bank integral grows only while the aileron command is inside its
            # stops or the error would bring it back (a jammed or floating aileron must not wind it up)
            ail_u = ail + da
            if -1.0 < ail_u < 1.0 or (ail_u >= 1.0) == (e_phi < 0.0):
                self._int_phi = int_phi + e_phi * dt
            # washout r_wo = tau s / (1 + tau s) r = r - x, with the low-pass x' = (r - x) / tau (Euler)
            r_wo_state = self._r_wo_state
            r_wo = r - r_wo_state
            self._r_wo_state = r_wo_state + dt * r_wo / tau_wo
            rud += k_r * r_wo
            if k_beta:
                rud -= k_beta * beta_m
        if altitude or airspeed:
            (k_h, hdot_max, hdot_min, k_v, vdot_max, k_te_p, k_te_i, k_eb_p, k_eb_i, w_speed, w_speed_sat,
             tau_sat, v_band, v_lim, tau_vlim, alpha_max, alpha_band, k_turn, theta_lim, k_theta, k_q,
             tau_wind, tau_v, zeta_v, tau_acc, thr_min, thr_max) = self._g_lon
            v0_fps, fps_per_kcas, r_h, r_v = self._v0_fps, self._fps_per_kcas, self._r_h, self._r_v
            # acceleration along the flight path [ft/s^2] (module docstring), gamma from the baro climb rate
            sth, cth = math.sin(theta), math.cos(theta)
            cphi_m, sphi_m = math.cos(phi), math.sin(phi)
            nzl = cphi_m * nz + sphi_m * ny
            sg = hdot_m / v0_fps  # clipped to +-0.5: a faulty hdot cannot break it
            sg = sg if sg < 0.5 else 0.5
            sg = sg if sg > -0.5 else -0.5
            acc = G0_FPS2 * ((cth * nx + sth * nzl) * math.sqrt(1.0 - sg * sg) - (cth * nzl - sth * nx + 1.0) * sg)
            acc_bias = self._acc_bias
            acc -= acc_bias
            # wind [ft/s, NED]: GNSS ground velocity minus the air velocity rotated body -> NED
            vt_m = vc_m * (fps_per_kcas + r_h * (h_m - tr.h_ft) + r_v * (vc_m - tr.vc_kts))
            cb = math.cos(beta_m)
            u_a, v_a, w_a = vt_m * math.cos(alpha_m) * cb, vt_m * math.sin(beta_m), vt_m * math.sin(alpha_m) * cb
            x_h = u_a * cth + (v_a * sphi_m + w_a * cphi_m) * sth  # along the heading, level
            y_h = v_a * cphi_m - w_a * sphi_m                       # to the right of it, level
            cpsi, spsi = math.cos(psi_m), math.sin(psi_m)
            wn_m, we_m = vn - (x_h * cpsi - y_h * spsi), ve - (x_h * spsi + y_h * cpsi)
            first = self._first
            if first:  # engagement: the wind estimate starts at the first sample
                wind_n, wind_e = wn_m, we_m
            else:
                wind_n, wind_e = self._wind_n_fps, self._wind_e_fps
            wind_n += dt * (wn_m - wind_n) / tau_wind
            wind_e += dt * (we_m - wind_e) / tau_wind
            self._wind_n_fps, self._wind_e_fps = wind_n, wind_e
            # airspeed relative to the estimated air mass [ft/s TAS]: v_s = |v_gnd - w_hat|
            dn, de_ = vn - wind_n, ve - wind_e
            v_s = math.sqrt(dn * dn + de_ * de_ + vd * vd)
            v_hat = v_s if first else self._v_hat
            # second-order complementary filter: speed [ft/s TAS] and acceleration bias [ft/s^2]
            e_f = v_s - v_hat
            v_hat += dt * (acc + 2.0 * zeta_v * e_f / tau_v)
            self._v_hat = v_hat
            self._acc_bias = acc_bias - dt * e_f / (tau_v * tau_v)
            acc_lp = self._acc_lp
            acc_lp += dt * (acc - acc_lp) / tau_acc
            self._acc_lp = acc = acc_lp
            # protections' inputs: low-passed measured airspeed [kt] and angle of attack [rad]
            if first:
                self._first, alpha_lp = False, alpha_m
            else:
                alpha_lp = self._alpha_lp
            vc_lp = self._vc_lp
            vc_lp += dt * (vc_m - vc_lp) / tau_vlim
            alpha_lp += dt * (alpha_m - alpha_lp) / tau_vlim
            self._vc_lp, self._alpha_lp = vc_lp, alpha_lp
            # energy-rate errors [ft/s]: potential (climb rate) and kinetic ((V_0/g) acceleration)
            pe = ke = 0.0
            if altitude:
                hdot_c = k_h * (h_ref - h_m) + hdot_ff  # sat(k_h e_h + hdot_ff, hdot_min, hdot_max)
                hdot_c = hdot_c if hdot_c < hdot_max else hdot_max
                hdot_c = hdot_c if hdot_c > hdot_min else hdot_min
                pe = hdot_c - hdot_m
            if airspeed:
                r_ref = fps_per_kcas + r_h * (h_m - tr.h_ft) + r_v * (vc_ref - tr.vc_kts)
                self._r_ref = r_ref
                e_v = r_ref * vc_ref - v_hat
                vdot_c = k_v * e_v  # sat(k_v e_v, vdot_max)
                vdot_c = vdot_c if vdot_c < vdot_max else vdot_max
                vdot_c = vdot_c if vdot_c > -vdot_max else -vdot_max
                ke = self._ke_s * (vdot_c - acc)
                e_rate = pe + ke  # total energy rate error -> throttle
                int_e = self._int_e
                thr_u = thr + k_te_p * e_rate + k_te_i * (int_e + e_rate * dt)
                sat = 0.0
                if thr_u > thr_max:  # anti-windup: integrate only away from the stop
                    thr = thr_max
                    if e_rate < 0.0:
                        self._int_e = int_e + e_rate * dt
                    else:
                        sat = 1.0
                elif thr_u < thr_min:
                    thr = thr_min
                    if e_rate > 0.0:
                        self._int_e = int_e + e_rate * dt
                    else:
                        sat = 1.0
                else:
                    thr = thr_u
                    self._int_e = int_e + e_rate * dt
                self._sat += dt * (sat - self._sat) / tau_sat
            if altitude:
                w_v = w_speed + self._sat * (w_speed_sat - w_speed)
                b_rate = (2.0 - w_v) * pe - w_v * ke if airspeed else pe  # energy balance rate error
                cphi = 0.5 if 0.5 > cphi_m else cphi_m  # max(cphi_m, 0.5)
                int_b = self._int_b
                dtheta = (k_eb_p * b_rate + k_eb_i * (int_b + b_rate * dt)
                          + k_turn * (1.0 / cphi - 1.0))
                # pitch limits about trim; the side that would make an over/underspeed worse fades out
                over = (vc_lp - vc_ref - v_lim) / v_band
                under = (vc_ref - vc_lp - v_lim) / v_band
                over = 0.0 if 0.0 > over else over  # min(max(over, 0), 1)
                lim_dn = theta_lim * (1.0 - (1.0 if 1.0 < over else over))
                stall = (alpha_lp - alpha_max) / alpha_band + 1.0
                fade = stall if stall > under else under  # min(max(under, stall, 0), 1)
                fade = 0.0 if 0.0 > fade else fade
                lim_up = theta_lim * (1.0 - (1.0 if 1.0 < fade else fade))
                if dtheta > lim_up:
                    dtheta = lim_up
                    if b_rate < 0.0:
                        self._int_b = int_b + b_rate * dt
                elif dtheta < -lim_dn:
                    dtheta = -lim_dn
                    if b_rate > 0.0:
                        self._int_b = int_b + b_rate * dt
                else:
                    self._int_b = int_b + b_rate * dt
                elev -= k_theta * (tr.theta_rad + dtheta - theta) - k_q * q
        # commands clipped to [-1, 1] (throttle [0, 1]): max(lo, min(hi, v))
        el, ai, ru, th = elev + de, ail + da, rud + dr, thr + dthr
        el = el if el < 1.0 else 1.0
        ai = ai if ai < 1.0 else 1.0
        ru = ru if ru < 1.0 else 1.0
        th = th if th < 1.0 else 1.0
        # tuple.__new__ builds the same PilotCommand without the named tuple's Python-level __new__ (0.2 us)
        return _TUPLE_NEW(PilotCommand, (t_s, el if el > -1.0 else -1.0, ai if ai > -1.0 else -1.0,
                                         ru if ru > -1.0 else -1.0, th if th > 0.0 else 0.0, h_ref, vc_ref, psi_ref,
                                         phi_ref))

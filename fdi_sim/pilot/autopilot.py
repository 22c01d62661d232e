"""The autopilot: altitude, airspeed and heading (or bank) holds, flying on the measurements.

Control laws (all deviations about the trim commands; angles in rad, rates in rad/s):

* altitude:  hdot_cmd = sat(k_h e_h) + hdot_ff,  theta_cmd = theta_0 + k_hdot (hdot_cmd - hdot)
  + k_hi int(e_h) + k_turn (1/cos(phi) - 1),  elevator = e_0 - (k_theta (theta_cmd - theta) - k_q q)
  (positive elevator is nose down on both aircraft);
* airspeed:  throttle = t_0 + k_v e_v + k_vi int(e_v), e_v = v_ref - v_hat [kt], where v_hat is a
  complementary filter of the measured airspeed and the longitudinal accelerometer,
  dv_hat/dt = g (n_x - sin(theta)) + (v_meas - v_hat) / tau_v, as autothrottles use so that
  they hold the speed through the air mass and do not chase gusts;
* lateral:   phi_cmd = sat(k_psi wrap(psi_ref - psi)) in heading mode or phi_ref in a turn,
  aileron = a_0 + k_phi (phi_cmd - phi) - k_p p + k_phii int(phi_cmd - phi);
* yaw damper: rudder = r_0 + k_r r_wo, r_wo the yaw rate through a washout of tau_wo.

Gains per aircraft live in ``aircraft/<name>/autopilot.toml`` with the reasoning.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.pilot.maneuvers import AXES, HeadingChange, PulseTrain, RefRamp, Turn
from fdi_sim.units import G0_FPS2, KT_PER_FPS, RAD_PER_DEG

AIRCRAFT_DATA = Path(__file__).resolve().parents[2] / "aircraft"
BLOCK_STEPS = 120  # maneuver tables are evaluated one block of steps at a time
#: measurements the autopilot flies on
NEEDED = ("h_ft", "hdot_fps", "vc_kts", "theta_rad", "q_radps", "phi_rad", "p_radps", "psi_rad", "r_radps", "nx_g")


@dataclass(frozen=True)
class AutopilotGains:
    """Gains of one aircraft (see the module docstring for the laws; units in brackets).

    Attributes
    ----------
    k_h_per_s : altitude error to climb-rate command [1/s]
    hdot_max_fps : climb-rate command limit [ft/s]
    k_hdot_rad_per_fps : climb-rate error to pitch command [rad/(ft/s)]
    k_hi_rad_per_ft_s : altitude-error integral to pitch command [rad/(ft s)]
    k_turn_rad : pitch added in a bank per unit (1/cos(phi) - 1) [rad]
    theta_lim_rad : pitch command limit about trim [rad]
    k_theta : pitch error to elevator [1/rad]
    k_q : pitch rate to elevator [s/rad]
    k_v_per_kt : airspeed error to throttle [1/kt]
    k_vi_per_kt_s : airspeed-error integral to throttle [1/(kt s)]
    k_psi : heading error to bank command [-]
    phi_max_rad : bank command limit [rad]
    k_phi : bank error to aileron [1/rad]
    k_p : roll rate to aileron [s/rad]
    k_phii : bank-error integral to aileron [1/(rad s)]
    k_r : washed-out yaw rate to rudder [s/rad]
    tau_wo_s : yaw-damper washout time constant [s]
    tau_v_s : time constant of the airspeed complementary filter [s]
    throttle_max_norm : throttle limit [-]
    """

    k_h_per_s: float
    hdot_max_fps: float
    k_hdot_rad_per_fps: float
    k_hi_rad_per_ft_s: float
    k_turn_rad: float
    theta_lim_rad: float
    k_theta: float
    k_q: float
    k_v_per_kt: float
    k_vi_per_kt_s: float
    k_psi: float
    phi_max_rad: float
    k_phi: float
    k_p: float
    k_phii: float
    k_r: float
    tau_wo_s: float
    tau_v_s: float
    throttle_max_norm: float

    @classmethod
    def for_aircraft(cls, name: str) -> "AutopilotGains":
        """Load ``aircraft/<name>/autopilot.toml`` (angles there are in deg, converted here)."""
        base = "DHC6" if name.startswith("DHC6") else name
        data = tomllib.loads((AIRCRAFT_DATA / base / "autopilot.toml").read_text())["gains"]
        kw = {}
        for f in fields(cls):
            if f.name.endswith("_rad") and f.name.replace("_rad", "_deg") in data:
                kw[f.name] = data[f.name.replace("_rad", "_deg")] * RAD_PER_DEG
            else:
                kw[f.name] = float(data[f.name])
        return cls(**kw)


@dataclass(frozen=True, slots=True)
class PilotCommand:
    """The pilot's commands for one step (normalized) and the references it flew to."""

    t_s: float
    elevator_cmd_norm: float
    aileron_cmd_norm: float
    rudder_cmd_norm: float
    throttle_cmd_norm: float
    h_ref_ft: float
    vc_ref_kts: float
    psi_ref_rad: float
    phi_ref_rad: float


@dataclass(frozen=True)
class AutopilotModes:
    """Which holds are engaged (all off = fixed controls plus stick inputs)."""

    altitude: bool = True
    airspeed: bool = True
    lateral: bool = True


@dataclass(frozen=True)
class TrimPoint:
    """What the pilot needs from the trim: commands and attitude [norm, rad, ft, kt]."""

    elevator_cmd_norm: float
    aileron_cmd_norm: float
    rudder_cmd_norm: float
    throttle_cmd_norm: float
    theta_rad: float
    phi_rad: float
    psi_rad: float
    h_ft: float
    vc_kts: float


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Pilot:
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
        self.idx = {n: measurement_names.index(n) for n in NEEDED if n in measurement_names}
        self.sticks = [m for m in maneuvers if isinstance(m, PulseTrain)]
        self.ramps = sorted((m for m in maneuvers if isinstance(m, RefRamp)), key=lambda m: m.t_start_s)
        self.headings = sorted((m for m in maneuvers if isinstance(m, HeadingChange)), key=lambda m: m.t_start_s)
        self.turns = sorted((m for m in maneuvers if isinstance(m, Turn)), key=lambda m: m.t_start_s)
        # reference starting values of each ramp: the reference reached by the ramps before it
        self._ramp_start: list[float] = []
        last = {"h_ft": trim.h_ft, "vc_kts": trim.vc_kts}
        for r in self.ramps:
            prev = [q for q in self.ramps if q.channel == r.channel and q.t_start_s < r.t_start_s]
            start = last[r.channel]
            for q, s in zip(self.ramps, self._ramp_start):
                if q in prev:
                    start = float(q.apply(np.array([r.t_start_s]), np.array([start]), s)[0])
            self._ramp_start.append(start)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Clear integrators and filters (the pilot is deterministic; ``rng`` is unused)."""
        self._int_h = self._int_v = self._int_phi = 0.0
        self._r_wo_state = 0.0
        self._vc_lp = self.trim.vc_kts
        self._psi_hold = self.trim.psi_rad
        self._in_turn = False
        self._block_start = -(10**9)
        self._tab: NDArray[np.float64] = np.zeros((0, 8))

    def _fill_block(self, k0: int) -> None:
        """Tables for steps k0 .. k0+BLOCK_STEPS-1: [de, da, dr, dt, h_ref, hdot_ff, vc_ref, turn_phi(or nan)]."""
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
        self._tab, self._block_start = tab, k0

    def _psi_ref(self, t_s: float) -> float:
        psi = self._psi_hold
        for hc in self.headings:
            if t_s >= hc.t_start_s:
                psi = hc.psi_deg * RAD_PER_DEG
        return psi

    def step(self, t_s: float, y: NDArray[np.float64]) -> PilotCommand:
        """Commands for time ``t_s`` [s] from the measurement vector ``y``."""
        k = int(round(t_s / self.dt_s))
        if not (self._block_start <= k < self._block_start + BLOCK_STEPS):
            self._fill_block(k)
        row = self._tab[k - self._block_start]
        g, tr, dt, ix = self.g, self.trim, self.dt_s, self.idx
        de, da, dr, dthr, h_ref, hdot_ff, vc_ref, turn_phi = row
        elev, ail, rud, thr = tr.elevator_cmd_norm, tr.aileron_cmd_norm, tr.rudder_cmd_norm, tr.throttle_cmd_norm
        phi_ref = 0.0
        psi_ref = self._psi_ref(t_s)
        if self.modes.lateral:
            phi, p, r = y[ix["phi_rad"]], y[ix["p_radps"]], y[ix["r_radps"]]
            if turn_phi == turn_phi:  # not NaN: in a turn
                self._in_turn = True
                phi_cmd = phi_ref = turn_phi
            else:
                if self._in_turn:  # leaving a turn: hold the heading reached
                    self._in_turn = False
                    self._psi_hold = y[ix["psi_rad"]]
                    self.headings = [h for h in self.headings if h.t_start_s > t_s]
                    psi_ref = self._psi_hold
                e_psi = _wrap(psi_ref - y[ix["psi_rad"]])
                phi_cmd = phi_ref = max(-g.phi_max_rad, min(g.phi_max_rad, g.k_psi * e_psi))
            e_phi = phi_cmd - phi
            self._int_phi += e_phi * dt
            ail += g.k_phi * e_phi - g.k_p * p + g.k_phii * self._int_phi
            # washout r_wo = tau s / (1 + tau s) r = r - x, with the low-pass x' = (r - x) / tau (Euler)
            r_wo = r - self._r_wo_state
            self._r_wo_state += dt * r_wo / g.tau_wo_s
            rud += g.k_r * r_wo
        else:
            phi = tr.phi_rad
        if self.modes.altitude:
            e_h = h_ref - y[ix["h_ft"]]
            self._int_h += e_h * dt
            hdot_cmd = max(-g.hdot_max_fps, min(g.hdot_max_fps, g.k_h_per_s * e_h)) + hdot_ff
            cphi = max(math.cos(y[ix["phi_rad"]]), 0.5)
            dtheta = (g.k_hdot_rad_per_fps * (hdot_cmd - y[ix["hdot_fps"]]) + g.k_hi_rad_per_ft_s * self._int_h
                      + g.k_turn_rad * (1.0 / cphi - 1.0))
            dtheta = max(-g.theta_lim_rad, min(g.theta_lim_rad, dtheta))
            theta_cmd = tr.theta_rad + dtheta
            elev -= g.k_theta * (theta_cmd - y[ix["theta_rad"]]) - g.k_q * y[ix["q_radps"]]
        if self.modes.airspeed:
            # complementary filter: inertial acceleration at high frequency, airspeed at low frequency
            acc_kts = G0_FPS2 * KT_PER_FPS * (y[ix["nx_g"]] - math.sin(y[ix["theta_rad"]]))
            self._vc_lp += dt * (acc_kts + (y[ix["vc_kts"]] - self._vc_lp) / g.tau_v_s)
            e_v = vc_ref - self._vc_lp
            self._int_v += e_v * dt
            thr += g.k_v_per_kt * e_v + g.k_vi_per_kt_s * self._int_v
            # anti-windup: undo the integration when the throttle saturates
            if thr > g.throttle_max_norm or thr < 0.0:
                self._int_v -= e_v * dt
                thr = max(0.0, min(g.throttle_max_norm, thr))
        return PilotCommand(
            t_s, max(-1.0, min(1.0, elev + de)), max(-1.0, min(1.0, ail + da)), max(-1.0, min(1.0, rud + dr)),
            max(0.0, min(1.0, thr + dthr)), h_ref, vc_ref, psi_ref, phi_ref,
        )

"""The autopilot: altitude, airspeed and heading (or bank) holds, flying on the measurements.

Control laws (deviations about the trim commands; angles in rad, rates in rad/s, energies per
unit weight in ft, energy rates in ft/s; positive elevator is nose down on both aircraft):

* speed estimate. The hold is judged against the steady air mass, so the autopilot must not
  chase the gusts that the air data sees; MIL-F-8785C turbulence has so much low-frequency
  content (a 60 s mean of the longitudinal gust reaches 10 ft/s in moderate turbulence) that
  no filter on air data and accelerometers alone separates it from a speed change. The GNSS
  velocity (drift-free, gust-free) does: the wind is the ground velocity minus the air velocity,
  w_m = v_gnd - R_nb(phi, theta, psi) V_t [cos a cos b, sin b, sin a cos b] (horizontal only,
  V_t = r(h, vc) vc, r the ISA TAS/CAS ratio linearized about the trim point); its estimate
  starts at engagement (the first sample) and follows slowly, w_hat' = (w_m - w_hat) / tau_wind,
  so that gusts shorter than tau_wind hardly enter it. The airspeed relative to that air mass is
  v_s = |v_gnd - w_hat| (true airspeed scale). A second-order complementary filter blends v_s
  (low frequencies) with the inertial acceleration along the flight path (high frequencies) and
  estimates the acceleration bias: a_m is the specific force rotated by roll and pitch into the
  level, heading-aligned frame, plus gravity, projected on (heading, gamma = asin(hdot / V_0)):
  a_m = g [(cos th n_x + sin th n_zl) cos gamma - (cos th n_zl - sin th n_x + 1) sin gamma],
  n_zl = cos phi n_z + sin phi n_y;
  dv_hat/dt = a_m - b + 2 zeta (v_s - v_hat) / tau_v,  db/dt = -(v_s - v_hat) / tau_v^2.
  a = a_m - b, low-passed with tau_acc, is the acceleration fed back below; the speed error is
  e_v = r(h, vc_ref) vc_ref - v_hat.
  Consequences: the hold is as good as the wind estimate at engagement (in the simulation the
  turbulence starts from rest at t = 0, so the first sample sees the steady air plus sensor
  errors); a real change of the wind, and an airspeed-sensor fault, reach the speed hold only
  through the wind estimate, with the time constant tau_wind (the protections below act on the
  measured airspeed directly). Without GNSS velocity the autopilot does not start.
* longitudinal, total energy control (TECS, Lambregts 1983) when both holds are engaged:
  hdot_c = sat(k_h e_h + hdot_ff, hdot_min, hdot_max),  vdot_c = sat(k_v e_v, vdot_max),
  pe = hdot_c - hdot,  ke = (V_0 / g) (vdot_c - a)  (potential and kinetic energy-rate errors),
  throttle = t_0 + k_te_p (pe + ke) + k_te_i int(pe + ke)            (total energy: thrust),
  theta_c  = theta_0 + k_eb_p B + k_eb_i int(B) + k_turn (1/cos(phi) - 1),
  B = (2 - w_v) pe - w_v ke                                           (energy balance: pitch),
  elevator = e_0 - (k_theta (theta_c - theta) - k_q q).
  The throttle answers every loss of total energy (downdraft, pull-up, drag) before the speed
  has changed, and the elevator trades height for speed. w_v (0 height only .. 2 speed only)
  moves from w_speed to w_speed_sat while the throttle sits at a stop: it decides where an
  energy deficit or surplus that the thrust cannot cover goes. With the altitude hold off the
  elevator stays at trim and the throttle holds the speed (pe = 0); with the airspeed hold off
  the throttle stays at trim and the elevator holds the height (B = pe).
* envelope protection on the pitch command (limits +-theta_lim about trim): the nose-down
  authority fades when the measured airspeed (low-passed with tau_vlim) is more than v_lim
  above the reference, the nose-up authority when it is more than v_lim below, or when the
  angle-of-attack vane (low-passed) comes within alpha_band of alpha_max.
* lateral:   phi_cmd = LP(sat(k_psi wrap(psi_ref - psi))) in heading mode, low-passed with tau_phi
  (yaw gusts swing the heading by several degrees within a second; the bank command should not
  follow them), or the turn's bank in a turn (the filter state too, so the roll-out is smooth),
  aileron = a_0 + k_phi (phi_cmd - phi) - k_p p + k_phii int(phi_cmd - phi) - k_absbeta |beta|
  (the last term cancels a rolling moment even in sideslip, see the DHC-6 gains; the integral
  stops while the command sits at a stop and the error pushes it further);
* yaw:       rudder = r_0 + k_r r_wo - k_beta beta, r_wo the yaw rate through a washout tau_wo.

Gains per aircraft live in ``aircraft/<name>/autopilot.toml`` with the reasoning. The step is one
compiled call (:mod:`fdi_sim.pilot._kernels`, numba): :meth:`Pilot.step_into` writes the commands
into an array the caller owns, :meth:`Pilot.step` wraps it and returns a :class:`PilotCommand`.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields
from typing import Callable, NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray

import fdi_sim.pilot._kernels as K  # the module, not its package (no import cycle through __init__)
from fdi_sim.data import aircraft_file  # aircraft/ in a checkout, packaged in a wheel
from fdi_sim.isa import vt_from_vc
from fdi_sim.pilot.maneuvers import AXES, HeadingChange, PulseTrain, RefRamp, Turn
from fdi_sim.units import FPS_PER_KT, G0_FPS2, RAD_PER_DEG

#: measurements the autopilot flies on
NEEDED = ("h_ft", "hdot_fps", "vc_kts", "theta_rad", "q_radps", "phi_rad", "p_radps", "psi_rad", "r_radps", "nx_g", "ny_g",
          "nz_g", "alpha_rad", "beta_rad", "v_north_fps", "v_east_fps", "v_down_fps")

@dataclass(frozen=True)
class AutopilotGains:
    """Gains of one aircraft (see the module docstring for the laws; units in brackets).

    Attributes
    ----------
    k_h_per_s : altitude error to climb-rate demand [1/s]
    hdot_max_fps : limit of the climb-rate demand, maneuver feedforward included [ft/s]
    hdot_min_fps : limit of the descent-rate demand (negative) [ft/s]
    k_v_per_s : speed error to acceleration demand [1/s]
    vdot_max_fps2 : limit of the acceleration demand [ft/s^2]
    k_te_p_per_fps : total-energy-rate error to throttle [1/(ft/s)]
    k_te_i_per_ft : integral of the total-energy-rate error to throttle [1/ft]
    k_eb_p_rad_per_fps : energy-balance-rate error to pitch command [rad/(ft/s)]
    k_eb_i_rad_per_ft : integral of the energy-balance-rate error to pitch command [rad/ft]
    w_speed : speed weight of the energy balance, 0 (height only) .. 2 (speed only) [-]
    w_speed_sat : speed weight while the throttle is at a stop and cannot supply the energy [-]
    tau_sat_s : time constant of the blend between the two speed weights [s]
    v_band_kt : airspeed band over which the pitch authority fades (envelope protection) [kt]
    tau_vlim_s : low-pass time constant of the measured airspeed and angle of attack used by
        the protections [s]
    alpha_max_rad : angle of attack (vane, low-passed) at which the nose-up pitch authority is gone [rad]
    alpha_band_rad : band below alpha_max over which the nose-up authority fades [rad]
    v_lim_kt : measured-airspeed deviation (low-passed) beyond which the pitch authority
        toward a larger deviation fades (overspeed / underspeed protection) [kt]
    k_turn_rad : pitch added in a bank per unit (1/cos(phi) - 1) [rad]
    theta_lim_rad : pitch command limit about trim [rad]
    k_theta : pitch error to elevator [1/rad]
    k_q : pitch rate to elevator [s/rad]
    k_psi : heading error to bank command [-]
    tau_phi_s : low-pass time constant of the bank command in heading mode [s]
    phi_max_rad : bank command limit [rad]
    k_phi : bank error to aileron [1/rad]
    k_p : roll rate to aileron [s/rad]
    k_phii : bank-error integral to aileron [1/(rad s)]
    k_absbeta : aileron per rad of |sideslip| (compensates a rolling moment even in beta) [1/rad]
    k_r : washed-out yaw rate to rudder [s/rad]
    k_beta : sideslip to rudder (directional stiffness) [1/rad]
    tau_wo_s : yaw-damper washout time constant [s]
    tau_wind_s : time constant of the wind estimate (GNSS ground velocity minus air velocity) [s]
    tau_v_s : natural period / (2 pi) of the airspeed complementary filter, 1/omega [s]
    zeta_v : damping ratio of the airspeed complementary filter [-]
    tau_acc_s : low-pass time constant of the acceleration used in the energy-rate feedback [s]
    throttle_min_norm : throttle lower limit [-]
    throttle_max_norm : throttle upper limit [-]
    """

    k_h_per_s: float
    hdot_max_fps: float
    hdot_min_fps: float
    k_v_per_s: float
    vdot_max_fps2: float
    k_te_p_per_fps: float
    k_te_i_per_ft: float
    k_eb_p_rad_per_fps: float
    k_eb_i_rad_per_ft: float
    w_speed: float
    w_speed_sat: float
    tau_sat_s: float
    v_band_kt: float
    v_lim_kt: float
    tau_vlim_s: float
    alpha_max_rad: float
    alpha_band_rad: float
    k_turn_rad: float
    theta_lim_rad: float
    k_theta: float
    k_q: float
    k_psi: float
    tau_phi_s: float
    phi_max_rad: float
    k_phi: float
    k_p: float
    k_phii: float
    k_absbeta: float
    k_r: float
    k_beta: float
    tau_wo_s: float
    tau_wind_s: float
    tau_v_s: float
    zeta_v: float
    tau_acc_s: float
    throttle_min_norm: float
    throttle_max_norm: float

    @classmethod
    def for_aircraft(cls, name: str) -> "AutopilotGains":
        """Load ``aircraft/<name>/autopilot.toml`` (angles there are in deg, converted here)."""
        data = tomllib.loads(aircraft_file(name, "autopilot.toml").read_text())["gains"]
        kw = {}
        for f in fields(cls):
            if f.name.endswith("_rad") and f.name.replace("_rad", "_deg") in data:
                kw[f.name] = data[f.name.replace("_rad", "_deg")] * RAD_PER_DEG
            else:
                kw[f.name] = float(data[f.name])
        return cls(**kw)


class PilotCommand(NamedTuple):
    """The pilot's commands for one step (normalized) and the references it flew to.

    A named tuple: built once per simulation step, and a frozen dataclass takes ~4x longer to build.
    """

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


_TUPLE_NEW = tuple.__new__


class Pilot:
    """Autopilot plus maneuver schedule; ``reset`` then ``step(t_s, y)`` (or ``step_into``) every step.

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

    Notes
    -----
    Everything the step reads lives in two float64 arrays, the constants ``_par`` and the filter
    states ``_state`` (layouts in :mod:`fdi_sim.pilot._kernels`); :meth:`step` and
    :meth:`step_into` run the same compiled function on them, so they can be mixed. The first
    call compiles it (a few seconds) or loads it from numba's cache in ``__pycache__``.
    """

    def __init__(self, gains: AutopilotGains, modes: AutopilotModes, trim: TrimPoint, maneuvers: Sequence[object],
                 measurement_names: Sequence[str], dt_s: float) -> None:
        missing = [n for n in NEEDED if n not in measurement_names]
        if missing and (modes.altitude or modes.airspeed or modes.lateral):
            raise ValueError(f"the autopilot needs the measurements {missing}")
        self.g, self.modes, self.trim, self.dt_s = gains, modes, trim, dt_s
        names = list(measurement_names)
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
        # the maneuver tables as rows of floats computed here once, with the arithmetic the
        # maneuvers themselves use (PulseTrain.pulses), so a row is the float the numpy tables held
        self._par = K.pack_params(
            tuple(getattr(gains, f) for f in K.LAT_GAINS), tuple(getattr(gains, f) for f in K.LON_GAINS),
            (trim.elevator_cmd_norm, trim.aileron_cmd_norm, trim.rudder_cmd_norm, trim.throttle_cmd_norm,
             trim.theta_rad, trim.h_ft, trim.vc_kts),
            (self._v0_fps, self._fps_per_kcas, self._r_h, self._r_v, self._ke_s), dt_s,
            (modes.lateral, modes.altitude, modes.airspeed),
            [names.index(n) if n in names else -1 for n in NEEDED],
            [(AXES.index(m.axis), m.pulses()) for m in self.sticks],
            [(0.0 if r.channel == "h_ft" else 1.0, r.t_start_s, r.target, r.rate, s)
             for r, s in zip(self.ramps, self._ramp_start)],
            [(tr.t_start_s, tr.t_start_s + tr.duration_s, tr.phi_deg * RAD_PER_DEG) for tr in self.turns],
            [(hc.t_start_s, hc.psi_deg * RAD_PER_DEG) for hc in self._headings],
        )
        self._state = np.zeros(K.N_STATE)
        self._out = np.zeros(8)  # step()'s own output buffer
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Clear integrators and filters (the pilot is deterministic; ``rng`` is unused)."""
        st = self._state
        st[:] = 0.0  # integrators, washout, wind, acceleration bias and low-pass, throttle-stop blend, alpha
        st[K.S_V_HAT] = self._fps_per_kcas * self.trim.vc_kts
        st[K.S_R_REF] = self._fps_per_kcas  # TAS/CAS ratio at the reference speed and measured height
        st[K.S_VC_LP] = self.trim.vc_kts
        st[K.S_FIRST] = 1.0  # the angle-of-attack filter and the wind estimate start from the first measurement
        st[K.S_PSI_HOLD] = self.trim.psi_rad
        st[K.S_HEAD0] = 0.0  # heading changes still ahead start here (a turn exit drops past ones)

    @property
    def headings(self) -> list[HeadingChange]:
        """The heading changes still ahead (a turn exit drops those started by then)."""
        return list(self._headings[int(self._state[K.S_HEAD0]):])

    @property
    def airspeed_estimate_kts(self) -> float:
        """The speed estimate relative to the estimated steady air mass, as calibrated airspeed [kt]."""
        return float(self._state[K.S_V_HAT]) / float(self._state[K.S_R_REF])

    @property
    def wind_estimate_fps(self) -> tuple[float, float]:
        """The estimated steady wind (north, east), the direction it blows to [ft/s]."""
        return float(self._state[K.S_WIND_N]), float(self._state[K.S_WIND_E])

    def step_into(self, t_s: float, y: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """Commands for time ``t_s`` [s] into ``out``, no object created (the loop's fast path).

        Parameters
        ----------
        t_s : float
            Time [s] (a Python float or float64; an int would compile a second specialization).
        y : ndarray, float64, shape (n_measurements,)
            Measurements in ``measurement_names`` order (read only).
        out : ndarray, float64, shape (8,)
            Receives (elevator, aileron, rudder, throttle [norm], h_ref [ft], vc_ref [kt],
            psi_ref [rad], phi_ref [rad]): fields 1..8 of :meth:`step`'s result, the same floats.
        """
        K.step(t_s, y, out, self._state, self._par)

    def compiled(self) -> tuple[Callable[..., None], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`step_into` without its Python frame, for the loop: ``(step, state, params)`` with
        ``step(t_s, y, out, state, params)`` the same call (the arrays are the pilot's own; :meth:`reset`
        changes them in place)."""
        return K.step, self._state, self._par

    def step(self, t_s: float, y: NDArray[np.float64] | list[float]) -> PilotCommand:
        """Commands for time ``t_s`` [s] from the measurement vector ``y`` (array or list of floats).

        :meth:`step_into` on a float64 copy of ``y`` (none for a contiguous float64 array), as a
        :class:`PilotCommand` of Python floats.
        """
        ya = np.array(y, dtype=np.float64) if type(y) is list else np.ascontiguousarray(y, dtype=np.float64)
        out = self._out
        K.step(float(t_s), ya, out, self._state, self._par)
        # tuple.__new__ builds the same PilotCommand without the named tuple's Python-level __new__ (0.2 us)
        return _TUPLE_NEW(PilotCommand, (t_s, *out.tolist()))

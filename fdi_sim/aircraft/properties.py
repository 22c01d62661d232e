"""The one table between JSBSim property names and fdi-sim's unit-suffixed signal names.

Everything outside ``fdi_sim.aircraft`` speaks only the suffixed names. A few signals map to
different properties on each aircraft (the DHC-6 aero model reads the *left* aileron only).
A signal is one property, the sum of several (a tuple: thrust of both engines) or one property
times a constant (:class:`Scaled`: the propeller's reaction torque turned into the gauge's torque).
The truth state is the common :data:`TRUTH_SIGNALS` followed by the aircraft's engine signals
(:data:`ENGINE_SIGNALS`); :func:`truth_signals` gives the whole tuple.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

from fdi_sim.data import aircraft_base

# name -> JSBSim property, common to both aircraft
_COMMON: dict[str, str] = {
    "t_s": "simulation/sim-time-sec",
    # air-relative and inertial velocities
    "vt_fps": "velocities/vt-fps",
    "vc_kts": "velocities/vc-kts",  # calibrated airspeed, about KIAS
    "mach": "velocities/mach",
    "alpha_rad": "aero/alpha-rad",
    "beta_rad": "aero/beta-rad",
    "u_body_fps": "velocities/u-fps",
    "v_body_fps": "velocities/v-fps",
    "w_body_fps": "velocities/w-fps",
    "hdot_fps": "velocities/h-dot-fps",
    # inertial velocity in the local NED frame (ground speed components)
    "v_north_fps": "velocities/v-north-fps",
    "v_east_fps": "velocities/v-east-fps",
    "v_down_fps": "velocities/v-down-fps",
    "gamma_rad": "flight-path/gamma-rad",
    # body rates relative to the Earth frame (what a strapdown gyro minus earth rate sees)
    "p_radps": "velocities/p-rad_sec",
    "q_radps": "velocities/q-rad_sec",
    "r_radps": "velocities/r-rad_sec",
    # attitude
    "phi_rad": "attitude/phi-rad",
    "theta_rad": "attitude/theta-rad",
    "psi_rad": "attitude/psi-rad",
    # position
    "h_ft": "position/h-sl-ft",
    "h_agl_ft": "position/h-agl-ft",
    "lat_deg": "position/lat-geod-deg",
    "lon_deg": "position/long-gc-deg",
    # specific force at the pilot station [g]; JSBSim sign: nz = -1 in level flight
    "nx_g": "accelerations/n-pilot-x-norm",
    "ny_g": "accelerations/n-pilot-y-norm",
    "nz_g": "accelerations/n-pilot-z-norm",
    "qbar_psf": "aero/qbar-psf",
    # atmosphere: turbulence velocity (NED) as JSBSim computes it
    "turb_north_fps": "atmosphere/turb-north-fps",
    "turb_east_fps": "atmosphere/turb-east-fps",
    "turb_down_fps": "atmosphere/turb-down-fps",
    # pilot commands (inputs)
    "elevator_cmd_norm": "fcs/elevator-cmd-norm",
    "aileron_cmd_norm": "fcs/aileron-cmd-norm",
    "rudder_cmd_norm": "fcs/rudder-cmd-norm",
    "throttle_cmd_norm": "fcs/throttle-cmd-norm",
    "pitch_trim_cmd_norm": "fcs/pitch-trim-cmd-norm",
    # surface positions read by the aero model
    "elevator_pos_rad": "fcs/elevator-pos-rad",
    "rudder_pos_rad": "fcs/rudder-pos-rad",
}

@dataclass(frozen=True)
class Scaled:
    """A signal that is one JSBSim property times a constant: ``signal = factor * prop``.

    Attributes
    ----------
    prop : str
        JSBSim property.
    factor : float
        Multiplier [signal unit per property unit].
    """

    prop: str
    factor: float


#: what one entry of the property map may be: a property, a sum of properties, a scaled property
PropertySpec = str | tuple[str, ...] | Scaled


def _engine_gauges(i: int) -> dict[str, PropertySpec]:
    """The PT6A-27 cockpit gauges of DHC-6 engine ``i`` (0 left, y = -109 in; 1 right), as truth.

    * ``n1_<i>_pct``: gas-generator speed Ng [% of 37 500 rpm], JSBSim's ``FGTurboProp`` N1.
    * ``torque_<i>_ftlb``: propeller shaft torque [lbf ft]. JSBSim gives the torque the propeller
      absorbs, ``propeller-torque-ftlb = -sense P_required / omega`` (FGPropeller; ``sense`` = +1 on
      both DHC-6 propellers, so the reading is negative): the gauge is its negative. It equals the
      engine's shaft torque ``550 P_hp / omega`` at steady rpm and differs by the propeller's
      ``I dOmega/dt`` while the rpm moves (0.05 % on a full-throttle step, far below the gauge's 1 %).
    * ``prop_<i>_rpm``: propeller speed [rpm].
    """
    e = f"propulsion/engine[{i}]"
    return {
        f"n1_{i}_pct": f"{e}/n1",
        f"torque_{i}_ftlb": Scaled(f"{e}/propeller-torque-ftlb", -1.0),
        f"prop_{i}_rpm": f"{e}/propeller-rpm",
    }


_PER_AIRCRAFT: dict[str, dict[str, PropertySpec]] = {
    "f16": {
        "aileron_pos_rad": "fcs/aileron-pos-rad",
        "throttle_pos_norm": "fcs/throttle-pos-norm",
        "thrust_lbf": "propulsion/engine/thrust-lbs",
        "flaps_pos_rad": "fcs/tef-pos-rad",  # trailing-edge flaps (automatic; 0 above 250 KCAS)
    },
    "DHC6": {
        "aileron_pos_rad": "fcs/left-aileron-pos-rad",
        "throttle_pos_norm": "fcs/throttle-pos-norm",
        "thrust_lbf": ("propulsion/engine[0]/thrust-lbs", "propulsion/engine[1]/thrust-lbs"),  # both engines, summed
        "flaps_pos_rad": "fcs/flap-pos-rad",
        **_engine_gauges(0),
        **_engine_gauges(1),
    },
}

#: signals of the truth state, in the order logged on ``/truth/state``
TRUTH_SIGNALS: tuple[str, ...] = (
    "vt_fps", "vc_kts", "mach", "alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps",
    "phi_rad", "theta_rad", "psi_rad", "h_ft", "hdot_fps", "gamma_rad", "nx_g", "ny_g", "nz_g",
    "u_body_fps", "v_body_fps", "w_body_fps", "v_north_fps", "v_east_fps", "v_down_fps", "qbar_psf",
    "lat_deg", "lon_deg",
    "turb_north_fps", "turb_east_fps", "turb_down_fps",
)
#: per aircraft, the engine signals appended to :data:`TRUTH_SIGNALS` on ``/truth/state`` (and
#: measured by the engine gauges of the sensor suite). The F-16 has none yet: its logs stay as they
#: were (its F100 core speed would be ``propulsion/engine/n2``, one entry here and one gauge).
ENGINE_SIGNALS: dict[str, tuple[str, ...]] = {
    "f16": (),
    "DHC6": ("n1_0_pct", "n1_1_pct", "torque_0_ftlb", "torque_1_ftlb", "prop_0_rpm", "prop_1_rpm"),
}
#: the pilot's commands, in the order logged on ``/commands/pilot``
COMMAND_SIGNALS: tuple[str, ...] = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
#: what the plant actually flies, logged on ``/truth/surfaces``
SURFACE_SIGNALS: tuple[str, ...] = (
    "elevator_pos_rad", "aileron_pos_rad", "rudder_pos_rad", "throttle_pos_norm", "thrust_lbf", "flaps_pos_rad",
)


@dataclass(frozen=True)
class SurfaceSpec:
    """A control surface the fault injector can take over (JSBSIM_NOTES sec. 3.2, 3.4).

    Attributes
    ----------
    target : str
        Fault target name (``"elevator"``, ``"aileron"``, ``"rudder"``).
    positions : tuple of str
        JSBSim nodes the aero model reads for this surface; a fault holds all of them, node ``i``
        at ``scales[i]`` times the surface angle.
    healthy : str
        The FCS component's own node: the position a healthy actuator would give [rad].
    min_deg, max_deg : float
        Travel stops, from the model's ``aerosurface_scale`` range [deg].
    rate_degps : float
        Fastest travel of the healthy actuator [deg/s]: the model's kinematic traverse time
        where it has one, otherwise a documented typical value (see ``source``).
    source : str
        Where the numbers come from.
    """

    target: str
    positions: tuple[str, ...]
    healthy: str
    min_deg: float
    max_deg: float
    rate_degps: float
    source: str
    scales: tuple[float, ...] = ()

    def scale(self, i: int) -> float:
        """Node ``i``'s value per radian of surface angle (1 unless given)."""
        return self.scales[i] if i < len(self.scales) else 1.0


# F-16 (f16.xml, Flight Control): elevator kinematic -1..1 in 0.3 s on +-0.436 rad -> 167 deg/s;
# rudder -1..1 in 0.4 s on +-0.524 rad -> 150 deg/s; the aileron has no kinematic in the model: 80 deg/s
# is the aileron rate limit used with the NASA F-16 data in Stevens & Lewis, Aircraft Control and
# Simulation (2nd ed., sec. 4.x; elevator 60, aileron 80, rudder 120 deg/s) -- an assumption.
# DHC-6 (Systems/Conventional Controls.xml): cable-driven, no actuator model; 30 deg/s is the
# documented assumption for a runaway autopilot servo or a jammed-then-released cable.
def _deg(rad: float) -> float:
    # stops are the XML ranges in rad, exactly (a rounded degree value would overshoot the model's stop)
    return math.degrees(rad)


SURFACES: dict[str, dict[str, SurfaceSpec]] = {
    "f16": {
        "elevator": SurfaceSpec("elevator", ("fcs/elevator-pos-rad",), "fcs/elevator-position", _deg(-0.436), _deg(0.436), 167.0,
                                "f16.xml fcs/elevator-position range +-0.436 rad, kinematic 0.3 s"),
        # the roll term reads fcs/aileron-pos-rad; the kinematic aileron path (left-aileron-pos-norm,
        # +-1 for +-0.375 rad) drives the flaperons, whose mix enters lift and drag (JSBSIM_NOTES 1.2,
        # bug 2): a roll-channel fault holds both, or the stick still moves the flaperons
        "aileron": SurfaceSpec("aileron", ("fcs/aileron-pos-rad", "fcs/left-aileron-pos-norm"), "fcs/aileron-control",
                               _deg(-0.375), _deg(0.375), 80.0,
                               "f16.xml fcs/aileron-control range +-0.375 rad; rate assumed (Stevens & Lewis)",
                               scales=(1.0, 1.0 / 0.375)),
        "rudder": SurfaceSpec("rudder", ("fcs/rudder-pos-rad",), "fcs/rudder-control", _deg(-0.524), _deg(0.524), 150.0,
                              "f16.xml fcs/rudder-control range +-0.524 rad, kinematic 0.4 s"),
    },
    "DHC6": {
        "elevator": SurfaceSpec("elevator", ("fcs/elevator-pos-rad",), "fcs/elevator-control", _deg(-0.454), _deg(0.244), 30.0,
                                "Conventional Controls.xml Elevator Control range -0.454..0.244 rad; rate assumed"),
        # the aero model reads the left aileron as the roll-channel deflection; both are held
        "aileron": SurfaceSpec("aileron", ("fcs/left-aileron-pos-rad", "fcs/right-aileron-pos-rad"),
                               "fcs/left-aileron-control", _deg(-0.28), _deg(0.33), 30.0,
                               "Conventional Controls.xml Left Aileron Control range -0.28..0.33 rad; rate assumed"),
        "rudder": SurfaceSpec("rudder", ("fcs/rudder-pos-rad",), "fcs/rudder-control", _deg(-0.28), _deg(0.28), 30.0,
                              "Conventional Controls.xml Rudder Control range +-0.28 rad; rate assumed"),
    },
}


#: number of engines (fault targets ``engine_0`` ...)
ENGINE_COUNT: dict[str, int] = {"f16": 1, "DHC6": 2}


def surfaces(aircraft: str) -> dict[str, SurfaceSpec]:
    """The fault-injectable surfaces of an aircraft, by target name."""
    return SURFACES[aircraft_base(aircraft)]


def truth_signals(aircraft: str) -> tuple[str, ...]:
    """The signals of ``/truth/state`` for one aircraft: :data:`TRUTH_SIGNALS` then its engine signals.

    The common signals come first and in the same order on every aircraft, so their indexes do not
    depend on the aircraft.
    """
    return TRUTH_SIGNALS + ENGINE_SIGNALS[aircraft_base(aircraft)]


def property_map(aircraft: str) -> MappingProxyType[str, PropertySpec]:
    """Signal name -> JSBSim property for one aircraft (``"f16"`` or ``"DHC6"``-based).

    A tuple of properties means the signal is their sum (thrust of several engines); a
    :class:`Scaled` one property times a constant.
    """
    base = aircraft_base(aircraft)
    if base not in _PER_AIRCRAFT:
        raise KeyError(aircraft)
    return MappingProxyType({**_COMMON, **_PER_AIRCRAFT[base]})

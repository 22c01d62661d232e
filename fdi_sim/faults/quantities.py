"""Fault magnitudes carry their unit in their key, in any unit of the target's dimension.

A fault on ``alpha_rad`` may give ``bias_deg = 2`` or ``bias_rad = 0.035``; a drift on ``vc_kts``
``drift_ktps = 0.1`` (a rate: the target's unit per second); a stuck elevator ``position_deg = -5``;
a throttle ``position_norm = 0.2``. The magnitude is converted here to the target's native unit
(the unit of its signal name: rad for surfaces, norm for the throttle, the sensor's suffix).
"""
from __future__ import annotations

from fdi_sim.units import FPS_PER_KT, FT_PER_M, G0_FPS2, RAD_PER_DEG

# dimension -> {unit: factor to the dimension's base unit}
_DIMENSIONS: dict[str, dict[str, float]] = {
    "angle": {"rad": 1.0, "deg": RAD_PER_DEG},
    "angular_rate": {"radps": 1.0, "degps": RAD_PER_DEG},
    "angular_acceleration": {"radps2": 1.0, "degps2": RAD_PER_DEG},
    "length": {"ft": 1.0, "m": FT_PER_M},
    "speed": {"fps": 1.0, "kts": FPS_PER_KT, "mps": FT_PER_M},
    "acceleration": {"fps2": 1.0, "ktps": FPS_PER_KT, "mps2": FT_PER_M, "g": G0_FPS2},
    "jerk": {"fps3": 1.0, "gps": G0_FPS2},
    "normalized": {"norm": 1.0},
    "normalized_rate": {"normps": 1.0},
    "mach": {"mach": 1.0},
    "mach_rate": {"machps": 1.0},
    "pressure": {"psf": 1.0},
    "pressure_rate": {"psfps": 1.0},
    "eta": {"eta": 1.0},
    # engine gauges (DHC-6 PT6A: n1_<i>_pct, torque_<i>_ftlb, prop_<i>_rpm)
    "percent": {"pct": 1.0},
    "percent_rate": {"pctps": 1.0},
    "torque": {"ftlb": 1.0},
    "torque_rate": {"ftlbps": 1.0},
    "rotational_speed": {"rpm": 1.0},
    "rotational_speed_rate": {"rpmps": 1.0},
}
_RATE_OF: dict[str, str] = {
    "angle": "angular_rate", "angular_rate": "angular_acceleration", "length": "speed", "speed": "acceleration",
    "acceleration": "jerk", "normalized": "normalized_rate", "mach": "mach_rate", "pressure": "pressure_rate",
    "percent": "percent_rate", "torque": "torque_rate", "rotational_speed": "rotational_speed_rate",
}
_UNIT_DIM: dict[str, str] = {u: d for d, units in _DIMENSIONS.items() for u in units}


def native_unit(signal: str) -> str:
    """The unit of a signal from its name: ``q_radps`` -> ``radps``, ``mach`` -> ``mach``."""
    unit = signal.rsplit("_", 1)[-1]
    if unit not in _UNIT_DIM:
        raise KeyError(f"signal {signal!r} has no known unit suffix")
    return unit


def target_unit(family: str, target: str) -> str | None:
    """Native unit of a fault target: rad for surfaces, norm for the throttle, a sensor's suffix;
    None for engines and the airframe (their magnitudes are dimensionless)."""
    if family == "actuator":
        return "norm" if target == "throttle" else "rad"
    if family == "sensor":
        return native_unit(target)
    return None


def allowed_units(native: str, rate: bool = False) -> tuple[str, ...]:
    """Units a magnitude of a target in unit ``native`` may be given in (``rate``: per second)."""
    dim = _UNIT_DIM[native]
    if rate:
        dim = _RATE_OF[dim]
    return tuple(_DIMENSIONS[dim])


def to_native(value: float, unit: str, native: str, rate: bool = False) -> float:
    """Convert ``value`` [unit] to the target's native unit (or its rate, per second).

    Raises
    ------
    ValueError
        The unit is not of the right dimension; the message lists the allowed ones.
    """
    allowed = allowed_units(native, rate)
    if unit not in allowed:
        raise ValueError(f"unit {unit!r} does not fit a target in {native}{' per second' if rate else ''}; "
                         f"use one of {', '.join(allowed)}")
    # a rate dimension mirrors the factors of its base (kts 1.688 fps <-> ktps 1.688 fps/s), so the
    # native factor is the native unit's factor in its own dimension in both cases
    return value * _DIMENSIONS[_UNIT_DIM[unit]][unit] / _DIMENSIONS[_UNIT_DIM[native]][native]

"""What each fault does, one step at a time, in the target's native unit.

Actuator laws (surfaces in rad, the throttle in normalized units) map the healthy position ``h``
(what the healthy actuator would give now), the position flown in the last step ``p`` and the
onset position ``p0`` to the faulty position::

    stuck        v = position, or p0
    float        v = p + dt / tau (delta_float - p),  delta_float = r * local flow angle
    hard-over    v = p moved toward the stop at rate
    runaway      v = p moved at the signed rate (until a stop)
    loss         v = effectiveness * h
    bias         v = h + bias
    rate-limit   v = p moved toward h at no more than rate
    oscillation  v = h + A sin(2 pi f (t - t_on))

then blended with the level ``w`` of the profile, ``v <- h + w (v - h)``, and clipped to the
stops. Float physics: a released surface with hinge-moment coefficient
``Ch = Ch_alpha alpha_local + Ch_delta delta`` trails to ``Ch = 0``, i.e.
``delta_float = -(Ch_alpha / Ch_delta) alpha_local`` (Etkin & Reid, Dynamics of Flight, sec. on
hinge moments; ``r = -Ch_alpha/Ch_delta``, about 0.5-0.8 for unbalanced surfaces). Positive
elevator is trailing edge down, so it floats trailing edge up with alpha:
``delta_float = -r alpha``; the rudder trails with the sideslip, ``delta_float = +r beta`` (sign
checked against both models' yaw response in the tests); the ailerons float symmetrically, which
the roll channel does not see: ``delta_float = 0`` (the roll-damping loss of antisymmetric float
is neglected). The surface reaches ``delta_float`` with a first-order lag ``tau`` (the surface's
own aerodynamic and inertial response, about 0.1-0.5 s).
"""
from __future__ import annotations

import math


def toward(p: float, target: float, max_step: float) -> float:
    """Move ``p`` toward ``target`` by at most ``max_step`` (>= 0)."""
    d = target - p
    if d > max_step:
        return p + max_step
    if d < -max_step:
        return p - max_step
    return target


def actuator_value(law: str, c: dict, t_s: float, t_on_s: float, h: float, p: float, p0: float, dt_s: float,
                   flow_angle_rad: float) -> float:
    """The faulty position before blending and clipping (see the module docstring).

    Parameters
    ----------
    law : str
    c : dict
        The law's constants in native units (``position``, ``rate``, ``stop``, ``bias``, ...).
    t_s, t_on_s : float
        Time now and of the onset of the current window [s].
    h, p, p0 : float
        Healthy position now, position flown in the last step, position at onset [native].
    dt_s : float
    flow_angle_rad : float
        Local flow angle for ``float`` [rad].
    """
    if law == "stuck":
        return c["position"] if c["position"] is not None else p0
    if law == "float":
        return p + dt_s / c["tau_s"] * (c["float_sign"] * c["float_ratio"] * flow_angle_rad - p)
    if law in ("hard-over", "runaway"):
        return toward(p, c["stop"], c["rate"] * dt_s)
    if law == "loss":
        return c["effectiveness"] * h
    if law == "bias":
        return h + c["bias"]
    if law == "rate-limit":
        return toward(p, h, c["rate"] * dt_s)
    if law == "oscillation":
        return h + c["amplitude"] * math.sin(2.0 * math.pi * c["frequency_hz"] * (t_s - t_on_s))
    raise ValueError(f"unknown actuator law {law!r}")

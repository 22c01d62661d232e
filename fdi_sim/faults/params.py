"""Parameter models of every fault type (the ``[[faults]]`` entries of a scenario).

Common keys (all faults): ``type`` (registered id), ``target``, optional ``label`` (the name of
the fault's fields in the log; default ``<target>_<type name>``), and the timing of
:class:`~fdi_sim.faults.profile.ProfileParams` (``t_start_s``, ``t_end_s``, ``ramp_s``,
``intermittent``).

Magnitudes carry their unit in the key, in any unit of the target's dimension
(:mod:`fdi_sim.faults.quantities`): ``bias_deg`` or ``bias_rad`` on a surface, ``position_norm``
on the throttle, ``bias_kts`` on ``vc_kts``, ``drift_degps2`` (a rate) on ``q_radps``.
"""
from __future__ import annotations

import difflib
from typing import ClassVar, Literal

from pydantic import ConfigDict, Field, model_validator

from fdi_sim.faults.profile import ProfileParams
from fdi_sim.faults.quantities import _UNIT_DIM, allowed_units, target_unit


class FaultParams(ProfileParams):
    """Keys common to all faults; subclasses declare their magnitudes in ``MAGNITUDES``."""

    model_config = ConfigDict(extra="allow", frozen=True)
    type: str
    target: str = Field(min_length=1, description="surface, throttle, engine_<i>, sensor name or airframe")
    label: str | None = Field(default=None, pattern=r"^[a-z][a-z0-9_]*$", max_length=60)

    #: magnitude prefix -> (required, is a rate per second)
    MAGNITUDES: ClassVar[dict[str, tuple[bool, bool]]] = {}

    @model_validator(mode="after")
    def _magnitude_keys(self) -> "FaultParams":
        seen: dict[str, str] = {}
        for key, value in (self.model_extra or {}).items():
            prefix = next((p for p in sorted(self.MAGNITUDES, key=len, reverse=True) if key.startswith(p + "_")), None)
            if prefix is None:
                takes = ", ".join(f"{p}_<unit>" for p in self.MAGNITUDES) or "no magnitude"
                raise ValueError(f"unknown key {key!r}: this fault takes {takes} besides the common keys "
                                 "(type, target, label, t_start_s, t_end_s, ramp_s, intermittent)")
            unit = key[len(prefix) + 1:]
            if unit not in _UNIT_DIM:
                raise ValueError(self._unit_fix(key, prefix, unit))
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{key!r} must be a number")
            if prefix in seen:
                raise ValueError(f"give {prefix} once (got {seen[prefix]!r} and {key!r})")
            seen[prefix] = key
        missing = [p for p, (req, _) in self.MAGNITUDES.items() if req and p not in seen]
        if missing:
            raise ValueError(f"missing {missing[0]}_<unit> (e.g. {missing[0]}_{'deg' if 'rate' not in missing[0] else 'degps'})")
        return self

    def _unit_fix(self, key: str, prefix: str, unit: str) -> str:
        """The message for a magnitude key with an unknown unit: the units of this target, the nearest one."""
        rate = self.MAGNITUDES[prefix][1]
        try:  # the family is the type id's first word (actuator-..., sensor-...; the catalogue imports this module)
            native = target_unit(self.type.split("-", 1)[0], self.target)
        except KeyError:  # a target with no unit suffix: check_faults names it later
            native = None
        units = allowed_units(native, rate) if native else tuple(sorted(_UNIT_DIM))
        near = difflib.get_close_matches(unit, units, n=1, cutoff=0.5)
        hint = f"did you mean {prefix}_{near[0]}? " if near else ""
        where = f"on {self.target} ({native}{' per second' if rate else ''})" if native else "here"
        return f"{key!r}: unknown unit {unit!r}; {hint}{prefix}_<unit> takes {where} one of: {', '.join(units)}"

    def magnitude(self, prefix: str) -> tuple[float, str] | None:
        """``(value, unit)`` of a magnitude as written, or None if not given."""
        for key, value in (self.model_extra or {}).items():
            if key.startswith(prefix + "_") and key[len(prefix) + 1:] in _UNIT_DIM:
                return float(value), key[len(prefix) + 1:]
        return None


# --------------------------------------------------------------------------- actuators
class ActuatorStuckParams(FaultParams):
    """Stuck (jammed) actuator: at its position at onset, or at ``position_<unit>``."""

    MAGNITUDES = {"position": (False, False)}


class ActuatorFloatParams(FaultParams):
    """Floating surface: released, it trails to its zero-hinge-moment angle with a first-order lag."""

    float_ratio: float = Field(default=0.6, ge=0.0, le=1.5,
                               description="-Ch_alpha/Ch_delta: surface angle per unit local flow angle [-]")
    tau_s: float = Field(default=0.3, gt=0.0, le=10.0, description="time constant of the trail [s]")


class ActuatorHardOverParams(FaultParams):
    """Hard-over: driven to a travel stop at ``rate_<unit>`` (default: the actuator's fastest rate)."""

    direction: Literal["max", "min"]
    MAGNITUDES = {"rate": (False, True)}


class ActuatorRunawayParams(FaultParams):
    """Runaway: moves from its onset position at a signed rate until it meets a stop."""

    MAGNITUDES = {"rate": (True, True)}


class ActuatorLossParams(FaultParams):
    """Loss of effectiveness: the surface gives ``effectiveness`` times the commanded deflection."""

    effectiveness: float = Field(ge=0.0, lt=1.0, description="fraction of the healthy deflection delivered [-]")


class ActuatorBiasParams(FaultParams):
    """Bias: a constant offset added to the healthy position."""

    MAGNITUDES = {"bias": (True, False)}


class ActuatorRateLimitParams(FaultParams):
    """Degraded rate limit: the surface follows the healthy position at no more than ``rate_<unit>``."""

    MAGNITUDES = {"rate": (True, True)}


class ActuatorOscillationParams(FaultParams):
    """Oscillatory failure: a sinusoid of ``amplitude_<unit>`` at ``frequency_hz`` added to the position."""

    frequency_hz: float = Field(gt=0.0, le=30.0, description="oscillation frequency [Hz]")
    MAGNITUDES = {"amplitude": (True, False)}


# --------------------------------------------------------------------------- engines
class EngineFlameoutParams(FaultParams):
    """Flame-out: fuel cut on one engine; cleared, it relights (airstart, takes seconds)."""


class EngineThrustLossParams(FaultParams):
    """Partial thrust (power) loss of one engine."""

    loss: float = Field(gt=0.0, le=1.0, description="fraction of thrust (F-16) or power-lever travel (DHC-6) lost [-]")


# --------------------------------------------------------------------------- sensors
class SensorBiasParams(FaultParams):
    MAGNITUDES = {"bias": (True, False)}


class SensorDriftParams(FaultParams):
    """Drift: an offset growing at ``drift_<unit>`` (a rate) from each onset."""

    MAGNITUDES = {"drift": (True, True)}


class SensorStuckParams(FaultParams):
    """Stuck/frozen: the output stays at its value at onset, or at ``value_<unit>``."""

    MAGNITUDES = {"value": (False, False)}


class SensorNoiseParams(FaultParams):
    """Extra white noise of standard deviation ``noise_std_<unit>`` per sample."""

    MAGNITUDES = {"noise_std": (True, False)}


class SensorScaleParams(FaultParams):
    """Scale-factor error: the sensed quantity is multiplied by ``scale`` (noise and bias are not)."""

    scale: float = Field(ge=-10.0, le=10.0, description="scale factor on the sensed value [-]")


class SensorDropoutParams(FaultParams):
    """Dropout: no new samples; the output holds its last value and its valid flag is 0."""


class SensorDelayParams(FaultParams):
    """Delay (latency): the output is the healthy output ``delay_s`` earlier."""

    delay_s: float = Field(gt=0.0, le=10.0, description="transport delay [s]")


class SensorOutlierParams(FaultParams):
    """Outliers: spikes of +-``size_<unit>`` at random sample instants, ``rate_hz`` per second on average."""

    rate_hz: float = Field(gt=0.0, le=100.0, description="mean number of spikes per second [1/s]")
    MAGNITUDES = {"size": (True, False)}


# --------------------------------------------------------------------------- airframe
class IcingParams(FaultParams):
    """Airframe icing: eta(t) = eta_final x level(t); the onset is t_start_s, the growth ramp_s."""

    target: str = "airframe"
    region: Literal["all", "tail", "wing"] = "all"
    eta_final: float = Field(ge=0.0, le=1.0, description="final icing severity eta [-] (Bragg et al.)")

"""Registered faults (ids used as ``type`` in ``[[faults]]`` of a scenario).

The laws are in :mod:`fdi_sim.faults.laws` (actuators) and :mod:`fdi_sim.faults.injector`
(sensors, engines, icing); the keys in :mod:`fdi_sim.faults.params`.
"""
from __future__ import annotations

from fdi_sim.faults import params as P
from fdi_sim.faults.injector import FaultDef
from fdi_sim.registry import register

#: id -> (family, law, parameter model, one line)
FAULTS: dict[str, tuple[str, str, type[P.FaultParams], str]] = {
    "actuator-stuck-v1": ("actuator", "stuck", P.ActuatorStuckParams,
                          "surface or throttle jammed at its onset position or at position_<unit>"),
    "actuator-float-v1": ("actuator", "float", P.ActuatorFloatParams,
                          "surface released: trails to its zero-hinge-moment angle (-Ch_a/Ch_d x local flow) with a lag"),
    "actuator-hard-over-v1": ("actuator", "hard-over", P.ActuatorHardOverParams,
                              "driven to its max or min stop at rate_<unit> (default: its fastest rate)"),
    "actuator-runaway-v1": ("actuator", "runaway", P.ActuatorRunawayParams,
                            "moves from its onset position at a signed rate_<unit> until a stop"),
    "actuator-loss-v1": ("actuator", "loss", P.ActuatorLossParams,
                         "loss of effectiveness: delivers a fraction 'effectiveness' of the healthy deflection"),
    "actuator-bias-v1": ("actuator", "bias", P.ActuatorBiasParams, "constant offset bias_<unit> on the healthy position"),
    "actuator-rate-limit-v1": ("actuator", "rate-limit", P.ActuatorRateLimitParams,
                               "degraded rate limit: follows the healthy position at no more than rate_<unit>"),
    "actuator-oscillation-v1": ("actuator", "oscillation", P.ActuatorOscillationParams,
                                "oscillatory failure: amplitude_<unit> sinusoid at frequency_hz added"),
    "engine-flameout-v1": ("engine", "flameout", P.EngineFlameoutParams,
                           "fuel cut on engine_<i> (spools down); relights (airstart) when cleared"),
    "engine-thrust-loss-v1": ("engine", "thrust-loss", P.EngineThrustLossParams,
                              "partial loss: thrust x (1 - loss) on a jet, power lever x (1 - loss) on a turboprop"),
    "sensor-bias-v1": ("sensor", "bias", P.SensorBiasParams, "constant offset bias_<unit> on a sensor"),
    "sensor-drift-v1": ("sensor", "drift", P.SensorDriftParams, "offset growing at drift_<unit> per second from onset"),
    "sensor-stuck-v1": ("sensor", "stuck", P.SensorStuckParams, "frozen at its onset output or at value_<unit>"),
    "sensor-noise-v1": ("sensor", "noise", P.SensorNoiseParams, "extra white noise noise_std_<unit> per sample"),
    "sensor-scale-v1": ("sensor", "scale", P.SensorScaleParams, "scale-factor error on the sensed value"),
    "sensor-dropout-v1": ("sensor", "dropout", P.SensorDropoutParams,
                          "no new samples: last value held, validity flag 0 on /sensors/valid"),
    "sensor-delay-v1": ("sensor", "delay", P.SensorDelayParams, "transport delay delay_s on the output"),
    "sensor-outlier-v1": ("sensor", "outlier", P.SensorOutlierParams, "random spikes of +-size_<unit>, rate_hz per second"),
    "icing-v1": ("airframe", "icing", P.IcingParams,
                 "airframe icing, C_iced = C (1 + eta k_C) (Bragg/UIUC), eta ramps to eta_final (region all/tail/wing)"),
}


def fault_def(type_id: str, params: P.FaultParams) -> FaultDef:
    """The unbound fault of a validated scenario entry."""
    family, law, _, _ = FAULTS[type_id]
    return FaultDef(type_id, family, law, params)


for _id, (_family, _law, _params, _summary) in FAULTS.items():
    register("fault", _id, _summary, lambda p, _id=_id: fault_def(_id, p), _params)

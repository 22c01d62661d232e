"""The bank's log layout: the per-member statistic topic, the reconfiguration events, message names.

Beside the per-detector ``/fdi/<id>/statistic``, ``/fdi/<id>/residual`` and ``/fdi/<id>/estimate``
(``fdi_sim.flightlog.fdi_topic``) the bank writes ``/fdi/alarms`` and ``/fdi/failure_log``
(``fdi_sim.flightlog.schemas``) and :data:`TOPIC_FDI_RECONFIG`.
"""
from __future__ import annotations

from typing import Any

#: topics of the bank (beside the per-detector ``/fdi/<id>/...``)
TOPIC_FDI_RECONFIG = "/fdi/reconfiguration"


def msg_name(detector_id: str, what: str) -> str:
    """A message name per detector and layout: ``fdi_sim/msg/KalmanGustV1Residual``."""
    import re

    return "fdi_sim/msg/" + "".join(p[:1].upper() + p[1:] for p in re.split(r"[^A-Za-z0-9]+", detector_id) if p) + what


#: fields of ``/fdi/<id>/statistic`` (numbers only, so that Foxglove and PlotJuggler plot them)
STAT_FIELDS = ("t_s", "statistic", "threshold", "exceedance", "alarm", "valid", "isolation", "point")


RECONFIG_JSON_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "fdi-sim reconfiguration action", "required": ["action", "sensor"],
    "properties": {
        "action": {"type": "string", "description": "what was done"},
        "sensor": {"type": "string", "description": "the sensor or actuator acted on"},
        "detector": {"type": "string", "description": "the detector whose isolation triggered it"},
        "t_s": {"type": "number", "description": "time of the isolated sample [s]"},
        "confirmed_by": {"type": "string", "description": "the members that confirmed the isolation"},
        "effectiveness": {"type": "number", "description": "estimated actuator effectiveness [-]"},
        "effectiveness_std": {"type": "number", "description": "its standard deviation [-]"},
        "scale": {"type": "number", "description": "the factor the command is multiplied by [-]"},
    },
}


"""The linear model a scenario's (or a log's) detectors are designed from: its initial point
trimmed and linearized by JSBSim (a few seconds), at the detector rate, in the samples' form
(:func:`fdi_sim.detectors.samples.paired_model`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from fdi_sim.detectors.samples import paired_model
from fdi_sim.errors import LogError
from fdi_sim.flightlog import METADATA_SCENARIO
from fdi_sim.flightlog.reader import FlightLog

@dataclass(frozen=True, eq=False)
class LogModel:
    """What a log's detectors are designed from."""

    scenario: Any
    schedule: Any
    model: Any
    aircraft: str

    def continuous(self) -> Any:
        """The continuous linearization at the log's initial point."""
        return self.schedule.continuous_at(self.scenario.operating_point())


def model_for_log(log: FlightLog, rate_hz: float) -> LogModel:
    """Trim and linearize the log's initial point; the model at ``rate_hz`` in the samples' form."""
    from fdi_sim.scenario.loader import from_dict

    meta = log.metadata.get(METADATA_SCENARIO)
    if not meta or "json" not in meta:
        raise LogError(str(log.path), "no 'scenario' metadata record: not a log written by `fdi-sim run`, so its "
                       "aircraft and operating point are unknown")
    sc = from_dict(json.loads(meta["json"]), source=f"{log.path} (scenario metadata)")
    return model_for_scenario(sc, rate_hz)


def model_for_scenario(sc: Any, rate_hz: float) -> LogModel:
    """Trim and linearize a scenario's initial point (one point, no validation, a few seconds)."""
    from fdi_sim.linear.grid import parse_grid_spec
    from fdi_sim.linear.linearize import linearize_grid

    ini = sc.model.initial
    speed = f"vt_kts={ini.vt_kts}" if getattr(ini, "vt_kts", None) else f"vc_kts={ini.vc_kts}"
    spec = f"h_ft={ini.h_ft};{speed}"
    if getattr(ini, "flaps_deg", 0.0):
        spec += f";flaps_deg={ini.flaps_deg}"
    sched = linearize_grid(parse_grid_spec(spec, sc.aircraft), validate=False)
    found = sched.model_at(sc.operating_point(), dt_s=1.0 / rate_hz)
    return LogModel(sc, sched, paired_model(found.model, float(sc.model.rate_hz)), sc.aircraft)


"""JSBSim adapter: the only subpackage that imports ``jsbsim``."""
from __future__ import annotations

from fdi_sim.aircraft.model import AIRCRAFT, TURBULENCE_LEVELS, Aircraft, Atmosphere, UnknownAircraftError
from fdi_sim.aircraft.properties import COMMAND_SIGNALS, SURFACE_SIGNALS, TRUTH_SIGNALS, property_map
from fdi_sim.aircraft.trim import TrimResult, trim

__all__ = [
    "AIRCRAFT", "TURBULENCE_LEVELS", "Aircraft", "Atmosphere", "UnknownAircraftError", "COMMAND_SIGNALS",
    "SURFACE_SIGNALS", "TRUTH_SIGNALS", "property_map", "TrimResult", "trim",
]

"""JSBSim adapter: the only subpackage that imports ``jsbsim``."""
from __future__ import annotations

from fdi_sim.aircraft.model import AIRCRAFT, TURBULENCE_LEVELS, Aircraft, Atmosphere, UnknownAircraftError
from fdi_sim.aircraft.properties import COMMAND_SIGNALS, SURFACE_SIGNALS, TRUTH_SIGNALS, property_map
from fdi_sim.aircraft.trim import TrimResult, trim
from fdi_sim.aircraft.wind import hold_trim_in_wind
from fdi_sim.aircraft import icing  # noqa: F401,E402  registers the iced overlays before any jsbsim_root()

__all__ = [
    "AIRCRAFT", "TURBULENCE_LEVELS", "Aircraft", "Atmosphere", "UnknownAircraftError", "COMMAND_SIGNALS",
    "SURFACE_SIGNALS", "TRUTH_SIGNALS", "property_map", "TrimResult", "trim", "hold_trim_in_wind",
]

"""Registered kinematic sensor checks (``fdi_sim.detectors.kinematic``), with their calibrated thresholds.

Each factory takes ``(model=None, **params)``: the model (a ``LinearModel`` or any object with
``output_names`` and ``meta["aircraft"]``) gives the order of ``y`` in ``step`` and the aircraft
whose calibrated threshold is used; ``turbulence`` ("none", "light", "moderate") picks the
calibration condition. Thresholds: empirical ``1 - 1e-3`` quantile at 20 Hz of 8 calibration
seeds x 120 s per aircraft and level (``docs/make_kinematic_card.py``; card in docs/kinematic.md).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from fdi_sim.detectors.kinematic import MEASUREMENTS, KinematicDesign, KinematicDetector
from fdi_sim.errors import DesignError
from fdi_sim.registry import register

KINDS = ("attitude", "altitude", "airspeed", "flow-angles")
#: per-channel residual scales (channel units, ``kinematic.CHANNELS``): about one fault-free sigma
SCALES: dict[str, tuple[float, ...]] = {
    "attitude": (0.0007, 0.0007, 0.0013),  # rad/s (turn-on bias removed); heading noise 0.1 deg on r
    "altitude": (2.2, 0.13),               # ft over 10 s (baro noise 1.5 ft + 1 ft quantum), ft/s
    "airspeed": (1.0,),                   # kt
    "flow-angles": (0.001, 0.001),        # rad
}
#: windows [s]: (window_s, average_s, tau_wind_s, tau_bias_s)
WINDOWS: dict[str, tuple[float, float, float, float]] = {
    "attitude": (2.0, 1.0, 60.0, 120.0),
    "altitude": (10.0, 2.0, 60.0, 120.0),
    "airspeed": (2.0, 10.0, 120.0, 0.0),
    "flow-angles": (2.0, 1.0, 60.0, 0.0),
}
#: calibrated thresholds on max |r_i| / scale_i, per (aircraft, turbulence, kind)
THRESHOLDS: dict[tuple[str, str, str], float] = {
    ('f16', 'none', 'attitude'): 3.689,
    ('f16', 'none', 'altitude'): 3.459,
    ('f16', 'none', 'airspeed'): 0.148,
    ('f16', 'none', 'flow-angles'): 2.520,
    ('f16', 'light', 'attitude'): 3.810,
    ('f16', 'light', 'altitude'): 3.569,
    ('f16', 'light', 'airspeed'): 4.761,
    ('f16', 'light', 'flow-angles'): 28.070,
    ('f16', 'moderate', 'attitude'): 4.027,
    ('f16', 'moderate', 'altitude'): 3.402,
    ('f16', 'moderate', 'airspeed'): 7.448,
    ('f16', 'moderate', 'flow-angles'): 43.726,
    ('DHC6', 'none', 'attitude'): 3.397,
    ('DHC6', 'none', 'altitude'): 3.552,
    ('DHC6', 'none', 'airspeed'): 0.110,
    ('DHC6', 'none', 'flow-angles'): 3.334,
    ('DHC6', 'light', 'attitude'): 3.411,
    ('DHC6', 'light', 'altitude'): 3.536,
    ('DHC6', 'light', 'airspeed'): 8.732,
    ('DHC6', 'light', 'flow-angles'): 92.933,
    ('DHC6', 'moderate', 'attitude'): 3.451,
    ('DHC6', 'moderate', 'altitude'): 3.431,
    ('DHC6', 'moderate', 'airspeed'): 12.634,
    ('DHC6', 'moderate', 'flow-angles'): 136.391,
}
LEVELS = ("none", "light", "moderate")


def design(kind: str, aircraft: str | None = None, turbulence: str = "moderate", **overrides: Any) -> KinematicDesign:
    """The registered design of one check; the threshold from :data:`THRESHOLDS` unless given."""
    if kind not in KINDS:
        raise DesignError(f"unknown kinematic check {kind!r}; one of {', '.join(KINDS)}")
    if turbulence not in LEVELS:
        raise DesignError(f"turbulence {turbulence!r} has no calibration; one of {', '.join(LEVELS)}")
    w, a, tau, tau_b = WINDOWS[kind]
    ac = {"f16": "f16", "dhc6": "DHC6"}.get((aircraft or "").lower(), "DHC6")
    thr = THRESHOLDS.get((ac, turbulence, kind), 5.0)
    d = KinematicDesign(kind, scales=SCALES[kind], threshold=thr, window_s=w, average_s=a, tau_wind_s=tau,
                         tau_bias_s=tau_b)
    return replace(d, **overrides) if overrides else d


def _factory(kind: str):
    def make(model: Any = None, turbulence: str = "moderate", aircraft: str | None = None,
             output_names: tuple[str, ...] | None = None, **overrides: Any) -> KinematicDetector:
        names = tuple(output_names or getattr(model, "output_names", ()) or MEASUREMENTS)
        ac = aircraft or (getattr(model, "meta", None) or {}).get("aircraft")
        if "rate_hz" not in overrides and getattr(model, "is_discrete", False):
            overrides["rate_hz"] = 1.0 / float(model.dt_s)  # run at the model's rate (threshold from 20 Hz)
        return KinematicDetector(design(kind, ac, turbulence, **overrides), names, id=f"kinematic-{kind}-v1")

    make.__doc__ = f"The kinematic {kind} check (``fdi_sim.detectors.kinematic``), calibrated threshold."
    return make


_SUMMARY = {
    "attitude": "AHRS attitude increment vs Euler-integrated gyro rates; isolates p/q/r gyro",
    "altitude": "baro altitude and vertical speed vs integrated GNSS v_down; isolates h, hdot or v_down",
    "airspeed": "vc through the ISA vs GNSS ground velocity minus steady wind; isolates vc_kts",
    "flow-angles": "alpha/beta vanes vs GNSS air-relative velocity in body axes; isolates alpha or beta",
}
for _kind in KINDS:
    register("detector", f"kinematic-{_kind}-v1", _SUMMARY[_kind], _factory(_kind))

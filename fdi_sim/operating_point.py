"""Operating points: where an aircraft is trimmed, linearized and scheduled.

This module is free of JSBSim so the linear, detector and study stages can use it.
"""
from __future__ import annotations

from dataclasses import dataclass

from fdi_sim.units import FPS_PER_KT


@dataclass(frozen=True)
class OperatingPoint:
    """A flight condition to trim at.

    Exactly one of ``vt_kts`` (true airspeed) and ``vc_kts`` (calibrated, about KIAS) is set.

    Attributes
    ----------
    aircraft : str
        JSBSim model name, ``"f16"`` or ``"DHC6"`` (or an overlay such as ``"DHC6ice"``).
    h_ft : float
        Altitude above sea level [ft].
    vt_kts : float or None
        True airspeed [kt].
    vc_kts : float or None
        Calibrated airspeed [kt].
    gamma_deg : float
        Flight-path angle [deg], positive climbing.
    phi_deg : float
        Bank angle [deg]; non-zero means a steady coordinated turn.
    psi_deg : float
        True heading [deg].
    flaps_deg : float
        Flap deflection [deg] (DHC-6: 0, 10, 20, ...; ignored for the F-16).
    icing_eta : float
        Icing severity eta [-] of the Bragg model (0 = clean).
    """

    aircraft: str
    h_ft: float
    vt_kts: float | None = None
    vc_kts: float | None = None
    gamma_deg: float = 0.0
    phi_deg: float = 0.0
    psi_deg: float = 0.0
    flaps_deg: float = 0.0
    icing_eta: float = 0.0

    def __post_init__(self) -> None:
        if (self.vt_kts is None) == (self.vc_kts is None):
            raise ValueError("OperatingPoint needs exactly one of vt_kts and vc_kts")

    def label(self) -> str:
        """Short human-readable description, e.g. ``f16 h=10000 ft VT=400 kt``."""
        spd = f"VT={self.vt_kts:g} kt" if self.vt_kts is not None else f"VC={self.vc_kts:g} kt"
        parts = [self.aircraft, f"h={self.h_ft:g} ft", spd]
        if self.gamma_deg:
            parts.append(f"gamma={self.gamma_deg:g} deg")
        if self.phi_deg:
            parts.append(f"phi={self.phi_deg:g} deg")
        if self.flaps_deg:
            parts.append(f"flaps={self.flaps_deg:g} deg")
        if self.icing_eta:
            parts.append(f"eta={self.icing_eta:g}")
        return " ".join(parts)

    @property
    def speed_fps(self) -> float:
        """The given airspeed (true or calibrated, whichever is set) [ft/s]."""
        v = self.vt_kts if self.vt_kts is not None else self.vc_kts
        return float(v) * FPS_PER_KT

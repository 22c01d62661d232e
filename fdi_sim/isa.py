"""The 1976 standard atmosphere and airspeed conversions, free of JSBSim.

Used where no aircraft is loaded (grid envelopes, schedule lookup) and by the autopilot for its
TAS/CAS scale about the trim point (computed once, when the pilot is built). Tested against the
1976 tables and against JSBSim's own air data in ``tests/linear/test_grid.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from fdi_sim.errors import DesignError
from fdi_sim.units import FPS_PER_KT, G0_FPS2, KT_PER_FPS

_T0_R = 518.67            # sea-level temperature [deg R]
_P0_PSF = 2116.22         # sea-level pressure [lbf/ft^2]
_LAPSE_R_PER_FT = 0.00356616
_H_TROPO_FT = 36089.24
_R_AIR_FTLBF_PER_SLUG_R = 1716.49  # gas constant of air [ft lbf / (slug deg R)]
_GAMMA = 1.4              # ratio of specific heats of air [-]


@dataclass(frozen=True)
class StandardAtmosphere:
    """Standard-atmosphere state at one altitude (not :class:`fdi_sim.aircraft.Atmosphere`, the wind).

    Attributes
    ----------
    temperature_R : float
        Static temperature [deg R].
    pressure_psf : float
        Static pressure [lbf/ft^2].
    density_slugft3 : float
        Density [slug/ft^3].
    sound_speed_fps : float
        Speed of sound [ft/s].
    """

    temperature_R: float
    pressure_psf: float
    density_slugft3: float
    sound_speed_fps: float


def isa(h_ft: float) -> StandardAtmosphere:
    """1976 standard atmosphere below 65 617 ft (geopotential altitude ~ geometric here)."""
    if not -2000.0 <= h_ft <= 65617.0:
        raise DesignError(f"h_ft = {h_ft:g} is outside the standard-atmosphere model (-2000 to 65617 ft)")
    if h_ft <= _H_TROPO_FT:
        T = _T0_R - _LAPSE_R_PER_FT * h_ft
        # p = p0 (T / T0)^(g / (R L))
        p = _P0_PSF * (T / _T0_R) ** (G0_FPS2 / (_R_AIR_FTLBF_PER_SLUG_R * _LAPSE_R_PER_FT))
    else:
        T = _T0_R - _LAPSE_R_PER_FT * _H_TROPO_FT
        p11 = _P0_PSF * (T / _T0_R) ** (G0_FPS2 / (_R_AIR_FTLBF_PER_SLUG_R * _LAPSE_R_PER_FT))
        p = p11 * math.exp(-G0_FPS2 * (h_ft - _H_TROPO_FT) / (_R_AIR_FTLBF_PER_SLUG_R * T))
    return StandardAtmosphere(T, p, p / (_R_AIR_FTLBF_PER_SLUG_R * T), math.sqrt(_GAMMA * _R_AIR_FTLBF_PER_SLUG_R * T))


def vc_from_vt(h_ft: float, vt_kts: float) -> tuple[float, float]:
    """Calibrated airspeed [kt] and Mach [-] of a true airspeed at ``h_ft`` (subsonic).

    ``qc = p ((1 + 0.2 M^2)^3.5 - 1)``, ``vc = a0 sqrt(5 ((qc / p0 + 1)^(2/7) - 1))``.
    """
    atm, a0 = isa(h_ft), isa(0.0).sound_speed_fps
    mach = vt_kts * FPS_PER_KT / atm.sound_speed_fps
    qc = atm.pressure_psf * ((1 + 0.2 * mach**2) ** 3.5 - 1)
    vc = a0 * math.sqrt(5 * ((qc / _P0_PSF + 1) ** (2 / 7) - 1))
    return vc * KT_PER_FPS, mach


def vt_from_vc(h_ft: float, vc_kts: float) -> tuple[float, float]:
    """True airspeed [kt] and Mach [-] of a calibrated airspeed at ``h_ft`` (subsonic)."""
    atm, a0 = isa(h_ft), isa(0.0).sound_speed_fps
    qc = _P0_PSF * ((1 + 0.2 * (vc_kts * FPS_PER_KT / a0) ** 2) ** 3.5 - 1)
    mach = math.sqrt(5 * ((qc / atm.pressure_psf + 1) ** (2 / 7) - 1))
    return mach * atm.sound_speed_fps * KT_PER_FPS, mach

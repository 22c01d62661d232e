"""Unit conversions: every conversion in fdi-sim goes through these named constants.

JSBSim works in ft, lbf, slug and rad; scenario files use the unit written in the key
name (``h_ft``, ``vc_kts``, ``phi_deg``).
"""
from __future__ import annotations

import math

DEG_PER_RAD: float = 180.0 / math.pi
RAD_PER_DEG: float = math.pi / 180.0
FT_PER_M: float = 1.0 / 0.3048
M_PER_FT: float = 0.3048
FPS_PER_KT: float = 1852.0 / 3600.0 / 0.3048  # 1 kt = 1.68781 ft/s
KT_PER_FPS: float = 1.0 / FPS_PER_KT
G0_FPS2: float = 32.174049  # standard gravity [ft/s^2]
NS_PER_S: int = 1_000_000_000
S_PER_H: float = 3600.0

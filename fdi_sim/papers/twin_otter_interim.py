"""INTERIM 4-state longitudinal DHC-6 Twin Otter used by the observer tests, figures and examples.

A hand-built model from the measured JSBSim derivatives (JSBSIM_NOTES.md sec. 4.3), with AllIce
icing factors. **To be replaced by the project linearizer's model** (``fdi_sim.linear``): every
observer design takes the model as an argument.
"""
from __future__ import annotations

import numpy as np

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.units import G0_FPS2

#: AllIce k factors (per unit eta) of the UIUC Twin Otter files (JSBSIM_NOTES.md sec. 5.2).
_K_ICE = {"CZ_a": -1.48148, "CZ_q": -0.20741, "CZ_de": -1.40741, "Cm_a": -1.46667, "Cm_q": -0.51852, "Cm_de": -1.48148, "CXo": 6.52696}


def twin_otter_longitudinal_interim(icing_eta: float = 0.0) -> LinearModel:
    """INTERIM 4-state longitudinal DHC-6 Twin Otter, 5000 ft, 120 KIAS (218 ft/s), flaps 0.

    States ``[vt_fps, alpha_rad, q_radps, theta_rad]``, inputs ``[elevator_cmd_norm,
    throttle_cmd_norm]``, outputs = states (``C = I``), continuous time. Measured JSBSim values
    (JSBSIM_NOTES.md sec. 4.3): ``Zw = -1.22 1/s``, ``M_alpha = -8.8 1/s^2``, ``Mq = -3.29 1/s``,
    ``M_de = -1.99 rad/s^2`` per unit command. Filled in (stated assumptions): m = 330 slug,
    S = 420 ft^2, cbar = 6.5 ft, rho = 0.002048 slug/ft^3 (q = 48.7 psf); ``Zq/V = -0.0846`` from
    ``CLq = 19.97``; ``X_alpha = (qS/m)(CL - CD_alpha) = 17.68 ft/s^2`` (CL = 0.519, CD_alpha from
    e = 0.8, AR = 10); ``M_u = 0``; ``X_u = -0.08939 1/s`` and ``Z_u/V = -1.338e-3 1/ft`` fitted so
    the phugoid is ``-0.042 +- 0.172j``; the short period then is ``-2.258 +- 2.644j`` (JSBSim
    ``-2.26 +- 2.64j``). Elevator: unit command = 0.2236 rad (Iyy = 26000 slug ft^2, Cm_de = -1.74),
    ``Z_de/V = -0.0387 1/s``; throttle ``X_dt = 6 ft/s^2`` per unit (about 2000 lbf).

    Icing: AllIce ``k`` factors (sec. 5.2) scale ``Zw`` (CL_alpha), ``Zq``, ``Z_de``, ``M_alpha``,
    ``M_q``, ``M_de`` by ``(1 + k eta)`` and ``X_u`` by ``(1 + k_CXo eta)`` (drag).

    Parameters
    ----------
    icing_eta : float
        Icing severity eta [-], 0 = clean; the UIUC files say not above about 0.4.
    """
    if not 0.0 <= icing_eta <= 0.5:
        raise DesignError(f"icing_eta = {icing_eta} outside [0, 0.5]; the Bragg model is only meant for eta <= 0.4")
    e, k = icing_eta, _K_ICE
    g = G0_FPS2
    Xu = -0.08939061 * (1 + k["CXo"] * e)
    Xa = 17.682557276520647
    ZuV = -1.33810742e-03
    Zw = -1.22 * (1 + k["CZ_a"] * e)
    ZqV = -0.08458565818181815 * (1 + k["CZ_q"] * e)
    Ma, Mq = -8.8 * (1 + k["Cm_a"] * e), -3.29 * (1 + k["Cm_q"] * e)
    Mde, ZdeV = -1.99 * (1 + k["Cm_de"] * e), -0.0387 * (1 + k["CZ_de"] * e)
    A = np.array([
        [Xu, Xa, 0.0, -g],  # dV/dt = Xu V + X_alpha alpha - g theta
        [ZuV, Zw, 1.0 + ZqV, 0.0],  # d alpha/dt = Zu/V V + Zw alpha + (1 + Zq/V) q
        [0.0, Ma, Mq, 0.0],  # dq/dt = M_alpha alpha + Mq q
        [0.0, 0.0, 1.0, 0.0],  # d theta/dt = q
    ])
    B = np.array([[0.0, 6.0], [ZdeV, 0.0], [Mde, 0.0], [0.0, 0.0]])
    names = ("vt_fps", "alpha_rad", "q_radps", "theta_rad")
    return LinearModel(
        A=A, B=B, C=np.eye(4), D=np.zeros((4, 2)), dt_s=0.0, state_names=names,
        input_names=("elevator_cmd_norm", "throttle_cmd_norm"), output_names=names,
        x0=np.array([218.0, 0.0, 0.0, 0.0]), u0=np.array([0.0, 0.797]), y0=np.array([218.0, 0.0, 0.0, 0.0]),
        meta={"source": "INTERIM hand-built model (twin_otter_interim.twin_otter_longitudinal_interim); replace by the linearizer's",
              "icing_eta": icing_eta},
    )

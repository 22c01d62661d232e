"""JSBSim's own ``FGLinearization`` (JSBSIM_NOTES sec. 4.1): the F-16 cross-check of the linearizer."""
from __future__ import annotations

import time
from dataclasses import dataclass

import jsbsim
import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize_state import has_propeller
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.errors import DesignError


@dataclass(frozen=True, eq=False)
class JsbsimLinearization:
    """The result of JSBSim's own ``FGLinearization`` (JSBSIM_NOTES sec. 4.1).

    Attributes
    ----------
    A, B : NDArray
        State and input matrices in JSBSim's state order and units.
    x_names, x_units, u_names : tuple of str
        JSBSim's names (``Vt``, ``Alpha``, ... ``Alt``; ``ThtlCmd``, ``DaCmd``, ``DeCmd``, ``DrCmd``).
    x0, u0 : NDArray
        Trim values.
    elapsed_s : float
        Wall time [s].
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    x_names: tuple[str, ...]
    x_units: tuple[str, ...]
    u_names: tuple[str, ...]
    x0: NDArray[np.float64]
    u0: NDArray[np.float64]
    elapsed_s: float


def fglinearization(ac: Aircraft, allow_propeller: bool = False) -> JsbsimLinearization:
    """Run JSBSim's ``FGLinearization`` about the current (just trimmed) state.

    Call it right after JSBSim's own trim. For propeller aircraft its ``Rpm`` rows and throttle
    column are wrong (the real step inside hits the turboprop N1 reset), and after the
    running-engine trim of the DHC-6 it does not converge (more than 15 min, JSBSIM_NOTES
    4.1), so it is refused unless ``allow_propeller`` (and then only right after JSBSim's trim).

    Raises
    ------
    DesignError
        Propeller aircraft without ``allow_propeller``.
    """
    if has_propeller(ac) and not allow_propeller:
        raise DesignError(f"FGLinearization is not reliable for the propeller aircraft {ac.name} (Rpm rows and "
                          "throttle column wrong, no convergence after the running trim); use central_difference, "
                          "or pass allow_propeller=True right after a plain JSBSim trim")
    t0 = time.perf_counter()
    try:
        lin = jsbsim.FGLinearization(ac.fdm)
        A, B, _, _ = lin.state_space
    finally:
        # FGLinearization leaves the integration suspended (dt = 0): give the aircraft its step back
        if ac.fdm.integration_suspended():
            ac.fdm.resume_integration()
        ac.fdm.set_dt(ac.dt_s)
    return JsbsimLinearization(
        A=np.array(A, dtype=float), B=np.array(B, dtype=float), x_names=tuple(lin.x_names),
        x_units=tuple(lin.x_units), u_names=tuple(lin.u_names), x0=np.array(lin.x0, dtype=float),
        u0=np.array(lin.u0, dtype=float), elapsed_s=time.perf_counter() - t0,
    )

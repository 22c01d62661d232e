"""A Python replica of JSBSim's ``FGLinearization``, with the number of model passes as a knob.

Why FGLinearization's F-16 roll root (-1.094 1/s at 10 kft / 400 KTAS) differs from ours
(-1.039) and from the simulation's (-1.031) is a question about *when* it reads the derivatives.
This module repeats its procedure step by step through the public Python API, so the answer can
be measured rather than argued (``tests/linear/test_fglin_roll_root.py``).

The procedure (JSBSim ``src/math/FGStateSpace.{h,cpp}``, ``src/initialization/FGLinearization.cpp``)
---------------------------------------------------------------------------------------------------
* States ``x = [Vt, Alpha, Theta, Q, Beta, Phi, P, Psi, R, Latitude, Longitude, Alt]`` (no
  propeller, so no ``Rpm``), inputs ``u = [ThtlCmd, DaCmd, DeCmd, DrCmd]``; ``x0``, ``u0`` are read
  from the model as it stands (right after the trim).
* ``FGLinearization`` suspends the integration (dt = 0) and computes ``A`` then ``B`` with
  ``numericalJacobian``: for every row ``iY`` (outer loop) and column ``iX`` (inner loop) it
  evaluates ``x0 + h, x0 + 2h, x0 - h, x0 - 2h`` (``h = 1e-4`` in every state's own unit) and
  takes ``(8 (f(+h) - f(-h)) - (f(+2h) - f(-2h))) / (12 h)``. Before each of the four points it
  first writes the whole ``x0`` (and ``u0``) back. Every write (``ComponentVector::set``) ends with
  ``FGStateSpace::run``; the same model is evaluated afresh for every entry of ``A``, in this order,
  so whatever JSBSim carries from one pass to the next comes from the previous evaluation.
* Each component's ``set`` writes the initial-condition object (``Alpha`` also rewrites beta,
  psi and theta, reading beta in *degrees* and writing it back as radians; ``Theta`` sets the
  flight-path angle ``theta - alpha``; ``Beta`` keeps psi); the commands go to the FCS inputs.
* ``FGStateSpace::run``: ``FGFDMExec::Initialize(IC)`` (``FGPropagate`` and ``FGAuxiliary``
  ``SetInitialState``, then **one** ``Run``, trim status off), ``InitRunning`` for every engine,
  then up to 1000 times {``GetSteadyState``, trim status on, ``Run`` at dt = 0, trim status off}
  until the sum of the 12 states stops changing (machine epsilon). At dt = 0 the states do not
  move, so that loop stops after **one** Run: the derivatives are read after two passes.
* Derivatives: ``Vt``: ``(u udot + v vdot + w wdot) / Vt``; ``Alpha``, ``Beta``: FGAuxiliary's
  ``adot``, ``bdot``; ``Theta``, ``Phi``, ``Psi``: FGAuxiliary's Euler rates; ``P``, ``Q``, ``R``:
  FGAccelerations; ``Lat``, ``Lon``: ``v_north / r``, ``v_east / (r cos(lat))``; ``Alt``: ``hdot``.

The Python API has no ``Initialize`` alone: ``run_ic`` is ``Initialize`` plus a second ``Run``.
Under ``hold()`` every model returns at once, so ``hold(); run_ic(); resume()`` leaves exactly
``SetInitialState`` (the state written, the air data and the FCS untouched), and the passes are
then run by hand: pass 1 with the trim status off (``Initialize``'s own Run), then ``n_runs``
passes with the trim status on (``n_runs = None``: FGStateSpace's convergence test, which gives 1).

What JSBSim carries between passes (``FGFDMExec::Run`` runs FCS, then FGAuxiliary, then the
aerodynamics and FGAccelerations), as seen by the F-16 FBW (``aircraft/f16/f16.xml``):

* the FCS reads the air data (``velocities/p-aero-rad_sec``, ``r-aero``, alpha, ``n-pilot-y/z``)
  that FGAuxiliary computed in the *previous* pass: in pass 1 those of the previous evaluation;
* ``fcs/roll-rate-pid`` (kp 3, kd -0.00125) and ``fcs/yaw-load-pid`` (kp 0.1055, kd 5e-5) take
  their D term as ``kd (input - previous input) / dt`` with the channel's fixed dt = 1/120 s,
  even at dt = 0: in pass 2 the previous input is pass 1's, i.e. the previous evaluation's, so
  the perturbation passes through ``kp + kd / dt`` (2.85 instead of 3 for roll);
* FGAuxiliary's ``adot``/``bdot`` come from FGAccelerations of the previous pass: read after pass 2
  they are pass 1's, with the FCS still at the previous evaluation's inputs.

Measured (F-16, 10 kft, 400 KTAS; ``tests/linear/test_fglin_roll_root.py``): with ``n_runs=None``
the replica's ``A`` and ``B`` equal FGLinearization's bit for bit (roll root -1.0940); with 4 or
more passes the roll root is -1.0389, ours. The lateral difference is the yaw channel's: the
beta row without the yaw damper's rudder (alone: -1.161) and the r row with the yaw-load PID's
D term and a stale ``n-pilot-y`` (alone: -0.981); the roll PID's D term moves it < 0.01 %.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize_state import has_propeller
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.errors import DesignError

#: FGLinearization's state and input names (no propeller: no Rpm states)
X_NAMES: tuple[str, ...] = ("Vt", "Alpha", "Theta", "Q", "Beta", "Phi", "P", "Psi", "R", "Latitude", "Longitude",
                            "Alt")
U_NAMES: tuple[str, ...] = ("ThtlCmd", "DaCmd", "DeCmd", "DrCmd")
#: components whose unit is "rad": their differences are wrapped to (-pi, pi] (numericalJacobian)
_RAD_STATES: frozenset[str] = frozenset({"Alpha", "Theta", "Beta", "Phi", "Psi", "Latitude", "Longitude"})
#: FGStateSpace's component getters (FGAuxiliary for Vt, alpha, beta; FGPropagate for the rest)
_GET: dict[str, str] = {
    "Vt": "velocities/vt-fps", "Alpha": "aero/alpha-rad", "Theta": "attitude/theta-rad", "Q": "velocities/q-rad_sec",
    "Beta": "aero/beta-rad", "Phi": "attitude/phi-rad", "P": "velocities/p-rad_sec", "Psi": "attitude/psi-rad",
    "R": "velocities/r-rad_sec", "Latitude": "position/lat-gc-rad", "Longitude": "position/long-gc-rad",
    "Alt": "position/h-sl-ft", "DaCmd": "fcs/aileron-cmd-norm", "DeCmd": "fcs/elevator-cmd-norm",
    "DrCmd": "fcs/rudder-cmd-norm", "ThtlCmd": "fcs/throttle-cmd-norm[0]",
}
#: components whose ``set`` writes one property (the others: :meth:`_StateSpace.set`)
_SET: dict[str, str] = {
    "Q": "ic/q-rad_sec", "Phi": "ic/phi-rad", "P": "ic/p-rad_sec", "Psi": "ic/psi-true-rad", "R": "ic/r-rad_sec",
    "Latitude": "ic/lat-gc-rad", "Longitude": "ic/long-gc-rad", "Alt": "ic/h-sl-ft", "DaCmd": "fcs/aileron-cmd-norm",
    "DeCmd": "fcs/elevator-cmd-norm", "DrCmd": "fcs/rudder-cmd-norm",
}
#: derivatives read directly from one property
_DERIV: dict[str, str] = {
    "Alpha": "aero/alphadot-rad_sec", "Theta": "velocities/thetadot-rad_sec", "Q": "accelerations/qdot-rad_sec2",
    "Beta": "aero/betadot-rad_sec", "Phi": "velocities/phidot-rad_sec", "P": "accelerations/pdot-rad_sec2",
    "Psi": "velocities/psidot-rad_sec", "R": "accelerations/rdot-rad_sec2", "Alt": "velocities/h-dot-fps",
}
#: the trim-status passes FGStateSpace::run allows before giving up
_MAX_RUNS = 1000


@dataclass(frozen=True, eq=False)
class ReplicaLinearization:
    """``A`` and ``B`` of the FGLinearization replica (JSBSim's state order and units).

    Attributes
    ----------
    A, B : NDArray
        ``d xdot / d x`` (12 x 12) and ``d xdot / d u`` (12 x 4) in :data:`X_NAMES`, :data:`U_NAMES`
        order and FGLinearization's mixed units (ft, ft/s, rad, rad/s, norm).
    x_names, u_names : tuple of str
        :data:`X_NAMES`, :data:`U_NAMES`.
    x0, u0 : NDArray
        The point linearized about.
    n_runs : int or None
        Trim-status passes after ``Initialize``'s pass (``None``: FGStateSpace's convergence test).
    runs_used : tuple of int
        Fewest and most such passes taken by one evaluation.
    n_evaluations : int
        Model evaluations (``FGStateSpace::run`` calls).
    elapsed_s : float
        Wall time [s].
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    x_names: tuple[str, ...]
    u_names: tuple[str, ...]
    x0: NDArray[np.float64]
    u0: NDArray[np.float64]
    n_runs: int | None
    runs_used: tuple[int, int]
    n_evaluations: int
    elapsed_s: float


class _StateSpace:
    """FGStateSpace's components and ``run`` on one aircraft (state: the pass counters)."""

    def __init__(self, ac: Aircraft, n_runs: int | None,
                 after_pass: Callable[[int], None] | None = None) -> None:
        self.ac, self.fdm, self.n_runs, self.after_pass = ac, ac.fdm, n_runs, after_pass
        self.n_eng = ac.n_engines
        self.runs_min, self.runs_max, self.n_eval = _MAX_RUNS + 1, 0, 0

    # --- components -------------------------------------------------------------------------
    def get(self, name: str) -> float:
        return float(self.fdm[_GET[name]])

    def set(self, name: str, val: float) -> None:
        """One component's ``set`` (FGStateSpace.h), without the ``run`` that follows it."""
        fdm = self.fdm
        if name == "Vt":
            fdm["ic/vt-fps"] = val
        elif name == "Alpha":
            # FGStateSpace::Alpha::set: GetBetaDegIC() written back through SetBetaRadIC (sic)
            beta, psi, theta = fdm["ic/beta-deg"], fdm["ic/psi-true-rad"], fdm["ic/theta-rad"]
            fdm["ic/alpha-rad"] = val
            fdm["ic/beta-rad"] = beta
            fdm["ic/psi-true-rad"] = psi
            fdm["ic/theta-rad"] = theta
        elif name == "Theta":
            fdm["ic/gamma-rad"] = val - fdm["ic/alpha-rad"]  # SetFlightPathAngleRadIC(theta - alpha)
        elif name == "Beta":
            psi = fdm["ic/psi-true-rad"]
            fdm["ic/beta-rad"] = val
            fdm["ic/psi-true-rad"] = psi
        elif name == "ThtlCmd":
            for i in range(self.n_eng):
                fdm[f"fcs/throttle-cmd-norm[{i}]"] = val
        else:
            fdm[_SET[name]] = val

    def deriv(self, name: str) -> float:
        """FGStateSpace's ``getDeriv`` of one state."""
        fdm = self.fdm
        if name == "Vt":  # from Lewis: Vt dot = (u udot + v vdot + w wdot) / Vt
            return sum(fdm[f"velocities/{c}-fps"] * fdm[f"accelerations/{c}dot-ft_sec2"] for c in "uvw") / fdm[
                "velocities/vt-fps"]
        if name == "Latitude":
            return fdm["velocities/v-north-fps"] / fdm["position/radius-to-vehicle-ft"]
        if name == "Longitude":
            return fdm["velocities/v-east-fps"] / (math.cos(fdm["position/lat-gc-rad"])
                                                   * fdm["position/radius-to-vehicle-ft"])
        return float(fdm[_DERIV[name]])

    # --- FGStateSpace::run ------------------------------------------------------------------
    def state_sum(self) -> float:
        return sum(self.get(n) for n in X_NAMES)

    def run(self) -> None:
        """``Initialize(IC)``, ``InitRunning``, then the trim-status passes (module docstring)."""
        fdm = self.fdm
        fdm.hold()  # every model returns at once: run_ic leaves only SetInitialState
        try:
            fdm.run_ic()
        finally:
            fdm.resume()
        fdm.set_trim_status(False)
        fdm.run()  # Initialize's own Run
        if self.after_pass is not None:
            self.after_pass(0)
        prop = fdm.get_propulsion()
        for i in range(prop.get_num_engines()):
            prop.get_engine(i).init_running()
        cost = self.state_sum()
        k = 0
        while k < (_MAX_RUNS if self.n_runs is None else self.n_runs):
            prop.get_steady_state()
            fdm.set_trim_status(True)
            fdm.run()
            fdm.set_trim_status(False)
            k += 1
            if self.after_pass is not None:
                self.after_pass(k)
            new = self.state_sum()
            if self.n_runs is None and abs(new - cost) < np.finfo(float).eps:
                break
            cost = new
        self.runs_min, self.runs_max, self.n_eval = min(self.runs_min, k), max(self.runs_max, k), self.n_eval + 1

    def set_all(self, names: tuple[str, ...], vals: NDArray[np.float64]) -> None:
        for n, v in zip(names, vals):
            self.set(n, float(v))
        self.run()

    def set_one(self, name: str, val: float) -> None:
        self.set(name, val)
        self.run()


@contextmanager
def _integration_suspended(ac: Aircraft) -> Iterator[None]:
    """FGLinearization's dt = 0 for the block; afterwards trim status off, integration on, dt restored."""
    fdm = ac.fdm
    fdm.suspend_integration()
    try:
        yield
    finally:
        fdm.set_trim_status(False)
        if fdm.integration_suspended():
            fdm.resume_integration()
        fdm.set_dt(ac.dt_s)


def _jacobian(ss: _StateSpace, x0: NDArray[np.float64], u0: NDArray[np.float64], wrt: tuple[str, ...],
              h: float) -> NDArray[np.float64]:
    """``numericalJacobian`` of the state derivatives with respect to ``wrt`` (X_NAMES or U_NAMES)."""
    base = x0 if wrt == X_NAMES else u0
    J = np.zeros((len(X_NAMES), len(wrt)))
    for iy, y in enumerate(X_NAMES):
        for ix, xn in enumerate(wrt):
            f = []
            for d in (h, 2 * h, -h, -2 * h):  # f1, f2, fn1, fn2, each after x0 written back
                ss.set_all(wrt, base)
                ss.set_one(xn, ss.get(xn) + d)  # x.set(iX, x.get(iX) + h): the value read after the reset
                f.append(ss.deriv(y))
            ss.set_all(wrt, base)  # x.set(x0) after the entry
            d1, d2 = f[0] - f[2], f[1] - f[3]
            if xn in _RAD_STATES:  # angle wrap, as numericalJacobian does
                d1, d2 = (math.remainder(d, 2 * math.pi) for d in (d1, d2))
            J[iy, ix] = (8 * d1 - d2) / (12 * h)
    return J


def fglin_replica(ac: Aircraft, n_runs: int | None = None, h: float = 1e-4,
                  after_pass: Callable[[int], None] | None = None) -> ReplicaLinearization:
    """Linearize ``ac`` about its current (just trimmed) state the way ``FGLinearization`` does.

    Parameters
    ----------
    ac : Aircraft
        A jet aircraft right after :func:`~fdi_sim.aircraft.trim.trim` (the state is read from it).
    n_runs : int, optional
        Trim-status passes after ``Initialize``'s pass, per evaluation. ``None``: FGStateSpace's
        test (stop when the state sum stops changing; 1 pass at dt = 0), i.e. FGLinearization
        itself. A larger number lets the one-pass-late signals settle (5 settle the F-16 FBW).
    h : float
        Difference step in every state's and input's own unit [mixed], FGStateSpace's 1e-4.
    after_pass : callable, optional
        Called with the pass index (0: ``Initialize``'s pass) after every pass, to read or hold
        FCS signals across passes.

    Returns
    -------
    ReplicaLinearization
        ``A``, ``B`` and the pass counts. The aircraft is left at ``x0``, dt restored, integration on.

    Raises
    ------
    DesignError
        Propeller aircraft (FGLinearization adds ``Rpm`` states there, not replicated).
    """
    if has_propeller(ac):
        raise DesignError(f"the FGLinearization replica covers jet aircraft only ({ac.name} has propellers: "
                          "FGLinearization adds Rpm states there)")
    if n_runs is not None and n_runs < 1:
        raise DesignError(f"n_runs must be None or >= 1, got {n_runs}")
    t0 = time.perf_counter()
    ss = _StateSpace(ac, n_runs, after_pass)
    x0 = np.array([ss.get(n) for n in X_NAMES])
    u0 = np.array([ss.get(n) for n in U_NAMES])
    with _integration_suspended(ac):
        A = _jacobian(ss, x0, u0, X_NAMES, h)
        B = _jacobian(ss, x0, u0, U_NAMES, h)
    return ReplicaLinearization(A=A, B=B, x_names=X_NAMES, u_names=U_NAMES, x0=x0, u0=u0, n_runs=n_runs,
                                runs_used=(ss.runs_min, ss.runs_max), n_evaluations=ss.n_eval,
                                elapsed_s=time.perf_counter() - t0)


def pass_history(ac: Aircraft, name: str, delta: float, props: tuple[str, ...], n_runs: int = 5) -> NDArray[np.float64]:
    """Signals after every pass of one FGStateSpace evaluation at ``x0`` with ``name`` moved by ``delta``.

    The evaluation is preceded by one at ``x0`` (as in ``numericalJacobian``), so pass 0 carries
    what a settled ``x0`` leaves behind. Use it right after a trim; the aircraft is left perturbed.

    Parameters
    ----------
    ac : Aircraft
        A jet aircraft right after the trim.
    name : str
        One of :data:`X_NAMES` or :data:`U_NAMES`.
    delta : float
        Perturbation in that component's unit [mixed].
    props : tuple of str
        JSBSim properties to read after each pass.
    n_runs : int
        Trim-status passes after ``Initialize``'s pass.

    Returns
    -------
    NDArray
        ``(n_runs + 1, len(props))``: row 0 after ``Initialize``'s pass, row k after trim-status pass k.
    """
    if name not in X_NAMES + U_NAMES:
        raise DesignError(f"unknown component {name!r}; one of {X_NAMES + U_NAMES}")
    rows: list[list[float]] = []
    ss = _StateSpace(ac, n_runs)
    x0 = np.array([ss.get(n) for n in X_NAMES])
    with _integration_suspended(ac):
        ss.set_all(X_NAMES, x0)  # settle at x0 first
        ss.after_pass = lambda k: rows.append([float(ac.fdm[p]) for p in props])
        ss.set_one(name, ss.get(name) + delta)
    return np.array(rows)

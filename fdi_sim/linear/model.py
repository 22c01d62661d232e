"""Linear models: the common currency between the linearizer and the detectors."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class StepTerms:
    """How the derivatives of a continuous model build up within JSBSim's simulation step.

    Measured by :func:`fdi_sim.aircraft.linearize.pass_jacobians` and turned into the discrete
    model of the simulation step by :mod:`fdi_sim.linear.step` (``discretize(..., method="step")``).
    ``Ax[k] x + Bu[k] u`` is the derivative of the first ``n_rigid`` states after pass ``k + 1``
    of the model with ``x`` and ``u`` changed before pass 1; ``Ax[-1]`` and ``Bu[-1]`` are the
    settled rows of the model's ``A`` and ``B``.

    Attributes
    ----------
    Ax : NDArray
        Shape (P, n_rigid, n) [1/s in the units of the states].
    Bu : NDArray
        Shape (P, n_rigid, m).
    Lf : NDArray
        Shape (q, n_rigid): the lagged outputs computed in the next pass from these derivatives.
    lagged_outputs : tuple of str
        Names of the rows of ``Lf`` (a subset of the model outputs).
    dt_s : float
        The simulation step [s].
    n_rigid : int
        States integrated by JSBSim's ``FGPropagate`` (the first ones); the rest (engine) are
        updated inside the pass by their own models.
    integrator : str
        ``"ab3"``: third-order Adams-Bashforth, as ``Aircraft`` sets all four integrators.
    """

    Ax: NDArray[np.float64]
    Bu: NDArray[np.float64]
    Lf: NDArray[np.float64]
    lagged_outputs: tuple[str, ...]
    dt_s: float
    n_rigid: int = 10
    integrator: str = "ab3"

    def __post_init__(self) -> None:
        Ax, Bu, Lf = (np.asarray(a, dtype=float) for a in (self.Ax, self.Bu, self.Lf))
        if Ax.ndim != 3 or Bu.ndim != 3 or Ax.shape[:2] != Bu.shape[:2] or Ax.shape[1] != self.n_rigid:
            raise ValueError(f"step terms: Ax{Ax.shape} and Bu{Bu.shape} must be (P, n_rigid={self.n_rigid}, .)")
        if Lf.shape != (len(self.lagged_outputs), self.n_rigid):
            raise ValueError(f"step terms: Lf{Lf.shape} must be ({len(self.lagged_outputs)}, {self.n_rigid})")
        if self.integrator != "ab3" or not self.dt_s > 0:
            raise ValueError(f"step terms: integrator {self.integrator!r} (only 'ab3') and dt_s {self.dt_s} (> 0)")
        for name, a in (("Ax", Ax), ("Bu", Bu), ("Lf", Lf)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "lagged_outputs", tuple(self.lagged_outputs))

    @property
    def n_passes(self) -> int:
        """Passes measured (``P``, the first axis of ``Ax`` and ``Bu``)."""
        return self.Ax.shape[0]

    def select_inputs(self, idx: Sequence[int]) -> "StepTerms":
        """The terms for a subset of the input columns."""
        return StepTerms(self.Ax, self.Bu[:, :, list(idx)], self.Lf, self.lagged_outputs, self.dt_s, self.n_rigid)

    def select_outputs(self, names: Sequence[str]) -> "StepTerms":
        """The terms keeping only the lagged outputs among ``names``."""
        keep = [i for i, n in enumerate(self.lagged_outputs) if n in names]
        return StepTerms(self.Ax, self.Bu, self.Lf[keep], tuple(self.lagged_outputs[i] for i in keep), self.dt_s,
                         self.n_rigid)


#: relative tolerance (to the largest entry) within which step terms' settled pass is the model's A, B
_SETTLED_RTOL: float = 1e-9


def _settled(S: NDArray[np.float64], M: NDArray[np.float64]) -> bool:
    """``S`` equals ``M`` to :data:`_SETTLED_RTOL` of ``M``'s largest entry (rounding of the axis change)."""
    return bool(np.max(np.abs(S - M), initial=0.0) <= _SETTLED_RTOL * np.max(np.abs(M), initial=0.0))


@dataclass(frozen=True, eq=False)
class LinearModel:
    """A linear time-invariant model about a trim point, continuous or discrete.

    ``x(k+1) = A x(k) + B u(k)`` (``dt_s > 0``) or ``dx/dt = A x + B u`` (``dt_s == 0``),
    ``y = C x + D u``, with all signals as deviations from the trim values ``x0, u0, y0``.

    Attributes
    ----------
    A, B, C, D : NDArray
        System matrices, shapes (n, n), (n, m), (p, n), (p, m).
    dt_s : float
        Sample time [s]; 0 for a continuous-time model.
    state_names, input_names, output_names : tuple of str
        Unit-suffixed signal names (``alpha_rad``, ``elevator_cmd_norm``, ``q_radps``).
    input_kinds : tuple of str
        ``"control"`` or ``"disturbance"`` per input column (robust designs use the latter).
    x0, u0, y0 : NDArray
        Trim values of states, inputs and outputs (absolute units).
    op : Any
        The operating point (``fdi_sim.operating_point.OperatingPoint``) or None.
    meta : dict
        Free-form provenance (method, aircraft, jsbsim version).
    step : StepTerms or None
        How the derivatives build up within JSBSim's step (continuous models from the
        linearizer); the input of ``discretize(..., method="step")``. Terms whose settled pass
        (``Ax[-1]``, ``Bu[-1]``) is no longer the model's ``A``, ``B`` (a model built by
        ``dataclasses.replace`` with new matrices) are dropped: the model then has none.
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    dt_s: float = 0.0
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    input_kinds: tuple[str, ...] = ()
    x0: NDArray[np.float64] | None = None
    u0: NDArray[np.float64] | None = None
    y0: NDArray[np.float64] | None = None
    op: Any = None
    meta: dict[str, Any] = field(default_factory=dict)
    step: StepTerms | None = None

    def __post_init__(self) -> None:
        A, B, C, D = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (self.A, self.B, self.C, self.D))
        n, m, p = A.shape[0], B.shape[1], C.shape[0]
        if A.shape != (n, n) or B.shape != (n, m) or C.shape != (p, n) or D.shape != (p, m):
            raise ValueError(f"inconsistent shapes A{A.shape} B{B.shape} C{C.shape} D{D.shape}")
        for name, M in zip("ABCD", (A, B, C, D)):
            M.setflags(write=False)
            object.__setattr__(self, name, M)
        defaults = {
            "state_names": tuple(f"x{i}" for i in range(n)),
            "input_names": tuple(f"u{i}" for i in range(m)),
            "output_names": tuple(f"y{i}" for i in range(p)),
            "input_kinds": ("control",) * m,
        }
        for key, default in defaults.items():
            val = tuple(getattr(self, key)) or default
            if len(val) != len(default):
                raise ValueError(f"{key} has {len(val)} entries, expected {len(default)}")
            object.__setattr__(self, key, val)
        for key, size in (("x0", n), ("u0", m), ("y0", p)):
            v = getattr(self, key)
            v = np.zeros(size) if v is None else np.asarray(v, dtype=float).reshape(size)
            v.setflags(write=False)
            object.__setattr__(self, key, v)
        st = self.step
        if st is not None:
            if st.Ax.shape[2] != n or st.Bu.shape[2] != m or st.n_rigid > n:
                raise ValueError(f"step terms Ax{st.Ax.shape} Bu{st.Bu.shape} do not fit a model with {n} states "
                                 f"and {m} inputs")
            missing = [o for o in st.lagged_outputs if o not in self.output_names]
            if missing:
                raise ValueError(f"step terms: lagged outputs {missing} are not model outputs")
            if not (_settled(st.Ax[-1], A[:st.n_rigid]) and _settled(st.Bu[-1], B[:st.n_rigid])):
                object.__setattr__(self, "step", None)  # A or B changed (dataclasses.replace): the terms are stale

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    @property
    def is_discrete(self) -> bool:
        return self.dt_s > 0

    def control_columns(self) -> NDArray[np.intp]:
        """Indices of the control (not disturbance) input columns."""
        return np.array([i for i, k in enumerate(self.input_kinds) if k == "control"], dtype=np.intp)

    def to_statespace(self) -> Any:
        """A named python-control ``StateSpace`` (discrete if ``dt_s > 0``)."""
        import control

        return control.ss(
            self.A, self.B, self.C, self.D, self.dt_s if self.is_discrete else 0,
            states=list(self.state_names), inputs=list(self.input_names), outputs=list(self.output_names),
        )

    @classmethod
    def from_statespace(cls, sys: Any, **kw: Any) -> "LinearModel":
        """Build from a python-control ``StateSpace``, keeping its signal names."""
        dt = 0.0 if sys.dt in (0, None) else float(sys.dt if sys.dt is not True else 1.0)
        return cls(
            A=sys.A, B=sys.B, C=sys.C, D=sys.D, dt_s=dt,
            state_names=tuple(sys.state_labels), input_names=tuple(sys.input_labels),
            output_names=tuple(sys.output_labels), **kw,
        )

    def discretize(self, dt_s: float) -> "LinearModel":
        """Zero-order-hold discretization at ``dt_s`` [s] (scipy's matrix exponential)."""
        if self.is_discrete:
            raise ValueError("model is already discrete")
        from scipy.signal import cont2discrete

        Ad, Bd, Cd, Dd, _ = cont2discrete((self.A, self.B, self.C, self.D), dt_s, method="zoh")
        return LinearModel(
            A=Ad, B=Bd, C=Cd, D=Dd, dt_s=dt_s, state_names=self.state_names, input_names=self.input_names,
            output_names=self.output_names, input_kinds=self.input_kinds, x0=self.x0, u0=self.u0, y0=self.y0,
            op=self.op, meta={**self.meta, "discretized": "zoh"},
        )

"""Linear models: the common currency between the linearizer and the detectors."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray


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

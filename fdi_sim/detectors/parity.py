"""Parity space of order s with known inputs (Chow-Willsky; Lou, Willsky & Verghese 1986).

For ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)`` the window of the last ``s + 1``
samples obeys

    Y(k) - H U(k) = O x(k-s)                                  (Lou et al. 1986, eq. 4-6)

with the observability matrix ``O = [C; CA; ...; CA^s]`` (eq. 3) and the input Toeplitz matrix
``H`` (eq. 5). Every ``w`` in the left null space of ``O`` gives a parity check
``r(k) = w' (Y(k) - H U(k))`` that is zero when the model holds (eq. 7; Chow, Lou, Verghese &
Willsky 1984, eq. 2.3-2.6). Stacked windows are ordered oldest first:
``Y(k) = [y(k-s); ...; y(k)]``. Hagenblad et al. write the same window with ``L = s + 1``.

This module holds the deterministic design (pure functions) and the additive-fault description
shared by the stochastic and robust designs. :class:`WindowParityDetector`, the FIR residual
generator behind every parity-type detector of the package, lives in
:mod:`fdi_sim.detectors.window_detector`; :func:`parity_detector` runs a parity space with it.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import null_space

from fdi_sim.detectors.window_detector import WindowParityDetector, check_order
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "AdditiveFaults",
    "ParitySpace",
    "fault_signatures",
    "input_columns",
    "input_toeplitz",
    "minimum_order",
    "observability_matrix",
    "parity_detector",
    "parity_basis",
    "parity_space",
    "select_outputs",
]

#: relative singular-value tolerance that decides the rank of O (and hence the parity dimension)
RANK_RTOL: float = 1e-10


def observability_matrix(A: NDArray, C: NDArray, order_s: int) -> NDArray[np.float64]:
    """Observability matrix ``O = [C; CA; ...; CA^s]``, shape ((s+1) r, n).

    Lou, Willsky & Verghese 1986, eq. 3; Hagenblad et al. eq. 3 with ``L = s + 1``.

    Parameters
    ----------
    A : NDArray
        State matrix (n, n) [discrete time].
    C : NDArray
        Output matrix (r, n).
    order_s : int
        Parity order s (window of s + 1 samples).
    """
    s = check_order(order_s)
    A, C = np.atleast_2d(np.asarray(A, float)), np.atleast_2d(np.asarray(C, float))
    blocks, CAk = [], C
    for _ in range(s + 1):
        blocks.append(CAk)
        CAk = CAk @ A
    return np.vstack(blocks)


def input_toeplitz(A: NDArray, B: NDArray, C: NDArray, D: NDArray, order_s: int) -> NDArray[np.float64]:
    """Lower block-Toeplitz matrix ``H`` of an input, shape ((s+1) r, (s+1) m).

    Block (i, j) is ``D`` for i = j and ``C A^(i-j-1) B`` for i > j (Lou et al. 1986, eq. 5;
    Hagenblad et al. eq. 2, where it is used for the inputs u, faults f and noise v alike).

    Parameters
    ----------
    A, B, C, D : NDArray
        Matrices of the channel, shapes (n, n), (n, m), (r, n), (r, m).
    order_s : int
        Parity order s.
    """
    s = check_order(order_s)
    A, B, C, D = (np.asarray(M, float) for M in (A, B, C, D))
    A, C = np.atleast_2d(A), np.atleast_2d(C)
    B = B[:, None] if B.ndim == 1 else B
    D = D.reshape(C.shape[0], B.shape[1]) if D.size else np.zeros((C.shape[0], B.shape[1]))
    r, m = D.shape
    H = np.zeros(((s + 1) * r, (s + 1) * m))
    markov = [D]  # D, CB, CAB, CA^2B, ...
    AkB = B
    for _ in range(s):
        markov.append(C @ AkB)
        AkB = A @ AkB
    for i in range(s + 1):
        for j in range(i + 1):
            H[i * r:(i + 1) * r, j * m:(j + 1) * m] = markov[i - j]
    return H


def parity_basis(O: NDArray, rtol: float = RANK_RTOL) -> NDArray[np.float64]:
    """Orthonormal basis ``W`` of the left null space of ``O`` (``W' O = 0``), shape (rows, p).

    scipy's ``null_space(O')``: left singular vectors beyond the numerical rank
    ``#{sv > rtol * sv_max}``. The one rank rule of every parity design in the package.
    """
    return null_space(np.atleast_2d(np.asarray(O, float)).T, rcond=rtol)


def minimum_order(A: NDArray, C: NDArray, rtol: float = RANK_RTOL) -> int:
    """Smallest order s with at least one parity relation, i.e. ``rank O_s < (s + 1) r``.

    It is at most n (Cayley-Hamilton). Chow et al. 1984, sec. 2; Lou et al. 1986, sec. 5.1.
    """
    A = np.atleast_2d(np.asarray(A, float))
    C = np.atleast_2d(np.asarray(C, float))
    for s in range(A.shape[0] + 1):
        if parity_basis(observability_matrix(A, C, s), rtol).shape[1] > 0:
            return s
    raise DesignError("no parity relation exists at any order (C has no rows?)")  # pragma: no cover


@dataclass(frozen=True, eq=False)
class ParitySpace:
    """The parity space of order s of one model, with known inputs (Lou et al. 1986, eq. 3-8).

    Attributes
    ----------
    order_s : int
        Parity order s; the window holds s + 1 samples.
    W : NDArray
        Orthonormal basis of the left null space of ``O``, shape ((s+1) r, p); ``W' O = 0``.
    O : NDArray
        Observability matrix (eq. 3).
    H : NDArray
        Toeplitz matrix of the known inputs (eq. 5), shape ((s+1) r, (s+1) m_known).
    known_inputs : tuple of int
        Model input columns treated as known (the control columns by default).
    """

    order_s: int
    W: NDArray[np.float64]
    O: NDArray[np.float64]
    H: NDArray[np.float64]
    known_inputs: tuple[int, ...]

    @property
    def n_relations(self) -> int:
        """Dimension p of the parity space (number of independent parity checks)."""
        return self.W.shape[1]

    def relations(self, W: NDArray | None = None) -> NDArray[np.float64]:
        """The checks as relations on the stacked ``[Y; U]``: ``[W; -H' W]``, so ``r = P' [Y; U]``.

        ``W`` defaults to the orthonormal basis; pass another basis of the same space (e.g. a
        noise-normalized one) to get its relations. This is the form of Lou et al. eq. 36-41.
        """
        W = self.W if W is None else np.asarray(W, float)
        return np.vstack([W, -self.H.T @ W])

    def input_adjusted(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Input-adjusted observations ``Y - H U`` (Lou et al. eq. 8) of stacked windows.

        Parameters
        ----------
        Y : NDArray
            Stacked outputs ((s+1) r,) or (..., (s+1) r), oldest sample first (deviations).
        U : NDArray
            Stacked known inputs ((s+1) m,) or (..., (s+1) m).
        """
        return np.asarray(Y, float) - np.asarray(U, float) @ self.H.T

    def residual(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Parity checks ``r = W' (Y - H U)`` (eq. 4) for stacked windows, see :meth:`input_adjusted`."""
        return self.input_adjusted(Y, U) @ self.W


def parity_space(
    model: LinearModel, order_s: int, known_inputs: Sequence[int] | None = None, rtol: float = RANK_RTOL
) -> ParitySpace:
    """Design the parity space of order s of a discrete model (Lou et al. 1986, eq. 3-8).

    Parameters
    ----------
    model : LinearModel
        Discrete-time model (``dt_s > 0``).
    order_s : int
        Parity order s (window of s + 1 samples).
    known_inputs : sequence of int, optional
        Input columns that the detector measures; default the model's control columns.
    rtol : float
        Relative singular-value tolerance for the rank of ``O``.

    Raises
    ------
    DesignError
        Continuous model, or an order too short to give any parity relation (the message gives
        the minimum order).
    """
    if not model.is_discrete:
        raise DesignError("parity relations need a discrete model; call model.discretize(dt_s) first")
    s = check_order(order_s)
    cols = tuple(int(c) for c in (model.control_columns() if known_inputs is None else known_inputs))
    O = observability_matrix(model.A, model.C, s)
    W = parity_basis(O, rtol)
    if W.shape[1] == 0:
        s_min = minimum_order(model.A, model.C, rtol)
        raise DesignError(
            f"parity order s={s} gives no parity relation: O has rank {O.shape[0]} = (s+1)*r with "
            f"r={model.n_outputs} outputs and n={model.n_states} states. Use order_s >= {s_min} "
            f"(the minimum order for this model)."
        )
    H = input_toeplitz(model.A, model.B[:, cols], model.C, model.D[:, cols], s)
    return ParitySpace(order_s=s, W=W, O=O, H=H, known_inputs=cols)


def select_outputs(model: LinearModel, outputs: Sequence[str]) -> LinearModel:
    """The same model measured by a subset of its sensors (sensor-set comparisons, Lou et al. sec. 5.1)."""
    idx = [_index_of(name, model.output_names, "output") for name in outputs]
    return LinearModel(A=model.A, B=model.B, C=model.C[idx], D=model.D[idx], dt_s=model.dt_s,
                       state_names=model.state_names, input_names=model.input_names,
                       output_names=tuple(outputs), input_kinds=model.input_kinds, x0=model.x0, u0=model.u0,
                       y0=model.y0[idx], op=model.op, meta={**model.meta, "outputs": tuple(outputs)})


def input_columns(model: LinearModel, kind: str) -> list[int]:
    """Input columns of ``model`` of one kind, ``"control"`` or ``"disturbance"``."""
    return [i for i, k in enumerate(model.input_kinds) if k == kind]


@dataclass(frozen=True, eq=False)
class AdditiveFaults:
    """Additive faults ``f`` entering as ``x+ = ... + Bf f``, ``y = ... + Df f`` (Hagenblad eq. 1).

    Attributes
    ----------
    Bf : NDArray
        (n, n_f) state entry of each fault.
    Df : NDArray
        (r, n_f) output entry of each fault.
    names : tuple of str
        One hypothesis name per fault column.
    """

    Bf: NDArray[np.float64]
    Df: NDArray[np.float64]
    names: tuple[str, ...]

    def __post_init__(self) -> None:
        Bf, Df = np.atleast_2d(np.asarray(self.Bf, float)), np.atleast_2d(np.asarray(self.Df, float))
        if Bf.shape[1] != Df.shape[1] or len(self.names) != Bf.shape[1]:
            raise DesignError(
                f"fault description inconsistent: Bf has {Bf.shape[1]} columns, Df {Df.shape[1]}, "
                f"{len(self.names)} names; give one name and one column of each per fault"
            )
        object.__setattr__(self, "Bf", Bf)
        object.__setattr__(self, "Df", Df)
        object.__setattr__(self, "names", tuple(self.names))

    @property
    def n_faults(self) -> int:
        return self.Bf.shape[1]

    @classmethod
    def from_model(
        cls, model: LinearModel, actuators: Sequence[str] = (), sensors: Sequence[str] = ()
    ) -> "AdditiveFaults":
        """Bias faults on named inputs (actuators) and outputs (sensors) of ``model``.

        An actuator fault on input j adds to the flown input: columns ``B[:, j]``, ``D[:, j]``.
        A sensor fault on output i adds to the measurement: columns ``0``, ``e_i``.
        Hypothesis names are ``"<input>_actuator"`` and ``"<output>_sensor"``.
        """
        n, r = model.n_states, model.n_outputs
        bcols, dcols, names = [], [], []
        for name in actuators:
            j = _index_of(name, model.input_names, "input")
            bcols.append(model.B[:, j])
            dcols.append(model.D[:, j])
            names.append(f"{name}_actuator")
        for name in sensors:
            i = _index_of(name, model.output_names, "output")
            bcols.append(np.zeros(n))
            dcols.append(np.eye(r)[i])
            names.append(f"{name}_sensor")
        if not names:
            raise DesignError("no faults given: name at least one actuator (input) or sensor (output)")
        return cls(Bf=np.column_stack(bcols), Df=np.column_stack(dcols), names=tuple(names))


def _index_of(name: str, names: tuple[str, ...], what: str) -> int:
    if name not in names:
        close = difflib.get_close_matches(name, names, n=2)
        hint = f" Did you mean {' or '.join(map(repr, close))}?" if close else ""
        raise DesignError(f"unknown {what} {name!r}.{hint} Model {what}s: {', '.join(names)}")
    return names.index(name)


def fault_signatures(
    model: LinearModel, faults: AdditiveFaults, order_s: int, W: NDArray
) -> NDArray[np.float64]:
    """Parity-space signature of each constant unit fault: rows ``mu_i = W' H_f (1 ⊗ e_i)``.

    Hagenblad et al. eq. 8 (``mu^i = W' H_f F^i`` with ``F^i`` the fault held constant over the
    window). Returns shape (n_f, p); use a whitened ``W`` (eq. 10) to get ``mu_bar``.
    """
    s = check_order(order_s)
    Hf = input_toeplitz(model.A, faults.Bf, model.C, faults.Df, s)
    F = np.kron(np.ones((s + 1, 1)), np.eye(faults.n_faults))  # column i = 1_(s+1) ⊗ e_i
    return (np.asarray(W, float).T @ Hf @ F).T


def parity_detector(
    detector_id: str, model: LinearModel, space: ParitySpace, W: NDArray | None = None, **kwargs: Any
) -> WindowParityDetector:
    """Run the checks ``W'(Y - H U)`` of ``space`` as a detector at ``model``'s trim point.

    ``W`` defaults to the orthonormal basis of ``space``; pass another basis of it (e.g. the
    noise-normalized one of Hagenblad et al. eq. 10). ``kwargs`` go to
    :class:`WindowParityDetector` (``cov_r``, ``threshold``, ``signatures``...).
    """
    W = space.W if W is None else np.asarray(W, float)
    return WindowParityDetector(
        detector_id=detector_id, order_s=space.order_s, proj_y=W.T, proj_u=-W.T @ space.H,
        known_inputs=space.known_inputs, u0=model.u0, y0=model.y0, **kwargs,
    )

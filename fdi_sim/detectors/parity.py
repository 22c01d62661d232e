"""Parity space of order s with known inputs (Chow-Willsky; Lou, Willsky & Verghese 1986).

For ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)`` the window of the last ``s + 1``
samples obeys

    Y(k) - H U(k) = O x(k-s)                                  (Lou et al. 1986, eq. 4-6)

with the observability matrix ``O = [C; CA; ...; CA^s]`` (eq. 3) and the input Toeplitz matrix
``H`` (eq. 5). Every ``w`` in the left null space of ``O`` gives a parity check
``r(k) = w' (Y(k) - H U(k))`` that is zero when the model holds (eq. 7; Chow, Lou, Verghese &
Willsky 1984, eq. 2.3-2.6). Stacked windows are ordered oldest first:
``Y(k) = [y(k-s); ...; y(k)]``. Hagenblad et al. write the same window with ``L = s + 1``.

This module holds the deterministic design (pure functions), the additive-fault description
shared by the stochastic and robust designs, and :class:`WindowParityDetector`, the FIR residual
generator behind every parity-type detector of the package.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fdi_sim.detectors.base import Residual
from fdi_sim.errors import DesignError, SimulationDiverged
from fdi_sim.linear.model import LinearModel

__all__ = [
    "AdditiveFaults",
    "ParitySpace",
    "WindowParityDetector",
    "fault_signatures",
    "input_toeplitz",
    "left_null_space",
    "minimum_order",
    "observability_matrix",
    "parity_space",
    "select_outputs",
    "stack_window",
]

#: relative singular-value tolerance that decides the rank of O (and hence the parity dimension)
RANK_RTOL: float = 1e-10


def _check_order(order_s: int) -> int:
    if int(order_s) != order_s or order_s < 0:
        raise DesignError(f"parity order s must be a non-negative integer, got {order_s!r}")
    return int(order_s)


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
    s = _check_order(order_s)
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
    s = _check_order(order_s)
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


def left_null_space(M: NDArray, rtol: float = RANK_RTOL) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Orthonormal basis of the left null space of ``M`` and the singular values of ``M``.

    Returns ``(W, sv)`` with ``W' M = 0`` (columns orthonormal) from the SVD ``M = U S V'``: the
    left singular vectors beyond the numerical rank ``#{sv > rtol * sv_max}``.
    """
    M = np.atleast_2d(np.asarray(M, float))
    U, sv, _ = np.linalg.svd(M, full_matrices=True)
    tol = rtol * (sv[0] if sv.size else 0.0)
    rank = int(np.sum(sv > tol)) if sv.size and sv[0] > 0 else 0
    return U[:, rank:], sv


def minimum_order(A: NDArray, C: NDArray, rtol: float = RANK_RTOL) -> int:
    """Smallest order s with at least one parity relation, i.e. ``rank O_s < (s + 1) r``.

    It is at most n (Cayley-Hamilton). Chow et al. 1984, sec. 2; Lou et al. 1986, sec. 5.1.
    """
    A = np.atleast_2d(np.asarray(A, float))
    C = np.atleast_2d(np.asarray(C, float))
    for s in range(A.shape[0] + 1):
        if left_null_space(observability_matrix(A, C, s), rtol)[0].shape[1] > 0:
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
    observability_sv : NDArray
        Singular values of ``O`` (descending); the rank decision is visible here.
    known_inputs : tuple of int
        Model input columns treated as known (the control columns by default).
    """

    order_s: int
    W: NDArray[np.float64]
    O: NDArray[np.float64]
    H: NDArray[np.float64]
    observability_sv: NDArray[np.float64]
    known_inputs: tuple[int, ...]

    @property
    def n_relations(self) -> int:
        """Dimension p of the parity space (number of independent parity checks)."""
        return self.W.shape[1]

    def projection_u(self) -> NDArray[np.float64]:
        """Matrix ``-W' H`` acting on the stacked known inputs, so ``r = W' Y + (-W' H) U``."""
        return -self.W.T @ self.H

    def residual(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Parity checks ``r = W' (Y - H U)`` (eq. 4) for stacked windows.

        Parameters
        ----------
        Y : NDArray
            Stacked outputs ((s+1) r,) or (..., (s+1) r), oldest sample first (deviations).
        U : NDArray
            Stacked known inputs ((s+1) m,) or (..., (s+1) m).
        """
        Y, U = np.asarray(Y, float), np.asarray(U, float)
        return (Y - U @ self.H.T) @ self.W


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
    s = _check_order(order_s)
    cols = tuple(int(c) for c in (model.control_columns() if known_inputs is None else known_inputs))
    O = observability_matrix(model.A, model.C, s)
    W, sv = left_null_space(O, rtol)
    if W.shape[1] == 0:
        s_min = minimum_order(model.A, model.C, rtol)
        raise DesignError(
            f"parity order s={s} gives no parity relation: O has rank {O.shape[0]} = (s+1)*r with "
            f"r={model.n_outputs} outputs and n={model.n_states} states. Use order_s >= {s_min} "
            f"(the minimum order for this model)."
        )
    H = input_toeplitz(model.A, model.B[:, cols], model.C, model.D[:, cols], s)
    return ParitySpace(order_s=s, W=W, O=O, H=H, observability_sv=sv, known_inputs=cols)


def select_outputs(model: LinearModel, outputs: Sequence[str]) -> LinearModel:
    """The same model measured by a subset of its sensors (sensor-set comparisons, Lou et al. sec. 5.1)."""
    idx = []
    for name in outputs:
        if name not in model.output_names:
            raise DesignError(f"unknown output {name!r}; model outputs: {', '.join(model.output_names)}")
        idx.append(model.output_names.index(name))
    return LinearModel(A=model.A, B=model.B, C=model.C[idx], D=model.D[idx], dt_s=model.dt_s,
                       state_names=model.state_names, input_names=model.input_names,
                       output_names=tuple(outputs), input_kinds=model.input_kinds, x0=model.x0, u0=model.u0,
                       y0=model.y0[idx], op=model.op, meta={**model.meta, "outputs": tuple(outputs)})


def stack_window(samples: NDArray) -> NDArray[np.float64]:
    """Stack a (s+1, k) block of samples, oldest first, into one ((s+1) k,) window vector."""
    return np.asarray(samples, float).reshape(-1)


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
        import difflib

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
    s = _check_order(order_s)
    Hf = input_toeplitz(model.A, faults.Bf, model.C, faults.Df, s)
    F = np.kron(np.ones((s + 1, 1)), np.eye(faults.n_faults))  # column i = 1_(s+1) ⊗ e_i
    return (np.asarray(W, float).T @ Hf @ F).T


class WindowParityDetector:
    """FIR residual generator ``r(k) = Py' Y(k) + Pu' U(k)`` with a chi-square test and angle isolation.

    The common engine of the parity, robust-parity and stochastic-parity detectors (and, with
    its own projection, PCA). Inputs and outputs are absolute values; the trim values ``u0`` and
    ``y0`` are subtracted here.

    Parameters
    ----------
    detector_id : str
        Registry id reported by the detector.
    order_s : int
        Window of s + 1 samples.
    proj_y : NDArray
        (p, (s+1) r) matrix acting on the stacked output deviations (oldest first).
    proj_u : NDArray
        (p, (s+1) m_k) matrix acting on the stacked known-input deviations.
    known_inputs : sequence of int
        Model input columns fed to ``proj_u`` (an input vector of the full model width is cut to
        these; a vector of exactly ``len(known_inputs)`` is taken as is).
    u0, y0 : NDArray
        Trim values subtracted from ``u`` (full model width) and ``y``.
    cov_r : NDArray, optional
        Fault-free residual covariance; the statistic is then ``r' cov_r^-1 r`` with p degrees
        of freedom. Without it the statistic is ``r' r`` (dof 0).
    threshold : float, optional
        Alarm threshold on the statistic; default the chi-square quantile for ``p_false_alarm``
        (requires ``cov_r``).
    p_false_alarm : float
        Target false-alarm probability per sample for the default threshold.
    signatures : NDArray, optional
        (n_h, p) residual direction of each hypothesis (same coordinates as ``r``).
    hypotheses : sequence of str
        Names of the signature rows.
    reject_angle_rad : float
        An alarm whose smallest angle exceeds this is reported without isolation [rad]
        (Hagenblad et al., Algorithm 1, reject option). ``pi`` disables rejection.
    """

    def __init__(
        self,
        detector_id: str,
        order_s: int,
        proj_y: NDArray,
        proj_u: NDArray,
        known_inputs: Sequence[int],
        u0: NDArray,
        y0: NDArray,
        cov_r: NDArray | None = None,
        threshold: float | None = None,
        p_false_alarm: float = 0.05,
        signatures: NDArray | None = None,
        hypotheses: Sequence[str] = (),
        reject_angle_rad: float = np.pi,
    ) -> None:
        self.id = detector_id
        self.order_s = _check_order(order_s)
        self.proj_y = np.atleast_2d(np.asarray(proj_y, float))
        p = self.proj_y.shape[0]
        self.proj_u = np.asarray(proj_u, float).reshape(p, -1)
        self.known_inputs = tuple(int(c) for c in known_inputs)
        self.u0, self.y0 = np.asarray(u0, float).ravel(), np.asarray(y0, float).ravel()
        n_y = self.proj_y.shape[1] // (self.order_s + 1)
        n_u = self.proj_u.shape[1] // (self.order_s + 1)
        if self.proj_y.shape[1] != (self.order_s + 1) * self.y0.size or n_u != len(self.known_inputs):
            raise DesignError(
                f"projection sizes {self.proj_y.shape}, {self.proj_u.shape} do not fit a window of "
                f"{self.order_s + 1} samples of {self.y0.size} outputs and {len(self.known_inputs)} known inputs"
            )
        self._n_y, self._n_u = n_y, n_u
        self.whiten: NDArray[np.float64] | None = None
        if cov_r is not None:
            self.whiten = _inverse_sqrt(np.asarray(cov_r, float), "residual covariance cov_r")
        if threshold is None:
            if self.whiten is None:
                raise DesignError("give a threshold, or cov_r so the chi-square threshold can be computed")
            threshold = float(chi2.isf(p_false_alarm, p))
        self.threshold = float(threshold)
        self.dof = p if self.whiten is not None else 0
        sig = np.zeros((0, p)) if signatures is None else np.atleast_2d(np.asarray(signatures, float))
        if sig.shape[1] != p or sig.shape[0] != len(hypotheses):
            raise DesignError(f"signatures {sig.shape} must be (len(hypotheses)={len(hypotheses)}, p={p})")
        self.hypotheses = tuple(hypotheses)
        sig_w = sig @ self.whiten.T if self.whiten is not None else sig
        norms = np.linalg.norm(sig_w, axis=1)
        self._detectable = norms > 1e-12 * max(float(norms.max(initial=0.0)), 1e-300)
        self._dirs = np.where(self._detectable[:, None], sig_w / np.maximum(norms, 1e-300)[:, None], 0.0)
        self.reject_angle_rad = float(reject_angle_rad)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Empty the window (the detector is deterministic; ``rng`` is unused)."""
        self._ybuf = np.zeros((self.order_s + 1, self._n_y))
        self._ubuf = np.zeros((self.order_s + 1, self._n_u))
        self._count = 0

    def _known_u(self, u: NDArray) -> NDArray[np.float64]:
        u = np.asarray(u, float).ravel()
        if u.size == self.u0.size:
            return (u - self.u0)[list(self.known_inputs)]
        if u.size == len(self.known_inputs):
            return u - self.u0[list(self.known_inputs)]
        raise DesignError(
            f"u has {u.size} entries; expected the model's {self.u0.size} inputs or the "
            f"{len(self.known_inputs)} known inputs"
        )

    def residual_of_windows(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Residuals of stacked deviation windows (vectorized form of :meth:`step`)."""
        return np.asarray(Y, float) @ self.proj_y.T + np.asarray(U, float) @ self.proj_u.T

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """Push one sample and return the residual of the window ending at ``t_s`` [s]."""
        y = np.asarray(y, float).ravel()
        if y.size != self._n_y:
            raise DesignError(f"y has {y.size} entries; the model has {self._n_y} outputs")
        uk = self._known_u(u)
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(uk))):
            bad = [f"y[{i}]" for i in np.flatnonzero(~np.isfinite(y))] + [
                f"u[{self.known_inputs[i]}]" for i in np.flatnonzero(~np.isfinite(uk))]
            raise SimulationDiverged(float(t_s), f"detector {self.id} received non-finite {', '.join(bad)}")
        self._ybuf = np.roll(self._ybuf, -1, axis=0)
        self._ubuf = np.roll(self._ubuf, -1, axis=0)
        self._ybuf[-1] = y - self.y0
        self._ubuf[-1] = uk
        self._count += 1
        r = self.proj_y @ self._ybuf.ravel() + self.proj_u @ self._ubuf.ravel()
        valid = self._count > self.order_s
        rw = self.whiten @ r if self.whiten is not None else r
        stat = float(rw @ rw) if valid else 0.0
        alarm = valid and stat > self.threshold
        scores, isolation = None, None
        if self.hypotheses:
            scores = _angles(rw, self._dirs, self._detectable)
            if alarm and np.any(self._detectable):
                best = int(np.nanargmin(scores))
                if scores[best] <= self.reject_angle_rad:
                    isolation = self.hypotheses[best]
        return Residual(t_s=float(t_s), r=rw, statistic=stat, dof=self.dof, threshold=self.threshold,
                        alarm=bool(alarm), isolation=isolation, scores=scores, valid=valid)


def _angles(r: NDArray, dirs: NDArray, detectable: NDArray) -> NDArray[np.float64]:
    """Angles [rad] between ``r`` and unit directions (nan for undetectable hypotheses)."""
    nr = float(np.linalg.norm(r))
    cos = dirs @ r / nr if nr > 0 else np.zeros(dirs.shape[0])
    ang = np.arccos(np.clip(cos, -1.0, 1.0))
    return np.where(detectable, ang, np.nan)


def _inverse_sqrt(M: NDArray, what: str) -> NDArray[np.float64]:
    """Symmetric inverse square root ``M^(-1/2)``; raises DesignError unless M is positive definite."""
    M = np.asarray(M, float)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise DesignError(f"{what} must be a square matrix, got shape {M.shape}")
    if not np.allclose(M, M.T, rtol=1e-8, atol=1e-12 * max(np.abs(M).max(), 1e-300)):
        raise DesignError(f"{what} must be symmetric")
    ev, V = np.linalg.eigh((M + M.T) / 2)
    if ev[0] <= 1e-12 * max(ev[-1], 0.0) or ev[-1] <= 0:
        raise DesignError(
            f"{what} is singular or indefinite (eigenvalues {ev[0]:.3g} ... {ev[-1]:.3g}); some residual "
            f"direction carries no noise. Add noise on every output, or drop those relations."
        )
    return (V / np.sqrt(ev)) @ V.T

"""PCA residuals trained on fault-free data (Hagenblad, Gustafsson & Klein, sec. 3, eq. 15-22).

Stack the windowed outputs and inputs into ``Z_t = (Y_t; U_t)`` (eq. 15). The eigen-
decomposition of the data correlation ``R_Z = 1/N sum Z_t Z_t' = U D U'`` (eq. 16) is split into
the model space (the largest eigenvalues) and the residual space ``W`` (the n_r smallest,
eq. 17). Residuals are ``r_t = W' Z_t`` (eq. 19) and ``r_bar_t = D_r^(-1/2) W' Z_t`` (eq. 20),
which has unit covariance as N grows. No model is needed; fault signatures come from data with
each fault (eq. 21-22). ``W'`` plays the role of ``W'[I, -H_u]`` of the parity space (eq. 5).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from fdi_sim.detectors.window_detector import WindowParityDetector
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "PcaModel",
    "EXACT_RTOL",
    "estimate_fault_signatures",
    "exact_relations",
    "make_pca_detector",
    "pca_train",
    "pca_train_from_series",
    "series_windows",
    "sliding_windows",
    "stack_data_windows",
    "suggest_residual_dimension",
]


def sliding_windows(series: NDArray, window_L: int) -> NDArray[np.float64]:
    """All windows of L consecutive samples of a (T, k) series, stacked oldest first: (T-L+1, L*k)."""
    x = np.asarray(series, float)
    x = x[:, None] if x.ndim == 1 else x
    T = x.shape[0]
    if window_L < 1 or T < window_L:
        raise DesignError(f"need at least L={window_L} samples to form a window, got {T}")
    idx = np.arange(window_L)[None, :] + np.arange(T - window_L + 1)[:, None]
    return x[idx].reshape(T - window_L + 1, -1)


def stack_data_windows(Y: NDArray, U: NDArray) -> NDArray[np.float64]:
    """Data vectors ``Z_t = (Y_t; U_t)`` (eq. 15) from stacked output and input windows, rows = t."""
    Y, U = np.atleast_2d(np.asarray(Y, float)), np.atleast_2d(np.asarray(U, float))
    if Y.shape[0] != U.shape[0]:
        raise DesignError(f"Y has {Y.shape[0]} windows but U has {U.shape[0]}")
    return np.hstack([Y, U])


@dataclass(frozen=True, eq=False)
class PcaModel:
    """A PCA split of the data space (eq. 16-20).

    Attributes
    ----------
    eigenvalues : NDArray
        All eigenvalues of ``R_Z`` (= singular values of the symmetric ``R_Z``), descending; the
        choice of n_r is read from them (Hagenblad et al. sec. 5).
    basis_model : NDArray
        ``O`` of eq. 17: (d, d - n_r) eigenvectors of the largest eigenvalues.
    W : NDArray
        (d, n_r) eigenvectors of the n_r smallest eigenvalues (residual space).
    D_r : NDArray
        (n_r,) the residual eigenvalues.
    n_samples : int
        N, the number of training windows.
    exact_relations : NDArray
        (d, k) orthonormal directions ``v`` with ``v' Z_t = 0`` in every training window (to
        :data:`EXACT_RTOL`): identically zero columns and exact linear relations, e.g. those the
        autopilot makes between commands and measurements. They are excluded from both spaces
        (``W' v = 0``); ``eigenvalues`` are those of ``R_Z`` on their orthogonal complement.
    notes : tuple of str
        Why each exact relation was dropped (column names where given).
    """

    eigenvalues: NDArray[np.float64]
    basis_model: NDArray[np.float64]
    W: NDArray[np.float64]
    D_r: NDArray[np.float64]
    n_samples: int
    exact_relations: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))
    notes: tuple[str, ...] = ()

    @property
    def n_residuals(self) -> int:
        return self.W.shape[1]

    def residual(self, Z: NDArray) -> NDArray[np.float64]:
        """``r_t = W' Z_t`` (eq. 19), rows = t."""
        return np.asarray(Z, float) @ self.W

    def normalized_residual(self, Z: NDArray) -> NDArray[np.float64]:
        """``r_bar_t = D_r^(-1/2) W' Z_t`` (eq. 20), rows = t."""
        return self.residual(Z) / np.sqrt(self.D_r)

    def split(self, Z: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Model part ``O O' Z`` and residual part ``W W' Z`` (eq. 18a-b)."""
        Z = np.asarray(Z, float)
        return Z @ self.basis_model @ self.basis_model.T, Z @ self.W @ self.W.T


#: an exact relation: a direction whose singular value in the unit-rms training data is at most
#: this (the relation holds to 1 ppm of the signals' rms). A relation made in software (an
#: autopilot's u = K y, a command held at 0) holds to rounding, 1e-16 in float64 and 6e-8 when a
#: log stores float32; a relation of the plant seen through sensors is blurred by their noise,
#: at least 1e-4 of a signal's rms (F-16 gyro noise 0.0014 rad/s against rates of 0.01-0.1 rad/s).
EXACT_RTOL = 1e-6


def exact_relations(Z: NDArray, column_names: Sequence[str] | None = None, rtol: float = EXACT_RTOL
                    ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Directions ``v`` with ``Z v = 0`` to ``rtol``: zero columns and exact linear relations.

    Parameters
    ----------
    Z : NDArray
        (N, d) data windows.
    column_names : sequence of str, optional
        Names of the d columns, for the notes.
    rtol : float
        Relative singular value below which a direction of the unit-rms data is exact.

    Returns
    -------
    basis : NDArray
        (d, k) orthonormal basis of the exact relations (k may be 0).
    notes : tuple of str
        One line per kind of relation found.
    """
    Z = np.atleast_2d(np.asarray(Z, float))
    N, d = Z.shape
    names = list(column_names) if column_names is not None else [f"z[{j}]" for j in range(d)]
    rms = np.sqrt(np.mean(Z**2, axis=0))
    zero = rms <= 0.0
    notes: list[str] = []
    dirs = [np.eye(d)[:, j] for j in np.flatnonzero(zero)]
    if zero.any():
        notes.append(f"{int(zero.sum())} column(s) identically zero: {', '.join(names[j] for j in np.flatnonzero(zero))}")
    keep = np.flatnonzero(~zero)
    if keep.size:
        # SVD of the unit-rms columns: the relative size of a singular value no longer depends on units
        _, sv, Vt = np.linalg.svd(Z[:, keep] / (rms[keep] * np.sqrt(N)), full_matrices=False)
        small = np.flatnonzero(sv <= rtol * sv[0])
        for i in small:
            v = np.zeros(d)
            v[keep] = Vt[i] / rms[keep]  # v' z = 0 in the original units
            dirs.append(v)
        if small.size:
            v = Vt[small[-1]]
            top = np.argsort(-np.abs(v))[:4]
            notes.append(
                f"{small.size} exact linear relation(s) among the columns (singular value <= {rtol:g} of the unit-rms "
                f"data, smallest {sv[small[-1]] / sv[0]:.1e}), e.g. "
                + " ".join(f"{v[j]:+.3f}*{names[keep[j]]}/rms" for j in top)
            )
    basis = sla.orth(np.column_stack(dirs)) if dirs else np.zeros((d, 0))
    return basis, tuple(notes)


def pca_train(Z: NDArray, n_residuals: int, column_names: Sequence[str] | None = None,
              exact_rtol: float = EXACT_RTOL) -> PcaModel:
    """Eigen-decomposition of the fault-free data correlation and the model/residual split.

    ``R_Z = 1/N sum_t Z_t Z_t'`` (eq. 16; the paper's N - L counts the windows, here N is the
    number of rows). Computed as the SVD of ``Z / sqrt(N)``, whose squared singular values are the
    eigenvalues of ``R_Z``.

    Exact relations in the data (:func:`exact_relations`: a command identically zero, an
    autopilot's exact ``u = K y``) are dropped before the split, with the reason recorded in
    ``PcaModel.notes``; they are not regularised. Such a relation is made by software, holds also
    when the aircraft has a fault (the autopilot still computes its law), so as a residual it is
    blind, and its eigenvalue is rounding: normalizing by it (eq. 20) would turn float rounding
    into alarms. The split is made on the orthogonal complement of the relations.

    Parameters
    ----------
    Z : NDArray
        (N, d) fault-free data windows (rows ``Z_t'``), see :func:`stack_data_windows`.
    n_residuals : int
        n_r, the number of smallest eigenvalues assigned to the residual (eq. 17), at most
        ``d - k - 1`` with k exact relations.
    column_names : sequence of str, optional
        Names of the d columns (for the notes).
    exact_rtol : float
        Tolerance of :func:`exact_relations`.

    Raises
    ------
    DesignError
        n_r outside 1..d-k-1, fewer windows than dimensions, non-finite data, or a residual
        eigenvalue that is still zero after the exact relations are dropped.
    """
    Z = np.atleast_2d(np.asarray(Z, float))
    N, d = Z.shape
    if N < d:
        raise DesignError(f"{N} training windows cannot estimate a {d}x{d} covariance; use at least {d} (many more in practice)")
    if not np.all(np.isfinite(Z)):
        raise DesignError("training data contain NaN or inf")
    Nx, notes = exact_relations(Z, column_names, exact_rtol)
    k = Nx.shape[1]
    nr = int(n_residuals)
    if not 1 <= nr < d - k:
        extra = f" after dropping {k} exact relation(s) ({'; '.join(notes)})" if k else ""
        raise DesignError(f"n_residuals must be between 1 and {d - k - 1} for {d}-dimensional data{extra}, got {n_residuals}")
    Q = np.eye(d) if k == 0 else sla.null_space(Nx.T)  # orthonormal complement of the exact relations
    _, sv, Vt = np.linalg.svd(Z @ Q / np.sqrt(N), full_matrices=False)
    ev = sv**2  # eigenvalues of R_Z = Z'Z/N (on the complement), descending
    D_r = ev[ev.size - nr:]
    if D_r[-1] <= 1e-14 * ev[0]:
        raise DesignError(
            f"the smallest residual eigenvalue is {D_r[-1]:.3g} (relative {D_r[-1] / ev[0]:.1e}) even after dropping "
            f"{k} exact relation(s): eq. 20 cannot normalize. Use noisy data or fewer residuals."
        )
    V = Q @ Vt.T
    return PcaModel(eigenvalues=ev, basis_model=V[:, : ev.size - nr], W=V[:, ev.size - nr:], D_r=D_r, n_samples=N,
                    exact_relations=Nx, notes=notes)


def series_windows(
    u: NDArray, y: NDArray, window_L: int, u0: NDArray | None = None, y0: NDArray | None = None
) -> NDArray[np.float64]:
    """Data vectors ``Z_t`` (eq. 15) of time series (a log): rows are samples of ``u`` (T, m) and ``y`` (T, r).

    Trim values ``u0``, ``y0`` are subtracted when given; windows slide by one sample.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    if u.shape[0] != y.shape[0]:
        raise DesignError(f"u has {u.shape[0]} samples but y has {y.shape[0]}")
    u = u - (0 if u0 is None else np.asarray(u0, float))
    y = y - (0 if y0 is None else np.asarray(y0, float))
    return stack_data_windows(sliding_windows(y, window_L), sliding_windows(u, window_L))


def pca_train_from_series(
    u: NDArray, y: NDArray, window_L: int, n_residuals: int,
    u0: NDArray | None = None, y0: NDArray | None = None,
) -> PcaModel:
    """Train from fault-free time series (a log), see :func:`series_windows`."""
    return pca_train(series_windows(u, y, window_L, u0, y0), n_residuals)


def suggest_residual_dimension(eigenvalues: NDArray, min_residuals: int = 1) -> int:
    """n_r at the largest gap of ``log10(eigenvalue)`` (descending order), at least ``min_residuals``.

    The choice the paper makes by eye from the singular values (sec. 3 and 5).
    """
    ev = np.asarray(eigenvalues, float)
    logs = np.log10(np.maximum(ev, np.finfo(float).tiny * 1e10))
    gaps = logs[:-1] - logs[1:]  # gap after position k (k+1 model dimensions)
    k = int(np.argmax(gaps[: ev.size - min_residuals]))
    return ev.size - (k + 1)


def estimate_fault_signatures(pca: PcaModel, fault_data: Sequence[NDArray]) -> NDArray[np.float64]:
    """Mean normalized residual of data with each fault, ``mu_bar_i = E(D_r^(-1/2) W' Z_t^i)`` (eq. 22).

    Returns (n_f, n_r), one row per entry of ``fault_data``.
    """
    return np.array([pca.normalized_residual(Z).mean(axis=0) for Z in fault_data])


def make_pca_detector(
    model: LinearModel,
    pca: PcaModel,
    window_L: int,
    signatures: NDArray | None = None,
    hypotheses: Sequence[str] = (),
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    reject_angle_rad: float = np.pi,
    known_inputs: Sequence[int] | None = None,
    detector_id: str = "pca-v1",
) -> WindowParityDetector:
    """Run a trained PCA as a detector: ``r_bar = D_r^(-1/2) W'(Y; U)`` over a sliding window.

    The model supplies only names, trim values and which inputs are recorded (the PCA itself
    is model-free). The default threshold is the chi-square quantile (eq. 13 applied to eq. 20).
    """
    cols = tuple(int(c) for c in (model.control_columns() if known_inputs is None else known_inputs))
    ny = window_L * model.n_outputs
    if pca.W.shape[0] != ny + window_L * len(cols):
        raise DesignError(
            f"PCA data dimension {pca.W.shape[0]} does not match L={window_L} windows of {model.n_outputs} "
            f"outputs and {len(cols)} inputs"
        )
    proj = (pca.W / np.sqrt(pca.D_r)).T  # D_r^(-1/2) W'
    return WindowParityDetector(
        detector_id=detector_id, order_s=window_L - 1, proj_y=proj[:, :ny], proj_u=proj[:, ny:],
        known_inputs=cols, u0=model.u0, y0=model.y0, cov_r=np.eye(pca.n_residuals), threshold=threshold,
        p_false_alarm=p_false_alarm, signatures=signatures, hypotheses=hypotheses,
        reject_angle_rad=reject_angle_rad,
    )

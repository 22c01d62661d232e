"""PCA residuals trained on fault-free data (Hagenblad, Gustafsson & Klein, sec. 3, eq. 15-22).

Stack the windowed outputs and inputs into ``Z_t = (Y_t; U_t)`` (eq. 15). The eigen-
decomposition of the data correlation ``R_Z = 1/N sum Z_t Z_t' = U D U'`` (eq. 16) is split into
the model space (the largest eigenvalues) and the residual space ``W`` (the n_r smallest,
eq. 17). Residuals are ``r_t = W' Z_t`` (eq. 19) and ``r_bar_t = D_r^(-1/2) W' Z_t`` (eq. 20),
which has unit covariance as N grows. No model is needed; fault signatures come from data with
each fault (eq. 21-22). ``W'`` plays the role of ``W'[I, -H_u]`` of the parity space (eq. 5).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.window_detector import WindowParityDetector
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "PcaModel",
    "estimate_fault_signatures",
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
    """

    eigenvalues: NDArray[np.float64]
    basis_model: NDArray[np.float64]
    W: NDArray[np.float64]
    D_r: NDArray[np.float64]
    n_samples: int

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


def pca_train(Z: NDArray, n_residuals: int) -> PcaModel:
    """Eigen-decomposition of the fault-free data correlation and the model/residual split.

    ``R_Z = 1/N sum_t Z_t Z_t'`` (eq. 16; the paper's N - L counts the windows, here N is the
    number of rows). Computed as the SVD of ``Z / sqrt(N)``, whose squared singular values are the
    eigenvalues of ``R_Z``.

    Parameters
    ----------
    Z : NDArray
        (N, d) fault-free data windows (rows ``Z_t'``), see :func:`stack_data_windows`.
    n_residuals : int
        n_r, the number of smallest eigenvalues assigned to the residual (eq. 17).

    Raises
    ------
    DesignError
        n_r outside 1..d-1, fewer windows than dimensions, or a zero residual eigenvalue
        (exactly collinear data: the normalization of eq. 20 would divide by zero).
    """
    Z = np.atleast_2d(np.asarray(Z, float))
    N, d = Z.shape
    if not 1 <= int(n_residuals) < d:
        raise DesignError(f"n_residuals must be between 1 and {d - 1} for {d}-dimensional data, got {n_residuals}")
    if N < d:
        raise DesignError(f"{N} training windows cannot estimate a {d}x{d} covariance; use at least {d} (many more in practice)")
    if not np.all(np.isfinite(Z)):
        raise DesignError("training data contain NaN or inf")
    _, sv, Vt = np.linalg.svd(Z / np.sqrt(N), full_matrices=False)
    ev = sv**2  # eigenvalues of R_Z = Z'Z/N, descending
    nr = int(n_residuals)
    D_r = ev[d - nr:]
    if D_r[-1] <= 1e-14 * ev[0]:
        raise DesignError(
            f"the smallest residual eigenvalue is {D_r[-1]:.3g} (relative {D_r[-1] / ev[0]:.1e}): the training "
            "data are exactly collinear (no noise), so eq. 20 cannot normalize. Use noisy data or fewer residuals."
        )
    V = Vt.T
    return PcaModel(eigenvalues=ev, basis_model=V[:, : d - nr], W=V[:, d - nr:], D_r=D_r, n_samples=N)


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

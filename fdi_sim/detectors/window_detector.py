"""The FIR residual generator behind every parity-type detector, and its angle isolation.

:class:`WindowParityDetector` keeps the last s + 1 samples (oldest first, the stacking of
Lou, Willsky & Verghese 1986, eq. 4-8), forms ``r = Py' Y + Pu' U``, tests ``r' cov_r^-1 r``
against a chi-square threshold (Hagenblad, Gustafsson & Klein, eq. 13) and isolates by the
smallest angle to the fault directions (their Algorithm 1). The parity, robust-parity,
stochastic-parity and PCA detectors differ only in the projections they hand it.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.errors import DesignError, SimulationDiverged

__all__ = [
    "WindowParityDetector",
    "best_hypothesis",
    "check_order",
    "residual_angles_rad",
    "unit_directions",
]


def check_order(order_s: int) -> int:
    """``order_s`` as an int; raises DesignError unless it is a non-negative integer."""
    if int(order_s) != order_s or order_s < 0:
        raise DesignError(f"parity order s must be a non-negative integer, got {order_s!r}")
    return int(order_s)


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
        Alarm threshold on the statistic; default :func:`~fdi_sim.decision.chi2.chi2_threshold`
        for ``p_false_alarm`` (requires ``cov_r``).
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
        self.order_s = check_order(order_s)
        self.proj_y = np.atleast_2d(np.asarray(proj_y, float))
        p = self.proj_y.shape[0]
        self.proj_u = np.asarray(proj_u, float).reshape(p, -1)
        self.known_inputs = tuple(int(c) for c in known_inputs)
        self.u0, self.y0 = np.asarray(u0, float).ravel(), np.asarray(y0, float).ravel()
        L = self.order_s + 1
        n_y, n_u = self.y0.size, len(self.known_inputs)
        if self.proj_y.shape[1] != L * n_y or self.proj_u.shape[1] != L * n_u:
            raise DesignError(
                f"projection sizes {self.proj_y.shape}, {self.proj_u.shape} do not fit a window of "
                f"{L} samples of {n_y} outputs and {n_u} known inputs"
            )
        self._n_y, self._n_u = n_y, n_u
        self.whiten: NDArray[np.float64] | None = None
        if cov_r is not None:
            self.whiten = _inverse_sqrt(np.asarray(cov_r, float), "residual covariance cov_r")
        if threshold is None:
            if self.whiten is None:
                raise DesignError("give a threshold, or cov_r so the chi-square threshold can be computed")
            threshold = chi2_threshold(p, p_false_alarm)
        self.threshold = float(threshold)
        self.dof = p if self.whiten is not None else 0
        sig = np.zeros((0, p)) if signatures is None else np.atleast_2d(np.asarray(signatures, float))
        if sig.shape[1] != p or sig.shape[0] != len(hypotheses):
            raise DesignError(f"signatures {sig.shape} must be (len(hypotheses)={len(hypotheses)}, p={p})")
        self.hypotheses = tuple(hypotheses)
        self.reject_angle_rad = float(reject_angle_rad)
        # constant per-step matrices: whitening folded into the projections, which act on the
        # window buffer's sample rows [y(k) - y0, u_k(k) - u0_k] laid out oldest first
        white = np.eye(p) if self.whiten is None else self.whiten
        Gy = (white @ self.proj_y).reshape(p, L, n_y)
        Gu = (white @ self.proj_u).reshape(p, L, n_u)
        self._G = np.concatenate([Gy, Gu], axis=2).reshape(p, L * (n_y + n_u))
        self._dirs = unit_directions(sig @ white.T)
        self._undetectable = np.flatnonzero(~self._dirs.any(axis=1))
        # added to the cosines before argmax so an undetectable hypothesis (cosine 0) never wins
        self._cos_mask = np.where(self._dirs.any(axis=1), 0.0, -np.inf)
        self._masked = np.empty(len(self.hypotheses))
        self._known_idx = np.array(self.known_inputs, dtype=np.intp)
        self._u0_known = self.u0[self._known_idx]
        self._finite = np.empty(n_y + n_u, dtype=bool)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Empty the window (the detector is deterministic; ``rng`` is unused)."""
        L, n_y = self.order_s + 1, self._n_y
        # each sample is written twice, at rows i and i + L, so the last L samples are always the
        # contiguous rows i+1 .. i+L (oldest first): a ring buffer without per-step copies
        self._buf = np.zeros((2 * L, n_y + self._n_u))
        self._slots = [(self._buf[i, :n_y], self._buf[i, n_y:], self._buf[i], self._buf[i + L],
                        self._buf[i + 1:i + 1 + L].reshape(-1)) for i in range(L)]
        self._pos = 0
        self._count = 0

    def residual_of_windows(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Residuals (not whitened) of stacked deviation windows (vectorized form of :meth:`step`)."""
        return np.asarray(Y, float) @ self.proj_y.T + np.asarray(U, float) @ self.proj_u.T

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """Push one sample and return the residual of the window ending at ``t_s`` [s]."""
        y, u = np.asarray(y, dtype=float), np.asarray(u, dtype=float)
        if y.ndim != 1:
            y = y.reshape(-1)
        if u.ndim != 1:
            u = u.reshape(-1)
        if y.size != self._n_y:
            raise DesignError(f"y has {y.size} entries; the model has {self._n_y} outputs")
        y_slot, u_slot, row, mirror, window = self._slots[self._pos]
        np.subtract(y, self.y0, out=y_slot)
        if u.size == self.u0.size:
            np.take(u, self._known_idx, out=u_slot)
            u_slot -= self._u0_known
        elif u.size == self._n_u:
            np.subtract(u, self._u0_known, out=u_slot)
        else:
            raise DesignError(
                f"u has {u.size} entries; expected the model's {self.u0.size} inputs or the "
                f"{self._n_u} known inputs"
            )
        np.isfinite(row, out=self._finite)
        if not self._finite.all():
            self._raise_non_finite(t_s)
        mirror[:] = row
        self._pos = (self._pos + 1) % (self.order_s + 1)
        self._count += 1
        rw = self._G @ window  # whitened residual
        sq = float(rw @ rw)
        full = self._count > self.order_s
        stat = sq if full else 0.0
        # finite inputs can still overflow (a mis-scaled model): a non-finite statistic is invalid
        valid = full and math.isfinite(sq)
        alarm = valid and stat > self.threshold
        scores, isolation = None, None
        if self.hypotheses:
            scores = self._dirs @ rw  # cosines, turned into angles in place (the array is returned)
            isolation = self._isolate(scores, sq, alarm)
        res = Residual(t_s=float(t_s), r=rw, statistic=stat, dof=self.dof, threshold=self.threshold,
                       alarm=bool(alarm), isolation=isolation, scores=scores, valid=valid)
        return res if valid or not full else finite_or_invalid(res)  # stat = |rw|^2: finite iff rw is

    def _isolate(self, scores: NDArray, sq: float, alarm: bool) -> str | None:
        """Turn ``scores`` (the cosines ``dirs @ r``) into angles [rad] in place; on alarm return the
        hypothesis of the smallest angle unless rejected.

        The rule of :func:`best_hypothesis` (largest cosine = smallest angle), written with
        in-place ufuncs because it runs every step; ``sq = r'r``.
        """
        if sq == 0.0:  # a zero residual has no direction
            scores.fill(np.nan)
            return None
        scores *= 1.0 / math.sqrt(sq)
        best = -1
        if alarm:
            np.add(scores, self._cos_mask, out=self._masked)
            best = int(self._masked.argmax())
        np.minimum(scores, 1.0, out=scores)
        np.maximum(scores, -1.0, out=scores)
        np.arccos(scores, out=scores)
        if self._undetectable.size:
            scores[self._undetectable] = np.nan
        if best < 0 or not scores[best] <= self.reject_angle_rad:  # (nan: every hypothesis undetectable)
            return None
        return self.hypotheses[best]

    def _raise_non_finite(self, t_s: float) -> None:
        bad = [f"y[{i}]" if i < self._n_y else f"u[{self.known_inputs[i - self._n_y]}]"
               for i in np.flatnonzero(~self._finite)]
        raise SimulationDiverged(float(t_s), f"detector {self.id} received non-finite {', '.join(bad)}")


def unit_directions(
    signatures: NDArray, detectable: NDArray | None = None, rtol: float = 1e-12
) -> NDArray[np.float64]:
    """Rows ``mu_i / |mu_i|`` of the (n_h, p) fault signatures; a zero row marks an undetectable one.

    A hypothesis is undetectable when ``detectable`` says so or its norm is below ``rtol`` times
    the largest norm.
    """
    sig = np.atleast_2d(np.asarray(signatures, float))
    norms = np.linalg.norm(sig, axis=1)
    ok = norms > rtol * norms.max(initial=0.0)
    if detectable is not None:
        ok &= np.asarray(detectable, bool)
    return np.where(ok[:, None], sig / np.where(ok, norms, 1.0)[:, None], 0.0)


def residual_angles_rad(r: NDArray, dirs: NDArray) -> NDArray[np.float64]:
    """Angle [rad] between residuals and unit directions (rows of :func:`unit_directions`).

    ``r`` is one residual (p,) or rows (N, p); returns (n_h,) or (N, n_h). The angle is nan for
    an undetectable hypothesis (zero direction) and for a zero residual (no direction).
    """
    r = np.asarray(r, float)
    cos = r @ dirs.T
    with np.errstate(invalid="ignore", divide="ignore"):
        cos /= np.asarray(np.linalg.norm(r, axis=-1))[..., None]
    ang = np.arccos(np.clip(cos, -1.0, 1.0, out=cos), out=cos)
    ang[..., ~dirs.any(axis=1)] = np.nan
    return ang


def best_hypothesis(angles_rad: NDArray, reject_angle_rad: float = np.pi) -> NDArray[np.intp]:
    """Index of the smallest angle (last axis), or -1 if it exceeds ``reject_angle_rad`` or none is defined.

    The isolation step of Hagenblad et al. Algorithm 1: ``argmin_i || r/|r| - mu_i/|mu_i| ||^2``
    is the smallest angle; nan angles (undetectable hypotheses) never win.
    """
    a = np.where(np.isnan(angles_rad), np.inf, angles_rad)
    if a.shape[-1] == 0:  # no hypotheses at all
        return np.full(a.shape[:-1], -1, dtype=np.intp)
    best = a.argmin(axis=-1)
    ok = np.take_along_axis(a, np.expand_dims(best, -1), axis=-1)[..., 0] <= reject_angle_rad
    return np.where(ok, best, -1)


def _psd_sqrt(M: NDArray) -> NDArray[np.float64]:
    """A square root ``G`` with ``G G' = M`` of a symmetric positive semidefinite matrix (eigh)."""
    ev, V = np.linalg.eigh((M + M.T) / 2)
    return V * np.sqrt(np.clip(ev, 0.0, None))


def _inverse_sqrt(M: NDArray, what: str) -> NDArray[np.float64]:
    """Symmetric inverse square root ``M^(-1/2)``; raises DesignError unless M is positive definite."""
    M = np.asarray(M, float)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise DesignError(f"{what} must be a square matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise DesignError(f"{what} is not finite (NaN or inf entries): the model or the noise covariance is "
                          "mis-scaled (an input or output in the wrong unit?); check model.B, model.D and R")
    if not np.allclose(M, M.T, rtol=1e-8, atol=1e-12 * max(np.abs(M).max(), 1e-300)):
        raise DesignError(f"{what} must be symmetric")
    ev, V = np.linalg.eigh((M + M.T) / 2)
    if ev[0] <= 1e-12 * max(ev[-1], 0.0) or ev[-1] <= 0:
        raise DesignError(
            f"{what} is singular or indefinite (eigenvalues {ev[0]:.3g} ... {ev[-1]:.3g}); some residual "
            f"direction carries no noise. Add noise on every output, or drop those relations."
        )
    return (V / np.sqrt(ev)) @ V.T

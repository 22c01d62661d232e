"""The runtime shared by the observer detectors: a discrete observer, and one that isolates by direction.

:class:`DiscreteObserver` runs a full-order observer on deviations from trim,

    ``r(k) = y(k) - C xh(k) - D u(k)``,  ``xh(k+1) = Phi xh(k) + Gam_u u(k) + Gam_y y(k)``,

(for a gain ``L``: ``Phi = A - L C``, ``Gam_u = B - L D``, ``Gam_y = L``), as one preallocated
matrix product per step. The steady-state Kalman filter (:mod:`fdi_sim.detectors.kalman`) uses it
as is. :class:`DirectionalObserver` adds the test of the Beard-Jones and LMI detection filters:
``r' S^-1 r`` against the chi-square threshold, and isolation by the angle between ``r`` and each
fault's output direction (the patent's phi_e, Miller & Ribbens App. A, seed
``002_d6038a6910cf5866.txt``), both whitened by ``S^-1/2`` so mixed units weigh by their noise
(a linear map keeps a fixed direction fixed). Only the design differs:
:mod:`fdi_sim.detectors.beard_jones_filter` and :mod:`fdi_sim.detectors.lmi_filter`.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.detectors.base import Residual, finite_or_invalid

Array = NDArray[np.float64]


class DiscreteObserver:
    """``xh(k+1) = Phi xh + Gam_u du + Gam_y dy``, residual ``r = dy - C xh - D du`` (deviations from trim).

    Parameters
    ----------
    Phi, Gam_u, Gam_y : arrays
        (n, n), (n, p), (n, m) observer matrices.
    C, D : arrays
        (m, n), (m, p) output matrices.
    u0, y0 : arrays
        Trim inputs and outputs, subtracted from the absolute ``u`` and ``y``.
    """

    def __init__(self, Phi: NDArray, Gam_u: NDArray, Gam_y: NDArray, C: NDArray, D: NDArray, u0: NDArray, y0: NDArray) -> None:
        C, D = np.asarray(C, float), np.asarray(D, float)
        (m, n), p = C.shape, D.shape[1]
        self._u0, self._y0 = np.asarray(u0, float), np.asarray(y0, float)
        # one product each on z = [xh; du; dy]: xh+ = F z, r = H z
        self._F = np.hstack([Phi, Gam_u, Gam_y])
        self._H = np.hstack([-C, -D, np.eye(m)])
        self._z = np.zeros(n + p + m)
        self._xh, self._du, self._dy = self._z[:n], self._z[n:n + p], self._z[n + p:]  # views into _z
        self._x_next = np.empty(n)

    @classmethod
    def from_gain(cls, A: NDArray, B: NDArray, C: NDArray, D: NDArray, L: NDArray, u0: NDArray, y0: NDArray) -> DiscreteObserver:
        """The observer ``xh(k+1) = A xh + B u + L r``."""
        return cls(A - L @ C, B - L @ D, L, C, D, u0, y0)

    @property
    def n_outputs(self) -> int:
        return self._H.shape[0]

    @property
    def x_hat(self) -> Array:
        """The current state estimate (deviation from trim), a copy."""
        return self._xh.copy()

    def reset(self) -> None:
        """Zero the state estimate."""
        self._xh[:] = 0.0

    def residual(self, u: NDArray, y: NDArray, r: Array) -> Array:
        """Write ``r = y - C xh - D u`` for absolute ``u``, ``y`` into ``r``, advance ``xh``; return ``r``."""
        np.subtract(u, self._u0, out=self._du)
        np.subtract(y, self._y0, out=self._dy)
        np.dot(self._H, self._z, out=r)
        np.dot(self._F, self._z, out=self._x_next)
        self._xh[:] = self._x_next
        return r


class DirectionalObserver:
    """A discrete observer with a chi-square test and isolation by residual direction.

    Parameters
    ----------
    observer : DiscreteObserver
    S : (m, m) array
        Residual covariance under no fault (positive definite).
    output_directions : (m, r) array
        The output direction of each fault hypothesis (columns, any length).
    hypotheses : tuple of str
        Fault names, in column order.
    alpha : float
        Per-sample false-alarm probability of the chi-square threshold (Gaussian residual).
    max_angle_rad : float
        Largest residual angle [rad] accepted for isolation.
    id : str
        Registry id.
    """

    def __init__(self, observer: DiscreteObserver, S: NDArray, output_directions: NDArray, hypotheses: tuple[str, ...],
                 alpha: float, max_angle_rad: float, id: str) -> None:
        m = observer.n_outputs
        self.observer = observer
        self.id, self.hypotheses, self.alpha, self.max_angle_rad = id, tuple(hypotheses), alpha, max_angle_rad
        self.threshold = chi2_threshold(m, alpha)
        self._W = np.linalg.inv(np.linalg.cholesky(S))  # S^-1 = W'W: r' S^-1 r = |W r|^2
        dirs = self._W @ np.asarray(output_directions, float).reshape(m, -1)
        self._dirs = dirs / np.linalg.norm(dirs, axis=0)  # unit columns, whitened
        self._dirs_T = np.ascontiguousarray(self._dirs.T)
        self._rw, self._cos, self._sin = np.empty(m), np.empty(len(self.hypotheses)), np.empty(len(self.hypotheses))
        self._perp = np.empty(self._dirs.shape)
        self._m = m

    @property
    def n_outputs(self) -> int:
        return self._m

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Zero the state estimate (the filter is deterministic; ``rng`` is unused)."""
        self.observer.reset()

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """One sample: time [s], absolute inputs ``u`` and measurements ``y`` in model order."""
        r, scores = np.empty(self._m), np.empty(len(self.hypotheses))
        stat = self.advance(u, y, r, scores)
        alarm = stat > self.threshold
        res = Residual(t_s, r, stat, self._m, self.threshold, alarm, self.isolate(scores) if alarm else None, scores)
        # stat = |W r|^2 is finite iff r is: a diverged observer is reported invalid, not "no alarm"
        return res if math.isfinite(stat) else finite_or_invalid(res)

    def advance(self, u: NDArray, y: NDArray, r: Array, scores: Array) -> float:
        """Filter one sample, writing the residual into ``r`` and the angles [rad] into ``scores``.

        Returns ``r' S^-1 r``. For callers that assemble their own record (a bank of filters).
        """
        self.observer.residual(u, y, r)
        rw = np.dot(self._W, r, out=self._rw)
        norm = float(np.sqrt(rw @ rw))
        if norm == 0.0:
            scores[:] = np.nan
            return 0.0
        rw /= norm
        c = np.dot(self._dirs_T, rw, out=self._cos)  # cosines to the unit directions
        perp = np.multiply(self._dirs, c, out=self._perp)
        np.subtract(rw[:, None], perp, out=perp)  # rw - c d: the sine side, accurate near 0 (unlike arccos)
        sin = np.sqrt(np.einsum("ij,ij->j", perp, perp, out=self._sin), out=self._sin)
        np.arctan2(sin, np.abs(c), out=scores)  # sign-insensitive angle
        return norm * norm

    def isolate(self, scores: Array) -> str | None:
        """The hypothesis with the smallest angle, if it is below ``max_angle_rad``; else None."""
        if not scores.size or np.isnan(scores).all():
            return None
        i = int(np.nanargmin(scores))
        return self.hypotheses[i] if scores[i] < self.max_angle_rad else None

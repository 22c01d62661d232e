"""The patent's two-step rule: residual magnitude above a threshold, then the angle to each fault direction.

Miller & Ribbens (US 6,643,569 B2, detailed description, the "combined use of error magnitude and
direction in output space", FIG. 3 "two-step detection logic"): the angle of the output error
residual ``e`` to the hypothesized failure's output direction ``C D_f`` is

    phi_f = arccos( <e, C D_f> / (||e|| ||C D_f||) ),

and a failure f is declared when *both* the magnitude and the angle satisfy their criteria. Here:

1. magnitude: ``T = e'e > h`` with ``P(chi2(p) > h) = p_false_alarm`` (``e`` whitened, p = its
   dimension);
2. angle: the hypothesis with the smallest ``phi_f`` is isolated if ``phi_f <= angle_bound_rad``;
   otherwise the alarm stands with no isolation (rejected: a fault none of the hypotheses explains).

A bias of unknown sign points along ``+C D_f`` or ``-C D_f``; with ``signed=False`` (default) the
angle is taken to the line, ``arccos(|cos|)`` in [0, pi/2]; ``signed=True`` is the patent's formula.

False alarms on white noise (``e ~ N(0, I_p)``: ``||e||`` and ``e/||e||`` are independent and the
direction is uniform on the sphere, so ``cos^2 phi ~ Beta(1/2, (p-1)/2)``): per sample
``P(alarm) = p_false_alarm`` and, per hypothesis, the signature ``F_f`` (magnitude *and* angle)
fires with probability ``p_false_alarm * q``, ``q = P(Beta(1/2, (p-1)/2) >= cos^2 theta)``
(halved when ``signed``, for ``theta < pi/2``).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import beta as beta_dist
from scipy.stats import chi2

from fdi_sim.decision.base import Decision, DecisionTrace, check_probability
from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.errors import DesignError

__all__ = ["AngleMagnitudeRule", "angle_false_signature_probability"]


def angle_false_signature_probability(dim: int, angle_bound_rad: float, signed: bool = False) -> float:
    """``P(phi <= angle_bound_rad)`` for an isotropic Gaussian residual of dimension ``dim`` (module doc)."""
    if dim == 1:
        return 0.5 if signed else 1.0
    c2 = math.cos(min(angle_bound_rad, math.pi / 2)) ** 2
    q = float(beta_dist.sf(c2, 0.5, (dim - 1) / 2.0))  # P(cos^2 >= cos^2 theta)
    if signed:
        # P(cos >= cos theta) = q / 2 for theta <= pi/2; 1 - q'/2 beyond (q' for pi - theta)
        if angle_bound_rad <= math.pi / 2:
            return q / 2.0
        c2b = math.cos(math.pi - angle_bound_rad) ** 2
        return 1.0 - float(beta_dist.sf(c2b, 0.5, (dim - 1) / 2.0)) / 2.0
    return q


class AngleMagnitudeRule:
    """Two-step decision on a whitened residual vector (Miller & Ribbens; module doc).

    Parameters
    ----------
    directions : NDArray
        (n_h, p) output direction ``C D_f`` of each hypothesis, in the whitened residual's coordinates.
    hypotheses : sequence of str
        Names of the rows of ``directions``.
    p_false_alarm : float
        Per-sample false-alarm probability of the magnitude step, in (0, 1).
    angle_bound_rad : float
        Largest angle to a direction that still isolates it [rad], in (0, pi].
    signed : bool
        Angle to the signed direction (the patent's formula) instead of to the line.
    threshold : float, optional
        Explicit threshold on ``e'e`` instead of the chi-square one.
    """

    id = "angle-magnitude-v1"

    def __init__(self, directions: NDArray, hypotheses: Sequence[str], p_false_alarm: float = 1e-3,
                 angle_bound_rad: float = 0.3, signed: bool = False, threshold: float | None = None) -> None:
        D = np.atleast_2d(np.asarray(directions, float))
        self.hypotheses = tuple(hypotheses)
        if D.size == 0 or D.shape[0] == 0:
            raise DesignError("the two-step rule needs at least one fault direction C D_f; the detector gives none")
        if D.shape[0] != len(self.hypotheses):
            raise DesignError(f"{D.shape[0]} fault directions for {len(self.hypotheses)} hypotheses")
        norms = np.linalg.norm(D, axis=1)
        bad = [h for h, n in zip(self.hypotheses, norms) if not (np.isfinite(n) and n > 0.0)]
        if bad:
            raise DesignError(f"hypotheses {bad} have a zero or non-finite direction C D_f: not isolable by angle")
        if not 0.0 < angle_bound_rad <= math.pi:
            raise DesignError(f"angle_bound_rad must be in (0, pi], got {angle_bound_rad}")
        self.dim = D.shape[1]
        self._dirs = D / norms[:, None]  # C D_f / ||C D_f||
        self.angle_bound_rad = float(angle_bound_rad)
        self.signed = bool(signed)
        if threshold is None:
            self.p_false_alarm = check_probability(p_false_alarm, "p_false_alarm")
            self.threshold = chi2_threshold(self.dim, self.p_false_alarm)
        else:
            self.threshold = float(threshold)
            self.p_false_alarm = float(chi2.sf(self.threshold, self.dim))
        self.p_false_signature = self.p_false_alarm * angle_false_signature_probability(
            self.dim, self.angle_bound_rad, self.signed)

    @classmethod
    def from_detector(cls, detector: Any, **params: Any) -> "AngleMagnitudeRule":
        """Build from a detector's ``fault_directions`` ((n_h, p), whitened) and ``hypotheses``.

        Raises :class:`DesignError` when the detector provides no fault direction.
        """
        D = getattr(detector, "fault_directions", None)
        hyp = tuple(getattr(detector, "hypotheses", ()) or ())
        name = getattr(detector, "id", type(detector).__name__)
        if D is None or not hyp or np.size(D) == 0:
            raise DesignError(
                f"detector {name!r} provides no fault direction (attribute fault_directions with one row per "
                "hypothesis): the angle step of the two-step rule needs C D_f. Design the detector with "
                "named faults, or use a detection-only rule (chi2-v1, cusum-v1)")
        return cls(D, hyp, **params)

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Stateless: nothing to clear."""

    def angles_rad(self, e: NDArray) -> NDArray[np.float64]:
        """Angles [rad] of residual(s) ``e`` ((p,) or (N, p)) to each direction: (n_h,) or (N, n_h)."""
        e = np.asarray(e, float)
        cos = e @ self._dirs.T
        with np.errstate(invalid="ignore", divide="ignore"):
            cos /= np.linalg.norm(e, axis=-1)[..., None]  # <e, CD_f> / (||e|| ||CD_f||)
        if not self.signed:
            np.abs(cos, out=cos)
        return np.arccos(np.clip(cos, -1.0, 1.0, out=cos), out=cos)

    def step(self, t_s: float, e: NDArray[np.float64]) -> Decision:
        """One residual vector ``e`` (p,) at time ``t_s`` [s]."""
        e = np.asarray(e, float).reshape(1, -1)  # one row: the same arithmetic as run()
        T = float(np.einsum("ij,ij->i", e, e)[0])  # e'e
        if not math.isfinite(T):
            return Decision(t_s, T, self.threshold, False, None, False)
        if T <= self.threshold:
            return Decision(t_s, T, self.threshold, False)
        ang = self.angles_rad(e)[0]
        i = int(np.argmin(ang))
        iso = self.hypotheses[i] if ang[i] <= self.angle_bound_rad else None
        return Decision(t_s, T, self.threshold, True, iso)

    def run(self, e: NDArray[np.float64]) -> DecisionTrace:
        """A trace of residuals (N, p); ``isolation`` is the hypothesis index, -1 for none or rejected."""
        e = np.asarray(e, float)
        T = np.einsum("ij,ij->i", e, e)
        ok = np.isfinite(T)
        alarm = (T > self.threshold) & ok
        ang = self.angles_rad(e)
        best = np.argmin(np.where(np.isnan(ang), np.inf, ang), axis=1)
        near = np.take_along_axis(ang, best[:, None], axis=1)[:, 0] <= self.angle_bound_rad
        iso = np.where(alarm & near, best, -1).astype(np.intp)
        return DecisionTrace(T, alarm, self.threshold, iso, None if ok.all() else ok)

    def signatures(self, e: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Per-hypothesis binary signature ``F_f`` (N, n_h): magnitude alarm *and* ``phi_f <= bound``
        (the patent's failure signal F, one per hypothesized failure; input of the failure log)."""
        e = np.asarray(e, float)
        T = np.einsum("ij,ij->i", e, e)
        return ((T > self.threshold) & np.isfinite(T))[:, None] & (self.angles_rad(e) <= self.angle_bound_rad)

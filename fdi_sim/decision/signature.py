"""Isolation by binary signature (structured residuals) with a reject option.

Each of ``n_r`` residuals has its own chi-square test (``P(chi2(dof_i) > h_i) = p_i``); the fired
pattern ``a`` (n_r bits) is compared with each hypothesis' signature row ``s_f`` (1 where fault f
makes residual i fire, the incidence matrix of structured residuals; Gertler 1998, ch. 6). The
hypothesis at the smallest Hamming distance is isolated if that distance is at most
``max_mismatch`` and no other hypothesis ties; otherwise the alarm is *rejected* (isolation -1).

False alarms on white noise, independent residuals (exact):

    P(alarm) = 1 - prod_i (1 - p_i),
    P(isolate f, max_mismatch = 0) = prod_i p_i^{s_fi} (1 - p_i)^{1 - s_fi}   (for a non-zero row s_f).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.base import Decision, DecisionTrace, check_probability
from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.errors import DesignError

__all__ = ["SignatureIsolation"]


class SignatureIsolation:
    """Threshold each residual's chi-square statistic, match the fired pattern to a signature table.

    Parameters
    ----------
    signatures : NDArray
        (n_h, n_r) 0/1 incidence: row f is the pattern fault f produces.
    hypotheses : sequence of str
        Names of the rows.
    dofs : sequence of int
        Degrees of freedom of each residual's statistic.
    p_false_alarm : float or sequence of float
        Per-sample false-alarm probability of each residual's test (one for all, or one each).
    max_mismatch : int
        Largest Hamming distance still accepted as a match (0: exact signatures).
    """

    id = "signature-isolation-v1"

    def __init__(self, signatures: NDArray, hypotheses: Sequence[str], dofs: Sequence[int],
                 p_false_alarm: float | Sequence[float] = 1e-3, max_mismatch: int = 0) -> None:
        S = np.atleast_2d(np.asarray(signatures))
        if not np.isin(S, (0, 1)).all():
            raise DesignError("signatures must be 0/1")
        self.signatures = S.astype(bool)
        self.hypotheses = tuple(hypotheses)
        n_h, n_r = S.shape
        if n_h != len(self.hypotheses):
            raise DesignError(f"{n_h} signature rows for {len(self.hypotheses)} hypotheses")
        if not self.signatures.any(axis=1).all():
            raise DesignError("a hypothesis with an all-zero signature cannot be told from no fault")
        dofs = [int(d) for d in dofs]
        if len(dofs) != n_r:
            raise DesignError(f"{len(dofs)} dofs for {n_r} residuals")
        p = np.broadcast_to(np.asarray(p_false_alarm, float), (n_r,))
        self.p_false_alarm_each = np.array([check_probability(v, "p_false_alarm") for v in p])
        self.thresholds = np.array([chi2_threshold(d, v) for d, v in zip(dofs, self.p_false_alarm_each)])
        self.max_mismatch = int(max_mismatch)
        self.threshold = float("nan")  # one threshold per residual: see ``thresholds``
        # P(alarm) = 1 - prod(1 - p_i); P(isolate f) = prod p_i^s (1 - p_i)^(1 - s)
        q = self.p_false_alarm_each
        self.p_false_alarm = float(-np.expm1(np.sum(np.log1p(-q))))
        self.p_false_isolation = np.prod(np.where(self.signatures, q, 1.0 - q), axis=1)

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Stateless: nothing to clear."""

    def _match(self, fired: NDArray[np.bool_]) -> NDArray[np.intp]:
        dist = (fired[..., None, :] != self.signatures).sum(axis=-1)  # Hamming distance to each row
        best = dist.argmin(axis=-1)
        dmin = np.take_along_axis(dist, best[..., None], axis=-1)[..., 0]
        unique = (dist == dmin[..., None]).sum(axis=-1) == 1
        return np.where(fired.any(axis=-1) & (dmin <= self.max_mismatch) & unique, best, -1).astype(np.intp)

    def step(self, t_s: float, statistics: NDArray[np.float64]) -> Decision:
        """Each residual's chi-square value (n_r,) at time ``t_s`` [s]; statistic = number fired."""
        s = np.asarray(statistics, float)
        if not np.all(np.isfinite(s)):
            return Decision(t_s, math.nan, self.threshold, False, None, False)
        fired = s > self.thresholds
        i = int(self._match(fired))
        return Decision(t_s, float(fired.sum()), self.threshold, bool(fired.any()),
                        self.hypotheses[i] if i >= 0 else None)

    def run(self, statistics: NDArray[np.float64]) -> DecisionTrace:
        """A trace (N, n_r); ``statistic`` is the number of residuals fired, ``isolation`` the index or -1."""
        s = np.asarray(statistics, float)
        ok = np.isfinite(s).all(axis=1)
        fired = (s > self.thresholds) & ok[:, None]
        iso = self._match(fired)
        count = np.where(ok, fired.sum(axis=1), np.nan)  # nan where a residual was not finite, as step()
        return DecisionTrace(count, fired.any(axis=1), self.threshold, iso,
                             None if ok.all() else ok)

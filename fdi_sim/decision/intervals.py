"""Confidence intervals for false-alarm and detection counts (shared by the card and the reports).

Clopper & Pearson (1934): the exact binomial interval of a proportion ``k / n``; Garwood (1936): the exact
Poisson interval of a rate (false alarms per flight hour); the central
binomial interval of counts for ``n`` independent samples at probability ``p``. Both assume
independent samples: for a windowed statistic whose alarms come in bursts they are optimistic.
"""
from __future__ import annotations

from scipy import stats


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of a proportion ``k / n`` (``(0, 1)`` bounds at ``k = 0`` / ``n``)."""
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def binomial_upper(n: int, p: float, level: float = 0.95) -> int:
    """Upper end of the central binomial interval of counts for ``n`` samples at probability ``p``."""
    return int(stats.binom.ppf(1.0 - (1.0 - level) / 2.0, n, p))


def poisson_rate_interval(k: int, exposure: float, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood 1936) interval of a Poisson rate from ``k`` events in ``exposure`` (e.g.
    flight hours): ``[chi2(a; 2k) / 2, chi2(1 - a; 2k + 2) / 2] / exposure``, ``a = (1 - level) / 2``
    (lower bound 0 at ``k = 0``)."""
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(stats.chi2.ppf(a, 2 * k)) / 2.0
    hi = float(stats.chi2.ppf(1.0 - a, 2 * k + 2)) / 2.0
    return lo / exposure, hi / exposure

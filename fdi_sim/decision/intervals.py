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


def rate_verdict(k: int, exposure_h: float, target_per_h: float, level: float = 0.95) -> str:
    """What ``k`` events in ``exposure_h`` say of a target rate: ``"above"`` (the interval lies
    above it), ``"below"`` (it lies below), ``"contains"``; ``"undetermined"`` when there is no
    exposure. With zero events the interval is ``[0, 3.69 / exposure]`` at 95 %: it says
    ``"below"`` only when that upper end is under the target; what a ``"contains"`` with few
    events is worth, :func:`detectable_ratio` says."""
    if not exposure_h > 0.0:
        return "undetermined"
    return interval_verdict(poisson_rate_interval(k, exposure_h, level), target_per_h)


def interval_verdict(ci_per_h: tuple[float, float] | list[float], target_per_h: float) -> str:
    """A rate interval [1/h] against a target [1/h]: ``"above"`` (it lies above the target),
    ``"below"`` or ``"contains"`` (any interval: exact, or scaled for overdispersion)."""
    return "above" if ci_per_h[0] > target_per_h else "below" if ci_per_h[1] < target_per_h else "contains"


def detectable_ratio(exposure_h: float, target_per_h: float, level: float = 0.95, power: float = 0.5) -> float:
    """The smallest ratio of a true rate to the target that ``exposure_h`` hours would show as
    ``"above"`` (:func:`rate_verdict`) with probability ``power``: what the check could have seen.

    With ``k*`` the fewest events whose interval lies above the target, the true rate ``r`` at
    which ``P(Poisson(r E) >= k*) = power`` (bisection), over the target [-]. 16.4 h at a target
    of 0.02 per h: ``k* = 3``, ``r = 0.163`` per h, a ratio of 8.2.
    """
    if not (exposure_h > 0.0 and target_per_h > 0.0):
        return float("inf")
    k = 1
    while poisson_rate_interval(k, exposure_h, level)[0] <= target_per_h:
        k += 1
    lo, hi = 0.0, 10.0 * k + 10.0  # expected counts
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if stats.poisson.sf(k - 1, mid) >= power:
            hi = mid
        else:
            lo = mid
    return hi / exposure_h / target_per_h

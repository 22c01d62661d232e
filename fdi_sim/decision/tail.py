"""Thresholds for false-alarm probabilities smaller than the training data can show.

A per-sample target ``p`` that a training set of ``N`` samples holds fewer than ten exceedances
of (``N p < 10``) has no empirical quantile worth the name. Peaks over threshold (Pickands 1975;
Coles 2001, sec. 4.3): above a high threshold ``u``, the excess ``x - u`` of a statistic with any
of the usual tails is close to a generalized Pareto distribution,

    P(X > u + z | X > u) = (1 + xi z / sigma)^(-1/xi),

so with ``q = P(X > u)`` the ``1 - p`` quantile is ``u + (sigma / xi) ((p / q)^(-xi) - 1)``
(``u - sigma log(p / q)`` for ``xi = 0``; Coles eq. 4.13). ``u`` is the empirical ``1 - q``
quantile with ``q`` chosen to leave about 1000 exceedances (at most 2 % of the samples), and
``xi``, ``sigma`` are the maximum-likelihood fit (``scipy.stats.genpareto``). The further ``p / q``
the larger the extrapolation error: the method string says how far it went.
"""
from __future__ import annotations

import math

import numpy as np
from typing import Sequence

from numpy.typing import NDArray
from scipy.optimize import fmin, minimize_scalar
from scipy.special import xlog1py
from scipy.stats import genpareto

from fdi_sim.decision.base import check_probability
from fdi_sim.errors import DesignError

__all__ = ["tail_threshold", "confident_tail_threshold", "fit_gpd", "persistence_series", "episode_threshold",
           "confident_episode_threshold"]

#: exceedances an empirical quantile needs
MIN_EMPIRICAL = 10
#: exceedances the tail fit aims for, and the fewest it accepts
TAIL_EXCEEDANCES = 1000
MIN_TAIL = 50
#: the largest tail fraction fitted
Q_MAX = 0.02


def tail_threshold(x: NDArray[np.float64], p: float) -> tuple[float, str]:
    """The ``1 - p`` quantile of the samples ``x``, tail-extrapolated where they are too few.

    Parameters
    ----------
    x : NDArray
        Training samples of the statistic (finite).
    p : float
        Exceedance probability per sample, in (0, 1).

    Returns
    -------
    (threshold, method) : (float, str)
        ``method`` is ``"empirical (k exceedances of N)"`` or the tail fit's parameters.

    Raises
    ------
    DesignError
        ``p`` outside (0, 1), or fewer samples than a tail fit needs.
    """
    p = check_probability(p, "per-sample false-alarm probability p")
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n * p >= MIN_EMPIRICAL:
        return float(np.quantile(x, 1.0 - p)), f"empirical ({n * p:.0f} exceedances expected of {n} samples)"
    q = min(Q_MAX, TAIL_EXCEEDANCES / max(n, 1))
    if n * q < MIN_TAIL:
        raise DesignError(f"{n} training samples are too few for a tail fit ({MIN_TAIL / Q_MAX:.0f} at least); fly more "
                          "or longer calibration flights")
    u = float(np.quantile(x, 1.0 - q))
    z = x[x > u] - u
    if z.size < MIN_TAIL:  # ties at the top (a saturated or discrete statistic): no tail to fit
        return float(x.max()), (f"degenerate upper tail ({z.size} of {n} samples above the {1 - q:.4f} quantile "
                                f"{u:.4g}): the training maximum")
    xi, sigma = fit_gpd(z)
    thr = u + float(genpareto.ppf(1.0 - p / q, xi, loc=0.0, scale=sigma))
    return thr, (f"GPD tail over the {1 - q:.4f} quantile ({z.size} exceedances of {n}), xi {xi:.3f}, sigma "
                 f"{sigma:.3g}, extrapolated {q / p:.3g} x beyond it")


#: scipy's penalty per sample outside the support or of infinite log-density, over 100
#: (``rv_continuous._nnlf_and_penalty``: ``n_bad * log(_XMAX) * 100``)
_LOG_XMAX = float(np.log(np.finfo(float).max))


def _gpd_nnlf(theta: NDArray[np.float64], z: NDArray[np.float64]) -> float:
    """The objective of ``genpareto.fit(z, floc=0)``, value for value: the negative log-likelihood
    of the generalized Pareto at ``theta = (xi, sigma)`` with scipy's penalty for samples outside
    the support (``rv_continuous._penalized_nnlf``), in plain numpy.

    ``-log f(x) = (1 + 1/xi) log(1 + xi x / sigma) + log sigma`` (``x / sigma`` for ``xi = 0``);
    support ``x >= 0``, and ``x <= -sigma / xi`` when ``xi < 0``. Scipy evaluates the same
    expressions through its array-API layer, 20 us a call of the ~190 a fit makes: a bootstrap of
    200 fits per member was 93 % of a seventeen-member bank's design (tests/sim/test_every_detector.py,
    133 s, cProfile).
    """
    c, s = float(theta[0]), float(theta[1])
    if not math.isfinite(c) or s <= 0.0:
        return math.inf
    x = z / s
    n = x.size
    bad = (x < 0.0) | (x > -1.0 / c) if c < 0.0 else x < 0.0
    n_bad = int(np.count_nonzero(bad))
    if n_bad:
        x = x[~bad]
    lp = -x if c == 0.0 else -xlog1py(c + 1.0, c * x) / c
    finite = np.isfinite(lp)
    n_bad += int(np.count_nonzero(~finite))
    if n_bad:
        return float(-np.sum(lp[finite]) + n_bad * _LOG_XMAX * 100 + n * np.log(s))
    return float(-np.sum(lp) + n * np.log(s))


def fit_gpd(z: NDArray[np.float64]) -> tuple[float, float]:
    """Maximum-likelihood generalized Pareto fit of exceedances ``z`` (location 0): ``(xi, sigma)``.

    ``genpareto.fit(z, floc=0.0)`` bit for bit (tests/decision/test_decision_tail.py checks it on
    light, heavy and bounded tails): scipy's start (``_fitstart``: xi 1, its scale estimate), its
    Nelder-Mead (``scipy.optimize.fmin`` with its defaults) on the same objective values
    (:func:`_gpd_nnlf`), 2.5 x faster.

    Raises
    ------
    DesignError
        The optimum is outside the distribution's parameter range (scipy's ``FitError``).
    """
    z = np.asarray(z, dtype=float).ravel()
    start = genpareto._fitstart(z)  # (xi, loc, scale): loc is fixed at 0 and left out, as fit() does
    xi, sigma = fmin(_gpd_nnlf, (start[0], start[-1]), args=(z,), disp=0)
    if not (math.isfinite(xi) and sigma > 0.0):
        raise DesignError(f"the tail fit converged outside the generalized Pareto's range (xi {xi}, sigma {sigma})")
    return float(xi), float(sigma)


def confident_tail_threshold(flights: Sequence[NDArray[np.float64]], p: float, rng: np.random.Generator,
                             level: float = 0.95, n_boot: int = 200) -> tuple[float, str]:
    """A threshold that meets ``p`` with confidence ``level``: the ``level`` quantile of
    :func:`tail_threshold` over bootstrap resamples of whole flights.

    A windowed statistic is correlated over seconds (the airspeed check's over tens of seconds:
    its residual is the longitudinal gust), so its training samples are far fewer independent
    draws than samples, and the point estimate of an extrapolated quantile is uncertain by more
    than their count suggests. Resampling flights (not samples) keeps that correlation (Efron &
    Tibshirani 1993, block bootstrap, ch. 8.6). A one-off measurement, on the DHC-6 in moderate
    turbulence (24 x 300 s training flights; seeds 101-108, which this choice then used up): the
    airspeed check's point estimate 15.56 kt was exceeded by 3 of 8 10-minute flights; the 95 %
    bound, 18.7 kt, by none. The test below checks the method on AR(1) flights.

    Parameters
    ----------
    flights : sequence of NDArray
        The statistic of each training flight (finite samples).
    p : float
        Per-sample exceedance probability, in (0, 1).
    rng : numpy.random.Generator
        For the resampling.
    level : float
        Confidence, in (0, 1).
    n_boot : int
        Bootstrap resamples.

    Returns
    -------
    (threshold, method) : (float, str)
    """
    level = check_probability(level, "confidence level")
    flights = [np.asarray(f, dtype=float) for f in flights if len(f)]
    if len(flights) < 2:
        raise DesignError("a confident threshold needs at least two training flights")
    point, how = tail_threshold(np.concatenate(flights), p)
    k = len(flights)
    boot = [tail_threshold(np.concatenate([flights[i] for i in rng.integers(0, k, k)]), p)[0] for _ in range(n_boot)]
    return _bound(point, how, boot, level, k)


def _bound(point: float, how: str, boot: Sequence[float], level: float, k: int) -> tuple[float, str]:
    """The ``level`` quantile of the bootstrap thresholds ``boot`` (never below the point estimate)
    and its method text."""
    thr = float(np.quantile(boot, level))
    return max(thr, point), (f"{level:.0%} bootstrap bound over {k} flights ({len(boot)} resamples) of: {how}; "
                             f"point estimate {point:.4g}")


# --- alarm episodes per hour (declustered peaks over threshold) -------------------------------------

#: run maxima (alarm episodes) the episode tail fit aims for, and the fewest it accepts
TAIL_EPISODES = 100
MIN_EPISODES = 30
#: alarm episodes an empirical episode threshold needs
MIN_EMPIRICAL_EPISODES = 10
#: the tail method's version, in every cache key of thresholds it sets (a change refits them)
TAIL_METHOD = "clusters-v3"
#: 95 % point of the 50:50 mixture of chi-square(0) and chi-square(1) (the deviance of a shape on
#: its boundary xi = 0): a fitted positive shape this much more likely than xi = 0 is kept
HEAVY_DEVIANCE = 2.706
#: log-likelihood by which the exponential in the square (the lighter tail) must beat the one in
#: the statistic to be chosen: a likelihood ratio of e^2 = 7.4. Too light a tail is the failure
#: that breaks the rate, too heavy a one costs detection. Measured at 2,500 x on 100 trials each
#: (docs/make_tail_coverage.py's statistics): margin 0 covered chi-square(1) in 0.83 of them and a
#: Gaussian mean in 0.96 (median level 1.16 x the exact one); margin 2: 0.91 and 0.99 (1.28 x);
#: margin 5: 0.92 and 0.99 (1.28 x)
SCALE_MARGIN = 2.0
#: the largest ratio of the fitted level's episode rate to the target at which the tail method's
#: coverage was measured (docs/tail_coverage.md: at least 0.89 for every statistic there, 1.0 for
#: the Gaussian one); a target further out is refused
MAX_EXTRAPOLATION = 10000.0


def persistence_series(stat: NDArray[np.float64], valid: NDArray[np.bool_], k: int, n: int) -> NDArray[np.float64]:
    """The statistic whose exceedance *is* the k-of-n alarm: at sample ``j`` the ``k``-th largest
    of the valid statistics among samples ``j - n + 1 .. j`` (``-inf`` where fewer than ``k`` of them
    are valid).

    "At least ``k`` of the last ``n`` valid samples exceed ``thr``" holds exactly when this
    series exceeds ``thr`` (:func:`fdi_sim.bank.kernels.decide`, whose ring starts empty at a reset),
    so a threshold set on its upcrossings sets the alarm episodes themselves.

    Parameters
    ----------
    stat, valid : NDArray
        One flight's statistic and whether each sample was armed and valid (N,).
    k, n : int
        Persistence: ``1 <= k <= n``.
    """
    s = np.where(np.asarray(valid, bool) & np.isfinite(stat), np.asarray(stat, float), -np.inf)
    if n == 1:
        return s
    padded = np.concatenate([np.full(n - 1, -np.inf), s])
    win = np.lib.stride_tricks.sliding_window_view(padded, n)  # (N, n): samples j - n + 1 .. j
    return np.partition(win, n - k, axis=1)[:, n - k]  # the k-th largest


def _runs(m: NDArray[np.float64], u: float) -> tuple[NDArray[np.float64], int]:
    """Maxima of the runs of ``m > u`` (one per alarm episode at level ``u``) and their count."""
    above = m > u
    if not above.any():
        return np.zeros(0), 0
    edges = np.diff(np.concatenate([[False], above, [False]]).astype(np.int8))
    starts = np.flatnonzero(edges == 1)
    # a run's maximum: from its start to the next start (the samples between are -inf)
    return np.maximum.reduceat(np.where(above, m, -np.inf), starts), len(starts)


def _cluster_maxima(m: NDArray[np.float64], u: float, run: int) -> NDArray[np.float64]:
    """Maxima of the clusters of ``m > u``: a cluster ends after ``run`` samples at or below ``u``
    (runs declustering, Coles 2001 sec. 5.3.2)."""
    idx = np.flatnonzero(m > u)
    if idx.size == 0:
        return np.zeros(0)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(idx) > run) + 1])
    return np.maximum.reduceat(m[idx], starts)


def _run_length(cs: Sequence["_Crossings"], w: NDArray[np.int64], u: float) -> int:
    """The run length that declusters exceedances of ``u`` into independent clusters, from the
    intervals estimator of the extremal index (Ferro & Segers 2003, eq. 4 and sec. 4): with ``N``
    exceedances and inter-exceedance times ``T``, ``theta = min(1, 2 (sum(T - 1))^2 / ((N - 1)
    sum((T - 1)(T - 2))))`` (``2 (sum T)^2 / ((N - 1) sum T^2)`` when no ``T`` exceeds 2), and the
    ``theta N``-th largest ``T`` separates clusters. A statistic that chatters about the level
    (a 10 s mean dipping below it for a sample or two) is then one cluster, not many episodes
    with tiny excesses, whose mixture would pass for a heavy tail."""
    gaps = [np.repeat(np.diff(np.flatnonzero(c.m > u)), int(wi)) for c, wi in zip(cs, w) if wi]
    t = np.concatenate(gaps).astype(float) if gaps else np.zeros(0)
    n_exc = t.size + sum(int(wi) for c, wi in zip(cs, w) if wi and (c.m > u).any())  # N - 1 gaps per flight
    if t.size < 2:
        return 1
    if t.max() <= 2.0:
        theta = min(1.0, 2.0 * t.sum() ** 2 / (t.size * float(np.sum(t * t))))
    else:
        den = float(np.sum((t - 1.0) * (t - 2.0)))
        theta = 1.0 if den <= 0.0 else min(1.0, 2.0 * float(np.sum(t - 1.0)) ** 2 / (t.size * den))
    n_clusters = max(1, int(math.floor(theta * n_exc)))
    if n_clusters > t.size:
        return 1
    return max(1, int(np.sort(t)[::-1][n_clusters - 1]))


class _Crossings:
    """One flight's upcrossings of every level at once: the series ``m`` upcrosses ``x`` at sample
    ``j`` when ``m[j-1] <= x < m[j]`` (``m[-1] = -inf``: a flight that starts above ``x`` starts an
    episode), so the count at ``x`` is the number of intervals ``[m[j-1], m[j])`` holding it: the
    sorted interval ends ``lo`` and ``hi`` (counted for many flights at once by :class:`_Pool`)."""

    def __init__(self, m: NDArray[np.float64]) -> None:
        self.m = np.asarray(m, float)
        prev = np.concatenate([[-np.inf], self.m[:-1]])
        up = self.m > prev
        self.lo, self.hi = np.sort(prev[up]), np.sort(self.m[up])
        fin = self.m[np.isfinite(self.m)]
        self.top = float(fin.max()) if fin.size else -np.inf
        self.finite = fin


class _Pool:
    """The upcrossing intervals of several flights pooled, for counts with per-flight weights.

    ``sum_i w_i count_i(x)`` is ``W_lo(x) - W_hi(x)``, the weights of the pooled interval starts and
    ends at or below ``x``: two binary searches in the sorted pooled ends and their cumulative
    weights (the same integers as the per-flight sum, without a Python loop over flights; a
    bootstrap resample only redoes the cumulative sums).
    """

    def __init__(self, cs: Sequence[_Crossings]) -> None:
        self.cs = list(cs)
        own = [np.full(c.lo.size, i, dtype=np.int64) for i, c in enumerate(self.cs)]
        lo = np.concatenate([c.lo for c in self.cs]) if self.cs else np.zeros(0)
        hi = np.concatenate([c.hi for c in self.cs]) if self.cs else np.zeros(0)
        owner = np.concatenate(own) if own else np.zeros(0, dtype=np.int64)
        i_lo, i_hi = np.argsort(lo, kind="stable"), np.argsort(hi, kind="stable")
        self.lo, self.lo_owner = lo[i_lo], owner[i_lo]
        self.hi, self.hi_owner = hi[i_hi], owner[i_hi]

    def counter(self, w: NDArray[np.int64]) -> "_Counter":
        return _Counter(self, np.asarray(w, dtype=np.int64))


class _Counter:
    """Weighted episode counts of a :class:`_Pool` at any level (``count(x)``)."""

    def __init__(self, pool: _Pool, w: NDArray[np.int64]) -> None:
        self.pool = pool
        self.cw_lo = np.concatenate([[0], np.cumsum(w[pool.lo_owner])])
        self.cw_hi = np.concatenate([[0], np.cumsum(w[pool.hi_owner])])

    def count(self, x: float) -> int:
        p = self.pool
        return int(self.cw_lo[np.searchsorted(p.lo, x, "right")] - self.cw_hi[np.searchsorted(p.hi, x, "right")])


def episode_threshold(flights: Sequence[NDArray[np.float64]], rate_per_h: float, hours: float,
                      weights: NDArray[np.int64] | None = None, power: float | None = None,
                      heavy: bool = True) -> tuple[float, str]:
    """The level whose upcrossings (alarm episodes) occur ``rate_per_h`` times per flight hour.

    Peaks over threshold on declustered data (Coles 2001, sec. 5.3.2): at a level ``u`` with
    about :data:`TAIL_EPISODES` episodes in the training flights, the exceedances are grouped into
    independent clusters (:func:`_run_length`, the intervals estimator of the extremal index), the
    excess of each cluster's peak over ``u`` is generalized Pareto (Coles eq. 4.2), so clusters
    above ``x`` come at ``lambda_u (1 + xi (x - u) / sigma)^(-1/xi)`` per hour, times the episodes
    per cluster at the highest levels (``split``: a statistic that chatters about a level starts
    several alarm episodes in one excursion); the threshold solves that for ``rate_per_h``. Unlike
    per-sample exceedances (:func:`tail_threshold`), the peaks are nearly independent: a statistic
    correlated over tens of samples (the airspeed check's 10 s mean of the longitudinal gust) puts
    hundreds of exceedances per excursion into a per-sample fit, whose shape then describes the
    top of a few smooth bumps, not the tail (DHC-6 approach, 24 x 300 s: xi -0.44, a fitted
    endpoint 2.6 kt above the 0.993 quantile, a threshold of 14.0 kt, 3.3 standard deviations of
    the residual, exceeded in a held-out flight by a 10 s mean gust of 12.7 kt).

    The tail is exponential (``xi = 0``) unless a heavier one is significant (:func:`_choose_tail`):
    the bank's statistics (means of Gaussian residuals, chi-square forms) lie in the Gumbel
    domain, so a fitted shape on a hundred peaks is mostly the sampling noise of a finite level. A
    negative one would cap the threshold at the fitted endpoint; a positive one is kept only where
    significant (the gust filter's, xi 0.2-0.7, is: its residual mismatch in turbulence is
    heavy-tailed). The exponential is in the statistic (``power = 1``: a chi-square form's
    upcrossings fall as ``exp(-x / 2)``) or in its square (``power = 2``: a Gaussian mean's fall
    as ``exp(-x^2 / 2 s^2)``, Rice's formula). A member that knows the form of its statistic says
    so (its stream's ``tail_power``, and ``tail_heavy = False`` for a statistic known to be
    light-tailed), and no choice is made; otherwise the two compete on likelihood. A target more than :data:`MAX_EXTRAPOLATION` times below the fitted level's rate is
    refused: the coverage of the method's bound was measured up to there
    (``docs/make_tail_coverage.py``).

    Parameters
    ----------
    flights : sequence of NDArray
        :func:`persistence_series` of each training flight.
    rate_per_h : float
        Target alarm episodes per flight hour (> 0).
    hours : float
        Armed flight hours the series cover (with their weights).
    weights : NDArray, optional
        How many times each flight counts (a bootstrap resample); all 1 by default.
    power : float, optional
        The scale of the exponential tail when the statistic's form is known (2: a mean of
        Gaussian residuals, 1: a quadratic form); None: chosen from the data.
    heavy : bool
        Whether a heavier (generalized Pareto) tail may replace the exponential where its
        deviance is significant; False for a statistic known to be light-tailed.

    Returns
    -------
    (threshold, method) : (float, str)

    Raises
    ------
    DesignError
        A non-positive target or too few episodes for a fit.
    """
    pool = _Pool([_Crossings(m) for m in flights])
    w = np.ones(len(pool.cs), dtype=np.int64) if weights is None else np.asarray(weights, dtype=np.int64)
    return _episode_fit(pool, w, rate_per_h, hours, power, heavy)[:2]


def _episode_fit(pool: _Pool, w: NDArray[np.int64], rate_per_h: float, hours: float,
                 power: float | None = None, heavy: bool = True) -> tuple[float, str, float, bool]:
    """:func:`episode_threshold` on the flights of ``pool`` counted ``w`` times each, and the scale
    (``power``) and tail (``heavy``) it chose (every bootstrap resample chooses again)."""
    if not (rate_per_h > 0.0 and math.isfinite(rate_per_h)):
        raise DesignError(f"episode rate target must be > 0 per flight hour, got {rate_per_h}")
    cs = pool.cs
    n_fin = sum(int(wi) * c.finite.size for c, wi in zip(cs, w))
    if n_fin < 2 * TAIL_EPISODES or hours <= 0.0:
        raise DesignError(f"{n_fin} valid training samples are too few for an episode-rate threshold; fly more "
                          "or longer calibration flights")
    counter = pool.counter(w)
    want = rate_per_h * hours  # episodes the training flights would show at the threshold
    # the highest level with about TAIL_EPISODES episodes (bisection; the count falls as the level rises)
    used = [c for c, wi in zip(cs, w) if wi]
    lo = float(np.median(np.concatenate([c.finite for c in used])))
    hi = max(c.top for c in used)
    at_median = counter.count(lo)
    if at_median < MIN_EPISODES:
        raise DesignError(f"only {at_median} alarm episodes above the median of the training statistic (a "
                          f"fit needs {MIN_EPISODES}); fly more or longer calibration flights")
    for _ in range(50 if at_median > TAIL_EPISODES else 0):  # else: fit above the median
        mid = 0.5 * (lo + hi)
        if counter.count(mid) >= TAIL_EPISODES:
            lo = mid
        else:
            hi = mid
    u = lo
    run = _run_length(cs, w, u)
    peaks = np.concatenate([np.repeat(_cluster_maxima(c.m, u, run), int(wi)) for c, wi in zip(cs, w) if wi])
    if peaks.size < MIN_EPISODES:
        raise DesignError(f"only {peaks.size} alarm episodes above any level of the training flights (a fit needs "
                          f"{MIN_EPISODES}); fly more or longer calibration flights")
    top = np.sort(peaks)[::-1]
    split = 1.0
    for r in range(MIN_EMPIRICAL_EPISODES, peaks.size, MIN_EMPIRICAL_EPISODES):
        x = float(np.nextafter(top[r - 1], -np.inf))  # just below the r-th peak: r peaks above it
        split = max(split, counter.count(x) / r)
    if MIN_EMPIRICAL_EPISODES <= want / split < peaks.size:
        i = int(math.floor(want / split))  # the level with that many peaks above it
        return float(top[i]), (f"empirical: {i} of {peaks.size} cluster peaks above it in {hours:.2f} h "
                                f"(split {split:.2f})"), 1.0, False
    xi, sigma, pw, heavy, how = _choose_tail(peaks, u, power, heavy)
    lam = peaks.size * split / hours
    at_u = counter.count(u) / hours  # episodes per hour at the fitted level: the extrapolation's start
    if at_u / rate_per_h > MAX_EXTRAPOLATION:
        raise DesignError(f"{rate_per_h:.3g} episodes per h is {at_u / rate_per_h:,.0f} x below the {at_u:.3g} per h "
                          f"the training flights show at the fitted level, beyond the {MAX_EXTRAPOLATION:,.0f} x at "
                          f"which the tail method's coverage was measured (docs/tail_coverage.md): fly at least "
                          f"{hours * at_u / (rate_per_h * MAX_EXTRAPOLATION):.3g} x the {hours:.3g} h of calibration "
                          f"flights")
    thr = u if rate_per_h >= lam else \
        (u ** pw + float(genpareto.ppf(1.0 - rate_per_h / lam, xi, loc=0.0, scale=sigma))) ** (1.0 / pw)
    on = "" if pw == 1.0 else f" of the statistic^{pw:g}"
    return thr, (f"GPD{on} over {peaks.size} clusters (run length {run}) above {u:.4g} ({lam:.3g} episodes per h, "
                 f"split {split:.2f}), "
                 f"{how}, sigma {sigma:.3g}, extrapolated {lam / rate_per_h:.3g} x to {rate_per_h:.3g} per h"), \
        pw, heavy


def _gpd_fit(z: NDArray[np.float64]) -> tuple[float, float, float]:
    """Maximum-likelihood generalized Pareto fit to excesses ``z > 0`` with the shape held at or
    above 0: ``(xi, sigma, log-likelihood)``.

    The profile likelihood in ``theta = xi / sigma`` (Grimshaw 1993): for a given ``theta`` the
    best shape is ``xi = mean(log(1 + theta z))``, and the log-likelihood
    ``-n log(xi / theta) - (1 + 1 / xi) sum(log(1 + theta z))``; at ``theta -> 0`` it is the
    exponential's, ``-n log(mean z) - n``. A bounded one-dimensional search (far faster than the
    general two-parameter fit, which the bootstrap would call thousands of times).
    """
    n = z.size
    zbar = float(z.mean())
    ll_exp = -n * math.log(zbar) - n

    def neg(log_t: float) -> float:
        t = math.exp(log_t) / zbar
        lz = np.log1p(t * z)
        xi = float(lz.mean())
        return n * math.log(xi / t) + (1.0 + 1.0 / xi) * float(lz.sum())

    best = minimize_scalar(neg, bounds=(-12.0, 8.0), method="bounded", options={"xatol": 1e-6})
    if -float(best.fun) <= ll_exp:
        return 0.0, zbar, ll_exp
    t = math.exp(float(best.x)) / zbar
    xi = float(np.log1p(t * z).mean())
    return xi, xi / t, -float(best.fun)


def _choose_tail(peaks: NDArray[np.float64], u: float, power: float | None = None,
                 allow_heavy: bool = True) -> tuple[float, float, float, bool, str]:
    """The tail of the episode peaks above ``u``: ``(xi, sigma, power, heavy, text)``.

    Two light tails compete on the likelihood of the same peaks (both one parameter, so no
    penalty is needed): exponential in the statistic (a chi-square form's upcrossings fall as
    ``exp(-x / 2)``) and exponential in its square (a Gaussian mean's fall as ``exp(-x^2 / 2 s^2)``,
    Rice's formula), the latter scored on the statistic's own scale (its density carries the
    Jacobian ``2 x``). A heavier tail (generalized Pareto, ``xi > 0``, on the chosen scale) is kept
    where its deviance against that exponential exceeds :data:`HEAVY_DEVIANCE`, the 95 % point of
    the 50:50 mixture of chi-square(0) and chi-square(1) that a shape on the boundary ``xi = 0``
    follows (Self & Liang 1987). The choice is a selection: :func:`confident_episode_threshold`
    repeats it on every bootstrap resample, so its bound carries the selection's variability.
    """
    best = None
    if power is not None and power not in (1.0, 2.0):
        raise DesignError(f"tail power must be 1 or 2, got {power}")
    if power == 2.0 and u <= 0.0:  # a square is not monotone below 0: choose from the data
        power = None
    for pw in ((1.0, 2.0) if u > 0.0 else (1.0,)) if power is None else (float(power),):
        with np.errstate(over="ignore"):
            z = peaks ** pw - u ** pw
        if not np.isfinite(z).all() or not (z > 0.0).any():
            continue
        z = np.maximum(z, 1e-300)
        s = float(z.mean())
        # log-likelihood of the peaks on the statistic's scale: exponential density of z times dz/dx
        ll = -z.size * math.log(s) - z.size + (0.0 if pw == 1.0 else float(np.sum(np.log(pw * peaks ** (pw - 1.0)))))
        ll -= 0.0 if pw == 1.0 or power is not None else SCALE_MARGIN  # the lighter tail must win by a margin
        if best is None or ll > best[0]:
            best = (ll, pw, z)
    if best is None:
        raise DesignError("the episode peaks have no spread above the fitted level: no tail to fit")
    _, pw, z = best
    xi, sigma, ll_gpd = _gpd_fit(z)
    s = float(z.mean())
    deviance = 2.0 * (ll_gpd - (-z.size * math.log(s) - z.size))
    form = "" if power is None else ", the statistic's form given" + ("" if allow_heavy else " (light-tailed)")
    if allow_heavy and xi > 0.0 and deviance > HEAVY_DEVIANCE:
        return xi, sigma, pw, True, f"xi {xi:.3f}, deviance {deviance:.2f}{form}"
    return 0.0, s, pw, False, f"xi 0 (MLE {xi:.3f}, deviance {deviance:.2f}){form}"


def confident_episode_threshold(flights: Sequence[NDArray[np.float64]], rate_per_h: float, hours: Sequence[float],
                                rng: np.random.Generator, level: float = 0.95,
                                n_boot: int = 200, power: float | None = None,
                                heavy: bool = True) -> tuple[float, str]:
    """:func:`episode_threshold` at its ``level`` bootstrap bound over whole flights (as
    :func:`confident_tail_threshold`, whose reasons apply: a flight's episodes share its turbulence).

    Parameters
    ----------
    flights : sequence of NDArray
        :func:`persistence_series` of each training flight.
    rate_per_h : float
        Target alarm episodes per flight hour.
    hours : sequence of float
        Armed hours of each flight.
    rng : numpy.random.Generator
        For the resampling.
    level : float
        Confidence, in (0, 1).
    n_boot : int
        Bootstrap resamples.
    power, heavy
        As :func:`episode_threshold`'s (the same in every resample).

    Returns
    -------
    (threshold, method) : (float, str)
    """
    level = check_probability(level, "confidence level")
    keep = [i for i, m in enumerate(flights) if len(m)]
    pool = _Pool([_Crossings(flights[i]) for i in keep])
    h = np.array([float(hours[i]) for i in keep])
    if len(pool.cs) < 2:
        raise DesignError("a confident threshold needs at least two training flights")
    k = len(pool.cs)
    point, how, _, _ = _episode_fit(pool, np.ones(k, dtype=np.int64), rate_per_h, float(h.sum()), power, heavy)
    boot, n_heavy = [], 0
    for _ in range(n_boot):
        w = np.bincount(rng.integers(0, k, k), minlength=k)
        try:
            thr, _, _, is_heavy = _episode_fit(pool, w, rate_per_h, float(w @ h), power, heavy)
            boot.append(thr)
            n_heavy += is_heavy
        except DesignError:
            continue  # a resample with too few episodes says nothing about the bound
    if len(boot) < n_boot // 2:
        raise DesignError(f"only {len(boot)} of {n_boot} bootstrap resamples could be fitted; fly more or longer "
                          "calibration flights")
    return _bound(point, f"{how} (a heavy tail in {n_heavy} of {len(boot)} resamples)", boot, level, k)

"""Clopper-Pearson and the binomial count interval against exact binomial tail sums."""
from __future__ import annotations

import pytest
from scipy import stats

from fdi_sim.decision.intervals import binomial_upper, clopper_pearson


@pytest.mark.parametrize("k,n", [(0, 48000), (4, 47680), (65, 47680), (10, 10)])
def test_clopper_pearson_bounds_have_the_tail_probability(k: int, n: int) -> None:
    lo, hi = clopper_pearson(k, n)
    if k > 0:  # P(X >= k | lo) = 2.5 %
        assert stats.binom.sf(k - 1, n, lo) == pytest.approx(0.025, rel=1e-6)
    else:
        assert lo == 0.0
    if k < n:  # P(X <= k | hi) = 2.5 %
        assert stats.binom.cdf(k, n, hi) == pytest.approx(0.025, rel=1e-6)
    else:
        assert hi == 1.0


def test_binomial_upper_is_the_975_quantile() -> None:
    """48,000 samples at 1e-4 (the card's held-out size and target): 4.8 expected, at most 10."""
    u = binomial_upper(48000, 1e-4)
    assert u == 10
    assert stats.binom.cdf(u, 48000, 1e-4) >= 0.975 > stats.binom.cdf(u - 1, 48000, 1e-4)


def test_poisson_rate_interval_covers_at_its_level():
    """Garwood's interval against simulated Poisson counts: coverage >= 95 % (exact intervals are
    conservative), and the textbook k = 0 upper bound 3.689 / T (95 %)."""
    import numpy as np

    from fdi_sim.decision.intervals import poisson_rate_interval

    assert poisson_rate_interval(0, 2.0) == (0.0, pytest.approx(3.6889 / 2.0, rel=1e-4))
    rng = np.random.default_rng(5)
    for rate in (0.3, 4.0):
        ks = rng.poisson(rate * 10.0, size=4000)
        cover = np.mean([lo <= rate <= hi for lo, hi in (poisson_rate_interval(int(k), 10.0) for k in ks)])
        assert 0.95 <= cover < 0.995


def test_verdicts_and_the_ratio_a_check_could_detect():
    """``rate_verdict`` words the exact interval against the target; ``detectable_ratio`` is the
    true rate at which the fewest counts whose interval lies above the target come half the time."""
    from scipy.stats import poisson

    from fdi_sim.decision.intervals import detectable_ratio, interval_verdict, poisson_rate_interval, rate_verdict

    assert rate_verdict(0, 16.4, 0.1) == "contains"  # 0 alarms in 16.4 h: [0, 0.225]
    assert rate_verdict(0, 50.0, 0.1) == "below" and rate_verdict(5, 10.0, 0.1) == "above"
    assert rate_verdict(3, 0.0, 0.1) == "undetermined"
    assert interval_verdict((0.2, 0.5), 0.1) == "above" and interval_verdict((0.0, 0.05), 0.1) == "below"
    for hours, target in ((16.4, 0.02), (32.8, 0.1), (500.0, 0.1)):
        ratio = detectable_ratio(hours, target)
        k = next(k for k in range(1, 1000) if poisson_rate_interval(k, hours)[0] > target)
        assert poisson_rate_interval(k - 1, hours)[0] <= target
        assert poisson.sf(k - 1, ratio * target * hours) == pytest.approx(0.5, abs=1e-9)
        assert ratio > 1.0
    assert detectable_ratio(500.0, 0.1) < detectable_ratio(32.8, 0.1)  # more hours see smaller excesses

"""The tail-extrapolated threshold against distributions whose quantiles are known."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fdi_sim.decision.tail import tail_threshold
from fdi_sim.errors import DesignError


def test_empirical_where_the_data_suffice():
    x = np.random.default_rng(1).exponential(size=100_000)
    thr, how = tail_threshold(x, 1e-3)
    assert how.startswith("empirical")
    assert abs(thr - np.log(1e3)) < 0.3


@pytest.mark.parametrize("p, tol", [(1e-6, 0.15), (1e-8, 0.35)])
def test_exponential_and_chi2_tails_are_extrapolated(p, tol):
    """1e3 and 1e5 times beyond the fitted quantile; the error grows with it (4 seeds: at most
    9 % and 29 %)."""
    rng = np.random.default_rng(2)
    x = rng.exponential(size=200_000)
    thr, how = tail_threshold(x, p)
    assert "GPD" in how
    assert abs(thr / -np.log(p) - 1.0) < tol
    y = chi2.rvs(14, size=200_000, random_state=rng)
    thr = tail_threshold(y, p)[0]
    assert abs(thr / chi2.isf(p, 14) - 1.0) < tol


def test_the_extrapolated_threshold_holds_on_fresh_samples():
    """Calibrated at p = 1e-5 on 20,000 samples (0.2 exceedances expected: extrapolated), the
    exceedance rate on 2,000,000 fresh samples is within a factor of 3 of p."""
    rng = np.random.default_rng(3)
    thr = tail_threshold(rng.gamma(3.0, size=20_000), 1e-5)[0]
    rate = np.mean(rng.gamma(3.0, size=2_000_000) > thr)
    assert 1e-5 / 3 < rate < 3e-5


def test_bad_input():
    with pytest.raises(DesignError, match=r"\(0, 1\)"):
        tail_threshold(np.ones(10), 1.5)
    with pytest.raises(DesignError, match="too few"):
        tail_threshold(np.random.default_rng(0).normal(size=500), 1e-6)


def test_confident_threshold_covers_correlated_flights():
    """AR(1) flights (correlation time 50 samples): the 95 % bootstrap bound is above the point
    estimate and meets the target on fresh flights more often than the point estimate does."""
    from fdi_sim.decision.tail import confident_tail_threshold

    def flights(rng, k, n=3000):
        out = []
        for _ in range(k):
            e = rng.normal(size=n)
            x = np.empty(n)
            x[0] = e[0]
            for i in range(1, n):
                x[i] = 0.98 * x[i - 1] + 0.2 * e[i]
            out.append(x)
        return out

    rng = np.random.default_rng(11)
    p = 1e-5
    true = 0.2 / np.sqrt(1 - 0.98 ** 2) * 4.2649  # the Gaussian 1 - 1e-5 quantile of the AR(1) marginal
    met_point = met_conf = 0
    for _ in range(6):
        fl = flights(rng, 12)
        thr, how = confident_tail_threshold(fl, p, rng, n_boot=60)
        point = tail_threshold(np.concatenate(fl), p)[0]
        assert thr >= point and "bootstrap" in how
        met_point += point >= true
        met_conf += thr >= true
    assert met_conf >= met_point and met_conf >= 4

"""Chi-square test: per-sample false-alarm rate on chi-square noise, detection of a mean shift."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import ncx2

from decision_intervals import binomial_ci, mean_ci
from fdi_sim.decision import Chi2Test
from fdi_sim.errors import DesignError


def test_false_alarm_rate_per_sample_matches_target() -> None:
    """N = 400 000 chi2(3) samples at p = 1e-2: the alarm count is Binomial(N, p)."""
    rule = Chi2Test(dof=3, p_false_alarm=1e-2)
    x = np.random.default_rng(20).chisquare(3, 400_000)
    tr = rule.run(x)
    lo, hi = binomial_ci(int(tr.alarm.sum()), x.size)
    assert lo <= 1e-2 <= hi, (tr.alarm.mean(), lo, hi)


def test_detects_a_mean_shift_within_expected_delay() -> None:
    """A whitened residual with mean m (|m| = 2): per-sample detection P_D = P(ncx2(3, |m|^2) > h),
    expected delay to the first alarm (geometric) 1 / P_D samples."""
    rule = Chi2Test(dof=3, p_false_alarm=1e-3)
    mean = np.array([2.0, 0.0, 0.0])
    pd = float(ncx2.sf(rule.threshold, 3, mean @ mean))
    rng = np.random.default_rng(21)
    r = rng.standard_normal((400, 4000, 3)) + mean
    alarm = rule.run(np.einsum("tmi,tmi->tm", r, r)).alarm
    delays = alarm.argmax(axis=0) + 1
    assert alarm.any(axis=0).all()
    m, lo, hi = mean_ci(delays)
    assert lo <= 1.0 / pd <= hi, (m, lo, hi, 1.0 / pd)


def test_bad_targets_raise() -> None:
    for p in (0.0, 1.0, -0.1, 1.5):
        with pytest.raises(DesignError):
            Chi2Test(dof=2, p_false_alarm=p)
    with pytest.raises(DesignError):
        Chi2Test(dof=0)

"""k-of-n persistence: P_FA = P(Bin(n, p) >= k) per sample on chi-square noise; delay on a step."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom, ncx2

from decision_intervals import binomial_ci
from fdi_sim.decision import Persistence, persistence_false_alarm, persistence_sample_probability
from fdi_sim.errors import DesignError


def test_inverse_is_exact() -> None:
    p = persistence_sample_probability(1e-4, 3, 5)
    assert persistence_false_alarm(p, 3, 5) == pytest.approx(1e-4, rel=1e-9)


def test_false_alarm_rate_per_sample_matches_binomial_formula() -> None:
    """3 of 5 at P_FA = 5e-3: outputs 5 samples apart use disjoint windows and are independent,
    so their alarm count over 100 000 windows is Binomial(100 000, P_FA)."""
    k, n = 3, 5
    rule = Persistence(k, n, dof=2, p_false_alarm=5e-3)
    x = np.random.default_rng(30).chisquare(2, 500_000 + n)
    alarm = rule.run(x).alarm[n - 1::n]  # full, disjoint windows
    lo, hi = binomial_ci(int(alarm.sum()), alarm.size)
    assert lo <= 5e-3 <= hi, (alarm.mean(), lo, hi)


def test_detects_a_step_within_n_samples() -> None:
    """A step raising the per-sample firing probability to P1: the alarm comes within n samples of
    the onset with probability P(Bin(n, P1) >= k) (windows entirely after the onset)."""
    k, n = 3, 5
    rule = Persistence(k, n, dof=1, p_false_alarm=1e-3)
    shift = 3.0
    p1 = float(ncx2.sf(rule.sample_threshold, 1, shift ** 2))
    rng = np.random.default_rng(31)
    pre, m = 50, 20_000
    z = rng.standard_normal((pre + n, m))
    z[pre:] += shift
    tr = rule.run(z * z).alarm
    clean = ~tr[:pre].any(axis=0)  # runs without a false alarm before the onset
    detected = tr[pre + n - 1, clean]  # the first window made only of faulty samples
    lo, hi = binomial_ci(int(detected.sum()), int(clean.sum()))
    expected = float(binom.sf(k - 1, n, p1))
    assert lo <= expected <= hi, (detected.mean(), lo, hi, expected)


def test_bad_parameters_raise() -> None:
    with pytest.raises(DesignError):
        Persistence(6, 5, dof=1)
    with pytest.raises(DesignError):
        Persistence(2, 5, dof=1, p_false_alarm=1.0)

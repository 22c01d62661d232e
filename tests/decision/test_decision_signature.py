"""Isolation by signature: false-alarm and false-isolation rates on white chi-square noise (exact
product formulas), isolation of a fault by its signature, rejection of an unknown pattern."""
from __future__ import annotations

import numpy as np
import pytest

from decision_intervals import binomial_ci
from fdi_sim.decision import SignatureIsolation
from fdi_sim.errors import DesignError

SIG = np.array([[1, 1, 0], [0, 1, 1], [1, 0, 1]])
HYP = ("pitch_gyro", "elevator", "alpha_vane")


def test_false_alarm_and_false_isolation_rates_on_white_noise() -> None:
    """Three chi2(2) residuals at p_i = 5e-2, 300 000 samples: alarm rate 1 - (1 - p)^3 and
    isolation to each hypothesis p^2 (1 - p), each in its binomial interval."""
    rule = SignatureIsolation(SIG, HYP, dofs=(2, 2, 2), p_false_alarm=5e-2)
    x = np.random.default_rng(80).chisquare(2, (300_000, 3))
    tr = rule.run(x)
    lo, hi = binomial_ci(int(tr.alarm.sum()), x.shape[0])
    assert lo <= rule.p_false_alarm <= hi and rule.p_false_alarm == pytest.approx(1 - 0.95 ** 3)
    for j in range(3):
        lo, hi = binomial_ci(int((tr.isolation == j).sum()), x.shape[0])
        assert lo <= rule.p_false_isolation[j] <= hi and rule.p_false_isolation[j] == pytest.approx(0.05 ** 2 * 0.95)


def test_isolates_a_step_by_its_signature_and_rejects_unknown_patterns() -> None:
    rule = SignatureIsolation(SIG, HYP, dofs=(1, 1, 1), p_false_alarm=1e-3)
    rng = np.random.default_rng(81)
    z = rng.standard_normal((1000, 3))
    z[:, 1:] += 8.0  # residuals 2 and 3 fire: the elevator's signature
    tr = rule.run(z * z)
    assert tr.alarm.all() and (tr.isolation == 1).mean() > 0.99
    d = rule.step(0.0, np.array([100.0, 100.0, 100.0]))  # all three: no hypothesis has it
    assert d.alarm and d.isolation is None
    loose = SignatureIsolation(SIG, HYP, dofs=(1, 1, 1), max_mismatch=1)
    assert loose.step(0.0, np.array([100.0, 0.0, 0.0])).isolation is None  # ties pitch_gyro and alpha_vane


def test_bad_tables_raise() -> None:
    with pytest.raises(DesignError):
        SignatureIsolation(np.array([[1, 0], [0, 0]]), ("a", "b"), dofs=(1, 1))
    with pytest.raises(DesignError):
        SignatureIsolation(SIG, HYP, dofs=(1, 1))
    with pytest.raises(DesignError):
        SignatureIsolation(SIG, HYP, dofs=(1, 1, 1), p_false_alarm=1.2)

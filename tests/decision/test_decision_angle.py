"""The patent's two-step rule: magnitude false-alarm rate and per-hypothesis false-signature rate on
white noise (exact: the direction of isotropic noise is uniform on the sphere); isolation of a step
along a fault direction; the reject option; refusal without fault directions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from decision_intervals import binomial_ci
from fdi_sim.decision import AngleMagnitudeRule
from fdi_sim.errors import DesignError

DIRS = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
HYP = ("a", "b", "c")


@pytest.mark.parametrize("signed", [False, True])
def test_false_alarm_and_false_signature_rates_on_white_noise(signed: bool) -> None:
    """e ~ N(0, I_3), 400 000 samples, p = 2e-2, bound 0.6 rad: alarms ~ Bin(N, p); signature f
    ~ Bin(N, p q), q = P(Beta(1/2, 1) >= cos^2 0.6) (halved when signed)."""
    rule = AngleMagnitudeRule(DIRS, HYP, p_false_alarm=2e-2, angle_bound_rad=0.6, signed=signed)
    e = np.random.default_rng(70 + signed).standard_normal((400_000, 3))
    tr = rule.run(e)
    lo, hi = binomial_ci(int(tr.alarm.sum()), e.shape[0])
    assert lo <= 2e-2 <= hi
    F = rule.signatures(e)
    q = 1.0 - math.cos(0.6)  # p = 3: P(|cos| >= c) = 1 - c exactly
    assert rule.p_false_signature == pytest.approx(2e-2 * (q / 2 if signed else q), rel=1e-9)
    for j in range(3):
        lo, hi = binomial_ci(int(F[:, j].sum()), e.shape[0])
        assert lo <= rule.p_false_signature <= hi, (HYP[j], F[:, j].mean(), lo, hi)


def test_isolates_a_step_along_a_fault_direction_and_rejects_an_unknown_one() -> None:
    rule = AngleMagnitudeRule(DIRS, HYP, p_false_alarm=1e-3, angle_bound_rad=0.3)
    rng = np.random.default_rng(72)
    b = DIRS[1] / np.linalg.norm(DIRS[1])
    e = rng.standard_normal((2000, 3)) * 0.2 + 8.0 * b  # |step| = 8 sigma along C D_b, either sign below
    e[1000:] *= -1.0
    tr = rule.run(e)
    assert tr.alarm.all() and (tr.isolation == 1).mean() > 0.99  # detected at once (delay 1 sample)
    unknown = np.array([1.0, -1.0, 0.0]) / math.sqrt(2) * 8.0  # orthogonal to a, b; angle to a is pi/4
    d = rule.step(0.0, unknown)
    assert d.alarm and d.isolation is None  # rejected
    assert rule.step(0.0, 8.0 * b).isolation == "b"


def test_refuses_without_fault_directions() -> None:
    class NoDirections:
        id = "parity-v1"
        hypotheses = ()

    with pytest.raises(DesignError, match="no fault direction"):
        AngleMagnitudeRule.from_detector(NoDirections())
    with pytest.raises(DesignError):
        AngleMagnitudeRule(np.zeros((0, 3)), ())
    with pytest.raises(DesignError, match="zero"):
        AngleMagnitudeRule(np.array([[0.0, 0.0, 0.0]]), ("a",))
    with pytest.raises(DesignError):
        AngleMagnitudeRule(DIRS, HYP, p_false_alarm=0.0)

    class WithDirections:
        id = "x-v1"
        hypotheses = HYP
        fault_directions = DIRS

    assert AngleMagnitudeRule.from_detector(WithDirections()).hypotheses == HYP

"""Every registered decision rule: the reset/step contract, step() equal to run() bit for bit
(a NaN sample included), frozen Decision, determinism, and DesignError on bad targets."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fdi_sim import registry
from fdi_sim.decision import Decision, DecisionRule
from fdi_sim.errors import DesignError

DIRS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])

#: id -> (parameters, input maker (rng, N) -> trace)
CASES = {
    "chi2-v1": ({"dof": 2, "p_false_alarm": 1e-2}, lambda rng, n: rng.chisquare(2, n)),
    "persistence-v1": ({"k": 2, "n": 4, "dof": 2, "p_false_alarm": 1e-2}, lambda rng, n: rng.chisquare(2, n)),
    "cusum-v1": ({"sigma": 1.0, "shift": 1.0, "arl0_samples": 50.0}, lambda rng, n: rng.standard_normal(n) + 0.5),
    "glr-v1": ({"sigma": 1.0, "w_max": 20, "w_min": 2, "arl0_samples": 50.0}, lambda rng, n: rng.standard_normal(n) + 0.5),
    "sprt-v1": ({"sigma": 1.0, "shift": 1.0, "alpha": 0.05, "beta": 0.1}, lambda rng, n: rng.standard_normal(n) + 0.5),
    "angle-magnitude-v1": ({"directions": DIRS, "hypotheses": ("a", "b"), "p_false_alarm": 0.2, "angle_bound_rad": 0.5},
                           lambda rng, n: rng.standard_normal((n, 3))),
    "signature-isolation-v1": ({"signatures": np.array([[1, 0], [1, 1]]), "hypotheses": ("a", "b"), "dofs": (1, 1),
                                "p_false_alarm": 0.2}, lambda rng, n: rng.chisquare(1, (n, 2))),
}
BAD_P = {
    "chi2-v1": "p_false_alarm", "persistence-v1": "p_false_alarm", "cusum-v1": None, "glr-v1": None,
    "sprt-v1": "alpha", "angle-magnitude-v1": "p_false_alarm", "signature-isolation-v1": "p_false_alarm",
}


def test_every_rule_is_registered() -> None:
    assert set(CASES) <= set(registry.ids("decision"))


@pytest.mark.parametrize("rule_id", sorted(CASES))
def test_step_equals_run(rule_id: str) -> None:
    params, make = CASES[rule_id]
    rule = registry.get("decision", rule_id).factory(**params)
    assert isinstance(rule, DecisionRule) and rule.id == rule_id
    x = make(np.random.default_rng(5), 400)
    x[37] = np.nan
    tr = rule.run(x)
    rule.reset(np.random.default_rng(0))
    steps = [rule.step(0.05 * k, x[k]) for k in range(len(x))]
    assert all(isinstance(d, Decision) for d in steps)
    with pytest.raises(dataclasses.FrozenInstanceError):
        steps[0].alarm = True  # type: ignore[misc]
    stat = np.array([d.statistic for d in steps])
    assert np.array_equal(stat, tr.statistic, equal_nan=True)
    assert np.array_equal(np.array([d.alarm for d in steps]), tr.alarm)
    assert not steps[37].valid and not steps[37].alarm and tr.valid is not None and not tr.valid[37]
    if tr.isolation is not None:
        names = [rule.hypotheses.index(d.isolation) if d.isolation else -1 for d in steps]
        assert np.array_equal(np.array(names), tr.isolation)
    assert np.array_equal(rule.run(x).statistic, tr.statistic, equal_nan=True)  # run starts from reset


@pytest.mark.parametrize("rule_id", sorted(CASES))
@pytest.mark.parametrize("bad", [0.0, 1.0, -0.5, 2.0])
def test_false_alarm_target_outside_unit_interval_raises(rule_id: str, bad: float) -> None:
    params, _ = CASES[rule_id]
    params = dict(params)
    key = BAD_P[rule_id]
    if key is None:  # the ARL rules take a per-sample rate instead of their ARL target
        params = {k: v for k, v in params.items() if k != "arl0_samples"}
        key = "p_false_alarm"
    params[key] = bad
    with pytest.raises(DesignError):
        registry.get("decision", rule_id).factory(**params)

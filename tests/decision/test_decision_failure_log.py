"""The failure log (patent FIG. 4): an intermittent fault gives several events, a persistent one one."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.decision import AngleMagnitudeRule, FailureEvent, FailureLogger, failure_log


def _signals() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(1200) / 20.0  # 60 s at 20 Hz
    F = np.zeros((t.size, 2), dtype=bool)
    F[200:400, 0] = True  # persistent: 10 s to 20 s
    for a in (100, 500, 900):  # intermittent: three 2 s bursts from 5 s, 25 s, 45 s
        F[a:a + 40, 1] = True
    F[1190:, 0] = True  # ... and a second occurrence of the first, still on at the end
    return t, F


def test_events_onset_end_duration_and_nature() -> None:
    t, F = _signals()
    F[1190:, 0] = False
    log = failure_log(t, F, ("pitch_gyro", "elevator"))
    assert [e.hypothesis for e in log] == ["elevator", "pitch_gyro", "elevator", "elevator"]
    gyro = [e for e in log if e.hypothesis == "pitch_gyro"]
    assert gyro == [FailureEvent("pitch_gyro", 10.0, 20.0, 10.0, "persistent")]
    elev = [e for e in log if e.hypothesis == "elevator"]
    assert [e.onset_t_s for e in elev] == [5.0, 25.0, 45.0]
    assert all(e.nature == "intermittent" and e.duration_s == pytest.approx(2.0) for e in elev)


def test_stepwise_logger_gives_the_same_events_and_open_events() -> None:
    t, F = _signals()
    logger = FailureLogger(("pitch_gyro", "elevator"))
    ended = [e for ti, f in zip(t, F) for e in logger.step(ti, f)]
    assert logger.events() == failure_log(t, F, ("pitch_gyro", "elevator"))
    # streamed: the first burst reads persistent when it ends, the later ones intermittent
    assert (ended[0].hypothesis, ended[0].nature) == ("elevator", "persistent")
    assert ended[0].duration_s == pytest.approx(2.0) and ended[2].nature == "intermittent"
    last = logger.events()[-1]
    assert last.ongoing and last.onset_t_s == 59.5 and last.nature == "intermittent"


def test_merge_gap_debounces_chatter() -> None:
    t = np.arange(100) * 0.01
    F = np.zeros(100, dtype=bool)
    F[10:20] = F[22:30] = F[60:70] = True
    assert len(failure_log(t, F, ("x",))) == 3
    merged = failure_log(t, F, ("x",), merge_gap_s=0.05)
    assert [(e.onset_t_s, e.end_t_s) for e in merged] == [pytest.approx((0.1, 0.3)), pytest.approx((0.6, 0.7))]


def test_from_the_two_step_rule_on_an_intermittent_fault() -> None:
    """Signatures of the two-step rule over an intermittent bias: one event per burst."""
    rule = AngleMagnitudeRule(np.eye(2), ("a", "b"), p_false_alarm=1e-4, angle_bound_rad=0.3)
    rng = np.random.default_rng(90)
    e = rng.standard_normal((600, 2))
    for a in (100, 300, 500):
        e[a:a + 50, 0] += 10.0
    log = failure_log(np.arange(600) * 0.05, rule.signatures(e), rule.hypotheses, merge_gap_s=0.2)
    assert [(e.hypothesis, e.nature) for e in log] == [("a", "intermittent")] * 3
    assert [e.onset_t_s for e in log] == pytest.approx([5.0, 15.0, 25.0])

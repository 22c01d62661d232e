"""The benchmark's scorer (fdi_sim.scoring) on hand-made alarm sequences with known answers,
including the point-adjustment trap."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.scoring import (
    CaseOutput,
    CaseTruth,
    point_adjust,
    sample_grid,
    score_suite,
)

T = np.arange(1001) / 10.0  # 10 Hz, 0..100 s


def _truth(case: str, window: tuple[float, float] | None, target: str = "q_radps", size_rank: int = 0) -> CaseTruth:
    return CaseTruth(case, "f16", "g", "test", "sensor-bias-v1" if window else "", target if window else "",
                     "1 bias_degps" if window else "", size_rank if window else -1,
                     (window,) if window else (), 5.0, 100.0)


def _alarm(*spans: tuple[float, float]) -> np.ndarray:
    a = np.zeros(T.size, bool)
    for lo, hi in spans:
        a |= (T >= lo) & (T < hi)
    return a


def _suite() -> tuple[list[CaseTruth], dict[str, CaseOutput]]:
    truths = [_truth("A", None), _truth("B", (40.0, 100.0)), _truth("C", (30.0, 100.0)), _truth("D", (30.0, 100.0))]
    iso_b = ["q_radps" if 42.0 <= t < 43.0 else None for t in T]
    outs = {"A": CaseOutput(T, _alarm((20.0, 21.0), (50.0, 52.0))),
            "B": CaseOutput(T, _alarm((42.0, 43.0)), isolation=iso_b),
            "C": CaseOutput(T, _alarm((10.0, 12.0), (38.0, 40.0))),
            "D": CaseOutput(T, _alarm())}
    return truths, outs


def test_control_metrics_equal_the_hand_computed_answer():
    truths, outs = _suite()
    s = score_suite(truths, outs)
    # exposure: A 95 s; B 35 s (5..40); C, D 25 s (5..30): 180 s = 0.05 h; false alarms 2 (A) + 1 (C)
    assert s["exposure_h"] == pytest.approx(180.0 / 3600.0)
    assert s["false_alarms"] == 3
    assert s["far_per_h"] == pytest.approx(60.0)
    d = s["detection"]
    assert (d["detected"]["k"], d["detected"]["n"]) == (2, 3)  # B at 42 s, C at 38 s (first alarm at/after onset)
    assert d["delay_s_median"] == pytest.approx(5.0)  # delays 2 and 8
    assert (d["isolation"]["k"], d["isolation"]["n"]) == (1, 1)  # B named q_radps; C names nothing
    assert s["confusion"] == {"q_radps": {"q_radps": 1, "not isolated": 1, "not detected": 1}}
    a = s["alfa"]  # A: FP (alarm, no fault); B: TP (2 s <= 5 s); C: FP (alarm before onset); D: FN
    assert (a["tp"], a["fp"], a["fn"], a["tn"]) == (1, 2, 1, 0)
    assert a["precision"] == pytest.approx(1 / 3) and a["recall"] == pytest.approx(1 / 2)
    assert a["mean_detection_time_s"] == pytest.approx(2.0)
    assert s["per_flight_detection"]["k"] == 1  # C's detection follows an early alarm: not clean
    e = s["event"]  # recalled: B (42 in [40, 102]), C (38 in [30, 102]); false events 3
    assert (e["recalled"], e["false_events"]) == (2, 3)
    assert e["precision"] == pytest.approx(2 / 5) and e["recall"] == pytest.approx(2 / 3)
    assert e["f1"] == pytest.approx(0.5)


def test_sample_metrics_equal_the_hand_computed_answer():
    truths, outs = _suite()
    s = score_suite(truths, outs)["sample"]
    # grid 5..100 s at 10 Hz: 951 samples per case. Positives: B 601 (40..100), C and D 701 (30..100).
    # Alarm samples: A 30 negative; B 10 positive; C 20 negative (10..12) + 20 positive (38..40)
    assert s["samples"] == 4 * 951
    assert s["positives"] == 601 + 701 + 701
    assert s["precision"] == pytest.approx(30 / 80)
    assert s["recall"] == pytest.approx(30 / 2003)
    assert s["auroc"] is None  # alarms only: no score, no curve


def test_auc_of_raw_scores_equals_the_hand_computed_answer():
    # one case, four grid samples (arm 0, end 0.3 s at 10 Hz): labels 0 0 1 1, scores 0.1 0.4 0.35 0.8
    tr = CaseTruth("x", "f16", "g", "test", "sensor-bias-v1", "q_radps", "", 0, ((0.2, 0.3),), 0.0, 0.3)
    t = np.array([0.0, 0.1, 0.2, 0.3])
    out = CaseOutput(t, np.zeros(4, bool), np.array([0.1, 0.4, 0.35, 0.8]))
    s = score_suite([tr], {"x": out}, grace_s=0.0)["sample"]
    # AUROC: of the 4 (positive, negative) pairs, 3 are ordered right: 0.75.
    # AP: ranked 0.8 (+), 0.4 (-), 0.35 (+): precision 1 at recall 0.5, 2/3 at recall 1: (1 + 2/3) / 2
    assert s["auroc"] == pytest.approx(0.75)
    assert s["auprc"] == pytest.approx((1.0 + 2.0 / 3.0) / 2.0)


def test_a_nan_score_is_the_lowest_not_a_hidden_sample():
    tr = CaseTruth("x", "f16", "g", "test", "sensor-bias-v1", "q_radps", "", 0, ((0.2, 0.3),), 0.0, 0.3)
    t = np.array([0.0, 0.1, 0.2, 0.3])
    s = score_suite([tr], {"x": CaseOutput(t, np.zeros(4, bool), np.array([0.1, 0.4, np.nan, 0.8]))},
                    grace_s=0.0)["sample"]
    assert s["samples"] == 4 and s["auroc"] == pytest.approx(0.5)  # the NaN positive ranks below both negatives


def test_grid_holds_the_latest_output_whatever_the_methods_rate():
    tr = _truth("B", (40.0, 100.0))
    t5 = np.arange(501) / 5.0  # 5 Hz
    a5 = (t5 >= 42.0) & (t5 < 43.0)
    lab, al, _ = sample_grid(tr, CaseOutput(t5, a5))
    g = 5.0 + np.arange(951) / 10.0
    assert np.array_equal(al, (g >= 42.0 - 1e-9) & (g < 43.0 - 1e-9))
    assert lab[0] == 0 and lab[-1] == 1


def test_point_adjustment_inflates_a_random_detector_and_the_scorer_does_not():
    """Kim et al. (2022): with point adjustment a detector that alarms at random looks state of the art."""
    rng = np.random.default_rng(7)
    truths, outs, adj_tp = [], {}, [0, 0, 0]
    for i in range(20):
        tr = _truth(f"c{i}", (float(rng.uniform(20, 40)), 100.0))
        alarm = rng.random(T.size) < 0.05
        truths.append(tr)
        outs[tr.case] = CaseOutput(T, alarm, rng.random(T.size))
        lab, al, _ = sample_grid(tr, outs[tr.case])
        pa = point_adjust(lab, al)
        keep = lab >= 0
        y = lab[keep] == 1
        adj_tp[0] += int(np.sum(pa[keep] & y))
        adj_tp[1] += int(np.sum(pa[keep] & ~y))
        adj_tp[2] += int(np.sum(~pa[keep] & y))
    tp, fp, fn = adj_tp
    f1_adjusted = 2 * tp / (2 * tp + fp + fn)
    s = score_suite(truths, outs)
    assert f1_adjusted > 0.9  # every window holds an alarm sample: all its samples count as detected
    assert s["sample"]["f1"] < 0.15  # the scorer: the random detector is as bad as it is
    assert s["sample"]["auroc"] == pytest.approx(0.5, abs=0.03)
    assert s["event"]["precision"] < 0.1  # hundreds of false episodes


def test_an_alarm_always_on_detects_nothing_by_the_alfa_and_event_rules():
    truths = [_truth(f"c{i}", (30.0, 100.0)) for i in range(5)]
    s = score_suite(truths, {t.case: CaseOutput(T, np.ones(T.size, bool)) for t in truths})
    assert s["detection"]["detected"]["k"] == 5  # the first-alarm rule alone would call it perfect...
    assert s["alfa"]["tp"] == 0 and s["alfa"]["fp"] == 5  # ...ALFA's: on before every onset
    assert s["event"]["recalled"] == 0 and s["per_flight_detection"]["k"] == 0


def test_detectability_per_size_and_a_missing_case():
    truths = [_truth("s0", (30.0, 100.0), size_rank=0), _truth("s1", (30.0, 100.0), size_rank=1)]
    outs = {"s0": CaseOutput(T, _alarm()), "s1": CaseOutput(T, _alarm((31.0, 33.0)))}
    d = score_suite(truths, outs)["detectability"]["sensor-bias-v1"]
    assert d["0"]["detected"]["k"] == 0 and d["1"]["detected"]["k"] == 1
    with pytest.raises(KeyError, match="no output"):
        score_suite(truths, {"s0": outs["s0"]})


def test_exposure_takes_the_union_of_overlapping_windows():
    from fdi_sim.scoring import exposure_s

    tr = CaseTruth("i", "DHC6", "g", "test", "sensor-stuck-v1", "alpha_rad", "", 0,
                   ((30.0, 31.0), (32.0, 33.0), (60.0, 61.0)), 5.0, 100.0)
    # [30, 33] + 2 s grace -> [30, 35]; [60, 63]: 5 + 3 = 8 s covered of 95
    assert exposure_s(tr) == pytest.approx(87.0)

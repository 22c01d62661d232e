"""Study statistics: formulas pinned on constructed records, then a summary of real runs."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats as sps

from fdi_sim.flightlog import TOPIC_FDI_ALARMS, read_log
from fdi_sim.study import stats as S

from . import shared_results

DETS = ["det-a", "det-b"]


def rec(index, *, status="completed", t_end_s=600.0, faults=(), alarms=(), false_alarms=None, detections=(),
        detectors=DETS, design=0.1):
    """A record in the study runner's shape (only the keys the statistics read)."""
    alarms = [dict(detector=d, onset_t_s=a, end_t_s=b, isolation=i) for d, a, b, i in alarms]
    if false_alarms is None:  # the run's rule: onsets outside every window + grace
        ws = [(w0, min(w1, t_end_s)) for f in faults for w0, w1 in f["windows_s"]]
        false_alarms = [a for a in alarms if not S.in_fault_window(a["onset_t_s"], ws)]
    dets = []
    for label, d, t1, iso, ok in detections:
        f = next(f for f in faults if f["label"] == label)
        t0 = f["windows_s"][0][0]
        dets.append(dict(fault=label, type=f["type"], target=f["target"], detector=d, onset_t_s=t0, detected_t_s=t1,
                         delay_s=None if t1 is None else t1 - t0, isolation=iso, isolation_correct=ok))
    return dict(index=index, seed=index, status=status, reason="" if status == "completed" else "why", t_end_s=t_end_s,
                flight_h=t_end_s / 3600.0, detectors=list(detectors), design_far_per_h=design, rate_hz=20.0,
                persistence=[3, 5], arm_s=5.0, n_members=len(detectors), faults=list(faults), alarms=alarms,
                false_alarms=false_alarms, detections=dets)


def fault(label, typ, target, *windows):
    return dict(label=label, type=typ, target=target, params={}, windows_s=[list(w) for w in windows])


# --- formulas -------------------------------------------------------------------------------------------
def test_exposure_is_armed_time_outside_windows_and_grace():
    assert S.exposure_s(rec(0)) == 595.0
    r = rec(0, faults=[fault("f", "x", "q_radps", (100.0, 200.0), (150.0, 300.0))])
    assert S.exposure_s(r) == pytest.approx(595.0 - 202.0)  # union [100, 302]
    r = rec(0, faults=[fault("f", "x", "q", (590.0, 700.0)), fault("g", "x", "p", (0.0, 1.0))])
    assert S.exposure_s(r) == pytest.approx(595.0 - 10.0)  # clipped to the flight; the early one before arming
    assert S.exposure_s(r, grace_s=10.0) == pytest.approx(595.0 - 10.0 - 6.0)


def test_merge_episodes():
    al = [dict(onset_t_s=1.0, end_t_s=2.0), dict(onset_t_s=2.0, end_t_s=3.0), dict(onset_t_s=2.5, end_t_s=2.7),
          dict(onset_t_s=5.0, end_t_s=None), dict(onset_t_s=6.0, end_t_s=7.0), dict(onset_t_s=3.05, end_t_s=4.0)]
    assert S.merge_episodes(al) == [(1.0, 3.0), (3.05, 4.0), (5.0, math.inf)]


def test_rates_and_intervals_are_the_exact_ones():
    """far_per_h's interval is Garwood's (chi-square), the per-run and detection probabilities'
    Clopper-Pearson (scipy's exact binomial interval)."""
    runs = [rec(i, alarms=[("det-a", 100.0 + j, 101.0 + j, None) for j in range(i % 3)]) for i in range(9)]
    runs += [rec(9 + i, faults=[fault("f", "sensor-bias-v1", "q_radps", (300.0, 600.0))],
                 detections=[("f", "det-a", 300.5 + i if i < 5 else None, "q_radps" if i < 5 else None,
                              True if i < 5 else None), ("f", "det-b", None, None, None)]) for i in range(7)]
    s = S.summarize(runs, confidence=0.9)
    a = s["detectors"][0]
    assert a["id"] == "det-a" and a["false_alarms"] == 9 and a["runs_with_false_alarm"] == 6
    T = (9 * 595.0 + 7 * 295.0) / 3600.0  # faulty: [5, 600] minus [300, 600 + 2]
    assert a["exposure_h"] == pytest.approx(T)
    assert a["far_per_h"] == pytest.approx(9 / T)
    lo, hi = sps.chi2.ppf(0.05, 18) / 2 / T, sps.chi2.ppf(0.95, 20) / 2 / T
    assert a["far_per_h_ci"] == pytest.approx([lo, hi], rel=1e-12)
    ci = sps.binomtest(6, 16).proportion_ci(0.9, method="exact")
    assert a["p_false_alarm_per_run_ci"] == pytest.approx([ci.low, ci.high], rel=1e-9)
    ci = sps.binomtest(5, 7).proportion_ci(0.9, method="exact")
    assert (a["detected"], a["faults"]) == (5, 7) and a["p_detect_ci"] == pytest.approx([ci.low, ci.high], rel=1e-9)
    assert a["delay_s_median"] == pytest.approx(2.5) and a["delay_s_p95"] == pytest.approx(np.percentile(
        [0.5, 1.5, 2.5, 3.5, 4.5], 95))
    # zero events: lower end 0, upper end -ln(alpha)/T at one-sided alpha (Garwood)
    b = s["detectors"][1]
    assert b["false_alarms"] == 0 and b["far_per_h_ci"][0] == 0.0
    assert b["far_per_h_ci"][1] == pytest.approx(-math.log(0.05) / T)
    assert b["p_detect"] == 0.0 and b["delay_s_median"] is None
    # prediction: design over members; the bank's is the design itself
    assert a["predicted_far_per_h"] == pytest.approx(0.05) and s["bank"]["predicted_far_per_h"] == pytest.approx(0.1)
    assert a["exceeds_prediction"] is True and b["exceeds_prediction"] is False and b["prediction_in_ci"] is True
    json.dumps(s)


def test_only_completed_runs_count_and_every_status_is_counted():
    runs = [rec(0), rec(1, status="diverged", alarms=[("det-a", 50.0, None, None)]), rec(2, status="timeout"),
            rec(3, status="error", detectors=[]), rec(4, status="weird")]
    s = S.summarize(runs)
    assert s["runs"] == 5 and s["completed"] == 1
    assert s["statuses"] == {"completed": 1, "diverged": 1, "interrupted": 0, "error": 1, "timeout": 1, "weird": 1}
    assert [r["index"] for r in s["not_completed"]] == [1, 2, 3, 4]
    assert s["flight_h"] == pytest.approx(600 / 3600) and s["flight_h_all"] == pytest.approx(5 * 600 / 3600)
    assert s["detectors"][0]["false_alarms"] == 0 and s["bank"]["runs"] == 1


def test_bank_confusion_and_alfa():
    fq = fault("q", "sensor-bias-v1", "q_radps", (100.0, 600.0))
    fe = fault("e", "actuator-loss-v1", "elevator", (100.0, 600.0))
    runs = [
        # detected by both members; det-b first but without an isolation: the bank names det-a's
        rec(0, faults=[fq], alarms=[("det-a", 101.0, None, "q_radps"), ("det-b", 100.5, None, None)],
            detections=[("q", "det-a", 101.0, "q_radps", True), ("q", "det-b", 100.5, None, None)]),
        # a false alarm before the onset, then a detection: an ALFA false positive for det-a and the bank
        rec(1, faults=[fq], alarms=[("det-a", 50.0, 51.0, "p_radps"), ("det-a", 100.2, None, "theta_rad")],
            detections=[("q", "det-a", 100.2, "theta_rad", False), ("q", "det-b", None, None, None)]),
        # not detected
        rec(2, faults=[fe], detections=[("e", "det-a", None, None, None), ("e", "det-b", None, None, None)]),
        # an actuator isolated by its command: right by the run's rule
        rec(3, faults=[fe], alarms=[("det-b", 103.0, None, "elevator_cmd_norm")],
            detections=[("e", "det-a", None, None, None), ("e", "det-b", 103.0, "elevator_cmd_norm", True)]),
        # fault-free: one with two touching member alarms (one bank episode), one quiet
        rec(4, alarms=[("det-a", 200.0, 201.0, None), ("det-b", 201.0, 202.0, None)]),
        rec(5),
    ]
    s = S.summarize(runs)
    a, b, bank = s["detectors"][0], s["detectors"][1], s["bank"]
    assert a["confusion"] == {"q_radps": {"q_radps": 1, "theta_rad": 1}, "elevator": {"not detected": 2}}
    assert b["confusion"] == {"q_radps": {"not isolated": 1, "not detected": 1},
                              "elevator": {"not detected": 1, "elevator_cmd_norm": 1}}
    assert bank["confusion"] == {"q_radps": {"q_radps": 1, "theta_rad": 1},
                                 "elevator": {"not detected": 1, "elevator_cmd_norm": 1}}
    assert bank["delays_s"] == pytest.approx([0.5, 0.2, 3.0]) and bank["isolated_correctly"] == 2
    assert (a["false_alarms"], b["false_alarms"], bank["false_alarms"]) == (2, 1, 2)  # run 4: one bank episode
    assert (a["alfa"]["tp"], a["alfa"]["fp"], a["alfa"]["fn"], a["alfa"]["tn"]) == (1, 2, 2, 1)
    assert a["alfa"]["precision"] == pytest.approx(1 / 3) and a["alfa"]["recall"] == pytest.approx(1 / 3)
    assert a["alfa"]["mean_detection_time_s"] == pytest.approx(1.0)
    al = bank["alfa"]
    assert (al["tp"], al["fp"], al["fn"], al["tn"]) == (2, 2, 1, 1)
    assert al["mean_detection_time_s"] == pytest.approx((0.5 + 3.0) / 2)
    assert set(bank["by_fault_type"]) == {"sensor-bias-v1", "actuator-loss-v1"} == set(s["fault_types"])
    assert bank["by_fault_type"]["actuator-loss-v1"]["p_detect"] == 0.5
    assert a["wrong_diagnosis_analytic"] is None and "parity-stochastic-v1" in a["wrong_diagnosis_analytic_reason"]


def test_records_without_windows_or_labels():
    """A record whose faults lack windows and labels (types then come from the targets, windows
    from the detections' onsets to the end of the flight)."""
    r = rec(0, faults=[fault("q", "sensor-bias-v1", "q_radps", (100.0, 600.0))],
            detections=[("q", "det-a", 101.0, "q_radps", True), ("q", "det-b", None, None, None)])
    for f in r["faults"]:
        del f["windows_s"], f["label"]
    for d in r["detections"]:
        del d["type"]
    s = S.summarize([r])
    assert s["detectors"][0]["by_fault_type"]["sensor-bias-v1"]["detected"] == 1
    assert s["bank"]["exposure_h"] == pytest.approx(95.0 / 3600)
    assert len(s["notes"]) == 1 and "windows_s" in s["notes"][0]
    assert S.summarize([rec(0)])["notes"] == []


# --- real runs --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return shared_results(tmp_path_factory)


def test_summary_of_real_runs(study):
    out, records = study
    s = S.summarize(records)
    json.dumps(s)
    assert (s["runs"], s["completed"], s["statuses"]["completed"]) == (12, 12, 12)
    assert s["flight_h"] == pytest.approx(12 * 60.0 / 3600)
    ids = records[0]["detectors"]
    assert [d["id"] for d in s["detectors"]] == ids
    for d in s["detectors"] + [s["bank"]]:
        for key in ("id", "false_alarms", "far_per_h", "far_per_h_ci", "p_detect", "p_detect_ci", "delay_s_median",
                    "delay_s_p95", "confusion", "predicted_far_per_h", "p_false_alarm_per_run_ci", "alfa"):
            assert key in d, key
        assert d["faults"] == 6
    # every alarm the logs raised (/fdi/alarms, a source independent of the records) is in the records
    raised: dict[str, int] = {}
    for r in records:
        for e in read_log(out / "runs" / r["log"]).topics[TOPIC_FDI_ALARMS].events:
            if e.payload["alarm"] and e.payload.get("event") != "isolated":
                raised[e.payload["detector"]] = raised.get(e.payload["detector"], 0) + 1
    assert raised == {i: sum(1 for r in records for a in r["alarms"] if a["detector"] == i) for i in raised}
    # members' counts are the records' false alarms; the exposure of a fault-free run is 55 s
    for d in s["detectors"]:
        assert d["false_alarms"] == sum(1 for r in records for a in r["false_alarms"] if a["detector"] == d["id"])
        assert d["predicted_far_per_h"] == pytest.approx(records[0]["design_far_per_h"] / len(ids))
    free = S.summarize([r for r in records if not r["faults"]])
    assert free["bank"]["exposure_h"] == pytest.approx(6 * 55.0 / 3600)
    assert free["bank"]["faults"] == 0 and free["bank"]["p_detect"] is None and free["fault_types"] == []
    b = s["bank"]
    assert b["detected"] >= max(d["detected"] for d in s["detectors"])
    assert b["false_alarms"] <= sum(d["false_alarms"] for d in s["detectors"])
    assert sum(sum(row.values()) for row in b["confusion"].values()) == 6


# --- overdispersion (alarms clustered by run) ------------------------------------------------------
def _coverage(shape: float, rate_per_h: float, rng: np.random.Generator, n_studies: int = 1000
              ) -> tuple[float, float]:
    """Coverage of the plain and the dispersion-scaled 95 % interval over simulated studies of 200
    runs of 20 s whose per-run rates are gamma-distributed (mean ``rate_per_h``, shape ``shape``)."""
    from fdi_sim.study.stats import overdispersed_rate, rate

    e_h = np.full(200, 20.0 / 3600.0)
    plain = scaled = 0
    for _ in range(n_studies):
        k = rng.poisson(rng.gamma(shape, rate_per_h / shape, e_h.size) * e_h)
        _, ci = rate(int(k.sum()), float(e_h.sum()), 0.95)
        _, ci_od, _ = overdispersed_rate(k, e_h, 0.95)
        plain += ci[0] <= rate_per_h <= ci[1]
        scaled += ci_od[0] <= rate_per_h <= ci_od[1]
    return plain / n_studies, scaled / n_studies


def test_overdispersed_interval_keeps_its_coverage_when_alarms_cluster_by_run() -> None:
    """Clustered alarms (gamma-mixed Poisson, shape 0.2, 36 /h as the attitude check's half-split
    measured): the Garwood interval under-covers, the quasi-Poisson-scaled one keeps about 95 %."""
    plain, scaled = _coverage(0.2, 36.0, np.random.default_rng(2026))
    assert plain < 0.90, plain  # measured 0.855 over 2,000 studies
    assert 0.93 <= scaled <= 0.99, scaled  # measured 0.948


def test_overdispersed_interval_equals_garwood_for_poisson_counts() -> None:
    """Without clustering the dispersion is about 1 and the interval is (nearly) Garwood's; phi is
    floored at 1, so a dispersion below 1 gives exactly the plain interval."""
    from fdi_sim.study.stats import dispersion, overdispersed_rate, rate

    rng = np.random.default_rng(7)
    e_h = np.full(400, 20.0 / 3600.0)
    phis = [dispersion(rng.poisson(36.0 * e_h), e_h) for _ in range(200)]
    assert abs(float(np.mean(phis)) - 1.0) < 0.03
    k = np.zeros(400, dtype=int)
    k[::40] = 1  # evenly spread single alarms: dispersion < 1
    assert dispersion(k, e_h) < 1.0
    _, ci_od, _ = overdispersed_rate(k, e_h, 0.95)
    _, ci = rate(int(k.sum()), float(e_h.sum()), 0.95)
    assert ci_od == pytest.approx(ci, rel=1e-12)
    assert dispersion([0, 0], [1.0, 1.0]) is None and dispersion([3], [1.0]) is None


def test_rate_ratio_interval_is_the_exact_conditional_one_and_covers() -> None:
    """The rate-ratio interval is the Clopper-Pearson interval of k_b out of k_a + k_b mapped to
    the ratio (integer counts, phi 1), and it covers the true ratio of two Poisson halves at least
    95 % of the time (exact conditional intervals are conservative); with gamma-mixed per-run rates
    (shape 0.2, 40 per h) and the pooled dispersion it keeps its coverage, where phi = 1 under-covers
    (measured over 2,000 pairs: Poisson 0.976; clustered 0.973 with phi, 0.866 without)."""
    from fdi_sim.decision.intervals import clopper_pearson
    from fdi_sim.study.stats import dispersion, rate_ratio_interval

    rho, (lo, hi) = rate_ratio_interval(4, 0.5, 12, 0.25, 0.95)
    w_lo, w_hi = clopper_pearson(12, 16, 0.95)
    assert rho == pytest.approx(6.0)
    assert lo == pytest.approx(w_lo / (1 - w_lo) * 2.0, rel=1e-9) and hi == pytest.approx(w_hi / (1 - w_hi) * 2.0, rel=1e-9)
    assert rate_ratio_interval(0, 1.0, 3, 1.0, 0.95)[1][1] == math.inf
    assert rate_ratio_interval(3, 1.0, 0, 1.0, 0.95)[1][0] == 0.0
    with pytest.raises(ValueError):
        rate_ratio_interval(1, 0.0, 1, 1.0, 0.95)
    rng = np.random.default_rng(14)
    n, e = 2000, np.full(100, 20.0 / 3600.0)  # two halves of 100 runs of 20 s, 10 per h: ~5.6 alarms each
    hits = hits_mixed = hits_mixed_plain = 0
    for _ in range(n):
        ka, kb = rng.poisson(10.0 * e.sum()), rng.poisson(10.0 * e.sum())
        _, (lo, hi) = rate_ratio_interval(ka, e.sum(), kb, e.sum(), 0.95)
        hits += lo <= 1.0 <= hi
        ca = rng.poisson(rng.gamma(0.2, 40.0 / 0.2, e.size) * e)  # clustered by run, 40 per h
        cb = rng.poisson(rng.gamma(0.2, 40.0 / 0.2, e.size) * e)
        phi = dispersion(np.concatenate([ca, cb]), np.concatenate([e, e]))
        _, (lo, hi) = rate_ratio_interval(ca.sum(), e.sum(), cb.sum(), e.sum(), 0.95, phi or 1.0)
        hits_mixed += lo <= 1.0 <= hi
        _, (lo, hi) = rate_ratio_interval(ca.sum(), e.sum(), cb.sum(), e.sum(), 0.95)
        hits_mixed_plain += lo <= 1.0 <= hi
    print(f"coverage: Poisson {hits / n:.3f}, clustered with phi {hits_mixed / n:.3f}, without {hits_mixed_plain / n:.3f}")
    assert hits / n >= 0.95 - 2.6 * math.sqrt(0.05 * 0.95 / n)
    assert hits_mixed / n >= 0.95 - 2.6 * math.sqrt(0.05 * 0.95 / n) and hits_mixed_plain / n < 0.92

"""The FDI bank in the loop (issue 13) on real JSBSim flights: detection, isolation, the log,
in-loop against replay, reconfiguration, bad input."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from fdi_sim.cli import main
from fdi_sim.errors import ScenarioError
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import load, loads
from fdi_sim.scenario.loader import from_dict
from fdi_sim.training import fly
from fdi_sim.training.build import replay_log
from fdi_sim.offline.detect import replay_bank

ROOT = Path(__file__).resolve().parents[2]
#: short calibrations keep the suite fast (the shipped default is 24 x 300 s)
QUICK = {"calibration_flights": 6, "calibration_duration_s": 60.0}


def _with_bank(path: str, **fdi) -> object:
    sc = load(ROOT / "scenarios" / path)
    d = json.loads(sc.to_json())
    d["fdi"] = {"bank": "default", **QUICK, **fdi}
    return from_dict(d, source=str(ROOT / "scenarios" / path))


@pytest.fixture(scope="module")
def gyro_run(tmp_path_factory):
    sc = _with_bank("f16_pitch_gyro_bias.toml", reconfigure=False)
    return fly(sc, tmp_path_factory.mktemp("bank"), progress=False)


def test_gyro_bias_is_detected_isolated_and_logged(gyro_run):
    s = gyro_run.summary
    assert gyro_run.status == "completed"
    assert s.fdi_detectors == ("kalman-gust-v1", "kinematic-attitude-v1", "kinematic-altitude-v1",
                               "kinematic-airspeed-v1", "kinematic-flow-angles-v1")
    found = {d.detector: d for d in s.fdi_detections}
    att = found["kinematic-attitude-v1"]
    assert att.detected_t_s is not None and 0.0 < att.delay_s < 3.0 and att.isolation == "q_radps"
    assert att.isolation_correct
    assert not s.fdi_false_alarms  # nothing before the onset, nothing outside the fault
    text = s.format()
    assert "kinematic-attitude-v1" in text and "delay" in text and "false alarms: none" in text
    log = read_log(gyro_run.log_path)
    for mid in s.fdi_detectors:
        st = log.topics[f"/fdi/{mid}/statistic"]
        assert len(st.t_s) == 1200 and np.all(np.diff(st.t_s) > 0)  # 60 s at 20 Hz, samples 1 .. 1200
        assert f"/fdi/{mid}/residual" in log.topics
    alarms = log.topics["/fdi/alarms"].events
    assert alarms and all(e.t_s >= 10.0 for e in alarms)  # the fault starts at 10 s
    flog = log.topics["/fdi/failure_log"].events
    onsets = [e.payload for e in flog if e.payload["event"] == "onset"]
    assert any(p["hypothesis"] == "q_radps" and p["onset_t_s"] >= 10.0 for p in onsets)
    meta = json.loads(log.metadata["fdi"]["calibration"])
    assert all(m["threshold"] > 0 for m in meta["members"])
    # every message decodes with the mcap reader, CRCs checked
    with open(gyro_run.log_path, "rb") as f:
        n = sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages())
    assert n == sum(log.message_counts.values())


def test_replay_of_the_in_loop_bank_is_bit_identical(gyro_run):
    log = read_log(gyro_run.log_path)
    traces = replay_log(log)
    for mid, v in traces.items():
        tp = log.topics[f"/fdi/{mid}/statistic"]
        for k in ("t_s", "statistic", "threshold", "exceedance", "alarm", "valid", "isolation", "point"):
            assert np.array_equal(np.asarray(tp[k], float), np.asarray(v[k], float), equal_nan=True), (mid, k)
    rep, same = replay_bank(gyro_run.log_path)
    assert same and all(same.values())
    # the offline report and the in-loop summary give the same detection and isolation
    loop = {(d.detector, d.detected_t_s, d.isolation) for d in gyro_run.summary.fdi_detections}
    offline = {(o.id, f.first_alarm_s, f.isolated_as) for o in rep.detectors for f in o.faults}
    assert loop == offline


def test_cli_detect_replay_exit_code(gyro_run, capsys):
    assert main(["detect", str(gyro_run.log_path), "--bank", "scenario"]) == 0
    assert "identical to the log's /fdi/kalman-gust-v1/statistic" in capsys.readouterr().out


def test_monte_carlo_log_holds_only_the_fdi_topics(tmp_path):
    sc = _with_bank("f16_pitch_gyro_bias.toml", reconfigure=False)
    d = json.loads(sc.to_json())
    d["log"] = {"per_step": False}
    res = fly(from_dict(d, source="mc"), tmp_path, progress=False)
    log = read_log(res.log_path)
    assert res.summary.steps == 7201
    assert not any(t.startswith(("/truth", "/sensors", "/commands", "/surfaces")) for t in log.topics)
    assert "/fdi/kinematic-attitude-v1/statistic" in log.topics and "/sim/status" in log.topics
    full = _with_bank("f16_pitch_gyro_bias.toml", reconfigure=False)
    res_full = fly(full, tmp_path / "full", progress=False)
    a, b = read_log(res.log_path), read_log(res_full.log_path)
    for mid in res.summary.fdi_detectors:  # the log level does not change what the bank computes
        t = f"/fdi/{mid}/statistic"
        assert np.array_equal(a.topics[t]["statistic"], b.topics[t]["statistic"], equal_nan=True)


def _after(log, t0_s: float) -> tuple[float, float]:
    """Largest |dh| [ft] and |dVc| [kt] (gust removed, as the run summary) from ``t0_s`` on."""
    tr, cmd = log.topics["/truth/state"], log.topics["/commands/pilot"]
    m = tr.t_s >= t0_s
    v_air = np.sqrt(tr["v_north_fps"] ** 2 + tr["v_east_fps"] ** 2 + tr["v_down_fps"] ** 2)  # no steady wind here
    dv = np.abs(tr["vc_kts"] * v_air / tr["vt_fps"] - cmd["vc_ref_kts"])
    return float(np.max(np.abs(tr["h_ft"] - cmd["h_ref_ft"])[m])), float(np.max(dv[m]))


def test_reconfiguration_holds_the_airspeed_after_isolation(tmp_path):
    """DHC-6 pitot drift of 0.1 kt/s: with reconfiguration the bank corrects vc_kts for the pilot
    once it is isolated, and the airspeed and altitude stay within the autopilot bars (100 ft,
    5 kt) from 30 s after it; without, the airspeed leaves them."""
    runs = {}
    for rc in (True, False):
        sc = _with_bank("dhc6_airspeed_drift.toml", reconfigure=rc)
        sc = sc.replace(duration_s=300.0)
        runs[rc] = fly(sc, tmp_path / str(rc), progress=False)
    on = runs[True].summary
    assert [r["sensor"] for r in on.fdi_reconfigurations] == ["vc_kts"]
    t_rc = on.fdi_reconfigurations[0]["t_s"]
    assert not runs[False].summary.fdi_reconfigurations
    dh_on, dv_on = _after(read_log(runs[True].log_path), t_rc + 30.0)
    dh_off, dv_off = _after(read_log(runs[False].log_path), t_rc + 30.0)
    assert dh_on < 100.0 and dv_on < 5.0, (dh_on, dv_on)
    assert dv_off > 5.0, dv_off
    log = read_log(runs[True].log_path)
    ev = [e.payload for e in log.topics["/fdi/reconfiguration"].events]
    assert ev[0]["sensor"] == "vc_kts" and "kinematic-airspeed-v1" in ev[0]["confirmed_by"]


@pytest.mark.parametrize("fdi, key, words", [
    ('far_per_h = 1.5', "fdi.far_per_h", "less than 1"),
    ('far_per_s = 1e-4', "fdi.far_per_s", "did you mean 'far_per_h'"),
    ('rate_hz = 7.0', "fdi.rate_hz", "does not divide"),
    ('block_s = 0.12', "fdi.block_s", "whole number"),
    ('persistence_k = 6', "fdi", "exceeds persistence_n"),
])
def test_bad_fdi_sections(f16_text, fdi, key, words):
    with pytest.raises(ScenarioError) as e:
        loads(f16_text + f'[fdi]\nbank = "default"\n{fdi}\n')
    assert key in str(e.value) and words in str(e.value)


def test_a_decision_rule_that_needs_fault_directions(tmp_path, f16_text):
    sc = loads(f16_text + '[fdi]\nbank = "default"\ndecision = "angle-magnitude"\n')
    with pytest.raises(ScenarioError, match="fault directions"):
        fly(sc, tmp_path, progress=False)
    assert not list(tmp_path.iterdir())  # no log, and no temporary one either


def test_bank_persistence_on_white_noise_matches_its_binomial_rate():
    """The bank's k-of-n kernel on a chi-square(3) statistic of white noise: the fraction of samples
    in alarm is P(Bin(n, p) >= k) (decision.persistence, exact), within 4 standard errors of batch
    means; and splitting the input changes nothing."""
    from scipy.stats import chi2

    from fdi_sim.decision.persistence import persistence_false_alarm
    from fdi_sim.bank.kernels import decide

    rng = np.random.default_rng(8)
    N, k, n, p = 400_000, 2, 5, 0.05
    stat = rng.chisquare(3, size=N)
    thr = np.full(N, chi2.isf(p, 3))
    valid = np.ones(N, dtype=np.bool_)
    hyp = np.zeros(N, dtype=np.int64)

    def go(blocks):
        ring, st, votes = np.zeros(n, np.int64), np.array([0, 0, 0, -1, 0, 0], np.int64), np.zeros(1, np.int64)
        ex, al, iso = np.empty(N, np.bool_), np.empty(N, np.bool_), np.empty(N, np.int64)
        lead = np.empty(N, np.int64)
        i = 0
        for b in blocks:
            sl = slice(i, min(N, i + int(b)))
            decide(stat[sl], thr[sl], valid[sl], hyp[sl], k, False, ring, st, votes, ex[sl], al[sl], iso[sl],
                    lead[sl])
            i += int(b)
        return ex, al, iso

    ex, al, iso = go([N])
    expect = persistence_false_alarm(p, k, n)
    # batch means: 400 batches of 1000 samples are independent to well within the test's margin
    # (the alarm's correlation is n = 5 samples long)
    b = al.reshape(400, -1).mean(axis=1)
    assert abs(b.mean() - expect) < 4.0 * b.std(ddof=1) / np.sqrt(len(b)), (b.mean(), expect)
    assert abs(ex.mean() - p) < 4 * np.sqrt(p * (1 - p) / N)
    assert np.all(iso[al] == 0) and np.all(iso[~al] == -1)
    ex2, al2, iso2 = go(rng.integers(1, 40, size=N))
    assert np.array_equal(al, al2) and np.array_equal(iso, iso2)


def test_gain_scheduled_bank_in_the_loop_equals_its_replay(tmp_path):
    """f16_climbing_turn climbs 10 kft -> 12 kft: kalman-gust-v1 is scheduled over two points, the
    active point changes during the flight, and the replay gives the same bits."""
    sc = _with_bank("f16_climbing_turn.toml", reconfigure=False)
    res = fly(sc, tmp_path, progress=False)
    assert res.status == "completed"
    assert any("gain-scheduled over" in n for n in res.summary.fdi_notes)
    log = read_log(res.log_path)
    pts = log.topics["/fdi/kalman-gust-v1/statistic"]["point"]
    assert len(np.unique(pts)) >= 2 and np.count_nonzero(np.diff(pts)) <= 4  # switched, without chattering
    rep, same = replay_bank(res.log_path)
    assert same and all(same.values())
    # the review of the log names the same switches, and its timeline marks them (issue 15)
    from fdi_sim.review.figures import report_sections
    from fdi_sim.review.run_review import review_log

    t_stat = log.topics["/fdi/kalman-gust-v1/statistic"].t_s
    changed = np.flatnonzero(np.diff(pts)) + 1
    gust = next(d for d in review_log(res.log_path).detectors if d.id == "kalman-gust-v1")
    assert [(t, p) for t, p in gust.schedule_switches] == [(float(t_stat[j]), int(pts[j])) for j in changed]
    timeline = next(s for s in report_sections([log], [""]) if s.id == "timeline").figures[0]
    marked = [x for tr in timeline.spec["data"] if "schedule switch" in str(tr.get("name", "")) for x in tr["x"]]
    assert sorted(marked) == pytest.approx(sorted(float(t_stat[j]) for j in changed), abs=1e-3)


def test_actuator_reconfiguration_makes_up_a_lost_elevator(tmp_path):
    """DHC-6 elevator at half effectiveness from 12 s: the bank isolates the elevator, estimates its
    effectiveness (fdi_sim.detectors.effectiveness) and rescales the command. In the doublet at
    16 s the delivered deflection then matches a fault-free flight's; without reconfiguration it is
    well short of it (0.62 of it: the autopilot's feedback makes up a little by itself)."""
    def swing(rc: bool | None) -> tuple[float, object]:
        sc = _with_bank("dhc6_elevator_loss.toml", reconfigure=bool(rc))
        if rc is None:  # the fault-free reference
            d = json.loads(sc.to_json())
            d["faults"] = []
            sc = from_dict(d, source="fault-free")
        res = fly(sc, tmp_path / str(rc), progress=False)
        surf = read_log(res.log_path).topics["/truth/surfaces"]
        m = (surf.t_s >= 16.0) & (surf.t_s < 19.0)
        e = surf["elevator_pos_rad"][m]
        return float(e.max() - e.min()), res.summary

    ref, _ = swing(None)
    on, s_on = swing(True)
    off, s_off = swing(False)
    (r,) = [r for r in s_on.fdi_reconfigurations if r["action"] == "rescale-command"]
    assert r["sensor"] == "elevator_cmd_norm" and abs(r["effectiveness"] - 0.5) < 0.1 and r["t_s"] < 16.0
    assert not s_off.fdi_reconfigurations
    assert abs(on / ref - 1.0) < 0.15, (on, ref)
    assert off / ref < 0.75, (off, ref)

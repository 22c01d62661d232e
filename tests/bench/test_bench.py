"""fdi-bench: the frozen suite and its hash, benchmark runs flown for real (JSBSim on a local Dask
cluster, MCAP logs read back), resume, 1 worker = 2 workers, the export read by pyarrow, external
scores, and bad input."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from fdi_sim.bench import suite as suite_mod
from fdi_sim.bench.errors import BenchError
from fdi_sim.bench.export import HASH_KEY, read_truths, scores_file_for
from fdi_sim.bench.run import bench_bank, fly_bench, suite_study
from fdi_sim.bench.score import BANK, case_outputs, score_folder
from fdi_sim.bench.suite import FROZEN, LATEST, SPLITS, load_suite, resolve_suite
from fdi_sim.cli import main
from fdi_sim.study.execute import TIMING_KEYS, load_records

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def suite():
    return load_suite()


def test_the_suite_hash_is_the_frozen_one_and_does_not_follow_the_hash_seed(suite):
    assert suite.name == LATEST and suite.hash == FROZEN[LATEST]
    for name in FROZEN:  # every shipped version still gives its frozen hash (load_suite checks it)
        assert load_suite(name).hash == FROZEN[name]
    code = "from fdi_sim.bench.suite import load_suite; print(load_suite(check_frozen=False).hash)"
    for seed in ("0", "4242"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
        assert out.stdout.strip() == suite.hash, seed


def test_a_changed_suite_is_refused_and_an_unknown_one_gets_a_did_you_mean(monkeypatch):
    monkeypatch.setitem(suite_mod.FROZEN, "fdi-bench-v1", "0" * 64)
    with pytest.raises(BenchError, match="a suite version never changes"):
        load_suite("fdi-bench-v1")
    with pytest.raises(BenchError, match="did you mean fdi-bench-v"):
        resolve_suite("fdi-bench-v9")


def _unnamed(scenario_json: str) -> dict:
    d = json.loads(scenario_json)
    for k in ("name", "description"):  # the suite's name is in both
        d.pop(k, None)
    return d


def test_v2_holds_every_case_of_v1_unchanged(suite):
    """A result on v1 stands on v2: each v1 case is a v2 case with the same id, split and flight."""
    v1 = load_suite("fdi-bench-v1")
    by_id = {c.case: c for c in suite.cases}
    assert len(suite.cases) > len(v1.cases)
    for c in v1.cases:
        c2 = by_id[c.case]
        assert (c2.index, c2.split, c2.params) == (c.index, c.split, c.params), c.case
        assert _unnamed(c2.scenario_json) == _unnamed(c.scenario_json), c.case


def _sizeless(params: type) -> bool:
    """True when a fault's parameter model requires no magnitude: no required ``<prefix>_<unit>``
    key (``MAGNITUDES``) and no required number of its own (``effectiveness``, ``loss``, ``scale``,
    ``delay_s``, ``eta_final``...). Such a fault (frozen at onset, released, fuel cut, no samples, or
    driven to a stop whatever its rate) has no size to grade: one "size", 10 cases a group."""
    from fdi_sim.faults.params import FaultParams

    own = set(params.model_fields) - set(FaultParams.model_fields) - {"t_start_s"}
    return (not any(req for req, _ in params.MAGNITUDES.values())
            and not any(params.model_fields[n].is_required() and params.model_fields[n].annotation is float
                        for n in own))


def test_the_sizeless_fault_types_are_the_ones_that_take_no_magnitude():
    """The rule reads the catalogue; this names what it gives, so a new fault type is a decision."""
    from fdi_sim.faults.catalogue import FAULTS

    assert {t for t, (_, _, params, _) in FAULTS.items() if _sizeless(params)} == {
        "actuator-stuck-v1", "actuator-float-v1", "actuator-hard-over-v1", "engine-flameout-v1",
        "sensor-stuck-v1", "sensor-dropout-v1"}


def test_the_suite_covers_what_the_issue_asks(suite):
    from fdi_sim.faults.catalogue import FAULTS

    by_ac = Counter((c.aircraft, c.fault_type.split("-")[0] if c.fault_type else "none") for c in suite.cases)
    for ac in ("f16", "DHC6"):
        for kind in ("sensor", "actuator", "engine", "icing"):
            assert by_ac[(ac, kind)] >= 10, (ac, kind)
        ff_h = sum(c.duration_s for c in suite.cases if c.aircraft == ac and not c.fault_type and not c.negative) / 3600
        assert ff_h >= 50.0, (ac, ff_h)
        # every fault type of the catalogue on this aircraft, on several targets where it has several,
        # at three sizes or more unless it has no size
        for ftype, (_, _, params, _) in FAULTS.items():
            cs = [c for c in suite.cases if c.aircraft == ac and c.fault_type == ftype]
            assert len(cs) >= 10, (ac, ftype)
            if not ftype.startswith(("engine", "icing")) and ftype != "actuator-float-v1":
                assert len({c.target for c in cs}) >= 2, (ac, ftype)
            if not _sizeless(params):
                assert len({c.size for c in cs}) >= 3, (ac, ftype)
    phases = {c.phase for c in suite.cases}
    assert {"f16-cruise", "f16-climb", "f16-descent", "f16-turn", "dhc6-approach"} <= phases
    sized = [g for g in suite.model.groups if g.size is not None]
    assert all(len(g.size.values) >= 3 for g in sized)
    assert {c.negative for c in suite.cases} >= {"steep turns", "3-2-1-1 inputs", "severe air"}


def test_splits_hold_whole_flights_60_20_20_per_group_and_size(suite):
    ids = [c.case for c in suite.cases]
    assert len(ids) == len(set(ids))
    per = Counter((c.group, c.size_rank, c.split) for c in suite.cases)
    for g in suite.model.groups:
        for r in ({-1} if g.size is None and g.fault is None else {0} if g.size is None else set(range(len(g.size.values)))):
            n = [per[(g.name, r, s)] for s in SPLITS]
            assert sum(n) == g.runs and n[0] == round(0.6 * g.runs) and n[1] == round(0.2 * g.runs), (g.name, r, n)
    assert {c.split for c in suite.cases} == set(SPLITS)


# --- flown for real -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def flown(suite, tmp_path_factory):
    """A cruise-phase selection (no training flight: the atlas holds its designs): the flameout first,
    then the selection grown by the three gyro-bias sizes on two workers; the same four on one."""
    tmp = tmp_path_factory.mktemp("bench")
    bank = bench_bank(True)
    first = suite.select(groups=("f16-engine-flameout",), per_group=1)
    both = suite.select(groups=("f16-engine-flameout", "f16-gyro-bias"), per_group=1)
    o1 = fly_bench(suite_study(suite, bank, first), tmp / "two", workers=2, progress=False)
    rec0 = tmp / "two" / "runs" / f"{first[0].index:06d}.json"
    mtime = rec0.stat().st_mtime_ns
    st = suite_study(suite, bank, both)
    o2 = fly_bench(st, tmp / "two", workers=2, progress=False)
    o3 = fly_bench(st, tmp / "two", workers=2, progress=False)
    o4 = fly_bench(st, tmp / "one", workers=1, progress=False)
    return {"tmp": tmp, "study": st, "outcomes": (o1, o2, o3, o4), "mtime": (rec0, mtime), "cases": both}


def test_a_bench_run_grows_and_resumes_without_flying_a_case_twice(flown):
    o1, o2, o3, _ = flown["outcomes"]
    assert (o1.flown, o2.done_before, o2.flown, o3.flown) == (1, 1, 3, 0)
    rec0, mtime = flown["mtime"]
    assert rec0.stat().st_mtime_ns == mtime  # the first case was not flown again


def test_a_call_records_its_designs_and_their_wall_time(flown, tmp_path):
    """The calls log says how many designs a call needed and what they cost, so that a reader of the
    cost block tells a call whose designs flew their training flights from one served by the cache."""
    from fdi_sim.bench.cli import read_calls, record_call

    o1, o2, o3, _ = flown["outcomes"]
    assert o1.designs >= 1 and o2.designs >= 1 and 0.0 < o2.design_wall_s <= 2 * o2.wall_s  # two workers
    assert (o3.designs, o3.design_wall_s) == (0, 0.0)  # nothing left to fly: no design asked for
    for o in (o2, o3):
        record_call(tmp_path, o, 2, None)
    calls = read_calls(tmp_path)
    assert len(calls) == 1  # a call that flew nothing is not a cost
    assert calls[0]["designs"] == o2.designs and calls[0]["design_wall_s"] == round(o2.design_wall_s, 1)


def test_one_worker_gives_the_records_of_two(flown):
    a = load_records(flown["tmp"] / "two")
    b = load_records(flown["tmp"] / "one")
    assert [r["index"] for r in a] == [r["index"] for r in b] and len(a) == 4
    for ra, rb in zip(a, b):
        assert {k: v for k, v in ra.items() if k not in TIMING_KEYS} == {k: v for k, v in rb.items() if k not in TIMING_KEYS}


def test_scores_come_from_the_logs_and_match_the_records(flown):
    res = score_folder(flown["study"], flown["tmp"] / "two")
    assert res.not_scored == [] and res.departed == [] and res.cases == 4
    s = res.scored["all"]
    recs = load_records(flown["tmp"] / "two")
    # the bank's detections by the scorer equal the run records' (earliest member detection per fault)
    hit = sum(any(d["detected_t_s"] is not None for d in r["detections"]) for r in recs)
    assert s[BANK]["detection"]["detected"]["k"] == hit
    from fdi_sim.study.stats import summarize

    summ = summarize(recs)["bank"]  # the study statistics' definitions, from the records alone
    assert s[BANK]["false_alarms"] == summ["false_alarms"]
    assert s[BANK]["exposure_h"] == pytest.approx(summ["exposure_h"], rel=1e-12)
    assert s[BANK]["detection"]["delay_s_median"] == pytest.approx(summ["delay_s_median"])
    for ident in recs[0]["detectors"]:
        assert s[ident]["cases"] == 4
        k = sum(any(d["detector"] == ident and d["detected_t_s"] is not None for d in r["detections"]) for r in recs)
        assert s[ident]["detection"]["detected"]["k"] == k, ident


@pytest.fixture(scope="module")
def exported(flown):
    out = flown["tmp"] / "export"
    assert main(["export", str(flown["tmp"] / "two"), "--out", str(out), "--quiet"]) == 0
    return out


def test_the_export_is_parquet_read_by_pyarrow_with_labels_and_splits(flown, exported):
    cases = pq.read_table(exported / "cases.parquet").to_pylist()
    assert len(cases) == 4 and all(c["faulty"] for c in cases)
    assert {c["split"] for c in cases} <= set(SPLITS)
    ev = pq.read_table(exported / "events.parquet").to_pylist()
    assert {e["case"] for e in ev} == {c["case"] for c in cases}
    grid = pq.read_table(exported / "grid.f16.parquet")
    assert sorted(p.name for p in exported.glob("grid*.parquet")) == ["grid.f16.parquet"]
    assert not any(c.startswith(("truth.", "faults.")) for c in grid.column_names)  # no label leak
    lab = np.asarray(grid.column("label"))
    assert set(np.unique(lab)) <= {-1, 0, 1} and (lab == 1).any() and (lab == 0).any()
    topics = sorted(p.name for p in (exported / "topics").glob("*.parquet"))
    assert "fdi.kalman-gust-v1.statistic.parquet" in topics
    t = pq.read_table(exported / "topics" / "fdi.kalman-gust-v1.statistic.parquet")
    assert {"case", "t_s", "statistic", "alarm"} <= set(t.column_names)
    meta = json.loads((exported / "suite.json").read_text())
    assert meta["suite_hash"] == FROZEN[LATEST]


def test_external_scores_of_the_banks_own_outputs_give_the_banks_numbers(flown, exported, tmp_path, capsys):
    """The round trip a learned detector takes: outputs on the export's log clock, scored by `bench score`."""
    recs = load_records(flown["tmp"] / "two")
    meta, _truths = read_truths(exported)
    by_case = {c.index: c.case for c in flown["cases"]}
    outs = {by_case[r["index"]]: case_outputs(flown["tmp"] / "two" / "runs" / r["log"])[BANK] for r in recs}
    f = scores_file_for(outs, tmp_path / "scores.parquet", meta["suite_hash"])
    assert main(["bench", "score", "--scores", str(f), "--export", str(exported), "--split", "all", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)["scores"]
    want = score_folder(flown["study"], flown["tmp"] / "two").scored["all"][BANK]
    for k in ("false_alarms", "detection", "alfa", "event", "sample", "far_per_h"):
        if k == "detection":  # isolation: the file carries no hypotheses
            assert got[k]["detected"] == want[k]["detected"] and got[k]["delay_s_median"] == want[k]["delay_s_median"]
        else:
            assert got[k] == want[k], k


def _scores(tmp: Path, rows: dict, meta_hash: str | None) -> Path:
    t = pa.table(rows)
    if meta_hash is not None:
        t = t.replace_schema_metadata({HASH_KEY: meta_hash.encode()})
    p = tmp / "s.parquet"
    pq.write_table(t, p)
    return p


@pytest.mark.parametrize("what, match", [
    ("other-suite", "not this export's"), ("no-hash", "does not say which suite"), ("missing", "are missing"),
    ("duplicate", "duplicate timestamps"), ("outside", "outside its flight"), ("no-alarm", "scores without alarms"),
    ("unknown", "not in the export")])
def test_a_bad_scores_file_is_refused_with_the_fix(exported, tmp_path, capsys, what, match):
    meta, truths = read_truths(exported)
    names = [t.case for t in truths]
    t = np.arange(0.0, 10.0, 0.5)
    case = [n for n in names for _ in t]
    tt = np.tile(t, len(names))
    rows = {"case": case, "t_s": tt, "score": np.zeros(tt.size), "alarm": np.zeros(tt.size, np.int8)}
    h: str | None = meta["suite_hash"]
    if what == "other-suite":
        h = "f" * 64
    elif what == "no-hash":
        h = None
    elif what == "missing":
        keep = [c != names[0] for c in case]
        rows = {k: np.asarray(v, dtype=object if k == "case" else None)[keep] for k, v in rows.items()}
        rows["case"] = list(rows["case"])
    elif what == "duplicate":
        rows["t_s"] = np.where(tt == 0.5, 0.0, tt)
    elif what == "outside":
        rows["t_s"] = tt + 1000.0
    elif what == "no-alarm":
        rows.pop("alarm")
    elif what == "unknown":
        rows["case"] = ["nobody/000"] * t.size + case[t.size:]
    f = _scores(tmp_path, rows, h)
    assert main(["bench", "score", "--scores", str(f), "--export", str(exported), "--split", "all"]) == 2
    err = capsys.readouterr().err
    assert match in err and "Fix:" in err, err


def test_an_export_folder_that_cannot_be_written_is_refused(flown, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["export", str(flown["tmp"] / "two"), "--out", str(blocker / "sub"), "--quiet"]) == 2
    assert "cannot be written" in capsys.readouterr().err


def test_the_leaderboard_ranks_every_scored_method(flown, tmp_path, capsys):
    # bench.json is what `bench run` writes: made here by the CLI on the flown folder (nothing left to fly)
    assert main(["bench", "run", "--group", "f16-engine-flameout", "--group", "f16-gyro-bias", "--per-group", "1",
                 "--out", str(flown["tmp"] / "two"), "--workers", "1", "--quiet"]) == 0
    capsys.readouterr()
    out = tmp_path / "lb.md"
    assert main(["bench", "leaderboard", str(flown["tmp"] / "two"), "--out", str(out)]) == 0
    md = out.read_text()
    assert "default bank" in md and "kalman-gust-v1 (default bank)" in md and "beats ALFA" in md
    assert out.with_suffix(".html").read_text().startswith("<!doctype html>")


def test_the_air_and_ending_subsets_partition_each_aircraft(flown):
    """``air:<aircraft>:<level>`` and ``ended:<aircraft>:<how>`` split an aircraft's cases without
    overlap or gap: their cases, exposures and bank false alarms add up to the aircraft's."""
    s = score_folder(flown["study"], flown["tmp"] / "two").scored
    whole = s["aircraft:f16"][BANK]
    for prefix in ("air:f16:", "ended:f16:"):
        parts = [m[BANK] for k, m in s.items() if k.startswith(prefix)]
        assert parts, prefix
        assert sum(p["cases"] for p in parts) == whole["cases"] == 4
        assert sum(p["false_alarms"] for p in parts) == whole["false_alarms"]
        assert sum(p["exposure_h"] for p in parts) == pytest.approx(whole["exposure_h"], rel=1e-12)
    levels = {json.loads(c.params)["atmosphere.turbulence"] for c in flown["cases"]}
    assert {k.rsplit(":", 1)[1] for k in s if k.startswith("air:f16:")} == levels
    assert "ended:f16:departed" not in s  # no case departed: an empty subset is left out


def test_the_shipped_leaderboard_ranks_every_registered_detector_in_markdown_and_html():
    """Issue 27's bar: the leaderboard in docs/ (Markdown in bench.md, HTML in leaderboard.html), with
    its stamp, every built-in detector on it for each aircraft it can be designed on, and ALFA's
    numbers beside them (whether the numbers are current is tests/test_generated_docs.py's check)."""
    import html as html_mod

    from fdi_sim import registry
    from fdi_sim.stamp import read_blocks

    md = {s.id: body for s, body in read_blocks((ROOT / "docs" / "bench.md").read_text())}["leaderboard"]
    page = (ROOT / "docs" / "leaderboard.html").read_text()
    blocks = {s.id: (s, body) for s, body in read_blocks(page)}
    stamp, body = blocks["leaderboard-html"]
    assert stamp.command.startswith("python docs/make_bench_tables.py")
    text = html_mod.unescape(body)
    assert LATEST in text and "Keipour" in text and "Keipour" in md
    for det in registry.ids("detector"):
        label = {"f16": "F-16", "DHC6": "DHC-6"}
        for ac in ("f16", "DHC6"):
            if (det, ac) == ("engine-gauges-v1", "f16"):  # two engines' gauges: the F-16 has one engine
                continue
            assert f"| {det} ({label[ac]}) |" in md, (det, ac)
            assert f"<td>{det} ({label[ac]})</td>" in text, (det, ac)


def test_a_bench_cases_design_does_not_depend_on_its_length(suite):
    """Two cases of one phase at one design point must train on the same flights: the benchmark scores
    a method, not the length of the flight that it happened to be designed for."""
    from fdi_sim.training.flights import DEFAULT_TRAINING_S, fault_free

    bank = bench_bank(True)
    long_ = next(c for c in suite.cases if c.group == "f16-fault-free" and c.phase == "f16-climb")
    short = next(c for c in suite.cases if c.group == "f16-surface-loss" and c.phase == "f16-climb")
    assert long_.duration_s > DEFAULT_TRAINING_S > short.duration_s
    from fdi_sim.training.cache import scenario_parts
    from fdi_sim.training.schedule import design_scenario

    trains, keys = [], []
    for c in (long_, short):
        sc, _ = suite_study(suite, bank, [c]).run_scenario(c.index)
        assert float(sc.model.duration_s) == c.duration_s  # the flight itself is the case's
        d = design_scenario(sc)
        trains.append(json.loads(fault_free(d, 0, DEFAULT_TRAINING_S).to_json())["maneuvers"])
        keys.append(json.dumps(scenario_parts(d, DEFAULT_TRAINING_S), sort_keys=True, default=str))
    assert len(trains[0]) > len([m for m in json.loads(short.scenario_json)["maneuvers"]])  # what the cut lost
    assert trains[0] == trains[1]
    assert keys[0] == keys[1]  # one design, one cache entry (the short case reuses the long one's)


@pytest.mark.xfail(strict=True, reason="not met: the F-16 turn phase's training flights roll into and out of a 30 deg "
                   "bank at up to ~97 deg/s; those transients give the gust statistic's tail fit xi ~1.4 and its bound "
                   "extrapolates to ~5e7, ~8e4 x the largest training value, so kalman-gust-v1 detects 1 of 63 F-16 "
                   "turn faults in fdi-bench-v2 (issue 25; a maneuver gate keyed on the commanded roll, applied in "
                   "calibration and in the loop, is the proposed fix)")
def test_the_gust_member_can_hear_in_an_f16_turn(suite):
    """Issue 25's 'every phase both aircraft fly': the default bank's kalman-gust-v1 threshold at the F-16
    turn phase's design node must stay within 100 x the largest statistic of its own training flights.
    Far beyond that the member cannot alarm in turns at all. (Some F-16 cruise nodes trained with
    aileron doublets, and the multistep negatives, show the same mechanism less strongly: not tested
    here.)"""
    from fdi_sim.sim.run import build_sensors
    from fdi_sim.training.build import build_loop_bank

    c = next(c for c in suite.cases if c.group == "f16-fault-free" and c.phase == "f16-turn")
    sc, _ = suite_study(suite, bench_bank(True), [c]).run_scenario(c.index)
    b = build_loop_bank(sc, build_sensors(sc, sc.dt_s), progress=False)
    gust = next(m for m in b.calibration["members"] if m["id"] == "kalman-gust-v1")
    assert gust["threshold"] <= 100.0 * gust["max_training"], gust

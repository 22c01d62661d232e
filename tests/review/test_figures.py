"""The review report's figures (issue 15): decimation that never hides a spike, and figures built
from real short flights (their MCAP logs, read back), checked against what the logs hold."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fdi_sim.flightlog import FlightLog, read_log
from fdi_sim.review.decimate import Decimator, zoom_windows
from fdi_sim.review.figures import Figure, Section, figure_html, plotly_script_tag, report_sections
from fdi_sim.review.plotly_spec import display_unit, values
from fdi_sim.units import DEG_PER_RAD

ROOT = Path(__file__).resolve().parents[2]
GYRO = ROOT / "scenarios" / "f16_pitch_gyro_bias.toml"
ICING = """
name = "figures_dhc6_tail_icing"
aircraft = "DHC6"
duration_s = 12.0
seed = 31
[initial]
h_ft = 5000.0
vc_kts = 100.0
[[faults]]
type = "icing-v1"
target = "airframe"
region = "tail"
eta_final = 0.3
t_start_s = 2.0
ramp_s = 8.0
"""
NO_BANK = """
name = "figures_no_bank"
aircraft = "f16"
duration_s = 6.0
seed = 7
[initial]
h_ft = 10000.0
vt_kts = 400.0
[[maneuvers]]
type = "doublet-v1"
axis = "elevator"
t_start_s = 2.0
amplitude_norm = 0.1
pulse_s = 1.0
"""


# --- decimation ----------------------------------------------------------------------------------
def _signal(n: int = 72_000, rate_hz: float = 120.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    return t, np.sin(0.3 * t) + 0.1 * rng.standard_normal(n)


def test_a_single_sample_spike_survives() -> None:
    t, y = _signal()
    y[41_234] = 25.0
    y[7_001] = -25.0
    d = Decimator(0.0, t[-1], (), 4000)(t, y)
    assert len(d) <= 4000
    assert 41_234 in d.index and 7_001 in d.index
    assert d.y.max() == 25.0 and d.y.min() == -25.0


def test_every_bucket_keeps_its_first_min_max_last_in_time_order() -> None:
    t, y = _signal(seed=1)
    cap = 2000
    dec = Decimator(0.0, t[-1], (), cap)
    d = dec(t, y)
    assert np.all(np.diff(d.index) > 0)  # time order
    n_buckets = cap // 4
    bucket = np.clip((t / t[-1] * n_buckets).astype(int), 0, n_buckets - 1)
    kept_bucket = bucket[d.index]
    for b in range(n_buckets):  # the test's own bucket walk, to check the vectorised one
        orig = np.flatnonzero(bucket == b)
        mine = d.index[kept_bucket == b]
        assert orig[0] in mine and orig[-1] in mine
        assert y[mine].max() == y[orig].max() and y[mine].min() == y[orig].min()
        assert len(mine) <= 4


def test_the_cap_holds_outside_windows_and_windows_keep_every_sample() -> None:
    t, y = _signal(seed=2)
    windows = zoom_windows([100.0, 103.0, 400.0])  # the first two merge
    assert windows == ((98.0, 108.0), (398.0, 405.0))
    for cap in (15, 100, 1000, 4000):  # the cap holds from 5 x (windows + 1) points
        dec = Decimator(0.0, t[-1], windows, cap)
        d = dec(t, y)
        inside = ((t >= 98.0) & (t <= 108.0)) | ((t >= 398.0) & (t <= 405.0))
        assert set(np.flatnonzero(inside)) <= set(d.index.tolist())
        assert np.count_nonzero(~inside[d.index]) <= cap, cap


def test_nan_gaps_stay_gaps() -> None:
    t, y = _signal(seed=3)
    y[30_000:30_500] = np.nan  # a 4 s gap
    y[50_000] = np.nan  # a single missing sample
    d = Decimator(0.0, t[-1], (), 1000)(t, y)
    kept_nan = d.index[np.isnan(d.y)]
    assert np.any((kept_nan >= 30_000) & (kept_nan < 30_500)) and 50_000 in kept_nan
    # no line is drawn across the gap: between the last sample before it and the first after it
    # a NaN is kept
    before = d.index[d.index < 30_000].max()
    after = d.index[d.index >= 30_500].min()
    between = d.y[(d.index > before) & (d.index < after)]
    assert between.size and np.all(np.isnan(between))
    assert np.nanmax(d.y) == np.nanmax(y) and np.nanmin(d.y) == np.nanmin(y)
    all_nan = Decimator(0.0, t[-1], (), 100)(t, np.full(t.size, np.nan))
    assert len(all_nan) > 0 and np.all(np.isnan(all_nan.y))


def test_short_signals_are_kept_whole() -> None:
    dec = Decimator(0.0, 10.0, zoom_windows([5.0]), 4000)
    for n in (0, 1, 2, 3999):
        t = np.linspace(0.0, 10.0, n)
        d = dec(t, np.cos(t))
        assert d.index.tolist() == list(range(n))
    with pytest.raises(ValueError, match="one value per time"):
        dec(np.zeros(3), np.zeros(4))


def test_traces_of_a_figure_share_their_bucket_edges() -> None:
    """Two signals on one time base, decimated by one Decimator, keep the same first and last
    sample of every bucket: most of their kept times coincide."""
    t, y1 = _signal(seed=4)
    _, y2 = _signal(seed=5)
    dec = Decimator(0.0, t[-1], (), 4000)
    a, b = dec(t, y1), dec(t, 3.0 * y2 + 1.0)
    shared = np.intersect1d(a.t_s, b.t_s)
    assert shared.size >= 2 * (4000 // 4) - 1


def test_decimation_cost_of_a_ten_minute_signal() -> None:
    """72,000 samples in well under a frame of a second: vectorised (about 5 ms on this machine)."""
    import time

    t, y = _signal(seed=6)
    dec = Decimator(0.0, t[-1], zoom_windows([10.0, 200.0]), 4000)
    dec(t, y)
    t0 = time.perf_counter()
    for _ in range(5):
        dec(t, y)
    assert (time.perf_counter() - t0) / 5 < 0.05


def test_values_round_to_six_digits_and_nan_is_null() -> None:
    out = values(np.array([1.23456789, -98765.4321, 3.3e-7, 0.0, np.nan, np.inf, 123456789.0]))
    assert out == [1.23457, -98765.4, 3.3e-07, 0.0, None, None, 123457000.0]
    assert json.dumps(out) == "[1.23457, -98765.4, 3.3e-07, 0.0, null, null, 123457000.0]"
    assert display_unit("alpha_rad") == ("alpha", "deg", DEG_PER_RAD)
    assert display_unit("q_radps")[1] == "deg/s" and display_unit("icing_eta")[1] == "-"


# --- figures from real flights --------------------------------------------------------------------
def _fly(text: str, path: Path) -> Path:
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly

    fly(loads(text), path.parent, log_path=path, progress=False, force=True)
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, FlightLog]:
    """Real logs: a 20 s pitch-gyro bias with the bank (fault at 10 s), the same without
    reconfiguration (the comparison), a 6 s F-16 without a bank, 12 s of DHC-6 tail icing without
    a bank (eta 0 -> 0.3 from 2 s to 10 s)."""
    d = tmp_path_factory.mktemp("figures")
    gyro = (GYRO.read_text().replace("duration_s = 60.0", "duration_s = 20.0")
            .replace("t_start_s = 30.0", "t_start_s = 16.0"))  # the rudder doublet inside 20 s
    return {
        "gyro": read_log(_fly(gyro, d / "gyro.mcap")),
        "gyro_b": read_log(_fly(gyro.replace('bank = "default"', 'bank = "default"\nreconfigure = false'),
                                d / "gyro_b.mcap")),
        "no_bank": read_log(_fly(NO_BANK, d / "no_bank.mcap")),
        "icing": read_log(_fly(ICING, d / "icing.mcap")),
    }


def _figures(sections: tuple[Section, ...]) -> list[Figure]:
    return [f for s in sections for f in s.figures]


def _fig(sections: tuple[Section, ...], fig_id: str) -> Figure:
    return next(f for f in _figures(sections) if f.id == fig_id)


def _trace(fig: Figure, name: str) -> dict[str, Any]:
    return next(tr for tr in fig.spec["data"] if tr["name"] == name)


def test_sections_in_order_and_every_spec_is_json(logs: dict[str, FlightLog]) -> None:
    for key, log in logs.items():
        sections = report_sections([log], [key])
        ids = [s.id for s in sections]
        assert ids[0] == "timeline" and "flight" in ids
        dets = [s for s in sections if s.detector]
        assert ids[1:1 + len(dets)] == [s.id for s in dets]  # detectors follow the timeline
        fig_ids = [f.id for f in _figures(sections)]
        assert len(fig_ids) == len(set(fig_ids)), fig_ids
        for f in _figures(sections):
            text = json.dumps(f.spec, allow_nan=False)  # NaN would raise: they are null
            assert {tr["type"] for tr in f.spec["data"]} <= {"scatter"}, f.id
            assert "mathjax" not in text.lower() and "http" not in text, f.id
            html = figure_html(f)
            assert html.startswith(f'<div id="{f.id}" class="fdi-figure">') and "Plotly.newPlot(" in html
            assert '"displaylogo":false' in html and '"responsive":true' in html
            lay = f.spec["layout"]
            for k, ax in lay.items():
                if k.startswith("yaxis") and ax.get("type") != "category":
                    assert "[" in ax["title"]["text"], (f.id, k, ax["title"])  # a unit on every axis
            last_x = [ax for k, ax in lay.items() if k.startswith("xaxis") and "title" in ax]
            assert [ax["title"]["text"] for ax in last_x] == ["t [s]"], f.id
            assert all(ax.get("matches") == "x" for k, ax in lay.items() if k.startswith("xaxis") and k != "xaxis")
    tag = plotly_script_tag()
    assert tag.startswith("<script>") and tag.endswith("</script>") and len(tag) > 1_000_000
    assert tag.count("</script>") == 1


def test_the_fault_band_spans_exactly_the_catalog_window(logs: dict[str, FlightLog]) -> None:
    from fdi_sim.offline.detect import fault_windows

    catalog = fault_windows(logs["gyro"])
    assert [f["windows_s"] for f in catalog] == [[[10.0, 21.0]]]
    sections = report_sections([logs["gyro"]], ["gyro"])
    for f in _figures(sections):
        bands = [s for s in f.spec["layout"]["shapes"] if s.get("name") == "fault q_radps_bias"]
        assert [(b["x0"], b["x1"]) for b in bands] == [(10.0, 21.0)], f.id
        assert f.spec["layout"]["xaxis"]["range"] == [logs["gyro"].start_t_s, logs["gyro"].end_t_s]


def test_statistic_threshold_and_alarms_are_the_logged_ones(logs: dict[str, FlightLog]) -> None:
    from fdi_sim.decision.outcome import first_alarm

    log = logs["gyro"]
    sections = report_sections([log], ["gyro"])
    assert [s.detector for s in sections if s.detector] == [
        k.split("/")[2] for k in log.topics if k.startswith("/fdi/") and k.endswith("/statistic")]
    for det in (s.detector for s in sections if s.detector):
        st = log.topics[f"/fdi/{det}/statistic"]
        fig = _fig(sections, f"fig-det-{det}-statistic")
        thr = _trace(fig, "threshold")
        idx = np.searchsorted(np.round(st.t_s, 3), thr["x"])
        np.testing.assert_allclose(thr["y"], st["threshold"][idx], rtol=1e-5)
        stat = _trace(fig, "statistic")
        idx = np.searchsorted(np.round(st.t_s, 3), stat["x"])
        invalid = st["valid"][idx] < 0.5
        assert invalid.any() and all(stat["y"][i] is None for i in np.flatnonzero(invalid))  # valid gaps
        shown = np.array([np.nan if v is None else v for v in stat["y"]])
        ok = (st["valid"] > 0.5) & np.isfinite(st["statistic"])
        assert np.nanmax(shown) == pytest.approx(st["statistic"][ok].max(), rel=1e-5)  # the peak survives
        # the detection in the caption is the log's first alarm after onset (the sim's own rule)
        hyp = next(m["hypotheses"] for m in json.loads(log.metadata["fdi"]["members"]) if m["id"] == det)
        iso = [None if k < 0 else hyp[int(k)] for k in st["isolation"]]
        t1, name = first_alarm(st.t_s, st["alarm"] > 0.5, iso, 10.0)
        if t1 is None:
            assert "not detected" in fig.caption
        else:
            assert f"detected at {t1:.2f} s, delay {t1 - 10.0:.2f} s, isolated as {name or 'rejected'}" in fig.caption
            notes = [a for a in fig.spec["layout"]["annotations"] if a["text"].startswith("delay")]
            assert [(a["x"], a["text"]) for a in notes] == [(round(t1, 3), f"delay {t1 - 10.0:.2f} s")]
        onsets = [tr for tr in fig.spec["data"] if tr["name"] == "alarm onset"]
        a = st["alarm"] > 0.5
        rising = st.t_s[np.flatnonzero(a & ~np.concatenate(([False], a[:-1])))]
        assert (onsets[0]["x"] if onsets else []) == np.round(rising, 3).tolist()
    timeline = _fig(sections, "fig-timeline")
    rec = _trace(timeline, "reconfiguration")
    assert rec["x"] == [round(e.t_s, 3) for e in log.topics["/fdi/reconfiguration"].events]


def test_flight_and_sensor_figures_show_degrees_and_the_fault(logs: dict[str, FlightLog]) -> None:
    log = logs["gyro"]
    sections = report_sections([log], ["gyro"])
    att = _fig(sections, "fig-flight-attitude")
    theta = _trace(att, "theta [deg]")
    truth = log.topics["/truth/state"]
    idx = np.searchsorted(np.round(truth.t_s, 3), theta["x"])
    np.testing.assert_allclose(theta["y"], truth["theta_rad"][idx] * DEG_PER_RAD, rtol=1e-5, atol=1e-9)
    sensor = _fig(sections, "fig-sensor-q_radps")
    err = _trace(sensor, "q measured - truth")
    x, y = np.array(err["x"]), np.array(err["y"], dtype=float)
    # the +0.5 deg/s bias from 10 s, in the error trace (noise averages out)
    assert np.mean(y[x > 11.0]) - np.mean(y[x < 9.0]) == pytest.approx(0.5, abs=0.05)
    assert not any(s.id == "sensors" for s in report_sections([logs["icing"]], ["icing"]))


def test_a_comparison_overlays_both_runs(logs: dict[str, FlightLog]) -> None:
    a, b = logs["gyro"], logs["gyro_b"]
    sections = report_sections([a, b], ["A", "B"])
    single = report_sections([a], ["A"])
    assert [s.id for s in sections] == [s.id for s in single]
    assert [f.id for f in _figures(sections)] == [f.id for f in _figures(single)]
    for f in _figures(sections):
        names = [tr["name"] for tr in f.spec["data"]]
        assert any(n.startswith("A: ") for n in names) and any(n.startswith("B: ") for n in names), f.id
        col = {run: {tr["line"]["color"] if tr["mode"] == "lines" else tr["marker"]["color"]
                     for tr in f.spec["data"] if tr["name"].startswith(run + ": ")} for run in "AB"}
        assert not col["A"] & col["B"], f.id  # one colour family per run
        axes = {(tr["xaxis"], tr["yaxis"]) for tr in f.spec["data"] if tr["name"].startswith("B: ")}
        assert axes <= {(tr["xaxis"], tr["yaxis"]) for tr in f.spec["data"] if tr["name"].startswith("A: ")}, f.id
    # only run A reconfigured: its marker is there, B's is not
    names = [tr["name"] for tr in _fig(sections, "fig-timeline").spec["data"]]
    assert "A: reconfiguration" in names and "B: reconfiguration" not in names
    # the same statistic panel holds both runs' statistics
    fig = _fig(sections, "fig-det-kalman-gust-v1-statistic")
    assert _trace(fig, "A: statistic")["yaxis"] == _trace(fig, "B: statistic")["yaxis"] == "y"
    # a run without a bank adds no detector sections but the union keeps the other's
    mixed = report_sections([a, logs["no_bank"]], ["A", "N"])
    assert [s.detector for s in mixed if s.detector] == [s.detector for s in single if s.detector]
    with pytest.raises(ValueError, match="one label per log"):
        report_sections([a, b], ["A"])


def test_a_log_without_a_bank_has_no_detector_sections(logs: dict[str, FlightLog]) -> None:
    sections = report_sections([logs["no_bank"]], ["n"])
    assert [s.id for s in sections] == ["timeline", "flight"]
    assert all(s.detector is None for s in sections)
    text = json.dumps([f.spec for f in _figures(sections)])
    assert "alarm" not in text and "statistic" not in text
    # nothing to draw on the timeline: the figure is left out and the section says why
    assert sections[0].figures == () and len(sections[0].notes) == 1
    assert "No fault was injected and no detector ran" in sections[0].notes[0]


def test_icing_eta_shows_on_the_timeline(logs: dict[str, FlightLog]) -> None:
    log = logs["icing"]
    sections = report_sections([log], ["icing"])
    tl = _fig(sections, "fig-timeline")
    eta = _trace(tl, "icing eta")
    assert eta["yaxis"] == "y2" and max(eta["y"]) == pytest.approx(float(np.max(
        log.topics["/truth/operating_point"]["icing_eta"])), rel=1e-5)
    assert max(eta["y"]) > 0.2
    band = [s for s in tl.spec["layout"]["shapes"] if s["type"] == "rect"]
    assert [(s["x0"], s["x1"]) for s in band] == [tuple(w) for f in json.loads(log.metadata["faults"]["catalog"])
                                                  for w in f["windows_s"]]

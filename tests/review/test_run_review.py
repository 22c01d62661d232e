"""``fdi-sim review LOG``: the review of one run from its MCAP log, on real flights.

The logs come from ``review_logs`` (conftest.py): real JSBSim flights with the bank in the loop,
a fault-free one, one without a bank, a SIGKILLed one (cut off, and repaired), a diverged and an
interrupted one.
"""
from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pytest

from fdi_sim.cli import main
from fdi_sim.decision.intervals import poisson_rate_interval
from fdi_sim.errors import LogError, ReviewError
from fdi_sim.flightlog import read_log
from fdi_sim.review.html_report import default_report_path, write_report
from fdi_sim.review.run_review import open_log, review_log
from fdi_sim.units import S_PER_H

ROOT = Path(__file__).resolve().parents[2]


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_numbers_equal_the_live_run_summary(tmp_path: Path) -> None:
    """The review's detections, alarm episodes and false alarms are the live run summary's, from
    the log alone (a real 20 s F-16 flight with the bank in the loop)."""
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly

    text = (ROOT / "scenarios" / "f16_pitch_gyro_bias.toml").read_text()
    sc, _ = loads(text.replace("seed = 12", "seed = 5")).shortened(20.0)
    res = fly(sc, tmp_path, progress=False)
    s = res.summary
    rev = review_log(res.log_path)
    assert rev.status == s.status == "completed"
    assert rev.t_end_s == pytest.approx(s.t_end_s)
    assert rev.bank == s.fdi_detectors
    mine = sorted((d for r in rev.detectors for d in r.detections), key=lambda d: (d.fault, d.detector))
    live = sorted(s.fdi_detections, key=lambda d: (d.fault, d.detector))
    assert mine == live and any(d.detected_t_s is not None for d in live)
    episodes = sorted((e.detector, e.onset_t_s, e.end_t_s, e.isolation) for r in rev.detectors for e in r.episodes)
    assert episodes == sorted((a.detector, a.onset_t_s, a.end_t_s, a.isolation) for a in s.fdi_alarms)
    false = sorted((e.detector, e.onset_t_s) for r in rev.detectors for e in r.episodes if e.false)
    assert false == sorted((a.detector, a.onset_t_s) for a in s.fdi_false_alarms)
    assert [r.t_s for r in rev.reconfigurations] == [float(e["t_s"]) for e in s.fdi_reconfigurations]
    # the terminal summary names every detection the live summary printed
    out = rev.format()
    for d in live:
        if d.detected_t_s is not None:
            assert f"{d.fault}: detected at {d.detected_t_s:.2f} s (delay {d.delay_s:.2f} s)" in out


def test_fault_run_review(review_logs: dict[str, Path]) -> None:
    """Faults with their true intervals, the failure log and reconfigurations as the log holds them."""
    path = review_logs["fault"]
    rev = review_log(path)
    log = read_log(path)
    assert (rev.aircraft, rev.scenario, rev.seed, rev.rate_hz) == ("f16", "f16_pitch_gyro_bias", 12, 120.0)
    assert rev.ending.startswith("completed at t = 30.00 s")
    [f] = rev.faults
    assert (f.label, f.target, f.windows_s[0][0]) == ("q_radps_bias", "q_radps", 10.0)
    assert len(rev.failure_log) == len(log.topics["/fdi/failure_log"].events) > 0
    assert [(r.t_s, r.sensor) for r in rev.reconfigurations] == [
        (e.t_s, e.payload["sensor"]) for e in log.topics["/fdi/reconfiguration"].events]
    first = rev.first_detection()
    assert first is not None and first.delay_s == pytest.approx(first.detected_t_s - 10.0)
    # design rate from the [fdi] table, split evenly over the members
    design = json.loads(log.metadata["scenario"]["json"])["fdi"]["far_per_h"]
    assert rev.design_far_per_h == design
    assert all(d.design_far_per_h == pytest.approx(design / len(rev.bank)) for d in rev.detectors)


def test_fault_free_rate_and_interval(review_logs: dict[str, Path]) -> None:
    """Fault-free: exposure is the armed time, the interval is Garwood's for the count."""
    rev = review_log(review_logs["fault_free"])
    arm_s = json.loads(read_log(review_logs["fault_free"]).metadata["scenario"]["json"])["fdi"]["arm_s"]
    assert rev.faults == ()
    assert rev.bank_exposure_h == pytest.approx((rev.t_end_s - arm_s) / S_PER_H)
    for d in rev.detectors:
        assert d.false_alarms == len(d.episodes)  # no fault window: every episode is false
        assert d.far_ci_per_h == pytest.approx(poisson_rate_interval(d.false_alarms, d.exposure_h, 0.95))
    assert "faults        none injected" in rev.format() or "none injected" in rev.format()


def test_endings_in_words(review_logs: dict[str, Path]) -> None:
    """Diverged, interrupted and crashed-then-repaired logs review, and say what happened."""
    div = review_log(review_logs["diverged"])
    assert div.status == "diverged"
    assert re.fullmatch(rf"diverged at t = {div.t_end_s:.2f} s: .+", div.ending), div.ending
    assert div.reason and div.reason in div.format()
    assert "no FDI bank in this log" in div.format()
    intr = review_log(review_logs["interrupted"])
    assert intr.status == "interrupted" and "wall-clock limit" in intr.ending
    rep = review_log(review_logs["repaired"])
    assert rep.status == "cut off"
    t_last = float(read_log(review_logs["repaired"]).topics["/truth/state"].t_s[-1])
    assert rep.ending == (f"ended without a final status record at t = {t_last:.2f} s: the process died "
                          "(log repaired)")


def test_cut_off_log_reviews_from_a_temporary_copy(review_logs: dict[str, Path]) -> None:
    """The unrepaired file is left untouched (bytes and folder) and the review says so."""
    path = review_logs["unrepaired"]
    before, listing = _sha(path), sorted(p.name for p in path.parent.iterdir())
    with pytest.raises(LogError, match="fdi-sim repair"):
        read_log(path)
    rev = review_log(path)
    assert _sha(path) == before and sorted(p.name for p in path.parent.iterdir()) == listing
    assert rev.read_path != rev.path and any("temporary copy" in n for n in rev.notes)
    assert rev.status == "cut off" and "the process died" in rev.ending
    assert rev.t_end_s == pytest.approx(review_log(review_logs["repaired"]).t_end_s)


def test_no_bank(review_logs: dict[str, Path]) -> None:
    rev = review_log(review_logs["no_bank"])
    assert rev.bank == () and rev.detectors == ()
    assert ("FDI", "no FDI bank in this log") in rev.headline()


def test_report_page(review_logs: dict[str, Path], tmp_path: Path) -> None:
    """One self-contained page: metas, every listed figure has its div, the headline comes first,
    nothing is loaded from the network."""
    path = review_logs["fault"]
    log, notes = open_log(path)
    rev = review_log(path)
    out = write_report([rev], [log], tmp_path / "page.html")
    page = out.read_text()
    assert '<meta name="fdi-sim-review" content="1">' in page
    ids = re.search(r'<meta name="fdi-sim-figures" content="([^"]*)">', page).group(1).split()
    assert ids and len(ids) == len(set(ids))
    for i in ids:
        assert page.count(f'<div id="{i}" class="fdi-figure">') == 1
    assert page.index('id="headline"') < page.index('class="fdi-figure"')
    # no external resource: scripts inline only; outside them no src/href to a URL, no <link>,
    # no @import, no url(http...) (plotly.js itself holds URL strings it never fetches at load)
    assert not re.search(r"<script[^>]*\bsrc\s*=", page)
    markup = re.sub(r"<script>.*?</script>", "", page, flags=re.S)
    assert not re.search(r'(src|href)\s*=\s*["\']?(https?:)?//', markup)
    assert "<link" not in markup and "@import" not in markup and not re.search(r"url\(\s*['\"]?https?:", markup)
    # the headline table holds the delay and isolation of the first detection
    d = rev.first_detection()
    head = page[page.index('id="headline"'):page.index("</section>", page.index('id="headline"'))]
    assert f"{d.delay_s:.2f} s" in head and d.isolation in head
    for row in rev.failure_log:
        assert f"<td>{row.t_s:.2f}</td><td>{row.event}</td><td>{row.detector}</td>" in page


def test_cli_review_writes_next_to_the_log(review_logs: dict[str, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Default path <stem>.review.html next to the log, the summary and timing printed; --json parses;
    --out to a folder puts the default name inside."""
    src = review_logs["interrupted"]
    log = tmp_path / src.name
    log.write_bytes(src.read_bytes())
    assert main(["review", str(log)]) == 0
    out = capsys.readouterr().out
    page = default_report_path([log])
    assert page == tmp_path / "interrupted.review.html" and page.is_file()
    assert "interrupted at t = " in out and f"report       {page}" in out
    assert re.search(r"took +[\d.]+ s \(read [\d.]+, metrics [\d.]+, figures [\d.]+, write [\d.]+\)", out)
    (tmp_path / "sub").mkdir()
    assert main(["review", str(log), "--json", "--out", str(tmp_path / "sub")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "interrupted" and Path(doc["report"]) == tmp_path / "sub" / page.name
    assert (tmp_path / "sub" / page.name).is_file()
    assert main(["review", str(log), "--quiet", "--out", str(tmp_path / "new" / "deeper" / "r.html")]) == 0
    assert (tmp_path / "new" / "deeper" / "r.html").is_file()
    assert "interrupted at" not in capsys.readouterr().out  # --quiet: the path and the time only


def _other_tool_mcap(path: Path) -> Path:
    from mcap.writer import Writer

    with path.open("wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="some-other-tool")
        sid = w.register_schema("Temp", "jsonschema", b'{"type":"object"}')
        cid = w.register_channel("/temperature", "json", sid)
        for k in range(5):
            w.add_message(cid, k * 10**9, b'{"c": 20.5}', k * 10**9)
        w.finish()
    return path


@pytest.mark.parametrize("case", ["text", "other_tool", "folder_is_file", "missing"])
def test_cli_bad_input(case: str, review_logs: dict[str, Path], tmp_path: Path,
                       capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 2, one paragraph naming the file and what is wrong, no traceback; nothing written."""
    args, expect = {
        "text": lambda: ([str(_write(tmp_path / "notes.mcap", "hello"))], "not an MCAP file"),
        "other_tool": lambda: ([str(_other_tool_mcap(tmp_path / "other.mcap"))],
                               "no `scenario` metadata and no /truth/state topic: not an fdi-sim log"),
        "folder_is_file": lambda: ([str(review_logs["no_bank"]), "--out",
                                    str(_write(tmp_path / "afile", "x") / "report.html")],
                                   "cannot create the report's folder"),
        "missing": lambda: ([str(tmp_path / "nope.mcap")], "missing"),
    }[case]()
    assert main(["review", *args]) == 2
    cap = capsys.readouterr()
    assert cap.err.startswith("fdi-sim review: ") and expect in cap.err, cap.err
    assert "Traceback" not in cap.err and cap.err.count("\n") == 1
    assert not list(tmp_path.glob("*.html"))


def _write(p: Path, text: str) -> Path:
    p.write_text(text)
    return p


def test_review_error_is_a_value_error() -> None:
    assert issubclass(ReviewError, ValueError)
    e = ReviewError("x.mcap", "what", "fix it")
    assert str(e) == "x.mcap: what. Fix: fix it"


def test_cli_open_hands_a_file_url_to_the_browser(review_logs: dict[str, Path], tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """``--open``: the standard ``webbrowser`` module gets the page's file:// URL ($BROWSER is a
    real program here that records what it was given)."""
    import os
    import time
    import webbrowser

    got = tmp_path / "url.txt"
    prog = tmp_path / "browser.sh"
    prog.write_text(f'#!/bin/sh\nprintf "%s" "$1" > "{got}"\n')
    prog.chmod(0o755)
    monkeypatch.setenv("BROWSER", str(prog))
    monkeypatch.setattr(webbrowser, "_tryorder", None)
    monkeypatch.setattr(webbrowser, "_browsers", {})
    out = tmp_path / "r.html"
    assert main(["review", str(review_logs["no_bank"]), "--quiet", "--open", "--out", str(out)]) == 0
    deadline = time.time() + 20
    while time.time() < deadline and not (got.exists() and got.stat().st_size):
        time.sleep(0.05)
    assert got.read_text() == out.resolve().as_uri() and os.path.isfile(out)


def test_a_log_cut_before_its_fault_began_says_the_fault_never_started(review_logs: dict[str, Path],
                                                                        tmp_path: Path) -> None:
    """A deterministic cut (the SIGKILL fixture's time depends on load): the first fifth of the bank
    fault run's bytes, repaired, ends before the 10 s onset. The headline says the fault never
    started (not "NOT detected"), and the timeline draws no fault bar outside the log."""
    from fdi_sim.flightlog import repair_log
    from fdi_sim.review.figures import report_sections

    src = review_logs["fault"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(src[: len(src) // 5])
    fixed = tmp_path / "cut.repaired.mcap"
    repair_log(cut, fixed)
    r = review_log(fixed)
    assert 2.0 < r.t_end_s < 10.0, r.t_end_s
    rows = dict(r.headline())
    assert rows["fault q_radps_bias"] == (f"never started: scheduled from 10.00 s, after the log ends at "
                                          f"{r.t_end_s:.2f} s")
    for s in report_sections([read_log(fixed)], [""]):
        for f in s.figures:
            for tr in f.spec["data"]:
                xs = [x for x in tr.get("x") or [] if isinstance(x, (int, float))]
                assert not xs or max(xs) <= r.t_end_s + 1e-3, (f.id, tr.get("name"), max(xs))

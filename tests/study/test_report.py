"""The study report on real runs: one self-contained page, headline first, figures embedded and saved."""
from __future__ import annotations

import base64
import json
import re
import time
from html.parser import HTMLParser

import numpy as np
import pytest

from fdi_sim.study import report as P
from fdi_sim.study.rescore import rescore
from fdi_sim.study.stats import summarize

from . import shared_results

FIGURES = ("roc.png", "far_vs_threshold.png", "delays.png", "confusion.png")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out, records = shared_results(tmp_path_factory)
    return out, records, summarize(records), rescore(records, out, np.geomspace(0.2, 5.0, 20))


class Tags(HTMLParser):
    """Open/close balance of the block tags, and every src/href."""

    BLOCK = ("table", "tr", "td", "th", "ul", "li", "div", "figure", "figcaption", "code", "b", "span", "h1", "h2", "p")

    def __init__(self) -> None:
        super().__init__()
        self.depth: dict[str, int] = {}
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag in self.BLOCK:
            self.depth[tag] = self.depth.get(tag, 0) + 1
        self.links += [v for k, v in attrs if k in ("src", "href")]

    def handle_endtag(self, tag):
        if tag in self.BLOCK:
            self.depth[tag] = self.depth.get(tag, 0) - 1
            assert self.depth[tag] >= 0, f"</{tag}> without <{tag}>"


def parse(text: str) -> Tags:
    t = Tags()
    t.feed(text)
    t.close()
    return t


def test_report_of_real_runs(study, tmp_path):
    out, records, summary, rs = study
    t0 = time.perf_counter()
    page = P.write_report(out / "report", records, summary, rs)
    wall = time.perf_counter() - t0
    assert wall < 30.0
    assert page == out / "report" / "index.html"
    text = page.read_text()
    tags = parse(text)
    assert all(v == 0 for v in tags.depth.values()), tags.depth
    # self-contained: every image is embedded, and is the PNG saved beside the page
    assert tags.links and all(u.startswith("data:image/png;base64,") for u in tags.links)
    embedded = [base64.b64decode(u.split(",", 1)[1]) for u in tags.links]
    saved = [(out / "report" / f).read_bytes() for f in FIGURES]
    assert embedded == saved and all(b[:8] == b"\x89PNG\r\n\x1a\n" for b in saved)
    # the headline numbers come first: before any table or figure
    head = text.index('class="headline"')
    assert head < text.index("<table") < text.index("<img")
    headline = text[head:text.index("</div>", head)]
    b = summary["bank"]
    assert P._f(b["far_per_h"]) in headline and P._ci(b["far_per_h_ci"]) in headline
    assert f"{b['false_alarms']}</b>" in headline and "design 0.9 /h" in headline  # tests/study BASE far_per_h
    assert P._f(b["delay_s_median"]) in headline
    # the comparison table: a row per member and the bank, each with its rate and its prediction
    table = text[text.index("Detectors on identical runs"):text.index("Per fault type")]
    rows = re.findall(r"<tr>(.*?)</tr>", table, re.S)[1:]
    assert len(rows) == len(summary["detectors"]) + 1
    for row, d in zip(rows, summary["detectors"] + [summary["bank"]]):
        assert (d["id"] in row) or (d["id"] == "bank" and "bank (any member)" in row)
        assert f">{P._f(d['far_per_h'])}<" in row and f">{P._f(d['predicted_far_per_h'])}<" in row
        assert P._pct(d["p_detect"], d["p_detect_ci"]) in row
    # how to fly a run again names files that exist
    cmds = re.findall(r"fdi-sim run (\S+?\.toml)", text)
    assert cmds and all(p.endswith(".toml") for p in cmds)
    from pathlib import Path

    named = [Path(c) for c in cmds if "NNNNNN" not in c]
    assert named and all(p.is_file() for p in named)
    fa_runs = [r["index"] for r in records if r["false_alarms"]]
    assert all(f"{i:06d}.toml" in text for i in fa_runs[: P.MAX_LISTED_RUNS])
    assert "open loop" in text and "parity-stochastic-v1" in text


def test_report_without_rescoring_and_without_faults(study, tmp_path):
    out, records, _, _ = study
    free = [r for r in records if not r["faults"]]
    bad = dict(free[0], index=99, status="diverged", reason="nz beyond 9 g at t = 12.3 s", scenario="000099.toml")
    runs = free + [bad]
    page = P.write_report(tmp_path / "rep", runs, summarize(runs), study_dir=out)
    text = page.read_text()
    assert not any((tmp_path / "rep" / f).exists() for f in FIGURES)
    assert "No re-scoring given" in text and "false-alarm study" in text
    assert "nz beyond 9 g" in text and "000099.toml" in text  # the diverged run: listed, not counted
    assert all(v == 0 for v in parse(text).depth.values())
    # a false-alarm-only study with re-scoring: the threshold figure, no ROC
    rs = rescore(free, out, [0.5, 1.0, 2.0])
    P.write_report(tmp_path / "rep2", free, summarize(free), rs, study_dir=out)
    assert (tmp_path / "rep2" / "far_vs_threshold.png").is_file() and not (tmp_path / "rep2" / "roc.png").exists()


def test_confusion_matrix_layout():
    rows, cols, m = P.confusion_matrix({"q_radps": {"q_radps": 3, "theta_rad": 1, "not detected": 2},
                                        "p_radps": {"not isolated": 1, "q_radps": 1}})
    assert rows == ["p_radps", "q_radps"]
    assert cols == ["q_radps", "theta_rad", "not isolated", "not detected"]  # targets first: right ones in line
    assert m.tolist() == [[1, 0, 1, 0], [3, 1, 0, 2]]


def test_page_from_results_json_is_the_same(study, tmp_path):
    """The page needs nothing but the JSON summary (a report can be written later from results.json)."""
    out, records, summary, _ = study
    free = [r for r in records if not r["faults"]][:3]
    s = summarize(free)
    a = P.write_report(tmp_path / "a", free, s, study_dir=out).read_text()
    b = P.write_report(tmp_path / "b", free, json.loads(json.dumps(s)), study_dir=out).read_text()
    assert a == b

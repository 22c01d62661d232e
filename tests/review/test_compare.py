"""``fdi-sim review A.mcap B.mcap``: two runs of one scenario side by side, on real flights."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from fdi_sim.cli import main
from fdi_sim.errors import ReviewError
from fdi_sim.review.compare import compare_logs
from fdi_sim.review.run_review import review_log


def test_with_and_without_reconfiguration(review_logs: dict[str, Path]) -> None:
    """The same flight with ``[fdi] reconfigure = false``: the scenario key is named, the
    reconfiguration row differs, both runs' numbers are the single-run reviews'."""
    a, b = review_logs["fault"], review_logs["fault_b"]
    c = compare_logs(a, b)
    assert c.scenario_changes == ("fdi.reconfigure: True -> False",)
    rows = {r[0]: r[1:] for r in c.rows}
    ra, rb = review_log(a), review_log(b)
    assert rows["reconfigured"][0].startswith("q_radps") and rows["reconfigured"][1] == "no"
    assert ("reconfigured",) + rows["reconfigured"] in c.differing()
    assert rb.reconfigurations == () and ra.reconfigurations
    assert c.a == ra and c.b == rb
    d = ra.first_detection("q_radps_bias")
    assert rows["q_radps_bias first alarm"][0].startswith(f"{d.detected_t_s:.2f} s by {d.detector}")
    out = c.format()
    assert str(a) in out and str(b) in out and "fdi.reconfigure: True -> False" in out
    assert re.search(r"^reconfigured .*\*$", out, re.M)


def test_other_seed(review_logs: dict[str, Path]) -> None:
    c = compare_logs(review_logs["fault"], review_logs["fault_seed"])
    assert c.scenario_changes == ("seed: 12 -> 13",)
    assert dict((r[0], r[1:]) for r in c.rows)["seed"] == ("12", "13")


@pytest.mark.parametrize("other", ["fault_free", "no_bank"])
def test_refuses_other_scenarios(review_logs: dict[str, Path], other: str) -> None:
    with pytest.raises(ReviewError, match="a run of another scenario") as exc:
        compare_logs(review_logs["fault"], review_logs[other])
    assert str(review_logs[other]) in str(exc.value) and "f16_pitch_gyro_bias" in str(exc.value)


def test_cut_off_against_complete(review_logs: dict[str, Path]) -> None:
    """A crashed run (its unrepaired file) compares with the complete one; the endings differ."""
    c = compare_logs(review_logs["fault"], review_logs["unrepaired"])
    ended = dict((r[0], r[1:]) for r in c.rows)["ended"]
    assert ended[0].startswith("completed") and "the process died" in ended[1]
    assert any(ch.startswith("duration_s: 30.0 -> 600.0") for ch in c.scenario_changes)


def test_cli_comparison_page(review_logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``<stemA>_vs_<stemB>.review.html`` next to A; both runs in the headline; figures on shared
    axes hold traces of both runs; --json has both reviews."""
    a, b = (tmp_path / "a" / "gyro.mcap", tmp_path / "b" / "noreconf.mcap")
    for src, dst in ((review_logs["fault"], a), (review_logs["fault_b"], b)):
        dst.parent.mkdir()
        dst.write_bytes(src.read_bytes())
    assert main(["review", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    page = tmp_path / "a" / "gyro_vs_noreconf.review.html"
    assert f"report       {page}" in out and "fdi.reconfigure: True -> False" in out
    html = page.read_text()
    head = html[html.index('id="headline"'):html.index("</section>", html.index('id="headline"'))]
    assert "A (gyro.mcap)" in head and "B (noreconf.mcap)" in head
    assert re.search(r'<tr class="diff"><td>reconfigured</td>', head)
    assert "<code>fdi.reconfigure: True -&gt; False</code>" in html
    ids = re.search(r'<meta name="fdi-sim-figures" content="([^"]*)">', html).group(1).split()
    specs = re.findall(r"Plotly\.newPlot\((\"[^\"]+\"),(\[.*?\]),\{", html)
    assert ids and len(specs) == len(ids)
    names = " ".join(json.dumps(json.loads(d)) for _, d in specs)
    assert re.search(r'"name": "A\b', names) and re.search(r'"name": "B\b', names)
    assert main(["review", str(a), str(b), "--json", "--out", str(tmp_path / "c.html")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["a"]["seed"] == doc["b"]["seed"] == 12 and doc["scenario_changes"] == ["fdi.reconfigure: True -> False"]


def test_cli_refuses_two_scenarios_in_a_process(review_logs: dict[str, Path], tmp_path: Path) -> None:
    """The real command: exit 2, one paragraph naming both files, no traceback, no page."""
    a, b = review_logs["fault"], review_logs["fault_free"]
    p = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "review", str(a), str(b), "--out",
                        str(tmp_path / "x.html")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert p.stderr.startswith(f"fdi-sim review: {b}: a run of another scenario than {a}")
    assert "Traceback" not in p.stderr and p.stderr.count("\n") == 1
    assert not (tmp_path / "x.html").exists()


def test_cli_refuses_the_same_file_twice(review_logs: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["review", str(review_logs["fault"]), str(review_logs["fault"])]) == 2
    assert "the same file as the first log" in capsys.readouterr().err

"""docs/regenerate.py: the queue that regenerates every stale block (its order and its commands;
nothing is flown here)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("regenerate", ROOT / "docs" / "regenerate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _line(md: str, block: str, cmd: str) -> str:
    return f"{md} [{block}]: stale (inputs aircraft changed since commit abc); run `{cmd}`"


def test_timing_blocks_go_last_and_each_command_runs_once():
    rg = _module()
    lines = [_line("bench.md", "leaderboard", "python docs/make_bench_tables.py --out-root DIR --workers 2"),
             _line("bank.md", "bank-speed", "python docs/make_bank_speed_table.py"),
             _line("bank.md", "bank-bars", "python docs/make_bank_bars_table.py"),
             _line("README.md", "bank-summary", "python docs/make_bank_bars_table.py"),
             _line("review.md", "review-timing", "python docs/make_review_table.py"),
             _line("detectors.md", "detector-card-conditions", "python docs/make_detector_card.py"),
             _line("bench.md", "bench-cost", "python docs/make_bench_tables.py --out-root DIR --workers 2")]
    q = rg.commands(lines)
    scripts = [Path(c.split()[1]).name for c in q]
    assert scripts == ["make_detector_card.py", "make_bank_bars_table.py", "make_bank_speed_table.py",
                       "make_review_table.py", "make_bench_tables.py"]
    assert q["python docs/make_bank_bars_table.py"] == ["bank.md [bank-bars]", "README.md [bank-summary]"]


def test_commands_as_run(tmp_path):
    rg = _module()
    bench = rg.argv_of("python docs/make_bench_tables.py --out-root DIR --workers 2", tmp_path, 1)
    assert bench == [sys.executable, "docs/make_bench_tables.py", "--out-root", str(tmp_path / "bench"),
                     "--workers", "1"]
    env = rg.argv_of("python docs/make_envelope_table.py", tmp_path, 2)
    assert env[-4:] == ["--out-root", str(tmp_path / "envelope"), "--workers", "2"]


def test_a_line_without_a_command_is_refused():
    rg = _module()
    try:
        rg.commands(["bank.md [x]: stale (inputs changed)"])
    except SystemExit as e:
        assert "names no command" in str(e)
    else:
        raise AssertionError("a stale line without a command was accepted")


def test_the_queue_reads_the_repository():
    """Every stale line of the checkout parses into a command (empty when nothing is stale)."""
    rg = _module()
    for cmd in rg.commands(rg.stale()):
        assert cmd.startswith("python docs/make_")

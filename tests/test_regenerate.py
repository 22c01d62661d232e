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


def test_timing_blocks_go_last_and_each_command_runs_once():
    rg = _module()
    bench = "python docs/make_bench_tables.py --out-root DIR --workers 2"
    bars = "python docs/make_bank_bars_table.py"
    blocks = [(bench, "bench.md [leaderboard]"), ("python docs/make_bank_speed_table.py", "bank.md [bank-speed]"),
              (bars, "bank.md [bank-bars]"), (bars, "README.md [bank-summary]"),
              ("python docs/make_review_table.py", "review.md [review-timing]"),
              ("python docs/make_detector_card.py", "detectors.md [detector-card-conditions]"),
              (bench, "bench.md [bench-cost]")]
    q = rg.commands(blocks)
    scripts = [Path(c.split()[1]).name for c in q]
    assert scripts == ["make_detector_card.py", "make_bank_bars_table.py", "make_bank_speed_table.py",
                       "make_review_table.py", "make_bench_tables.py"]
    assert q[bars] == ["bank.md [bank-bars]", "README.md [bank-summary]"]
    assert q[bench] == ["bench.md [leaderboard]", "bench.md [bench-cost]"]


def test_commands_as_run(tmp_path):
    rg = _module()
    bench = rg.argv_of("python docs/make_bench_tables.py --out-root DIR --workers 2", tmp_path, 1)
    assert bench == [sys.executable, "docs/make_bench_tables.py", "--out-root", str(tmp_path / "bench"),
                     "--workers", "1"]
    env = rg.argv_of("python docs/make_envelope_table.py", tmp_path, 2)
    assert env[-4:] == ["--out-root", str(tmp_path / "envelope"), "--workers", "2"]


def test_a_stale_block_is_found_with_its_command(tmp_path):
    """A copy of the repository's docs with one block's inputs changed: that block, and its command."""
    from fdi_sim.stamp import make_stamp, replace_block

    rg = _module()
    (tmp_path / "docs" / "card").mkdir(parents=True)
    (tmp_path / "README.md").write_text("# x\n")
    (tmp_path / "in.txt").write_text("a")
    md = tmp_path / "docs" / "t.md"
    md.write_text(replace_block("# t\n", make_stamp("blk", "python docs/make_t.py", ("in.txt",), tmp_path), "| 1 |"))
    assert rg.stale(tmp_path) == []
    (tmp_path / "in.txt").write_text("b")
    assert rg.stale(tmp_path) == [("python docs/make_t.py", "t.md [blk]")]


def test_every_stamp_of_the_checkout_names_a_script_the_queue_can_run():
    """Every stamp of the repository's generated files (stale or not, so the check has something to
    check on a clean checkout) names an existing docs script, and the queue turns it into a command."""
    from fdi_sim.stamp import file_stamps, generated_files

    rg = _module()
    stamps = [(f, s) for f in generated_files(ROOT) for s in file_stamps(f)]
    assert len(stamps) > 30, len(stamps)
    for f, s in stamps:
        script = s.command.split()[1]
        assert s.command.startswith("python docs/make_") and (ROOT / script).is_file(), (f.name, s.id, s.command)
    queue = rg.commands([(s.command, f"{f.name} [{s.id}]") for f, s in stamps])
    assert sum(len(b) for b in queue.values()) == len(stamps)
    for cmd in queue:
        argv = rg.argv_of(cmd, Path("/tmp/out"), 2)
        assert (ROOT / argv[1]).is_file(), argv

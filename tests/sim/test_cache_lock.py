"""The calibration cache's lock: a second process that needs an entry another is computing waits for it
and reads it, instead of flying the same training flights (fdi_sim.training.cache.cache_lock)."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from fdi_sim.training.cache import cache_lock

HOLD = """
import sys, time
from pathlib import Path
from fdi_sim.training.cache import cache_lock
entry = Path(sys.argv[1])
with cache_lock(entry):
    print("locked", flush=True)
    time.sleep(1.5)  # computing the entry
    entry.write_text("computed by the first process")
"""


def test_a_second_process_waits_for_the_entry_and_reads_it(tmp_path: Path) -> None:
    entry = tmp_path / "cache" / "bank-abc.json"
    first = subprocess.Popen([sys.executable, "-c", HOLD, str(entry)], stdout=subprocess.PIPE, text=True)
    try:
        assert first.stdout is not None and first.stdout.readline().strip() == "locked"
        t0 = time.monotonic()
        with cache_lock(entry):
            waited_s = time.monotonic() - t0
            assert entry.read_text() == "computed by the first process"  # the entry is there once we hold it
        assert waited_s > 0.5, waited_s
    finally:
        first.wait(timeout=30)
    assert first.returncode == 0


def test_a_dead_holder_leaves_no_stale_lock(tmp_path: Path) -> None:
    entry = tmp_path / "bank-def.json"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(entry)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
    holder.kill()  # SIGKILL while computing
    holder.wait(timeout=30)
    t0 = time.monotonic()
    with cache_lock(entry):
        assert not entry.exists()  # nothing half-written; this process computes it
    assert time.monotonic() - t0 < 1.0


def test_no_lock_without_the_cache(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")  # a file where the cache folder should be: the lock cannot be made
    with cache_lock(blocker / "sub" / "bank-x.json"):
        pass
    with cache_lock(tmp_path / "bank-y.json", use=False):
        assert not (tmp_path / "bank-y.lock").exists()

"""Regenerate every stale generated block of the docs, in one queue, in an order that keeps the
timings honest: the blocks that fly first, the blocks that time something last (on a machine
with nothing else running), each command once however many blocks it writes.

    python docs/regenerate.py --out-root DIR [--workers 2] [--dry-run] [--skip make_x.py,...]

Staleness is :func:`fdi_sim.stamp.stale_stamps` over :func:`fdi_sim.stamp.generated_files` (what
``tests/test_generated_docs.py`` checks); each stale block's stamp names its command.
``DIR`` in a command (the benchmark folders) becomes ``DIR/bench``, and the envelope table gets
``--out-root DIR/envelope``, so a second call after an interruption reuses the flights already
made (the studies resume; the training flights come from ``$FDI_SIM_CACHE``). After each command
the stale list is read again: a command that leaves its own blocks stale stops the queue, and
blocks that another block's inputs stale (the DHC-6 atlas changing ``aircraft/``) are picked up.

The time of each command is printed and appended to ``DIR/regenerate.log``. With a cold cache
most of it is training flights (the detector card trains every member at each condition).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.stamp import generated_files, stale_stamps  # noqa: E402

#: the scripts that time something (wall clock, rates, ratios against bare JSBSim): run last, in
#: this order, after every flying step; the benchmark's cost block is measured while it flies
TIMING = ("make_bank_speed_table.py", "make_member_cost_table.py", "make_review_table.py",
          "make_atlas_table.py", "make_bench_tables.py")
#: flying steps that go first because others reuse their cache entries (the card trains every
#: registered member at the cruise conditions the in-loop table and the benchmark use again)
FIRST = ("make_detector_card.py", "make_in_loop_table.py")


def stale(root: Path = ROOT) -> list[tuple[str, str]]:
    """Every stale block as ``(command, "file [id]")``."""
    return [(s.command, f"{f.name} [{s.id}]") for f in generated_files(root) for s, _ in stale_stamps(f, root)]


def commands(blocks: list[tuple[str, str]]) -> dict[str, list[str]]:
    """The commands of the stale blocks, each with the blocks it writes, in queue order."""
    out: dict[str, list[str]] = {}
    for cmd, block in blocks:
        out.setdefault(cmd, []).append(block)

    def rank(cmd: str) -> tuple[int, int]:
        script = Path(cmd.split()[1]).name
        if script in TIMING:
            return 2, TIMING.index(script)
        return (0, FIRST.index(script)) if script in FIRST else (1, 0)

    return dict(sorted(out.items(), key=lambda kv: rank(kv[0])))


def argv_of(cmd: str, out_root: Path, workers: int) -> list[str]:
    """The command as run: ``python`` is this interpreter, ``DIR`` the benchmark folders."""
    args = cmd.split()
    args[0] = sys.executable
    args = [str(out_root / "bench") if a == "DIR" else a for a in args]
    script = Path(args[1]).name
    if script == "make_envelope_table.py" and "--out-root" not in args:
        args += ["--out-root", str(out_root / "envelope"), "--workers", str(workers)]
    if "--workers" in args:
        args[args.index("--workers") + 1] = str(workers)
    return args


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out-root", type=Path, required=True, help="where studies and benchmark folders are kept")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--dry-run", action="store_true", help="print the queue and run nothing")
    p.add_argument("--skip", default="", help="comma-separated script names left out of this call")
    a = p.parse_args(argv)
    skip = {s.strip() for s in a.skip.split(",") if s.strip()}
    a.out_root.mkdir(parents=True, exist_ok=True)
    log = a.out_root / "regenerate.log"
    done: set[str] = set()
    t_all = time.perf_counter()
    while True:
        queue = {c: b for c, b in commands(stale()).items()
                 if c not in done and Path(c.split()[1]).name not in skip}
        if not queue:
            break
        if a.dry_run:
            for c, blocks in queue.items():
                print(f"{' '.join(argv_of(c, a.out_root, a.workers)[1:])}\n    {', '.join(blocks)}")
            return 0
        cmd, blocks = next(iter(queue.items()))
        print(f"[{len(done) + 1}, {len(queue) - 1} more queued] {cmd}  ({len(blocks)} blocks)", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run(argv_of(cmd, a.out_root, a.workers), cwd=ROOT).returncode
        wall_s = time.perf_counter() - t0
        with log.open("a") as f:
            f.write(json.dumps({"command": cmd, "rc": rc, "wall_s": round(wall_s, 1), "blocks": blocks,
                                "time": time.strftime("%Y-%m-%dT%H:%M:%S")}) + "\n")
        print(f"    rc {rc}, {wall_s / 60:.1f} min", flush=True)
        if rc != 0:
            raise SystemExit(f"`{cmd}` failed (rc {rc}); fix it and run this again (done steps are not redone)")
        left = [b for c, bs in commands(stale()).items() if c == cmd for b in bs]
        if left:
            raise SystemExit(f"`{cmd}` ran but left {left} stale: its stamp's inputs changed while it ran?")
        done.add(cmd)
    print(f"nothing stale ({len(done)} commands, {(time.perf_counter() - t_all) / 60:.1f} min)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

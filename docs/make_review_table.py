"""How long ``fdi-sim review`` takes on a 10-minute flight, as the generated block ``review-timing``
of docs/review.md (wall-clock timings: they depend on the machine and its load, which the table's
caption states).

In a temporary folder: ``fdi-sim run scenarios/f16_pitch_gyro_bias.toml --duration 600 --log
h1_10min.mcap --force --quiet`` (the default bank in the loop), then ``fdi-sim review
h1_10min.mcap --quiet`` three times, each in a fresh process: the ``took`` line it prints (read,
metrics, figures, write, total), the whole command's wall time and peak RSS (``os.wait4``), the
log's size and steps, the report's size and how much of it is plotly.js; then the same for a 30 s
flight of the same scenario, reviewed once. No random draw of its own (the flights use the
scenario's seed). The 600 s flight dominates: 2-5 min niced on a busy 2-core machine.

    python docs/make_review_table.py
"""
from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402

MD = ROOT / "docs" / "review.md"
BLOCK = "review-timing"
COMMAND = "python docs/make_review_table.py"
SCENARIO = "scenarios/f16_pitch_gyro_bias.toml"
INPUTS = (SCENARIO, "aircraft", "fdi_sim/_aircraft", "fdi_sim/review", "fdi_sim/flightlog", "fdi_sim/cli.py",
          "fdi_sim/sim", "fdi_sim/bank", "fdi_sim/detectors", "fdi_sim/decision", "fdi_sim/training",
          "fdi_sim/sensors", "fdi_sim/faults", "fdi_sim/pilot", "fdi_sim/scenario", "fdi_sim/aircraft",
          "docs/make_review_table.py")
REPEATS = 3
TOOK = re.compile(r"took\s+([\d.]+) s \(read ([\d.]+), metrics ([\d.]+), figures ([\d.]+), write ([\d.]+)\)")
REPORT = re.compile(r"report\s+(\S+) \(([\d.]+) MB\)")


def _cli() -> list[str]:
    """The ``fdi-sim`` entry point of this interpreter's environment."""
    exe = Path(sys.executable).parent / "fdi-sim"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "fdi_sim.cli"]


def _timed(args: list[str]) -> tuple[str, float]:
    """Run a command; its stdout and wall time [s]."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}): {err[-2000:]}")
    return out, wall


def _review(log: Path) -> dict[str, float]:
    """One ``fdi-sim review --quiet`` in a fresh process, through a wrapper process that reports
    the review's wall time and peak RSS (Linux ``ru_maxrss``, kB), so that no other child's peak
    (the flight's) is counted."""
    wrapper = ("import resource, subprocess, sys, time\n"
               "t0 = time.perf_counter()\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "wall = time.perf_counter() - t0\n"
               "sys.stdout.write(p.stdout)\n"
               "sys.stderr.write(p.stderr)\n"
               "print(f'WALL {wall:.3f} RSS {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0:.1f}')\n"
               "sys.exit(p.returncode)\n")
    out, _ = _timed([sys.executable, "-c", wrapper, *_cli(), "review", str(log), "--quiet"])
    m, r = TOOK.search(out), REPORT.search(out)
    w = re.search(r"WALL ([\d.]+) RSS ([\d.]+)", out)
    if not (m and r and w):
        raise RuntimeError(f"unexpected output of fdi-sim review: {out!r}")
    total, read, metrics, figures, write = (float(g) for g in m.groups())
    return {"read": read, "metrics": metrics, "figures": figures, "write": write, "total": total,
            "report_mb": float(r.group(2)), "wall": float(w.group(1)), "rss_mb": float(w.group(2))}


def _flight(tmp: Path, duration_s: float, name: str) -> tuple[Path, float]:
    log = tmp / f"{name}.mcap"
    _, wall = _timed([*_cli(), "run", SCENARIO, "--duration", f"{duration_s:g}", "--log", str(log), "--force",
                         "--quiet"])
    return log, wall


def _steps(log: Path) -> int:
    """Samples of the log's most frequent topic (the simulation steps)."""
    from fdi_sim.flightlog import read_log

    return max(len(t.t_s) for t in read_log(log).topics.values())


def _machine() -> str:
    cpu = platform.machine()
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} from other jobs, niced"


def render() -> str:
    from plotly.offline import get_plotlyjs

    machine_before = _machine()
    with tempfile.TemporaryDirectory(prefix="review_timing_") as tmp:
        log, fly_s = _flight(Path(tmp), 600.0, "h1_10min")
        size_mb, steps = log.stat().st_size / 1e6, _steps(log)
        runs = [_review(log) for _ in range(REPEATS)]
        short, _ = _flight(Path(tmp), 30.0, "h1_30s")
        short_run = _review(short)
    plotly_mb = len(get_plotlyjs().encode()) / 1e6
    cell = lambda k, d=2: " / ".join(f"{r[k]:.{d}f}" for r in runs)  # noqa: E731
    lines = ["| part | time [s] |", "| --- | --- |",
             f"| read (MCAP into numpy) | {cell('read')} |",
             f"| metrics (the review) | {cell('metrics')} |",
             f"| figures | {cell('figures')} |",
             f"| write (render + file) | {cell('write')} |",
             f"| **total** | **{cell('total')}** |",
             "",
             f"The `took` line of `fdi-sim review <log> --quiet`, three runs in order, each a fresh process, on "
             f"{machine_before} (at the start). The log: {size_mb:.1f} MB, {steps:,} steps (the 600 s flight took "
             f"{fly_s:.0f} s to fly). The report: {runs[0]['report_mb']:.2f} MB, of which {plotly_mb:.1f} MB is "
             f"plotly.js. The whole command, including Python start-up and imports: "
             f"{cell('wall', 1)} s wall, peak RSS "
             f"{max(r['rss_mb'] for r in runs):.0f} MB. A 30 s flight of the same scenario: took "
             f"{short_run['total']:.2f} s (read {short_run['read']:.2f}), {short_run['wall']:.1f} s wall."]
    return "\n".join(lines)


def main() -> int:
    t0 = time.perf_counter()
    stamp = make_stamp(BLOCK, COMMAND, INPUTS)
    body = render()
    MD.write_text(replace_block(MD.read_text(), stamp, body))
    print(body)
    print(f"wrote the {BLOCK} block of {MD} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

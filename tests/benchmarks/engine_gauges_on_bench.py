"""Benchmark (on demand; not a test, not a benchmark score): the engine-gauge check over the DHC-6
engine cases of a benchmark folder, as it would have seen them in the bank.

    python tests/benchmarks/engine_gauges_on_bench.py BENCH_FOLDER OUT_FOLDER

``BENCH_FOLDER`` is a default-bank folder that `fdi-sim bench run` wrote (its ``runs/*.toml`` are the
cases' scenarios; its logs hold the FDI topics only). Each ``dhc6-engine-*`` case is flown again with
`fdi-sim run` into ``OUT_FOLDER`` (the same scenario and seed: the default bank in the loop, the
full log), then the check (``engine-gauges-v1``, default design) runs over the logged gauges. The
check is passive (nothing in the loop reads it), so its statistic is the one it would have had in
the bank. An alarm: 3 of 5 samples above the threshold, the bank's persistence; two thresholds, the
median and the largest its in-loop designs got on the DHC-6 envelope development study (seed 15102).
Detected: an alarm within 60 s of the onset and none before it; isolated right: the first alarm
names the fault's target (the engine, or the gauge for a gauge fault).
"""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

from fdi_sim.detectors.engine_gauges import GAUGES, HYPOTHESES, make_engine_gauges
from fdi_sim.detectors.kinematic import MeasurementSet
from fdi_sim.detectors.samples import log_samples
from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.flightlog import read_log

#: the in-loop thresholds on the development study: median and largest of its 41 designs
THRESHOLDS = (6.37, 10.32)
WINDOW_S = 60.0


def _statistic(log_path: Path) -> tuple[np.ndarray, BlockOutputs]:
    s = log_samples(read_log(log_path), MeasurementSet(output_names=GAUGES), 20.0)
    idx = [s.output_names.index(n) for n in GAUGES]
    y = np.ascontiguousarray((s.dy + s.y0)[:, idx])
    ok = np.ascontiguousarray(s.valid[:, idx])
    out = BlockOutputs.allocate(s.n, 3)
    make_engine_gauges(aircraft="DHC6").process_block(s.t_s, np.zeros((s.n, 0)), y, ok, ok, out)
    return s.t_s, out


def _alarm(stat: np.ndarray, thr: float, k: int = 3, n: int = 5) -> np.ndarray:
    e = (np.nan_to_num(stat, nan=0.0) > thr).astype(int)
    return np.convolve(e, np.ones(n, dtype=int))[:len(e)] >= k


def main(bench: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    cases = sorted(p for p in (bench / "runs").glob("*.toml")
                   if tomllib.loads(p.read_text())["name"].startswith("dhc6-engine-"))
    if not cases:
        sys.exit(f"{bench}/runs has no dhc6-engine-* case: give a default-bank folder of `fdi-sim bench run`")
    rows: dict[tuple[str, float], list[tuple]] = {}
    for i, p in enumerate(cases):
        log = out / f"{p.stem}.mcap"
        if not log.exists():
            subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(p), "--log", str(log), "--quiet"],
                           check=True, stdout=subprocess.DEVNULL)
        print(f"\r{i + 1}/{len(cases)} cases", end="", file=sys.stderr)
        sc = tomllib.loads(p.read_text())
        fault = sc["faults"][0]
        onset, target = float(fault["t_start_s"]), fault["target"]
        group = sc["name"].rsplit("_", 1)[0]
        t, st = _statistic(log)
        for thr in THRESHOLDS:
            a = _alarm(st.statistic, thr)
            before = bool(a[t < onset].any())
            hit = np.flatnonzero(a & (t >= onset) & (t <= onset + WINDOW_S))
            h = int(st.hypothesis[hit[0]]) if len(hit) else -1
            rows.setdefault((group, thr), []).append(
                (len(hit) > 0 and not before, float(t[hit[0]] - onset) if len(hit) else None,
                 h >= 0 and HYPOTHESES[h] == target, before))
    print(file=sys.stderr)
    print("| group (size index) | threshold | detected within 60 s | within 5 s | isolated right | alarm before onset "
          "| delay median [s] |")
    print("|---|---|---|---|---|---|---|")
    for (g, thr), r in sorted(rows.items()):
        d = [x for x in r if x[0]]
        med = f"{np.median([x[1] for x in d]):.2f}" if d else "-"
        print(f"| {g} | {thr:g} | {len(d)}/{len(r)} | {sum(x[1] <= 5.0 for x in d)} | {sum(x[2] for x in d)} | "
              f"{sum(x[3] for x in r)} | {med} |")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]))

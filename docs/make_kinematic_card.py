"""Calibrate and card the kinematic sensor checks (``fdi_sim.detectors.kinematic``); numbers for docs/kinematic.md.

Fault-free 120 s flights of the shipped cruise-doublet scenarios (turbulence edited in the TOML
text), both aircraft, calm / light / moderate: thresholds at the empirical ``1 - 1e-3`` quantile
of the calibration seeds' statistics at 20 Hz, false-alarm fractions with Clopper-Pearson 95 %
intervals on held-out seeds, then the three shipped sensor-fault scenarios.

Writes the two tables as the generated blocks ``kinematic-false-alarms`` and ``kinematic-faults``
of docs/kinematic.md (stamped, :mod:`fdi_sim.stamp`) and prints the threshold table for
``fdi_sim/detectors/catalogue_kinematic.py``; ``--quick`` (2 + 2 seeds) only prints. Real JSBSim,
96 flights of 120 s and the three fault scenarios: 1-2 min (niced, on a busy 2-core machine).

    python docs/make_kinematic_card.py [--quick]
"""
from __future__ import annotations

import platform
import re
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
from scipy.stats import beta

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fdi_sim.detectors.kinematic import KinematicDetector, MeasurementSet, absolute, empirical_threshold
from fdi_sim.detectors.catalogue_kinematic import KINDS, design
from fdi_sim.detectors.samples import log_samples
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import loads
from fdi_sim.stamp import make_stamp, replace_block
from fdi_sim.training import fly

AIRCRAFT = {"f16": "scenarios/f16_cruise_doublets.toml", "DHC6": "scenarios/dhc6_cruise_doublets.toml"}
LEVELS = ("none", "light", "moderate")
FAULTS = ("scenarios/f16_pitch_gyro_bias.toml", "scenarios/dhc6_airspeed_drift.toml",
          "scenarios/dhc6_intermittent_aoa.toml")
RATE_HZ = 20.0
P_FA = 1e-3
MD = REPO / "docs" / "kinematic.md"
COMMAND = "python docs/make_kinematic_card.py"
INPUTS = tuple(AIRCRAFT.values()) + FAULTS + (
    "aircraft", "fdi_sim/_aircraft", "fdi_sim/aircraft", "fdi_sim/sim", "fdi_sim/pilot", "fdi_sim/sensors",
    "fdi_sim/scenario", "fdi_sim/flightlog", "fdi_sim/faults", "fdi_sim/bank", "fdi_sim/decision",
    "fdi_sim/detectors", "fdi_sim/training", "fdi_sim/seeds.py", "docs/make_kinematic_card.py")
STEP_ROWS = 400


def sensor_rates(aircraft: str) -> dict[str, float]:
    """Per-signal sampling rate [Hz] from ``aircraft/<name>/sensors.toml``."""
    table = tomllib.loads((REPO / "aircraft" / aircraft / "sensors.toml").read_text())["sensor"]
    return {k: float(v["rate_hz"]) for k, v in table.items()}


def fly_text(text: str, aircraft: str, out: Path, seed: int | None = None, duration_s: float | None = None):
    """Fly a scenario text; return (log, samples of the absolute measurements at 20 Hz)."""
    sc = loads(text)
    if seed is not None:
        sc = sc.replace(seed=seed)
    if duration_s is not None:
        sc, _ = sc.shortened(duration_s)
    res = fly(sc, out, progress=False)
    log = read_log(res.log_path)
    return log, log_samples(log, MeasurementSet(), RATE_HZ, sensor_rates_hz=sensor_rates(aircraft))


def cruise_text(aircraft: str, level: str) -> str:
    """The shipped cruise-doublet scenario with its turbulence set to ``level``."""
    text = (REPO / AIRCRAFT[aircraft]).read_text()
    return re.sub(r'turbulence = "\w+"', f'turbulence = "{level}"', text, count=1)


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of k successes in n trials."""
    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def fault_onset_s(log) -> float:
    """First time any ``*_active`` flag of /faults/active is set [s]."""
    a = log.topics["/faults/active"]
    t = np.asarray(a.t_s)
    on = np.zeros(len(t), dtype=bool)
    for f in a.fields:
        if f.endswith("_active"):
            on |= np.asarray(a[f]) > 0.5
    return float(t[np.argmax(on)]) if on.any() else float("nan")


def machine() -> str:
    """The CPU and core count the timings were taken on."""
    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    import os

    return f"{cpu}, {os.cpu_count()} cores, niced, with other jobs running"


def step_cost_us(s, kind: str, ac: str, level: str) -> float:
    """Median wall time [us] of one ``step`` call over the first ``STEP_ROWS`` rows of a flight."""
    det = KinematicDetector(design(kind, ac, level, threshold=np.inf), id=f"kinematic-{kind}-v1")
    det.reset(None)
    y = absolute(s)
    dt = []
    for j in range(min(STEP_ROWS, s.n)):
        t0 = time.perf_counter()
        det.step(float(s.t_s[j]), np.zeros(0), y[j])
        dt.append(time.perf_counter() - t0)
    return 1e6 * float(np.median(dt))


def main(quick: bool = False) -> tuple[str, str]:
    """Fly, calibrate, card; the two tables' Markdown (false alarms with the costs, fault scenarios)."""
    from fdi_sim.seeds import seeds

    cal_seeds = seeds("kinematic-calibration")[:None if not quick else 2]
    held_seeds = seeds("kinematic-card")[:None if not quick else 2]
    dur = 120.0
    out = Path(tempfile.mkdtemp(prefix="kin_card_"))
    stats: dict = {}
    cost: dict = {}
    step_cost: dict = {}
    for ac in AIRCRAFT:
        for level in LEVELS:
            for seed in cal_seeds + held_seeds:
                _, s = fly_text(cruise_text(ac, level), ac, out / f"{ac}_{level}_{seed}", seed, dur)
                for kind in KINDS:
                    det = KinematicDetector(design(kind, ac, level, threshold=np.inf), id=f"kinematic-{kind}-v1")
                    t0 = time.perf_counter()
                    z = det.run(s).statistic
                    cost.setdefault(kind, []).append((time.perf_counter() - t0) / s.n)
                    stats.setdefault((ac, level, kind), {})[seed] = z
                    if seed == held_seeds[0] and level == "moderate":
                        step_cost.setdefault(kind, []).append(step_cost_us(s, kind, ac, level))
    print("## thresholds (THRESHOLDS in catalogue_kinematic.py)\n")
    thr = {}
    for key, by_seed in stats.items():
        thr[key] = empirical_threshold([by_seed[s] for s in cal_seeds], P_FA)
        print(f"    {key!r}: {thr[key]:.3f},")
    fa = ["| aircraft | turbulence | check | threshold | held-out FA | 95 % interval | target inside |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    for (ac, level, kind), by_seed in stats.items():
        z = np.concatenate([by_seed[s] for s in held_seeds])
        z = z[np.isfinite(z)]
        k, n = int(np.sum(z > thr[(ac, level, kind)])), z.size
        lo, hi = clopper_pearson(k, n)
        fa.append(f"| {ac} | {level} | {kind} | {thr[(ac, level, kind)]:.2f} | {k}/{n} = {k / n:.2e} | "
                  f"[{lo:.1e}, {hi:.1e}] | {'yes' if lo <= P_FA <= hi else 'no'} |")
    fa += ["", "| check | cost per sample, `run` (median over the flights) [us] | cost per call, `step` (median "
           f"over the first {STEP_ROWS} rows of seed {held_seeds[0]}'s moderate flights) [us] |", "| --- | --- | --- |"]
    for kind, c in cost.items():
        fa.append(f"| {kind} | {1e6 * np.median(c):.1f} | {np.median(step_cost[kind]):.0f} |")
    fa += ["", f"Thresholds from seeds {cal_seeds[0]}-{cal_seeds[-1]}, held-out seeds {held_seeds[0]}-{held_seeds[-1]}, "
           f"{dur:g} s each at {RATE_HZ:g} Hz; timings on {machine()}."]
    ft = ["| scenario | check | first alarm [s] | onset [s] | delay [s] | alarm before onset | isolation at first alarm "
          "| alarm fraction after onset |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for path in FAULTS:
        text = (REPO / path).read_text()
        ac = loads(text).model.aircraft
        level = re.search(r'turbulence = "(\w+)"', text)
        level = level.group(1) if level else "none"
        log, s = fly_text(text, ac, out / Path(path).stem)
        onset = fault_onset_s(log)
        for kind in KINDS:
            res = KinematicDetector(design(kind, ac, level, threshold=thr[(ac, level, kind)]),
                                    id=f"kinematic-{kind}-v1").run(s)
            a = res.alarm
            first = float(s.t_s[np.argmax(a)]) if a.any() else float("nan")
            before = bool(np.any(a & (s.t_s < onset)))
            after = s.t_s >= onset
            iso = res.isolation[np.argmax(a)] if a.any() else "-"
            ft.append(f"| {Path(path).stem} | {kind} | {first:.2f} | {onset:.2f} | {first - onset:.2f} | {before} | "
                      f"{iso} | {np.mean(a[after]):.3f} |")
    ft += ["", "Thresholds: this run's calibration at the scenario's turbulence level; the shipped scenarios' own "
           "seeds and durations."]
    return "\n".join(fa), "\n".join(ft)


def write(bodies: tuple[str, str]) -> None:
    text = MD.read_text()
    for block_id, body in zip(("kinematic-false-alarms", "kinematic-faults"), bodies):
        text = replace_block(text, make_stamp(block_id, COMMAND, INPUTS), body)
    MD.write_text(text)
    print(f"wrote the kinematic-false-alarms and kinematic-faults blocks of {MD}")


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    t_start = time.perf_counter()
    tables = main(quick=quick)
    if quick:
        print("\n\n".join(tables))
    else:
        write(tables)
    print(f"run time {time.perf_counter() - t_start:.0f} s")

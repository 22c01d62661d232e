"""The default bank on fault-free flights it was not calibrated on (issue 13's false-alarm bar).

Per aircraft, at the cruise, climb and approach points of the shipped scenarios
(:data:`POINTS`): each scenario with its faults removed, in moderate turbulence, flown for
``duration_s`` (10 minutes) with held-out seeds (301-308; the bank's training flights use seeds
1e6 + i), the default bank in the loop, FDI topics only (``[log] per_step = false``). Every alarm
episode is a false alarm. The rate per flight hour is given with its exact Poisson interval
(Garwood) beside the bank's design rate ``far_per_h``.

``python -m fdi_sim.study.bank_false_alarms [--seeds 8] [--duration 600] [--json out.json]``
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

from fdi_sim.seeds import seeds as registry_seeds
from fdi_sim.decision.intervals import poisson_rate_interval
from fdi_sim.scenario import load
from fdi_sim.scenario.loader import from_dict
from fdi_sim.scenario.shipped import shipped_dir
from fdi_sim.units import S_PER_H

#: the shipped scenarios whose operating points the bar names, per aircraft
POINTS: dict[str, tuple[str, ...]] = {
    "f16": ("f16_cruise_doublets", "f16_climbing_turn", "f16_climb_accelerate"),
    "DHC6": ("dhc6_cruise_doublets", "dhc6_climb", "dhc6_approach_flaps"),
}
#: seeds 101-108 were looked at while the threshold method was chosen (the DHC-6 airspeed check's
#: point-estimate threshold alarmed 3 times on them, which led to the bootstrap bound); seeds
#: 201-208 were the report until the alarm of seed 204 (DHC-6 approach) was traced to the
#: per-sample tail fit, which led to the episode-rate thresholds; the bar is now reported on
#: 301-308, which no design decision saw
DEVELOPMENT_SEEDS = registry_seeds("bank-development-1") + registry_seeds("bank-development-2")
HELD_OUT_SEEDS = registry_seeds("bank-bar")


@dataclass(frozen=True)
class PointResult:
    """One scenario's fault-free flights with the default bank."""

    scenario: str
    aircraft: str
    flights: int
    flight_h: float
    false_alarms: int
    far_per_h: float
    far_per_h_ci: tuple[float, float]
    design_far_per_h: float
    by_detector: dict[str, int]
    statuses: dict[str, int]
    first_alarms: tuple[str, ...]
    notes: tuple[str, ...]


def fault_free_flight(name: str, seed: int, duration_s: float, turbulence: str = "moderate") -> object:
    """A shipped scenario without faults, in ``turbulence``, with the default bank, FDI topics only."""
    sc = load(shipped_dir() / f"{name}.toml")
    d = json.loads(sc.to_json())
    d.update(seed=int(seed), duration_s=float(duration_s), faults=[], detectors=[])
    d["atmosphere"] = {**d.get("atmosphere", {}), "turbulence": turbulence}
    d["fdi"] = {**d.get("fdi", {}), "bank": "default"}
    d["log"] = {"per_step": False}
    return from_dict(d, source=f"{sc.source} (fault-free, seed {seed}, {turbulence} turbulence)")


def study_point(name: str, seeds: Sequence[int] = HELD_OUT_SEEDS, duration_s: float = 600.0,
                progress: bool = True) -> PointResult:
    """Fly the held-out fault-free flights of one scenario; count the alarms."""
    from fdi_sim.training import fly

    alarms, by_det, statuses, firsts, hours = 0, {}, {}, [], 0.0
    notes: tuple[str, ...] = ()
    design = 0.0
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fdi-sim-fa-") as tmp:
        for i, seed in enumerate(seeds):
            sc = fault_free_flight(name, seed, duration_s)
            design = sc.model.fdi.far_per_h
            res = fly(sc, tmp, progress=False, force=True)
            s = res.summary
            statuses[res.status] = statuses.get(res.status, 0) + 1
            hours += s.t_end_s / S_PER_H
            notes = s.fdi_notes
            for a in s.fdi_false_alarms:
                alarms += 1
                by_det[a.detector] = by_det.get(a.detector, 0) + 1
                firsts.append(f"seed {seed}: {a.detector} at {a.onset_t_s:.2f} s ({a.isolation})")
            Path(res.log_path).unlink(missing_ok=True)
            if progress and sys.stderr.isatty():
                el = time.perf_counter() - t0
                print(f"\r{name}: {i + 1}/{len(seeds)} flights, {hours * S_PER_H / el:.0f} sim s/s, "
                      f"ETA {(len(seeds) - i - 1) * el / (i + 1):.0f} s, {alarms} alarms", end="", file=sys.stderr,
                      flush=True)
    if progress and sys.stderr.isatty():
        print(file=sys.stderr)
    ac = load(shipped_dir() / f"{name}.toml").aircraft
    return PointResult(name, ac, len(seeds), hours, alarms, alarms / hours, poisson_rate_interval(alarms, hours),
                       design, by_det, statuses, tuple(firsts), notes)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=len(HELD_OUT_SEEDS))
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    seeds = tuple(HELD_OUT_SEEDS[0] + i for i in range(a.seeds))
    rows = []
    print(f"{'scenario':24} {'flights':>7} {'hours':>6} {'alarms':>6} {'per h':>7} {'95 % interval':>16} {'design':>7}")
    for names in POINTS.values():
        for name in names:
            r = study_point(name, seeds, a.duration)
            rows.append(r)
            print(f"{r.scenario:24} {r.flights:7d} {r.flight_h:6.2f} {r.false_alarms:6d} {r.far_per_h:7.3f} "
                  f"[{r.far_per_h_ci[0]:.3f}, {r.far_per_h_ci[1]:.3f}] {r.design_far_per_h:7.3g}  "
                  f"{r.statuses} {'; '.join(r.first_alarms[:3])}", flush=True)
    tot_h = sum(r.flight_h for r in rows)
    tot = sum(r.false_alarms for r in rows)
    lo, hi = poisson_rate_interval(tot, tot_h)
    print(f"{'all':24} {sum(r.flights for r in rows):7d} {tot_h:6.2f} {tot:6d} {tot / tot_h:7.3f} [{lo:.3f}, {hi:.3f}]")
    if a.json:
        Path(a.json).write_text(json.dumps([asdict(r) for r in rows], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

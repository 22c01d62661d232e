"""Fault-free training flights of a scenario: the flights every calibration is set on.

The training flights are the scenario itself with its faults, detectors and bank removed
(:func:`fault_free`), flown with seeds the scenario's own runs do not use
(:data:`TRAINING_SEED_BASE` + i, the seed registry's training set), for ``duration_s`` each;
their measurement and command rows are kept in memory (``fdi_sim.sim.run(..., keep_rows=True)``).
"""
from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence


from fdi_sim.seeds import seeds as _seeds
from fdi_sim.errors import DesignError
from fdi_sim.scenario import Scenario
from fdi_sim.scenario.loader import from_dict


#: training seeds are TRAINING_SEED_BASE + i (the seed registry's "training" set: far from the
#: small seeds scenarios and studies use)
TRAINING_SEED_BASE = _seeds("training")[0]


DEFAULT_TRAINING_FLIGHTS = 24


DEFAULT_TRAINING_S = 300.0


#: per-sample false-alarm target at the detector rate; 1e-3 put alarms on the autopilot's doublets
#: (the linear model's largest misses), 1e-4 clears every shipped scenario's pre-fault maneuvers
DEFAULT_TARGET = 1e-4


def fault_free(sc: Scenario, seed: int, duration_s: float) -> Scenario:
    """The scenario without its faults, detectors and FDI bank, with full logs, another seed and duration."""
    data = json.loads(sc.to_json())
    data.update(faults=[], detectors=[], seed=int(seed), duration_s=float(duration_s))
    data.pop("fdi", None)  # no bank in a training flight (it would need training itself), full logs
    data.pop("log", None)
    data["maneuvers"] = [m for m in data.get("maneuvers", []) if float(m.get("t_start_s", 0.0)) < duration_s]
    return from_dict(data, source=f"{sc.source} (fault-free training flight, seed {seed})")


def training_seeds(n: int) -> tuple[int, ...]:
    """The first ``n`` seeds of the registry's training set."""
    s = _seeds("training")
    if n > len(s):
        raise ValueError(f"{n} training flights asked for; the seed registry's training set has {len(s)}")
    return s[:n]


def fly_training(sc: Scenario, seeds: Sequence[int], duration_s: float, progress: bool = True,
                 label: str = "") -> list[Any]:
    """Fly the fault-free training flights; return their logs: the measurement and command topics,
    kept in memory as the log would hold them (``run(..., keep_rows=True)``: no per-step topic is
    written or read back, which was half a training flight's cost).

    Parameters
    ----------
    sc : Scenario
        Flown by :func:`fault_free` with each seed.
    seeds : sequence of int
    duration_s : float
        Length of each flight [s].
    progress : bool
        One line on stderr, rewritten after each flight (flights done, sim s per s, ETA), only
        when stderr is a terminal.
    label : str
        Put before the progress line (which calibration this is: ``"point 2/4 (h 12000 ft, vc 320 kt): "``).
    """
    from fdi_sim.sim.run import run

    logs = []
    t0 = time.perf_counter()
    show = progress and sys.stderr.isatty()
    with tempfile.TemporaryDirectory(prefix="fdi-sim-train-") as tmp:
        for i, seed in enumerate(seeds):
            res = run(fault_free(sc, seed, duration_s), tmp, progress=False, keep_rows=True)
            if res.status == "interrupted":  # Ctrl-C / SIGTERM during calibration: stop like any run
                raise KeyboardInterrupt(f"calibration interrupted during training flight seed {seed}")
            if res.status != "completed":
                raise DesignError(f"{sc.source}: fault-free training flight seed {seed} ended {res.status} "
                                  f"({res.summary.reason}); a detector cannot be calibrated on a scenario that does not "
                                  "fly without its faults")
            logs.append(res.rows)  # measurements and commands, kept in memory: no topic written or read back
            Path(res.log_path).unlink()
            if show:
                el = time.perf_counter() - t0
                rate = (i + 1) * duration_s / el
                print(f"\r{label}calibration flights {i + 1}/{len(seeds)}  {rate:.0f} sim s/s  "
                      f"ETA {(len(seeds) - i - 1) * el / (i + 1):.0f} s", end="", file=sys.stderr, flush=True)
    if show:
        print(file=sys.stderr)
    return logs


class LazyTraining:
    """The scenario's fault-free training flights, flown on first use (then kept)."""

    def __init__(self, sc: Scenario, progress: bool) -> None:
        self.sc, self.progress = sc, progress
        self.n = sc.model.fdi.calibration_flights
        self._logs: list[Any] | None = None

    def __len__(self) -> int:
        return self.n

    def __iter__(self):
        if self._logs is None:


            f = self.sc.model.fdi
            self._logs = fly_training(self.sc, training_seeds(self.n), f.calibration_duration_s,
                                      progress=self.progress)
        return iter(self._logs)



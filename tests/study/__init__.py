"""Tests of :mod:`fdi_sim.study`; :func:`fly_results` flies real short runs into a results folder.

The folder has the layout of a study's (``runs/NNNNNN.json`` record, ``.mcap`` log with the FDI
topics only, ``.toml`` scenario); each record is built here from :class:`~fdi_sim.sim.run.RunSummary`
and the log's fault catalog in the record shape the study runner writes.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

from fdi_sim.units import S_PER_H

BASE = """name = "t{index}"
aircraft = "DHC6"
duration_s = {duration_s}
seed = {seed}
[initial]
h_ft = 6000.0
vc_kts = 124.0
[atmosphere]
turbulence = "moderate"
[fdi]
bank = "default"
far_per_h = 0.9  # the largest allowed: alarms for the re-scoring checks to compare on six 60 s flights
calibration_flights = 4
calibration_duration_s = 60.0
log_residuals = false
[log]
per_step = false
"""

#: six fault entries of different kinds: detected at once, a window that ends (the grace after it),
#: a slow drift, an intermittent fault (several windows), an actuator, one too small to detect
FAULTS: tuple[str, ...] = (
    'type = "sensor-bias-v1"\ntarget = "q_radps"\nbias_degps = 2.0\nt_start_s = 20.0\n',
    'type = "sensor-bias-v1"\ntarget = "p_radps"\nbias_degps = 3.0\nt_start_s = 25.0\nt_end_s = 40.0\n',
    'type = "sensor-drift-v1"\ntarget = "vc_kts"\ndrift_ktps = 0.5\nt_start_s = 15.0\n',
    'type = "sensor-stuck-v1"\ntarget = "alpha_rad"\nt_start_s = 10.0\n'
    'intermittent = { duty_cycle = 0.3, mean_dwell_s = 2.0 }\n',
    'type = "actuator-loss-v1"\ntarget = "elevator"\neffectiveness = 0.3\nt_start_s = 20.0\n',
    'type = "sensor-bias-v1"\ntarget = "q_radps"\nbias_degps = 0.05\nt_start_s = 30.0\n',
)


def _alarm(a: Any) -> dict[str, Any]:
    return {"detector": a.detector, "onset_t_s": a.onset_t_s, "end_t_s": a.end_t_s, "isolation": a.isolation}


def record_of(index: int, result: Any, sc: Any) -> dict[str, Any]:
    """The study record of one flown run (the shape :mod:`fdi_sim.study.stats` reads)."""
    from fdi_sim.flightlog import METADATA_FAULTS, read_log

    s = result.summary
    f = sc.model.fdi
    log = read_log(result.log_path)
    catalog = json.loads(log.metadata.get(METADATA_FAULTS, {}).get("catalog", "[]"))
    types = {c["label"]: c["type"] for c in catalog}
    return {
        "index": index, "seed": sc.seed, "status": s.status, "reason": s.reason, "t_end_s": s.t_end_s,
        "flight_h": s.t_end_s / S_PER_H, "wall_s": s.wall_s, "worker": "local",
        "params": {"fault": catalog[0]["type"] if catalog else None},
        "detectors": list(s.fdi_detectors), "thresholds": dict(zip(s.fdi_detectors, s.fdi_thresholds)),
        "design_far_per_h": f.far_per_h, "rate_hz": f.rate_hz, "persistence": [f.persistence_k, f.persistence_n],
        "arm_s": f.arm_s, "decision": f.decision, "n_members": len(s.fdi_detectors),
        "faults": catalog,
        "alarms": [_alarm(a) for a in s.fdi_alarms], "false_alarms": [_alarm(a) for a in s.fdi_false_alarms],
        "detections": [{"fault": d.fault, "type": types.get(d.fault, ""), "target": d.target, "detector": d.detector,
                        "onset_t_s": d.onset_t_s, "detected_t_s": d.detected_t_s, "delay_s": d.delay_s,
                        "isolation": d.isolation, "isolation_correct": d.isolation_correct}
                       for d in s.fdi_detections],
        "reconfigurations": [dict(r) for r in s.fdi_reconfigurations],
        "log": f"{index:06d}.mcap", "scenario": f"{index:06d}.toml",
    }


def fly_results(out_dir: Path, cache_dir: Path, *, n_free: int = 6, faults: Sequence[str] = FAULTS,
                duration_s: float = 60.0, seed0: int = 100) -> list[dict[str, Any]]:
    """Fly ``n_free`` fault-free runs, then one run per entry of ``faults``, into ``out_dir/runs``.

    ``FDI_SIM_CACHE`` is set to ``cache_dir`` for the calls (the bank is calibrated once, on the
    first run, and shared by the others).
    """
    import fdi_sim.scenario
    import fdi_sim.training

    runs = Path(out_dir) / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    texts = [""] * n_free + ["[[faults]]\n" + f for f in faults]
    old = os.environ.get("FDI_SIM_CACHE")
    os.environ["FDI_SIM_CACHE"] = str(cache_dir)
    records = []
    try:
        for i, text in enumerate(texts):
            path = runs / f"{i:06d}.toml"
            path.write_text(BASE.format(index=i, seed=seed0 + i, duration_s=duration_s) + text)
            sc = fdi_sim.scenario.load(path)
            res = fdi_sim.training.fly(sc, log_path=runs / f"{i:06d}.mcap", progress=False)
            rec = record_of(i, res, sc)
            (runs / f"{i:06d}.json").write_text(json.dumps(rec, indent=1, sort_keys=True))
            records.append(rec)
    finally:
        if old is None:
            os.environ.pop("FDI_SIM_CACHE", None)
        else:
            os.environ["FDI_SIM_CACHE"] = old
    return records


def load_folder(out_dir: Path) -> list[dict[str, Any]]:
    """The records of a results folder, in index order."""
    return [json.loads(p.read_text()) for p in sorted((Path(out_dir) / "runs").glob("[0-9]*.json"))]


_SHARED: dict[str, tuple[Path, list[dict[str, Any]]]] = {}


def shared_results(tmp_path_factory: Any) -> tuple[Path, list[dict[str, Any]]]:
    """The folder of :func:`fly_results` with its defaults, flown once per test session (the
    first test module that asks flies it, about 45 s; the others reuse it read-only)."""
    if "default" not in _SHARED:
        out = tmp_path_factory.mktemp("study_results")
        records = fly_results(out, tmp_path_factory.mktemp("study_cache"))
        _SHARED["default"] = (out, records)
    out, records = _SHARED["default"]
    return out, [json.loads(json.dumps(r)) for r in records]  # a copy a test may change

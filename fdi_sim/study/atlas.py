"""Making an aircraft's calibration atlas (:mod:`fdi_sim.training.atlas`): the default bank's
calibrated design at every schedule-grid node of its envelope, trained once, shipped.

``python -m fdi_sim.study.atlas f16 [--workers 2]`` writes ``aircraft/f16/fdi_atlas.json``. Each node
is one task on a local Dask cluster: the calibrated design scenario there
(:func:`fdi_sim.training.schedule.calibrated_design` of the reference scenario at the node), its
bank built as a flight would build it with the atlas off (the training flights flown, the gust
filter's calibration and the members' thresholds computed), and the cache entries that gave
recorded with their atlas keys and design fingerprints. The entries go through the ordinary
on-disk cache under ``$FDI_SIM_CACHE/fdi-sim/atlas-build/<aircraft>``, so an interrupted generation
starts again without flying a node twice.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

#: per aircraft: the reference scenario (its calibration studies' base) and the box of initial
#: points the atlas covers (the envelope hold-out studies' sampling box, scenarios/studies/
#: *_envelope_hold_out.toml): ``h_ft`` and ``vt_kts`` or ``vc_kts``, [min, max]
ENVELOPES: Mapping[str, Mapping[str, Any]] = {
    "f16": {"reference": "f16_cruise_doublets", "h_ft": (5000.0, 18000.0), "vt_kts": (330.0, 430.0)},
    "DHC6": {"reference": "dhc6_cruise_doublets", "h_ft": (2000.0, 8000.0), "vc_kts": (95.0, 135.0)},
}
#: points per axis of the box mapped to their nodes (the nodes any point of the box can reach)
_BOX_SAMPLES = 121
#: the files the atlas's numbers depend on (its stamp)
STAMP_INPUTS = ("fdi_sim/training", "fdi_sim/detectors", "fdi_sim/decision", "fdi_sim/bank", "fdi_sim/aircraft",
                "fdi_sim/sensors", "fdi_sim/sim", "fdi_sim/pilot", "aircraft")


def envelope_nodes(aircraft: str, envelope: Mapping[str, Any] | None = None) -> list[tuple[float, float]]:
    """The grid nodes ``(h_ft, vc_kts)`` that initial points in the aircraft's box design at (the rule
    of :func:`fdi_sim.training.schedule._design_scenario`), sorted."""
    from fdi_sim.isa import vc_from_vt
    from fdi_sim.training.schedule import default_spacing

    env = dict(ENVELOPES[aircraft] if envelope is None else envelope)
    dh, dv = default_spacing(aircraft)
    hs = np.linspace(*env["h_ft"], _BOX_SAMPLES)
    speed_key = "vt_kts" if "vt_kts" in env else "vc_kts"
    vs = np.linspace(*env[speed_key], _BOX_SAMPLES)
    out = set()
    for h in hs:
        for v in vs:
            vc = float(vc_from_vt(float(h), float(v))[0]) if speed_key == "vt_kts" else float(v)
            out.add((max(dh, round(float(h) / dh) * dh), max(dv, round(vc / dv) * dv)))
    return sorted(out)


def node_flight(aircraft: str, h_ft: float, vc_kts: float, turbulence: str = "moderate",
                maneuvers: str = "doublets") -> Any:
    """The reference scenario at a node with the default bank: the flight whose calibrated design
    the atlas holds there (any flight with default sensors and ``[fdi]`` settings near the node has
    the same design)."""
    from fdi_sim.scenario.loader import from_dict, load
    from fdi_sim.scenario.shipped import shipped_dir

    ref = ENVELOPES[aircraft]["reference"]
    data = json.loads(load(shipped_dir() / f"{ref}.toml").to_json())
    data["initial"] = {**data["initial"], "h_ft": float(h_ft), "vc_kts": float(vc_kts), "vt_kts": None}
    data["atmosphere"] = {**data.get("atmosphere", {}), "turbulence": turbulence}
    if maneuvers == "steady":
        data["maneuvers"] = []
    data["fdi"] = {"bank": "default"}
    data["faults"] = []
    return from_dict(data, source=f"{ref} at the atlas node h {h_ft:g} ft, vc {vc_kts:g} kt, {turbulence} turbulence")


def node_task(aircraft: str, h_ft: float, vc_kts: float, turbulence: str, maneuvers: str,
              cache: str) -> dict[str, Any]:
    """One node, turbulence level and maneuver variant (in a worker): its calibrated design, bank
    and recorded entries, or why it has none."""
    os.environ["FDI_SIM_CACHE"] = cache
    os.environ["FDI_SIM_ATLAS"] = "off"  # never the file being remade
    from fdi_sim.errors import DesignError
    from fdi_sim.sim.run import PILOT_FIELDS, build_sensors
    from fdi_sim.training import atlas
    from fdi_sim.training.atlas import scenario_digest
    from fdi_sim.bank.members import per_sample_target
    from fdi_sim.training.build import build_bank
    from fdi_sim.training.flights import LazyTraining
    from fdi_sim.training.schedule import calibrated_design
    from fdi_sim.training.thresholds import calibrate_thresholds

    t0 = time.perf_counter()
    flight = node_flight(aircraft, h_ft, vc_kts, turbulence, maneuvers)
    des = calibrated_design(flight, ENVELOPES[aircraft]["reference"])
    node = {"h_ft": float(des.model.initial.h_ft), "vc_kts": float(des.model.initial.vc_kts),
            "flaps_deg": float(des.model.initial.flaps_deg), "turbulence": des.model.atmosphere.turbulence,
            "maneuvers": "doublets" if des.maneuvers else "steady",
            "design_digest": scenario_digest(json.loads(des.to_json()))}
    atlas.RECORDER = []
    try:
        sensors = build_sensors(des, des.dt_s)
        logs = LazyTraining(des, False)
        bank = build_bank(des, meas_names=sensors.names, cmd_names=PILOT_FIELDS,
                          sensor_rates_hz={s.name: s.rate_hz for s in sensors.specs}, pilot_sensors=sensors.names,
                          progress=False, training_logs=logs)
        thresholds = {m.id: float(m.threshold) for m in bank.members}
        # the trained thresholds too where a study's file gave the bank its own (its design node):
        # on another CPU that file is matched by them (fdi_sim.training.thresholds.apply_study_thresholds)
        f = des.model.fdi
        calibrate_thresholds(des, bank, per_sample_target(f.far_per_h, len(bank.members), f.rate_hz),
                             progress=False, training_logs=logs)
        rec = list(atlas.RECORDER)
        status = "ok"
    except DesignError as exc:
        rec, status, thresholds = [], f"failed: {exc}", {}
    finally:
        atlas.RECORDER = None
    return {**node, "status": status, "entries": rec, "thresholds": thresholds, "wall_s": time.perf_counter() - t0}


def make_atlas(aircraft: str, out: Path, *, workers: int = 2, progress: bool = True,
               nodes: Sequence[tuple[float, float]] | None = None,
               doublet_levels: Sequence[str] | None = None) -> dict[str, Any]:
    """Fly every node's training flights (cached) and write the atlas file ``out``.

    Returns the file's content.
    """
    from fdi_sim.stamp import make_stamp
    from fdi_sim.study.execute import _client
    from fdi_sim.training.atlas import CONDITIONS, LEVELS, MANEUVERS
    from fdi_sim.training.cache import cache_dir
    from fdi_sim.training.flights import training_seeds
    from fdi_sim.scenario.loader import load
    from fdi_sim.scenario.shipped import shipped_dir

    env = ENVELOPES[aircraft]
    nodes = list(nodes) if nodes is not None else envelope_nodes(aircraft)
    cache = str(cache_dir().parent / "atlas-build" / aircraft)
    client, cluster = _client(workers, None)
    results: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    try:
        from distributed import as_completed

        combos = [(lv, mv) for mv in MANEUVERS for lv in LEVELS
                  if mv != "doublets" or doublet_levels is None or lv in doublet_levels]
        futs = [client.submit(node_task, aircraft, h, v, lv, mv, cache, pure=False)
                for lv, mv in combos for h, v in nodes]
        for i, fut in enumerate(as_completed(futs, loop=client.loop), 1):
            r = fut.result()
            results.append(r)
            if progress:
                print(f"atlas {aircraft}: {i}/{len(futs)}, h {r['h_ft']:g} ft vc {r['vc_kts']:g} kt "
                      f"{r['turbulence']} {r['maneuvers']}: "
                      f"{r['status'][:80]} ({r['wall_s']:.0f} s; {time.perf_counter() - t0:.0f} s in all)",
                      file=sys.stderr, flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    results.sort(key=lambda r: (MANEUVERS.index(r["maneuvers"]), LEVELS.index(r["turbulence"]), r["h_ft"], r["vc_kts"]))
    ref = load(shipped_dir() / f"{env['reference']}.toml")
    fdi = ref.model.fdi
    entries: dict[str, Any] = {}
    for r in results:
        for e in r["entries"]:
            entries[f"{e['kind']}:{e['key']}"] = {"node": [r["h_ft"], r["vc_kts"], r["flaps_deg"], r["turbulence"],
                                                           r["maneuvers"]],
                                                  "fingerprint": e["fingerprint"], "entry": e["entry"]}
    seeds = training_seeds(fdi.calibration_flights)
    stamp = make_stamp(f"atlas-{aircraft}", f"python -m fdi_sim.study.atlas {aircraft} --workers {workers}",
                       STAMP_INPUTS)
    doc = {"kind": "fdi-atlas", "aircraft": aircraft, "reference": env["reference"],
           "envelope": {k: list(v) for k, v in env.items() if k != "reference"}, "conditions": dict(CONDITIONS),
           "training": (f"{fdi.calibration_flights} fault-free flights of {fdi.calibration_duration_s:g} s per node "
                        f"(training seeds {seeds[0]}-{seeds[-1]})"),
           "stamp": asdict(stamp),
           "levels": list(LEVELS), "maneuvers": list(MANEUVERS),
           "variants": [list(c) for c in combos],
           "nodes": [{k: r[k] for k in ("h_ft", "vc_kts", "flaps_deg", "turbulence", "maneuvers", "design_digest",
                                        "status", "thresholds")} for r in results],
           "entries": entries}
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=None, separators=(",", ":")) + "\n")
    os.replace(tmp, out)
    return doc


REFERENCE_FLIGHTS = 2
REFERENCE_DURATION_S = 120.0


def reference_task(aircraft: str, h_ft: float, vc_kts: float, turbulence: str, maneuvers: str,
                   cache: str) -> dict[str, Any]:
    """One node and variant (in a worker): the turbulence estimate's reference on
    :data:`REFERENCE_FLIGHTS` fault-free flights of :data:`REFERENCE_DURATION_S` at its calibrated
    design (the first training seeds), for :func:`fdi_sim.bank.turbulence.power_schedule`."""
    os.environ["FDI_SIM_CACHE"] = cache
    os.environ["FDI_SIM_ATLAS"] = "off"
    from types import SimpleNamespace

    from fdi_sim.detectors.samples import decimation
    from fdi_sim.training.flights import fly_training, training_seeds
    from fdi_sim.training.schedule import calibrated_design
    from fdi_sim.bank.turbulence import estimate_spec
    from fdi_sim.training.thresholds import turbulence_reference

    des = calibrated_design(node_flight(aircraft, h_ft, vc_kts, turbulence, maneuvers), ENVELOPES[aircraft]["reference"])
    f = des.model.fdi
    logs = fly_training(des, training_seeds(REFERENCE_FLIGHTS), REFERENCE_DURATION_S, progress=False)
    probe = SimpleNamespace(n=decimation(float(des.model.rate_hz), float(f.rate_hz)), rate_hz=float(f.rate_hz),
                            arm_samples=int(round(f.arm_s * f.rate_hz)))
    ref = turbulence_reference(probe, logs, f"{REFERENCE_FLIGHTS} fault-free flights of {REFERENCE_DURATION_S:g} s "
                                            "at the calibrated design (the first training seeds)", estimate_spec(aircraft))
    return {"node": [h_ft, vc_kts, float(des.model.initial.flaps_deg), turbulence, maneuvers], "reference": ref}


def add_turbulence_reference(aircraft: str, path: Path, *, workers: int = 2, progress: bool = True) -> int:
    """Put the turbulence reference of every calibrated node and variant into the atlas file's
    thresholds entries (:func:`reference_task`); returns how many entries got one."""
    from distributed import as_completed

    from fdi_sim.study.execute import _client
    from fdi_sim.training.cache import cache_dir

    doc = json.loads(path.read_text())
    cache = str(cache_dir().parent / "atlas-build" / aircraft)
    todo = [n for n in doc["nodes"] if n["status"] == "ok"]
    client, cluster = _client(workers, None)
    out: dict[tuple, Any] = {}
    t0 = time.perf_counter()
    try:
        futs = [client.submit(reference_task, aircraft, n["h_ft"], n["vc_kts"], n["turbulence"], n["maneuvers"], cache,
                              pure=False) for n in todo]
        for i, fut in enumerate(as_completed(futs, loop=client.loop), 1):
            r = fut.result()
            out[tuple(r["node"])] = r["reference"]
            if progress:
                print(f"atlas {aircraft} turbulence reference: {i}/{len(futs)} {r['node']}: "
                      f"{r['reference']['sigma_ref']:.4g} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    n = 0
    for k, e in doc["entries"].items():
        ref = out.get(tuple(e["node"]))
        if k.startswith("bank:") and ref is not None:
            e["entry"]["turbulence_reference"] = ref
            n += 1
    for node in doc["nodes"]:
        ref = out.get((node["h_ft"], node["vc_kts"], node["flaps_deg"], node["turbulence"], node["maneuvers"]))
        node["sigma_ref"] = ref["sigma_ref"] if ref else None
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=None, separators=(",", ":")) + "\n")
    os.replace(tmp, path)
    return n


def main(argv: Sequence[str] | None = None) -> int:
    from fdi_sim.training.atlas import atlas_path

    ap = argparse.ArgumentParser(prog="python -m fdi_sim.study.atlas", description=__doc__.split("\n\n")[0])
    ap.add_argument("aircraft", choices=sorted(ENVELOPES))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None, help="default: aircraft/<aircraft>/fdi_atlas.json")
    ap.add_argument("--doublet-levels", default=None,
                    help="comma-separated levels at which the reference's maneuvers are also trained (default: all)")
    ap.add_argument("--turbulence-reference-only", action="store_true",
                    help="only add the turbulence estimate's reference to an existing atlas's entries")
    a = ap.parse_args(argv)
    out = a.out or atlas_path(a.aircraft)
    if a.turbulence_reference_only:
        n = add_turbulence_reference(a.aircraft, out, workers=a.workers)
        print(f"{out}: turbulence reference in {n} thresholds entries")
        return 0
    levels = None if a.doublet_levels is None else [x.strip() for x in a.doublet_levels.split(",") if x.strip()]
    doc = make_atlas(a.aircraft, out, workers=a.workers, doublet_levels=levels)
    add_turbulence_reference(a.aircraft, out, workers=a.workers)
    ok = sum(n["status"] == "ok" for n in doc["nodes"])
    print(f"{out}: {ok} of {len(doc['nodes'])} nodes calibrated, {len(doc['entries'])} entries")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

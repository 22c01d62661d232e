"""Flying a study on Dask, into a results folder that a crash cannot corrupt and a rerun resumes.

Results folder (``DIR``)::

    study.json            the study (its identity hash: a folder holds one study only)
    runs/000017.json      run 17's record: seed, status, metrics (written last: it marks the run done)
    runs/000017.mcap      its FDI topics (statistics at the detector rate), or the full log
    runs/000017.toml      its scenario: ``fdi-sim run DIR/runs/000017.toml`` flies it again
    results.json          the statistics (fdi_sim.study.stats.summarize), rewritten at the end
    report/index.html     the report (fdi_sim.study.report)

The store is one file per run, committed by rename (written to a hidden temporary name,
``fsync``-ed, then ``os.replace``-d), chosen over SQLite in WAL mode because (1) only the client
writes, so there is no concurrent-writer problem to solve, (2) a finished run is a file a user can
open, copy or delete with the shell, and the log beside it is a file anyway, (3) a crash at any
instant leaves either the old state or the new one, and a half-written run is a hidden temporary
file that the next start removes. A run is done when its ``.json`` exists; a rerun of the same
command flies exactly the runs without one.

Execution: every run is one Dask task, ``fly_run(index, scenario_json, ...)``, whose scenario the
client builds from the study file and the run index (:mod:`fdi_sim.study.spec`), so a run's
result does not depend on the worker. The runs wait on one design task per distinct bank design
(:func:`fdi_sim.study.spec.design_groups`), so a calibration is flown once, not by every worker
at once. Workers run one task at a time (``threads_per_worker = 1``); Dask's nanny starts them with
``OMP_NUM_THREADS = MKL_NUM_THREADS = OPENBLAS_NUM_THREADS = 1`` (``distributed.nanny.pre-spawn-environ``)
and JSBSim, numba (no parallel kernels) and the zstd writer use one thread each, so ``N``
workers use ``N`` cores. A task that raises is retried ``retries`` times; a worker that dies
(SIGKILL, out of memory) has its tasks moved to another (``distributed.scheduler.allowed-failures``
for a local cluster); a flight that raises is recorded as status ``error`` (a deterministic
failure: flying it again would fail again), one over ``time_limit_s`` as ``timeout``.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from fdi_sim import signals
from fdi_sim.errors import StudyError
from fdi_sim.study.spec import FULL_LOG_BYTES_PER_H, STATISTICS_BYTES_PER_H, Study, design_groups, scenario_toml
from fdi_sim.units import S_PER_H

#: the disk check's margin on the log sizes (spec.STATISTICS_BYTES_PER_H, spec.FULL_LOG_BYTES_PER_H)
DISK_MARGIN = 1.25
#: seconds the client waits for a scheduler to answer
CONNECT_TIMEOUT_S = 5.0
#: record keys that describe how a run was flown, not what it gave (differ between workers)
TIMING_KEYS = ("wall_s", "worker")


@dataclass(frozen=True)
class StudyOutcome:
    """What :func:`fly_study` did.

    Attributes
    ----------
    out_dir : Path
    total, done_before, flown, lost : int
        Runs of the study; finished before this call; finished by it; whose task failed for a
        reason not of the flight (a worker lost more than ``retries`` times: fly again to retry).
    interrupted : bool
        Ctrl-C or SIGTERM stopped it (every finished run is kept).
    wall_s : float
        This call's wall time, designs included [s].
    flight_h : float
        Flight hours this call flew [h].
    designs : int
        Bank designs this call needed (one per design group of the runs it flew).
    design_wall_s : float
        Their wall time summed over the workers [s]: seconds when every design came from the cache,
        minutes per design that flew its training flights (a cold call and a warm one told apart).
    """

    out_dir: Path
    total: int
    done_before: int
    flown: int
    lost: int
    interrupted: bool
    wall_s: float
    flight_h: float
    designs: int = 0
    design_wall_s: float = 0.0

    @property
    def complete(self) -> bool:
        return self.done_before + self.flown == self.total


# --- the results folder ------------------------------------------------------------------------
def run_name(index: int) -> str:
    return f"{index:06d}"


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def open_results(study: Study, out_dir: str | Path) -> Path:
    """Create or reopen a results folder for ``study``; refuse one of another study.

    Raises
    ------
    StudyError
        The folder holds another study (or is not a results folder and is not empty).
    """
    out = Path(out_dir)
    meta = out / "study.json"
    ident = study.identity()
    if meta.is_file():
        try:
            have = json.loads(meta.read_text())
        except (ValueError, OSError) as exc:
            raise StudyError(str(meta), "", f"unreadable ({exc})", "delete the folder or give another --out") from None
        if have.get("identity") != ident:
            raise StudyError(str(out), "", f"holds the runs of study {have.get('name')!r} (identity "
                             f"{have.get('identity')}), not of {study.name!r} as written now (identity {ident}): "
                             "the two would mix results of different studies",
                             "give another --out, or delete the folder to start again") from None
    else:
        if out.exists() and any(p.name != "report" for p in out.iterdir()):
            raise StudyError(str(out), "", "is not empty and is not a study's results folder (no study.json)",
                             "give a new or empty --out folder")
        (out / "runs").mkdir(parents=True, exist_ok=True)
        rec = {"identity": ident, "name": study.name, "source": study.source,
               "study": study.model.model_dump(mode="json"), "base_scenario": json.loads(study.base.to_json())}
        _write_atomic(meta, json.dumps(rec, indent=1).encode())
    (out / "runs").mkdir(parents=True, exist_ok=True)
    for p in (out / "runs").glob(".*.tmp*"):  # a write a crash cut short
        p.unlink(missing_ok=True)
    return out


def done_runs(out_dir: str | Path) -> set[int]:
    """Indices of the runs whose record is in the folder."""
    out = set()
    for p in (Path(out_dir) / "runs").glob("[0-9]*.json"):
        try:
            out.add(int(p.stem))
        except ValueError:
            pass
    return out


def load_records(out_dir: str | Path) -> list[dict[str, Any]]:
    """Every run record of a results folder, in index order."""
    recs = []
    for p in sorted((Path(out_dir) / "runs").glob("[0-9]*.json")):
        recs.append(json.loads(p.read_text()))
    return recs


def commit_run(out_dir: Path, index: int, record: dict[str, Any], log: bytes | None, scenario_text: str) -> None:
    """Store one finished run: log and scenario first, the record last (it marks the run done)."""
    runs = out_dir / "runs"
    name = run_name(index)
    if log is not None:
        _write_atomic(runs / f"{name}.mcap", log)
    _write_atomic(runs / f"{name}.toml", scenario_text.encode())
    _write_atomic(runs / f"{name}.json", json.dumps(record, indent=1, sort_keys=True).encode())


def check_disk(study: Study, out_dir: Path, remaining: int, remaining_h: float) -> None:
    """Refuse, before flying, a study whose logs would not fit on the disk."""
    o = study.model.output
    per_h = (FULL_LOG_BYTES_PER_H if o.full_logs else STATISTICS_BYTES_PER_H if o.statistics else 0.0)
    need = remaining_h * per_h * DISK_MARGIN
    free = shutil.disk_usage(out_dir).free
    if need > free:
        what = "full 120 Hz logs" if o.full_logs else "statistics logs"
        raise StudyError(study.source, "output.full_logs" if o.full_logs else "output.statistics",
                         f"{remaining} runs ({remaining_h:.1f} flight h) of {what} need about {need / 1e9:.1f} GB "
                         f"and {out_dir} has {free / 1e9:.1f} GB free",
                         "set output.full_logs = false (statistics only, ~50 x smaller), fly fewer runs, or give "
                         "--out on a larger disk")


# --- the tasks (run on the workers) -------------------------------------------------------------
def prepare_design(scenario_json: str, source: str) -> dict[str, Any]:
    """Design and calibrate one bank (cached on the worker's disk); returns its notes or the error."""
    from fdi_sim.errors import FdiSimError
    from fdi_sim.scenario.loader import from_dict
    from fdi_sim.sim.run import build_sensors
    from fdi_sim.training.build import build_loop_bank

    sc = from_dict(json.loads(scenario_json), source=source)
    t0 = time.perf_counter()
    try:
        bank = build_loop_bank(sc, build_sensors(sc, sc.dt_s), progress=False)
    except FdiSimError as exc:
        return {"error": str(exc)}
    notes = list(bank.notes) if bank is not None else []
    return {"error": None, "notes": notes, "wall_s": time.perf_counter() - t0}


def fly_run(index: int, scenario_json: str, source: str, time_limit_s: float, keep_log: bool,
            params: dict[str, Any], design: Any = None) -> dict[str, Any]:
    """Fly run ``index`` and return ``{"record": ..., "log": bytes | None}``.

    ``design`` is the run's design task's result: a dependency only (the bank comes from the cache).
    """
    import traceback

    import fdi_sim.training.build as training_build
    from fdi_sim.scenario.loader import from_dict

    try:
        from distributed import get_worker

        worker = get_worker().address
    except (ImportError, ValueError):
        worker = "local"
    if training_build.DESIGN_MEMO is None:
        training_build.DESIGN_MEMO = {}  # this process flies runs of shared designs
    sc = from_dict(json.loads(scenario_json), source=source)
    rec: dict[str, Any] = {"index": int(index), "seed": int(sc.seed), "scenario": f"{run_name(index)}.toml",
                           "params": params, "duration_s": float(sc.duration_s), "worker": worker}
    log = None
    with tempfile.TemporaryDirectory(prefix="fdi-sim-study-") as tmp:
        path = Path(tmp) / f"{run_name(index)}.mcap"
        t0 = time.perf_counter()
        try:
            res = training_build.fly(sc, log_path=path, progress=False, wall_limit_s=time_limit_s)
        except Exception as exc:  # the flight itself failed: deterministic, recorded, not retried
            rec.update(status="error", reason=f"{type(exc).__name__}: {exc}", t_end_s=0.0, flight_h=0.0,
                       wall_s=time.perf_counter() - t0, log=None, traceback=traceback.format_exc(limit=4))
            return {"record": rec, "log": None}
        s = res.summary
        status, reason = s.status, s.reason
        if status == "interrupted" and reason.startswith("wall-clock limit"):
            status = "timeout"
        rec.update(record_from_summary(s, sc))
        rec.update(status=status, reason=reason, wall_s=s.wall_s)
        if sc.faults and path.is_file():  # the injector's catalog: labels and the true fault windows
            from fdi_sim.flightlog import METADATA_FAULTS, read_log

            cat = json.loads(read_log(path).metadata.get(METADATA_FAULTS, {}).get("catalog", "[]"))
            if cat:
                rec["faults"] = cat
                types = {c["label"]: c["type"] for c in cat}
                for d in rec["detections"]:
                    d["type"] = types.get(d["fault"])
        if keep_log and path.is_file():
            log = path.read_bytes()
            rec["log"] = f"{run_name(index)}.mcap"
        else:
            rec["log"] = None
    return {"record": rec, "log": log}


def record_from_summary(s: Any, sc: Any) -> dict[str, Any]:
    """The metrics of a run record from a :class:`~fdi_sim.sim.run.RunSummary`."""
    f = sc.model.fdi

    def alarm(a: Any) -> dict[str, Any]:
        return {"detector": a.detector, "onset_t_s": a.onset_t_s, "end_t_s": a.end_t_s, "isolation": a.isolation}

    faults = []
    for (tid, p), raw in zip(sc.faults, sc.model.faults):
        faults.append({"type": tid, "target": raw.get("target"), "params": {k: v for k, v in raw.items()
                                                                            if k not in ("type", "target")}})
    labels = {}
    for d in s.fdi_detections:
        labels.setdefault(d.fault, d)
    return {
        "t_end_s": s.t_end_s, "flight_h": s.t_end_s / S_PER_H, "steps": s.steps,
        "max_abs_dh_ft": s.max_abs_dh_ft, "max_abs_dvc_kts": s.max_abs_dvc_kts,
        "detectors": list(s.fdi_detectors), "thresholds": dict(zip(s.fdi_detectors, s.fdi_thresholds)),
        "design_far_per_h": f.far_per_h, "rate_hz": f.rate_hz, "persistence": [f.persistence_k, f.persistence_n],
        "arm_s": f.arm_s, "decision": f.decision, "n_members": len(s.fdi_detectors),
        "faults": faults, "fault_labels": sorted(labels),
        "alarms": [alarm(a) for a in s.fdi_alarms], "false_alarms": [alarm(a) for a in s.fdi_false_alarms],
        "detections": [{"fault": d.fault, "target": d.target, "detector": d.detector, "onset_t_s": d.onset_t_s,
                        "detected_t_s": d.detected_t_s, "delay_s": d.delay_s, "isolation": d.isolation,
                        "isolation_correct": d.isolation_correct} for d in s.fdi_detections],
        "reconfigurations": [dict(r) for r in s.fdi_reconfigurations],
    }


# --- the client -----------------------------------------------------------------------------------
def _client(workers: int | None, scheduler: str | None) -> tuple[Any, Any]:
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s", set_as_default=False), None
        except (OSError, TimeoutError) as exc:
            raise StudyError(scheduler, "--scheduler", f"no Dask scheduler answers there within "
                             f"{CONNECT_TIMEOUT_S:g} s ({type(exc).__name__}: {exc})",
                             "start one (`dask scheduler`, then `dask worker ADDRESS --nthreads 1` per core) "
                             "or leave out --scheduler to use a local cluster") from None
    n = int(workers) if workers else (os.cpu_count() or 1)
    with dask.config.set({"distributed.scheduler.allowed-failures": 3}), _environ_kept():
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    return Client(cluster, set_as_default=False), cluster


@contextlib.contextmanager
def _environ_kept() -> Iterator[None]:
    """Restore the client's environment after Dask's nannies start: they apply their
    ``pre-spawn-environ`` (``OMP/MKL/OPENBLAS_NUM_THREADS=1``) to this process's ``os.environ`` and
    leave it there, so a subprocess started afterwards (``fdi-sim study --calibrate`` in a test)
    inherited one BLAS thread (measured in session 10: None before the cluster, "1" after)."""
    before = dict(os.environ)
    try:
        yield
    finally:
        for k in set(os.environ) - set(before):
            del os.environ[k]
        for k, v in before.items():
            if os.environ.get(k) != v:
                os.environ[k] = v


def fly_study(study: Study, out_dir: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              progress: bool = True, client: Any = None) -> StudyOutcome:
    """Fly every run of ``study`` not yet in ``out_dir``; store each as it finishes.

    Parameters
    ----------
    study : Study
    out_dir : path
        The results folder (created; reopened to resume).
    workers : int, optional
        Worker processes of the local cluster (default: the cores); ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    progress : bool
        A bar with flight hours per second and the ETA (stderr).
    client : distributed.Client, optional
        An existing client to use (neither closed nor its cluster).

    Returns
    -------
    StudyOutcome

    Raises
    ------
    StudyError
        A folder of another study, a scheduler that does not answer, too little disk: before any run
        flies; a bank that cannot be designed: when its design task ends (runs of other designs
        finished by then are kept).
    """
    held: dict[str, Any] = {"client": client, "cluster": None}
    if client is None and scheduler:  # a scheduler that does not answer: said before the folder is made
        held["client"], _ = _client(workers, scheduler)
    try:
        return _fly(study, out_dir, workers, held, progress)
    finally:
        if client is None and held["client"] is not None:  # ours: closed however the study ended
            held["client"].close()
            if held["cluster"] is not None:
                held["cluster"].close()


def _fly(study: Study, out_dir: str | Path, workers: int | None, held: dict[str, Any], progress: bool) -> StudyOutcome:
    from distributed import as_completed

    out = open_results(study, out_dir)
    indices = study.run_indices()
    total = len(indices)
    done = done_runs(out) & set(indices)
    todo = [i for i in indices if i not in done]
    todo_h = sum(study.run_duration_s(i) for i in todo) / S_PER_H
    check_disk(study, out, len(todo), todo_h)
    t0 = time.perf_counter()
    if not todo:
        return StudyOutcome(out, total, len(done), 0, 0, False, 0.0, 0.0)
    planned = [(i, *study.run_scenario(i)) for i in todo]
    groups, keys = design_groups([sc for _, sc, _ in planned])
    if len(groups) > max(32, len(todo) // 4):  # a grid has tens of nodes; one design per run is the mistake
        raise StudyError(study.source, "bank.design", f"the runs need {len(groups)} different bank designs "
                         f"(one per sampled value of a key the bank is designed for): each is calibrated on "
                         f"{study.base.model.fdi.calibration_flights if 'calibration_flights' not in study.model.bank else study.model.bank['calibration_flights']} "
                         "training flights of its own",
                         'design the bank at nominal conditions: bank.design = { point = "grid", turbulence = '
                         '"moderate", wind_speed_kts = 0.0, noise_scale = 1.0 } (keep only what you sample)')
    if held["client"] is None:  # a local cluster, started only when there is something to fly
        held["client"], held["cluster"] = _client(workers, None)
    client = held["client"]
    keep = study.model.output.statistics or study.model.output.full_logs
    flown = lost = 0
    hours = 0.0
    interrupted = False
    bar = _bar(todo_h, progress, study.name)
    futures: list[Any] = []
    design_futs: dict[str, Any] = {}
    design_wall_s = 0.0
    try:
        key_of = {i: k for (i, _, _), k in zip(planned, keys)}
        for key, sc in groups.items():
            design_futs[key] = client.submit(prepare_design, sc.to_json(), sc.source, key=f"design-{key}",
                                             retries=study.model.retries, pure=False)
        if bar is not None:
            bar.set_postfix_str(f"designing {len(groups)} bank(s) (cached: at once)")
        texts = {}
        for i, sc, params in planned:
            texts[i] = scenario_toml(sc)
            futures.append(client.submit(fly_run, i, sc.to_json(), sc.source, study.model.time_limit_s, keep,
                                         params, design_futs[key_of[i]], key=f"run-{study.identity()}-{i}",
                                         retries=study.model.retries, pure=False))
        alarms = designed = 0
        if signals.stop_requested():
            raise KeyboardInterrupt
        is_design = {f.key for f in design_futs.values()}
        # designs and runs as they finish: a run of a finished design is stored while other designs
        # still fly their training flights (a study of many designs showed nothing for minutes)
        for fut in as_completed([*design_futs.values(), *futures], loop=client.loop):
            if signals.stop_requested():  # a Ctrl-C or SIGTERM whose exception was dropped (fdi_sim.signals)
                raise KeyboardInterrupt
            if fut.key in is_design:
                r = fut.result()
                if r.get("error"):
                    raise StudyError(study.source, "bank", f"the bank cannot be designed: {r['error']}",
                                     "fix the bank section or the sampled point (or bank.on_design_failure = \"skip\")")
                designed += 1
                design_wall_s += float(r.get("wall_s", 0.0))
                if bar is not None and designed < len(design_futs):
                    bar.set_postfix_str(f"{designed}/{len(design_futs)} bank designs ready, {flown} runs stored")
                continue
            try:
                res = fut.result()
            except Exception as exc:  # a worker lost too often, a task cancelled: not the flight's fault
                lost += 1
                if bar is not None:
                    bar.write(f"run lost ({type(exc).__name__}: {exc}); fly the study again to retry it")
                continue
            finally:
                fut.release()
            rec = res["record"]
            commit_run(out, rec["index"], rec, res["log"], texts.pop(rec["index"]))
            flown += 1
            hours += rec.get("flight_h", 0.0)
            alarms += len(rec.get("false_alarms", []))
            if bar is not None:
                bar.update(study.run_duration_s(rec["index"]) / S_PER_H)
                bar.set_postfix_str(f"{flown}/{len(todo)} runs, {alarms} false alarms, "
                                    f"{hours * S_PER_H / max(time.perf_counter() - t0, 1e-9):.0f} sim s/s")
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
        try:
            client.cancel(futures, force=True)  # runs not finished are not wanted any more
        except Exception:  # noqa: BLE001 - closing anyway
            pass
    return StudyOutcome(out, total, len(done), flown, lost, interrupted, time.perf_counter() - t0, hours,
                        len(design_futs), design_wall_s)


def _bar(total_h: float, progress: bool, name: str) -> Any:
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total_h, unit="fh", desc=name, file=sys.stderr, dynamic_ncols=True,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} flight h "
                           "[{elapsed}<{remaining}, {rate_fmt}] {postfix}")

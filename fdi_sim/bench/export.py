"""``fdi-sim export`` and external scores: labelled datasets in Parquet, and score files read back.

Export (reads a benchmark results folder's logs and labels only; flies nothing)::

    OUT/suite.json          suite, suite_hash, bank, grid_hz, the fdi-sim version, the schema below
    OUT/cases.parquet       one row per scored flight (completed or departed: fdi_sim.bench.score):
                            case, index, split, aircraft, group, phase, fault_type, fault_class,
                            target, size, size_rank, negative, arm_s, t_end_s, status, faulty (the
                            per-flight label)
    OUT/events.parquet      one row per fault window: case, fault_class, fault_type, target, size,
                            onset_s, end_s
    OUT/topics/<topic>.parquet
                            each vector topic of the logs on the log clock: case, t_s, its fields
                            (``/fdi/kalman-gust-v1/statistic`` -> ``fdi.kalman-gust-v1.statistic.parquet``;
                            a topic whose fields differ between cases, a fault's own, gets one file
                            per field set, ``<topic>.<hash of the fields>.parquet``); the truth and
                            fault topics are there for analysis: never a learner's input
    OUT/grid.<aircraft>.parquet
                            every case on the scorer's uniform grid (fdi_sim.scoring.GRID_HZ)
                            from 0 to t_end_s: case, split, t_s, label (1 fault, 0 fault-free, -1 the
                            grace after a window: left out by the scorer), then the fields of the
                            measurement, command and bank topics (:data:`GRID_TOPICS`) held from their
                            latest sample (``<topic>.<field>``, NaN before the first); cases whose
                            columns differ from the first of their aircraft (another member set) go
                            to ``grid.<aircraft>.<hash of the columns>.parquet``

A benchmark run keeps the FDI topics (statistics at the detector rate) by default; with
``--full-logs`` the 120 Hz sensor, command and truth topics too (their size per flight hour is
:data:`fdi_sim.study.spec.FULL_LOG_BYTES_PER_H`), which is what a learned detector trains on.

External scores (``fdi-sim bench score``): Parquet or CSV with columns ``case`` (string), ``t_s``
(seconds of the case's log clock), ``score`` (float, larger = more faulty) and/or ``alarm`` (0/1),
optionally ``isolation`` (a hypothesis name), and the suite's hash, as a ``suite_hash`` column or
as the Parquet key-value metadata ``fdi_bench.suite_hash``. Refused with the file, the problem and
the fix (exit 2): another suite's hash, cases missing or unknown, duplicate or unsorted timestamps
within a case, times outside ``[0, t_end_s]``, no score and no alarm.
"""
from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fdi_sim.bench.errors import BenchError
from fdi_sim.bench.suite import Case
from fdi_sim.scoring import GRID_HZ, CaseOutput, CaseTruth

SCHEMA_VERSION = 1
#: written by ``bench run`` beside the runs: the suite's labels of every case in the folder
CASES_FILE = "bench_cases.json"
#: Parquet metadata key of a scores file's suite hash
HASH_KEY = b"fdi_bench.suite_hash"
#: the topics the grid holds: what a detector can see (measurements, commands) and the in-loop bank's
#: outputs; never /truth or /faults (they would hand a learner its label)
GRID_TOPICS = ("/sensors/", "/commands/", "/fdi/")
#: a time this far past the end of the flight is still inside it [s] (the log's last sample)
T_TOL_S = 1e-6


#: the run statuses a benchmark scores: completed, and departed up to the departure (fdi_sim.bench.score)
SCORED_STATUSES = ("completed", "diverged")


def case_truth(case: Case, record: Mapping[str, Any]) -> CaseTruth:
    """A flown case's label: the injector's windows (clipped to the flight's end), arming and end."""
    t_end = float(record["t_end_s"])
    windows = tuple((float(a), min(float(b), t_end)) for f in record.get("faults", []) for a, b in f.get("windows_s", [])
                    if float(a) <= t_end)
    return CaseTruth(case.case, case.aircraft, case.group, case.split, case.fault_type, case.target, case.size,
                     case.size_rank, tuple(sorted(windows)), float(record.get("arm_s") or 0.0), t_end, case.negative)


def write_cases_file(out_dir: Path, suite: Any) -> None:
    """The suite's labels of every case, beside the runs (``bench run`` writes it; export reads it)."""
    from fdi_sim.study.execute import _write_atomic

    rec = {"suite": suite.name, "suite_hash": suite.hash, "cases": [
        {k: getattr(c, k) for k in ("index", "case", "aircraft", "group", "phase", "split", "fault_type", "target",
                                    "size", "size_rank", "negative", "duration_s")} for c in suite.cases]}
    _write_atomic(out_dir / CASES_FILE, json.dumps(rec).encode())


def read_cases_file(folder: Path) -> dict[str, Any]:
    p = folder / CASES_FILE
    try:
        return json.loads(p.read_text())
    except OSError:
        raise BenchError(str(folder), "", f"no {CASES_FILE}: not a benchmark results folder",
                         "give the folder `fdi-sim bench run --out DIR` wrote") from None


@dataclass(frozen=True)
class ExportOutcome:
    out_dir: Path
    cases: int
    skipped: int
    topics: int
    grid_rows: int
    bytes: int


def _topic_file(topic: str) -> str:
    return topic.strip("/").replace("/", ".") + ".parquet"


def export(results_dir: str | Path, out_dir: str | Path, *, grid_hz: float = GRID_HZ,
           progress: bool = False) -> ExportOutcome:
    """Write the labelled dataset of a benchmark results folder (module docstring).

    Raises
    ------
    BenchError
        Not a results folder, or an output folder that cannot be written (nothing half-written is
        left as a dataset: the files are written under a temporary name, then renamed).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from fdi_sim.flightlog import VectorTopic, read_log
    from fdi_sim.scoring import sample_grid
    from fdi_sim.study.execute import load_records

    src = Path(results_dir)
    meta = read_cases_file(src)
    by_index = {int(c["index"]): c for c in meta["cases"]}
    out = Path(out_dir)
    try:
        (out / "topics").mkdir(parents=True, exist_ok=True)
        probe = out / ".write-probe"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise BenchError(str(out), "--out", f"cannot be written ({exc.strerror})", "give a folder you can write") from None
    study = json.loads((src / "study.json").read_text())
    recs = [r for r in load_records(src) if int(r["index"]) in by_index]
    writers: dict[str, Any] = {}
    grid_writers: dict[str, Any] = {}
    case_rows, event_rows = [], []
    skipped = grid_rows = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(recs), unit="case", desc="export")
    try:
        for r in recs:
            if bar is not None:
                bar.update(1)
            c = by_index[int(r["index"])]
            if r.get("status") not in SCORED_STATUSES or not r.get("log"):
                skipped += 1
                continue
            case = _case_obj(c)
            truth = case_truth(case, r)
            log = read_log(src / "runs" / r["log"])
            case_rows.append({**{k: c[k] for k in ("case", "index", "split", "aircraft", "group", "phase", "fault_type",
                                                    "target", "size", "size_rank", "negative")},
                              "fault_class": truth.fault_class, "arm_s": truth.arm_s, "t_end_s": truth.t_end_s,
                              "status": r["status"],
                              "faulty": bool(truth.windows_s)})
            for w0, w1 in truth.windows_s:
                event_rows.append({"case": c["case"], "fault_class": truth.fault_class, "fault_type": c["fault_type"],
                                   "target": c["target"], "size": c["size"], "onset_s": w0, "end_s": w1})
            full = CaseTruth(truth.case, truth.aircraft, truth.group, truth.split, truth.fault_type, truth.target,
                             truth.size, truth.size_rank, truth.windows_s, 0.0, truth.t_end_s, truth.negative)
            lab, _, _ = sample_grid(full, CaseOutput(np.zeros(1), np.zeros(1, bool)), grid_hz=grid_hz)
            g = np.arange(lab.size) / grid_hz
            cols: dict[str, Any] = {"case": pa.array([c["case"]] * g.size, pa.string()),
                                    "split": pa.array([c["split"]] * g.size, pa.string()),
                                    "t_s": pa.array(g), "label": pa.array(lab)}
            for topic in sorted(log.topics):
                data = log.topics[topic]
                if not isinstance(data, VectorTopic) or not len(data):
                    continue
                arr = data.as_array()
                tbl = pa.table({"case": pa.array([c["case"]] * len(data), pa.string()),
                                **{f: pa.array(arr[:, j]) for j, f in enumerate(data.fields)}})
                name = _topic_file(topic)
                if name in writers and not writers[name].schema.equals(tbl.schema):
                    # a fault's own topic names its target's fields: one file per field set
                    sig = hashlib.sha256(",".join(data.fields).encode()).hexdigest()[:8]
                    name = name.removesuffix(".parquet") + f".{sig}.parquet"
                if name not in writers:
                    writers[name] = pq.ParquetWriter(out / "topics" / f".{name}.tmp", tbl.schema)
                writers[name].write_table(tbl)
                if not topic.startswith(GRID_TOPICS):
                    continue  # truth and fault state would leak the label into a learner's features
                k = np.searchsorted(arr[:, 0], g + 1e-9, side="right") - 1
                for j, f in enumerate(data.fields[1:], start=1):
                    col = np.full(g.size, np.nan)
                    col[k >= 0] = arr[k[k >= 0], j]
                    cols[f"{topic.strip('/').replace('/', '.')}.{f}"] = pa.array(col)
            gt = pa.table(cols)
            gname = f"grid.{c['aircraft']}.parquet"  # the aircraft's sensors differ (the DHC-6's engine gauges)
            if gname in grid_writers and not grid_writers[gname].schema.equals(gt.schema):
                gname = gname.removesuffix(".parquet") + "." + hashlib.sha256(
                    ",".join(gt.column_names).encode()).hexdigest()[:8] + ".parquet"  # another bank member set
            if gname not in grid_writers:
                grid_writers[gname] = pq.ParquetWriter(out / f".{gname}.tmp", gt.schema)
            grid_writers[gname].write_table(gt)
            grid_rows += gt.num_rows
    finally:
        if bar is not None:
            bar.close()
        for w in writers.values():
            w.close()
        for w in grid_writers.values():
            w.close()
    for name in writers:
        (out / "topics" / f".{name}.tmp").replace(out / "topics" / name)
    for name in grid_writers:
        (out / f".{name}.tmp").replace(out / name)
    pq.write_table(pa.Table.from_pylist(case_rows), out / "cases.parquet")
    ev_schema = pa.schema([("case", pa.string()), ("fault_class", pa.string()), ("fault_type", pa.string()),
                           ("target", pa.string()), ("size", pa.string()), ("onset_s", pa.float64()),
                           ("end_s", pa.float64())])
    pq.write_table(pa.Table.from_pylist(event_rows, schema=ev_schema), out / "events.parquet")
    from fdi_sim import __version__

    (out / "suite.json").write_text(json.dumps({
        "suite": meta["suite"], "suite_hash": meta["suite_hash"], "bank": study.get("study", {}).get("bank"),
        "grid_hz": grid_hz, "fdi_sim": __version__, "schema_version": SCHEMA_VERSION, "source": str(src),
        "cases": len(case_rows), "skipped_not_scored": skipped}, indent=1))
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return ExportOutcome(out, len(case_rows), skipped, len(writers), grid_rows, size)


def _case_obj(c: Mapping[str, Any]) -> Case:
    return Case(int(c["index"]), c["case"], c["aircraft"], c["group"], c["phase"], c["split"], c["fault_type"],
                c["target"], c["size"], int(c["size_rank"]), c["negative"], float(c["duration_s"]), "{}", "{}")


# --- external scores ----------------------------------------------------------------------------
def read_truths(export_dir: str | Path) -> tuple[dict[str, Any], list[CaseTruth]]:
    """An export's suite record and its cases' labels."""
    import pyarrow.parquet as pq

    d = Path(export_dir)
    try:
        meta = json.loads((d / "suite.json").read_text())
        cases = pq.read_table(d / "cases.parquet").to_pylist()
        events = pq.read_table(d / "events.parquet").to_pylist()
    except (OSError, ValueError) as exc:
        raise BenchError(str(d), "--export", f"not an export folder ({exc})",
                         "give the folder `fdi-sim export RESULTS --out DIR` wrote") from None
    win: dict[str, list[tuple[float, float]]] = {}
    for e in events:
        win.setdefault(e["case"], []).append((float(e["onset_s"]), float(e["end_s"])))
    truths = [CaseTruth(c["case"], c["aircraft"], c["group"], c["split"], c["fault_type"], c["target"], c["size"],
                        int(c["size_rank"]), tuple(sorted(win.get(c["case"], []))), float(c["arm_s"]),
                        float(c["t_end_s"]), c["negative"]) for c in cases]
    return meta, truths


def read_scores(path: str | Path, truths: Sequence[CaseTruth], suite_hash: str, *,
                threshold: float | None = None) -> dict[str, CaseOutput]:
    """A scores file as outputs per case, checked against the cases it must score (module docstring).

    Raises
    ------
    BenchError
        Every refusal names the file, the problem and the fix.
    """
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise BenchError(src, "--scores", "no such file", "give the path of a Parquet (.parquet) or CSV (.csv) scores file")
    try:
        if p.suffix.lower() == ".csv":
            table = pcsv.read_csv(p, convert_options=pcsv.ConvertOptions(
                column_types={"case": pa.string(), "isolation": pa.string(), "suite_hash": pa.string()}))
            kv: dict[bytes, bytes] = {}
        else:
            table = pq.read_table(p)
            kv = dict(table.schema.metadata or {})
    except (OSError, pa.ArrowInvalid) as exc:
        raise BenchError(src, "--scores", f"cannot be read as {'CSV' if p.suffix.lower() == '.csv' else 'Parquet'} "
                         f"({exc})", "give a Parquet (.parquet) or CSV (.csv) file with columns case, t_s, score "
                         "and/or alarm") from None
    cols = set(table.column_names)
    for need in ("case", "t_s"):
        if need not in cols:
            raise BenchError(src, need, f"no {need!r} column (columns: {sorted(cols)})",
                             "write columns case, t_s, score and/or alarm (docs/bench.md)")
    if "score" not in cols and "alarm" not in cols:
        raise BenchError(src, "score", "neither a score nor an alarm column", "write one of them (or both)")
    if "alarm" not in cols and threshold is None:
        raise BenchError(src, "alarm", "scores without alarms", "add an alarm column, or give --threshold X "
                         "(alarm = score > X)")
    have_hash = None
    if HASH_KEY in kv:
        have_hash = kv[HASH_KEY].decode()
    elif "suite_hash" in cols:
        hs = set(table.column("suite_hash").to_pylist())
        if len(hs) != 1:
            raise BenchError(src, "suite_hash", f"{len(hs)} different suite hashes in one file", "score one suite per file")
        have_hash = str(hs.pop())
    if have_hash is None:
        raise BenchError(src, "suite_hash", "the file does not say which suite it scores",
                         f"add a suite_hash column (or Parquet metadata {HASH_KEY.decode()}) = {suite_hash}")
    if have_hash != suite_hash:
        raise BenchError(src, "suite_hash", f"scores suite {have_hash[:16]}..., not this export's {suite_hash[:16]}...",
                         "score the export of the suite the file was made for, or remake the scores on this one")
    case = np.asarray(table.column("case").to_pylist(), dtype=object)
    t = np.asarray(table.column("t_s").to_numpy(zero_copy_only=False), dtype=float)
    if not np.all(np.isfinite(t)):
        raise BenchError(src, "t_s", f"{int(np.sum(~np.isfinite(t)))} times are NaN or infinite", "give every row a time")
    score = np.asarray(table.column("score").to_numpy(zero_copy_only=False), dtype=float) if "score" in cols else None
    alarm = (np.asarray(table.column("alarm").to_numpy(zero_copy_only=False), dtype=float) > 0.5) if "alarm" in cols \
        else (np.nan_to_num(score, nan=-np.inf) > float(threshold))  # type: ignore[arg-type]
    iso = table.column("isolation").to_pylist() if "isolation" in cols else None
    by_case = {tr.case: tr for tr in truths}
    order = np.argsort(case.astype(str), kind="stable")
    names, starts = np.unique(case[order].astype(str), return_index=True)
    unknown = [n for n in names if n not in by_case]
    if unknown:
        raise BenchError(src, "case", f"{len(unknown)} case(s) not in the export (first {unknown[:3]})",
                         "score only the export's cases (cases.parquet)")
    missing = sorted(set(by_case) - set(names))
    if missing:
        raise BenchError(src, "case", f"{len(missing)} of the {len(by_case)} cases to score are missing "
                         f"(first {missing[:3]})", "give every case of the split a row per sample "
                         "(or choose the split you scored with --split)")
    outs: dict[str, CaseOutput] = {}
    bounds = list(starts) + [len(order)]
    for n, a, b in zip(names, bounds[:-1], bounds[1:]):
        idx = order[a:b]
        tt = t[idx]
        if np.any(np.diff(tt) < 0):
            raise BenchError(src, "t_s", f"case {n}: times are not in order", "sort each case's rows by t_s")
        if np.any(np.diff(tt) == 0):
            raise BenchError(src, "t_s", f"case {n}: duplicate timestamps (first at {tt[np.flatnonzero(np.diff(tt) == 0)[0]]:g} s)",
                             "one row per sample time")
        tr = by_case[n]
        if tt[0] < 0.0 or tt[-1] > tr.t_end_s + T_TOL_S:
            raise BenchError(src, "t_s", f"case {n}: times {tt[0]:g}..{tt[-1]:g} s outside its flight [0, {tr.t_end_s:g}] s",
                             "use the case's log clock (seconds from its start, as in the export)")
        outs[n] = CaseOutput(tt, alarm[idx], None if score is None else score[idx],
                             None if iso is None else [iso[k] for k in idx])
    return outs


def scores_file_for(outputs: Mapping[str, CaseOutput], path: str | Path, suite_hash: str) -> Path:
    """Write outputs as a scores file (Parquet with the suite's hash): what an external method hands in."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows_case, rows_t, rows_s, rows_a = [], [], [], []
    for n, o in outputs.items():
        rows_case += [n] * len(o.t_s)
        rows_t.append(np.asarray(o.t_s, float))
        rows_s.append(np.asarray(o.score, float) if o.score is not None else np.full(len(o.t_s), math.nan))
        rows_a.append(np.asarray(o.alarm, bool).astype(np.int8))
    t = pa.table({"case": pa.array(rows_case, pa.string()), "t_s": pa.array(np.concatenate(rows_t)),
                  "score": pa.array(np.concatenate(rows_s)), "alarm": pa.array(np.concatenate(rows_a))})
    t = t.replace_schema_metadata({HASH_KEY: suite_hash.encode()})
    pq.write_table(t, path)
    return Path(path)

"""Two runs of one scenario side by side (``fdi-sim review A.mcap B.mcap``).

For example two banks, two seeds, or the same flight with and without reconfiguration. The two
logs must come from the same scenario (same name and aircraft); :func:`compare_logs` refuses
others, naming what differs. The comparison lists both runs' headline numbers side by side,
each detector's detection delay and isolation per fault, and the scenario keys that differ
(seed, ``[fdi]``, faults, ...), read from the scenario text stored in each log.
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from fdi_sim.errors import ReviewError
from fdi_sim.flightlog.reader import FlightLog
from fdi_sim.review.run_review import RunReview, open_log, review_flight_log


@dataclass(frozen=True)
class Comparison:
    """Two reviews of runs of one scenario.

    Attributes
    ----------
    a, b : RunReview
    rows : tuple of (str, str, str)
        ``(label, value in A, value in B)``: the headline and per-detector numbers.
    scenario_changes : tuple of str
        ``key: A -> B`` for every scenario key that differs (dotted TOML paths).
    logs : tuple of FlightLog
        The two logs read (for the report's figures; not compared).
    """

    a: RunReview
    b: RunReview
    rows: tuple[tuple[str, str, str], ...]
    scenario_changes: tuple[str, ...]
    logs: tuple[FlightLog, ...] = field(default=(), compare=False, repr=False)

    def differing(self) -> tuple[tuple[str, str, str], ...]:
        """The rows whose values differ."""
        return tuple(r for r in self.rows if r[1] != r[2])

    def format(self) -> str:
        """The two runs' numbers side by side, then what differs in the scenario."""
        wl = max([len("scenario"), *(len(r[0]) for r in self.rows)]) + 2
        wa = max([len("A"), *(len(r[1]) for r in self.rows)]) + 2
        out = [f"{'A':{wl}}{self.a.path}", f"{'B':{wl}}{self.b.path}",
               f"{'scenario':{wl}}{self.a.scenario} ({self.a.aircraft})", "",
               f"{'':{wl}}{'A':{wa}}B"]
        for label, va, vb in self.rows:
            mark = "" if va == vb else "   *"
            out.append(f"{label:{wl}}{va:{wa}}{vb}{mark}")
        out.append("")
        if self.scenario_changes:
            out.append("scenario differences (A -> B):")
            out += [f"  {c}" for c in self.scenario_changes]
        else:
            out.append("scenario differences: none (the same scenario text)")
        return "\n".join(out)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict (``--json``)."""
        return {"a": self.a.to_dict(), "b": self.b.to_dict(),
                "rows": [{"label": r[0], "a": r[1], "b": r[2]} for r in self.rows],
                "scenario_changes": list(self.scenario_changes)}


def _flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_flatten(v, key + "."))
        elif isinstance(v, list) and v and all(isinstance(x, Mapping) for x in v):
            for i, x in enumerate(v):
                out.update(_flatten(x, f"{key}[{i}]."))
        else:
            out[key] = v
    return out


def scenario_changes(a: RunReview, b: RunReview) -> tuple[str, ...]:
    """``key: A -> B`` for each scenario key that differs: from the validated scenario JSON in the
    logs' metadata (every key, defaults included), else from the TOML texts."""
    try:
        if a.scenario_json and b.scenario_json:
            fa, fb = _flatten(json.loads(a.scenario_json)), _flatten(json.loads(b.scenario_json))
        else:
            fa, fb = _flatten(tomllib.loads(a.scenario_text)), _flatten(tomllib.loads(b.scenario_text))
    except (tomllib.TOMLDecodeError, json.JSONDecodeError):
        return () if a.scenario_text == b.scenario_text else ("the scenario texts differ (not parseable)",)
    out = []
    for k in sorted(set(fa) | set(fb), key=lambda k: (k.count("."), k)):
        va, vb = fa.get(k, "(absent)"), fb.get(k, "(absent)")
        if va != vb:
            out.append(f"{k}: {va!r} -> {vb!r}")
    return tuple(out)


def _detection(r: RunReview, det: str, fault: str) -> str:
    for d in next((x.detections for x in r.detectors if x.id == det), ()):
        if d.fault == fault:
            if d.detected_t_s is None:
                return "not detected"
            mark = "" if d.isolation_correct is None else (" right" if d.isolation_correct else " wrong")
            return f"{d.delay_s:.2f} s, {d.isolation or 'not isolated'}{mark}"
    return "-"


def _far(r: RunReview) -> str:
    if r.bank_far_per_h is None:
        return f"{r.bank_false_alarms} (no exposure)"
    return f"{r.bank_false_alarms} ({r.bank_far_per_h:.3g} /h, <= {r.bank_far_ci_per_h[1]:.3g})"


def compare_reviews(a: RunReview, b: RunReview, logs: tuple[FlightLog, ...] = ()) -> Comparison:
    """The comparison of two reviews.

    Raises
    ------
    ReviewError
        Different scenario name or aircraft.
    """
    for what, va, vb in (("scenario", a.scenario, b.scenario), ("aircraft", a.aircraft, b.aircraft)):
        if va != vb:
            raise ReviewError(b.path, f"a run of another {what} than {a.path} ({what} {vb!r}, not {va!r}): the "
                              "comparison is for two runs of one scenario",
                              "compare two logs of the same scenario, or review each with `fdi-sim review LOG`")
    rows: list[tuple[str, str, str]] = [
        ("seed", str(a.seed), str(b.seed)),
        ("ended", a.ending, b.ending),
        ("flown", f"{a.duration_s:.2f} s", f"{b.duration_s:.2f} s"),
        ("bank", f"{len(a.bank)} members" if a.bank else "none", f"{len(b.bank)} members" if b.bank else "none"),
    ]
    if set(a.bank) != set(b.bank):
        rows.append(("members only in one", ", ".join(sorted(set(a.bank) - set(b.bank))) or "-",
                     ", ".join(sorted(set(b.bank) - set(a.bank))) or "-"))
    labels = list(dict.fromkeys([f.label for f in a.faults] + [f.label for f in b.faults]))
    for lab in labels:
        rows.append((f"{lab} first alarm", _first(a.first_detection(lab)), _first(b.first_detection(lab))))
    rows.append(("false alarms (bank)", _far(a), _far(b)))
    rows.append(("reconfigured", ", ".join(f"{x.sensor} {x.t_s:.2f} s" for x in a.reconfigurations) or "no",
                 ", ".join(f"{x.sensor} {x.t_s:.2f} s" for x in b.reconfigurations) or "no"))
    rows.append(("failure-log onsets", str(sum(x.event == "onset" for x in a.failure_log)),
                 str(sum(x.event == "onset" for x in b.failure_log))))
    for det in dict.fromkeys(a.bank + b.bank):
        for lab in labels:
            rows.append((f"{det} {lab}", _detection(a, det, lab), _detection(b, det, lab)))
        ea = next((x for x in a.detectors if x.id == det), None)
        eb = next((x for x in b.detectors if x.id == det), None)
        rows.append((f"{det} episodes/false", "-" if ea is None else f"{len(ea.episodes)}/{ea.false_alarms}",
                     "-" if eb is None else f"{len(eb.episodes)}/{eb.false_alarms}"))
    return Comparison(a, b, tuple(rows), scenario_changes(a, b), logs)


def _first(d: Any) -> str:
    if d is None:
        return "not detected"
    mark = "" if d.isolation_correct is None else (" right" if d.isolation_correct else " wrong")
    return f"{d.detected_t_s:.2f} s by {d.detector} ({d.isolation or 'not isolated'}{mark})"


def compare_logs(a: str | Path, b: str | Path) -> Comparison:
    """Compare two logs of the same scenario.

    Parameters
    ----------
    a, b : str or Path
        MCAP logs (cut-off ones are read from repaired temporary copies, as :func:`review_log`).

    Raises
    ------
    ReviewError
        Either log unreadable or not an fdi-sim log; the two of different scenarios or aircraft;
        the same file twice.
    """
    if Path(a).resolve() == Path(b).resolve():
        raise ReviewError(str(b), "the same file as the first log", "give two different logs of one scenario")
    la, na = open_log(a)
    lb, nb = open_log(b)
    ra, rb = review_flight_log(la, str(a), na), review_flight_log(lb, str(b), nb)
    return compare_reviews(ra, rb, (la, lb))

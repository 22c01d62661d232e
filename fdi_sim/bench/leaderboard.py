"""The leaderboard: one row per scored method of benchmark results folders, in Markdown and HTML.

Ranked by the ALFA criterion's F1 (detected within 5 s of the onset, no alarm before it; see
:mod:`fdi_sim.scoring`), then by the event-level F1. Beside each row: whether it beats the ALFA
dataset's best-known published detector, Keipour, Mousaei & Scherer's recursive least squares
(2019; precision 88.23 %, recall 88.23 %, mean detection time 2.02 s on 47 real flights), on the
ALFA criterion as a whole and per fault class. The two are not the same flights: ALFA's are a
fixed-wing UAV's real engine and surface failures, ours simulated; the column says which of our
methods reach that bar here, not that they would there.
"""
from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fdi_sim.bench.errors import BenchError

#: Keipour, Mousaei & Scherer (2019), RLS on ALFA: precision, recall, mean detection time [s]
ALFA_RLS = {"precision": 0.8823, "recall": 0.8823, "mean_detection_time_s": 2.02}


@dataclass(frozen=True)
class Row:
    method: str
    bank: str
    suite: str
    suite_hash: str
    split: str
    scores: dict[str, Any]

    @property
    def beats_alfa(self) -> bool:
        a = self.scores["alfa"]
        return _beats(a)

    @property
    def beats_alfa_classes(self) -> list[str]:
        return [k for k, a in self.scores.get("alfa_by_class", {}).items() if _beats(a)]


def _beats(a: dict[str, Any]) -> bool:
    p, r = a.get("precision"), a.get("recall")
    return p is not None and r is not None and p > ALFA_RLS["precision"] and r > ALFA_RLS["recall"]


def leaderboard_rows(folders: Sequence[Path], split: str = "all") -> list[Row]:
    """Every method scored in ``folders`` (their ``bench.json``), ranked.

    Raises
    ------
    BenchError
        A folder without results, results of two suites, or a split not scored.
    """
    rows: list[Row] = []
    hashes = set()
    for f in folders:
        p = f / "bench.json"
        try:
            d = json.loads(p.read_text())
        except (OSError, ValueError) as exc:
            raise BenchError(str(f), "", f"no readable bench.json ({exc})", "run `fdi-sim bench run --out` into it") from None
        hashes.add(d["suite_hash"])
        if split not in d["scored"]:
            raise BenchError(str(p), "--split", f"split {split!r} was not scored (have {sorted(d['scored'])})",
                             "give a scored split")
        rows += result_rows(d, split)
    if len(hashes) > 1:
        raise BenchError(", ".join(map(str, folders)), "", f"results of {len(hashes)} different suites",
                         "rank the results of one suite version")

    return rank(rows)


#: how a subset of the default banks' results is named in a row
AIRCRAFT_LABELS = {"aircraft:f16": "F-16", "aircraft:DHC6": "DHC-6"}


def result_rows(d: dict[str, Any], subset: str) -> list[Row]:
    """One row per method of a ``bench.json`` (``d``) on ``subset``: the default banks' members named
    with their aircraft's bank, the OR of a detectors bank as ``all detectors (OR)``, a detectors
    bank's rows on one aircraft with the aircraft in brackets."""
    ac = AIRCRAFT_LABELS.get(subset, "")
    out = []
    for m, s in d["scored"][subset].items():
        if d["bank"] == "default":
            where = f", {ac}" if ac else ""
            label = f"default bank{where}" if m == "bank" else f"{m} ({ac + ' ' if ac else ''}default bank)"
        else:
            base = "all detectors (OR)" if m == "bank" else m
            label = f"{base} ({ac})" if ac else base
        out.append(Row(label, d["bank"], d["suite"], d["suite_hash"], subset, s))
    return out


def rank(rows: list[Row]) -> list[Row]:
    """By the ALFA criterion's F1, then the event-level F1 (module docstring)."""
    return sorted(rows, key=lambda r: (-(r.scores["alfa"].get("f1") or 0.0), -(r.scores["event"].get("f1") or 0.0)))


def _f(x: Any, spec: str) -> str:
    return "-" if x is None else format(x, spec)  # (cli.py's _f also pads the dash to the column)


def far_cell(s: dict[str, Any]) -> str:
    """A scorer dict's false-alarm rate as a table cell: ``0.309 [0.180, 0.495]`` [1/flight h], or ``-``
    without armed fault-free exposure."""
    if s["far_per_h"] is None:
        return "-"
    lo, hi = s["far_per_h_ci"]
    return f"{s['far_per_h']:.3f} [{lo:.3f}, {hi:.3f}]"


def _ci(p: dict[str, Any]) -> str:
    return "-" if p.get("p") is None else f"{p['p']:.2f} [{p['ci'][0]:.2f}, {p['ci'][1]:.2f}]"


HEADER = ("method", "cases", "false alarms per h [95 %]", "P(detect) [95 %]", "delay median / p95 [s]",
          "isolation right", "ALFA precision / recall", "ALFA mean t [s]", "event F1", "AUROC", "AUPRC",
          "beats ALFA's RLS")


def _cells(r: Row) -> list[str]:
    s = r.scores
    d, a = s["detection"], s["alfa"]
    beats = ("yes" if r.beats_alfa else "no") + (f" ({', '.join(r.beats_alfa_classes)})" if r.beats_alfa_classes else "")
    return [r.method, str(s["cases"]), far_cell(s), _ci(d["detected"]),
            f"{_f(d['delay_s_median'], '.2f')} / {_f(d['delay_s_p95'], '.2f')}", _ci(d["isolation"]),
            f"{_f(a['precision'], '.2f')} / {_f(a['recall'], '.2f')}", _f(a["mean_detection_time_s"], ".2f"),
            _f(s["event"]["f1"], ".2f"), _f(s["sample"]["auroc"], ".3f"), _f(s["sample"]["auprc"], ".3f"), beats]


def leaderboard_markdown(rows: Sequence[Row]) -> str:
    """The table (Markdown)."""
    out = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    out += ["| " + " | ".join(_cells(r)) + " |" for r in rows]
    return "\n".join(out)


def leaderboard_table_html(rows: Sequence[Row]) -> str:
    """The table as an HTML ``<table>`` (the cells of :func:`leaderboard_markdown`)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in HEADER)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in _cells(r)) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def html_page(body: str, title: str = "fdi-bench leaderboard") -> str:
    """A self-contained HTML page around ``body`` (no script, no external file)."""
    return ("<!doctype html>\n<html><head><meta charset='utf-8'><title>" + html.escape(title) + "</title><style>"
            "body{font-family:sans-serif}table{border-collapse:collapse;margin-bottom:1em}"
            "td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}td:first-child{text-align:left}"
            "</style></head><body>\n<h1>" + html.escape(title) + "</h1>\n" + body + "\n</body></html>\n")


def leaderboard_html(rows: Sequence[Row]) -> str:
    """The table as a self-contained HTML page."""
    suite = f"{rows[0].suite} ({rows[0].suite_hash[:12]}), split {rows[0].split}" if rows else ""
    return html_page(f"<p>{html.escape(suite)}</p>{leaderboard_table_html(rows)}")

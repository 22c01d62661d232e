"""The study report: one self-contained ``index.html`` (figures embedded, and saved beside it).

Order, so that it reads in a minute: the headline numbers (runs, flight hours, the bank's
false-alarm rate against its design, detection and delay); the table comparing the members on
the same runs; the figures (ROC curves, false-alarm rate against threshold scale, delay
histograms, confusion matrices); statuses; how to fly a run again; the definitions.

Everything shown comes from the run records (:func:`fdi_sim.study.stats.summarize`) and, for the
ROC and threshold figures, from the logged statistics (:func:`fdi_sim.study.rescore.rescore`),
so any study can be reported later, elsewhere (STYLE rule 13). The figures are drawn with
matplotlib's object interface and the Agg renderer (no pyplot state, no display).
"""
from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.study.stats import BANK, NOT_DETECTED, NOT_ISOLATED
from fdi_sim.review.study_figures import _f, _figure, _save, _ids, roc_figure, _log_ticks, far_figure, delay_figure, confusion_matrix, confusion_figure  # noqa: F401 - re-exported

#: at most this many runs listed per kind in "fly a run again"
MAX_LISTED_RUNS = 5

CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222}
h1{font-size:1.5em;margin-bottom:0.2em} h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
.headline{background:#f4f6fa;border-left:4px solid #3a6ea5;padding:0.6em 1em;font-size:1.05em}
.headline li{margin:0.25em 0} .bad{color:#b00020;font-weight:600} .ok{color:#1b7a1b;font-weight:600}
table{border-collapse:collapse;font-size:0.86em;margin:0.5em 0} th,td{border:1px solid #ccc;padding:3px 6px}
th{background:#eef} td.num{text-align:right;font-variant-numeric:tabular-nums}
img{max-width:100%;border:1px solid #ddd} code{background:#f3f3f3;padding:0 3px}
.small{font-size:0.85em;color:#555}
"""


# --- formatting ----------------------------------------------------------------------------------
def _ci(ci: Sequence[float] | None, digits: int = 3) -> str:
    return "-" if ci is None else f"{_f(ci[0], digits)} - {_f(ci[1], digits)}"


def _pct(p: float | None, ci: Sequence[float] | None = None) -> str:
    if p is None:
        return "-"
    s = f"{100 * p:.0f} %"
    if ci is not None:
        s += f" ({100 * ci[0]:.0f} - {100 * ci[1]:.0f} %)"
    return s


def _e(x: Any) -> str:
    return html.escape(str(x))


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]], numeric_from: int = 1) -> str:
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>"]
    for row in rows:
        cells = []
        for i, c in enumerate(row):
            cls = ' class="num"' if i >= numeric_from else ""
            cells.append(f"<td{cls}>{c}</td>")  # cells are escaped by the caller (they may hold markup)
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "\n".join(out) + "</table>"


def _verdict(d: Mapping[str, Any]) -> str:
    """Empirical false-alarm rate against the prediction, in words (with markup)."""
    if d.get("far_per_h_ci") is None or d.get("predicted_far_per_h") is None:
        return "-"
    if d["exceeds_prediction"]:
        return '<span class="bad">above</span>'
    if d["prediction_in_ci"]:
        return "consistent"
    return '<span class="ok">below</span>'


# --- sections ----------------------------------------------------------------------------------------
def _headline(summary: Mapping[str, Any]) -> str:
    b = summary["bank"]
    st = ", ".join(f"{c} {s}" for s, c in summary["statuses"].items() if c)
    items = [f"<b>{summary['runs']} runs</b> ({st}); <b>{summary['flight_h']:.4g} flight hours</b> completed, "
             f"{b['exposure_h']:.4g} h of them armed and fault-free."]
    if b.get("far_per_h") is not None:
        design = b.get("predicted_far_per_h")
        word = {"above": '<span class="bad">ABOVE the design rate</span>',
                "below": '<span class="ok">below the design rate</span>',
                "consistent": "consistent with the design rate"}
        key = ("above" if b["exceeds_prediction"] else "consistent" if b["prediction_in_ci"] else "below") \
            if design is not None else None
        items.append(f"Bank false alarms: <b>{b['false_alarms']}</b> in {b['exposure_h']:.4g} h = <b>{_f(b['far_per_h'])} "
                     f"per flight hour</b> ({summary['confidence']:.0%} interval {_ci(b['far_per_h_ci'])}); design "
                     f"{_f(design)} /h: {word[key] if key else '-'}.")
    if b["faults"]:
        items.append(f"Detection: <b>{_pct(b['p_detect'], b['p_detect_ci'])}</b> of {b['faults']} injected faults; delay "
                     f"median <b>{_f(b['delay_s_median'])} s</b>, 95th percentile {_f(b['delay_s_p95'])} s; isolation "
                     f"right in {_pct(b['p_isolation_correct'])} of the detected.")
        a = b["alfa"]
        items.append(f"ALFA form (per flight): precision {_f(a['precision'])}, recall {_f(a['recall'])}, mean detection "
                     f"time {_f(a['mean_detection_time_s'])} s (TP {a['tp']}, FP {a['fp']}, FN {a['fn']}, TN {a['tn']}).")
    worst = [d for d in summary["detectors"] if d.get("exceeds_prediction")]
    if worst:
        items.append("Members above their predicted rate: " + ", ".join(
            f"<b>{_e(d['id'])}</b> ({_f(d['far_per_h'])} /h vs {_f(d['predicted_far_per_h'])})" for d in worst) + ".")
    items += [f'<span class="bad">Note:</span> {_e(n)}' for n in summary.get("notes", [])]
    return '<div class="headline"><ul>' + "".join(f"<li>{i}</li>" for i in items) + "</ul></div>"


def _comparison(summary: Mapping[str, Any]) -> str:
    rows = []
    for d in list(summary["detectors"]) + [summary["bank"]]:
        name = "<b>bank (any member)</b>" if d["id"] == BANK else f"<code>{_e(d['id'])}</code>"
        a = d["alfa"]
        rows.append([name, _f(d["runs"]), _f(d["false_alarms"]), _f(d["far_per_h"]), _ci(d["far_per_h_ci"]),
                     _f(d.get("dispersion")), _ci(d.get("far_per_h_ci_overdispersed")),
                     _f(d["predicted_far_per_h"]), _verdict(d), _pct(d["p_false_alarm_per_run"], d["p_false_alarm_per_run_ci"]),
                     f"{d['detected']}/{d['faults']}", _pct(d["p_detect"], d["p_detect_ci"]), _f(d["delay_s_median"]),
                     _f(d["delay_s_p95"]), _pct(d["p_isolation_correct"]), _f(a["precision"]), _f(a["recall"])])
    hdr = ["detector", "runs", "false alarms", "per flight h", "interval", "dispersion",
           "interval (clustered)", "predicted", "vs prediction",
           "P(false alarm) per run", "detected", "p_detect", "delay median [s]", "delay p95 [s]", "isolation right",
           "ALFA precision", "ALFA recall"]
    return _table(hdr, rows)


def _by_type(summary: Mapping[str, Any]) -> str:
    types = summary.get("fault_types", [])
    if not types:
        return "<p>No faults were injected (a false-alarm study).</p>"
    rows = []
    for d in list(summary["detectors"]) + [summary["bank"]]:
        cells = []
        for t in types:
            x = d["by_fault_type"].get(t)
            cells.append("-" if x is None else f"{_pct(x['p_detect'])} of {x['faults']}, {_f(x['delay_s_median'])} s")
        rows.append([("<b>bank</b>" if d["id"] == BANK else f"<code>{_e(d['id'])}</code>")] + cells)
    return _table(["detector"] + [f"{t}: p_detect, median delay" for t in types], rows)


def _statuses(summary: Mapping[str, Any]) -> str:
    s = _table(["status", "runs"], [[_e(k), _f(v)] for k, v in summary["statuses"].items()])
    nc = summary.get("not_completed", [])
    if nc:
        s += "<p>Not completed (not counted in any rate):</p>" + _table(
            ["run", "status", "reason"], [[_f(r["index"]), _e(r["status"]), _e(r["reason"])] for r in nc[:50]], 3)
        if len(nc) > 50:
            s += f"<p class='small'>... and {len(nc) - 50} more (runs/NNNNNN.json).</p>"
    return s


def _refly(records: Sequence[Mapping[str, Any]], results_dir: Path) -> str:
    def cmd(r: Mapping[str, Any]) -> str:
        scenario = r.get("scenario") or f"{int(r['index']):06d}.toml"
        return f"<code>fdi-sim run {_e(results_dir / 'runs' / scenario)}</code>"

    fa = [r for r in records if r.get("status") == "completed" and r.get("false_alarms")]
    miss = [r for r in records if r.get("status") == "completed"
            and any(d["detected_t_s"] is None for d in r.get("detections", []))
            and not _any_member_detected_all(r)]
    bad = [r for r in records if r.get("status") != "completed"]
    out = ["<p>Every run flies again alone from its scenario file (its seed is in it), and writes a normal "
           "full log: <code>fdi-sim run DIR/runs/NNNNNN.toml</code>. "
           f"Here DIR is <code>{_e(results_dir)}</code>.</p><ul>"]
    for what, rs in (("with a false alarm", fa), ("with a fault no member detected", miss), ("not completed", bad)):
        if rs:
            out.append(f"<li>Runs {what} ({len(rs)}): " + "; ".join(
                f"run {int(r['index'])}: {cmd(r)}" for r in rs[:MAX_LISTED_RUNS]) + (" ..." if len(rs) > MAX_LISTED_RUNS else "")
                + "</li>")
    out.append("</ul>")
    return "".join(out)


def _any_member_detected_all(r: Mapping[str, Any]) -> bool:
    """Every fault of the run detected by some member."""
    faults = {d["fault"] for d in r.get("detections", [])}
    hit = {d["fault"] for d in r.get("detections", []) if d["detected_t_s"] is not None}
    return faults <= hit


def _definitions(summary: Mapping[str, Any], rescored: Any) -> str:
    b = summary["bank"]
    items = [
        "Only completed runs count for rates and probabilities. Intervals are exact at "
        f"{summary['confidence']:.0%}: Poisson (Garwood) for rates, Clopper-Pearson for probabilities.",
        "A <b>false alarm</b> is an alarm episode that begins outside every fault window + "
        f"{summary['grace_s']:g} s; its rate is per <b>armed fault-free flight hour</b> (the flight from "
        "<code>arm_s</code> on, minus the fault windows + grace).",
        "<b>Predicted</b> rate: the bank splits its design rate evenly over its members (union bound), so a member is "
        "predicted at most design / members per hour, the bank at most the design rate. Above = the interval's lower "
        "end exceeds the prediction.",
        "<b>Detection</b>: the first alarm sample at or after the fault's first onset; delay from that onset. The "
        "bank's alarm is the OR of its members'.",
        "<b>ALFA form</b> (Keipour et al. 2019, 2021), one outcome per flight: an alarm before the fault onset or on "
        "a fault-free flight is a false positive; else a detected fault flight is a true positive, an undetected one "
        "a false negative.",
        "<b>Analytic probability of wrong diagnosis</b> (Hagenblad Algorithm 2, eq. 14): "
        + _e(b.get("wrong_diagnosis_analytic_reason", "")) + ".",
    ]
    if rescored is not None:
        rule = "each run's own k of n" if rescored.k is None else f"{rescored.k} of {rescored.n}"
        items.append("<b>ROC and threshold curves</b> re-score the logged statistics at threshold x scale "
                     f"(persistence: {rule}): "
                     "exact at scale 1 (the decision the runs made), <b>open loop</b> after the first alarm at any "
                     "other scale, since in the loop a confirmed alarm reconfigures the bank and changes the flight.")
    return "<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _img(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{data}"/>'
            f'<figcaption class="small">{_e(caption)} (also <code>{_e(path.name)}</code>)</figcaption></figure>')


def _study_name(results_dir: Path) -> str:
    p = results_dir / "study.json"
    if p.is_file():
        try:
            d = json.loads(p.read_text())
            return str(d.get("name") or d.get("study", {}).get("name") or results_dir.name)
        except (ValueError, AttributeError):
            pass
    return results_dir.name


def write_report(out_dir: str | Path, records: Sequence[Mapping[str, Any]], summary: Mapping[str, Any],
                 rescored: Any = None, *, study_dir: str | Path | None = None, confidence: float | None = None
                 ) -> Path:
    """Write ``out_dir/index.html`` and its figures (``roc.png``, ``far_vs_threshold.png``,
    ``delays.png``, ``confusion.png``) and return the page's path.

    Parameters
    ----------
    out_dir : path
        The report folder (created).
    records : sequence of mapping
        The run records (for statuses and the runs to fly again).
    summary : mapping
        :func:`fdi_sim.study.stats.summarize` of the records.
    rescored : Rescored, optional
        :func:`fdi_sim.study.rescore.rescore` over a range of scales; without it the ROC and
        threshold figures are left out (and the page says so).
    study_dir : path, optional
        The study's results folder, for the ``fdi-sim run`` commands and the study's name
        (default: ``out_dir``'s parent when it holds ``runs/``, else ``out_dir``).
    confidence : float, optional
        Interval level of the figures (default: the summary's).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if study_dir is None:
        study_dir = out.parent if (out.parent / "runs").is_dir() else out
    results_dir = Path(study_dir).resolve()
    conf = float(confidence if confidence is not None else summary.get("confidence", 0.95))
    figs = []
    if rescored is not None:
        if any(d.by_type for d in rescored.detectors.values()):
            figs.append(_img(roc_figure(rescored, out / "roc.png", conf),
                             "ROC per detector and fault type: detection probability against false alarms per flight "
                             "hour, over threshold scales (open loop after the first alarm except at scale 1)"))
        figs.append(_img(far_figure(rescored, summary, out / "far_vs_threshold.png", conf),
                         "False alarms per armed fault-free flight hour against threshold scale, with exact Poisson "
                         "intervals; dashed: the predicted (design) rate; grey: the logged threshold"))
    if summary["bank"]["faults"]:
        figs.append(_img(delay_figure(summary, out / "delays.png"), "Detection delays after the fault onset"))
        figs.append(_img(confusion_figure(summary, out / "confusion.png"),
                         "Confusion: true target (rows) -> isolated as (columns), counts of (run, fault) pairs"))
    name = str(summary.get("study") or _study_name(results_dir))
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>{_e(name)}: study report</title><style>{CSS}</style></head><body>",
        f"<h1>{_e(name)}</h1><p class='small'>Study report of <code>{_e(results_dir)}</code>.</p>",
        _headline(summary),
        "<h2>Detectors on identical runs</h2>", _comparison(summary),
        "<h2>Per fault type</h2>", _by_type(summary),
        "<h2>Figures</h2>",
    ]
    if rescored is None:
        parts.append("<p>No re-scoring given: ROC and false-alarm-rate-against-threshold figures left out "
                     "(<code>fdi_sim.study.rescore.rescore</code>).</p>")
    parts += figs
    parts += ["<h2>Run statuses</h2>", _statuses(summary),
              "<h2>Fly a run again</h2>", _refly(records, results_dir),
              "<h2>Definitions</h2>", _definitions(summary, rescored), "</body></html>"]
    page = out / "index.html"
    page.write_text("\n".join(parts), encoding="utf-8")
    return page

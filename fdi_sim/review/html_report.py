"""The run review as ONE self-contained HTML page (``fdi-sim review`` writes it next to the log).

Inline CSS, plotly.js inline (:func:`fdi_sim.review.figures.plotly_script_tag`), nothing loaded
from the network: the page opens offline, days later, on another machine. Order: the headline
numbers (a table: detected or not, delay, isolation, false alarms per hour, how the run ended),
how each run ended, the faults with their true intervals, the failure log, the
reconfigurations, the per-detector table, then the figure sections (timeline, one per detector
with its alarm episodes, flight, faulty sensors), notes and the scenario text.

``<meta name="fdi-sim-figures" content="id1 id2 ...">`` lists every figure's DOM id and
``<meta name="fdi-sim-review" content="1">`` marks the page (the browser test reads both).
"""
from __future__ import annotations

import html
import os
import tempfile
from pathlib import Path
from typing import Any, Sequence

from fdi_sim.errors import ReviewError
from fdi_sim.flightlog.reader import FlightLog
from fdi_sim.review.run_review import DetectorReview, RunReview, windows_text

CSS = """
nav.toc{font-size:.9em;margin:.4em 0 1em} nav.toc a{color:#0b5cad;text-decoration:none}
details.fold>summary{cursor:pointer;color:#0b5cad;margin:.3em 0}
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:1.5em auto;max-width:1200px;
     color:#1b1f24;padding:0 1em;line-height:1.4}
h1{font-size:1.45em;margin-bottom:.1em} h2{font-size:1.2em;border-bottom:1px solid #ccd;padding-bottom:.2em;
     margin-top:1.6em} h3{font-size:1.02em;margin-bottom:.3em}
.sub{color:#57606a;margin-top:0;font-size:.92em;word-break:break-all}
table{border-collapse:collapse;margin:.4em 0 1em;font-size:.9em}
th,td{border:1px solid #d0d7de;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f3f5f7} tr.diff td{background:#fff8c5}
table.headline td:first-child{font-weight:600;white-space:nowrap}
.ok{color:#1a7f37;font-weight:600} .bad{color:#cf222e;font-weight:600} .warn{color:#9a6700;font-weight:600}
.fdi-figure{width:100%;min-height:320px} .caption{color:#57606a;font-size:.88em;margin:.1em 0 1.2em}
pre{background:#f6f8fa;padding:.7em;overflow:auto;font-size:.85em} .none{color:#57606a;font-style:italic}
"""


def default_report_path(logs: Sequence[str | Path]) -> Path:
    """``<stem>.review.html`` next to the log; for two, ``<stemA>_vs_<stemB>.review.html`` next to A."""
    a = Path(logs[0])
    name = a.stem if len(logs) == 1 else f"{a.stem}_vs_{Path(logs[1]).stem}"
    return a.with_name(name + ".review.html")


def _e(x: object) -> str:
    return html.escape(str(x), quote=True)


def _table(head: Sequence[str], rows: Sequence[Sequence[object]], cls: str = "", raw: bool = False,
           row_cls: Sequence[str] | None = None) -> str:
    if not rows:
        return '<p class="none">none</p>'
    c = f' class="{cls}"' if cls else ""
    out = [f"<table{c}><thead><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr></thead><tbody>"]
    for i, r in enumerate(rows):
        rc = f' class="{row_cls[i]}"' if row_cls and row_cls[i] else ""
        out.append(f"<tr{rc}>" + "".join(f"<td>{v if raw else _e(v)}</td>" for v in r) + "</tr>")
    return "\n".join(out) + "</tbody></table>"


#: a table longer than this is folded into a <details> element, so the figures stay near the top
FOLD_ROWS = 12


def _folded(summary: str, n_rows: int, table: str) -> str:
    """``table`` as it is, or folded under ``summary`` when it has more than :data:`FOLD_ROWS` rows."""
    if n_rows <= FOLD_ROWS:
        return table
    return f'<details class="fold"><summary>{_e(summary)} ({n_rows} rows: show)</summary>{table}</details>'


def _detection_cell(r: RunReview, fault: str) -> str:
    d = r.first_detection(fault)
    if d is None and (why := r.never_started(fault)):
        return _e(why)
    if d is None:
        return '<span class="bad">not detected</span>'
    iso = "" if d.isolation_correct is None else (' <span class="ok">right</span>' if d.isolation_correct
                                                  else ' <span class="bad">wrong</span>')
    return (f'<span class="ok">detected</span> at {d.detected_t_s:.2f} s by {_e(d.detector)}, delay '
            f"<b>{d.delay_s:.2f} s</b>, isolated as {_e(d.isolation or 'not isolated')}{iso}")


def _ending_cell(r: RunReview) -> str:
    cls = "ok" if r.status == "completed" else "bad"
    return f'<span class="{cls}">{_e(r.status)}</span>: {_e(r.ending)}'


def _far_cell(r: RunReview) -> str:
    if not r.bank:
        return '<span class="none">no FDI bank in this log</span>'
    if r.bank_far_per_h is None:
        return f"{r.bank_false_alarms} (no armed fault-free time)"
    lo, hi = r.bank_far_ci_per_h
    design = "" if r.design_far_per_h is None else f"; design {r.design_far_per_h:g} /h"
    cls = "ok" if r.bank_false_alarms == 0 else "warn"
    return (f'<span class="{cls}">{r.bank_false_alarms}</span> in {r.bank_exposure_h * 60:.2f} armed fault-free min: '
            f"{r.bank_far_per_h:.3g} /h (95 % {lo:.3g} .. {hi:.3g}){design}")


def _headline(reviews: Sequence[RunReview]) -> str:
    labels = list(dict.fromkeys(f.label for r in reviews for f in r.faults))
    rows: list[list[str]] = [["run"] + [f"{_e(r.scenario)} ({_e(r.aircraft)}, seed {_e(r.seed)})" for r in reviews],
                             ["how it ended"] + [_ending_cell(r) for r in reviews]]
    for lab in labels:
        rows.append([f"fault {_e(lab)}"] + [_detection_cell(r, lab) if any(f.label == lab for f in r.faults)
                                            else '<span class="none">not in this run</span>' for r in reviews])
    if not labels:
        rows.append(["faults"] + ['<span class="none">none injected</span>' for _ in reviews])
    rows.append(["false alarms"] + [_far_cell(r) for r in reviews])
    rows.append(["reconfigured"] + [", ".join(f"{_e(x.sensor)} at {x.t_s:.2f} s" for x in r.reconfigurations)
                                    or "no" for r in reviews])
    rows.append(["flown"] + [f"{r.duration_s:.2f} s" + ("" if r.planned_s is None else f" of {r.planned_s:g} s")
                             + ("" if r.rate_hz is None else f" at {r.rate_hz:g} Hz") for r in reviews])
    head = [""] + (["this run"] if len(reviews) == 1 else [f"{k} ({Path(r.path).name})" for k, r in zip("AB", reviews)])
    cls = [("diff" if len(reviews) > 1 and len(set(row[1:])) > 1 else "") for row in rows]
    return _table(head, rows, "headline", raw=True, row_cls=cls)


def _detector_rows(r: RunReview, d: DetectorReview) -> list[list[str]]:
    far = "-" if d.far_per_h is None else f"{d.far_per_h:.3g} ({d.far_ci_per_h[0]:.3g} .. {d.far_ci_per_h[1]:.3g})"
    per_fault = "; ".join(
        f"{x.fault}: " + ("not detected" if x.detected_t_s is None else
                          f"{x.delay_s:.2f} s, {x.isolation or 'not isolated'}"
                          + ("" if x.isolation_correct is None else (" (right)" if x.isolation_correct else " (wrong)")))
        for x in d.detections) or "no fault"
    design = "-" if d.design_far_per_h is None else f"{d.design_far_per_h:.3g}"
    return [[d.id, f"{d.threshold:.4g}", str(len(d.episodes)), str(d.false_alarms), far, design, per_fault,
             str(len(d.schedule_switches))]]


DETECTOR_HEAD = ("detector", "threshold", "alarm episodes", "false alarms", "false alarms /h (95 %)",
                 "design /h", "per fault: delay, isolation", "schedule switches")


def _run_details(r: RunReview, tag: str) -> str:
    out = [f"<h3>{_e(tag)}How the run ended</h3><p>{_ending_cell(r)}</p>"]
    if r.read_path != r.path:
        out.append(f"<p class=\"warn\">{_e(r.notes[0])}</p>")
    out.append(f"<h3>{_e(tag)}Faults injected</h3>")
    out.append(_table(("label", "type", "target", "true intervals"),
                      [(f.label, f.type, f.target, windows_text(f.windows_s, r.t_end_s))
                       for f in r.faults]))
    out.append(f"<h3>{_e(tag)}Failure log</h3>")
    onsets = [x for x in r.failure_log if x.event == "onset"]
    first = (f"first onset {onsets[0].t_s:.2f} s: {onsets[0].detector}, {onsets[0].hypothesis}" if onsets
             else "no onset")
    out.append(_folded(f"{len(r.failure_log)} entries, {len(onsets)} onsets; {first}", len(r.failure_log),
                       _table(("t [s]", "event", "detector", "hypothesis", "kind", "nature", "duration [s]"),
                              [(f"{x.t_s:.2f}", x.event, x.detector, x.hypothesis, x.kind, x.nature,
                                "" if x.duration_s is None else f"{x.duration_s:.2f}") for x in r.failure_log])))
    out.append(f"<h3>{_e(tag)}Reconfigurations</h3>")
    out.append(_table(("t [s]", "action", "sensor", "by", "confirmed by"),
                      [(f"{x.t_s:.2f}", x.action, x.sensor, x.detector, x.confirmed_by) for x in r.reconfigurations]))
    out.append(f"<h3>{_e(tag)}Detectors</h3>")
    if r.bank:
        out.append(_table(DETECTOR_HEAD, [row for d in r.detectors for row in _detector_rows(r, d)]))
    else:
        out.append('<p class="none">no FDI bank in this log</p>')
    return "\n".join(out)


def _episode_table(reviews: Sequence[RunReview], det: str) -> str:
    rows = []
    for k, r in zip("AB", reviews):
        for d in r.detectors:
            if d.id != det:
                continue
            for e in d.episodes:
                rows.append(([k] if len(reviews) > 1 else []) + [
                    f"{e.onset_t_s:.2f}", "open at the end" if e.end_t_s is None else f"{e.end_t_s:.2f}",
                    e.isolation or "not isolated", "FALSE ALARM" if e.false else "in a fault window"])
    head = (["run"] if len(reviews) > 1 else []) + ["onset [s]", "end [s]", "isolated as", "kind"]
    detail = []
    for k, r in zip("AB", reviews):
        d = next((x for x in r.detectors if x.id == det), None)
        if d is not None:
            detail.append(_table(DETECTOR_HEAD, _detector_rows(r, d)) if len(reviews) == 1 else
                          f"<p><b>{k}</b></p>" + _table(DETECTOR_HEAD, _detector_rows(r, d)))
    n_false = sum(1 for r in rows if r[-1] == "FALSE ALARM")
    return "\n".join(detail) + "<p>Alarm episodes:</p>" + _folded(
        f"{len(rows)} alarm episodes, {n_false} false", len(rows), _table(head, rows))


def render_report(reviews: Sequence[RunReview], sections: Sequence[object], changes: Sequence[str] = ()) -> str:
    """The page's HTML for one review, or two (a comparison) and the scenario keys that differ."""
    from fdi_sim.review.figures import figure_html, plotly_script_tag

    ids = [f.id for s in sections for f in s.figures]
    title = (f"Run review: {reviews[0].scenario}" if len(reviews) == 1 else
             f"Comparison: {reviews[0].scenario}, {Path(reviews[0].path).name} vs {Path(reviews[1].path).name}")
    body = [f"<h1>{_e(title)}</h1>",
            "".join(f'<p class="sub">{k}{_e(r.path)}</p>' for k, r in
                    zip(("",) if len(reviews) == 1 else ("A: ", "B: "), reviews)),
            '<section id="headline"><h2>Headline</h2>', _headline(reviews), "</section>"]
    if len(reviews) > 1:
        body += ['<section id="scenario-changes"><h2>What differs in the scenario (A &rarr; B)</h2>',
                 "<ul>" + "".join(f"<li><code>{_e(c)}</code></li>" for c in changes) + "</ul>" if changes
                 else '<p class="none">nothing: the same scenario text</p>', "</section>"]
    # what a reviewer looks at first: the headline, then the timeline, then the details and the rest
    ordered = sorted(sections, key=lambda s: s.id != "timeline")
    toc = [("headline", "Headline")] + [(s.id, s.title) for s in ordered[:1] if s.id == "timeline"]
    toc += [(f'run{"-" + k[0].lower() if k else ""}', f"{k}Run details")
            for k in (("",) if len(reviews) == 1 else ("A: ", "B: "))]
    toc += [(s.id, s.title) for s in ordered if s.id != "timeline"] + [("notes", "Notes")]
    body.insert(2, '<nav class="toc">' + " &middot; ".join(f'<a href="#{_e(i)}">{_e(t)}</a>' for i, t in toc)
                + "</nav>")

    def _section(s: Any) -> None:
        body.append(f'<section id="{_e(s.id)}"><h2>{_e(s.title)}</h2>')
        if s.detector is not None:
            body.append(_episode_table(reviews, s.detector))
        for f in s.figures:
            body.extend([f"<h3>{_e(f.title)}</h3>", figure_html(f), f'<p class="caption">{_e(f.caption)}</p>'])
        body.extend(f'<p class="none">{_e(n)}</p>' for n in getattr(s, "notes", ()))
        body.append("</section>")

    for s in ordered[:1]:
        if s.id == "timeline":
            _section(s)
    for k, r in zip(("",) if len(reviews) == 1 else ("A: ", "B: "), reviews):
        body += [f'<section id="run{"-" + k[0].lower() if k else ""}"><h2>{_e(k)}Run details</h2>',
                 _run_details(r, k), "</section>"]
    for s in ordered:
        if s.id != "timeline":
            _section(s)
    notes = [(k, n) for k, r in zip(("",) if len(reviews) == 1 else ("A: ", "B: "), reviews) for n in r.notes]
    body += ['<section id="notes"><h2>Notes</h2>', "<ul>" + "".join(f"<li>{_e(k)}{_e(n)}</li>" for k, n in notes)
             + "</ul>" if notes else '<p class="none">none</p>', "</section>"]
    for k, r in zip(("",) if len(reviews) == 1 else ("A: ", "B: "), reviews):
        body.append(f"<details><summary>{_e(k)}Scenario text (from the log's metadata)</summary>"
                    f"<pre>{_e(r.scenario_text or '(none)')}</pre></details>")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{_e(title)}</title>"
            '<meta name="fdi-sim-review" content="1">'
            f'<meta name="fdi-sim-figures" content="{_e(" ".join(ids))}">'
            f"<style>{CSS}</style>{plotly_script_tag()}</head>\n<body>\n" + "\n".join(body) + "\n</body></html>\n")


def write_report(reviews: Sequence[RunReview], logs: Sequence[FlightLog], out_path: str | Path | None = None, *,
                 sections: Sequence[object] | None = None, changes: Sequence[str] = ()) -> Path:
    """Write the self-contained HTML report of one run (or two: a comparison).

    Parameters
    ----------
    reviews : sequence of RunReview
        One, or two of the same scenario.
    logs : sequence of FlightLog
        The logs they came from (the figures read them).
    out_path : str or Path, optional
        The page; an existing folder gets the default name inside it. Default
        :func:`default_report_path` of the reviews' logs.
    sections : sequence of Section, optional
        Figures already made (:func:`fdi_sim.review.figures.report_sections`); made here if None.
    changes : sequence of str
        The scenario keys that differ (a comparison).

    Returns
    -------
    Path
        The page written.

    Raises
    ------
    ReviewError
        The folder cannot be created or written (a file where a folder should be, no permission).
    """
    if sections is None:
        from fdi_sim.review.figures import report_sections

        sections = report_sections(list(logs), ["A", "B"][:len(logs)] if len(logs) > 1 else [Path(reviews[0].path).stem])
    out = Path(out_path) if out_path is not None else default_report_path([r.path for r in reviews])
    if out.is_dir():
        out = out / default_report_path([r.path for r in reviews]).name
    text = render_report(reviews, sections, changes)
    fix = "pass --out with a path in a folder you can write"
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReviewError(str(out), f"cannot create the report's folder {out.parent} "
                          f"({exc.strerror or exc}: a file where a folder should be, or no permission)", fix) from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=".review-", suffix=".html", dir=out.parent)
    except OSError as exc:
        raise ReviewError(str(out), f"cannot write in the report's folder {out.parent} ({exc.strerror or exc})", fix) from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, out)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise ReviewError(str(out), f"cannot write the report ({exc.strerror or exc})", fix) from None
    return out

"""The review report's figures, from flight logs only: plotly figure specs built as plain dicts.

:func:`report_sections` turns one log (or two runs of one scenario, overlaid on shared axes)
into sections of figures, in this order: timeline, one section per detector, flight, sensors.
:func:`figure_html` renders one figure as a ``<div>`` and its ``Plotly.newPlot`` call;
:func:`plotly_script_tag` inlines plotly.js once per page (the page loads nothing from the network).

The specs are plain dicts with plotly attribute names: validating those of a 10-minute run with
``plotly.graph_objects.Figure`` took 0.67 s on top of the 0.21 s that building them takes. Time
series are decimated by :class:`fdi_sim.review.decimate.Decimator` (every spike kept, full
resolution around fault and alarm onsets) and stored as lists: values at 6 significant digits, times at 1 ms, NaN as null,
so a spec is JSON as it stands. Only ``scatter`` traces (WebGL fails in headless Chromium).
Angles are logged in rad and shown in degrees; every axis names its unit.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.flightlog import (
    TOPIC_COMMANDS,
    TOPIC_FAULT_EVENTS,
    TOPIC_OPERATING_POINT,
    TOPIC_SENSORS,
    TOPIC_SURFACES,
    TOPIC_TRUTH_STATE,
    EventTopic,
    FlightLog,
    VectorTopic,
)
from fdi_sim.review.decimate import MAX_POINTS, Decimator, zoom_windows
from fdi_sim.review.plotly_spec import (
    BAND_FILLS,
    FAMILIES,
    bars,
    display_unit,
    dom_id,
    dumps,
    line,
    markers,
    panel_layout,
    values,
)

CONFIG: dict[str, Any] = {"displaylogo": False, "responsive": True}
ZOOM_POINTS: int = 3000
"""Most samples a trace keeps at full resolution around onsets (fault onsets come first): 25 s of
a 120 Hz signal, 150 s of a 20 Hz detector statistic."""
MAX_SWITCH_LINES: int = 200
TOPIC_RECONFIGURATION = "/fdi/reconfiguration"

# --- the agreed interface ------------------------------------------------------------------
@dataclass(frozen=True)
class Figure:
    """One plotly figure of the report.

    Attributes
    ----------
    id : str
        Unique DOM id (``fig-timeline``).
    title : str
    caption : str
        One sentence: what to look at.
    spec : dict
        The plotly figure, JSON as it stands: ``{"data": [...], "layout": {...}}``.
    """

    id: str
    title: str
    caption: str
    spec: dict[str, Any]


@dataclass(frozen=True)
class Section:
    """A group of figures: ``timeline``, ``detector-<id>``, ``flight``, ``sensors``.

    Attributes
    ----------
    id, title : str
    detector : str or None
        The detector id of a per-detector section.
    figures : tuple of Figure
        Only figures with something to draw.
    notes : tuple of str
        What was left out and why (a figure whose signals hold no finite sample in this log).
    """

    id: str
    title: str
    detector: str | None
    figures: tuple[Figure, ...]
    notes: tuple[str, ...] = ()


def _drawable(fig: Figure) -> bool:
    """Whether any trace of ``fig`` has a finite point within the time axis' range (y of null is a
    gap, not a point; a fault window that starts after a cut-off log ends lies outside the axes)."""
    t_range = fig.spec["layout"].get("xaxis", {}).get("range")
    for tr in fig.spec["data"]:
        ys, xs = tr.get("y"), tr.get("x")
        if ys is None:
            continue
        pts = [x for x, y in zip(xs if xs is not None else range(len(ys)), ys)
               if y is not None and not (isinstance(y, float) and math.isnan(y))]
        if not pts:
            continue
        if t_range is None or xs is None or not all(isinstance(x, (int, float)) for x in pts):
            return True
        if min(pts) <= t_range[1] and max(pts) >= t_range[0]:  # a segment or a point in view
            return True
    return False


def _keep_drawable(section: Section) -> Section:
    """``section`` without its empty figures, each named in its notes (an empty plot reads as a bug)."""
    keep = tuple(f for f in section.figures if _drawable(f))
    if len(keep) == len(section.figures):
        return section

    def why(f: Figure) -> str:
        t_range = f.spec["layout"].get("xaxis", {}).get("range") or [math.nan, math.nan]
        span = f"t = {t_range[0]:.2f} .. {t_range[1]:.2f} s"
        if f.id == "fig-timeline":
            return (f.caption if not f.spec["data"] else
                    f"No fault was active and no detector alarmed within the log's time span ({span}); a fault "
                    "scheduled later never started.")
        return (f"None of its signals has a finite sample within the log's time span ({span}): the run ended, "
                "or the detector was not valid, before there was one.")

    notes = section.notes + tuple(f"{f.title}: not drawn. {why(f)}" for f in section.figures if f not in keep)
    return Section(section.id, section.title, section.detector, keep, notes)


def report_sections(logs: Sequence[FlightLog], labels: Sequence[str]) -> tuple[Section, ...]:
    """The report's sections for one run, or for runs of one scenario overlaid on shared axes.

    Parameters
    ----------
    logs : sequence of FlightLog
        One log, or two (a comparison: every figure shows both runs, one colour family each).
    labels : sequence of str
        A short label per log, shown in the legends (``A``, ``B`` or file names).

    Returns
    -------
    tuple of Section
        Timeline; one section per detector of any log; flight; sensors (when a sensor is faulty).
    """
    if not logs:
        raise ValueError("report_sections needs at least one flight log")
    if len(labels) != len(logs):
        raise ValueError(f"report_sections: {len(logs)} logs but {len(labels)} labels; give one label per log")
    runs = tuple(_Run(log, str(lab), k, len(logs) > 1) for k, (log, lab) in enumerate(zip(logs, labels)))
    ctx = _Context(runs)
    sections = [Section("timeline", "Timeline", None, (_timeline(ctx),))]
    for det in ctx.detectors:
        figs = [_statistic_figure(ctx, det)]
        res = _residual_figure(ctx, det)
        if res is not None:
            figs.append(res)
        sections.append(Section(f"detector-{dom_id(det)}", f"Detector {det}", det, tuple(figs)))
    sections.append(Section("flight", "Flight", None, tuple(f for f in _flight_figures(ctx) if f is not None)))
    sensors = tuple(_sensor_figures(ctx))
    if sensors:
        sections.append(Section("sensors", "Faulty sensors: truth against measurement", None, sensors))
    for tr in (tr for s in sections for f in s.figures for tr in f.spec["data"]):
        if tr.get("legendgroup", "run-0") != "run-0":
            tr.setdefault("opacity", 0.8)  # a later run drawn over the first lets it show where they agree
    return tuple(_keep_drawable(s) for s in sections)


@lru_cache(maxsize=1)
def plotly_script_tag() -> str:
    """``<script>`` with plotly.js inline, once per page (nothing is fetched from the network)."""
    from plotly.offline import get_plotlyjs

    return "<script>" + get_plotlyjs().replace("</script", "<\\/script") + "</script>"


def figure_html(fig: Figure) -> str:
    """A ``<div id=fig.id class="fdi-figure">`` and the script that draws the figure into it."""
    spec = fig.spec
    args = ",".join(dumps(x) for x in (fig.id, spec.get("data", []), spec.get("layout", {}), CONFIG))
    return (f'<div id="{fig.id}" class="fdi-figure"></div>\n'
            f"<script>Plotly.newPlot({args});</script>")


def specdumps(fig: Figure) -> str:
    """The figure's spec as compact JSON (no NaN: they are null already)."""
    return dumps(fig.spec)


# --- what the logs hold ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Run:
    log: FlightLog
    label: str
    index: int
    multi: bool

    def name(self, text: str) -> str:
        return f"{self.label}: {text}" if self.multi else text

    def colour(self, k: int) -> str:
        fam = FAMILIES[self.index % len(FAMILIES)]
        return fam[k % len(fam)]

    def vector(self, topic: str) -> VectorTopic | None:
        t = self.log.topics.get(topic)
        return t if isinstance(t, VectorTopic) and len(t) else None

    def events(self, topic: str) -> tuple[Any, ...]:
        t = self.log.topics.get(topic)
        return t.events if isinstance(t, EventTopic) else ()

    def catalog(self) -> list[dict[str, Any]]:
        """The injected faults (label, type, target, windows_s) from the ``/faults/events`` catalog."""
        for e in self.events(TOPIC_FAULT_EVENTS):
            if e.payload.get("event") == "catalog":
                return [dict(f) for f in e.payload.get("faults", [])]
        text = self.log.metadata.get("faults", {}).get("catalog")
        return list(json.loads(text)) if text else []

    def hypotheses(self, det: str) -> list[str]:
        text = self.log.metadata.get("fdi", {}).get("members")
        for m in json.loads(text) if text else []:
            if m.get("id") == det:
                return list(m.get("hypotheses", []))
        return []

    def rate_hz(self, topic: str) -> float:
        """Sample rate of a vector topic [Hz] (median step; 120 Hz when it has under two samples)."""
        vt = self.vector(topic)
        dt = np.diff(vt.t_s) if vt is not None else np.zeros(0)
        dt = dt[dt > 0]
        return 1.0 / float(np.median(dt)) if dt.size else 120.0

    def statistic(self, det: str) -> VectorTopic | None:
        return self.vector(f"/fdi/{det}/statistic")

    def detectors(self) -> list[str]:
        found = [k[len("/fdi/"):-len("/statistic")] for k in self.log.topics
                 if k.startswith("/fdi/") and k.endswith("/statistic") and self.vector(k) is not None]
        text = self.log.metadata.get("fdi", {}).get("members")
        order = [m.get("id") for m in json.loads(text)] if text else []
        return sorted(found, key=lambda d: (order.index(d) if d in order else len(order), d))

    def alarm_onsets_s(self, det: str) -> NDArray[np.float64]:
        st = self.statistic(det)
        if st is None:
            return np.zeros(0)
        a = st["alarm"] > 0.5
        return st.t_s[np.flatnonzero(a & ~np.concatenate(([False], a[:-1])))]

    def switches(self) -> list[tuple[float, str, int, int]]:
        """Schedule switches: (t [s], detector, node before, node after) where ``point`` changes."""
        out = []
        for det in self.detectors():
            st = self.statistic(det)
            p = st["point"] if st is not None and "point" in st.fields else np.zeros(0)
            for i in np.flatnonzero(np.diff(p) != 0).tolist():
                out.append((float(st.t_s[i + 1]), det, int(p[i]), int(p[i + 1])))
        return sorted(out)


@dataclass(frozen=True, eq=False)
class _Context:
    runs: tuple[_Run, ...]

    @property
    def detectors(self) -> list[str]:
        seen: list[str] = []
        for r in self.runs:
            seen += [d for d in r.detectors() if d not in seen]
        return seen

    @property
    def span_s(self) -> tuple[float, float]:
        t0 = min(r.log.start_t_s for r in self.runs)
        t1 = max(r.log.end_t_s for r in self.runs)
        return t0, max(t1, t0 + 1e-3)

    def fault_onsets_s(self) -> list[float]:
        return [float(w[0]) for r in self.runs for f in r.catalog() for w in f.get("windows_s", [])]

    def decimator(self, det: str | None = None) -> Decimator:
        """One decimator per figure: full resolution around fault onsets, then the alarm onsets of
        ``det`` (or of every detector), for at most :data:`ZOOM_POINTS` samples of the figure's
        fastest signal (the detector's statistic, else the truth state)."""
        dets = [det] if det else self.detectors
        alarms = sorted({float(t) for r in self.runs for d in dets for t in r.alarm_onsets_s(d)})
        rate_hz = max(r.rate_hz(f"/fdi/{det}/statistic" if det else TOPIC_TRUTH_STATE) for r in self.runs)
        t0, t1 = self.span_s
        windows = zoom_windows(self.fault_onsets_s() + alarms, budget_s=ZOOM_POINTS / rate_hz)
        return Decimator(t0, t1, windows, MAX_POINTS)

    def bands(self) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """Shapes and labels shading every true fault interval (identical ones across runs once)."""
        shapes: list[dict[str, Any]] = []
        notes: list[dict[str, Any]] = []
        seen: set[tuple[str, float, float]] = set()
        labels: list[str] = []
        for r in self.runs:
            for f in r.catalog():
                lab = str(f.get("label", f.get("type", "fault")))
                labels += [lab] if lab not in labels else []
                for w0, w1 in f.get("windows_s", []):
                    key = (lab, float(w0), float(w1))
                    if key in seen:
                        continue
                    seen.add(key)
                    shapes.append({"type": "rect", "xref": "x", "yref": "paper", "x0": float(w0), "x1": float(w1),
                                   "y0": 0, "y1": 1, "fillcolor": BAND_FILLS[labels.index(lab) % len(BAND_FILLS)],
                                   "line": {"width": 0}, "layer": "below", "name": f"fault {lab}"})
                    notes.append({"x": float(w0), "y": 1.0, "xref": "x", "yref": "paper", "text": lab,
                                  "showarrow": False, "xanchor": "left", "yanchor": "bottom",
                                  "font": {"size": 10, "color": "#8c2d04"}})
        return shapes, notes


def _series(dec: Decimator, topic: VectorTopic, field: str, scale: float = 1.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    d = dec(topic.t_s, topic[field])
    return d.t_s, d.y * scale


def _layout(ctx: _Context, ylabels: Sequence[str], **kw: Any) -> dict[str, Any]:
    """Panels on the runs' time span, shaded over every true fault interval."""
    return panel_layout(ctx.span_s, ylabels, bands=ctx.bands(), **kw)


# --- timeline -----------------------------------------------------------------------------------
def _intervals(t: NDArray[np.float64], on: NDArray[np.bool_], t_end: float) -> list[tuple[float, float]]:
    """(start, end) [s] of each run of ``on``; the last one ends at ``t_end`` if still on."""
    edges = np.diff(np.concatenate(([0], on.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(float(t[a]), float(t[b]) if b < len(t) else t_end) for a, b in zip(starts, stops)]


def _timeline(ctx: _Context) -> Figure:
    data: list[dict[str, Any]] = []
    rows: list[str] = []
    icing: list[tuple[_Run, VectorTopic]] = []
    for r in ctx.runs:
        g = f"run-{r.index}"
        faults = [(r.name(f"fault {f.get('label', '?')}"),
                   [(float(a), min(float(b), r.log.end_t_s)) for a, b in f.get("windows_s", [])
                    if float(a) <= r.log.end_t_s]) for f in r.catalog()]  # a window after a cut-off log never began
        alarm_rows, onset_x, onset_y, onset_txt, iso_x, iso_y, iso_txt = [], [], [], [], [], [], []
        for det in r.detectors():
            st = r.statistic(det)
            row = r.name(det)
            alarm = st["alarm"] > 0.5
            alarm_rows.append((row, _intervals(st.t_s, alarm, r.log.end_t_s)))
            on = r.alarm_onsets_s(det)
            onset_x += on.tolist()
            onset_y += [row] * on.size
            onset_txt += [f"{det}: alarm"] * on.size
            hyp = r.hypotheses(det)
            iso = st["isolation"] if "isolation" in st.fields else np.full(len(st), -1.0)
            ch = np.flatnonzero((iso >= 0) & (np.diff(np.concatenate(([-1.0], iso))) != 0))
            iso_x += st.t_s[ch].tolist()
            iso_y += [row] * ch.size
            iso_txt += [f"{det}: isolated {_hyp_name(hyp, int(iso[i]))}" for i in ch.tolist()]
        rows += [f for f, _ in faults] + [a for a, _ in alarm_rows]
        for tr in (bars(faults, r.name("true fault interval"), r.colour(3), 10, g),
                   bars(alarm_rows, r.name("alarm active"), r.colour(0), 6, g)):
            if tr is not None:
                data.append(tr)
        if onset_x:
            data.append(markers(onset_x, onset_y, r.name("alarm onset"), r.colour(0), "triangle-up",
                                 text=onset_txt, group=g))
        if iso_x:
            data.append(markers(iso_x, iso_y, r.name("isolation"), r.colour(1), "diamond", text=iso_txt,
                                 size=7, group=g))
        rec = [e for e in r.events(TOPIC_RECONFIGURATION)]
        if rec:
            row = r.name("reconfiguration")
            rows.append(row)
            data.append(markers([e.t_s for e in rec], [row] * len(rec), r.name("reconfiguration"), r.colour(2), "x",
                                 text=[f"{e.payload.get('action', '')} {e.payload.get('sensor', '')} "
                                       f"(by {e.payload.get('detector', '')})" for e in rec], size=11, group=g))
        sw = r.switches()
        if sw:
            row = r.name("schedule switch")
            rows.append(row)
            data.append(markers([s[0] for s in sw], [row] * len(sw), r.name("schedule switch"), r.colour(4),
                                 "line-ns-open", text=[f"{d}: node {a} -> {b}" for _, d, a, b in sw], size=12,
                                 group=g))
        op = r.vector(TOPIC_OPERATING_POINT)
        if op is not None and "icing_eta" in op.fields and bool(np.any(op["icing_eta"] > 0)):
            icing.append((r, op))
    rows = list(dict.fromkeys(rows)) or ["(no faults, no detectors)"]
    heights = [max(1.0, 0.22 * len(rows))] + ([0.8] if icing else [])
    lay = _layout(ctx, [""] + (["icing eta [-]"] if icing else []), title="Timeline", heights=heights)
    lay["yaxis"].update({"type": "category", "categoryorder": "array", "categoryarray": rows[::-1],
                         "range": [-0.7, len(rows) - 0.3], "tickfont": {"size": 10}, "automargin": True})
    dec = ctx.decimator()
    for r, op in icing:
        t, y = _series(dec, op, "icing_eta")
        data.append(line(t, y, r.name("icing eta"), r.colour(5), panel=2, group=f"run-{r.index}"))
    if not data:
        later = [f"{f.get('label', '?')} from {float(f['windows_s'][0][0]):.2f} s" for r in ctx.runs
                 for f in r.catalog() if f.get("windows_s")]  # every window began after the log's end
        if later:
            caption = (f"No fault started and no detector alarmed before the log ends: {', '.join(later)} was "
                       "scheduled after it.")
        elif ctx.detectors:
            caption = "No fault was injected and no detector alarmed in this run: nothing to mark on the timeline."
        else:
            caption = "No fault was injected and no detector ran in this run: nothing to mark on the timeline."
        return Figure("fig-timeline", "Faults, alarms and isolations", caption, {"data": data, "layout": lay})
    caption = ("Shaded bands and thick bars are the true fault intervals from the log's catalog; thin bars mark "
               "each detector's alarm, triangles its onsets, diamonds each isolation (hover for the hypothesis)"
               + ("; crosses the reconfigurations" if any(r.events(TOPIC_RECONFIGURATION) for r in ctx.runs) else "")
               + ("; the lower panel the icing severity eta." if icing else "."))
    return Figure("fig-timeline", "Faults, alarms and isolations", caption, {"data": data, "layout": lay})


def _hyp_name(hyp: Sequence[str], k: int) -> str:
    if k < 0:
        return "rejected"
    return hyp[k] if k < len(hyp) else f"hypothesis {k}"


# --- per detector ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Detection:
    text: str
    t_s: float | None  # first alarm at or after the onset [s]
    delay_s: float | None


def _detection(r: _Run, det: str, st: VectorTopic) -> list[_Detection]:
    """One per injected fault: first alarm at or after onset, delay, isolation (right/wrong), by the
    rule of the run summary and the review (:func:`fdi_sim.decision.outcome.fault_outcome`)."""
    from fdi_sim.decision.outcome import fault_outcome

    a = st["alarm"] > 0.5
    iso = st["isolation"] if "isolation" in st.fields else np.full(len(st), -1.0)
    hyp = r.hypotheses(det)
    names = [None if k < 0 else _hyp_name(hyp, int(k)) for k in iso.tolist()]
    out = []
    for f in r.catalog():
        if not f.get("windows_s"):
            continue
        o = fault_outcome({"label": f.get("label", "?"), **f}, st.t_s, a, names)
        lab = r.name(o.label)
        if o.first_alarm_s is None:
            out.append(_Detection(f"{lab}: not detected", None, None))
            continue
        mark = "" if o.isolation_correct is None else (" (right)" if o.isolation_correct else " (wrong)")
        out.append(_Detection(f"{lab}: detected at {o.first_alarm_s:.2f} s, delay {o.delay_s:.2f} s, isolated as "
                              f"{o.isolated_as or 'not isolated'}{mark}", o.first_alarm_s, o.delay_s))
    return out


def _statistic_figure(ctx: _Context, det: str) -> Figure:
    dec = ctx.decimator(det)
    data: list[dict[str, Any]] = []
    found: list[tuple[_Run, _Detection, float]] = []
    positive: list[NDArray[np.float64]] = []
    for r in ctx.runs:
        st = r.statistic(det)
        if st is None:
            continue
        g = f"run-{r.index}"
        valid = st["valid"] > 0.5 if "valid" in st.fields else np.ones(len(st), dtype=bool)
        s = np.where(valid, st["statistic"], np.nan)
        d = dec(st.t_s, s)
        data.append(line(d.t_s, d.y, r.name("statistic"), r.colour(0), group=g))
        thr = dec(st.t_s, st["threshold"])
        data.append(line(thr.t_s, thr.y, r.name("threshold"), r.colour(1), dash="dash", width=1.6, group=g))
        on = np.flatnonzero(np.isin(st.t_s, r.alarm_onsets_s(det)))
        if on.size:
            hyp = r.hypotheses(det)
            iso = st["isolation"] if "isolation" in st.fields else np.full(len(st), -1.0)
            data.append(markers(st.t_s[on].tolist(), values(st["statistic"][on]), r.name("alarm onset"), r.colour(0),
                                 "triangle-up", text=[f"alarm, isolated {_hyp_name(hyp, int(iso[i]))}" for i in on],
                                 group=g))
        data.append(line(*_step(dec, st.t_s, valid.astype(np.float64)), r.name("valid"), r.colour(2), panel=2,
                          shape="hv", group=g))
        data.append(line(*_step(dec, st.t_s, (st["alarm"] > 0.5).astype(np.float64) * 0.9), r.name("alarm"),
                          r.colour(0), panel=2, shape="hv", width=2, group=g))
        fin = np.concatenate((s[np.isfinite(s)], st["threshold"]))
        positive.append(fin[fin > 0])
        for hit in _detection(r, det, st):
            k = int(np.searchsorted(st.t_s, hit.t_s)) if hit.t_s is not None else 0
            found.append((r, hit, float(st["statistic"][min(k, len(st) - 1)])))
    pos = np.concatenate(positive) if positive else np.zeros(0)
    log_y = pos.size > 0 and float(pos.max()) / float(pos.min()) > 100.0
    lay = _layout(ctx, ["statistic [-]", "valid, alarm [0/1]"], title=f"{det}: test statistic against threshold",
                  ylog=(1,) if log_y else (), heights=[2.2, 0.6])
    lay["yaxis2"].update({"range": [-0.1, 1.1], "tickvals": [0, 1]})
    for r, hit, y in found:  # the detection delay, pointed at (log axes place annotations in log10)
        if hit.t_s is not None and np.isfinite(y) and (y > 0 or not log_y):
            lay["annotations"].append({"x": round(hit.t_s, 3), "y": float(np.log10(y)) if log_y else y,
                                       "xref": "x", "yref": "y", "text": r.name(f"delay {hit.delay_s:.2f} s"),
                                       "showarrow": True, "arrowhead": 2, "ax": 30, "ay": -30,
                                       "font": {"size": 10, "color": r.colour(0)}, "arrowcolor": r.colour(0)})
    lines = [hit.text for _, hit, _ in found]
    caption = (f"Statistic against its threshold{' (log scale)' if log_y else ''} over the shaded true fault "
               "intervals; gaps where the detector was not valid. " + ("; ".join(lines) + "." if lines else
                                                                      "No fault injected."))
    return Figure(f"fig-det-{dom_id(det)}-statistic", f"{det}: statistic", caption, {"data": data, "layout": lay})


def _step(dec: Decimator, t: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    d = dec(t, y)
    return d.t_s, d.y


def _residual_figure(ctx: _Context, det: str) -> Figure | None:
    comps: list[str] = []
    for r in ctx.runs:
        res = r.vector(f"/fdi/{det}/residual")
        if res is not None:
            comps += [c for c in res.fields[1:] if c not in comps]
    if not comps:
        return None
    dec = ctx.decimator(det)
    data = []
    ylabels = []
    for i, c in enumerate(comps, start=1):
        base, unit, scale = display_unit(c)
        ylabels.append(f"{base} [{unit}]")
        for r in ctx.runs:
            res = r.vector(f"/fdi/{det}/residual")
            if res is not None and c in res.fields:
                t, y = _series(dec, res, c, scale)
                data.append(line(t, y, r.name(f"{base} [{unit}]"), r.colour(0 if r.multi else i - 1), panel=i,
                                  group=f"run-{r.index}"))
    lay = _layout(ctx, ylabels, title=f"{det}: residual components", heights=[0.8] * len(comps))
    return Figure(f"fig-det-{dom_id(det)}-residual", f"{det}: residuals",
                  "Each residual component in its own unit; a fault shows as a shift inside its shaded band.",
                  {"data": data, "layout": lay})


# --- flight --------------------------------------------------------------------------------------
def _panel_figure(ctx: _Context, fig_id: str, title: str, caption: str,
                  panels: Sequence[Sequence[tuple[str, str, str]]], ylabels: Sequence[str],
                  overlay: dict[int, tuple[str, Sequence[tuple[str, str, str]]]] | None = None,
                  extra_shapes: Sequence[dict[str, Any]] = ()) -> Figure | None:
    """Panels of (topic, field, legend) lines, truth solid and references dashed.

    ``overlay`` maps a panel to (axis label, lines) drawn on a right-hand y axis.
    """
    dec = ctx.decimator()
    data: list[dict[str, Any]] = []
    overlay = overlay or {}
    axis_of = {p: len(panels) + j for j, p in enumerate(sorted(overlay), start=1)}
    for r in ctx.runs:
        k = 0
        for i, lines in enumerate(panels, start=1):
            groups = [(lines, None)] + ([(overlay[i][1], axis_of[i])] if i in overlay else [])
            for lines_, yaxis in groups:
                for topic, field, legend in lines_:
                    vt = r.vector(topic)
                    if vt is None or field not in vt.fields:
                        continue
                    _, _, scale = display_unit(field)
                    t, y = _series(dec, vt, field, scale)
                    ref = "ref" in field or "_cmd_" in field or yaxis is not None
                    data.append(line(t, y, r.name(legend), r.colour(k), panel=i, yaxis=yaxis,
                                      dash="dash" if ref else None, width=1.1 if ref else 1.4,
                                      group=f"run-{r.index}"))
                    k += 1
    if not data:
        return None
    lay = _layout(ctx, ylabels, title=title, overlay={p: lab for p, (lab, _) in overlay.items()})
    lay["shapes"] = list(lay.get("shapes", [])) + list(extra_shapes)
    return Figure(fig_id, title, caption, {"data": data, "layout": lay})


def _flight_figures(ctx: _Context) -> list[Figure | None]:
    S, C, O, P = TOPIC_TRUTH_STATE, TOPIC_COMMANDS, TOPIC_OPERATING_POINT, TOPIC_SURFACES
    figs = [
        _panel_figure(ctx, "fig-flight-path", "Altitude and airspeed",
                      "Altitude and calibrated airspeed (truth) against the autopilot's references.",
                      [[(S, "h_ft", "h [ft]"), (C, "h_ref_ft", "h ref [ft]")],
                       [(S, "vc_kts", "vc [kt]"), (C, "vc_ref_kts", "vc ref [kt]")],
                       [(S, "hdot_fps", "hdot [ft/s]")]],
                      ["h [ft]", "vc [kt]", "hdot [ft/s]"]),
        _panel_figure(ctx, "fig-flight-attitude", "Attitude",
                      "Bank, pitch and heading angles (truth) against the references the autopilot holds.",
                      [[(S, "phi_rad", "phi [deg]"), (C, "phi_ref_rad", "phi ref [deg]")],
                       [(S, "theta_rad", "theta [deg]")],
                       [(S, "psi_rad", "psi [deg]"), (C, "psi_ref_rad", "psi ref [deg]")]],
                      ["phi [deg]", "theta [deg]", "psi [deg]"]),
        _panel_figure(ctx, "fig-flight-rates", "Rates, flow angles and load factor",
                      "Body rates, angle of attack and sideslip, and normal load factor (truth).",
                      [[(S, "p_radps", "p [deg/s]"), (S, "q_radps", "q [deg/s]"), (S, "r_radps", "r [deg/s]")],
                       [(S, "alpha_rad", "alpha [deg]"), (S, "beta_rad", "beta [deg]")],
                       [(S, "nz_g", "nz [g]")]],
                      ["p, q, r [deg/s]", "alpha, beta [deg]", "nz [g]"]),
        _panel_figure(ctx, "fig-flight-surfaces", "Surfaces against commands",
                      "Surface positions flown (left axis, deg) against the pilot's commands (dashed, right axis): "
                      "an actuator fault shows as a position that stops following its command.",
                      [[(P, "elevator_pos_rad", "elevator [deg]")], [(P, "aileron_pos_rad", "aileron [deg]")],
                       [(P, "rudder_pos_rad", "rudder [deg]")],
                       [(P, "throttle_pos_norm", "throttle [-]"), (C, "throttle_cmd_norm", "throttle cmd [-]")]],
                      ["elevator [deg]", "aileron [deg]", "rudder [deg]", "throttle [-]"],
                      overlay={1: ("cmd [-]", [(C, "elevator_cmd_norm", "elevator cmd [-]")]),
                               2: ("cmd [-]", [(C, "aileron_cmd_norm", "aileron cmd [-]")]),
                               3: ("cmd [-]", [(C, "rudder_cmd_norm", "rudder cmd [-]")])}),
    ]
    switches = [s for r in ctx.runs for s in r.switches()][:MAX_SWITCH_LINES]
    lines = [{"type": "line", "xref": "x", "yref": "paper", "x0": t, "x1": t, "y0": 0, "y1": 1,
              "line": {"color": "#7f7f7f", "width": 1, "dash": "dot"}, "name": f"{d}: node {a} -> {b}"}
             for t, d, a, b in switches]
    figs.append(_panel_figure(
        ctx, "fig-flight-operating-point", "Operating point and schedule switches",
        "The operating point the detectors are scheduled on; dotted lines mark schedule switches"
        + (f" ({len(switches)})." if switches else " (none in this run)."),
        [[(O, "h_ft", "h [ft]")], [(O, "vc_kts", "vc [kt]")], [(O, "mach", "mach [-]")],
         [(O, "alpha_rad", "alpha [deg]")], [(O, "flaps_deg", "flaps [deg]")], [(O, "icing_eta", "icing eta [-]")]],
        ["h [ft]", "vc [kt]", "mach [-]", "alpha [deg]", "flaps [deg]", "icing eta [-]"], extra_shapes=lines))
    return figs


# --- sensors ---------------------------------------------------------------------------------------
def _sensor_figures(ctx: _Context) -> list[Figure]:
    targets: list[str] = []
    for r in ctx.runs:
        meas = r.vector(TOPIC_SENSORS)
        for f in r.catalog():
            tg = str(f.get("target", ""))
            if meas is not None and tg in meas.fields and tg not in targets:
                targets.append(tg)
    dec = ctx.decimator()
    figs = []
    for tg in targets:
        base, unit, scale = display_unit(tg)
        data = []
        for r in ctx.runs:
            meas, truth = r.vector(TOPIC_SENSORS), r.vector(TOPIC_TRUTH_STATE)
            g = f"run-{r.index}"
            if meas is None or tg not in meas.fields:
                continue
            t, y = _series(dec, meas, tg, scale)
            data.append(line(t, y, r.name(f"{base} measured"), r.colour(0), group=g))
            if truth is not None and tg in truth.fields:
                t, y = _series(dec, truth, tg, scale)
                data.append(line(t, y, r.name(f"{base} truth"), r.colour(1), dash="dash", group=g))
                err = _error(meas, truth, tg)
                d = dec(meas.t_s, err)
                data.append(line(d.t_s, d.y * scale, r.name(f"{base} measured - truth"), r.colour(2), panel=2,
                                  group=g))
        lay = _layout(ctx, [f"{base} [{unit}]", f"error [{unit}]"], title=f"Sensor {tg}: truth against measurement",
                      heights=[1.4, 1.0])
        figs.append(Figure(f"fig-sensor-{dom_id(tg)}", f"Sensor {tg}",
                           f"The measured {base} against the truth, and their difference; the fault acts inside the "
                           "shaded band.", {"data": data, "layout": lay}))
    return figs


def _error(meas: VectorTopic, truth: VectorTopic, field: str) -> NDArray[np.float64]:
    """Measurement minus truth at the measurement times (truth interpolated where they differ)."""
    tm, tt = meas.t_s, truth.t_s
    y_true = truth[field] if tm.shape == tt.shape and np.array_equal(tm, tt) else np.interp(tm, tt, truth[field])
    return meas[field] - y_true

"""Building blocks of plotly figure specs as plain dicts: numbers, units, panels, traces.

:mod:`fdi_sim.review.figures` composes the report's figures from these. Values are stored at 6
significant digits and times at 1 ms, NaN as None, so a spec is JSON as it stands; panels share
one time axis through ``matches``; only ``scatter`` traces (WebGL fails in headless Chromium).
"""
from __future__ import annotations

import json
import math
import re
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.units import DEG_PER_RAD

PANEL_PX: int = 150
"""Height of a panel of unit weight [px]."""

# one colour family per run: cool for the first, warm for the second, then greys and purples
FAMILIES: tuple[tuple[str, ...], ...] = (
    ("#1f5fa8", "#2a9d8f", "#6a8fd0", "#1b7837", "#5e3c99", "#4d4d4d"),
    ("#d62728", "#ff7f0e", "#e377c2", "#b8860b", "#8c2d04", "#c51b7d"),
    ("#555555", "#8e6bbf", "#999999", "#6b4c9a", "#333333", "#b39ddb"),
)
BAND_FILLS: tuple[str, ...] = ("rgba(214,39,40,0.13)", "rgba(255,127,14,0.13)", "rgba(148,103,189,0.13)",
                               "rgba(140,86,75,0.13)", "rgba(23,190,207,0.13)")
_UNITS: tuple[tuple[str, str, float], ...] = (
    ("_radps", "deg/s", DEG_PER_RAD), ("_rad", "deg", DEG_PER_RAD), ("_degps", "deg/s", 1.0), ("_deg", "deg", 1.0),
    ("_kts", "kt", 1.0), ("_fps", "ft/s", 1.0), ("_ft", "ft", 1.0), ("_g", "g", 1.0), ("_norm", "-", 1.0),
    ("_lbf", "lbf", 1.0), ("_s", "s", 1.0))


def dumps(x: Any) -> str:
    """Compact JSON, no NaN, safe inside ``<script>`` (``</`` escaped)."""
    return json.dumps(x, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


# --- numbers for the spec ------------------------------------------------------------------
def values(y: NDArray[np.float64]) -> list[float | None]:
    """Values rounded to 6 significant digits, NaN and inf as None (a gap in the line).

    Rounding is vectorised: ``round(y * 10**k) / 10**k`` with ``k = 5 - floor(log10|y|)``; dividing
    an integer by an exact power of ten gives the double nearest the decimal, whose shortest repr
    is the 6-digit string, so the JSON stays short.
    """
    v = np.asarray(y, dtype=np.float64)
    bad = ~np.isfinite(v)
    a = np.abs(np.where(bad, 1.0, v))
    k = np.where(a > 0, 5 - np.floor(np.log10(np.where(a > 0, a, 1.0))), 0).astype(np.int64)
    k = np.clip(k, -300, 300)
    r = np.where(k >= 0, np.round(v * 10.0 ** np.maximum(k, 0)) / 10.0 ** np.maximum(k, 0),
                 np.round(v / 10.0 ** np.maximum(-k, 0)) * 10.0 ** np.maximum(-k, 0))
    out: list[float | None] = np.where(bad, 0.0, r).tolist()
    for i in np.flatnonzero(bad).tolist():
        out[i] = None
    return out


def times(t_s: NDArray[np.float64]) -> list[float]:
    """Times [s] at 1 ms."""
    return np.round(np.asarray(t_s, dtype=np.float64), 3).tolist()


def display_unit(name: str) -> tuple[str, str, float]:
    """``(label, unit, scale)`` for a suffixed signal name: ``alpha_rad`` -> ``("alpha", "deg", 57.3)``."""
    for suffix, unit, scale in _UNITS:
        if name.endswith(suffix):
            return name[: -len(suffix)], unit, scale
    return name, "-", 1.0


def dom_id(text: str) -> str:
    """A DOM id fragment from a detector id or signal name (``offline/kalman-nis-v1`` -> ``offline-kalman-nis-v1``)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text)


# --- layout helpers ---------------------------------------------------------------------------
def axis_key(i: int, letter: str) -> str:
    """Layout key of panel ``i``'s axis (1-based): ``xaxis``, ``yaxis3``."""
    return f"{letter}axis" if i == 1 else f"{letter}axis{i}"


def axis_ref(i: int, letter: str) -> str:
    """A trace's reference to panel ``i``'s axis: ``x``, ``y3``."""
    return letter if i == 1 else f"{letter}{i}"


def panel_layout(span_s: tuple[float, float], ylabels: Sequence[str], *, title: str,
                 bands: tuple[list[dict[str, Any]], list[dict[str, Any]]] | None = None,
                 ylog: Sequence[int] = (), overlay: dict[int, str] | None = None,
                 heights: Sequence[float] | None = None) -> dict[str, Any]:
    """Stacked panels sharing one time axis (``matches``: zooming one zooms all).

    Parameters
    ----------
    span_s : (float, float)
        The time axis range [s] (the runs' span: a catalog window past the log's end is clipped here).
    ylabels : sequence of str
        One y label per panel, top to bottom, each with its unit.
    bands : (shapes, annotations), optional
        Fault-band shapes and their labels.
    ylog : sequence of int
        Panels (1-based) on a log y axis.
    overlay : dict of int to str, optional
        Panel -> label of a second y axis on its right (axes ``n + 1``, ``n + 2``, ... in panel order).
    heights : sequence of float, optional
        Relative panel heights; a unit weight is :data:`PANEL_PX` pixels.
    """
    n = len(ylabels)
    w = np.asarray(heights if heights is not None else [1.0] * n, dtype=np.float64)
    gap = 0.06 if n <= 3 else 0.025
    usable = 1.0 - gap * (n - 1)
    tops = 1.0 - np.concatenate(([0.0], np.cumsum(w / w.sum() * usable + gap)[:-1]))
    # the axis spans the log to the millisecond the traces are rounded to, so a segment ending at the log's
    # last sample is not cut off by its own rounding
    t0, t1 = math.floor(span_s[0] * 1000.0) / 1000.0, math.ceil(span_s[1] * 1000.0) / 1000.0
    lay: dict[str, Any] = {"title": {"text": title, "x": 0.01, "font": {"size": 14}},
                           "height": int(90 + PANEL_PX * w.sum()), "margin": {"l": 70, "r": 70, "t": 50, "b": 45},
                           "hovermode": "closest", "showlegend": True,
                           "legend": {"orientation": "h", "traceorder": "normal", "y": -0.06 - 0.25 / max(n, 1), "font": {"size": 10}},
                           "plot_bgcolor": "white"}
    for i in range(1, n + 1):
        top = float(tops[i - 1])
        bottom = top - float(w[i - 1] / w.sum() * usable)
        xa: dict[str, Any] = {"anchor": axis_ref(i, "y"), "showticklabels": i == n, "showgrid": True,
                              "gridcolor": "#eeeeee", "zeroline": False, "range": [t0, t1]}
        if i > 1:
            xa["matches"] = "x"
        if i == n:
            xa["title"] = {"text": "t [s]"}
        lay[axis_key(i, "x")] = xa
        lay[axis_key(i, "y")] = {"domain": [max(bottom, 0.0), min(top, 1.0)], "anchor": axis_ref(i, "x"),
                              "title": {"text": ylabels[i - 1], "font": {"size": 11}}, "gridcolor": "#eeeeee",
                              "type": "log" if i in ylog else "linear", "zeroline": False}
    for j, (panel, label) in enumerate(sorted((overlay or {}).items()), start=n + 1):
        lay[axis_key(j, "y")] = {"overlaying": axis_ref(panel, "y"), "side": "right", "anchor": axis_ref(panel, "x"),
                              "title": {"text": label, "font": {"size": 11}}, "showgrid": False, "zeroline": False}
    if bands is not None:
        lay["shapes"], lay["annotations"] = list(bands[0]), list(bands[1])
    return lay


def line(t: NDArray[np.float64], y: NDArray[np.float64], name: str, colour: str, *, panel: int = 1,
         yaxis: int | None = None, dash: str | None = None, width: float = 1.3, group: str | None = None,
         shape: str | None = None) -> dict[str, Any]:
    """A ``scatter`` line trace on panel ``panel`` (or on y axis ``yaxis``, an overlay).

    Parameters
    ----------
    t : NDArray
        Times [s] (stored at 1 ms).
    y : NDArray
        Values in the unit the axis names (stored at 6 significant digits, NaN as a gap).
    width : float
        Line width [px].
    shape : str, optional
        ``"hv"`` for a step (flags such as ``valid``).
    """
    style: dict[str, Any] = {"color": colour, "width": width}
    if dash:
        style["dash"] = dash
    if shape:
        style["shape"] = shape
    tr: dict[str, Any] = {"type": "scatter", "mode": "lines", "name": name, "x": times(t), "y": values(y),
                          "line": style, "xaxis": axis_ref(panel, "x"), "yaxis": axis_ref(yaxis or panel, "y"),
                          "connectgaps": False}
    if group:
        tr["legendgroup"] = group
    return tr


def markers(t: Sequence[float], y: Sequence[Any], name: str, colour: str, symbol: str, *, panel: int = 1,
            text: Sequence[str] | None = None, size: int = 9, group: str | None = None) -> dict[str, Any]:
    """Event markers at times ``t`` [s] (1 ms), ``y`` values or category rows, ``text`` on hover; ``size`` [px]."""
    tr: dict[str, Any] = {"type": "scatter", "mode": "markers", "name": name, "x": [round(float(v), 3) for v in t],
                          "y": list(y), "marker": {"color": colour, "symbol": symbol, "size": size,
                                                   "line": {"width": 1, "color": colour}},
                          "xaxis": axis_ref(panel, "x"), "yaxis": axis_ref(panel, "y")}
    if text is not None:
        tr["text"] = list(text)
        tr["hovertemplate"] = "%{text}<br>t = %{x:.3f} s<extra></extra>"
    if group:
        tr["legendgroup"] = group
    return tr


def bars(rows: list[tuple[str, list[tuple[float, float]]]], name: str, colour: str, width: float,
         group: str) -> dict[str, Any] | None:
    """One trace of horizontal bars on the category rows of panel 1: ``(row, [(start, end) [s], ...])``;
    ``width`` [px]. None when there is no interval."""
    x: list[float | None] = []
    y: list[str | None] = []
    for row, spans in rows:
        for a, b in spans:
            x += [round(a, 3), round(b, 3), None]
            y += [row, row, None]
    if not x:
        return None
    return {"type": "scatter", "mode": "lines", "name": name, "x": x, "y": y, "legendgroup": group, "xaxis": "x",
            "yaxis": "y", "line": {"color": colour, "width": width}, "opacity": 0.55, "hoverinfo": "x+y",
            "connectgaps": False}

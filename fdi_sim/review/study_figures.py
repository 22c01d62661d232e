"""The study report's figures (matplotlib's object interface, the Agg renderer: no pyplot state,
no display): ROC curves, false-alarm rate against threshold scale, delay histograms, confusion
matrices. Used by :mod:`fdi_sim.study.report`; here because ``review/`` is where matplotlib is imported.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.study.stats import BANK, NOT_DETECTED, NOT_ISOLATED

def _f(x: Any, digits: int = 3) -> str:
    """A number in ``digits`` significant figures ("-" for None or NaN)."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return f"{float(x):.{digits}g}"


def _figure(n_panels: int, panel_w: float = 3.6, panel_h: float = 2.8, cols: int = 3) -> tuple[Any, list[Any]]:
    from matplotlib.figure import Figure

    cols = max(1, min(cols, n_panels))
    rows = max(1, math.ceil(n_panels / cols))
    fig = Figure(figsize=(panel_w * cols, panel_h * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel().tolist()
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return fig, axes[:n_panels]


def _save(fig: Any, path: Path) -> Path:
    fig.savefig(path, dpi=90)
    return path


def _ids(summary: Mapping[str, Any]) -> list[str]:
    return [d["id"] for d in summary["detectors"]] + [BANK]


def roc_figure(rescored: Any, path: Path, confidence: float = 0.95) -> Path:
    """ROC per member (and the bank): p_detect against false alarms per flight hour (log x), one
    curve per fault type; a point with no false alarm is drawn at the axis' left edge (hollow)."""
    from fdi_sim.study.rescore import roc

    curves = roc(rescored, confidence)
    ids = list(curves)
    fig, axes = _figure(max(1, len(ids)))
    for ax, ident in zip(axes, ids):
        pos = [c.far_per_h[c.far_per_h > 0] for c in curves[ident].values()]
        pos = np.concatenate(pos) if pos else np.zeros(0)
        floor = 0.5 * float(pos.min()) if pos.size else 0.1
        for ty, c in curves[ident].items():
            x = np.where(c.far_per_h > 0, c.far_per_h, floor)
            line, = ax.plot(x, c.p_detect, "-", lw=1.2, label=f"{ty} ({c.faults})")
            zero = c.far_per_h == 0
            ax.plot(x[zero], c.p_detect[zero], "o", mfc="none", ms=4, color=line.get_color())
            at1 = int(np.argmin(np.abs(np.log(c.scales))))
            ax.plot(x[at1], c.p_detect[at1], "s", ms=5, color=line.get_color())
        ax.set_xscale("log")
        ax.set_ylim(-0.03, 1.03)
        ax.set_title(ident, fontsize=9)
        ax.set_xlabel("false alarms per flight hour")
        ax.set_ylabel("p_detect")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, loc="lower right")
    if not ids:
        axes[0].text(0.5, 0.5, "no faults injected: no ROC", ha="center", va="center")
    fig.suptitle("ROC (square: the logged threshold; hollow: no false alarm, drawn at the left edge)", fontsize=9)
    return _save(fig, path)


def _log_ticks(ax: Any, lo: float, hi: float, axis: str = "x") -> None:
    """Plain-number ticks (1-2-5 steps) on a log axis between ``lo`` and ``hi``."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    decades = np.arange(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1)
    ticks = [m * 10.0 ** e for e in decades for m in (1, 2, 5) if lo <= m * 10.0 ** e <= hi]
    target = ax.xaxis if axis == "x" else ax.yaxis
    target.set_major_locator(FixedLocator(ticks))
    target.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    target.set_minor_locator(NullLocator())


def far_figure(rescored: Any, summary: Mapping[str, Any], path: Path, confidence: float = 0.95) -> Path:
    """False alarms per flight hour against threshold scale with exact Poisson intervals, per
    member and the bank, with the predicted (design) rate as a line; a scale with no false alarm
    is a hollow triangle at the bottom edge (its interval's upper end still shows)."""
    from fdi_sim.decision.intervals import poisson_rate_interval

    pred = {d["id"]: d.get("predicted_far_per_h") for d in list(summary["detectors"]) + [summary["bank"]]}
    ids = list(rescored.detectors)
    fig, axes = _figure(max(1, len(ids)))
    x = rescored.scales
    for ax, ident in zip(axes, ids):
        d = rescored.detectors[ident]
        if d.exposure_h <= 0:
            ax.set_title(f"{ident}: no fault-free exposure", fontsize=9)
            continue
        ci = np.array([poisson_rate_interval(int(c), d.exposure_h, confidence) for c in d.false_alarms])
        r = d.far_per_h
        lows = [v for v in (list(r[r > 0]) + list(ci[:, 1]) + [pred.get(ident) or math.inf]) if v > 0]
        bottom = 0.5 * min(lows)
        ax.fill_between(x, np.maximum(ci[:, 0], bottom), ci[:, 1], alpha=0.25, label=f"{confidence:.0%} interval")
        pos = r > 0
        ax.plot(x[pos], r[pos], "k.-", lw=1.0, ms=3, label="empirical")
        ax.plot(x[~pos], np.full((~pos).sum(), bottom), "kv", mfc="none", ms=4, label="no false alarm")
        if pred.get(ident):
            ax.axhline(pred[ident], color="r", ls="--", lw=1.0, label=f"predicted {pred[ident]:.3g} /h")
        ax.axvline(1.0, color="grey", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(bottom / 1.5, None)
        if x.size and x.min() > 0:
            _log_ticks(ax, float(x.min()), float(x.max()))
        ax.set_title(f"{ident} ({d.exposure_h:.3g} h)", fontsize=9)
        ax.set_xlabel("threshold scale")
        ax.set_ylabel("false alarms per flight hour")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
    return _save(fig, path)


def delay_figure(summary: Mapping[str, Any], path: Path) -> Path:
    """Detection-delay histograms per member and the bank, stacked by fault type."""
    blocks = list(summary["detectors"]) + [summary["bank"]]
    fig, axes = _figure(len(blocks))
    every = [x for b in blocks for x in b["delays_s"]]
    edges = np.histogram_bin_edges(every, bins=20) if every else np.linspace(0, 1, 11)
    for ax, b in zip(axes, blocks):
        per_type = [(t, x["delays_s"]) for t, x in b["by_fault_type"].items() if x["delays_s"]]
        if per_type:
            ax.hist([v for _, v in per_type], bins=edges, stacked=True, label=[t for t, _ in per_type])
            ax.legend(fontsize=6)
        else:
            ax.text(0.5, 0.5, "no detection", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(f"{b['id']}: median {_f(b['delay_s_median'])} s, p95 {_f(b['delay_s_p95'])} s", fontsize=9)
        ax.set_xlabel("delay [s]")
        ax.set_ylabel("faults")
    return _save(fig, path)


def confusion_matrix(confusion: Mapping[str, Mapping[str, int]]) -> tuple[list[str], list[str], NDArray[np.int64]]:
    """Rows (true targets), columns (isolated as: the targets first, in row order, so that right
    isolations of sensors lie on the diagonal; then ``not isolated``, ``not detected``) and counts."""
    rows = sorted(confusion)
    named = {c for r in confusion.values() for c in r} - {NOT_ISOLATED, NOT_DETECTED}
    cols = [r for r in rows if r in named] + sorted(named - set(rows)) + [NOT_ISOLATED, NOT_DETECTED]
    m = np.array([[confusion[r].get(c, 0) for c in cols] for r in rows], dtype=np.int64).reshape(len(rows), len(cols))
    return rows, cols, m


def confusion_figure(summary: Mapping[str, Any], path: Path) -> Path:
    """One confusion matrix per member and the bank: true target (rows) -> isolated as (columns)."""
    blocks = [b for b in list(summary["detectors"]) + [summary["bank"]] if b["confusion"]]
    fig, axes = _figure(max(1, len(blocks)), panel_w=4.2, panel_h=3.4)
    for ax, b in zip(axes, blocks):
        rows, cols, m = confusion_matrix(b["confusion"])
        ax.imshow(m, cmap="Blues", aspect="auto")
        for i in range(m.shape[0]):
            for j in range(m.shape[1]):
                if m[i, j]:
                    ax.text(j, i, str(m[i, j]), ha="center", va="center", fontsize=7,
                            color="white" if m[i, j] > 0.6 * m.max() else "black")
        ax.set_xticks(range(len(cols)), cols, rotation=60, ha="right", fontsize=6)
        ax.set_yticks(range(len(rows)), rows, fontsize=6)
        ax.set_title(b["id"], fontsize=9)
        ax.set_ylabel("true target", fontsize=7)
    if not blocks:
        axes[0].text(0.5, 0.5, "no faults injected", ha="center", va="center")
    return _save(fig, path)


# --- the page ---------------------------------------------------------------------------------------------

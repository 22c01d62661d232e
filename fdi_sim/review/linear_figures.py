"""Figures of a linear model schedule (matplotlib lives only in ``fdi_sim.review``).

:func:`pole_map` draws the continuous-time eigenvalues of every schedule point, one marker per
named mode and the colour by calibrated airspeed, with a zoomed panel for the slow modes
(phugoid, spiral) next to the full view.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

_MARKERS = {"short period": "o", "phugoid": "s", "altitude": "v", "dutch roll": "D", "roll": "^", "spiral": "P",
            "heading": "x", "engine": "*", "other": "."}


def pole_map(schedule: Any, path: str | Path, title: str | None = None) -> Path:
    """Save the pole map of ``schedule`` (a :class:`fdi_sim.linear.schedule.ModelSchedule`) as PNG.

    Returns
    -------
    Path
        The file written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    pts = schedule.ok_points
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), layout="constrained")
    vc = np.array([p.sched["vc_kts"] for p in pts]) if pts else np.zeros(0)
    norm = plt.Normalize(vc.min(), vc.max()) if vc.size else None
    cmap = plt.get_cmap("viridis")
    seen: set[str] = set()
    slow_lim = 0.0
    for p, v in zip(pts, vc):
        for m in p.info.get("modes", []):
            if m["name"] == "heading":
                continue
            re, im = m["re"], m["im"]
            xs, ys = ([re, re], [im, -im]) if im else ([re], [0.0])
            seen.add(m["name"])
            for ax in axes:
                ax.scatter(xs, ys, marker=_MARKERS.get(m["name"], "."), color=cmap(norm(v)) if norm else "k",
                           s=28, edgecolors="none")
            if m["name"] in ("phugoid", "spiral", "altitude"):
                slow_lim = max(slow_lim, abs(re), abs(im))
    for ax in axes:
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xlabel("real part [1/s]")
        ax.set_ylabel("imaginary part [rad/s]")
        ax.grid(True, lw=0.3)
    lim = 1.3 * (slow_lim or 0.3)
    axes[1].set_xlim(-lim, 0.3 * lim)
    axes[1].set_ylim(-lim, lim)
    axes[0].set_title("all modes")
    axes[1].set_title("slow modes (phugoid, spiral, altitude)")
    handles = [Line2D([], [], marker=_MARKERS[n], color="0.3", ls="none", label=n) for n in _MARKERS if n in seen]
    axes[0].legend(handles=handles, loc="upper left", fontsize=8)
    if norm is not None:
        sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
        fig.colorbar(sm, ax=axes, label="calibrated airspeed [kt]", shrink=0.85)
    fig.suptitle(title or f"{schedule.aircraft}: poles across the envelope ({len(pts)} points)")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out

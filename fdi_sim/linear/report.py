"""Human-readable report of a model schedule (markdown; plain text reads the same).

Sections: summary (points, timing, worst validation point and output), a table of modes per
point (short period, phugoid, Dutch roll, roll, spiral with frequency and damping or time
constant), the validation table, the FGLinearization check, and every point without a model
with its reason. The pole-map figure is drawn by :mod:`fdi_sim.review.linear_figures`.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from fdi_sim.linear.schedule import ModelSchedule, SchedulePoint
from fdi_sim.linear.validate import NRMSE_BAR


def _fmt(x: Any, spec: str = ".3g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return format(x, spec)


def _speed(p: SchedulePoint) -> str:
    op = p.op
    return f"{op.vt_kts:g} KTAS" if op.vt_kts is not None else f"{op.vc_kts:g} KCAS"


def _mode_cell(modes: Sequence[dict[str, Any]], name: str) -> str:
    ms = [m for m in modes if m["name"] == name]
    if not ms:
        return "-"
    cells = []
    for m in ms:
        if m["im"]:
            cells.append(f"{m['wn_radps']:.3g} rad/s, ζ {m['zeta']:.2f}")
        else:
            cells.append(f"τ {m['tau_s']:.3g} s" if m["re"] < 0 else f"T2 {-m['tau_s'] * math.log(2):.3g} s (unstable)")
    return "; ".join(cells)


def worst_validation(schedule: ModelSchedule, method: str) -> tuple[str, str, float] | None:
    """(point label, output, error) of the largest per-output error over the schedule."""
    best: tuple[str, str, float] | None = None
    for p in schedule.ok_points:
        v = p.info.get("validation", {}).get(method)
        if v and (best is None or v["worst"] > best[2]):
            best = (p.op.label(), v["worst_output"], float(v["worst"]))
    return best


def format_report(schedule: ModelSchedule, figure: str | None = None) -> str:
    """The report as markdown text."""
    pts = schedule.points
    ok = [p for p in pts if p.status == "ok"]
    bad = [p for p in pts if p.status != "ok"]
    meta = schedule.meta
    methods = meta.get("validation", {}).get("methods", [])
    lines = [f"# Linear model schedule: {schedule.aircraft}", ""]
    lines += [
        f"- grid: {meta.get('grid_source', '?')}",
        f"- points: {len(pts)} ({len(ok)} trimmed and linearized, "
        f"{sum(p.status == 'untrimmable' for p in pts)} untrimmable, {sum(p.status == 'skipped' for p in pts)} skipped)",
        f"- states: {', '.join(schedule.names.get('state_names', ()))}",
        f"- inputs: {', '.join(schedule.names.get('input_names', ()))} "
        f"(disturbances: {', '.join(n for n, k in zip(schedule.names.get('input_names', ()), schedule.names.get('input_kinds', ())) if k == 'disturbance')})",
        f"- outputs: {', '.join(schedule.names.get('output_names', ()))}",
        f"- JSBSim {meta.get('jsbsim_version', '?')}, {meta.get('created_by', '')}, wall time {_fmt(meta.get('elapsed_s'), '.1f')} s",
    ]
    for meth in methods:
        w = worst_validation(schedule, meth)
        if w:
            n_pass = sum(bool(p.info.get("validation", {}).get(meth, {}).get("passed")) for p in ok)
            lines.append(f"- validation ({meth}): {n_pass}/{len(ok)} points below {NRMSE_BAR:.0%} on every output; "
                         f"worst {w[1]} {w[2]:.1%} at {w[0]}")
            wt = max(((p.info["validation"][meth]["worst_without_throttle"], p.info["validation"][meth]
                       ["worst_output_without_throttle"], p.op.label()) for p in ok if meth in p.info.get("validation", {})),
                     default=None)
            if wt:
                lines.append(f"  - leaving out the throttle doublet: worst {wt[1]} {wt[0]:.1%} at {wt[2]}")
    if figure:
        lines += ["", f"![pole map]({figure})"]
    lines += ["", "## Modes per point", "",
              "| point | alpha deg | throttle | short period | phugoid | dutch roll | roll | spiral |",
              "|---|---|---|---|---|---|---|---|"]
    for p in ok:
        m = p.info.get("modes", [])
        lines.append(
            f"| {p.op.h_ft:g} ft {_speed(p)}{f' flaps {p.op.flaps_deg:g}' if p.op.flaps_deg else ''} "
            f"| {math.degrees(p.trim['alpha_rad']):.2f} | {p.trim['throttle_cmd_norm']:.3f} "
            f"| {_mode_cell(m, 'short period')} | {_mode_cell(m, 'phugoid')} | {_mode_cell(m, 'dutch roll')} "
            f"| {_mode_cell(m, 'roll')} | {_mode_cell(m, 'spiral')} |")
    if ok:
        m0 = ok[0].info.get("modes", [])
        lines += ["", "Dominant states (first point): " + "; ".join(
            f"{m['name']}: {', '.join(m['dominant'])}" for m in m0), ""]
    if methods and ok:
        outs = schedule.names.get("output_names", ())
        lines += ["## Validation: normalized RMS error per output over all doublet runs", "",
                  f"Doublets: {meta['validation'].get('amplitudes')} (width {meta['validation'].get('width_s')} s, "
                  f"{meta['validation'].get('duration_s')} s per run). Error = sqrt(sum (y_lin - y_nl)^2) / "
                  "sqrt(sum y_nl^2), JSBSim responses relative to an unforced run.", ""]
        for meth in methods:
            lines += [f"### discretization: {meth}", "", "| point | worst output | worst | largest error from | "
                      "worst w/o throttle | " + " | ".join(outs) + " |", "|---" * (5 + len(outs)) + "|"]
            for p in ok:
                v = p.info.get("validation", {}).get(meth)
                if not v:
                    continue
                # the run that contributes most squared error to the worst output
                err = np.array(v["nrmse_pair"], dtype=float) * np.array(v["rms_nl"], dtype=float)
                jo = outs.index(v["worst_output"])
                run = v["input_names"][int(np.argmax(np.where(np.isfinite(err[:, jo]), err[:, jo], -1)))]
                lines.append(f"| {p.op.h_ft:g} ft {_speed(p)}{f' f{p.op.flaps_deg:g}' if p.op.flaps_deg else ''} "
                             f"| {v['worst_output']} | {v['worst']:.1%} | {run} | "
                             f"{v['worst_output_without_throttle']} {v['worst_without_throttle']:.1%} | " +
                             " | ".join(f"{x * 100:.1f}" for x in v["nrmse"]) + " |")
            lines.append("")
    fg = [p for p in ok if "fglin" in p.info]
    if fg:
        lines += ["## FGLinearization check (same 10 states, eigenvalues matched one to one)", "",
                  "| point | max relative difference | worst mode |", "|---|---|---|"]
        for p in fg:
            pm = p.info["fglin"]["per_mode"]
            wm = max(pm, key=pm.get) if pm else "-"
            lines.append(f"| {p.op.h_ft:g} ft {_speed(p)} | {p.info['fglin']['max_rel']:.2%} | {wm} ({pm.get(wm, 0):.2%}) |")
        lines.append("")
    lines += ["## Points without a model", ""]
    if not bad:
        lines.append("None: every point trimmed.")
    for p in bad:
        lines.append(f"- {p.op.label()}: **{p.status}**: {p.reason}")
    lines.append("")
    return "\n".join(lines)

"""Human-readable report of a model schedule (markdown; plain text reads the same).

Sections: summary (points, timing, worst validation point and output), a table of modes per
point (short period, phugoid, Dutch roll, roll, spiral with frequency and damping or time
constant), the validation table, the FGLinearization check, and every point without a model
with its reason. The pole-map figure is drawn by :mod:`fdi_sim.review.linear_figures`.

Validation entries are read from each point's ``info``: ``info["validation"][method]`` for the
linear model as it is, discretized by ``method`` (``"zoh"``: the detectors' default; ``"step"``:
the discrete model of JSBSim's own step, :mod:`fdi_sim.linear.step`), and, where the point has a
gas-generator state (DHC-6), ``info["validation_engine_lag"]``: the model (its ``method``) flown
with the asymmetric N1 lag identified from JSBSim in place of its N1 row
(:mod:`fdi_sim.linear.validate`). All are shown; the bar is judged on ``"step"`` where the
schedule has it (:func:`bar_method`): the model of what the simulation does at its step, which is
what the bar asks of a linearization. Every point that misses the bar is listed with what JSBSim
does there that no linear model holds: the slope jumps of its tables within the doublet's
excursion (``info["nonsmooth"]``) and the asymmetric engine lag.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from fdi_sim.linear.schedule import ModelSchedule, SchedulePoint
from fdi_sim.linear.validate import NRMSE_BAR

#: a slope jump (:func:`~fdi_sim.aircraft.linearize_response.slope_jumps`, ``info["nonsmooth"]``) at
#: least this large within a doublet's excursion is listed as a non-smoothness of JSBSim's model there [-]
NONSMOOTH_JUMP: float = 0.05


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


#: the ``info`` key of the validation with the identified N1 lag (see the module notes)
ENGINE_LAG_KEY: str = "validation_engine_lag"


def _entry(p: SchedulePoint, method: str) -> dict[str, Any] | None:
    """The validation entry of ``p`` for ``method`` (a discretization, or :data:`ENGINE_LAG_KEY`)."""
    if method == ENGINE_LAG_KEY:
        return p.info.get(ENGINE_LAG_KEY)
    return p.info.get("validation", {}).get(method)


def worst_validation(schedule: ModelSchedule, method: str) -> tuple[str, str, float] | None:
    """(point label, output, error) of the largest per-output error over the schedule.

    ``method`` is a discretization (``"zoh"``, ``"euler"``) or :data:`ENGINE_LAG_KEY`.
    """
    best: tuple[str, str, float] | None = None
    for p in schedule.ok_points:
        v = _entry(p, method)
        if v and (best is None or v["worst"] > best[2]):
            best = (p.op.label(), v["worst_output"], float(v["worst"]))
    return best


def _label(method: str, schedule: ModelSchedule | None = None) -> str:
    if method != ENGINE_LAG_KEY:
        return method
    base = "zoh"
    for p in schedule.ok_points if schedule is not None else ():
        if ENGINE_LAG_KEY in p.info:
            base = p.info[ENGINE_LAG_KEY].get("method", "zoh")
            break
    return f"{base} with the identified N1 lag"


def bar_method(schedule: ModelSchedule) -> str:
    """The discretization the bar is judged on: ``"step"`` where validated, else ``"zoh"``."""
    return "step" if any("step" in p.info.get("validation", {}) for p in schedule.ok_points) else "zoh"


def nonsmooth_causes(p: SchedulePoint, min_jump: float = NONSMOOTH_JUMP) -> list[str]:
    """What JSBSim does at ``p`` that no linear model holds: slope jumps and the engine lag."""
    out = []
    for name, d in sorted(p.info.get("nonsmooth", {}).items(), key=lambda kv: -kv[1]["jump"]):
        if d["jump"] >= min_jump:
            out.append(f"{name}: slopes differ by {d['jump']:.0%} across +-{d['excursion']:.3g}")
    lag = p.info.get("engine_lag")
    if lag:
        out.append(f"throttle_cmd_norm: N1 lag {lag['tau_up_s']:.2g} s up, {lag['tau_down_s']:.2g} s down "
                   "(FGTurboProp ExpSeek, non-smooth at the trim)")
    return out


def _summary_lines(schedule: ModelSchedule, method: str) -> list[str]:
    """Pass count and worst point/output of one validation, and the same leaving out the throttle."""
    ok = schedule.ok_points
    w = worst_validation(schedule, method)
    if not w:
        return []
    entries = [(p, _entry(p, method)) for p in ok]
    entries = [(p, v) for p, v in entries if v]
    n_pass = sum(bool(v.get("passed")) for _, v in entries)
    lines = [f"- validation ({_label(method, schedule)}): {n_pass}/{len(entries)} points below {NRMSE_BAR:.0%} on every "
             f"output; worst {w[1]} {w[2]:.1%} at {w[0]}"]
    wt = max(((v["worst_without_throttle"], v["worst_output_without_throttle"], p.op.label()) for p, v in entries),
             default=None)
    if wt:
        n_wt = sum(v["worst_without_throttle"] < NRMSE_BAR for _, v in entries)
        lines.append(f"  - leaving out the throttle doublet: {n_wt}/{len(entries)} points pass; worst {wt[1]} "
                     f"{wt[0]:.1%} at {wt[2]}")
    return lines


def _validation_table(schedule: ModelSchedule, method: str) -> list[str]:
    """One row per point: worst output, the run it comes from, and every output's error [%]."""
    outs = schedule.names.get("output_names", ())
    lines = [f"### {_label(method, schedule)}", "", "| point | worst output | worst | largest error from | "
             "worst w/o throttle | " + " | ".join(outs) + " |", "|---" * (5 + len(outs)) + "|"]
    for p in schedule.ok_points:
        v = _entry(p, method)
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
    return lines + [""]


def _bar_lines(schedule: ModelSchedule) -> list[str]:
    """The bar's method, and every point that misses it with the non-smoothness JSBSim has there."""
    meth = bar_method(schedule)
    entries = [(p, p.info.get("validation", {}).get(meth)) for p in schedule.ok_points]
    entries = [(p, v) for p, v in entries if v]
    miss = [(p, v) for p, v in entries if not v.get("passed")]
    lines = [f"- bar ({NRMSE_BAR:.0%} on every output) judged on '{meth}': {len(entries) - len(miss)}/{len(entries)} "
             "points pass" + ("; the others, with what JSBSim does there that no linear model holds:" if miss else "")]
    for p, v in miss:
        causes = nonsmooth_causes(p)
        lagv = p.info.get(ENGINE_LAG_KEY)
        with_lag = ""
        if lagv:
            with_lag = ("; with the identified N1 lag it passes" if lagv.get("passed") else
                        f"; with the identified N1 lag {lagv['worst_output']} {lagv['worst']:.1%}")
        lines.append(f"  - {p.op.label()}: {v['worst_output']} {v['worst']:.1%} (without the throttle run "
                     f"{v['worst_output_without_throttle']} {v['worst_without_throttle']:.1%}{with_lag}); "
                     + ("; ".join(causes) if causes else "no slope jump found within the doublets"))
    return lines


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
    lag = [ENGINE_LAG_KEY] if any(ENGINE_LAG_KEY in p.info for p in ok) else []
    for meth in (*methods, *lag):
        lines += _summary_lines(schedule, meth)
    if methods and ok:
        lines += _bar_lines(schedule)
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
        lines += ["## Validation: normalized RMS error per output over all doublet runs", "",
                  f"Doublets: {meta['validation'].get('amplitudes')} (width {meta['validation'].get('width_s')} s, "
                  f"{meta['validation'].get('duration_s')} s per run). Error = sqrt(sum (y_lin - y_nl)^2) / "
                  "sqrt(sum y_nl^2), JSBSim responses relative to an unforced run.", ""]
        if "step" in methods:
            lines += ["'zoh' is the continuous model discretized by zero-order hold (the detectors' default). "
                      "'step' is the discrete model of JSBSim's own step (fdi_sim.linear.step): third-order "
                      "Adams-Bashforth integration, the FCS and aero signals JSBSim reads one pass late, the "
                      "engines updated inside the pass, the accelerometers one step late; measured pass by "
                      "pass at each trim.", ""]
        if lag:
            lines += ["The gas generator of the DHC-6 follows the throttle with 1 s up and 2.4 s down "
                      "(FGTurboProp), which no linear model holds: a throttle doublet leaves N1 above the "
                      f"trim. '{_label(ENGINE_LAG_KEY, schedule)}' flies the model with that lag, identified from "
                      "JSBSim at each point, in place of its N1 row; the tables named by a discretization "
                      "score the linear model itself.", ""]
        for meth in (*methods, *lag):
            lines += _validation_table(schedule, meth)
    fg = [p for p in ok if "fglin" in p.info]
    if fg:
        lines += ["## FGLinearization check (same 10 states, eigenvalues matched one to one)", "",
                  "'sim' are the poles of the step model mapped back by ln(z)/dt: the modes of the 120 Hz "
                  "simulation itself, validated against it above. FGLinearization reads its derivatives "
                  "after JSBSim's Initialize and one Run (two passes, FGStateSpace::run), with the FCS and "
                  "the PID derivative terms still moving from the previous evaluation of its stencil.", "",
                  "| point | max relative difference | worst mode | roll: ours vs sim | roll: FGLin vs sim |",
                  "|---|---|---|---|---|"]
        for p in fg:
            pm = p.info["fglin"]["per_mode"]
            wm = max(pm, key=pm.get) if pm else "-"
            sim = p.info["fglin"].get("sim", {})
            roll = [k for k in sim.get("ours_vs_sim", {}) if k.startswith("roll")]
            cells = (f"{sim['ours_vs_sim'][roll[0]]:.2%} | {sim['fglin_vs_sim'][roll[0]]:.2%}" if roll else "- | -")
            lines.append(f"| {p.op.h_ft:g} ft {_speed(p)} | {p.info['fglin']['max_rel']:.2%} | {wm} ({pm.get(wm, 0):.2%}) "
                         f"| {cells} |")
        lines.append("")
    lines += ["## Points without a model", ""]
    if not bad:
        lines.append("None: every point trimmed.")
    for p in bad:
        lines.append(f"- {p.op.label()}: **{p.status}**: {p.reason}")
    lines.append("")
    return "\n".join(lines)

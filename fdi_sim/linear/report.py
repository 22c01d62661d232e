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
from fdi_sim.linear.validate import ENGINE_LAG_KEY, NONSMOOTH_JUMP, NRMSE_BAR


def _fmt(x: Any, spec: str = ".3g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return format(x, spec)


def _point_cell(p: SchedulePoint) -> str:
    """A table's point column: altitude, speed and, where set, flaps and icing (iced grids repeat the rest)."""
    op = p.op
    speed = f"{op.vt_kts:g} KTAS" if op.vt_kts is not None else f"{op.vc_kts:g} KCAS"
    return (f"{op.h_ft:g} ft {speed}" + (f" flaps {op.flaps_deg:g}" if op.flaps_deg else "")
            + (f" eta {op.icing_eta:g}" if op.icing_eta else ""))


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


#: the pseudo-method of the bar's own validation (:func:`bar_entry`)
BAR: str = "bar"


def bar_entry(p: SchedulePoint, method: str = "step") -> dict[str, Any] | None:
    """The validation entry the bar is judged on at ``p``.

    The ``method`` model (``"step"`` where validated, :func:`bar_method`), flown with the
    identified N1 lag where the engine has one (:data:`ENGINE_LAG_KEY`), on doublets kept inside
    the smooth range of JSBSim's tables (``info["linear_range"]``,
    :func:`fdi_sim.linear.linearize.linear_range_runs`; the configured doublets in schedules
    made before it existed).
    """
    src = p.info.get("linear_range") or p.info
    lag = src.get(ENGINE_LAG_KEY)
    if lag is not None and lag.get("method", method) == method:
        return lag
    return src.get("validation", {}).get(method)


def _entry(p: SchedulePoint, method: str, schedule: ModelSchedule | None = None) -> dict[str, Any] | None:
    """The validation entry of ``p`` for ``method`` (a discretization, :data:`ENGINE_LAG_KEY` or :data:`BAR`)."""
    if method == BAR:
        return bar_entry(p, bar_method(schedule) if schedule is not None else "step")
    if method == ENGINE_LAG_KEY:
        return p.info.get(ENGINE_LAG_KEY)
    return p.info.get("validation", {}).get(method)


def worst_validation(schedule: ModelSchedule, method: str) -> tuple[str, str, float] | None:
    """(point label, output, error) of the largest per-output error over the schedule.

    ``method`` is a discretization (``"zoh"``, ``"euler"``, ``"step"``), :data:`ENGINE_LAG_KEY` or :data:`BAR`.
    """
    best: tuple[str, str, float] | None = None
    for p in schedule.ok_points:
        v = _entry(p, method, schedule)
        if v and (best is None or v["worst"] > best[2]):
            best = (p.op.label(), v["worst_output"], float(v["worst"]))
    return best


def method_label(method: str, schedule: ModelSchedule | None = None) -> str:
    """How the report names a validation: a discretization, the engine-lag one or :data:`BAR`."""
    if method == BAR:
        meth = bar_method(schedule) if schedule is not None else "step"
        lag = schedule is not None and any(ENGINE_LAG_KEY in p.info for p in schedule.ok_points)
        return (f"{meth}" + (" with the identified N1 lag" if lag else "") +
                ", doublets inside the smooth range of JSBSim's tables")
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


def nonsmooth_causes(p: SchedulePoint, min_jump: float = NONSMOOTH_JUMP,
                     key: tuple[str, ...] = ("nonsmooth",)) -> list[str]:
    """What JSBSim does at ``p`` that no linear model holds: slope jumps and the engine lag.

    ``key`` is the path of the slope jumps in ``p.info`` (``("linear_range", "nonsmooth")`` for
    those of the doublets kept in the smooth range).
    """
    out = []
    jumps: Any = p.info
    for k in key:
        jumps = jumps.get(k, {}) if isinstance(jumps, dict) else {}
    for name, d in sorted(jumps.items(), key=lambda kv: -kv[1]["jump"]):
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
    entries = [(p, _entry(p, method, schedule)) for p in ok]
    entries = [(p, v) for p, v in entries if v]
    n_pass = sum(bool(v.get("passed")) for _, v in entries)
    lines = [f"- validation ({method_label(method, schedule)}): {n_pass}/{len(entries)} points below {NRMSE_BAR:.0%} on every "
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
    lines = [f"### {'bar: ' if method == BAR else ''}{method_label(method, schedule)}", "", "| point | worst output | worst | largest error from | "
             "worst w/o throttle | " + " | ".join(outs) + " |", "|---" * (5 + len(outs)) + "|"]
    for p in schedule.ok_points:
        v = _entry(p, method, schedule)
        if not v:
            continue
        # the run that contributes most squared error to the worst output
        err = np.array(v["nrmse_pair"], dtype=float) * np.array(v["rms_nl"], dtype=float)
        jo = outs.index(v["worst_output"])
        run = v["input_names"][int(np.argmax(np.where(np.isfinite(err[:, jo]), err[:, jo], -1)))]
        lines.append(f"| {_point_cell(p)} | {v['worst_output']} | {v['worst']:.1%} | {run} | "
                     f"{v['worst_output_without_throttle']} {v['worst_without_throttle']:.1%} | " +
                     " | ".join(f"{x * 100:.1f}" for x in v["nrmse"]) + " |")
    return lines + [""]


def reduced_doublets(p: SchedulePoint) -> list[str]:
    """The doublets flown smaller at ``p`` to stay inside the smooth range, with the kink that made it so."""
    out = []
    lr = p.info.get("linear_range") or {}
    for name, r in lr.get("reduced", {}).items():
        out.append(f"{name} x{r['factor']:.2g} ({r['by']}: slopes differ by {r['jump']:.0%} across the configured "
                   f"doublets' excursion, by less than {NONSMOOTH_JUMP:.0%} within +-{r['radius']:.2g})")
    for name, j in lr.get("no_smooth_range", {}).items():
        out.append(f"{name}: kink at the trim itself (slopes differ by {j:.0%} however small the excursion)")
    return out


def _bar_lines(schedule: ModelSchedule) -> list[str]:
    """The bar, the doublets made smaller and why, and every point that misses it with its causes."""
    meth = bar_method(schedule)
    entries = [(p, bar_entry(p, meth)) for p in schedule.ok_points]
    entries = [(p, v) for p, v in entries if v]
    if not entries:
        return []
    miss = [(p, v) for p, v in entries if not v.get("passed")]
    w = max(entries, key=lambda e: e[1]["worst"])
    lines = [f"- **bar** ({NRMSE_BAR:.0%} on every output; {method_label(BAR, schedule)}): "
             f"**{len(entries) - len(miss)}/{len(entries)} points pass**; worst {w[1]['worst_output']} "
             f"{w[1]['worst']:.1%} at {w[0].op.label()}"]
    red = [(p, reduced_doublets(p)) for p, _ in entries]
    red = [(p, r) for p, r in red if r]
    if red:
        lines.append(f"  - doublets made smaller at {len(red)}/{len(entries)} points (elsewhere as configured):")
        lines += [f"    - {p.op.label()}: " + "; ".join(r) for p, r in red]
    for p, v in miss:
        causes = nonsmooth_causes(p, key=("linear_range", "nonsmooth"))
        lines.append(f"  - misses: {p.op.label()}: {v['worst_output']} {v['worst']:.1%}; "
                     + ("; ".join(causes) if causes else "no slope jump found within the doublets"))
    return lines + _configured_lines(schedule)


def _configured_lines(schedule: ModelSchedule) -> list[str]:
    """The linear model as it is at the configured amplitudes, and what JSBSim does where it misses."""
    meth = bar_method(schedule)
    entries = [(p, p.info.get("validation", {}).get(meth)) for p in schedule.ok_points]
    entries = [(p, v) for p, v in entries if v]
    miss = [(p, v) for p, v in entries if not v.get("passed")]
    lines = [f"- '{meth}' as it is, configured doublets: {len(entries) - len(miss)}/{len(entries)} "
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
            f"| {_point_cell(p)} | {math.degrees(p.trim['alpha_rad']):.2f} | {p.trim['throttle_cmd_norm']:.3f} "
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
                      f"trim. '{method_label(ENGINE_LAG_KEY, schedule)}' flies the model with that lag, identified from "
                      "JSBSim at each point, in place of its N1 row; the tables named by a discretization "
                      "score the linear model itself.", ""]
        bar = [BAR] if any("linear_range" in p.info for p in ok) else []
        if bar:
            lines += [f"'bar: {method_label(BAR, schedule)}' is the table the bar is judged on: each doublet that carries "
                      "JSBSim across a kink of its tables (a slope jump of at least "
                      f"{NONSMOOTH_JUMP:.0%} within its excursion, of its own input or of alpha, beta, p, q, r "
                      "or N1) is flown again with its amplitude scaled to the excursion, found by halving, "
                      "without one (fdi_sim.linear.linearize.linear_range_runs). The other tables keep the "
                      "configured doublets.", ""]
        for meth in (*bar, *methods, *lag):
            lines += _validation_table(schedule, meth)
    fg = [p for p in ok if "fglin" in p.info]
    if fg:
        lines += ["## FGLinearization check (same 10 states, eigenvalues matched one to one)", "",
                  "'sim' are the poles of the step model mapped back by ln(z)/dt: the modes of the 120 Hz "
                  "simulation itself, validated against it above. FGLinearization reads its derivatives "
                  "after JSBSim's Initialize and one Run (two passes, FGStateSpace::run), with the FBW still "
                  "moving from the previous evaluation of its stencil (F-16 roll root: beta-dot without the "
                  "yaw damper's rudder, the yaw-load PID's derivative term). 'FGLin procedure settled' is "
                  "FGLinearization's own procedure (4th-order stencil, h = 1e-4) replayed with five passes per "
                  "evaluation (fdi_sim.aircraft.fglin_replica; with one it equals FGLinearization bit for bit, "
                  "tests/linear/test_fglin_roll_root.py): its largest relative eigenvalue difference to ours.", "",
                  "| point | max relative difference | worst mode | FGLin procedure settled: max difference "
                  "| roll: ours vs sim | roll: FGLin vs sim |",
                  "|---|---|---|---|---|---|"]
        for p in fg:
            pm = p.info["fglin"]["per_mode"]
            wm = max(pm, key=pm.get) if pm else "-"
            sim = p.info["fglin"].get("sim", {})
            roll = [k for k in sim.get("ours_vs_sim", {}) if k.startswith("roll")]
            cells = (f"{sim['ours_vs_sim'][roll[0]]:.2%} | {sim['fglin_vs_sim'][roll[0]]:.2%}" if roll else "- | -")
            settled = p.info["fglin"].get("settled")
            sc = f"{settled['max_rel']:.1e}" if settled else "-"
            lines.append(f"| {_point_cell(p)} | {p.info['fglin']['max_rel']:.2%} | {wm} ({pm.get(wm, 0):.2%}) "
                         f"| {sc} | {cells} |")
        lines.append("")
    lines += ["## Points without a model", ""]
    if not bad:
        lines.append("None: every point trimmed.")
    for p in bad:
        lines.append(f"- {p.op.label()}: **{p.status}**: {p.reason}")
    lines.append("")
    return "\n".join(lines)

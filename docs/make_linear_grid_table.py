"""The default grids' linearization and validation summary, as the generated block ``default-grids``
of docs/linear.md, and the F-16 grid's FGLinearization comparison as the block ``fglin-grid``.

Runs what ``fdi-sim linearize f16``, ``fdi-sim linearize DHC6`` and ``fdi-sim linearize DHC6
--grid iced`` run (``linearize_grid(resolve_grid(spec, aircraft))`` with the doublet validation
and, on the F-16, the FGLinearization cross-check; real JSBSim, no random draw) and tabulates per
grid: the points trimmed (and why the others are not), the bar (the step model with the
identified N1 lag, doublets inside the smooth range of JSBSim's tables), the doublets made
smaller and the kinks that made them so, and the configured doublets with the step model and with
ZOH. The summaries are the ones ``fdi-sim linearize`` prints and ``tests/linear/test_default_grids.py``
asserts. ``fglin-grid``, from the same F-16 schedule (``info["fglin"]`` of every point): the
largest eigenvalue difference of FGLinearization's procedure replayed with its passes settled,
stock FGLinearization's worst mode against ours (the roll root and the rest), and the relative
distance of our and of FGLinearization's roll root to the simulation's own (the step model's
poles mapped back by ln(z)/dt). 77 points: about 1.5 min niced on a busy 2-core machine.

    python docs/make_linear_grid_table.py
"""
from __future__ import annotations

import re
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.linear.grid import resolve_grid  # noqa: E402
from fdi_sim.linear.linearize import linearize_grid  # noqa: E402
from fdi_sim.linear.report import bar_entry, bar_method  # noqa: E402
from fdi_sim.linear.validate import NRMSE_BAR  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402

MD = ROOT / "docs" / "linear.md"
BLOCK = "default-grids"
COMMAND = "python docs/make_linear_grid_table.py"
INPUTS = ("aircraft", "fdi_sim/_aircraft", "fdi_sim/aircraft", "fdi_sim/linear", "fdi_sim/operating_point.py",
          "fdi_sim/isa.py", "fdi_sim/units.py", "fdi_sim/errors.py", "fdi_sim/data.py", "fdi_sim/threads.py",
          "docs/make_linear_grid_table.py")
FGLIN_BLOCK = "fglin-grid"
#: the F-16 grid only: its grid file, the aircraft layer and the linearizer
FGLIN_INPUTS = ("aircraft/f16/grid.toml", "fdi_sim/aircraft", "fdi_sim/linear", "fdi_sim/operating_point.py",
                "fdi_sim/isa.py", "fdi_sim/units.py", "fdi_sim/errors.py", "fdi_sim/threads.py",
                "docs/make_linear_grid_table.py")
#: (row label, aircraft, --grid spec as given to fdi-sim linearize)
GRIDS = (("F-16", "f16", None), ("DHC-6", "DHC6", None), ("DHC-6 iced", "DHC6", "iced"))


def _where(p) -> str:
    """A point as the table names it: altitude, speed, flaps and icing where set."""
    op = p.op
    speed = f"{op.vt_kts:g} KTAS" if op.vt_kts is not None else f"{op.vc_kts:g} KCAS"
    return (f"{op.h_ft:g} ft / {speed}" + (f" flaps {op.flaps_deg:g}" if op.flaps_deg else "")
            + (f" eta {op.icing_eta:g}" if op.icing_eta else ""))


def _speed(op) -> float:
    return op.vt_kts if op.vt_kts is not None else op.vc_kts


def _axes(points) -> str:
    """The grid's shape: how many altitudes and speeds (per flaps and icing setting: the speeds
    can differ between flap settings), and the flaps and icing values where they vary."""
    ops = [p.op for p in points]
    unit = "KTAS" if ops[0].vt_kts is not None else "KCAS"
    n_alt = len({o.h_ft for o in ops})
    extra, n_sets = [], 1
    for name, key in (("flaps", "flaps_deg"), ("eta", "icing_eta")):
        vals = sorted({getattr(o, key) or 0.0 for o in ops})
        n_sets *= len(vals)
        if len(vals) > 1:
            extra.append(f"{name} " + "/".join(f"{v:g}" for v in vals))
    n_speed = len(ops) // (n_alt * n_sets) if len(ops) % (n_alt * n_sets) == 0 else len({_speed(o) for o in ops})
    return " x ".join([f"{n_alt} alt", f"{n_speed} {unit}"] + extra)


def _why(reason: str) -> str:
    """The trim failure's reason in a few words: the residual it stopped at and the command at its
    limit, or that none was (the full text is in ``fdi-sim linearize``'s report)."""
    res = re.search(r"stopped at residual ([\d.e+-]+)", reason)
    lim = re.search(r"(\w+) = ([\d.]+) at its limit", reason)
    out = [f"residual {res.group(1)}"] if res else []
    if lim:
        out.append(f"{lim.group(1)} = {lim.group(2)} at its limit")
    elif "no command at its limit" in reason:
        thr = re.search(r"throttle_cmd_norm ([\d.]+)", reason)
        out.append("no command at its limit" + (f" (throttle_cmd_norm {thr.group(1)})" if thr else ""))
    return ", ".join(out) or reason[:100]


def _row(label: str, schedule, seconds: float) -> str:
    pts, ok = schedule.points, schedule.ok_points
    bad = [p for p in pts if p.status != "ok"]
    trim = f"{len(ok)}/{len(pts)} trim" + (("; not trimmed: " + "; ".join(f"{_where(p)} ({_why(p.reason)})" for p in bad))
                                           if bad else "")
    meth = bar_method(schedule)
    bars = [(p, bar_entry(p, meth)) for p in ok]
    n_bar = sum(bool(v and v.get("passed")) for _, v in bars)
    wp, wv = max(bars, key=lambda pv: pv[1]["worst"])
    bar = f"**{n_bar}/{len(ok)}**, worst `{wv['worst_output']}` {100 * wv['worst']:.1f} % ({_where(wp)})"
    reduced: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    n_red = 0
    for p in ok:
        red = (p.info.get("linear_range") or {}).get("reduced", {})
        n_red += bool(red)
        for name, r in red.items():
            reduced[(name, r["by"])].append((float(r["factor"]), _speed(p.op)))
    unit = "KTAS" if ok[0].op.vt_kts is not None else "KCAS"

    def group(name: str, by: str, fs: list[tuple[float, float]]) -> str:
        f = [x for x, _ in fs]
        speeds = "/".join(f"{v:g}" for v in sorted({v for _, v in fs}))
        return (f"{name} x{min(f):.2g}" + (f"-{max(f):.2g}" if max(f) > min(f) else "")
                + f" at {len(fs)} ({speeds} {unit}; kink in {by})")

    if n_red:
        made = f"{n_red} points: " + "; ".join(group(name, by, fs) for (name, by), fs in sorted(reduced.items()))
    else:
        made = "none"
    conf = [p.info["validation"][meth] for p in ok]
    n_conf = sum(bool(v["passed"]) for v in conf)
    cell = f"{n_conf}/{len(ok)}"
    if n_conf < len(ok) and all("worst_without_throttle" in v for v in conf):
        n_wt = sum(v["worst_without_throttle"] < NRMSE_BAR for v in conf)
        cell += f"; {n_wt}/{len(ok)} without the throttle run"
    zoh = [p.info["validation"]["zoh"] for p in ok]
    n_zoh = sum(bool(v["passed"]) for v in zoh)
    wz = max(zoh, key=lambda v: v["worst"])
    zcell = f"{n_zoh}/{len(ok)}" + (f", worst `{wz['worst_output']}` {100 * wz['worst']:.1f} %" if n_zoh < len(ok) else "")
    return f"| {label} ({_axes(pts)}) | {trim} | {bar} | {made} | {cell} | {zcell} |"


def fglin_render(schedule) -> str:
    """The F-16 grid against FGLinearization: settled replay, stock worst modes, roll root vs the simulation."""
    ok = schedule.ok_points
    fg = {_where(p): p.info["fglin"] for p in ok}

    def is_roll(k: str) -> bool:
        return k.startswith("roll")

    def worst(pred) -> tuple[float, str, str]:
        # (relative difference, mode, point) of the worst mode matching pred; zero roots have none
        return max((v, k.rsplit(" ", 1)[0], w) for w, f in fg.items() for k, v in f["per_mode"].items()
                   if pred(k) and abs(float(k.split()[-1])) > 1e-3)

    settled = max(f["settled"]["max_rel"] for f in fg.values())
    r_fg, _, r_at = worst(is_roll)
    o_fg, o_mode, o_at = worst(lambda k: not is_roll(k))
    roll = {w: next(k for k in f["per_mode"] if is_roll(k)) for w, f in fg.items()}
    ours = [f["sim"]["ours_vs_sim"][roll[w]] for w, f in fg.items()]
    theirs = [f["sim"]["fglin_vs_sim"][roll[w]] for w, f in fg.items()]
    lines = ["| F-16 default grid, " + f"{len(ok)} points | relative eigenvalue difference |", "|---|---|",
             f"| FGLinearization's procedure, passes settled, against ours (worst mode) | {settled:.1e} |",
             f"| stock FGLinearization against ours, roll root (worst point) | {r_fg:.1%} ({r_at}) |",
             f"| stock FGLinearization against ours, every other mode (worst) | {o_fg:.1%} ({o_mode}, {o_at}) |",
             f"| ours against the simulation's roll pole (step model, ln(z)/dt) | {min(ours):.1%} - {max(ours):.1%} |",
             f"| stock FGLinearization against the simulation's roll pole | {min(theirs):.1%} - {max(theirs):.1%} |"]
    return "\n".join(lines).replace("%", " %")


def render() -> tuple[str, str]:
    """The ``default-grids`` and ``fglin-grid`` bodies, from one linearization of each grid."""
    rows, times = [], []
    fglin = ""
    for label, aircraft, spec in GRIDS:
        grid = resolve_grid(spec, aircraft)
        t0 = time.perf_counter()
        schedule = linearize_grid(grid, validate=True, check_fglin=None)
        times.append((label, time.perf_counter() - t0, len(grid.points)))
        rows.append(_row(label, schedule, times[-1][1]))
        if aircraft == "f16":
            fglin = fglin_render(schedule)
    lines = ["| grid | points | bar: step model (+ N1 lag), smooth-range doublets | doublets made smaller | "
             "configured doublets | ZOH, configured |", "|---|---|---|---|---|---|"] + rows
    lines += ["", f"Bar: every output's normalized rms error below {100 * NRMSE_BAR:g} %; configured doublets: the "
              "step model as it is (no N1 lag), all doublets at their configured size. Linearized and validated in "
              + ", ".join(f"{t:.0f} s ({label}, {n} points)" for label, t, n in times)
              + " (niced, on a 2-core machine shared with other jobs)."]
    return "\n".join(lines), fglin


def main() -> int:
    t0 = time.perf_counter()
    stamps = make_stamp(BLOCK, COMMAND, INPUTS), make_stamp(FGLIN_BLOCK, COMMAND, FGLIN_INPUTS)
    bodies = render()
    text = MD.read_text()
    for stamp, body in zip(stamps, bodies):
        text = replace_block(text, stamp, body)
        print(body)
    MD.write_text(text)
    print(f"wrote the {BLOCK} and {FGLIN_BLOCK} blocks of {MD} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

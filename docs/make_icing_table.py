"""DHC-6 trims and modes with icing (the ``all`` region), as the generated block ``iced-trims`` of
docs/icing.md.

Real JSBSim on the iced overlay (``Aircraft("DHC6", icing=True)``): the grids
``h_ft=5000;vc_kts=100;icing_eta=0,0.05,0.1,0.15,0.2`` and ``h_ft=5000;vc_kts=120;icing_eta=0,0.05,0.1``
linearized with ``linearize_grid(..., validate=False)`` (level, running-engine trim, beta
-0.3 deg): per point the trimmed throttle, alpha and pitch trim, the natural frequencies of the
short period and the Dutch roll and the roll root from the named modes; the elevator [deg] is the
surface position (``fcs/elevator-pos-rad``) after :func:`fdi_sim.aircraft.trim` of the same
point on a fresh aircraft (its throttle checked against the grid's). An untrimmable point gives
the trim's reason. No randomness. Runs in a few seconds.

    python docs/make_icing_table.py
"""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.aircraft import Aircraft, trim  # noqa: E402
from fdi_sim.linear.grid import parse_grid_spec  # noqa: E402
from fdi_sim.linear.linearize import linearize_grid  # noqa: E402
from fdi_sim.operating_point import OperatingPoint  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "icing.md"
BLOCK = "iced-trims"
GRIDS = ("h_ft=5000;vc_kts=100;icing_eta=0,0.05,0.1,0.15,0.2", "h_ft=5000;vc_kts=120;icing_eta=0,0.05,0.1")
INPUTS = ("aircraft/DHC6", "fdi_sim/aircraft", "fdi_sim/linear", "fdi_sim/operating_point.py", "fdi_sim/isa.py",
          "docs/make_icing_table.py")


def _mode(point, name: str) -> dict:
    return next(m for m in point.info["modes"] if m["name"] == name)


def _why(reason: str) -> str:
    """The trim's reason, short: residual and best point."""
    res = re.search(r"residual ([0-9.eE+-]+)", reason)
    if "at its limit" in reason and "no command at its limit" not in reason:
        lim = re.search(r"best point: (.*?) \(", reason)
        return f'"{lim.group(1) if lim else reason}" (not enough thrust)'
    best = re.search(r"alpha ([0-9.-]+) deg, throttle_cmd_norm ([0-9.]+)", reason)
    if res and best:
        return (f"the running-engine trim stops at residual {float(res.group(1)):.2f} with throttle "
                f"{float(best.group(2)):.2f}, alpha {float(best.group(1)):.1f} deg, no command at its limit")
    return reason


def render() -> str:
    lines = ["| DHC-6 | throttle | alpha [deg] | pitch trim | elevator [deg] | short period wn | dutch roll wn | roll [1/s] |",
             "|---|---|---|---|---|---|---|---|"]
    for spec in GRIDS:
        for p in linearize_grid(parse_grid_spec(spec, "DHC6"), validate=False).points:
            where = f"{p.op.vc_kts:g} KIAS, eta {p.op.icing_eta:g}"
            if p.status != "ok":
                lines.append(f"| {where} | untrimmable: {_why(p.reason)} | | | | | | |")
                continue
            t = p.trim
            ac = Aircraft("DHC6", icing=True)
            r = trim(ac, OperatingPoint("DHC6", p.op.h_ft, vc_kts=p.op.vc_kts, icing_eta=p.op.icing_eta))
            if abs(r.throttle_cmd_norm - t["throttle_cmd_norm"]) > 1e-6:
                raise RuntimeError(f"{where}: trim() and the grid disagree: {r.throttle_cmd_norm} against {t}")
            elev = math.degrees(ac["fcs/elevator-pos-rad"])
            lines.append(f"| {where} | {t['throttle_cmd_norm']:.3f} | {math.degrees(t['alpha_rad']):.2f} | "
                         f"{t['pitch_trim_cmd_norm']:.3f} | {elev:.2f} | {_mode(p, 'short period')['wn_radps']:.2f} | "
                         f"{_mode(p, 'dutch roll')['wn_radps']:.2f} | {_mode(p, 'roll')['re']:.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_icing_table.py", [(BLOCK, INPUTS, render)], sys.argv[1:]))

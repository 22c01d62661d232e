"""The calibration atlases and the take-off time of a new scenario, as the generated block
``atlas`` of docs/bank.md.

For each aircraft: the atlas's nodes (how many calibrated, which failed and why), the gust
filter's trained threshold range over them; then the time from starting ``fdi-sim run`` to the
end of a 0.5 s flight of each hold-out scenario of ``tests/data/holdout`` (written for issue 24,
not shipped) in a fresh process with an empty calibration cache, after one unmeasured warm-up
run: the time to take-off with the default bank, its design and thresholds from the atlas (an
upper bound: it includes the interpreter's start, the imports and the 0.5 s flight).

    python docs/make_atlas_table.py
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.bank.members import DEFAULT_BANKS, default_member_far_per_h  # noqa: E402
from fdi_sim.scenario.schema import FdiSection  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training.atlas import read_atlas  # noqa: E402

AIRCRAFT = ("f16", "DHC6")
HOLDOUT = sorted((ROOT / "tests" / "data" / "holdout").glob("*.toml"))
INPUTS = tuple(f"aircraft/{ac}/fdi_atlas.json" for ac in AIRCRAFT) + (
    "tests/data/holdout", "fdi_sim/training/atlas.py", "fdi_sim/training/schedule.py",
    "fdi_sim/bank/members.py", "fdi_sim/scenario/schema.py", "docs/make_atlas_table.py")  # the members: the split
MD = ROOT / "docs" / "bank.md"
REPEATS = 3


def _takeoff(path: Path, cache: Path) -> tuple[float, dict]:
    """Wall time [s] of ``fdi-sim run`` on a 0.5 s copy of the scenario, and the log's calibration."""
    with tempfile.TemporaryDirectory() as tmp:
        lines, skip = [], False
        for ln in path.read_text().splitlines():  # 0.5 s of flight, its faults (later) left out
            if ln.startswith("["):
                skip = ln.strip() == "[[faults]]"
            if not skip:
                lines.append("duration_s = 0.5" if ln.startswith("duration_s") else ln)
        sc = Path(tmp) / path.name
        sc.write_text("\n".join(lines) + "\n")
        log = Path(tmp) / "run.mcap"
        env = {**os.environ, "FDI_SIM_CACHE": str(cache)}
        env.pop("FDI_SIM_ATLAS", None)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(sc), "--log", str(log)], check=True,
                       env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        from fdi_sim.flightlog import read_log

        cal = json.loads(read_log(log).metadata["fdi"]["calibration"])
        return wall, cal


def render() -> str:
    lines = ["| aircraft | envelope | turbulence | training flights | nodes calibrated | not calibrated | "
             "gust filter's trained threshold over the nodes (min - max) | airspeed check's |",
             "|---|---|---|---|---|---|---|---|"]
    for ac in AIRCRAFT:
        a = read_atlas(ROOT / "aircraft" / ac / "fdi_atlas.json", ac)
        raw = json.loads((ROOT / "aircraft" / ac / "fdi_atlas.json").read_text())
        env = ", ".join(f"{k} {v[0]:g}-{v[1]:g}" for k, v in a.envelope.items())
        combos = sorted({(n["maneuvers"], n["turbulence"]) for n in raw["nodes"]},
                        key=lambda c: (raw["maneuvers"].index(c[0]), raw["levels"].index(c[1])))
        for mv, lv in combos:
            if True:
                nodes = [n for n in raw["nodes"] if n["turbulence"] == lv and n["maneuvers"] == mv]
                ok = [n for n in nodes if n["status"] == "ok"]
                bad = [f"{n['h_ft']:g} ft / {n['vc_kts']:g} kt ({n['status'][:60]})" for n in nodes
                       if n["status"] != "ok"]

                def rng(mid: str) -> str:
                    v = [n["thresholds"][mid] for n in ok if mid in n["thresholds"]]
                    return f"{min(v):.4g} - {max(v):.4g}" if v else "-"

                what = f"`{a.reference}`'s pulse trains" if mv == "doublets" else "steady"
                lines.append(f"| {ac} | {env} | {lv} | {what} | {len(ok)} of {len(nodes)} | {'; '.join(bad) or 'none'} "
                             f"| {rng('kalman-gust-v1')} | {rng('kinematic-airspeed-v1')} |")
    lines.append("")
    far_per_h = FdiSection.model_fields["far_per_h"].default
    member = default_member_far_per_h()
    split = "; ".join(f"{ac}: {len(DEFAULT_BANKS[ac])}, {member[ac]:.3g} per h each" for ac in AIRCRAFT)
    lines.append("Per node: " + read_atlas(ROOT / "aircraft" / AIRCRAFT[0] / "fdi_atlas.json").training
                 + f", no wind, sensor-noise scale 1; thresholds at the bank's {far_per_h:g} false alarms per flight hour "
                 f"split evenly over its members ({split}).")
    lines += ["", "| new scenario (tests/data/holdout, its faults left out) | calibration in its log | node | start to the "
              "end of a 0.5 s flight, fresh process, empty cache [s] |", "|---|---|---|---|"]
    for path in HOLDOUT:
        with tempfile.TemporaryDirectory() as cache:
            _takeoff(path, Path(cache) / "warm-up")  # warms the OS's file cache and the imports' bytecode
            walls, cal = [], {}
            for i in range(REPEATS):
                w, cal = _takeoff(path, Path(cache) / f"c{i}")
                walls.append(w)
        node = cal.get("atlas", {}).get("node", {})
        where = f"{node.get('h_ft', float('nan')):g} ft / {node.get('vc_kts', float('nan')):g} kt" if node else "-"
        lines.append(f"| `{path.stem}` | {cal.get('source')} | {where} | {min(walls):.2f} (median "
                     f"{sorted(walls)[len(walls) // 2]:.2f} of {REPEATS}) |")
    return "\n".join(lines)


def main() -> int:
    stamp = make_stamp("atlas", "python docs/make_atlas_table.py", INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, render()))
    print(f"wrote the atlas block of {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

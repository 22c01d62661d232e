"""Actuator fault responses on the elevator and rudder of both aircraft through a doublet, as the
generated block ``actuator-faults`` of docs/faults.md.

The cases of ``tests/faults/test_actuator_faults.py`` flown the same way with real JSBSim: from
the trim of ``tests/faults/conftest.py`` (F-16 10 000 ft / 400 kt, DHC-6 5000 ft / 120 kt),
autopilot off, seed 1, 8 s, the fault from 2 s and a 0.1 doublet of 1 s pulses from 3 s; each
case flown with and without the doublet. The doublet response is the body rate (q for the
elevator, r for the rudder) with the doublet minus without it; a row gives its peak over
3-6 s, or that peak over the healthy aircraft's, and for the hard-over the fastest travel of
the surface after the onset (``/truth/surfaces``) and the time to its stop. Runs in about
10 s.

    python docs/make_faults_table.py
"""
from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.flightlog import read_log  # noqa: E402
from fdi_sim.scenario import from_dict  # noqa: E402
from fdi_sim.sim import run  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "faults.md"
BLOCK = "actuator-faults"
INPUTS = ("aircraft/f16", "aircraft/DHC6", "fdi_sim/aircraft", "fdi_sim/faults", "fdi_sim/sim", "fdi_sim/pilot",
          "fdi_sim/sensors", "fdi_sim/scenario", "fdi_sim/flightlog", "docs/make_faults_table.py")

POINTS = {"f16": {"h_ft": 10000.0, "vt_kts": 400.0}, "DHC6": {"h_ft": 5000.0, "vc_kts": 120.0}}
NAMES = {"f16": "F-16", "DHC6": "DHC-6"}
T_ON_S, T_DOUBLET_S, DT_S = 2.0, 3.0, 1.0 / 120.0
RATE = {"elevator": "q_radps", "rudder": "r_radps"}
LAWS = {
    "stuck": {"type": "actuator-stuck-v1"},
    "loss": {"type": "actuator-loss-v1", "effectiveness": 0.5},
    "hard-over": {"type": "actuator-hard-over-v1", "direction": "max"},
    "bias": {"type": "actuator-bias-v1", "bias_deg": 1.0},
}
COLUMNS = [(ac, s) for ac in ("f16", "DHC6") for s in ("elevator", "rudder")]


def _fly(tmp: Path, aircraft: str, faults: list[dict], maneuvers: list[dict]) -> dict:
    sc = from_dict({"name": "t", "aircraft": aircraft, "duration_s": 8.0, "seed": 1, "initial": POINTS[aircraft],
                    "autopilot": {"altitude": False, "airspeed": False, "lateral": False},
                    "maneuvers": maneuvers, "faults": faults})
    res = run(sc, log_path=tmp / f"t_{len(list(tmp.glob('*.mcap')))}.mcap", progress=False)
    if res.status not in ("completed", "diverged"):
        raise RuntimeError(f"{aircraft} {faults}: {res.status} {res.summary.reason}")
    return dict(read_log(res.log_path).topics)


def _pair(tmp: Path, aircraft: str, surface: str, law: str | None) -> tuple[dict, dict]:
    faults = [] if law is None else [dict(LAWS[law], target=surface, t_start_s=T_ON_S)]
    d = {"type": "doublet-v1", "axis": surface, "t_start_s": T_DOUBLET_S, "amplitude_norm": 0.1, "pulse_s": 1.0}
    return _fly(tmp, aircraft, faults, [d]), _fly(tmp, aircraft, faults, [])


def _peak(pair: tuple[dict, dict], rate: str) -> float:
    a, b = pair[0]["/truth/state"][rate], pair[1]["/truth/state"][rate]
    n = min(len(a), len(b))
    t = np.arange(n) * DT_S
    w = (t >= T_DOUBLET_S) & (t < T_DOUBLET_S + 3.0)
    if not w.any():
        raise RuntimeError("the run ended before the doublet")
    return float(np.abs(a[:n] - b[:n])[w].max())


def _hard_over(run_: dict, surface: str) -> tuple[float, float]:
    """Fastest travel after the onset [deg/s] and the time from the onset to the stop [s]."""
    s = run_["/truth/surfaces"]
    t, pos = np.asarray(s["t_s"]), np.asarray(s[f"{surface}_pos_rad"])
    on = t >= T_ON_S
    t, pos = t[on], pos[on]
    at_stop = np.flatnonzero(np.isclose(pos, pos.max(), atol=1e-12))
    return math.degrees(float(np.abs(np.diff(pos)).max()) / DT_S), float(t[at_stop[0]] - T_ON_S)


def render() -> str:
    cells: dict[str, list[str]] = {k: [] for k in ("stuck", "loss", "hard-over", "bias")}
    with tempfile.TemporaryDirectory() as tmp:
        for ac, surf in COLUMNS:
            d = Path(tmp) / f"{ac}_{surf}"
            d.mkdir()
            rate = RATE[surf]
            healthy = _peak(_pair(d, ac, surf, None), rate)
            fbw = " (FBW)" if ac == "f16" else ""
            stuck = _peak(_pair(d, ac, surf, "stuck"), rate)
            cells["stuck"].append(f"{stuck:.3g}")
            cells["loss"].append(f"{_peak(_pair(d, ac, surf, 'loss'), rate) / healthy:.2f}{fbw}")
            pair = _pair(d, ac, surf, "hard-over")
            slew, t_stop = _hard_over(pair[0], surf)
            cells["hard-over"].append(f"{slew:.0f} deg/s (stop after {t_stop:.2f} s)")
            cells["bias"].append(f"{_peak(_pair(d, ac, surf, 'bias'), rate) / healthy:.2f}")
    rows = {"stuck": "stuck: response", "loss": "loss 50 %: response ratio",
            "hard-over": "hard-over: rate to the stop", "bias": "bias 1 deg: response ratio"}
    lines = ["| | " + " | ".join(f"{NAMES[a]} {s}" for a, s in COLUMNS) + " |", "|---|---|---|---|---|"]
    lines += [f"| {rows[k]} | " + " | ".join(v) + " |" for k, v in cells.items()]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_faults_table.py", [(BLOCK, INPUTS, render)], sys.argv[1:]))

"""Figures of docs/faults.md: real JSBSim runs with faults, read back from their MCAP logs.

    .venv/bin/python docs/make_fault_figures.py      # writes docs/figures/faults_*.png (about 20 s)
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fdi_sim.flightlog import read_log  # noqa: E402
from fdi_sim.scenario import from_dict  # noqa: E402
from fdi_sim.sim import run  # noqa: E402

OUT = Path(__file__).resolve().parent / "figures"
T_ON_S = 2.0


def fly(tmp: Path, aircraft: str, faults: list[dict], name: str, initial: dict, duration_s: float = 10.0,
        autopilot: bool = False, maneuvers: list[dict] | None = None) -> dict:
    sc = from_dict({"name": name, "aircraft": aircraft, "duration_s": duration_s, "seed": 1, "initial": initial,
                    "autopilot": {"altitude": autopilot, "airspeed": autopilot, "lateral": autopilot},
                    "maneuvers": maneuvers if maneuvers is not None else
                    [{"type": "doublet-v1", "axis": "elevator", "t_start_s": 3.0, "amplitude_norm": 0.1, "pulse_s": 1.0}],
                    "faults": faults})
    res = run(sc, log_path=tmp / f"{name}.mcap", progress=False)
    return read_log(res.log_path).topics


def actuator_figure(tmp: Path) -> None:
    laws = {
        "healthy": [],
        "stuck": [{"type": "actuator-stuck-v1", "target": "elevator", "t_start_s": T_ON_S}],
        "loss 50 %": [{"type": "actuator-loss-v1", "target": "elevator", "effectiveness": 0.5, "t_start_s": T_ON_S}],
        "float": [{"type": "actuator-float-v1", "target": "elevator", "t_start_s": T_ON_S}],
        "rate limit 5 deg/s": [{"type": "actuator-rate-limit-v1", "target": "elevator", "rate_degps": 5.0, "t_start_s": T_ON_S}],
        "oscillation 1 deg 2 Hz": [{"type": "actuator-oscillation-v1", "target": "elevator", "amplitude_deg": 1.0,
                                    "frequency_hz": 2.0, "t_start_s": T_ON_S}],
    }
    fig, ax = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    for label, faults in laws.items():
        T = fly(tmp, "DHC6", faults, label.split()[0], {"h_ft": 5000.0, "vc_kts": 120.0})
        s, x = T["/truth/surfaces"], T["/truth/state"]
        ax[0].plot(s["t_s"], np.degrees(s["elevator_pos_rad"]), label=label)
        ax[1].plot(x["t_s"], np.degrees(x["q_radps"]), label=label)
    for a in ax:
        a.axvspan(T_ON_S, 10.0, color="0.9", zorder=0)
        a.grid(alpha=0.3)
    ax[0].set_ylabel("elevator flown [deg]")
    ax[1].set_ylabel("pitch rate q [deg/s]")
    ax[1].set_xlabel("t [s]  (grey: fault active from 2 s; elevator doublet 3-5 s)")
    ax[0].legend(fontsize=8, ncol=2)
    ax[0].set_title("DHC-6 120 KIAS, elevator faults, autopilot off (real JSBSim)")
    fig.tight_layout()
    fig.savefig(OUT / "faults_dhc6_elevator.png", dpi=110)


def icing_figure(tmp: Path) -> None:
    faults = [{"type": "icing-v1", "target": "airframe", "eta_final": 0.2, "t_start_s": 10.0, "ramp_s": 40.0}]
    T = fly(tmp, "DHC6", faults, "icing", {"h_ft": 5000.0, "vc_kts": 100.0}, duration_s=90.0, autopilot=True, maneuvers=[])
    op, x, s = T["/truth/operating_point"], T["/truth/state"], T["/truth/surfaces"]
    fig, ax = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    ax[0].plot(op["t_s"], op["icing_eta"])
    ax[0].set_ylabel("eta [-]")
    ax[1].plot(s["t_s"], s["throttle_pos_norm"])
    ax[1].set_ylabel("throttle [-]")
    ax[2].plot(x["t_s"], np.degrees(x["alpha_rad"]))
    ax[2].set_ylabel("alpha [deg]")
    ax[3].plot(x["t_s"], x["h_ft"])
    ax[3].set_ylabel("h [ft]")
    ax[3].set_xlabel("t [s]")
    for a in ax:
        a.axvspan(10.0, 90.0, color="0.9", zorder=0)
        a.grid(alpha=0.3)
    ax[0].set_title("DHC-6 100 KIAS, whole-aircraft icing eta 0 -> 0.2 (10-50 s), autopilot holding 5000 ft")
    fig.tight_layout()
    fig.savefig(OUT / "faults_dhc6_icing.png", dpi=110)


if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as d:
        actuator_figure(Path(d))
        icing_figure(Path(d))
    print("wrote", *sorted(p.name for p in OUT.glob("faults_*.png")))

"""What Sidar's adaptive observer estimates on the iced interim Twin Otter, as the generated block
``adapted-entries`` of docs/observers.md.

The adaptive run of the NIS false-alarm study (``fig_far`` of docs/make_observer_figures.py, the
same set-up: the interim longitudinal Twin Otter at 120 Hz, ZOH, the steady-state Kalman design
of the clean model, elevator and throttle sum-of-sines, the plant iced at eta 0.2 simulated with
``simulate_discrete`` and ``numpy.random.default_rng(6)``, Sidar's discrete law with per-row
gains 3e-4, 0.3, 0.3, 0.3 on the entries A[vt,vt], A[alpha..q, alpha..q] and B[q, elevator], 600 s):
per adapted entry the relative change ``estimates().relative_change`` at every step of the second
300 s, its mean and range, against the true relative change of the continuous derivative
(eta k of the UIUC factors) and of the discrete entry the observer adapts (A - I on the
diagonal, as ``AdaptiveObserver`` compares). No JSBSim (the interim model). Runs in about 10 s.

    python docs/make_observer_table.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, choose_sidar_gains  # noqa: E402
from fdi_sim.detectors.kalman import simulate_discrete, steady_state_kalman  # noqa: E402
from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "observers.md"
BLOCK = "adapted-entries"
INPUTS = ("fdi_sim/detectors/adaptive_observer.py", "fdi_sim/detectors/kalman.py", "fdi_sim/detectors/base.py",
          "fdi_sim/detectors/directional_observer.py", "fdi_sim/papers/twin_otter_interim.py", "fdi_sim/linear/model.py",
          "fdi_sim/linear/transform.py", "fdi_sim/decision/chi2.py", "fdi_sim/errors.py", "fdi_sim/units.py",
          "docs/make_observer_table.py")
DT = 1 / 120
QD = np.diag([0.02, 2e-4, 1e-3, 1e-5]) ** 2
RD = np.diag([0.1, 0.002, 0.002, 0.002]) ** 2
T_S, ETA = 600.0, 0.2
#: (row label, observer hypothesis, matrix, row, column)
ROWS = (("M_α", "A[q_radps,alpha_rad]", "A", 2, 1), ("M_δe", "B[q_radps,elevator_cmd_norm]", "B", 2, 0),
        ("Zw", "A[alpha_rad,alpha_rad]", "A", 1, 1), ("drag A[vt,vt]", "A[vt_fps,vt_fps]", "A", 0, 0))


def _true(clean, iced, M: str, r: int, c: int) -> float:
    """Relative change (iced - clean) / |clean| of one entry (A - I on a discrete diagonal)."""
    one = 1.0 if (M == "A" and r == c and clean.is_discrete) else 0.0
    a, b = getattr(clean, M)[r, c] - one, getattr(iced, M)[r, c] - one
    return float((b - a) / abs(a))


def render() -> str:
    clean = twin_otter_longitudinal_interim().discretize(DT)
    iced = twin_otter_longitudinal_interim(ETA).discretize(DT)
    des = steady_state_kalman(clean, QD, RD)
    n = int(T_S / DT)
    t = np.arange(n) * DT
    u = np.column_stack([0.2 * (np.sin(2 * np.pi * 0.3 * t) + np.sin(2 * np.pi * 0.8 * t) + np.sin(2 * np.pi * 1.7 * t)),
                         0.1 * np.sin(2 * np.pi * 0.05 * t)])
    run = simulate_discrete(iced, u, QD, RD, np.random.default_rng(6))  # fig_far's seed of the iced run
    mask_A = np.zeros((4, 4), bool)
    mask_A[0, 0] = True
    mask_A[1:3, 1:3] = True
    mask_B = np.zeros((4, 2), bool)
    mask_B[2, 0] = True
    g = np.array([3e-4, 0.3, 0.3, 0.3])
    gains = choose_sidar_gains(clean.A, des.predictor_gain, clean.C, g, g, 0.05, 0.2, mask_A, mask_B, dt_s=DT)
    obs = AdaptiveObserver(clean, des.predictor_gain, gains.M, gains.N, mask_A, mask_B, S=des.S, alpha=0.01)
    late = []
    for k in range(n):
        obs.step(run.t_s[k], run.u[k], run.y[k])
        if run.t_s[k] >= T_S / 2:
            late.append(obs.estimates().relative_change)
    late = np.array(late)
    cc, ci = twin_otter_longitudinal_interim(), twin_otter_longitudinal_interim(ETA)
    lines = ["| adapted entry | estimated change, mean (range) over the second 300 s | true change |", "|---|---|---|"]
    for label, hyp, M, r, c in ROWS:
        v = late[:, obs.hypotheses.index(hyp)]
        lines.append(f"| {label} | {v.mean():+.2f} ({v.min():.2f}…{v.max():.2f}) | {_true(cc, ci, M, r, c):+.3f} "
                     f"(discrete entry {_true(clean, iced, M, r, c):+.3f}) |")
    lines += ["", f"Relative change of the entry from the clean model, at every 120 Hz step of 300-600 s; eta {ETA:g}, "
              "seed 6; true change: of the continuous derivative (eta k) and of the discrete entry the observer adapts."]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_observer_table.py", [(BLOCK, INPUTS, render)], sys.argv[1:]))

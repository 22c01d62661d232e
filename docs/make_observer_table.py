"""The interim Twin Otter's modes, what Sidar's adaptive observer estimates on it iced, and how
the observer fares on JSBSim flights, as the generated blocks ``interim-modes``,
``adapted-entries`` and ``adaptive-jsbsim`` of docs/observers.md.

``interim-modes``: the eigenvalues of the continuous interim model
(``twin_otter_longitudinal_interim``), clean and at the eta of the studies below.

The adaptive run of the NIS false-alarm study (``fig_far`` of docs/make_observer_figures.py, the
same set-up: the interim longitudinal Twin Otter at 120 Hz, ZOH, the steady-state Kalman design
of the clean model, elevator and throttle sum-of-sines, the plant iced at eta 0.2 simulated with
``simulate_discrete`` and ``numpy.random.default_rng(6)``, Sidar's discrete law with per-row
gains 3e-4, 0.3, 0.3, 0.3 on the entries A[vt,vt], A[alpha..q, alpha..q] and B[q, elevator], 600 s):
per adapted entry the relative change ``estimates().relative_change`` at every step of the second
300 s, its mean and range, against the true relative change of the continuous derivative
(eta k of the UIUC factors) and of the discrete entry the observer adapts (A - I on the
diagonal, as ``AdaptiveObserver`` compares). No JSBSim (the interim model); about 10 s.

``adaptive-jsbsim``: as ``tests/detectors/test_adaptive_observer.py`` (its ``jsbsim_flights``), but
60 s long and in light and moderate turbulence: fault-free JSBSim flights (seed 3; F-16 10 kft /
400 KTAS, DHC-6 5000 ft / 120 KCAS; autopilot, default sensor suite, no detector bank), each
with the model linearized at its point, read back from the MCAP log as (u(k-1), y(k)) pairs,
and run through ``adaptive-observer-v1``'s factory at Sidar's unnormalized law (per-step
m = n = 0.1, 0.01, 0.001) and at the normalized law (0.01, the default, and 0.1): when the
state stops being finite (``diverged_t_s`` after the first sample); with the gains at zero (the
Kalman filter, no adaptation) the median |x̂|² and the rms of the largest x̂ components; and the
smallest nominal entry the relative-change scores divide by. Seconds per flight.

    python docs/make_observer_table.py
"""
from __future__ import annotations

import sys
import tempfile
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
INTERIM_INPUTS = ("fdi_sim/papers/twin_otter_interim.py", "fdi_sim/linear/model.py", "fdi_sim/units.py",
                  "fdi_sim/errors.py", "docs/make_observer_table.py")
#: the flights (the sim loop without a detector bank, the log) and the observer's factory
JSBSIM_INPUTS = ("aircraft", "fdi_sim/_aircraft", "fdi_sim/aircraft", "fdi_sim/sim", "fdi_sim/pilot", "fdi_sim/sensors",
                 "fdi_sim/scenario", "fdi_sim/flightlog", "fdi_sim/faults/injector.py", "fdi_sim/signals.py",
                 "fdi_sim/linear", "fdi_sim/operating_point.py", "fdi_sim/isa.py", "fdi_sim/seeds.py",
                 "fdi_sim/units.py", "fdi_sim/errors.py", "fdi_sim/detectors/adaptive_observer.py",
                 "fdi_sim/detectors/catalogue_observers.py", "fdi_sim/detectors/kalman.py",
                 "fdi_sim/detectors/noise.py", "fdi_sim/detectors/directional_observer.py",
                 "fdi_sim/detectors/base.py", "fdi_sim/decision/chi2.py", "fdi_sim/decision/base.py",
                 "docs/make_observer_table.py")
#: (label, aircraft, [initial] of the scenario, operating point arguments)
JSBSIM_POINTS = (("F-16 10 kft / 400 KTAS", "f16", "h_ft = 10000.0\nvt_kts = 400.0", dict(h_ft=10000.0, vt_kts=400.0)),
                 ("DHC-6 5000 ft / 120 KCAS", "DHC6", "h_ft = 5000.0\nvc_kts = 120.0", dict(h_ft=5000.0, vc_kts=120.0)))
TURBULENCE = ("light", "moderate")
FLIGHT_S, FLIGHT_SEED = 60.0, 3
#: (column label, per-step gain m = n, normalized law)
LAWS = (("Sidar, m = 0.1", 0.1, False), ("Sidar, m = 0.01", 0.01, False), ("Sidar, m = 0.001", 0.001, False),
        ("normalized, m = 0.01 (default)", 0.01, True), ("normalized, m = 0.1", 0.1, True))
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


def interim_table() -> str:
    """Short period and phugoid of the continuous interim model, clean and iced."""
    lines = ["| interim Twin Otter | short period [1/s] | phugoid [1/s] |", "|---|---|---|"]
    for eta in (0.0, ETA):
        z = np.linalg.eigvals(twin_otter_longitudinal_interim(eta).A)
        up = sorted((w for w in z if w.imag > 0), key=abs)  # the two upper-half-plane roots, slow first
        ph, sp = up[0], up[-1]
        lines.append(f"| eta {eta:g} | {sp.real:.3f} ± {sp.imag:.3f}j | {ph.real:.3f} ± {ph.imag:.3f}j |")
    return "\n".join(lines)


def _flight(aircraft: str, init: str, op_kw: dict, turbulence: str, tmp: Path):
    """One fault-free flight and its model: (model, t [s], u(k-1), y(k)) as the test reads them."""
    from fdi_sim.aircraft import Aircraft
    from fdi_sim.flightlog import read_log
    from fdi_sim.linear.linearize import linearize
    from fdi_sim.operating_point import OperatingPoint
    from fdi_sim.scenario import loads
    from fdi_sim.sim.run import run

    model = linearize(Aircraft(aircraft), OperatingPoint(aircraft, **op_kw)).model
    text = (f'name = "ao_{aircraft}_{turbulence}"\naircraft = "{aircraft}"\nduration_s = {FLIGHT_S}\n'
            f'seed = {FLIGHT_SEED}\n[initial]\n{init}\n[atmosphere]\nturbulence = "{turbulence}"\n')
    log = read_log(run(loads(text, "ao.toml"), tmp).log_path)
    meas, cmd = log.topics["/sensors/measurements"], log.topics["/commands/pilot"]
    y = np.stack([meas[o] for o in model.output_names], axis=1)
    u = np.stack([cmd[c] if c in cmd.fields else np.full(len(cmd), model.u0[j])  # gust columns: trim (0)
                  for j, c in enumerate(model.input_names)], axis=1)
    return model, meas.t_s[1:], u[:-1], y[1:]


def _fmt(v: float) -> str:
    """A positive number: whole from 10 up (63, 7420), 2 significant digits below."""
    return f"{v:.0f}" if v >= 10 else f"{v:.2g}"


def _fly_observer(obs, t_s, u, y) -> tuple[str, list[np.ndarray]]:
    """Run ``obs`` over the flight; its divergence time after the first sample ("60 s" when it
    stays finite) and its state estimate at every step while finite."""
    xs = []
    for t, uk, yk in zip(t_s, u, y):
        obs.step(t, uk, yk)
        if obs.diverged_t_s is not None:
            return f"{obs.diverged_t_s - t_s[0]:.3f} s", xs
        xs.append(np.array(obs.x_hat, float))
    return f"finite for {t_s[-1] - t_s[0]:.0f} s", xs


def jsbsim_table() -> str:
    from fdi_sim.detectors.catalogue_observers import make_adaptive_observer

    head = "| flight | " + " | ".join(lab for lab, _, _ in LAWS) + " | median \\|x̂\\|² | largest rms of x̂ |"
    lines = [head, "|---" * (len(LAWS) + 3) + "|"]
    smallest = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, aircraft, init, op_kw in JSBSIM_POINTS:
            for turb in TURBULENCE:
                model, t_s, u, y = _flight(aircraft, init, op_kw, turb, Path(tmp) / f"{aircraft}_{turb}")
                cells = []
                for _, m, normalized in LAWS:
                    obs = make_adaptive_observer(model, m_gain=m, n_gain=m, normalized=normalized)
                    cells.append(_fly_observer(obs, t_s, u, y)[0])
                # the regressor's scale, free of any adaptation: the same observer with zero gains
                # (the Kalman filter), whose state estimate stays finite
                obs = make_adaptive_observer(model, m_gain=0.0, n_gain=0.0)
                x = np.array(_fly_observer(obs, t_s, u, y)[1])
                names = obs.model.state_names
                nominal = np.abs(obs._nominal[obs._nominal != 0])  # what the relative-change scores divide by
                smallest.append(f"{label.split(' ')[0]} {nominal.min():.0e}")
                x2 = np.einsum("ij,ij->i", x, x)
                rms = np.sqrt(np.mean(x ** 2, axis=0))
                top = np.argsort(rms)[::-1][:3]
                lines.append(f"| {label}, {turb} | " + " | ".join(cells) + f" | {_fmt(float(np.median(x2)))} | "
                             + ", ".join(f"{names[i]} {rms[i]:.3g}" for i in top) + " |")
    lines += ["", f"Fault-free {FLIGHT_S:g} s flights, seed {FLIGHT_SEED}, autopilot, default sensor suite; Sidar: the "
              "unnormalized law (eq. 23), normalized: each update divided by 1 + \\|x̂\\|² + \\|u\\|²; a time is when "
              "the state estimate stopped being finite, after the first sample. \\|x̂\\|² and rms: the state "
              "estimate's deviation from trim with the gains at zero (no adaptation: the Kalman filter), in the model's "
              "units (ft, ft/s, rad, rpm, %), the three largest. "
              f"Smallest nominal adapted entry (the scores' denominator): {', '.join(dict.fromkeys(smallest))}."]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_observer_table.py", [("interim-modes", INTERIM_INPUTS, interim_table),
                                                                                   (BLOCK, INPUTS, render),
                                                                                   ("adaptive-jsbsim", JSBSIM_INPUTS,
                                                                                    jsbsim_table)], sys.argv[1:]))

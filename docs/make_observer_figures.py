"""Figures for docs/observers.md: ``.venv/bin/python docs/make_observer_figures.py`` writes docs/figures/observer_*.png.

Everything is computed by fdi_sim.detectors (Beard-Jones, LMI, Kalman, Sidar); this script only plots.
The Twin Otter is the INTERIM hand-built model ``twin_otter_longitudinal_interim()``.
"""
from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.linalg as sla  # noqa: E402
from scipy.signal import place_poles  # noqa: E402
from scipy.stats import binomtest  # noqa: E402

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, choose_sidar_gains, run_sidar_example  # noqa: E402
from fdi_sim.detectors.beard_jones import angle_rad, beard_jones_gain  # noqa: E402
from fdi_sim.detectors.kalman import KalmanInnovationDetector, MultipleModelBank, simulate_discrete, steady_state_kalman  # noqa: E402
from fdi_sim.detectors.lmi_filter import design_lmi_filter, sensitivity_max_sv  # noqa: E402
from fdi_sim.detectors.twin_otter_interim import twin_otter_longitudinal_interim  # noqa: E402

OUT = Path(__file__).parent / "figures"
DT = 1 / 120
QD = np.diag([0.02, 2e-4, 1e-3, 1e-5]) ** 2
RD = np.diag([0.1, 0.002, 0.002, 0.002]) ** 2


def _save(fig: plt.Figure, name: str, legends: dict[plt.Axes, int]) -> None:
    """Legends (axes -> font size), tight layout, write ``docs/figures/<name>`` and close."""
    for ax, fontsize in legends.items():
        ax.legend(fontsize=fontsize)
    fig.tight_layout()
    fig.savefig(OUT / name, dpi=110)
    plt.close(fig)


def _zoh_error(Acl: np.ndarray, f: np.ndarray, n_of_t, dt: float, steps: int) -> np.ndarray:
    n = Acl.shape[0]
    blk = np.zeros((n + 1, n + 1))
    blk[:n, :n], blk[:n, n] = Acl * dt, f * dt
    E = sla.expm(blk)
    e, out = np.zeros(n), []
    for k in range(steps):
        e = E[:n, :n] @ e + E[:n, n] * n_of_t(k * dt)
        out.append(e.copy())
    return np.array(out)


def fig_beard_jones() -> None:
    A = np.array([[0.0, 3.0, 4.0], [1.0, 2.0, 3.0], [0.0, 2.0, 5.0]])
    C = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    f = np.array([1.0, -0.5, 0.5])
    d = beard_jones_gain(A, C, f[:, None], [[-8.0]], [-4.0, -5.0])
    Lp = place_poles(A.T, C.T, [-4.0, -5.0, -8.0]).gain_matrix.T
    n_of_t = lambda t: np.sin(3 * t) + 0.5 * np.cos(11 * t)  # noqa: E731
    t = np.arange(1, 3001) * 1e-3
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    for Acl, name, ls in ((d.A_cl, "Beard-Jones (eq. 2.50)", "-"), (A - Lp @ C, "plain observer, same poles", "--")):
        R = _zoh_error(Acl, f, n_of_t, 1e-3, 3000) @ C.T
        ax[0].plot(R[:, 0], R[:, 1], ls, label=name)
        ang = [np.degrees(angle_rad(r, C @ f)) if np.linalg.norm(r) > 1e-12 else np.nan for r in R]
        ax[1].plot(t, ang, ls, label=name)
    cf = C @ f / np.linalg.norm(C @ f)
    ax[0].plot([-0.2 * cf[0], 0.2 * cf[0]], [-0.2 * cf[1], 0.2 * cf[1]], "k:", label="C f")
    ax[0].set(xlabel="r1 = e2", ylabel="r2 = e3", title="residual path, fault n(t) = sin 3t + 0.5 cos 11t")
    ax[1].set(xlabel="t [s]", ylabel="angle(r, C f) [deg]", title="patent 3x3 example (eq. 2.47-2.54)")
    _save(fig, "observer_beard_jones.png", {ax[0]: 8, ax[1]: 8})


def fig_lmi() -> dict[str, object]:
    m = twin_otter_longitudinal_interim()
    V = np.diag([1.0, 0.002, 0.002, 0.002]) ** 2
    res: dict[str, object] = {}
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    w = np.logspace(-3, 3, 400)
    for method, eps in (("least-squares", 1e-7), ("direct", 0.0), ("literal", 1e-7)):
        t0 = time.perf_counter()
        d = design_lmi_filter(m, "elevator_cmd_norm", V, 20.0, epsilon=eps or 1e-7, method=method)  # type: ignore[arg-type]
        res[method] = (d, time.perf_counter() - t0)
        ax[0].semilogx(w, sensitivity_max_sv(np.asarray(m.A), np.asarray(m.C), d.L, V, w), label=f"{method}: {d.alignment_error_deg:.2f} deg")
        ax[1].plot(d.poles.real, d.poles.imag, "o", label=method, alpha=0.7)
    ax[0].axhline(1.0, color="k", ls=":")
    ax[0].set(xlabel="w [rad/s]", ylabel="max sv of V^-1/2 S(jw) V^1/2", title="Twin Otter (interim), elevator, h = 20 1/s")
    ax[1].axvline(-20.0, color="k", ls=":", label="-h")
    ax[1].set(xlabel="Re s [1/s]", ylabel="Im s [1/s]", title="closed-loop poles")
    _save(fig, "observer_lmi.png", {ax[0]: 8, ax[1]: 8})
    return res


def fig_sidar() -> None:
    cases = [
        ("observer_sidar_fig6.png", 1, False), ("observer_sidar_fig7.png", 1, True),
        ("observer_sidar_fig8.png", 2, False), ("observer_sidar_fig9.png", 2, True),
    ]
    for fname, ex, tracking in cases:
        per_step = (10 / 0.05, 5 / 0.05) if ex == 1 else (1 / 0.05, 1 / 0.05)
        runs = [("stated gains (continuous)", run_sidar_example(ex, tracking, t_end_s=20.0)),
                ("per-step gains / 0.05 s", run_sidar_example(ex, tracking, *per_step, t_end_s=20.0))]
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        for (label, r), ls in zip(runs, ("-", "--")):
            ax[0].semilogy(r.t_s, np.maximum(r.output_error_norm, 1e-6), ls, label=label)
            for j, nm in enumerate(r.names):
                ax[1].plot(r.t_s, r.params_hat[:, j], ls, label=f"{nm}0 ({label})" if ls == "-" else None)
        for j, nm in enumerate(runs[0][1].names):
            ax[1].plot(runs[0][1].t_s, runs[0][1].params_true[:, j], "k:", lw=1)
        ax[0].axhline(4e-3 if ex == 1 else 5e-2, color="k", ls=":", lw=1)
        ax[0].set(xlabel="t [s]", ylabel="|y - yh|", title=f"Sidar example {ex}{' tracking' if tracking else ''}: output error")
        ax[1].set(xlabel="t [s]", ylabel="parameter", title="estimates (dotted: truth)")
        _save(fig, fname, {ax[0]: 8, ax[1]: 7})


def fig_far() -> dict[str, tuple[int, int]]:
    clean = twin_otter_longitudinal_interim().discretize(DT)
    iced = twin_otter_longitudinal_interim(0.2).discretize(DT)
    des = steady_state_kalman(clean, QD, RD)
    T = 600.0
    n = int(T / DT)
    t = np.arange(n) * DT
    u = np.column_stack([0.2 * (np.sin(2 * np.pi * 0.3 * t) + np.sin(2 * np.pi * 0.8 * t) + np.sin(2 * np.pi * 1.7 * t)),
                         0.1 * np.sin(2 * np.pi * 0.05 * t)])
    run_c = simulate_discrete(clean, u, QD, RD, np.random.default_rng(5))
    run_i = simulate_discrete(iced, u, QD, RD, np.random.default_rng(6))
    mask_A = np.zeros((4, 4), bool)
    mask_A[0, 0] = True
    mask_A[1:3, 1:3] = True
    mask_B = np.zeros((4, 2), bool)
    mask_B[2, 0] = True
    g = np.array([3e-4, 0.3, 0.3, 0.3])
    gains = choose_sidar_gains(clean.A, des.predictor_gain, clean.C, g, g, 0.05, 0.2, mask_A, mask_B, dt_s=DT)
    obs = AdaptiveObserver(clean, des.predictor_gain, gains.M, gains.N, mask_A, mask_B, S=des.S, alpha=0.01)
    counts: dict[str, tuple[int, int]] = {}
    hist = []
    for name, det, run, burn in (("matched", KalmanInnovationDetector(des, alpha=0.01), run_c, 0.0),
                                 ("mismatched", KalmanInnovationDetector(des, alpha=0.01), run_i, 0.0),
                                 ("adaptive", obs, run_i, T / 2)):
        a = k_n = 0
        for k in range(n):
            r = det.step(run.t_s[k], run.u[k], run.y[k])
            if name == "adaptive" and k % 60 == 0:
                hist.append((run.t_s[k], *obs.estimates().relative_change))
            if run.t_s[k] >= burn:
                k_n += 1
                a += bool(r.alarm)
        counts[name] = (a, k_n)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    for i, (name, (a, k_n)) in enumerate(counts.items()):
        ci = binomtest(a, k_n, 0.01).proportion_ci(0.95)
        ax[0].errorbar(i, a / k_n, yerr=[[a / k_n - ci.low], [ci.high - a / k_n]], fmt="o", capsize=4)
    ax[0].axhline(0.01, color="k", ls=":")
    ax[0].set_xticks(range(3), list(counts))
    ax[0].set(ylabel="NIS false-alarm rate (95 % CI)", title="alpha = 0.01, 600 s at 120 Hz, icing eta = 0.2")
    H = np.array(hist)
    for j, nm in enumerate(obs.hypotheses):
        ax[1].plot(H[:, 0], H[:, j + 1], label=nm)
    ax[1].set(xlabel="t [s]", ylabel="relative change of adapted entry", title="Sidar estimates on the iced aircraft")
    _save(fig, "observer_nis_far.png", {ax[1]: 7})
    return counts


def fig_mmae() -> None:
    clean = twin_otter_longitudinal_interim().discretize(DT)
    designs = [steady_state_kalman(twin_otter_longitudinal_interim(e).discretize(DT), QD, RD) for e in (0.0, 0.1, 0.2)]
    n = int(60 / DT)
    t = np.arange(n) * DT
    u = np.column_stack([0.2 * (np.sin(2 * np.pi * 0.3 * t) + np.sin(2 * np.pi * 0.8 * t)), 0 * t])
    x = np.zeros(4)
    rng = np.random.default_rng(1)
    bank = MultipleModelBank(designs, ["clean", "eta 0.1", "eta 0.2"], alarm_probability=0.95)
    P = []
    for k in range(n):
        eta = 0.0 if t[k] < 20 else min(0.2, 0.01 * (t[k] - 20))  # ice accretes from 20 s, 0.01 per s
        md = twin_otter_longitudinal_interim(eta).discretize(DT) if k % 60 == 0 else md
        y = md.C @ x + rng.multivariate_normal(np.zeros(4), RD) + clean.y0
        P.append(bank.step(t[k], u[k] + clean.u0, y).scores)
        x = md.A @ x + md.B @ u[k] + rng.multivariate_normal(np.zeros(4), QD)
    P = np.array(P)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for j, nm in enumerate(bank.hypotheses):
        ax.plot(t, P[:, j], label=nm)
    ax.set(xlabel="t [s]", ylabel="hypothesis probability", title="multiple-model bank; ice grows 0 -> 0.2 over 20-40 s")
    _save(fig, "observer_mmae.png", {ax: 8})


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    fig_beard_jones()
    lmi = fig_lmi()
    for k, (d, s) in lmi.items():
        print(f"LMI {k}: {s:.2f} s, align {d.alignment_error_deg:.3f} deg, max sv S {d.max_sensitivity:.6f}, "  # type: ignore[attr-defined]
              f"poles {np.round(d.poles, 2)}, trace P {np.trace(d.P):.4g}, objective {d.objective:.4g}")  # type: ignore[attr-defined]
    fig_sidar()
    print("FAR", {k: (a, n, round(a / n, 5)) for k, (a, n) in fig_far().items()})
    fig_mmae()

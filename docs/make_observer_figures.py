"""Figures for docs/observers.md: ``.venv/bin/python docs/make_observer_figures.py`` writes docs/figures/observer_*.png.

``--sidar`` makes only Sidar's figures 6-9 and prints the readings tables of the Sidar section.

Everything is computed by fdi_sim.detectors (Beard-Jones, LMI, Kalman, Sidar); this script only plots.
The Twin Otter is the INTERIM hand-built model ``twin_otter_longitudinal_interim()``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.linalg as sla  # noqa: E402
from scipy.signal import place_poles  # noqa: E402
from scipy.stats import binomtest  # noqa: E402

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, choose_sidar_gains  # noqa: E402
from fdi_sim.detectors.beard_jones import angle_rad, beard_jones_gain  # noqa: E402
from fdi_sim.detectors.kalman import KalmanInnovationDetector, MultipleModelBank, simulate_discrete, steady_state_kalman  # noqa: E402
from fdi_sim.detectors.lmi_filter import design_lmi_filter, sensitivity_max_sv  # noqa: E402
from fdi_sim.papers.sidar_examples import SidarReading, sidar_bars, simulate_sidar  # noqa: E402
from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim  # noqa: E402

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


# --------------------------------------------------------------------------- Sidar (sec. VI): figures 6-9 and the readings study

SIDAR_GRID_1 = np.geomspace(1.0, 1e4, 17)  # m, n grid of example 1 [1/s] (continuous-equivalent: per step = x 0.05 s)
SIDAR_GRID_2 = np.geomspace(0.1, 3e3, 23)  # common gain of example 2 [1/s]
# example 1: (row label, reading); example 2 likewise; "printed" = the literal text
SIDAR_READINGS_1 = [
    ("eq. 22 continuous, x_hat, K for theta_hat(0), printed x(0), x_hat(0) [literal]", SidarReading()),
    ("regressor x (true state)", SidarReading(regressor="x")),
    ("K for the true theta(0)", SidarReading(gain_design="true")),
    ("every entry of A0, B0 adapts (M, N all m, n)", SidarReading(full_matrices=True)),
    ("normalized law (/ 1 + |x_hat|^2 + |u|^2)", SidarReading(normalized=True)),
    ("eq. 23 every 0.05 s, plant + observer continuous in between", SidarReading(law="sampled")),
    ("... update applied one step late (the module before issue 12)", SidarReading(law="sampled", update="next_sample")),
    ("eq. 23, plant and observer forward Euler at 0.05 s", SidarReading(law="euler")),
    ("eq. 23, observer Euler on samples, plant exact (biased)", SidarReading(law="euler_observer")),
    ("x_hat2(0) = 0 instead of 1", SidarReading(x_hat0=(0.8, 0.0))),
    ("x_hat(0) = x(0)", SidarReading(x_hat0=(1.0, 0.0))),
]
SIDAR_READINGS_2 = [
    ("eq. 22 continuous, M = g C+, b from eps2, printed x_hat(0) [literal]", SidarReading()),
    ("b from eps1", SidarReading(b_from="y1")),
    ("b from eps1 + eps2", SidarReading(b_from="y1+y2")),
    ("M, N all ones (every output drives every parameter)", SidarReading(outputs="all")),
    ("eq. 23 every 0.05 s, plant + observer continuous in between", SidarReading(law="sampled")),
    ("eq. 23, plant and observer forward Euler at 0.05 s", SidarReading(law="euler")),
    ("eq. 23, observer Euler on samples, plant exact (biased)", SidarReading(law="euler_observer")),
    ("x_hat(0) = x(0)", SidarReading(x_hat0=(1.0, 0.0, 0.0))),
]
SIDAR_FIG9_ONLY = [
    ("fig. 9 starts matched (theta_hat(0) = theta(0), x_hat(0) = x(0))", SidarReading(start_matched=True)),
    ("... and c held at its true value", SidarReading(start_matched=True, adapt_c=False)),
    ("... sampled law, per-step gains", SidarReading(start_matched=True, law="sampled")),
]


def _sidar_scale(reading: SidarReading) -> float:
    """Continuous-equivalent gain [1/s] -> the reading's gain (per step for the discrete laws)."""
    return 1.0 if reading.law == "continuous" else reading.step_s


def _bars_text(bars, j: int) -> str:
    return " / ".join(f"{b.measured[j]:.3g}" if np.isfinite(b.measured[j]) else "div." for b in bars) + (
        " **met**" if all(b.met[j] for b in bars) else "")


def sidar_readings() -> dict[str, list[str]]:
    """The readings tables of docs/observers.md (markdown rows); every number from simulate_sidar."""
    out: dict[str, list[str]] = {"ex1": [], "ex2": [], "ex2_pp": []}
    stated1 = np.array([[10.0, 5.0], [200.0, 100.0]])  # stated m, n as [1/s], and as per 0.05-s step
    grid1 = np.array([(m, n) for m in SIDAR_GRID_1 for n in SIDAR_GRID_1])
    for label, rd in SIDAR_READINGS_1:
        g = np.vstack([stated1, grid1]) * _sidar_scale(rd)
        b6 = sidar_bars(simulate_sidar(1, g, False, rd, 12.0))
        b7 = sidar_bars(simulate_sidar(1, g, True, rd, 20.0))
        ok6, ok7 = np.logical_and.reduce([b.met for b in b6]), np.logical_and.reduce([b.met for b in b7])
        out["ex1"].append(f"| {label} | {_bars_text(b6, 0)} | {_bars_text(b6, 1)} | {_bars_text(b7, 0)} | {_bars_text(b7, 1)} "
                          f"| {ok6[2:].sum()} / {ok7[2:].sum()} / {(ok6 & ok7)[2:].sum()} |")
    stated2 = np.array([[1.0] * 3, [20.0] * 3])  # unity as [1/s], and per 0.05-s step
    grid2 = np.repeat(SIDAR_GRID_2[:, None], 3, axis=1)
    for label, rd in SIDAR_READINGS_2 + SIDAR_FIG9_ONLY:
        g = np.vstack([stated2, grid2]) * _sidar_scale(rd)
        b9 = sidar_bars(simulate_sidar(2, g, True, rd, 16.0))
        ok9 = np.logical_and.reduce([b.met for b in b9])
        if rd.start_matched:
            out["ex2"].append(f"| {label} | - | - | {_bars_text(b9, 0)} | {_bars_text(b9, 1)} | - / {ok9[2:].sum()} / - |")
            continue
        b8 = sidar_bars(simulate_sidar(2, g, False, rd, 12.0))
        ok8 = np.logical_and.reduce([b.met for b in b8])
        out["ex2"].append(f"| {label} | {_bars_text(b8, 0)} | {_bars_text(b8, 1)} | {_bars_text(b9, 0)} | {_bars_text(b9, 1)} "
                          f"| {ok8[2:].sum()} / {ok9[2:].sum()} / {(ok8 & ok9)[2:].sum()} |")
    # example 2 with a gain per parameter (a, b, c): which gains can meet fig. 8 at all
    gv = 10.0 ** (0.1 + 0.2 * np.arange(17))  # 1.26 .. 2512 /s, 0.2 decade, holds 50.1 and 794
    g3 = np.array([(ga, gb, gc) for ga in gv for gb in gv for gc in gv])
    for label, rd in (("literal (continuous)", SidarReading()), ("sampled (eq. 23 every 0.05 s)", SidarReading(law="sampled"))):
        b8 = sidar_bars(simulate_sidar(2, g3 * _sidar_scale(rd), False, rd, 12.0))
        ok8 = np.logical_and.reduce([b.met for b in b8])
        gm = g3[ok8] if ok8.any() else np.full((1, 3), np.nan)  # continuous-equivalent [1/s]
        k = int(np.argmin(gm.max(axis=1)))  # the met row with the smallest largest gain
        out["ex2_pp"].append(f"| {label} | {ok8.sum()} of {len(g3)} | {gm.max(axis=1)[k]:.3g} | ({gm[k, 0]:.3g}, {gm[k, 1]:.3g}, "
                             f"{gm[k, 2]:.3g}): {_bars_text(b8, int(np.flatnonzero(ok8)[k]) if ok8.any() else 0)} |")
    return out


def fig_sidar() -> None:
    """docs/figures/observer_sidar_fig6..9.png: the literal reading with the stated and the per-step gains,
    and the nearest reading that meets the figure's statements (named in the legend)."""
    cases = [  # file, example, tracking, [(label, gains [1/s], reading, line style)]
        ("observer_sidar_fig6.png", 1, False, [("literal, m=10, n=5 /s", (10, 5), SidarReading(), ":"),
                                               ("literal, per step: 200, 100 /s", (200, 100), SidarReading(), "-"),
                                               ("x_hat2(0)=0, 200, 100 /s", (200, 100), SidarReading(x_hat0=(0.8, 0.0)), "--")]),
        ("observer_sidar_fig7.png", 1, True, [("literal, m=10, n=5 /s", (10, 5), SidarReading(), ":"),
                                              ("literal, per step: 200, 100 /s", (200, 100), SidarReading(), "-"),
                                              ("x_hat2(0)=0, 200, 100 /s", (200, 100), SidarReading(x_hat0=(0.8, 0.0)), "--")]),
        ("observer_sidar_fig8.png", 2, False, [("literal, unity /s", (1, 1, 1), SidarReading(), ":"),
                                               ("literal, per step: 20 /s", (20, 20, 20), SidarReading(), "-"),
                                               ("tuned: a 50, b 794, c 794 /s", (50.12, 794.3, 794.3), SidarReading(), "--"),
                                               ("unequal: a 1000, b 1000, c 100 /s", (1000, 1000, 100), SidarReading(), "-.")]),
        ("observer_sidar_fig9.png", 2, True, [("literal, unity /s", (1, 1, 1), SidarReading(), ":"),
                                              ("literal, per step: 20 /s", (20, 20, 20), SidarReading(), "-"),
                                              ("starts matched, 400 /s", (400, 400, 400), SidarReading(start_matched=True), "--"),
                                              ("unequal: a 1000, b 1000, c 100 /s", (1000, 1000, 100), SidarReading(), "-.")]),
    ]
    for fname, ex, tracking, runs in cases:
        q = ex + 1
        fig, ax = plt.subplots(1, q + 1, figsize=(3.6 * (q + 1), 3.6))
        for i, (label, gains, rd, ls) in enumerate(runs):
            r = simulate_sidar(ex, np.array(gains, float), tracking, rd, 20.0 if tracking else 12.0)
            met = "all met" if all(b.met[0] for b in sidar_bars(r)) else "not met"
            ax[0].semilogy(r.t_s, np.maximum(r.output_error_norm[0], 1e-7), ls, color=f"C{i}", lw=1, label=f"{label} ({met})")
            for j in range(q):
                ax[j + 1].plot(r.t_s, r.params_hat[0, :, j], ls, color=f"C{i}", lw=1)
        for j, nm in enumerate(r.names):
            ax[j + 1].plot(r.t_s, r.params_true[:, j], "k", lw=0.8)
            lo, hi = r.params_true[:, j].min(), r.params_true[:, j].max()
            ax[j + 1].set(xlabel="t [s]", title=f"{nm}_0 (black: plant {nm})", ylim=(lo - 1.2, hi + 1.0))
        for b in sidar_bars(r):  # the output-error statements: a level over a time window
            if "|eps|" in b.text:
                t0, t1 = (float(b.text.split("t >= ")[1].split(" ")[0]), r.t_s[-1]) if "t >= " in b.text else (
                    float(b.text.split("(")[1].split("-")[0]), 12.0)
                ax[0].hlines(b.limit, t0, t1, colors="k", linestyles=":", lw=1)
        ax[0].set(xlabel="t [s]", ylabel="|y - y_hat|", ylim=(1e-6, 3), title=f"Sidar fig. {fname[-5]}: output error")
        fig.text(0.01, 0.01, "dotted black: the paper's output-error bounds; parameter bounds: docs/observers.md", fontsize=7)
        _save(fig, fname, {ax[0]: 6})


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
    md = clean  # the plant flown; re-linearized every 60 steps as the ice grows
    for k in range(n):
        eta = 0.0 if t[k] < 20 else min(0.2, 0.01 * (t[k] - 20))  # ice accretes from 20 s, 0.01 per s
        if k % 60 == 0:
            md = twin_otter_longitudinal_interim(eta).discretize(DT)
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
    if "--sidar" in sys.argv:  # only Sidar's figures and the readings tables (about 10 min)
        fig_sidar()
        for key, rows in sidar_readings().items():
            print(f"\n[{key}]\n" + "\n".join(rows))
        raise SystemExit(0)
    fig_beard_jones()
    lmi = fig_lmi()
    for k, (d, s) in lmi.items():
        print(f"LMI {k}: {s:.2f} s, align {d.alignment_error_deg:.3f} deg, max sv S {d.max_sensitivity:.6f}, "  # type: ignore[attr-defined]
              f"poles {np.round(d.poles, 2)}, trace P {np.trace(d.P):.4g}, objective {d.objective:.4g}")  # type: ignore[attr-defined]
    fig_sidar()
    print("FAR", {k: (a, n, round(a / n, 5)) for k, (a, n) in fig_far().items()})
    fig_mmae()

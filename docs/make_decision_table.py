"""The decision rules measured against their documented false-alarm rates, run lengths and sample
numbers on white noise, as the generated block ``decision-white-noise`` of docs/decision.md.

The same seeded runs as the tests of ``tests/decision/`` (the seeds 20, 30, 40-42, 50, 51, 60,
61, 70, 71, 80 of ``numpy.random.default_rng``, the same draws in the same order): per-sample
rates with the Clopper-Pearson 95 % interval (:func:`fdi_sim.decision.intervals.clopper_pearson`;
for k of n the outputs n samples apart, whose windows are disjoint), run lengths and sample
numbers with the CLT 95 % interval of the mean over independent runs from reset (4000 runs for
the ARLs). Runs in about 10 s.

    python docs/make_decision_table.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.stats import norm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.decision import (  # noqa: E402
    AngleMagnitudeRule,
    Chi2Test,
    Cusum,
    Persistence,
    SignatureIsolation,
    Sprt,
    WindowGlr,
    cusum_arl_exact,
    sprt_operating_characteristic,
)
from fdi_sim.decision.glr import GLR_ARL_MEASURED_RATIO  # noqa: E402
from fdi_sim.decision.intervals import clopper_pearson  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "decision.md"
INPUTS = ("fdi_sim/decision", "fdi_sim/errors.py", "docs/make_decision_table.py")


def _mean_ci(x: np.ndarray) -> tuple[float, float, float]:
    """Mean and its 95 % interval (CLT)."""
    x = np.asarray(x, float)
    m, se = float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size))
    z = float(norm.ppf(0.975))
    return m, m - z * se, m + z * se


def _run_lengths(rule, rng: np.random.Generator, n_runs: int, length: int, shift: float = 0.0,
                 batch: int = 500) -> np.ndarray:
    """First-alarm times [samples, 1-based] of ``rule.run`` on ``n_runs`` independent N(shift, 1)
    traces of ``length`` (as tests/decision/decision_intervals.py draws them)."""
    out = []
    for start in range(0, n_runs, batch):
        m = min(batch, n_runs - start)
        a = rule.run(rng.standard_normal((length, m)) + shift).alarm
        if not a.any(axis=0).all():
            raise RuntimeError("some runs never alarmed: make the traces longer")
        out.append(a.argmax(axis=0) + 1)
    return np.concatenate(out)


def _sprt_tests(rule: Sprt, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(accepted H1 per completed test, samples per test) from one trace."""
    L = rule.run(x).statistic
    end = np.flatnonzero((L >= rule.a) | (L <= rule.b))
    return L[end] >= rule.a, np.diff(np.concatenate([[-1], end]))


def _rate(k: int, n: int, digits: int) -> tuple[str, str]:
    lo, hi = clopper_pearson(int(k), int(n))
    return f"{k / n:#.{digits}g}", f"[{lo:#.{digits}g}, {hi:#.{digits}g}]"


def _mean(x: np.ndarray, fmt: str) -> tuple[str, str]:
    m, lo, hi = _mean_ci(x)
    return f"{m:{fmt}}", f"[{lo:{fmt}}, {hi:{fmt}}]"


def rows() -> list[tuple[str, str, str, str]]:
    out = []

    rule = Chi2Test(dof=3, p_false_alarm=1e-2)
    x = np.random.default_rng(20).chisquare(3, 400_000)
    out.append(("chi2-v1, P_FA per sample, dof 3, N = 400 000", "0.01",
                *_rate(int(rule.run(x).alarm.sum()), x.size, 4)))

    k, n = 3, 5
    rule = Persistence(k, n, dof=2, p_false_alarm=5e-3)
    x = np.random.default_rng(30).chisquare(2, 500_000 + n)
    alarm = rule.run(x).alarm[n - 1::n]
    out.append((f"persistence-v1, 3 of 5, P_FA per sample (p = {rule.p_sample:.4f})", f"{rule.p_false_alarm:g}",
                *_rate(int(alarm.sum()), alarm.size, 4)))

    for delta, arl0, seed in ((1.0, 500.0, 40), (2.0, 300.0, 41)):
        rule = Cusum(sigma=1.0, shift=delta, arl0_samples=arl0)
        exact = cusum_arl_exact(rule.threshold, delta)
        rl = _run_lengths(rule, np.random.default_rng(seed), 4000, int(12 * arl0))
        out.append((f"cusum-v1, ARL0, delta = {delta:g}, h = {rule.threshold:.3f} (Siegmund {arl0:g})",
                    f"{exact:.1f} exact", *_mean(rl, ".1f")))

    rule = Cusum(sigma=1.0, shift=1.0, p_false_alarm=1e-3)
    exact = cusum_arl_exact(rule.threshold, 1.0, shift_fraction=1.0)
    rl = _run_lengths(rule, np.random.default_rng(42), 20_000, 80, shift=1.0)
    out.append(("cusum-v1, ARL1 (delay), delta = 1, ARL0 1000",
                f"{exact:.2f} exact (Siegmund {rule.arl1_samples():.2f})", *_mean(rl, ".2f")))

    rule = WindowGlr(sigma=1.0, w_max=30, arl0_samples=500.0)
    rl = _run_lengths(rule, np.random.default_rng(50), 4000, 6000)
    out.append((f"glr-v1, ARL0, w_max = 30, h = {rule.threshold:.3f}",
                f"{rule.arl0_samples:.0f} approx. (x {GLR_ARL_MEASURED_RATIO[30]:.2f} measured)", *_mean(rl, ".1f")))
    for shift, name in ((1.0, "1"), (-1.5, "-1.5")):
        rule = WindowGlr(sigma=1.0, w_max=30, arl0_samples=500.0)
        rl = _run_lengths(rule, np.random.default_rng(51), 4000, 200, shift=shift)
        out.append((f"glr-v1, delay, step {name} sigma (bound)", f"<= {rule.delay_bound_samples(shift):.2f}",
                    *_mean(rl, ".2f")))

    rule = Sprt(sigma=1.0, shift=1.0, alpha=0.05, beta=0.05)
    oc = rule.characteristic
    wald = sprt_operating_characteristic(rule.a, rule.b, 1.0, overshoot=False)
    h1, n_ = _sprt_tests(rule, np.random.default_rng(60).standard_normal(600_000))
    out.append(("sprt-v1, alpha' (nominal alpha = beta = 0.05, delta = 1)", f"{oc.alpha:.4g} corrected",
                *_rate(int(h1.sum()), h1.size, 4)))
    out.append(("sprt-v1, E0 N", f"{oc.asn0_samples:.3f} corrected (Wald {wald.asn0_samples:.2f})", *_mean(n_, ".3f")))
    rule = Sprt(sigma=2.0, shift=2.0, alpha=0.05, beta=0.05)  # delta = 1 in units of 2
    oc = rule.characteristic
    h1, n_ = _sprt_tests(rule, 2.0 * np.random.default_rng(61).standard_normal(600_000) + 2.0)
    out.append(("sprt-v1, beta' on the design step", f"{oc.beta:.4g} corrected", *_rate(int((~h1).sum()), h1.size, 4)))
    out.append(("sprt-v1, E1 N", f"{oc.asn1_samples:.3f} corrected", *_mean(n_, ".3f")))

    dirs = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
    for signed in (False, True):
        rule = AngleMagnitudeRule(dirs, ("a", "b", "c"), p_false_alarm=2e-2, angle_bound_rad=0.6, signed=signed)
        e = np.random.default_rng(70 + signed).standard_normal((400_000, 3))
        tr = rule.run(e)
        F = rule.signatures(e)
        which = "signed" if signed else "p = 0.02, dim 3"
        out.append((f"angle-magnitude-v1, P(alarm), {which}", f"{rule.p_false_alarm:g}",
                    *_rate(int(tr.alarm.sum()), e.shape[0], 4)))
        which = "signed" if signed else "bound 0.6 rad, unsigned"
        out.append((f"angle-magnitude-v1, P(F_b), {which}", f"{rule.p_false_signature:.4g}",
                    *_rate(int(F[:, 1].sum()), e.shape[0], 4)))

    sig = np.array([[1, 1, 0], [0, 1, 1], [1, 0, 1]])
    rule = SignatureIsolation(sig, ("pitch_gyro", "elevator", "alpha_vane"), dofs=(2, 2, 2), p_false_alarm=5e-2)
    x = np.random.default_rng(80).chisquare(2, (300_000, 3))
    tr = rule.run(x)
    out.append(("signature-isolation-v1, P(alarm), 3 x chi2(2) at p_i = 0.05", f"{rule.p_false_alarm:.5g}",
                *_rate(int(tr.alarm.sum()), x.shape[0], 5)))
    for j, f in enumerate(rule.hypotheses):
        out.append((f"signature-isolation-v1, P(isolate f), f = {f}", f"{rule.p_false_isolation[j]:.4g}",
                    *_rate(int((tr.isolation == j).sum()), x.shape[0], 4)))
    return out


def render() -> str:
    lines = ["| rule and quantity | documented | measured | 95 % interval |", "| --- | --- | --- | --- |"]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows()]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_decision_table.py", [("decision-white-noise", INPUTS, render)], sys.argv[1:]))

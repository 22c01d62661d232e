"""The measured numbers of the F-16 prose of docs/parity.md, as stamped generated blocks.

docs/make_parity_figures.py writes the tables of the F-16 and the DHC-6 studies; its DHC-6 part
flies for a long time and its blocks list the script itself as an input, so the numbers the prose
around the F-16 tables quotes are made here, in a script of their own, from their own seeds:

* ``parity-f16-eq28``: our eq. 28 (Algorithm 2, eq. 14) under the reading used, with the paper's
  eq. 28 beside it, the unrounded ZOH model's entries, the geometry of the fault vectors mu_bar
  (singular values of the stack, cos(mu_bar_2, mu_bar_5), |mu_bar_5|) and the parity study at
  full size (Algorithm 1 simulated, 200 000 windows per case);
* ``parity-f16-pca``: the eigenvalues of R_Z of a 30 s-run training, the n_r that
  ``suggest_residual_dimension`` picks with its log gap, the principal angles between the PCA
  residual space and the model-based [W; -H'W], the same training from 3 s runs (smallest
  model-space eigenvalue, alarm rate of fault 4), and the PCA study at full size;
* ``parity-robust-curve``: J*(p) of Lou's robustness curves (the synthetic clean + iced set,
  s = 2, the three sensor sets of ``figures/parity_robustness_curve.png``; no randomness);
* ``parity-dhc6-trims``: the DHC-6 study's models (``linearize_models(StudyConfig())``: JSBSim
  trims and linearizes, no flight): per eta the pitch trim, elevator angle and throttle, and the
  trim shift of every output at the largest eta; the full clean model's beta trim and its
  d nx / d beta.

The F-16 and synthetic parts are numpy on the paper's matrices; the DHC-6 part trims JSBSim.
Runs in well under a minute.

    python docs/make_parity_numbers.py [--print]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.linalg as sl

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.detectors.parity import parity_space, select_outputs  # noqa: E402
from fdi_sim.detectors.pca import estimate_fault_signatures, pca_train, suggest_residual_dimension  # noqa: E402
from fdi_sim.detectors.robust_parity import example_icing_models, robust_parity  # noqa: E402
from fdi_sim.detectors.stochastic_parity import (  # noqa: E402
    incorrect_diagnosis_matrix,
    isolation_rates,
    threshold_by_simulation,
)  # noqa: E402
from fdi_sim.papers.hagenblad_f16 import (  # noqa: E402
    PAPER_ISOLATION_PARITY,
    PAPER_ISOLATION_PCA,
    PAPER_P_EQ28,
    PAPER_READING,
    PAPER_THRESHOLD_PARITY,
    PAPER_THRESHOLD_PCA,
    f16_design,
    f16_model,
    f16_parity_study,
    f16_pca_study,
    f16_reading,
    simulate_f16,
)
from fdi_sim.papers.dhc6_icing_flights import StudyConfig, linearize_models  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "parity.md"
COMMAND = "python docs/make_parity_numbers.py"
#: what the F-16 numbers run through: the paper's model and reading, the parity and PCA designs,
#: the simulated threshold (``threshold_by_simulation``) and Algorithm 1's isolation rule
F16_INPUTS = ("fdi_sim/papers/hagenblad_f16.py", "fdi_sim/detectors/parity.py", "fdi_sim/detectors/stochastic_parity.py",
              "fdi_sim/detectors/pca.py", "fdi_sim/detectors/window_detector.py", "fdi_sim/detectors/base.py",
              "fdi_sim/decision/chi2.py", "fdi_sim/decision/base.py", "fdi_sim/linear/model.py", "fdi_sim/errors.py",
              "docs/make_parity_numbers.py")
ROBUST_INPUTS = ("fdi_sim/detectors/robust_parity.py", "fdi_sim/detectors/parity.py",
                 "fdi_sim/detectors/window_detector.py", "fdi_sim/detectors/base.py", "fdi_sim/decision/chi2.py",
                 "fdi_sim/decision/base.py", "fdi_sim/linear/model.py", "fdi_sim/errors.py",
                 "docs/make_parity_numbers.py", "docs/make_parity_figures.py")
#: the DHC-6 models: the study's module, JSBSim trims and the linearizer on the icing overlay
DHC6_INPUTS = ("fdi_sim/papers/dhc6_icing_flights.py", "aircraft/DHC6", "fdi_sim/aircraft", "fdi_sim/linear",
               "fdi_sim/operating_point.py", "fdi_sim/isa.py", "fdi_sim/units.py", "fdi_sim/errors.py",
               "docs/make_parity_numbers.py")
#: seeds of this script's own draws (independent of docs/make_parity_figures.py's stream)
SEED_PARITY, SEED_PCA = 2028, 2029
#: windows per case of the full-size studies, and training windows of the PCA
N_WINDOWS, N_TRAIN = 200_000, 100_000
#: windows per training run: 100 (30 s at L = 3, dt 0.1 s; ``simulate_f16``'s default) and 10 (3 s)
LONG_RUN, SHORT_RUN = 100, 10
WINDOW_L, N_RESIDUALS = 3, 4
READING = f16_reading(*PAPER_READING)
FAULTS = ("f1", "f2", "f3", "f4", "f5", "f6")


def _g(x: float) -> str:
    """``x`` with 2 significant digits, as 490, 0.026 or 1.6e-6."""
    if abs(x) >= 100:
        return f"{x:.0f}"
    if abs(x) >= 1e-3:
        return f"{x:.2g}"
    m, ex = f"{x:.1e}".split("e")
    return f"{m}e{int(ex)}"


def _row(v) -> str:
    return ", ".join(f"{round(float(x), 3):g}" for x in v)


def _se(p: float, n: int) -> float:
    """Binomial standard error of a rate ``p`` over ``n`` windows."""
    return float(np.sqrt(p * (1 - p) / n))


def eq28_block() -> str:
    """Our eq. 28 against the paper's, the unrounded model, the fault vectors, Algorithm 1 at full size."""
    design = f16_design(READING)
    P = incorrect_diagnosis_matrix(design, READING.magnitudes).P
    Pe = incorrect_diagnosis_matrix(f16_design(READING, exact=True), READING.magnitudes).P
    printed, zoh = f16_model(), f16_model(exact=True)
    # entries where the unrounded ZOH and the printed eq. 23-24 differ by more than the printed rounding
    off = [f"{M}[{i},{j}] {getattr(zoh, M)[i, j]:.5f} vs {getattr(printed, M)[i, j]:.4f}" for M in ("A", "B")
           for i, j in zip(*np.nonzero(np.abs(getattr(zoh, M) - getattr(printed, M)) > 0.5e-4 + 1e-12))]
    mu = design.mu_bar
    sv = np.linalg.svd(mu, compute_uv=False)
    cos25 = mu[1] @ mu[4] / (np.linalg.norm(mu[1]) * np.linalg.norm(mu[4]))
    rng = np.random.default_rng(SEED_PARITY)
    res = f16_parity_study(READING, N_WINDOWS, rng)
    noisy = f16_reading("all-states", "unit")
    P_noisy = incorrect_diagnosis_matrix(f16_design(noisy), noisy.magnitudes).P
    # designed for R only (the reading used) but simulated with 1e-4 noise on every state
    w = simulate_f16(noisy, None, N_WINDOWS, rng)
    r = design.residual(w.Y, w.U)
    th_mis = threshold_by_simulation(np.einsum("ij,ij->i", r, r), 0.05)
    lines = ["Eq. 28, P(diagnosis i | fault j), ours under the reading used and the paper's (ours / paper; "
             "fault 4 has a zero row and column in both):", "",
             "| diagnosis | " + " | ".join(FAULTS) + " |", "|---" * 7 + "|"]
    for i in range(6):
        cells = [f"{P[i, j]:.4f} / {PAPER_P_EQ28[i, j]:.4f}" if (P[i, j] or PAPER_P_EQ28[i, j]) else "0"
                 for j in range(6)]
        lines.append(f"| d{i + 1} | " + " | ".join(cells) + " |")
    p55, n = res.p_correct[4], res.n_windows
    lines += ["",
              "| quantity | ours | paper |", "|---|---|---|",
              f"| P(5\\|5), eq. 14 | {P[4, 4]:.4f} | {PAPER_P_EQ28[4, 4]:.4f} (eq. 28) |",
              f"| P(3\\|3), eq. 14 | {P[2, 2]:.4f} | {PAPER_P_EQ28[2, 2]:.4f} (eq. 28) |",
              f"| P(5\\|5), Algorithm 1 simulated | {p55:.3f} ± {_se(p55, n):.3f} | {PAPER_ISOLATION_PARITY[4]:g} |",
              f"| P(3\\|3), Algorithm 1 simulated | {res.p_correct[2]:.3f} | {PAPER_ISOLATION_PARITY[2]:g} |",
              f"| P(correct) f1..f6, Algorithm 1 simulated | {_row(res.p_correct)} | {_row(PAPER_ISOLATION_PARITY)} |",
              f"| h (5 % FA) [95 % CI] | {res.threshold.h:.3f} [{res.threshold.h_low:.3f}, {res.threshold.h_high:.3f}] | {PAPER_THRESHOLD_PARITY:g} |",
              f"| P(2\\|5), P(5\\|6): printed / unrounded ZOH model | {P[1, 4]:.4f} / {Pe[1, 4]:.4f}, "
              f"{P[4, 5]:.4f} / {Pe[4, 5]:.4f} | {PAPER_P_EQ28[1, 4]:.4f}, {PAPER_P_EQ28[4, 5]:.4f} |",
              f"| entries of the unrounded ZOH (vs printed eq. 23-24) off by more than the 4th decimal's rounding | "
              f"{'; '.join(off) or 'none'} | |",
              f"| P(1\\|3), P(5\\|6), eq. 14 with B_v = I_5, Q = 1e-4 (unit sizes) | {P_noisy[0, 2]:.2f}, "
              f"{P_noisy[4, 5]:.2f} | {PAPER_P_EQ28[0, 2]:.4f}, {PAPER_P_EQ28[4, 5]:.4f} |",
              f"| h (5 % FA) designed for R only, simulated with Q = 1e-4 on every state [95 % CI] | "
              f"{th_mis.h:.0f} [{th_mis.h_low:.0f}, {th_mis.h_high:.0f}] | {PAPER_THRESHOLD_PARITY:g} |",
              f"| singular values of the stacked mu_bar | {', '.join(f'{s:.4g}' for s in sv[:3])}, "
              f"{sv[3] / sv[0]:.0e} x the first | |",
              f"| cos(mu_bar_2, mu_bar_5), \\|mu_bar_5\\| | {cos25:.4f}, {np.linalg.norm(mu[4]):.2f} | |",
              "",
              f"Algorithm 1: {n} simulated windows per case (threshold and each fault; also the mismatched "
              f"threshold), seed {SEED_PARITY}; "
              "± one binomial standard error; the paper's column is its sec. 4 (h, simulated P(correct)) and eq. 28."]
    return "\n".join(lines)


def _short_run_pca(rng: np.random.Generator):
    """PCA trained on 3 s runs (10 windows each), fault signatures likewise, and tested on 3 s runs
    as in ``f16_pca_study``. Returns the model, the signatures, the 5 % threshold, the alarm rate of
    fault 4 and the rate at which its windows are isolated as fault 4."""
    pca = pca_train(simulate_f16(READING, None, N_TRAIN, rng, WINDOW_L, SHORT_RUN).Z, N_RESIDUALS)
    sig = estimate_fault_signatures(
        pca, [simulate_f16(READING, j, N_TRAIN, rng, WINDOW_L, SHORT_RUN).Z for j in range(6)])
    detectable = np.linalg.norm(sig, axis=1) > 4.0 * np.sqrt(N_RESIDUALS / N_TRAIN)  # f16_pca_study's rule
    r0 = pca.normalized_residual(simulate_f16(READING, None, N_WINDOWS, rng, WINDOW_L, SHORT_RUN).Z)
    h = threshold_by_simulation(np.einsum("ij,ij->i", r0, r0), 0.05).h
    r4 = pca.normalized_residual(simulate_f16(READING, 3, N_WINDOWS, rng, WINDOW_L, SHORT_RUN).Z)
    alarm = float(np.mean(np.einsum("ij,ij->i", r4, r4) > h))
    return pca, sig, h, alarm, float(isolation_rates(r4, sig, detectable, h)[3])


def pca_block() -> str:
    """Eigenvalues of R_Z and the n_r choice, the residual space against the parity space, short
    training runs, and the PCA study at full size."""
    rng = np.random.default_rng(SEED_PCA)
    pca = pca_train(simulate_f16(READING, None, N_TRAIN, rng, WINDOW_L, LONG_RUN).Z, N_RESIDUALS)
    ev = pca.eigenvalues
    n_r = suggest_residual_dimension(ev)
    k = ev.size - n_r  # model-space dimension: the gap is between ev[k - 1] and ev[k]
    gap_dec = float(np.log10(ev[k - 1] / ev[k]))
    ang_rad = sl.subspace_angles(pca.W, parity_space(f16_model(), WINDOW_L - 1).relations())
    short, short_sig, h_short, alarm4, iso4 = _short_run_pca(rng)
    res = f16_pca_study(READING, N_TRAIN, N_WINDOWS, rng, WINDOW_L, n_residuals=N_RESIDUALS)
    lines = ["| quantity | 30 s training runs | 3 s training runs |", "|---|---|---|",
             f"| eigenvalues of R_Z, descending | {', '.join(_g(e) for e in ev)} | "
             f"{', '.join(_g(e) for e in short.eigenvalues)} |",
             f"| n_r by `suggest_residual_dimension` (log gap, decades) | {n_r} ({gap_dec:.1f}) | "
             f"{suggest_residual_dimension(short.eigenvalues)} |",
             f"| smallest model-space eigenvalue (the {k}th) | {_g(ev[k - 1])} | {_g(short.eigenvalues[k - 1])} |",
             f"| largest principal angle to [W; -H'W] [rad] | {ang_rad.max():.1e} | "
             f"{sl.subspace_angles(short.W, parity_space(f16_model(), WINDOW_L - 1).relations()).max():.1e} |",
             f"| \\|mu_bar_4\\| estimated (eq. 22) | {np.linalg.norm(f16_sig4(pca, rng)):.3f} | "
             f"{np.linalg.norm(short_sig[3]):.3f} |",
             f"| h (5 % FA) | {res.threshold.h:.2f} | {h_short:.2f} |",
             f"| fault 4: alarm rate / isolated as fault 4 | {res.p_correct[3]:.3f} / - (signature below the noise) | "
             f"{alarm4:.3f} / {iso4:.3f} |",
             "",
             "| PCA, 30 s runs | P(correct) f1..f6 | h (5 % FA) |", "|---|---|---|",
             f"| ours | {_row(res.p_correct)} | {res.threshold.h:.2f} |",
             f"| paper | {_row(PAPER_ISOLATION_PCA)} | {PAPER_THRESHOLD_PCA:g} |",
             "",
             f"L = {WINDOW_L}, n_r = {N_RESIDUALS}, {N_TRAIN} training windows per case (fault-free and each "
             f"fault's signature), {N_WINDOWS} test windows per case, each column from runs of its length (3 s: "
             f"{SHORT_RUN} windows, 30 s: {LONG_RUN}); seed {SEED_PCA}. A fault counts as detectable when its "
             "estimated signature exceeds 4 standard errors (`f16_pca_study`'s rule); fault 4's alarm rate at "
             "30 s is the false-alarm rate."]
    return "\n".join(lines)


def f16_sig4(pca, rng: np.random.Generator) -> np.ndarray:
    """Eq. 22 signature of fault 4 (altitude sensor bias) under ``pca``, from 30 s runs."""
    return estimate_fault_signatures(pca, [simulate_f16(READING, 3, N_TRAIN, rng, WINDOW_L, LONG_RUN).Z])[0]


#: the noise of the robustness curves: the figure's own (one definition; its script only defines at import)
from make_parity_figures import NOISE  # noqa: E402
SENSOR_SETS = {"all 5 sensors": None, "no az": ("u_mps", "alpha_rad", "q_radps", "theta_rad"),
               "no alpha, no az": ("u_mps", "q_radps", "theta_rad")}


def robust_curve_block() -> str:
    """J*(p), p = 1..6, for the three sensor sets, inputs as noise (eq. 35) and known (eq. 41)."""
    ms = example_icing_models((0.0, 0.05, 0.1))
    lines = ["| inputs | sensors | J*(1) … J*(6) [noise units] |", "|---|---|---|"]
    for mode, label in (("noise", "as noise (eq. 35)"), ("known", "known (eq. 41)")):
        for name, outs in SENSOR_SETS.items():
            mm = ms if outs is None else [select_outputs(m, outs) for m in ms]
            idx = [ms[0].output_names.index(o) for o in mm[0].output_names]
            noise = {**NOISE, "measurement_sqrt": NOISE["measurement_sqrt"][np.ix_(idx, idx)]}
            d = robust_parity(mm, 2, n_relations=1, state_sqrt="stationary", inputs=mode,
                              output_scale=np.diag(noise["measurement_sqrt"]),
                              input_scale=[0.05, 0.1] if mode == "known" else None, **noise)
            lines.append(f"| {label} | {name} | {', '.join(f'{c:.3g}' for c in d.curve()[1:7])} |")
    lines += ["", "Synthetic clean + iced (eta 0.05, 0.1) set (`example_icing_models`), s = 2, stationary state "
              "scaling, noise-unit scaling; the curves of `figures/parity_robustness_curve.png`."]
    return "\n".join(lines)


def dhc6_trims_block() -> str:
    """Trims of the DHC-6 study's models per eta, and the trim shift the ``robust+trim`` set nulls."""
    cfg = StudyConfig()
    ms = linearize_models(cfg)
    clean = ms.lon[0]
    lines = ["| eta | pitch trim [-] | elevator [rad] | throttle [-] |", "|---|---|---|---|"]
    for eta, pt, m in zip(ms.etas, ms.pitch_trim_cmd_norm, ms.lon):
        lines.append(f"| {eta:g} | {pt:.4f} | {m.u0[0]:.4f} | {m.u0[1]:.3f} |")
    last = ms.lon[-1]
    du = last.u0[:2] - clean.u0[:2]
    dy = last.y0 - clean.y0
    full = ms.full[0]
    beta = full.state_names.index("beta_rad")
    nx = full.output_names.index("nx_g")
    lines += ["", f"Trim shift at eta {ms.etas[-1]:g} (what `robust+trim` uses): elevator {du[0]:+.4f} rad "
              f"({np.degrees(du[0]):+.2f} deg), throttle {du[1]:+.3f}; outputs "
              + ", ".join(f"{n} {v:+.2g}" if abs(v) > 1e-6 else f"{n} 0" for n, v in zip(clean.output_names, dy))
              + " (0: below 1e-6).",
              "",
              f"Clean model: beta trim {np.degrees(full.x0[beta]):.2f} deg; d nx_g / d beta "
              f"{full.C[nx, beta]:.2f} g/rad. {cfg.h_ft:g} ft / {cfg.vc_kts:g} KCAS / flaps {cfg.flaps_deg:g}, "
              "running-engine trim on the icing overlay (`linearize_models(StudyConfig())`)."]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, COMMAND, [("parity-f16-eq28", F16_INPUTS, eq28_block),
                                              ("parity-f16-pca", F16_INPUTS, pca_block),
                                              ("parity-robust-curve", ROBUST_INPUTS, robust_curve_block),
                                              ("parity-dhc6-trims", DHC6_INPUTS, dhc6_trims_block)],
                                sys.argv[1:]))

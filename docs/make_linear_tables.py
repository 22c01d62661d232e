"""The reduced step models and the F-16 roll root against FGLinearization, as the generated blocks
``reduced-models`` and ``fglin-roll-root`` of docs/linear.md.

Real JSBSim, no randomness. ``reduced-models``: as ``tests/linear/test_reduce.py``, each
aircraft linearized at 5000 ft (F-16 420 KTAS, DHC-6 120 KCAS), the grid file's default doublets
flown for 10 s, the step model (``discretize(..., method="step")``) balanced-truncated by
``reduce`` at its default tolerance and to 10 states (scales: the doublet amplitudes and the
response RMS); the worst per-output normalized RMS error over the doublets (the DHC-6 without its
throttle run). ``fglin-roll-root``: as ``tests/linear/test_fglin_roll_root.py``, the F-16 trimmed
at 10 000 ft / 400 KTAS, the eigenvalues of the longitudinal [Vt alpha q theta] and lateral
[beta p r phi] 4 x 4 blocks of A from JSBSim's FGLinearization, its replica with one and with
two to five trim-status passes, and our central differences; under the table, FGLinearization's
and the settled replica's d beta-dot / d r, and the roll root of the step model (JSBSim's own
120 Hz step, ``discretize(..., method="step")``) mapped back by ln(z)/dt (``equivalent_poles``),
the referee both are compared with. ``iced-modes``: as ``tests/linear/test_iced_grid.py``, the
DHC-6 with the icing overlay trimmed and linearized at 5000 ft / 100 KCAS for eta 0, 0.05, 0.1
(``linearize_grid``, no validation): the short period's and the Dutch roll's natural frequencies
and the roll root. ``fglin-dhc6``: as ``test_fglinearization_is_wrong_for_the_dhc6_propeller``,
FGLinearization on the DHC-6 right after JSBSim's own trim (5000 ft / 120 KCAS; it does not
converge after the running trim): its propeller-speed entries and short period against ours at
the running trim. Runs in seconds.

    python docs/make_linear_tables.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.aircraft import Aircraft, trim  # noqa: E402
from fdi_sim.aircraft.fglin_replica import X_NAMES, fglin_replica  # noqa: E402
from fdi_sim.aircraft.linearize_fglin import fglinearization  # noqa: E402
from fdi_sim.linear.grid import default_grid_path, load_grid, parse_grid_spec  # noqa: E402
from fdi_sim.linear.linearize import linearize, linearize_grid  # noqa: E402
from fdi_sim.linear.step import equivalent_poles  # noqa: E402
from fdi_sim.linear.transform import discretize, reduce  # noqa: E402
from fdi_sim.linear.validate import compare, default_doublets, fly_doublets  # noqa: E402
from fdi_sim.operating_point import OperatingPoint  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "linear.md"
COMMAND = "python docs/make_linear_tables.py"
COMMON = ("fdi_sim/aircraft", "fdi_sim/linear", "fdi_sim/operating_point.py", "fdi_sim/isa.py",
          "docs/make_linear_tables.py")
REDUCED_INPUTS = ("aircraft/f16", "aircraft/DHC6") + COMMON
FGLIN_INPUTS = ("aircraft/f16",) + COMMON
ICED_INPUTS = ("aircraft/DHC6",) + COMMON
DHC6_FGLIN_INPUTS = ("aircraft/DHC6",) + COMMON
DHC6_OP = OperatingPoint("DHC6", 5000.0, vc_kts=120.0)
REDUCED_POINTS = (("F-16 5000 ft / 420 KTAS", OperatingPoint("f16", 5000.0, vt_kts=420.0), ()),
                  ("DHC-6 5000 ft / 120 KCAS (without the throttle run)", OperatingPoint("DHC6", 5000.0, vc_kts=120.0),
                   ("throttle_cmd_norm",)))
F16_OP = OperatingPoint("f16", 10000.0, vt_kts=400.0)
SETTLED = 5  # trim-status passes that settle the F-16 FBW (tests/linear/test_fglin_roll_root.py)
#: the iced point of JSBSIM_NOTES 5.3 and tests/linear/test_iced_grid.py
ICED_SPEC = "h_ft=5000;vc_kts=100;icing_eta=0,0.05,0.1"


def reduced_table() -> str:
    lines = ["| model | states | reduced | worst doublet error, full -> reduced |", "|---|---|---|---|"]
    ten = []
    for label, op, without in REDUCED_POINTS:
        ac = Aircraft(op.aircraft)
        lp = linearize(ac, op, check_fglin=False)
        m = lp.model
        g = load_grid(default_grid_path(op.aircraft), op.aircraft)
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, g.validation), m.output_names, 10.0)
        full = discretize(m, ac.dt_s, method="step")
        su = np.array([g.validation.amplitudes[n] for n in m.input_names])
        sy = np.sqrt(np.mean(runs.dy ** 2, axis=(0, 1)))
        red = reduce(full, input_scale=su, output_scale=sy)

        def err(md) -> np.ndarray:
            v = compare(md, runs)
            return v.nrmse_without(without) if without else v.nrmse

        ef, er = err(full), err(red)
        i = int(np.argmax(ef))
        worst_r = m.output_names[int(np.argmax(er))]
        red_txt = f"{er[i]:.2%}" if worst_r == m.output_names[i] else f"{worst_r} {er.max():.2%}"
        lines.append(f"| {label} | {full.n_states} | {red.n_states} | {m.output_names[i]} {ef[i]:.2%} -> {red_txt} |"
                     .replace("%", " %"))
        e10 = err(reduce(full, 10, input_scale=su, output_scale=sy))
        ten.append(f"{label.split(' ')[0]} {m.output_names[int(np.argmax(e10))]} {e10.max():.0%}".replace("%", " %"))
    lines += ["", "Reduced to 10 states instead, the worst doublet error: " + ", ".join(ten) + "."]
    return "\n".join(lines)


def _eigs(A: np.ndarray, idx: list[int]) -> np.ndarray:
    return np.sort_complex(np.linalg.eigvals(A[np.ix_(idx, idx)]))


def _modes(A: np.ndarray, lon: list[int], lat: list[int]) -> list[str]:
    """Short period (two real roots), phugoid (pair), Dutch roll (pair), roll, spiral (the faster
    and the slower real lateral root)."""
    lo, la = _eigs(A, lon), _eigs(A, lat)
    lo_real = sorted((z.real for z in lo if abs(z.imag) < 1e-9), key=abs, reverse=True)
    lo_pair = [z for z in lo if z.imag > 1e-9]
    la_real = sorted((z.real for z in la if abs(z.imag) < 1e-9), key=abs, reverse=True)
    la_pair = [z for z in la if z.imag > 1e-9]
    if not (len(lo_real) == 2 and len(lo_pair) == 1 and len(la_real) == 2 and len(la_pair) == 1):
        raise RuntimeError(f"unexpected eigenstructure: {lo}, {la}")
    ph, dr = lo_pair[0], la_pair[0]
    return [f"{lo_real[0]:.3f}, {lo_real[1]:.3f}", f"{ph.real:.4f} ± {ph.imag:.4f}j", f"{dr.real:.2f} ± {dr.imag:.3f}j",
            f"{la_real[0]:.4f}", f"{la_real[1]:.4f}"]


def _trimmed() -> Aircraft:
    ac = Aircraft("f16")
    trim(ac, F16_OP)
    return ac


def _nearest(z: np.ndarray, target: float) -> complex:
    return complex(z[np.argmin(np.abs(z - target))])


def fglin_table() -> str:
    lat = [X_NAMES.index(s) for s in ("Beta", "P", "R", "Phi")]
    lon = [X_NAMES.index(s) for s in ("Vt", "Alpha", "Q", "Theta")]
    jl = fglinearization(_trimmed())
    one = fglin_replica(_trimmed())
    passes = {k: fglin_replica(_trimmed(), n_runs=k) for k in range(2, SETTLED + 1)}
    settled = passes[SETTLED]
    lp = linearize(Aircraft("f16"), F16_OP, check_fglin=False)
    n = lp.model.state_names
    ours = _modes(lp.model.A, [n.index(s) for s in ("vt_fps", "alpha_rad", "q_radps", "theta_rad")],
                  [n.index(s) for s in ("beta_rad", "p_radps", "r_radps", "phi_rad")])
    a, b = _modes(jl.A, lon, lat), _modes(one.A, lon, lat)
    same = "= replica, 1 pass" if a == b else f"replica, 1 pass: {', '.join(b)}"
    rows = [(f"FGLinearization ({same})", a)]
    rows += [(f"replica, {k} passes", _modes(r.A, lon, lat)) for k, r in passes.items()]
    rows.append(("ours", ours))
    lines = ["| 10 kft / 400 KTAS | short period | phugoid | Dutch roll | roll | spiral |", "|---|---|---|---|---|---|"]
    lines += [f"| {k} | " + " | ".join(v) + " |" for k, v in rows]
    # the referee: the roll pole of JSBSim's own step, ln(z)/dt, nearest our roll root
    roll_ours = float(ours[3])
    roll_fg = float(a[3])
    sim = _nearest(equivalent_poles(discretize(lp.model, method="step")), roll_ours).real
    b_idx, r_idx = X_NAMES.index("Beta"), X_NAMES.index("R")
    lines += ["", f"Roll root of the step model (JSBSim's 120 Hz step) mapped back by ln(z)/dt: {sim:.4f} 1/s; ours is "
              f"{abs(roll_ours - sim) / abs(sim):.2%} off it, FGLinearization's {abs(roll_fg - sim) / abs(sim):.2%}. "
              f"FGLinearization's roll root is {abs(roll_fg - roll_ours) / abs(roll_ours):.1%} from ours. "
              f"d beta-dot / d r: FGLinearization {jl.A[b_idx, r_idx]:.3f}, replica with {SETTLED} passes "
              f"{settled.A[b_idx, r_idx]:.3f}."]
    return "\n".join(lines).replace("%", " %")


def iced_table() -> str:
    """Short period, Dutch roll and roll root of the iced DHC-6 at one point, per eta."""
    s = linearize_grid(parse_grid_spec(ICED_SPEC, "DHC6"), validate=False)
    lines = ["| DHC-6 5000 ft / 100 KCAS | short period wn [rad/s] | Dutch roll wn [rad/s] | roll root [1/s] |",
             "|---|---|---|---|"]
    for p in s.points:
        if p.status != "ok":
            lines.append(f"| eta {p.op.icing_eta:g} | {p.status}: {p.reason} | | |")
            continue
        m = {x["name"]: x for x in p.info["modes"]}
        lines.append(f"| eta {p.op.icing_eta:g} | {m['short period']['wn_radps']:.2f} | "
                     f"{m['dutch roll']['wn_radps']:.2f} | {m['roll']['re']:.2f} |")
    lines += ["", "Running-engine trim with the icing overlay, our central differences (`linearize_grid`)."]
    return "\n".join(lines)


def _short_period(A: np.ndarray, idx: list[int]) -> complex:
    """The fastest root of the longitudinal 4 x 4 block, upper half plane."""
    z = max(np.linalg.eigvals(A[np.ix_(idx, idx)]), key=abs)
    return complex(z.real, abs(z.imag))


def dhc6_fglin_table() -> str:
    """FGLinearization's propeller rows on the DHC-6 against our model's."""
    ac = Aircraft("DHC6")
    f = ac.fdm
    f["ic/h-sl-ft"], f["ic/vc-kts"], f["ic/gamma-deg"], f["ic/psi-true-deg"] = 5000.0, 120.0, 0.0, 0.0
    f["propulsion/set-running"] = -1
    f.run_ic()
    f.do_trim(1)  # JSBSim's own trim: after the running trim FGLinearization does not converge
    jl = fglinearization(ac, allow_propeller=True)
    i, j = jl.x_names.index("Rpm0"), jl.u_names.index("ThtlCmd")
    fg_sp = _short_period(jl.A, [jl.x_names.index(n) for n in ("Vt", "Alpha", "Q", "Theta")])
    m = linearize(Aircraft("DHC6"), DHC6_OP).model
    n = m.state_names
    r, n1, thr = n.index("prop_rpm"), n.index("n1_pct"), m.input_names.index("throttle_cmd_norm")
    sp = _short_period(m.A, [n.index(s) for s in ("vt_fps", "alpha_rad", "q_radps", "theta_rad")])
    lines = ["| DHC-6 5000 ft / 120 KCAS | d rpm-dot / d throttle [rpm/s] | d rpm-dot / d rpm [1/s] | "
             "d rpm-dot / d N1 [rpm/s/%] | d N1-dot / d throttle [%/s] | short period [1/s] |", "|---|---|---|---|---|---|",
             f"| FGLinearization (after JSBSim's trim) | {jl.B[i, j]:.0f} | {jl.A[i, i]:+.3f} | - | - | "
             f"{fg_sp.real:.3f} ± {fg_sp.imag:.3f}j |",
             f"| ours (running trim) | {m.B[r, thr]:.3g} | {m.A[r, r]:+.3f} | {m.A[r, n1]:.3g} | {m.B[n1, thr]:.3g} | "
             f"{sp.real:.3f} ± {sp.imag:.3f}j |",
             "", f"Short periods {abs(sp - fg_sp) / abs(fg_sp):.2%} apart.".replace("%", " %")]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, COMMAND, [("reduced-models", REDUCED_INPUTS, reduced_table),
                                              ("fglin-roll-root", FGLIN_INPUTS, fglin_table),
                                              ("fglin-dhc6", DHC6_FGLIN_INPUTS, dhc6_fglin_table),
                                              ("iced-modes", ICED_INPUTS, iced_table)], sys.argv[1:]))

"""Figures and numbers for docs/linear.md (linearizer: pole maps, doublet validation examples).

Run from the repository root:  .venv/bin/python docs/make_linear_figures.py   (about a minute)
Writes docs/figures/linear_*.png and prints every number quoted in docs/linear.md that is not
in the reports of ``fdi-sim linearize``.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fdi_sim.aircraft import Aircraft  # noqa: E402
from fdi_sim.linear.grid import default_grid_path, load_grid, resolve_grid  # noqa: E402
from fdi_sim.linear.linearize import linearize, linearize_grid  # noqa: E402
from fdi_sim.linear.transform import discretize  # noqa: E402
from fdi_sim.linear.validate import DoubletSpec, compare, fly_doublets  # noqa: E402
from fdi_sim.operating_point import OperatingPoint  # noqa: E402
from fdi_sim.review.linear_figures import pole_map  # noqa: E402
from fdi_sim.units import DEG_PER_RAD  # noqa: E402

OUT = Path(__file__).resolve().parent / "figures"


def pole_maps() -> None:
    """The pole map of each shipped grid (modes only: no validation)."""
    for name, grid in (("f16", load_grid(default_grid_path("f16"), "f16")),
                       ("dhc6", load_grid(default_grid_path("DHC6"), "DHC6")),
                       ("dhc6_iced", resolve_grid("iced", "DHC6"))):
        s = linearize_grid(grid, validate=False, check_fglin=False)
        pole_map(s, OUT / f"linear_poles_{name}.png")
        print(f"{name}: {len(s.ok_points)}/{len(s.points)} points trimmed")


def _one(ax, t, y_nl, fits: dict[str, np.ndarray], scale: float, unit: str, title: str) -> None:
    ax.plot(t, y_nl * scale, "k", lw=2.2, label="JSBSim")
    for (label, y), style in zip(fits.items(), ("--", ":", "-.")):
        ax.plot(t, y * scale, style, lw=1.6, label=label)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(unit)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def validation_examples() -> None:
    """Three doublets where the choice of model or amplitude decides the error."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), layout="constrained")
    # (a) F-16: the FBW's one-pass sensor delay and AB3, held by the step model only
    ac = Aircraft("f16")
    lp = linearize(ac, OperatingPoint("f16", 5000.0, vt_kts=420.0), check_fglin=False)
    m = lp.model
    runs = fly_doublets(ac, lp.trim_state, [DoubletSpec("rudder_cmd_norm", 0.01)], m.output_names, 4.0)
    i = m.output_names.index("r_radps")
    fits = {}
    for meth in ("zoh", "step"):
        v = compare(discretize(m, ac.dt_s, method=meth), runs)
        fits[f"{meth} ({v.nrmse_pair[0, i]:.1%})"] = v.y_lin[0, :, i]
        print(f"F-16 5000 ft / 420 KTAS rudder doublet, r_radps error: {meth} {v.nrmse_pair[0, i]:.2%}")
    t = np.arange(runs.dy.shape[1]) * ac.dt_s
    _one(axes[0], t, runs.dy[0, :, i], fits, DEG_PER_RAD, "r [deg/s]",
         "F-16 5000 ft / 420 KTAS, rudder doublet 0.01")
    # (b) DHC-6 132 KCAS: the aileron doublet across the left aileron's kink, per unit amplitude
    ac = Aircraft("DHC6")
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=132.0))
    m = lp.model
    md = discretize(m, ac.dt_s, method="step")
    i = m.output_names.index("phi_rad")
    ax = axes[1]
    for a, style in ((0.004, "tab:red"), (0.001, "tab:blue")):
        runs = fly_doublets(ac, lp.trim_state, [DoubletSpec("aileron_cmd_norm", a)], m.output_names, 10.0)
        v = compare(md, runs, engine_lag=True)
        t = np.arange(runs.dy.shape[1]) * ac.dt_s
        ax.plot(t, runs.dy[0, :, i] / a, color=style, lw=2.2, label=f"JSBSim, {a:g}")
        ax.plot(t, v.y_lin[0, :, i] / a, "--", color=style, lw=1.4, label=f"step model, {a:g} ({v.nrmse_pair[0, i]:.1%})")
        print(f"DHC-6 5000 ft / 132 KCAS aileron doublet {a:g}: phi_rad error {v.nrmse_pair[0, i]:.2%}")
    print(f"  trim aileron command {lp.trim['aileron_cmd_norm']:.4f}")
    ax.set_title("DHC-6 5000 ft / 132 KCAS, aileron doublet: phi per unit command\n"
                 f"trim command {lp.trim['aileron_cmd_norm']:.4f}, kink at zero left-aileron deflection", fontsize=10)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("phi / amplitude [rad]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    # (c) DHC-6 120 KCAS: the throttle doublet and FGTurboProp's asymmetric N1 lag
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=120.0))
    m = lp.model
    md = discretize(m, ac.dt_s, method="step")
    runs = fly_doublets(ac, lp.trim_state, [DoubletSpec("throttle_cmd_norm", 0.02)], m.output_names, 10.0)
    i = m.output_names.index("h_ft")
    fits = {}
    for lag, label in ((False, "step model"), (True, "step model + identified N1 lag")):
        v = compare(md, runs, engine_lag=lag)
        fits[f"{label} ({v.nrmse_pair[0, i]:.1%})"] = v.y_lin[0, :, i]
        print(f"DHC-6 5000 ft / 120 KCAS throttle doublet 0.02, h_ft error: {label} {v.nrmse_pair[0, i]:.2%}")
    print(f"  N1 lag: {runs.engine_lag}")
    t = np.arange(runs.dy.shape[1]) * ac.dt_s
    _one(axes[2], t, runs.dy[0, :, i], fits, 1.0, "h - h_trim [ft]",
         "DHC-6 5000 ft / 120 KCAS, throttle doublet 0.02\nN1 lag 1 s up, 2.4 s down")
    fig.savefig(OUT / "linear_validation_examples.png", dpi=110)


if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    pole_maps()
    validation_examples()

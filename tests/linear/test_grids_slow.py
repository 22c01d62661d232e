"""The full default grids with the 10 s doublet validation at every point (``pytest -m slow``).

Measured on the development machine (AB3 simulation; 2 cores shared with other jobs): F-16 20
points in about 40 s, DHC-6 30 points in about 65 s (``fdi-sim linearize <aircraft>``).

The bar is judged on the step model (``discretize(..., method="step")``: the discrete model of
JSBSim's own step, :mod:`fdi_sim.linear.step`). ZOH is validated too, for the detectors' default.

F-16: 20/20 points below 5 % on every output with the step model (largest h_ft 1.6 % at 5000 ft /
420 KTAS); with ZOH 17/20 (r_radps up to 5.7 %: the FBW reads its sensors one pass late and AB3
overshoots after each doublet step, neither of which a continuous model holds).

DHC-6: no linear model passes the throttle doublet anywhere: FGTurboProp moves N1 with 1 s up
and 2.4 s down, non-smooth at the trim (40-95 % error). With that lag identified from JSBSim in
front of the step model 27/30 points pass; the three others (132 KCAS) trim with the left aileron
0.001 from its zero-deflection kink (the 0.004 doublet crosses it: phi_rad 16-17 %). Leaving the
throttle run out, 24/30 pass: the 132 KCAS points and the 108 KCAS points, whose trim alpha lies
0.07 deg from a breakpoint of the lift table (h_ft 5.4-7.1 %). Both causes are shown by
``slope_jumps`` in ``info["nonsmooth"]`` and by the amplitude test below (a doublet that stays
on one side passes).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft
from fdi_sim.linear.grid import default_grid_path, load_grid
from fdi_sim.linear.linearize import linearize, linearize_grid
from fdi_sim.linear.transform import discretize
from fdi_sim.linear.validate import NRMSE_BAR, compare, default_doublets, fly_doublets
from fdi_sim.operating_point import OperatingPoint


@pytest.mark.slow
def test_default_f16_grid() -> None:
    grid = load_grid(default_grid_path("f16"), "f16")
    s = linearize_grid(grid)
    assert len(s.points) == len(grid.points)
    for p in s.points:  # no silent skips
        assert p.status == "ok" or p.reason
    ok = s.ok_points
    assert len(ok) == len(grid.points)  # every default point is inside the trimmable envelope
    # FGLinearization within 5 % except the roll root (<= 7 %), and for that root the simulation
    # itself (the poles of the step model) sides with ours at every point
    for p in ok:
        fg = p.info["fglin"]
        pm = fg["per_mode"]
        assert all(v < (0.07 if k.startswith("roll") else 0.05) for k, v in pm.items() if abs(float(k.split()[-1])) > 1e-3), pm
        roll = [k for k in pm if k.startswith("roll")][0]
        assert fg["sim"]["ours_vs_sim"][roll] < 0.015
        assert fg["sim"]["fglin_vs_sim"][roll] > 2 * fg["sim"]["ours_vs_sim"][roll], (p.op.label(), fg["sim"])
    step = [p.info["validation"]["step"] for p in ok]
    assert all(v["passed"] for v in step)
    assert max(v["worst"] for v in step) < 0.02
    zoh = [p.info["validation"]["zoh"] for p in ok]
    assert sum(v["passed"] for v in zoh) >= 17
    assert {v["worst_output"] for v in zoh if not v["passed"]} <= {"r_radps"}


@pytest.mark.slow
def test_default_dhc6_grid() -> None:
    grid = load_grid(default_grid_path("DHC6"), "DHC6")
    s = linearize_grid(grid)
    ok = s.ok_points
    assert len(ok) == len(grid.points)  # every default point trims
    it = list(s.names["input_names"]).index("throttle_cmd_norm")
    for p in ok:
        v, lag = p.info["validation"]["step"], p.info["validation_engine_lag"]
        # the linear model's throttle failure stays visible everywhere, with its cause
        assert not v["passed"] and np.min(np.array(v["nrmse_pair"])[it]) > 0.3
        assert p.info["engine_lag"]["tau_down_s"] > 2 * p.info["engine_lag"]["tau_up_s"]
        jumps = {k: d["jump"] for k, d in p.info["nonsmooth"].items()}
        if p.op.vc_kts == 132.0:  # the left-aileron kink at zero deflection
            assert not lag["passed"] and lag["worst_output"] == "phi_rad" and lag["worst"] < 0.2
            assert jumps["aileron_cmd_norm"] > 0.1
        else:
            assert lag["passed"], (p.op.label(), lag["worst_output"], lag["worst"])
            assert jumps["aileron_cmd_norm"] < 0.05
        if v["worst_without_throttle"] >= NRMSE_BAR:  # without the throttle run: only the two kinks
            assert p.op.vc_kts in (108.0, 132.0), p.op.label()
            assert max(jumps["alpha_rad"], jumps["aileron_cmd_norm"]) >= 0.05
    assert sum(p.info["validation_engine_lag"]["passed"] for p in ok) == 27
    assert sum(p.info["validation"]["step"]["worst_without_throttle"] < NRMSE_BAR for p in ok) >= 24


@pytest.mark.slow
@pytest.mark.parametrize("vc_kts, doublet, scale", [(108.0, "elevator_cmd_norm", 0.25), (132.0, "aileron_cmd_norm", 0.2)])
def test_smaller_doublets_stay_off_the_kinks(vc_kts: float, doublet: str, scale: float) -> None:
    """The cause of the two non-linear points: with the one doublet that crosses JSBSim's kink made
    small enough to stay on one side (alpha 0.07 deg from the lift-table breakpoint at 108 KCAS,
    left aileron 0.001 from zero deflection at 132 KCAS), the same model passes."""
    grid = load_grid(default_grid_path("DHC6"), "DHC6")
    ac = Aircraft("DHC6")
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=vc_kts))
    m, md = lp.model, discretize(lp.model, ac.dt_s, method="step")
    errs = []
    for k in (1.0, scale):
        amps = {**grid.validation.amplitudes, doublet: grid.validation.amplitudes[doublet] * k}
        v = replace(grid.validation, amplitudes=amps)
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, v), m.output_names, v.duration_s)
        errs.append(float(np.max(compare(md, runs).nrmse_without(("throttle_cmd_norm",)))))
    assert errs[0] > NRMSE_BAR > 0.8 * NRMSE_BAR > errs[1], errs

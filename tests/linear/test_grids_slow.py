"""The full default grids with the 10 s doublet validation at every point (``pytest -m slow``).

Measured on the development machine (AB3 simulation, ZOH models; 2 cores): F-16 20 points in
about 16 s, DHC-6 30 points in about 30 s.

F-16: 17/20 points below 5 % on every output; the other three (5000 ft / 400-420 KTAS,
10 kft / 420 KTAS) miss on r_radps by at most 5.7 % (the FBW loops sample their sensors one step
late and the AB3 start after each doublet step overshoots; neither is in a continuous model).

DHC-6: the linear model fails the throttle doublet at every point (asymmetric N1 lag: 40-95 %);
with the identified lag in front of it the throttle run is below 5 % at 28 points (2000 ft /
132 KCAS: N1 crosses the 94 % breakpoint of the PT6A power table; 8000 ft / 124 KCAS: ny_g 7.8 %)
and 12/30 points pass on every output. What fails is named in the assertions below.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft
from fdi_sim.linear.grid import default_grid_path, load_grid
from fdi_sim.linear.linearize import linearize, linearize_grid
from fdi_sim.linear.transform import discretize
from fdi_sim.linear.validate import NRMSE_BAR, compare, default_doublets, fly_doublets


@pytest.mark.slow
def test_default_f16_grid() -> None:
    grid = load_grid(default_grid_path("f16"), "f16")
    s = linearize_grid(grid)
    assert len(s.points) == len(grid.points)
    for p in s.points:  # no silent skips
        assert p.status == "ok" or p.reason
    ok = s.ok_points
    assert len(ok) == len(grid.points)  # every default point is inside the trimmable envelope
    # FGLinearization within 5 % except the roll root (<= 7 %: FGLinearization reads its derivatives
    # after one model pass, where lagged signals and the PID derivative terms are stale)
    for p in ok:
        pm = p.info["fglin"]["per_mode"]
        assert all(v < (0.07 if k.startswith("roll") else 0.05) for k, v in pm.items() if abs(float(k.split()[-1])) > 1e-3), pm
    zoh = [p.info["validation"]["zoh"] for p in ok]
    assert sum(v["passed"] for v in zoh) >= 17
    assert max(v["worst"] for v in zoh) < 0.06
    failing = {v["worst_output"] for v in zoh if not v["passed"]}
    assert failing <= {"r_radps"}, failing


@pytest.mark.slow
def test_default_dhc6_grid() -> None:
    """Per point: the linear model as it is and with the identified N1 lag (the schedule's report shows
    both; this test flies the runs itself so it checks both whatever the grid driver stores)."""
    grid = load_grid(default_grid_path("DHC6"), "DHC6")
    ac = Aircraft("DHC6")
    rows = []
    for op in grid.points:
        lp = linearize(ac, op)
        assert lp.status == "ok", (op.label(), lp.reason)  # every default point trims
        m = lp.model
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, grid.validation), m.output_names,
                            grid.validation.duration_s)
        it = runs.input_names.index("throttle_cmd_norm")
        linear = compare(discretize(m, ac.dt_s), runs)
        lagged = compare(discretize(m, ac.dt_s), runs, engine_lag=True)
        rows.append((op, lp.trim["aileron_cmd_norm"], linear, lagged, it))
    # the linear model's throttle failure stays visible at every point
    assert all(np.min(linear.nrmse_pair[it]) > 0.3 for _, _, linear, _, it in rows)
    # with the N1 lag the throttle run fits, except where N1 crosses a power-table breakpoint
    thr = np.array([np.max(lagged.nrmse_pair[it]) for _, _, _, lagged, it in rows])
    assert np.sum(thr < NRMSE_BAR) >= 28 and np.max(thr) < 0.3, thr
    assert sum(lagged.passed() for _, _, _, lagged, _ in rows) >= 12
    # the airframe channels (throttle run left out): below 10 % wherever the aileron doublet stays on
    # one side of the left-aileron kink at zero (|trim| > amplitude); with flaps the induced drag is
    # one step late in JSBSim (aero/cl-squared) and shows as a one-sample nx_g spike at each gust step
    amp = grid.validation.amplitudes["aileron_cmd_norm"]
    for op, ail, linear, _, _ in rows:
        wo = linear.nrmse_without(("throttle_cmd_norm",))
        if abs(ail) > amp:
            assert np.max(wo) < 0.10, (op.label(), dict(zip(linear.runs.output_names, wo)))
        else:
            assert np.max(wo) < 0.25, op.label()

"""The linearizer against JSBSim: FGLinearization, the notes' eigenvalues, physics checks, validation.

One representative point per aircraft (F-16 10 kft / 400 KTAS, DHC-6 5000 ft / 120 KCAS); the
full default grids are in ``test_default_grids.py``.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.aircraft.linearize import FDSettings, central_difference
from fdi_sim.aircraft.linearize_fglin import fglinearization
from fdi_sim.aircraft.linearize_response import identify_engine_lag, slope_jumps
from fdi_sim.aircraft.linearize_state import capture_trim
from fdi_sim.errors import DesignError
from fdi_sim.isa import vc_from_vt
from fdi_sim.linear.grid import default_grid_path, load_grid, parse_grid_spec
from fdi_sim.linear.linearize import linearize, linearize_grid
from fdi_sim.linear.modes import identify_modes, participation
from fdi_sim.linear.step import equivalent_poles
from fdi_sim.linear.transform import discretize
from fdi_sim.linear.validate import DoubletSpec, compare, default_doublets, fly_doublets, nrmse, simulate_linear
from fdi_sim.operating_point import OperatingPoint

F16_OP = OperatingPoint("f16", 10000.0, vt_kts=400.0)
DHC6_OP = OperatingPoint("DHC6", 5000.0, vc_kts=120.0)


@pytest.fixture(scope="module")
def f16():
    ac = Aircraft("f16")
    return ac, linearize(ac, F16_OP, check_fglin=True)


@pytest.fixture(scope="module")
def dhc6():
    ac = Aircraft("DHC6")
    return ac, linearize(ac, DHC6_OP)


def test_f16_eigenvalues_match_fglinearization(f16) -> None:
    """Issue 4 bar: within 5 % of FGLinearization (JSBSIM_NOTES 4.3 lists both sets), except the roll root.

    The roll root differs by 5.0 %, and the simulation itself says whose it is: the poles of the
    step model (the discrete model of JSBSim's 120 Hz step, validated against JSBSim below to
    1.6 % on every output) mapped back by ln(z)/dt put the roll root at -1.031 1/s; ours is -1.039
    (0.7 % off), FGLinearization's -1.094 (6.1 % off). FGLinearization reads its derivatives after
    JSBSim's Initialize and one Run (two passes, ``FGStateSpace::run``), with the yaw channel
    still carrying the previous stencil evaluation: beta-dot from the previous pass's accelerations
    without the yaw damper's rudder, the yaw-load PID's derivative term and its stale side
    acceleration (not the roll PID). ``test_fglin_roll_root.py`` shows it: FGLinearization's own
    procedure replayed through the Python API gives its A and B bit for bit with its pass count and
    our roll root (-1.0389) once the passes settle. So the roll root is allowed 5.5 % against
    FGLinearization, and the referee numbers are asserted.
    """
    _, lp = f16
    mt = identify_modes(lp.model.A, lp.model.state_names)
    for m, r in zip(mt.modes, mt.relative_errors(lp.fglin_eigs)):
        if abs(m.eigenvalue) > 1e-3:  # a zero root has no relative error
            assert r < (0.055 if m.name == "roll" else 0.05), (m.name, m.eigenvalue, r)
    names = {m.name for m in mt.modes}
    assert {"short period", "phugoid", "dutch roll", "roll", "spiral"} <= names
    # the values of JSBSIM_NOTES 4.3, own-FD column
    roll = mt.get("roll")[0].eigenvalue
    assert abs(roll + 1.039) < 0.02
    # the referee: the simulation's own roll pole
    sim = equivalent_poles(discretize(lp.model, method="step"))
    sim_roll = sim[np.argmin(np.abs(sim - roll))]
    fg_roll = lp.fglin_eigs[np.argmin(np.abs(lp.fglin_eigs - roll))]
    assert abs(roll - sim_roll) / abs(sim_roll) < 0.015
    assert abs(fg_roll - sim_roll) / abs(sim_roll) > 0.05
    # modes.py: the FBW F-16's real "roll" root sits on beta (participation 0.91), named by speed
    lam, P = participation(lp.model.A)
    assert P[lp.model.state_names.index("beta_rad"), np.argmin(abs(lam - roll))] > 0.85
    assert abs(mt.get("spiral")[0].eigenvalue + 0.0465) < 0.002
    assert sorted(m.eigenvalue.real for m in mt.get("short period")) == pytest.approx([-10.56, -1.723], rel=0.01)


def test_simulation_integrates_with_ab3_from_the_last_three_derivatives() -> None:
    """JSBSim's step (fdi_sim.linear.step, note 1): after an elevator and aileron step the state moves by
    dt (23 f_k - 16 f_(k-1) + 5 f_(k-2)) / 12 with the derivatives JSBSim reports, not by dt f_k."""
    ac = Aircraft("f16")
    tr = trim(ac, F16_OP)
    fdm = ac.fdm
    rec = []
    for k in range(20):
        fdm["fcs/elevator-cmd-norm"] = tr.elevator_cmd_norm + (0.01 if k >= 10 else 0.0)
        fdm["fcs/aileron-cmd-norm"] = tr.aileron_cmd_norm + (0.01 if k >= 10 else 0.0)
        ac.step()
        rec.append([ac[p] for p in ("velocities/p-rad_sec", "accelerations/pdot-rad_sec2", "velocities/q-rad_sec",
                                    "accelerations/qdot-rad_sec2", "velocities/w-fps", "accelerations/wdot-ft_sec2")])
    r = np.array(rec)
    h = ac.dt_s
    for c in (0, 2, 4):
        x, f = r[:, c], r[:, c + 1]
        for k in range(10, 18):
            ab3 = h * (23 * f[k] - 16 * f[k - 1] + 5 * f[k - 2]) / 12
            assert x[k + 1] - x[k] == pytest.approx(ab3, rel=1e-4, abs=1e-12)  # (inertial vs body frame: 1e-6)
        assert abs((x[11] - x[10]) / (h * f[10]) - 23 / 12) < 0.01  # the first step after the input: 23/12, not 1


def test_fbw_reads_alpha_one_pass_late(f16) -> None:
    """fdi_sim.linear.step, note 2: in the first pass after a change of alpha (a vertical gust, as the
    simulation meets it) the F-16 pitch moment is the bare airframe's (the FBW reads alpha and n_z from
    FGAuxiliary, which runs after the FCS); the FBW's alpha feedback arrives in the second pass."""
    _, lp = f16
    m, st = lp.model, lp.model.step
    assert st is not None and st.n_passes == 5
    iq, ia = m.state_names.index("q_radps"), m.state_names.index("alpha_rad")
    settled = m.A[iq, ia]
    assert settled < -5.0  # the FBW makes M_alpha strongly stabilizing (-9 1/s^2)
    assert abs(st.Ax[0][iq, ia]) < 0.05 * abs(settled)
    assert st.Ax[1][iq, ia] == pytest.approx(settled, rel=0.15)
    np.testing.assert_allclose(st.Ax[-1], m.A[:st.n_rigid])  # the last pass is the settled model
    assert m.meta["step_lf_residual"] < 1e-6  # the accelerometers are a fixed map of the previous derivatives


def test_f16_model_fits_jsbsim_better_than_fglinearization(f16) -> None:
    """On an aileron doublet flown in JSBSim, our roll response is closer than FGLinearization's.

    Measured (ZOH, AB3 simulation): p_radps 3.0 % against 4.8 %, phi_rad 1.5 % against 3.9 %.
    """
    ac, lp = f16
    ac2 = Aircraft("f16")
    trim(ac2, F16_OP)
    jl = fglinearization(ac2)
    runs = fly_doublets(ac, lp.trim_state, [DoubletSpec("aileron_cmd_norm", 0.005)], ("p_radps", "phi_rad"))
    u = runs.du[0]
    iu = jl.u_names.index("DaCmd")
    Ad, Bd, *_ = cont2discrete((jl.A, jl.B[:, [iu]], np.eye(len(jl.x_names)), np.zeros((len(jl.x_names), 1))),
                               ac.dt_s, method="zoh")
    x, xs = np.zeros(len(jl.x_names)), []
    for uk in u:
        xs.append(x.copy())
        x = Ad @ x + Bd[:, 0] * uk
    xs = np.array(xs)
    ours = discretize(lp.model)
    ip, iphi = ours.output_names.index("p_radps"), ours.output_names.index("phi_rad")
    U = np.zeros((len(u), ours.n_inputs))
    U[:, ours.input_names.index("aileron_cmd_norm")] = u
    y = simulate_linear(ours, U)
    for col, ij, name in ((ip, jl.x_names.index("P"), "p"), (iphi, jl.x_names.index("Phi"), "phi")):
        e_ours = float(nrmse(y[:, col], runs.dy[0][:, list(runs.output_names).index(ours.output_names[col])]))
        e_fg = float(nrmse(xs[:, ij], runs.dy[0][:, list(runs.output_names).index(ours.output_names[col])]))
        assert e_ours < e_fg, (name, e_ours, e_fg)
        assert e_ours < 0.035


def test_f16_gust_columns_mirror_the_velocity_columns(f16) -> None:
    """Moments depend on the air-relative velocity only: dM/d(gust) = -dM/d(u, v, w) (body axes)."""
    ac, _ = f16
    tr = trim(ac, F16_OP)
    bj = central_difference(ac, tr)
    rows = [bj.state_names.index(s) for s in ("p_radps", "q_radps", "r_radps")]
    B_g = bj.B[np.ix_(rows, [bj.input_names.index(g) for g in ("u_gust_body_fps", "v_gust_body_fps", "w_gust_body_fps")])]
    A_v = bj.A[np.ix_(rows, [0, 1, 2])]
    scale = np.max(np.abs(A_v), axis=1, keepdims=True)
    np.testing.assert_allclose(B_g / scale, -A_v / scale, atol=0.02)
    # the centre evaluation reproduces the trim: accelerations near zero
    assert np.max(np.abs(bj.xdot0[:3])) < 0.01 and np.max(np.abs(bj.xdot0[3:6])) < 1e-3
    assert bj.knob_condition < 1e6


def test_isa_calibrated_airspeed_matches_jsbsim(f16) -> None:
    _, lp = f16
    vc, mach = vc_from_vt(F16_OP.h_ft, F16_OP.vt_kts)
    assert vc == pytest.approx(lp.trim["vc_kts"], rel=3e-3)
    assert mach == pytest.approx(lp.trim["mach"], rel=3e-3)


def test_dhc6_modes_match_the_notes(dhc6) -> None:
    """JSBSIM_NOTES 4.3, DHC-6 5000 ft 120 KIAS, own FD after the running trim (beta -0.29 deg)."""
    _, lp = dhc6
    mt = identify_modes(lp.model.A, lp.model.state_names)
    assert abs(mt.get("short period")[0].eigenvalue - complex(-2.260, 2.635)) / 3.47 < 0.01
    assert abs(mt.get("dutch roll")[0].eigenvalue - complex(-0.411, 4.445)) / 4.46 < 0.01
    assert mt.get("roll")[0].eigenvalue.real == pytest.approx(-5.560, rel=0.01)
    # spiral: stable as the notes say for beta = -0.3 deg (-0.0225 with the engine frozen; our
    # engine states move thrust and torque with airspeed, -0.019)
    assert -0.03 < mt.get("spiral")[0].eigenvalue.real < -0.015
    assert lp.model.state_names[-2:] == ("n1_pct", "prop_rpm")


def test_dhc6_engine_rows_follow_the_engine_source(dhc6) -> None:
    """FGTurboProp::Run: N1 -> IdleN1 + throttle N1_factor by ExpSeek with tau 1 s up, 2.4 s down
    (PT6A-27.xml: idlen1 60, maxn1 100, n1idle_max_delay 1). The central difference averages the two."""
    _, lp = dhc6
    m = lp.model
    i = m.state_names.index("n1_pct")
    rate = 0.5 * (1 / 1.0 + 1 / 2.4)
    assert m.A[i, i] == pytest.approx(-rate, rel=1e-3)
    assert m.B[i, m.input_names.index("throttle_cmd_norm")] == pytest.approx(40.0 * rate, rel=1e-3)
    others = np.delete(m.A[i], i)
    assert np.max(np.abs(others)) < 1e-6


def test_representative_points_validate(f16, dhc6) -> None:
    """Small doublets, 10 s, per-output normalized RMS error (numbers in the report).

    The step model (the discrete model of JSBSim's step) is the one the bar is judged on. F-16
    10 kft / 400 KTAS: every output below 5 % with ZOH (largest r_radps 4.9 %), below 1.6 % with
    the step model. DHC-6 5000 ft / 120 KCAS: the linear model fails the throttle doublet
    (43-95 % per output: N1 rises with 1 s and falls with 2.4 s, so a zero-mean doublet leaves it
    above the trim), with ZOH and with the step model alike; with that asymmetric lag identified
    from JSBSim in front of the step model every output of every run is below 5 %, and so is
    every output leaving the throttle doublet out. Also the numbers quoted in
    :func:`fdi_sim.linear.transform.discretize` (accelerometer lag states) and in
    ``Aircraft.__init__`` (AB3 integrators).
    """
    for ac, lp in (f16, dhc6):
        g = load_grid(default_grid_path(ac.name), ac.name)
        m = lp.model
        out = m.output_names.index
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, g.validation), m.output_names)
        zoh = compare(discretize(m, ac.dt_s), runs)
        euler = compare(discretize(m, ac.dt_s, method="euler"), runs)
        step = compare(discretize(m, ac.dt_s, method="step"), runs)
        if ac.name == "f16":
            assert runs.engine_lag is None  # the F100 is quasi-static in the model: nothing to replace
            assert zoh.passed(), {n: e for n, e in zip(m.output_names, zoh.nrmse) if e >= 0.05}
            assert zoh.nrmse[out("r_radps")] > 0.04  # the FBW's one-pass delays and AB3, not in ZOH
            assert np.all(step.nrmse < 0.02), dict(zip(m.output_names, step.nrmse))
            # the accelerometers one step late: the elevator doublet's nz_g error is 12 % without the lag states
            ie, iz = runs.input_names.index("elevator_cmd_norm"), out("nz_g")
            no_lag = compare(discretize(m, ac.dt_s, lag_outputs=False), runs)
            assert no_lag.nrmse_pair[ie, iz] == pytest.approx(0.12, abs=0.01)
            assert zoh.nrmse_pair[ie, iz] < 0.03
        else:
            it = runs.input_names.index("throttle_cmd_norm")
            assert np.all(zoh.nrmse_without(("throttle_cmd_norm",)) < 0.05)
            assert np.all(step.nrmse_without(("throttle_cmd_norm",)) < 0.025)
            for linear in (zoh, step):  # the linear model's throttle failure must stay visible
                assert np.min(linear.nrmse_pair[it]) > 0.3
            lagged = compare(discretize(m, ac.dt_s, method="step"), runs, engine_lag=True)
            assert lagged.engine_lag == runs.engine_lag and lagged.passed()
            assert np.all(lagged.nrmse_pair[it] < 0.05), dict(zip(m.output_names, lagged.nrmse_pair[it]))
            # docs/linear.md (figure, right): the throttle run's h_ft 73 % without the lag, 0.2 % with it
            assert step.nrmse_pair[it, out("h_ft")] == pytest.approx(0.73, abs=0.02)
            assert lagged.nrmse_pair[it, out("h_ft")] < 0.003
            # JSBSim integrates the body rates with AB3 (Aircraft.__init__): ZOH follows it, Euler does
            # not (p_radps 1.6 % against 15 %; with JSBSim's default Euler it was 11 % against 2 %)
            ip = out("p_radps")
            assert zoh.nrmse_without(("throttle_cmd_norm",))[ip] < 0.03
            assert euler.nrmse_without(("throttle_cmd_norm",))[ip] > 0.1


def test_slope_jumps_find_the_left_aileron_kink() -> None:
    """DHC-6 at 132 KCAS trims with the left aileron 0.001 from zero deflection, where its
    aerosurface_scale (-0.28 / +0.33 rad) changes slope by 18 %: a 0.004 doublet crosses it.
    slope_jumps sees the kink there and not at 120 KCAS (trim 0.005)."""
    ac = Aircraft("DHC6")
    jumps = {}
    for vc in (120.0, 132.0):
        lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=vc))
        jumps[vc] = slope_jumps(ac, lp.trim_state, {"aileron_cmd_norm": 0.004, "rudder_cmd_norm": 0.005})
    assert jumps[132.0]["aileron_cmd_norm"] > 0.1
    assert jumps[120.0]["aileron_cmd_norm"] < 0.02
    assert max(j["rudder_cmd_norm"] for j in jumps.values()) < 0.02
    with pytest.raises(DesignError, match="unknown probe"):
        slope_jumps(ac, lp.trim_state, {"no_such_input": 1.0})


def test_linear_range_flies_only_the_kink_crossing_doublet_smaller() -> None:
    """DHC-6 5000 ft / 132 KCAS: the configured 0.004 aileron doublet crosses the left aileron's
    kink at zero deflection (trim command about 0.001 from it) and fails (phi 16-18 %); the smooth
    radius found by halving is no larger than the distance to the kink, only the aileron doublet is
    flown again, and with it the model passes. At 124 KCAS (trim 0.003) nothing is changed."""
    from fdi_sim.linear.linearize import linear_range_runs, nonsmooth

    ac = Aircraft("DHC6")
    grid = load_grid(default_grid_path("DHC6"), "DHC6")
    out = {}
    for vc in (124.0, 132.0):
        lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=vc))
        m = lp.model
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, grid.validation), m.output_names, 10.0)
        lr = linear_range_runs(ac, lp.trim_state, runs, nonsmooth(ac, lp.trim_state, runs))
        md = discretize(m, ac.dt_s, method="step")
        out[vc] = (lp, runs, lr, compare(md, runs, engine_lag=True), compare(md, lr.runs, engine_lag=True))
    lp, runs, lr, before, after = out[132.0]
    assert set(lr.reduced) == {"aileron_cmd_norm"} and lr.reduced["aileron_cmd_norm"]["by"] == "aileron_cmd_norm"
    trim_cmd = abs(lp.trim["aileron_cmd_norm"])
    assert lr.reduced["aileron_cmd_norm"]["radius"] <= 1.5 * trim_cmd < 0.004
    ia = runs.input_names.index("aileron_cmd_norm")
    assert lr.runs.doublets[ia].amplitude == pytest.approx(0.004 * lr.reduced["aileron_cmd_norm"]["factor"])
    others = [i for i in range(len(runs.doublets)) if i != ia]
    assert np.array_equal(lr.runs.dy[others], runs.dy[others])  # the other runs are not flown again
    assert before.worst[0] == "phi_rad" and before.worst[1] > 0.1
    assert after.passed(), after.worst
    # docs/linear.md (figure, middle): the aileron run's phi error 33 % at 0.004, 1.0 % at 0.001
    iphi = m.output_names.index("phi_rad")
    assert lr.runs.doublets[ia].amplitude == pytest.approx(0.001)
    assert before.nrmse_pair[ia, iphi] == pytest.approx(0.33, abs=0.02)
    assert after.nrmse_pair[ia, iphi] == pytest.approx(0.010, abs=0.002)
    lp, runs, lr, before, after = out[124.0]
    assert lr.reduced == {} and lr.runs is runs and before.passed()


def test_lifted_step_model_follows_jsbsim_at_20_hz() -> None:
    """A detector at 20 Hz (6 simulation steps, input held over each block, outputs read after the
    block): the step model lifted to 0.05 s follows JSBSim on the F-16's fast modes within 1 %
    (measured 0.01-0.75 %; the ZOH of the continuous model read the same way: 2-30 %)."""
    ac = Aircraft("f16")
    lp = linearize(ac, OperatingPoint("f16", 5000.0, vt_kts=420.0), check_fglin=False)
    m, n = lp.model, 6
    runs = fly_doublets(ac, lp.trim_state, [DoubletSpec("rudder_cmd_norm", 0.01), DoubletSpec("elevator_cmd_norm", 0.01)],
                        m.output_names, 6.0)
    lifted = discretize(m, n * ac.dt_s, method="step")
    assert lifted.dt_s == pytest.approx(0.05)
    for r, outs in enumerate((("r_radps", "beta_rad", "ny_g"), ("q_radps", "alpha_rad", "nz_g", "theta_rad"))):
        U = np.zeros((runs.du.shape[1] // n, m.n_inputs))
        U[:, m.input_names.index(runs.input_names[r])] = runs.du[r, ::n]  # the doublet is block-aligned
        y_lin = simulate_linear(lifted, U)
        for o in outs:
            i = m.output_names.index(o)
            assert nrmse(y_lin[:, i], runs.dy[r, n - 1::n, i]) < 0.01, (runs.input_names[r], o)
    # docs/linear.md (figure, left): at the simulation step, a 4 s rudder doublet's r error is 5.6 %
    # with the ZOH of the continuous model and within 0.01 % with the step model
    fig = fly_doublets(ac, lp.trim_state, [DoubletSpec("rudder_cmd_norm", 0.01)], m.output_names, 4.0)
    ir = m.output_names.index("r_radps")
    assert compare(discretize(m, ac.dt_s), fig).nrmse_pair[0, ir] == pytest.approx(0.056, abs=0.002)
    assert compare(discretize(m, ac.dt_s, method="step"), fig).nrmse_pair[0, ir] < 1e-4


def test_fglinearization_is_wrong_for_the_dhc6_propeller() -> None:
    """JSBSIM_NOTES 4.1 (a): for the DHC-6 FGLinearization's Rpm rows and throttle column are garbage.

    Right after JSBSim's own trim (5000 ft, 120 KIAS; after the running trim it does not converge)
    it gives ``d Rpm-dot / d throttle`` = -1140 rpm/s per unit (more throttle, a slower propeller: its
    real 1/120 s step hits the turboprop's N1 -> idle reset) and an unstable propeller speed
    (``A[Rpm, Rpm]`` = +0.107 1/s). Our model at the running trim has the governed propeller
    settling and the throttle acting through N1, which is what the doublets validate; the airframe's
    short period agrees (-2.254 +- 2.636j against -2.260 +- 2.635j in the notes)."""
    ac = Aircraft("DHC6")
    f = ac.fdm
    f["ic/h-sl-ft"], f["ic/vc-kts"], f["ic/gamma-deg"], f["ic/psi-true-deg"] = 5000.0, 120.0, 0.0, 0.0
    f["propulsion/set-running"] = -1
    f.run_ic()
    f.do_trim(1)
    with pytest.raises(DesignError, match="not reliable for the propeller"):
        fglinearization(ac)
    jl = fglinearization(ac, allow_propeller=True)
    i, j = jl.x_names.index("Rpm0"), jl.u_names.index("ThtlCmd")
    assert jl.B[i, j] < -500.0 and jl.A[i, i] > 0.05, (jl.B[i, j], jl.A[i, i])
    lon = [jl.x_names.index(n) for n in ("Vt", "Alpha", "Q", "Theta")]
    fg_sp = max(np.linalg.eigvals(jl.A[np.ix_(lon, lon)]), key=abs)
    m = linearize(Aircraft("DHC6"), DHC6_OP).model
    r, n1, thr = m.state_names.index("prop_rpm"), m.state_names.index("n1_pct"), m.input_names.index("throttle_cmd_norm")
    assert m.A[r, r] < 0.0 and m.A[r, n1] > 0.0 and abs(m.B[r, thr]) < 1.0 and m.B[n1, thr] > 0.0
    sp = identify_modes(m.A, m.state_names).get("short period")[0].eigenvalue
    assert abs(sp - fg_sp.conjugate() if fg_sp.imag * sp.imag < 0 else sp - fg_sp) / abs(fg_sp) < 0.02, (sp, fg_sp)


def test_simulation_integrates_with_ab3() -> None:
    """Aircraft sets all four FGPropagate integrators to AB3 (4); JSBSim keeps them through trims."""
    ac = Aircraft("DHC6")
    trim(ac, DHC6_OP)
    for _ in range(10):
        ac.step()
    kinds = ("rate/rotational", "rate/translational", "position/rotational", "position/translational")
    assert [ac[f"simulation/integrator/{k}"] for k in kinds] == [4.0] * 4


def test_engine_lag_is_identified_from_jsbsim(dhc6) -> None:
    """identify_engine_lag finds FGTurboProp's ExpSeek constants (PT6A-27.xml n1idle_max_delay 1 s,
    down 2.4 x that) at the trim, and the linear model's N1 row holds their mean rate."""
    ac, lp = dhc6
    lag = identify_engine_lag(ac, lp.trim_state)
    assert lag is not None
    assert lag.tau_up_s == pytest.approx(1.0, rel=1e-6) and lag.tau_down_s == pytest.approx(2.4, rel=1e-6)
    i = lp.model.state_names.index(lag.state_name)
    assert -lp.model.A[i, i] == pytest.approx(0.5 * (1 / lag.tau_up_s + 1 / lag.tau_down_s), rel=1e-3)
    # the aircraft is back at the trim afterwards: the next run starts where the doublet runs do
    assert ac.get("vc_kts") == pytest.approx(DHC6_OP.vc_kts, abs=0.05)


def test_n1_excursion_estimate_matches_the_n1_jsbsim_flies(dhc6) -> None:
    """The smooth-range probe of N1 (linear_range_runs) takes the throttle run's N1 excursion from the
    continuous model's static gain (-B/A of its N1 row) and the identified lag; JSBSim's own N1 over
    the same doublet peaks at the same value (0.506 % for 0.02: 40 % x 0.02 x (1 - exp(-1 s / 1 s)))."""
    from fdi_sim.aircraft.linearize_state import CONTROL_INPUTS, command_props, engine_reader, restore_trim
    from fdi_sim.linear.linearize import n1_excursions

    ac, lp = dhc6
    ts = lp.trim_state
    runs = fly_doublets(ac, ts, [DoubletSpec("throttle_cmd_norm", 0.02), DoubletSpec("elevator_cmd_norm", 0.01)],
                        lp.model.output_names, 4.0)
    est = n1_excursions(runs, lp.model)
    assert est[1] == 0.0  # only the throttle moves the gas generator
    read, props = engine_reader(ac), command_props(ac, "throttle_cmd_norm")
    u0 = ts.u_cmd[CONTROL_INPUTS.index("throttle_cmd_norm")]
    n1 = []
    for u in (np.zeros_like(runs.du[0]), runs.du[0]):  # unforced, then the doublet, from the trim
        restore_trim(ac, ts)
        ac.fdm["propulsion/fuel_freeze"] = 1
        trace = []
        for du in u:
            for prop in props:
                ac.fdm[prop] = u0 + du
            ac.fdm.run()
            trace.append(read()[0])
        n1.append(np.array(trace))
    ac.fdm["propulsion/fuel_freeze"] = 0
    restore_trim(ac, ts)
    peak = float(np.max(np.abs(n1[1] - n1[0])))
    assert peak == pytest.approx(0.8 * (1 - np.exp(-1.0)), rel=0.02)
    assert est[0] == pytest.approx(peak, rel=1e-4), (est[0], peak)  # measured 1.5e-7


def test_untrimmable_and_skipped_points_say_why() -> None:
    ac = Aircraft("DHC6")
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=170.0))
    assert lp.status == "untrimmable" and lp.reason and lp.model is None
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=120.0, icing_eta=0.05))
    assert lp.status == "skipped" and "icing overlay not available" in lp.reason
    with pytest.raises(DesignError, match="operating point is for"):
        linearize(ac, F16_OP)
    with pytest.raises(DesignError, match="not reliable for the propeller"):
        fglinearization(ac)


def test_grid_reports_every_point() -> None:
    """No silent skips: an untrimmable point keeps its reason, an unknown model skips every point.
    (Iced points fly the icing overlay: tests/linear/test_iced_grid.py.)"""
    g = parse_grid_spec("h_ft=5000;vc_kts=120", "DHC6")
    # built directly: the grid file's envelope check would refuse 170 KCAS
    beyond = type(g)("DHC6", (*g.points, OperatingPoint("DHC6", 5000.0, vc_kts=170.0)), g.envelope, g.validation,
                     "test")
    s = linearize_grid(beyond, validate=False)
    assert [p.status for p in s.points] == ["ok", "untrimmable"]
    assert s.points[1].reason and s.points[1].info["timing_s"]["trim"] > 0
    unknown = type(g)("DHC6ice", tuple(OperatingPoint("DHC6ice", 5000.0, vc_kts=120.0, icing_eta=e) for e in (0, 0.05, 0.1)),
                      g.envelope, g.validation, "test")
    s2 = linearize_grid(unknown, validate=False)
    assert [p.status for p in s2.points] == ["skipped"] * 3
    assert all("overlay not available" in p.reason for p in s2.points)


def test_bad_fd_settings() -> None:
    ac = Aircraft("f16")
    tr = trim(ac, F16_OP)
    with pytest.raises(DesignError, match="FDSettings.engine"):
        central_difference(ac, tr, FDSettings(engine="jet"))
    with pytest.raises(DesignError, match="needs propeller engines"):
        central_difference(ac, tr, FDSettings(engine="dynamic"))
    with pytest.raises(DesignError, match="no property"):
        central_difference(ac, tr, extra_disturbances={"x": ("fcs/no-such-thing", 0.1)})
    ts = capture_trim(ac, tr)
    assert ts.n1_pct is None  # no propeller: no engine state to restore


def test_extra_disturbance_column_from_a_property() -> None:
    """The mechanism the icing direction will use (a model property as a disturbance column), on the
    DHC-6 speed brake: CDsb = 0.028 per unit with no lift, so du/dt = -qbar S 0.028 cos(alpha) / m."""
    ac = Aircraft("DHC6")
    tr = trim(ac, DHC6_OP)
    qbar, S, m = ac["aero/qbar-psf"], ac["metrics/Sw-sqft"], ac["inertia/mass-slugs"]
    bj = central_difference(ac, tr, extra_disturbances={"speedbrake_pos_norm": ("fcs/speedbrake-pos-norm", 0.01)})
    j = bj.input_names.index("speedbrake_pos_norm")
    assert bj.input_kinds[j] == "disturbance"
    expected = -qbar * S * 0.028 * np.cos(tr.alpha_rad) / m
    assert bj.B[0, j] == pytest.approx(expected, rel=0.03)
    assert "icing_eta" not in bj.input_names and any("icing/eta" in n for n in bj.notes)

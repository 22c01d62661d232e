"""The linearizer against JSBSim: FGLinearization, the notes' eigenvalues, physics checks, validation.

One representative point per aircraft (F-16 10 kft / 400 KTAS, DHC-6 5000 ft / 120 KCAS); the
full default grids are in ``test_grids_slow.py`` (``-m slow``).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.aircraft.linearize import FDSettings, central_difference
from fdi_sim.aircraft.linearize_fglin import fglinearization
from fdi_sim.aircraft.linearize_response import identify_engine_lag
from fdi_sim.aircraft.linearize_state import capture_trim
from fdi_sim.errors import DesignError
from fdi_sim.isa import vc_from_vt
from fdi_sim.linear.grid import default_grid_path, load_grid, parse_grid_spec
from fdi_sim.linear.linearize import linearize, linearize_grid
from fdi_sim.linear.modes import identify_modes, participation
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
    """Issue 4 bar: within 5 % of FGLinearization (JSBSIM_NOTES 4.3 lists both sets).

    The roll root differs by 5.0 %: FGLinearization reads the derivatives after one model pass,
    where the roll-rate PID's derivative term (kd = -1.25e-3, divided by the 1/120 s step) still
    sees the perturbation as a jump and cuts the roll loop's gain by kd 120 / kp = 5 %. Our
    central differences settle five passes (the term is 0, as in the flown aircraft; see the next
    test), so this one root is allowed 5.5 %.
    """
    _, lp = f16
    mt = identify_modes(lp.model.A, lp.model.state_names)
    for m, r in zip(mt.modes, mt.relative_errors(lp.fglin_eigs)):
        if abs(m.eigenvalue) > 1e-3:  # a zero root has no relative error
            assert r < (0.055 if m.name == "roll" else 0.05), (m.name, m.eigenvalue, r)
    names = {m.name for m in mt.modes}
    assert {"short period", "phugoid", "dutch roll", "roll", "spiral"} <= names
    # the values of JSBSIM_NOTES 4.3, own-FD column
    assert abs(mt.get("roll")[0].eigenvalue + 1.039) < 0.02
    # modes.py: the FBW F-16's real "roll" root sits on beta (participation 0.91), named by speed
    lam, P = participation(lp.model.A)
    assert P[lp.model.state_names.index("beta_rad"), np.argmin(abs(lam - mt.get("roll")[0].eigenvalue))] > 0.85
    assert abs(mt.get("spiral")[0].eigenvalue + 0.0465) < 0.002
    assert sorted(m.eigenvalue.real for m in mt.get("short period")) == pytest.approx([-10.56, -1.723], rel=0.01)


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
    """Small doublets, 10 s, per-output normalized RMS error, ZOH models (numbers in the report).

    F-16 10 kft / 400 KTAS: every output below 5 % (largest r_radps 4.9 %). DHC-6 5000 ft /
    120 KCAS: the linear model as it is fails the throttle doublet (43-95 % per output: N1 rises
    with 1 s and falls with 2.4 s, so a zero-mean doublet leaves it above the trim); with that
    asymmetric lag identified from JSBSim in front of the linear model every output of every run
    is below 5 % (largest 4.3 %, ny_g of the throttle run), and so is every output leaving the
    throttle doublet out. Also the numbers quoted in :func:`fdi_sim.linear.transform.discretize`
    (accelerometer lag states) and in ``Aircraft.__init__`` (AB3 integrators).
    """
    for ac, lp in (f16, dhc6):
        g = load_grid(default_grid_path(ac.name), ac.name)
        m = lp.model
        out = m.output_names.index
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, g.validation), m.output_names)
        zoh = compare(discretize(m, ac.dt_s), runs)
        euler = compare(discretize(m, ac.dt_s, method="euler"), runs)
        if ac.name == "f16":
            assert runs.engine_lag is None  # the F100 is quasi-static in the model: nothing to replace
            assert zoh.passed(), {n: e for n, e in zip(m.output_names, zoh.nrmse) if e >= 0.05}
            # the accelerometers one step late: the elevator doublet's nz_g error is 12 % without the lag states
            ie, iz = runs.input_names.index("elevator_cmd_norm"), out("nz_g")
            no_lag = compare(discretize(m, ac.dt_s, lag_outputs=False), runs)
            assert no_lag.nrmse_pair[ie, iz] == pytest.approx(0.12, abs=0.01)
            assert zoh.nrmse_pair[ie, iz] < 0.03
        else:
            it = runs.input_names.index("throttle_cmd_norm")
            assert np.all(zoh.nrmse_without(("throttle_cmd_norm",)) < 0.05)
            assert np.min(zoh.nrmse_pair[it]) > 0.3  # the linear model's throttle failure must stay visible
            lagged = compare(discretize(m, ac.dt_s), runs, engine_lag=True)
            assert lagged.engine_lag == runs.engine_lag and lagged.passed()
            assert np.all(lagged.nrmse_pair[it] < 0.05), dict(zip(m.output_names, lagged.nrmse_pair[it]))
            # JSBSim integrates the body rates with AB3 (Aircraft.__init__): ZOH follows it, Euler does
            # not (p_radps 1.6 % against 15 %; with JSBSim's default Euler it was 11 % against 2 %)
            ip = out("p_radps")
            assert zoh.nrmse_without(("throttle_cmd_norm",))[ip] < 0.03
            assert euler.nrmse_without(("throttle_cmd_norm",))[ip] > 0.1


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

"""Why FGLinearization's F-16 roll root is -1.094 1/s and ours -1.039 (10 kft, 400 KTAS, FBW on).

:mod:`fdi_sim.aircraft.fglin_replica` repeats FGLinearization's procedure through the Python API
with the number of trim-status passes after ``Initialize`` as a knob. Measured (this file):

=========================  ==========================  ====================  ==================
lateral [beta p r phi]     Dutch roll                  roll                  spiral
=========================  ==========================  ====================  ==================
FGLinearization            -10.7205 +- 1.7159j         -1.0940               -0.0457
replica, 1 pass (= FGLin)  -10.7205 +- 1.7159j         -1.0940               -0.0457
replica, 5 passes          -10.5365 +- 2.1776j         -1.0389               -0.0465
ours (central_difference)  -10.5366 +- 2.1776j         -1.0389               -0.0465
=========================  ==========================  ====================  ==================

Longitudinal [Vt alpha q theta]: FGLinearization and the 1-pass replica -10.7822, -1.6519,
-0.0097 +- 0.0457j; 5 passes -10.5635, -1.7232, -0.0096 +- 0.0447j; ours -10.5636, -1.7233,
-0.0096 +- 0.0447j. The 1-pass replica's A and B equal FGLinearization's bit for bit; two
passes already give -1.0321, three -1.0392, four and more -1.0389.

Where the difference comes from, read pass by pass (``pass_history``) and by moving rows of
``A`` between the two settings: not the roll PID. Its D term (kd / dt = -0.15 on kp 3) does
reach the second pass (roll-rate-pid 0.95 of its settled value), but FGLinearization's p row
moves the root by less than 0.01 %. The yaw channel does it:

* beta row: FGAuxiliary computes beta-dot from the *previous* pass's accelerations, and in the
  first pass after ``Initialize`` the FCS still reads the previous evaluation's air data, so the
  rudder of the yaw damper is missing from FGLinearization's beta row (d beta-dot / d r -0.994,
  the bare -cos(alpha), against -0.863 settled). Alone it moves the root to -1.161;
* r row: ``fcs/yaw-load-pid``'s D term (kd / dt = 0.006 on kp 0.1055: the rudder per yaw rate
  5.7 % high in the second pass) and ``fcs/yaw-load-norm`` still holding the previous evaluation's
  ``n-pilot-y`` (d r-dot / d beta 10.216 against 10.392). Alone they move the root to -0.981.

Together they give -1.094. With the rudder held (write-protect) the two settings' lateral A differ
by 0.27 (Frobenius) instead of 1.72; with the aileron held by 1.69.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.aircraft.fglin_replica import X_NAMES, fglin_replica, pass_history
from fdi_sim.aircraft.linearize_fglin import fglinearization
from fdi_sim.errors import DesignError
from fdi_sim.linear.linearize import linearize
from fdi_sim.linear.modes import identify_modes
from fdi_sim.linear.step import equivalent_poles
from fdi_sim.linear.transform import discretize
from fdi_sim.operating_point import OperatingPoint

F16_OP = OperatingPoint("f16", 10000.0, vt_kts=400.0)
LAT = [X_NAMES.index(s) for s in ("Beta", "P", "R", "Phi")]
LON = [X_NAMES.index(s) for s in ("Vt", "Alpha", "Q", "Theta")]
#: the trim-status passes that settle the F-16 FBW (pilot-station accelerations in the third pass)
SETTLED = 5


def _trimmed(hold: str | None = None) -> Aircraft:
    ac = Aircraft("f16")
    trim(ac, F16_OP)
    if hold is not None:  # write-protect one surface at its trim position
        h = ac.surface(hold)
        h.hold(h.position())
    return ac


def _eigs(A: np.ndarray, idx: list[int]) -> np.ndarray:
    return np.sort_complex(np.linalg.eigvals(A[np.ix_(idx, idx)]))


def _roll(A: np.ndarray) -> float:
    """The real lateral root between -5 and -0.5 1/s (roll subsidence; spiral -0.05, Dutch roll -10.5)."""
    lam = _eigs(A, LAT)
    real = [z.real for z in lam if abs(z.imag) < 1e-9 and -5.0 < z.real < -0.5]
    assert len(real) == 1, lam
    return real[0]


@pytest.fixture(scope="module")
def runs():
    jl = fglinearization(_trimmed())
    fg = fglin_replica(_trimmed())  # FGStateSpace's own convergence test
    settled = fglin_replica(_trimmed(), n_runs=SETTLED)
    lp = linearize(Aircraft("f16"), F16_OP, check_fglin=False)
    return jl, fg, settled, lp


def test_replica_reproduces_fglinearization(runs) -> None:
    """(a) With FGLinearization's settings (one trim-status pass, found by its own test) the replica
    gives its A and B to rounding, hence the roll root -1.0940 and every other eigenvalue."""
    jl, fg, _, _ = runs
    assert tuple(jl.x_names) == X_NAMES and fg.runs_used == (1, 1)
    assert fg.n_evaluations == 8 * 12 * (12 + 4) + 12 * (12 + 4)  # 4 points + 4 resets per entry, 1 reset after
    np.testing.assert_allclose(fg.x0, jl.x0, rtol=0, atol=0)
    np.testing.assert_allclose(fg.A, jl.A, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fg.B, jl.B, rtol=1e-9, atol=1e-12)
    assert abs(_roll(fg.A) / _roll(jl.A) - 1) < 1e-6
    assert _roll(jl.A) == pytest.approx(-1.0940, abs=5e-4)
    for idx in (LAT, LON):
        np.testing.assert_allclose(_eigs(fg.A, idx), _eigs(jl.A, idx), rtol=1e-6)


def test_settled_replica_moves_to_ours(runs) -> None:
    """(b) The same procedure with the passes settled lands on our central differences (-1.0389)
    and on the simulation's own roll pole (step model, -1.031), 5 % away from FGLinearization."""
    jl, _, settled, lp = runs
    ours = identify_modes(lp.model.A, lp.model.state_names).get("roll")[0].eigenvalue.real
    sim = equivalent_poles(discretize(lp.model, method="step"))
    sim_roll = sim[np.argmin(np.abs(sim - ours))].real
    r = _roll(settled.A)
    assert abs(r / ours - 1) < 2e-3, (r, ours)
    assert abs(r / sim_roll - 1) < 0.015, (r, sim_roll)
    assert abs(_roll(jl.A) / r - 1) > 0.045
    # every lateral and longitudinal eigenvalue, not only the roll root (ours in aero order)
    names = lp.model.state_names
    for ours_idx, rep_idx in (([names.index(s) for s in ("beta_rad", "p_radps", "r_radps", "phi_rad")], LAT),
                              ([names.index(s) for s in ("vt_fps", "alpha_rad", "q_radps", "theta_rad")], LON)):
        a, b = _eigs(settled.A, rep_idx), _eigs(lp.model.A, ours_idx)
        assert np.all(np.abs(a - b) <= 0.005 * np.abs(b) + 1e-4), (a, b)


def test_the_difference_sits_in_the_beta_and_r_rows(runs) -> None:
    """Rows of FGLinearization's A put into the settled A: beta alone -1.161, r alone -0.981,
    p (the roll PID's D term) unchanged, beta + p + r exactly FGLinearization's root."""
    _, fg, settled, _ = runs
    base = _roll(settled.A)

    def with_rows(*names: str) -> float:
        A = settled.A.copy()
        rows = [X_NAMES.index(n) for n in names]
        A[rows] = fg.A[rows]
        return _roll(A)

    assert with_rows("Beta") < 1.10 * base  # -1.161
    assert with_rows("R") > 0.96 * base  # -0.981
    assert abs(with_rows("P") / base - 1) < 1e-3
    assert abs(with_rows("Beta", "P", "R") / _roll(fg.A) - 1) < 1e-9


def test_yaw_channel_values_across_passes() -> None:
    """The FCS signals pass by pass (f16.xml: yaw-load-pid kp 0.1055 kd 5e-5, roll-rate-pid kp 3
    kd -0.00125, both with the channel's fixed dt 1/120 s even at dt = 0)."""
    props = ("fcs/yaw-load-pid", "fcs/roll-rate-pid", "aero/betadot-rad_sec", "fcs/yaw-load-norm")
    dr = dp = db = 1e-4
    hr = pass_history(_trimmed(), "R", dr, props, n_runs=SETTLED)
    hp = pass_history(_trimmed(), "P", dp, props, n_runs=SETTLED)
    hb = pass_history(_trimmed(), "Beta", db, props, n_runs=SETTLED)
    dt = 1.0 / 120.0
    # D terms in the pass FGLinearization reads (row 1): (kp + kd/dt) / kp of the settled value
    assert hr[1, 0] / hr[-1, 0] == pytest.approx((0.1055 + 5e-5 / dt) / 0.1055, rel=2e-3)
    assert hp[1, 1] / hp[-1, 1] == pytest.approx((3.0 - 0.00125 / dt) / 3.0, rel=1e-3)
    # beta-dot there is the previous pass's: without the yaw damper's rudder, -cos(alpha)-like
    assert hr[1, 2] / dr == pytest.approx(-0.994, abs=0.002)
    assert hr[-1, 2] / dr == pytest.approx(-0.8625, abs=0.002)
    # n-pilot-y (yaw-load-norm) still the previous evaluation's in that pass, settled later
    assert abs(hb[1, 3] - hb[0, 3]) < 1e-9 < abs(hb[-1, 3] - hb[0, 3])


def test_rudder_path_not_roll_loop_carries_the_lateral_difference() -> None:
    """Write-protect one surface at its trim value and compare the two settings' lateral A:
    rudder held 0.27 (only the roll PID's D term on d p-dot / d p is left), aileron held 1.69,
    free 1.72 (Frobenius norm of the difference)."""
    diff = {}
    for hold in (None, "rudder", "aileron"):
        fg = fglin_replica(_trimmed(hold))
        settled = fglin_replica(_trimmed(hold), n_runs=SETTLED)
        diff[hold] = np.linalg.norm((fg.A - settled.A)[np.ix_(LAT, LAT)])
    assert diff[None] == pytest.approx(1.72, abs=0.02)
    assert diff["rudder"] < 0.2 * diff[None]
    assert diff["aileron"] > 0.9 * diff[None]


def test_replica_refuses_what_it_does_not_cover() -> None:
    with pytest.raises(DesignError, match="jet aircraft only"):
        fglin_replica(Aircraft("DHC6"))
    with pytest.raises(DesignError, match="n_runs"):
        fglin_replica(_trimmed(), n_runs=0)
    with pytest.raises(DesignError, match="unknown component"):
        pass_history(_trimmed(), "Gamma", 1e-4, ("fcs/yaw-load-pid",))

"""Iced grid points of the linearizer: the DHC-6 icing overlay trimmed and linearized per eta.

JSBSIM_NOTES 5.3 (running trim, own central differences): at 100 KIAS / 5000 ft the short period
goes from 2.93 to 2.66 rad/s with eta 0 -> 0.1, the dutch roll from 4.51 to 3.91 rad/s, roll
subsidence from -4.49 to -3.87 1/s; 120 KIAS with eta = 0.1 has not enough thrust.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft
from fdi_sim.linear.grid import parse_grid_spec
from fdi_sim.linear.linearize import linearize, linearize_grid
from fdi_sim.operating_point import OperatingPoint


def _mode(point, name: str) -> dict:
    return next(m for m in point.info["modes"] if m["name"] == name)


def test_iced_grid_trims_linearizes_and_reports_the_untrimmable_point() -> None:
    g = parse_grid_spec("h_ft=5000;vc_kts=100,120;icing_eta=0,0.05,0.1", "DHC6")
    s = linearize_grid(g, validate=False)
    status = {(p.op.vc_kts, p.op.icing_eta): p for p in s.points}
    assert [p.status for p in s.points] == ["ok"] * 5 + ["untrimmable"]
    bad = status[(120.0, 0.1)]
    assert "throttle_cmd_norm = 1.000 at its limit" in bad.reason  # not enough thrust
    assert s.names["input_names"][-1] == "icing_eta"  # every point flew the overlay: one signal set
    for vc, etas in ((100.0, (0.0, 0.05, 0.1)), (120.0, (0.0, 0.05))):
        pts = [status[(vc, e)] for e in etas]
        assert [p.sched["icing_eta"] for p in pts] == list(etas)
        thr = [p.trim["throttle_cmd_norm"] for p in pts]
        sp = [_mode(p, "short period")["wn_radps"] for p in pts]
        dr = [_mode(p, "dutch roll")["wn_radps"] for p in pts]
        roll = [_mode(p, "roll")["re"] for p in pts]
        assert np.all(np.diff(thr) > 0.04), thr          # ice costs power
        assert np.all(np.diff(sp) < 0), sp               # less pitch stiffness: slower short period
        assert np.all(np.diff(dr) < 0), dr               # less Cn_beta: slower dutch roll
        assert np.all(np.diff(roll) > 0), roll           # less roll damping
    p0, p1 = status[(100.0, 0.0)], status[(100.0, 0.1)]
    assert _mode(p0, "short period")["wn_radps"] == pytest.approx(2.93, abs=0.03)
    assert _mode(p1, "short period")["wn_radps"] == pytest.approx(2.66, abs=0.03)
    assert _mode(p0, "dutch roll")["wn_radps"] == pytest.approx(4.51, abs=0.05)
    assert _mode(p1, "dutch roll")["wn_radps"] == pytest.approx(3.91, abs=0.05)
    assert _mode(p0, "roll")["re"] == pytest.approx(-4.49, abs=0.05)
    assert _mode(p1, "roll")["re"] == pytest.approx(-3.87, abs=0.05)


def test_icing_eta_column_is_the_drag_of_the_iced_cd0() -> None:
    """B[vt, icing_eta] at the trim is mostly the CD0 increment per unit eta,
    dVt/dt = -qbar S k_CD0 CD0(alpha) / m; the lift lost at fixed alpha lowers the induced drag
    (CDi = 0.039 CL^2) and takes about 7 % off that, hence the 10 % tolerance."""
    ac = Aircraft("DHC6", icing=True)
    lp = linearize(ac, OperatingPoint("DHC6", 5000.0, vc_kts=100.0, icing_eta=0.05))
    m = lp.model
    assert lp.status == "ok" and m is not None
    j = m.input_names.index("icing_eta")
    assert m.input_kinds[j] == "disturbance"
    cd0 = ac["aero/coefficient/CD0"] / (ac["aero/qbar-psf"] * ac["metrics/Sw-sqft"])
    expected = -ac["aero/qbar-psf"] * ac["metrics/Sw-sqft"] * ac["icing/k-CD0"] * cd0 / ac["inertia/mass-slugs"]
    dvt = m.B[m.state_names.index("vt_fps"), j]
    assert dvt == pytest.approx(expected, rel=0.10)
    assert m.B[m.state_names.index("q_radps"), j] != 0.0  # ice also changes the pitch moment


def test_failed_trim_without_a_limit_reports_its_best_point() -> None:
    """2000 ft / 120 KCAS with eta 0.1: the Newton trim stops without any command at its stop;
    the reason then gives the best point it found (measured: throttle 0.936, residual 0.79)."""
    from fdi_sim.aircraft import trim
    from fdi_sim.errors import TrimError

    ac = Aircraft("DHC6", icing=True)
    with pytest.raises(TrimError) as e:
        trim(ac, OperatingPoint("DHC6", 2000.0, vc_kts=120.0, icing_eta=0.1))
    msg = str(e.value)
    assert "residual" in msg and "best point (no command at its limit): alpha" in msg
    assert "throttle_cmd_norm 0.9" in msg and "pitch_trim_cmd_norm" in msg

"""Grid files, specs, envelope checks and the standard atmosphere behind them."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdi_sim.aircraft.linearize_state import CONTROL_INPUTS, GUST_INPUTS, OPTIONAL_DISTURBANCES
from fdi_sim.errors import DesignError
from fdi_sim.isa import isa, vc_from_vt, vt_from_vc
from fdi_sim.linear.grid import default_grid_path, load_grid, parse_grid_spec, resolve_grid

# U.S. Standard Atmosphere 1976 (English units table): h ft, T degR, p lbf/ft^2, rho slug/ft^3, a ft/s
STD_ATM = [
    (0.0, 518.67, 2116.2, 0.0023769, 1116.4),
    (10000.0, 483.04, 1455.6, 0.0017556, 1077.4),
    (20000.0, 447.43, 972.5, 0.0012673, 1036.9),
    (30000.0, 411.84, 629.7, 0.00089068, 994.8),
    (40000.0, 389.97, 393.1, 0.00058727, 968.1),
]


@pytest.mark.parametrize("h, T, p, rho, a", STD_ATM)
def test_isa_against_the_1976_table(h: float, T: float, p: float, rho: float, a: float) -> None:
    atm = isa(h)
    assert atm.temperature_R == pytest.approx(T, rel=1e-3)
    assert atm.pressure_psf == pytest.approx(p, rel=5e-3)
    assert atm.density_slugft3 == pytest.approx(rho, rel=5e-3)
    assert atm.sound_speed_fps == pytest.approx(a, rel=1e-3)


def test_calibrated_equals_true_at_sea_level() -> None:
    vc, mach = vc_from_vt(0.0, 300.0)
    assert vc == pytest.approx(300.0, rel=1e-12)
    assert mach == pytest.approx(300.0 * 1.6878099 / 1116.4267, rel=1e-6)


@given(h=st.floats(0, 40000), vc=st.floats(60, 600))
@settings(max_examples=50, deadline=None)
def test_vc_vt_round_trip(h: float, vc: float) -> None:
    vt, mach = vt_from_vc(h, vc)
    assert vt >= vc - 1e-9  # true airspeed is never below calibrated above sea level
    vc2, mach2 = vc_from_vt(h, vt)
    assert vc2 == pytest.approx(vc, rel=1e-9)
    assert mach2 == pytest.approx(mach, rel=1e-9)


def test_default_grids_meet_the_issue_sizes() -> None:
    f16 = load_grid(default_grid_path("f16"), "f16")
    assert len({p.h_ft for p in f16.points}) >= 4 and len({p.vt_kts for p in f16.points}) >= 5
    assert len(f16.points) >= 20
    dhc6 = load_grid(default_grid_path("DHC6"), "DHC6")
    flaps = {p.flaps_deg for p in dhc6.points}
    assert len({p.h_ft for p in dhc6.points}) >= 3 and len(flaps) >= 2
    for f in flaps:
        assert len({p.vc_kts for p in dhc6.points if p.flaps_deg == f}) >= 5
    for g in (f16, dhc6):  # every model input has a doublet amplitude
        assert {"elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm",
                "u_gust_body_fps", "v_gust_body_fps", "w_gust_body_fps"} <= set(g.validation.amplitudes)


def test_spec_ranges_and_icing_axis() -> None:
    g = parse_grid_spec("h_ft=5000,10000;vt_kts=350:430:20", "f16")
    assert len(g.points) == 10 and sorted({p.vt_kts for p in g.points}) == [350, 370, 390, 410, 430]
    d = resolve_grid("h_ft=5000;vc_kts=100;icing_eta=0,0.05,0.1", "DHC6")
    assert [p.icing_eta for p in d.points] == [0.0, 0.05, 0.1]


@pytest.mark.parametrize("spec, match", [
    ("h_ft=10000;vt_kts=600", "outside the linearization envelope"),   # M 0.94
    ("h_ft=10000;vt_kts=200", "outside the linearization envelope"),   # below 250 KCAS: flaps deploy
    ("h_ft=10000;vt_kts=350;icing_eta=0.1", "icing_eta"),               # no F-16 icing model
    ("h_ft=10000;mach=0.6", "unknown axis"),
    ("h_ft=10000;vt_kts=400:300:10", "start:stop:step"),
    ("h_ft=10000", "exactly one of vt_kts, vc_kts"),
    ("h_ft 10000", "axis=values"),
])
def test_bad_specs_are_refused(spec: str, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        parse_grid_spec(spec, "f16")


def test_bad_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DesignError, match="not found"):
        load_grid(tmp_path / "none.toml")
    bad = tmp_path / "g.toml"
    bad.write_text('aircraft = "DHC6"\n[[block]]\nh_ft = [5000]\nvc_kts = [120]\n')
    with pytest.raises(DesignError, match="is for aircraft 'DHC6'"):
        load_grid(bad, "f16")
    bad.write_text('aircraft = "f16"\nspeed = 3\n[[block]]\nh_ft = [5000]\nvt_kts = [400]\n')
    with pytest.raises(DesignError, match="unknown top-level"):
        load_grid(bad)
    bad.write_text('aircraft = "f16"\n[[block]\n')
    with pytest.raises(DesignError, match="g.toml"):
        load_grid(bad)


@pytest.mark.parametrize("table, match", [
    ("[validation]\nduraton_s = 5.0\n", "unknown \\[validation\\] keys \\['duraton_s'\\]"),
    ("[validation]\nduration_s = -1.0\n", "validation.duration_s = -1 s"),
    ("[validation]\nwidth_s = 'long'\n", "validation.width_s must be a number"),
    ("[validation.amplitudes]\nelevator_cmd_norm = [0.01, 0.02]\n", "validation.amplitudes.elevator_cmd_norm"),
])
def test_validation_table_is_strict(tmp_path: Path, table: str, match: str) -> None:
    g = tmp_path / "g.toml"
    g.write_text('aircraft = "f16"\n[[block]]\nh_ft = [10000]\nvt_kts = [400]\n' + table)
    with pytest.raises(DesignError, match=match):
        load_grid(g)


def test_validation_defaults_and_values() -> None:
    v = load_grid(default_grid_path("DHC6"), "DHC6").validation
    assert (v.duration_s, v.width_s, v.start_s) == (10.0, 1.0, 0.5)
    assert v.amplitudes["aileron_cmd_norm"] == 0.004


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_validation_tables_cover_every_model_input(aircraft: str) -> None:
    """default_doublets refuses a model input without an amplitude, so each shipped table names every
    command and gust; the DHC-6 one also the icing direction its iced grids carry (icing/eta overlay)."""
    amps = load_grid(default_grid_path(aircraft), aircraft).validation.amplitudes
    need = set(CONTROL_INPUTS + GUST_INPUTS) | (set(OPTIONAL_DISTURBANCES) if aircraft == "DHC6" else set())
    assert need <= set(amps), need - set(amps)
    assert all(a > 0 for a in amps.values())

"""The icing overlay on real JSBSim (issue 3, icing bars at the aircraft level).

C_iced = C (1 + eta k) (Bragg et al., AIAA 2000-0360) through ``icing/eta`` and ``icing/k-<X>``;
the k are the UIUC Twin Otter values (aircraft/DHC6/icing.toml) and generic ones for the F-16.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft, overlays, trim
from fdi_sim.aircraft.icing import (
    ICED_MODELS, IcingDataError, _parse_table, data_path, eta_max, icing_data, k_values, regions,
)
from fdi_sim.aircraft.overlays import jsbsim_root
from fdi_sim.errors import FdiSimError, TrimError
from fdi_sim.operating_point import OperatingPoint

DHC6_100 = OperatingPoint("DHC6", 5000.0, vc_kts=100.0)
F16_400 = OperatingPoint("f16", 10000.0, vt_kts=400.0)
CLEAN_POINTS = {"DHC6": DHC6_100, "f16": F16_400}
ETA = 0.1
_STATE = ("position/h-sl-ft", "velocities/vt-fps", "aero/alpha-rad", "aero/beta-rad", "attitude/phi-rad",
          "attitude/theta-rad", "attitude/psi-rad", "velocities/p-rad_sec", "velocities/q-rad_sec",
          "velocities/r-rad_sec", "fcs/elevator-pos-rad", "accelerations/n-pilot-z-norm")


def _at(op: OperatingPoint, eta: float) -> OperatingPoint:
    return OperatingPoint(op.aircraft, op.h_ft, vt_kts=op.vt_kts, vc_kts=op.vc_kts, icing_eta=eta)


def _table(aircraft: str, function: str) -> ET.Element:
    """The one ``<table>`` of an aero function of the (clean) model in the patched JSBSim root."""
    root = ET.parse(jsbsim_root() / "aircraft" / aircraft / f"{aircraft}.xml").getroot()
    fn = next(f for f in root.iter("function") if f.get("name") == function)
    return fn.find("product/table")


def _elevator_doublet(ac: Aircraft, amp_norm: float, width_s: float, start_s: float, duration_s: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fly an elevator doublet about the trim, other controls fixed: time [s], q [rad/s], elevator [rad]."""
    e0 = ac["fcs/elevator-cmd-norm"]
    n = int(round(duration_s / ac.dt_s))
    t, q, de = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        ts = k * ac.dt_s + 1e-9
        first, second = start_s <= ts < start_s + width_s, start_s + width_s <= ts < start_s + 2 * width_s
        ac["fcs/elevator-cmd-norm"] = e0 + (amp_norm if first else -amp_norm if second else 0.0)
        ac.step()
        t[k], q[k], de[k] = ac.t_s, ac["velocities/q-rad_sec"], ac["fcs/elevator-pos-rad"]
    return t, q, de


# ---------------------------------------------------------------------- data and properties
def test_icing_data_files() -> None:
    for name in ("DHC6", "f16"):
        d = icing_data(name)
        assert regions(name) == ("all", "tail", "wing")
        assert 0.0 < eta_max(name) <= 0.4  # UIUC files: "do not set higher than about 0.4"
        assert len(d.k_names) == 16 and all(d.uiuc_names[k].startswith("k") for k in d.k_names)
        for r in regions(name):
            assert set(k_values(name, r)) == set(d.k_names)
        # icing degrades: more drag, less lift slope, stiffness, control power and damping
        k = k_values(name, "all")
        assert k["CD0"] > 0 and all(v < 0 for n, v in k.items() if n != "CD0")
    assert icing_data("f16").generic and not icing_data("DHC6").generic
    # the UIUC Twin Otter values of JSBSIM_NOTES 5.2 (AllIce column), spot checks
    assert k_values("DHC6")["CmDe"] == -1.48148 and k_values("DHC6")["CD0"] == 6.52696
    assert k_values("DHC6", "tail")["CmDe"] == -1.24756 and k_values("DHC6", "wing")["CLalpha"] == -0.83259
    with pytest.raises(IcingDataError, match="Did you mean 'tail'"):
        k_values("DHC6", "tale")
    with pytest.raises(IcingDataError, match="no icing overlay"):
        k_values("C172", "all")


@pytest.mark.parametrize("name", ["DHC6", "f16"])
def test_k_properties_as_documented(name: str) -> None:
    """Defaults = whole-aircraft k of the data file (a stale overlay cache fails here); k survive a
    JSBSim reset (persistent), eta goes back to clean."""
    ac = Aircraft(name, icing=True)
    assert ac["icing/eta"] == 0.0
    for x, v in k_values(name, "all").items():
        assert ac[f"icing/k-{x}"] == v, x
    pm = ac.fdm.get_property_manager()
    assert all(pm.hasNode(t.increment) for t in icing_data(name).terms)
    tail = k_values(name, "tail")
    ac.set_icing_k(tail)
    ac.icing_writer()(0.25)
    ac.fdm.reset_to_initial_conditions(0)
    assert ac["icing/eta"] == 0.0
    assert all(ac[f"icing/k-{x}"] == v for x, v in tail.items())
    assert not Aircraft(name).fdm.get_property_manager().hasNode("icing/eta")  # the clean model has none
    assert ICED_MODELS[name] == f"{name}_iced"


def test_overlay_cache_key_follows_the_icing_data(tmp_path, monkeypatch) -> None:
    """The JSBSim root is keyed on the contents of each builder's data file: the same bytes elsewhere
    give the same root, an edited k a new one (else a stale iced model would keep the old k)."""
    build = overlays.GENERATORS[ICED_MODELS["DHC6"]]
    assert tuple(build.data_files) == (data_path("DHC6"),)
    before = overlays._fingerprint()
    copy = tmp_path / "icing.toml"
    copy.write_bytes(data_path("DHC6").read_bytes())
    monkeypatch.setattr(build, "data_files", (copy,))
    assert overlays._fingerprint() == before
    copy.write_text(copy.read_text().replace("CmDe = -1.48148", "CmDe = -1.5", 1))
    assert overlays._fingerprint() != before


# ---------------------------------------------------------------------- eta = 0 is the clean model
@pytest.mark.parametrize("name", ["DHC6", "f16"])
def test_eta_zero_flies_exactly_as_clean(name: str) -> None:
    op = CLEAN_POINTS[name]
    runs = []
    for iced in (False, True):
        ac = Aircraft(name, icing=iced)
        tr = trim(ac, op)
        states = []
        for k in range(int(8.0 / ac.dt_s)):  # an elevator and an aileron pulse, then free
            t = k * ac.dt_s
            ac["fcs/elevator-cmd-norm"] = tr.elevator_cmd_norm + (0.05 if 1.0 <= t < 2.0 else 0.0)
            ac["fcs/aileron-cmd-norm"] = tr.aileron_cmd_norm + (0.05 if 3.0 <= t < 3.5 else 0.0)
            ac.step()
            states.append([ac[p] for p in _STATE])
        runs.append((tr, np.array(states)))
    (tc, xc), (ti, xi) = runs
    assert ti.throttle_cmd_norm == pytest.approx(tc.throttle_cmd_norm, abs=1e-12)
    assert ti.alpha_rad == pytest.approx(tc.alpha_rad, abs=1e-12)
    assert np.ptp(xc[:, _STATE.index("velocities/q-rad_sec")]) > 0.01  # the pulses did move the aircraft
    np.testing.assert_allclose(xi, xc, rtol=0.0, atol=1e-12)


# ---------------------------------------------------------------------- which part each k scales
def test_dhc6_increments_scale_the_documented_parts() -> None:
    ac = Aircraft("DHC6", icing=True)
    trim(ac, _at(DHC6_100, ETA))
    ac.step()
    qS, b, c = ac["aero/qbar-psf"] * ac["metrics/Sw-sqft"], ac["metrics/bw-ft"], ac["metrics/cbarw-ft"]
    k = k_values("DHC6")
    for term in icing_data("DHC6").terms:
        inc, base = ac[term.increment], ac[term.function]
        if term.part == "whole":  # C_iced = C (1 + eta k): the increment is eta k C
            assert inc == pytest.approx(ETA * k[term.k_name] * base, rel=1e-12, abs=1e-9), term
    # lift and pitch-moment tables: only the part that changes with alpha (kCZo = kCmo = 0)
    cl0 = _parse_table(_table("DHC6", "aero/coefficient/CLalpha")).at_zero("aero/alpha-rad")
    cm0 = _parse_table(_table("DHC6", "aero/coefficient/Cma")).at_zero("aero/alpha-rad")
    assert (cl0, cm0) == (0.44, 0.093)
    assert ac["aero/coefficient/CLalpha_ice"] == pytest.approx(
        ETA * k["CLalpha"] * (ac["aero/coefficient/CLalpha"] - qS * cl0), rel=1e-12)
    assert ac["aero/coefficient/Cma_ice"] == pytest.approx(
        ETA * k["Cma"] * (ac["aero/coefficient/Cma"] - qS * c * cm0), rel=1e-12)
    # Clb is a table of Cl(beta, alpha), non-zero at beta = 0 above alpha 4 deg: only the beta part is iced
    ac["ic/alpha-deg"], ac["ic/beta-deg"] = 12.0, 2.0
    ac.fdm.run_ic()
    alpha = ac["aero/alpha-rad"]
    clb_beta0 = _parse_table(_table("DHC6", "aero/coefficient/Clb")).at_zero("aero/beta-rad")
    cl_at_beta0 = float(np.interp(alpha, clb_beta0.rows, clb_beta0.values))
    assert abs(cl_at_beta0) > 1e-3  # the point is where the subtraction matters
    qS = ac["aero/qbar-psf"] * ac["metrics/Sw-sqft"]
    assert ac["aero/coefficient/Clb_ice"] == pytest.approx(
        ETA * k["Clb"] * (ac["aero/coefficient/Clb"] - qS * b * cl_at_beta0), rel=1e-9)


def test_f16_split_tables_add_up() -> None:
    """The F-16 tables CLDh(alpha, de), CmDh(alpha, de) are split into an alpha part and an elevator
    part; with the two k equal they add up to the whole table minus its zero value."""
    ac = Aircraft("f16", icing=True)
    trim(ac, _at(F16_400, ETA))
    ac["fcs/elevator-cmd-norm"] = -0.3  # move the stabilator well off zero (FBW pitch command)
    for _ in range(60):
        ac.step()
    assert abs(ac["fcs/elevator-pos-rad"]) > 0.02
    qS = ac["aero/qbar-psf"] * ac["metrics/Sw-sqft"]
    k = k_values("f16")
    cl00 = _parse_table(_table("f16", "aero/coefficient/CLDh")).at_zero("fcs/elevator-pos-rad").at_zero("aero/alpha-rad")
    cm00 = _parse_table(_table("f16", "aero/coefficient/CmDh")).at_zero("fcs/elevator-pos-rad").at_zero("aero/alpha-rad")
    cd00 = _parse_table(_table("f16", "aero/coefficient/CDDh")).at_zero("fcs/elevator-pos-rad").at_zero("aero/alpha-rad")
    lift = ac["aero/coefficient/CLDh_ice_CLalpha"] / k["CLalpha"] + ac["aero/coefficient/CLDh_ice_CLde"] / k["CLde"]
    assert lift == pytest.approx(ETA * (ac["aero/coefficient/CLDh"] - qS * ac["aero/function/kCLge"] * cl00), rel=1e-9)
    pitch = ac["aero/coefficient/CmDh_ice_Cma"] / k["Cma"] + ac["aero/coefficient/CmDh_ice_CmDe"] / k["CmDe"]
    c = ac["metrics/cbarw-ft"]
    assert pitch == pytest.approx(ETA * (ac["aero/coefficient/CmDh"] - qS * c * cm00), rel=1e-9)
    assert ac["aero/coefficient/CDDh_ice"] == pytest.approx(ETA * k["CD0"] * qS * cd00, rel=1e-12)
    assert ac["aero/coefficient/CLDh_ice_CLde"] != 0.0 and ac["aero/coefficient/CmDh_ice_CmDe"] != 0.0


def _pitch_control_power(ac: Aircraft, d_norm: float = 0.01) -> float:
    """dM_aero / d(elevator command) at the current initial condition, evaluated at dt = 0 [lbf ft]."""
    e0 = ac["fcs/elevator-cmd-norm"]
    m = []
    for d in (d_norm, -d_norm):
        ac["fcs/elevator-cmd-norm"] = e0 + d
        ac.fdm.set_trim_status(True)
        ac.fdm.run_ic()  # the elevator actuator jumps to the command
        ac.fdm.set_trim_status(False)
        m.append(ac["moments/m-aero-lbsft"])
    ac["fcs/elevator-cmd-norm"] = e0
    return (m[0] - m[1]) / (2 * d_norm)


def test_tail_ice_cuts_elevator_power_more_than_wing_ice() -> None:
    """Regions: tail ice takes 12.5 % of the pitch control power at eta 0.1, wing ice 2.7 %; wing ice
    takes more lift slope than tail ice (UIUC TailIce / WingIce files)."""
    ac = Aircraft("DHC6", icing=True)
    trim(ac, DHC6_100)  # clean trim; icing switched on at the same state
    ratio, lift = {}, {}
    for region in ("all", "tail", "wing"):
        ac.set_icing_k(k_values("DHC6", region))
        ac.icing_writer()(0.0)
        clean = _pitch_control_power(ac)
        ac.icing_writer()(ETA)
        ratio[region] = _pitch_control_power(ac) / clean
        lift[region] = ac["aero/coefficient/CLalpha_ice"]
    k_de = {r: k_values("DHC6", r)["CmDe"] for r in ratio}
    assert ratio["tail"] < ratio["wing"] < 1.0
    for r in ratio:  # elevator power follows Cm_de (CL_de acts at the small CG-to-reference arm)
        assert ratio[r] == pytest.approx(1.0 + ETA * k_de[r], abs=0.01), (r, ratio[r])
    assert lift["wing"] < lift["tail"] < 0.0  # lift lost at this alpha: wing more than tail


# ---------------------------------------------------------------------- the bars
def test_trim_with_ice_at_100_kias() -> None:
    """Whole-aircraft eta = 0.1 at 100 KIAS, 5000 ft raises the trim throttle (JSBSIM_NOTES 5.3:
    0.695 -> 0.806, alpha 3.41 -> 3.82 deg)."""
    ac = Aircraft("DHC6", icing=True)
    clean = trim(ac, DHC6_100)
    iced = trim(ac, _at(DHC6_100, ETA))
    assert ac["icing/eta"] == ETA
    assert clean.throttle_cmd_norm == pytest.approx(0.695, abs=0.005)
    assert iced.throttle_cmd_norm == pytest.approx(0.806, abs=0.005)
    assert np.degrees(iced.alpha_rad) == pytest.approx(3.82, abs=0.05)
    assert iced.alpha_rad > clean.alpha_rad and iced.pitch_trim_cmd_norm > clean.pitch_trim_cmd_norm
    # and it flies: 30 s with fixed controls stays level
    h0 = ac["position/h-sl-ft"]
    for _ in range(int(30.0 / ac.dt_s)):
        ac.step()
    assert abs(ac["position/h-sl-ft"] - h0) < 20.0 and abs(ac["velocities/vc-kts"] - 100.0) < 1.0


def test_elevator_doublet_pitch_response_drops_10_to_20_percent() -> None:
    """Bar: eta = 0.1 cuts the pitch response to an elevator doublet by 10-20 %.

    Response: peak-to-peak pitch rate q over a +-0.01 elevator-command doublet of 2 x 0.5 s, each
    aircraft trimmed at 100 KIAS / 5000 ft at its eta, other controls fixed. The amplitude is small on
    purpose: the DHC-6 elevator scale is 0.244 rad per unit up and 0.454 down, and the iced trim sits
    at a different command, so a larger doublet would move the clean and iced surfaces by different
    angles. Here both surfaces move by the same angle (checked), so the drop is the aerodynamics.
    The drop measured is quoted in docs/icing.md (a past measurement with its commit); the bound
    below is the issue's bar, not that value.
    """
    resp = {}
    for eta in (0.0, ETA):
        ac = Aircraft("DHC6", icing=True)
        trim(ac, _at(DHC6_100, eta))
        de0 = ac["fcs/elevator-pos-rad"]
        t, q, de = _elevator_doublet(ac, 0.01, 0.5, 1.0, 3.0)
        window = (t >= 1.0) & (t <= 2.0 + 1e-9)
        resp[eta] = (float(np.ptp(q[window])), de - de0)
    (p_clean, de_clean), (p_iced, de_iced) = resp[0.0], resp[ETA]
    np.testing.assert_allclose(de_iced, de_clean, atol=1e-9)  # same surface motion
    drop = 1.0 - p_iced / p_clean
    assert 0.10 <= drop <= 0.20, f"pitch-rate response drop {drop:.3f}"


def test_iced_trim_needs_the_overlay() -> None:
    clean = Aircraft("DHC6")
    with pytest.raises(TrimError, match="icing=True"):
        trim(clean, _at(DHC6_100, ETA))
    with pytest.raises(FdiSimError, match="icing=True"):  # the clean model has no icing/eta to write
        clean.icing_writer()
    with pytest.raises(FdiSimError, match="icing=True"):
        clean.set_icing_k(k_values("DHC6", "tail"))


def test_f16_generic_ice_costs_thrust() -> None:
    ac = Aircraft("f16", icing=True)
    clean = trim(ac, F16_400)
    iced = trim(ac, _at(F16_400, ETA))
    assert iced.throttle_cmd_norm > clean.throttle_cmd_norm + 0.02  # CD0 +65 % at eta 0.1
    assert iced.alpha_rad > clean.alpha_rad  # less lift slope

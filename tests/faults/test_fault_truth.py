"""Issue 3 bars: fault truth in the log matches the scenario to the step; intermittent faults from
the same seed repeat exactly; engines and the throttle; bad fault input."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import fly
from fdi_sim.errors import ScenarioError
from fdi_sim.faults.profile import ProfileParams, make_profile
from fdi_sim.scenario import from_dict

DT_S = 1.0 / 120.0


def test_truth_matches_the_scenario_to_the_step(tmp_path: Path) -> None:
    faults = [
        {"type": "sensor-bias-v1", "target": "q_radps", "bias_degps": 0.5, "t_start_s": 1.0, "t_end_s": 2.5},
        {"type": "actuator-bias-v1", "target": "elevator", "bias_deg": 0.5, "t_start_s": 1.5, "ramp_s": 1.0},
        {"type": "sensor-bias-v1", "target": "p_radps", "bias_degps": 0.5, "t_start_s": 0.5,
         "intermittent": {"windows_s": [[0.5, 1.0], [2.0, 2.25], [3.0, 3.5]]}},
    ]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=4.0)
    f = run["/faults/active"]
    t = f["t_s"]
    k = np.arange(len(t))
    np.testing.assert_array_equal(t, k * DT_S)
    # onset and clear at the first step at or after the scenario times, exactly
    np.testing.assert_array_equal(f["q_radps_bias_active"], ((k >= 120) & (k < 300)).astype(float))
    np.testing.assert_array_equal(f["elevator_bias_active"], (k >= 180).astype(float))
    on_p = np.zeros(len(k), bool)
    for a, b in ((0.5, 1.0), (2.0, 2.25), (3.0, 3.5)):
        on_p |= (k >= round(a * 120)) & (k < round(b * 120))
    np.testing.assert_array_equal(f["p_radps_bias_active"], on_p.astype(float))
    # ramp-in: level (t - 1.5)/1.0, error = level x bias
    lvl = np.clip((t - 1.5) / 1.0, 0.0, 1.0)
    np.testing.assert_allclose(f["elevator_bias_level"][k > 180], lvl[k > 180], atol=1e-12)
    np.testing.assert_allclose(f["elevator_bias_error"][k > 180], lvl[k > 180] * math.radians(0.5), atol=1e-12)
    # the events topic lists the catalogue, then every onset and clear at its step
    ev = run["log"].topics["/faults/events"].events
    assert ev[0].payload["event"] == "catalog" and len(ev[0].payload["faults"]) == 3
    q = [(e.t_s, e.payload["event"]) for e in ev if e.payload.get("label") == "q_radps_bias"]
    assert q == [(pytest.approx(1.0), "onset"), (pytest.approx(2.5), "clear")]
    assert "faults" in run["log"].metadata


def _random_windows(tmp_path: Path, seed: int) -> np.ndarray:
    faults = [{"type": "sensor-dropout-v1", "target": "alpha_rad", "t_start_s": 1.0,
               "intermittent": {"duty_cycle": 0.3, "mean_dwell_s": 0.4}}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=12.0, seed=seed)
    return run["/faults/active"]["alpha_rad_dropout_active"], run["/sensors/measurements"]["alpha_rad"]


def test_intermittent_faults_repeat_exactly_from_the_seed(tmp_path: Path) -> None:
    a1, y1 = _random_windows(tmp_path, 5)
    a2, y2 = _random_windows(tmp_path, 5)
    a3, _ = _random_windows(tmp_path, 6)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(y1, y2)
    assert not np.array_equal(a1, a3)
    assert np.count_nonzero(np.diff(a1) == 1) >= 3  # really intermittent
    duty = a1[120:].mean()
    assert 0.1 < duty < 0.6


def test_random_intermittency_has_the_duty_cycle_and_dwell() -> None:
    p = ProfileParams(t_start_s=0.0, intermittent={"duty_cycle": 0.25, "mean_dwell_s": 2.0})
    prof = make_profile(p, 20000.0, np.random.default_rng(1))
    on = np.array([b - a for a, b in prof.windows])
    assert on.mean() == pytest.approx(2.0, rel=0.05)
    assert on.sum() / 20000.0 == pytest.approx(0.25, rel=0.05)


def test_adding_a_fault_changes_neither_noise_nor_turbulence(tmp_path: Path) -> None:
    atm = {"turbulence": "light"}
    a = fly(tmp_path, "DHC6", duration_s=3.0, atmosphere=atm)
    b = fly(tmp_path, "DHC6", duration_s=3.0, atmosphere=atm,
            faults=[{"type": "sensor-bias-v1", "target": "r_radps", "bias_degps": 1.0, "t_start_s": 2.9}])
    np.testing.assert_array_equal(a["/sensors/measurements"].data[:300], b["/sensors/measurements"].data[:300])
    np.testing.assert_array_equal(a["/truth/state"].data[:300], b["/truth/state"].data[:300])


def _thrust(run: dict, t_on_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(t_s [s], total thrust [lbf], its mean before the onset ``t_on_s`` [lbf]) of a run."""
    s = run["/truth/surfaces"]
    t, thrust = s["t_s"], s["thrust_lbf"]
    return t, thrust, float(thrust[t < t_on_s].mean())


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_engine_flameout_and_relight(aircraft: str, tmp_path: Path) -> None:
    faults = [{"type": "engine-flameout-v1", "target": "engine_0", "t_start_s": 1.0, "t_end_s": 6.0}]
    run = fly(tmp_path, aircraft, faults=faults, duration_s=40.0)
    t, thrust, t0 = _thrust(run, 1.0)
    assert thrust[(t > 4.0) & (t < 6.0)].mean() < (0.05 if aircraft == "f16" else 0.55) * t0  # one of two engines
    assert thrust[t > 35.0].mean() > 0.8 * t0  # relit (airstart takes seconds)
    if aircraft == "DHC6":  # asymmetric thrust yaws the aircraft toward the dead (left) engine
        x = run["/truth/state"]
        assert x["r_radps"][(x["t_s"] > 2.0) & (x["t_s"] < 6.0)].mean() < 0.0


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_thrust_loss(aircraft: str, tmp_path: Path) -> None:
    faults = [{"type": "engine-thrust-loss-v1", "target": "engine_0", "loss": 0.5, "t_start_s": 1.0}]
    run = fly(tmp_path, aircraft, faults=faults, duration_s=8.0)
    t, thrust, t0 = _thrust(run, 1.0)
    late = thrust[(t > 6.0)].mean() / t0
    if aircraft == "f16":  # exact: thrust x cos(reverser angle) = 0.5 x thrust
        assert late == pytest.approx(0.5, abs=0.03)
    else:  # power lever of one of two engines at half: total thrust falls, not to half
        assert 0.55 < late < 0.95


def test_throttle_stuck_holds_the_lever_against_the_autothrottle(tmp_path: Path) -> None:
    maneuvers = [{"type": "airspeed-v1", "t_start_s": 2.0, "vc_kts": 110.0, "rate_ktps": 2.0}]
    faults = [{"type": "actuator-stuck-v1", "target": "throttle", "position_norm": 0.9, "t_start_s": 1.0}]
    run = fly(tmp_path, "DHC6", faults=faults, maneuvers=maneuvers, duration_s=10.0, autopilot=True)
    s, c = run["/truth/surfaces"], run["/commands/pilot"]
    on = s["t_s"] >= 1.0
    np.testing.assert_allclose(s["throttle_pos_norm"][on], 0.9, atol=1e-12)
    assert c["throttle_cmd_norm"][c["t_s"] > 8.0].mean() < 0.85  # the autothrottle asks for less, in vain


BASE = {"name": "b", "aircraft": "DHC6", "duration_s": 30.0, "initial": {"h_ft": 5000.0, "vc_kts": 120.0}}


def _load(*faults: dict, **top) -> None:
    from_dict({**BASE, **top, "faults": list(faults)}, "bad.toml")


@pytest.mark.parametrize("fault,key,words", [
    ({"type": "actuator-stuck-v1", "target": "flaperon", "t_start_s": 1}, "faults[0].target", "elevator, aileron, rudder, throttle"),
    ({"type": "sensor-bias-v1", "target": "tas_kts", "bias_kts": 1, "t_start_s": 1}, "faults[0].target", "vc_kts"),
    ({"type": "engine-flameout-v1", "target": "engine_2", "t_start_s": 1}, "faults[0].target", "engine_0, engine_1"),
    ({"type": "actuator-float-v1", "target": "throttle", "t_start_s": 1}, "faults[0].target", "rudder"),
    ({"type": "sensor-bias-v1", "target": "vc_kts", "bias_deg": 1, "t_start_s": 1}, "faults[0].bias_deg", "bias_kts"),
    ({"type": "actuator-bias-v1", "target": "elevator", "bias_norm": 1, "t_start_s": 1}, "faults[0].bias_norm", "bias_deg"),
    ({"type": "sensor-bias-v1", "target": "vc_kts", "bias": 1, "t_start_s": 1}, "faults[0]", "bias_<unit>"),
    ({"type": "sensor-drift-v1", "target": "vc_kts", "drift_kps": 1, "t_start_s": 1}, "faults[0]",
     "did you mean drift_ktps? drift_<unit> takes on vc_kts (kts per second) one of: fps2, ktps, mps2, g"),
    ({"type": "actuator-bias-v1", "target": "elevator", "bias_dge": 1, "t_start_s": 1}, "faults[0]",
     "did you mean bias_deg?"),
    ({"type": "sensor-bias-v1", "target": "vc_kts", "bias_kts": 1, "t_start_s": 5, "t_end_s": 2}, "faults[0]", "after t_start_s"),
    ({"type": "sensor-bias-v1", "target": "vc_kts", "bias_kts": 1, "t_start_s": 40}, "faults[0].t_start_s", "after the run ends"),
    ({"type": "actuator-runaway-v1", "target": "rudder", "rate_degps": 0, "t_start_s": 1}, "faults[0].rate", "non-zero"),
    ({"type": "actuator-stuck-v1", "target": "elevator"}, "faults[0].t_start_s", "missing"),
    ({"type": "sensor-bias-v1", "target": "vc_kts", "bias_kts": 1, "t_start_s": 1,
      "intermittent": {"duty_cycle": 0.5}}, "faults[0]", "mean_dwell_s"),
])
def test_bad_fault_input_names_file_key_and_fix(fault: dict, key: str, words: str) -> None:
    with pytest.raises(ScenarioError) as e:
        _load(fault)
    msg = str(e.value)
    assert "bad.toml" in msg and key in msg and words in msg, msg


def test_overlapping_faults_on_one_target_are_refused() -> None:
    a = {"type": "sensor-bias-v1", "target": "q_radps", "bias_degps": 1, "t_start_s": 5, "t_end_s": 10}
    b = {"type": "sensor-noise-v1", "target": "q_radps", "noise_std_degps": 1, "t_start_s": 8}
    with pytest.raises(ScenarioError, match=r"faults\[1\].*overlaps faults\[0\].*one fault per target"):
        _load(a, b)
    _load(a, dict(b, t_start_s=10))  # back to back is fine
    _load(a, dict(b, target="p_radps"))  # another target is fine


def test_info_lists_the_faults(tmp_path: Path) -> None:
    from fdi_sim.flightlog import log_info

    faults = [{"type": "sensor-bias-v1", "target": "q_radps", "bias_degps": 0.5, "t_start_s": 1.0, "t_end_s": 2.5},
              {"type": "actuator-stuck-v1", "target": "rudder", "t_start_s": 2.0, "label": "jam"}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=3.0)
    text = log_info(run["res"].log_path).format()
    assert "q_radps_bias  sensor-bias-v1 on q_radps, [1, 2.5) s" in text
    assert "jam  actuator-stuck-v1 on rudder, from 2 s" in text


def test_intermittent_stuck_surface_is_released_between_windows(tmp_path: Path) -> None:
    from conftest import doublet

    faults = [{"type": "actuator-stuck-v1", "target": "elevator", "t_start_s": 1.0,
               "intermittent": {"windows_s": [[1.0, 2.0], [3.0, 4.0]]}}]
    run = fly(tmp_path, "DHC6", faults=faults, maneuvers=[doublet("elevator", 1.5, 0.05, 1.0)], duration_s=5.0)
    s = run["/truth/surfaces"]
    t, pos = s["t_s"], s["elevator_pos_rad"]

    def span(a: float, b: float) -> float:
        return float(np.ptp(pos[(t >= a) & (t < b)]))

    assert span(1.0, 2.0) == 0.0 and span(3.0, 4.0) == 0.0  # jammed in each window (re-captured at onset)
    assert span(2.0, 3.0) > np.radians(1.0)  # released between: it follows the doublet again
    assert pos[(t >= 3.0) & (t < 4.0)][0] != pos[(t >= 1.0) & (t < 2.0)][0]


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_stuck_roll_channel_takes_every_aileron_path(aircraft: str, tmp_path: Path) -> None:
    """A jammed roll channel: an aileron doublet changes nothing, neither the roll (the aero roll
    term) nor, on the F-16, lift and drag through the flaperon mix of the kinematic aileron path."""
    from conftest import doublet

    faults = [{"type": "actuator-stuck-v1", "target": "aileron", "t_start_s": 2.0}]
    with_d = fly(tmp_path, aircraft, faults=faults, maneuvers=[doublet("aileron", 3.0, 0.2)], duration_s=6.0)
    without = fly(tmp_path, aircraft, faults=faults, duration_s=6.0)
    for name in ("p_radps", "nx_g", "nz_g", "vt_fps"):
        np.testing.assert_array_equal(with_d["/truth/state"][name], without["/truth/state"][name])


def test_pitch_trim_is_logged_with_the_commands(tmp_path: Path) -> None:
    run = fly(tmp_path, "DHC6", duration_s=2.0, initial={"h_ft": 5000.0, "vc_kts": 100.0})
    pt = run["/commands/pilot"]["pitch_trim_cmd_norm"]
    assert np.ptp(pt) == 0.0 and abs(pt[0]) > 1e-3  # set by the running-engine trim, held
    # the DHC-6 FCS gears elevator_cmd + pitch_trim into the surface (0.244 rad per unit trailing edge down)
    c, s = run["/commands/pilot"], run["/truth/surfaces"]
    total = c["elevator_cmd_norm"][:-1] + pt[:-1]
    np.testing.assert_allclose(s["elevator_pos_rad"], np.where(total > 0, 0.244, 0.454) * total, atol=1e-9)

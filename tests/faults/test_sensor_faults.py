"""Issue 3 bar: every sensor fault type, flown in real JSBSim with the autopilot on the faulty sensor.

Each test checks (1) before the onset the measurement is truth plus noise (turn-on biases off,
so |y - x| stays within the sensor's noise and quantization), (2) after the onset the logged
error (faulty minus healthy measurement, ``/faults/active``) follows the fault model exactly,
and (3) where the autopilot flies on that sensor, the aircraft reacts as physics says.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import fly
from fdi_sim.sensors import load_suite

T_ON_S = 10.0
NOISE_ONLY = {"biases": False}


def _spec(aircraft: str, name: str):
    return next(s for s in load_suite(aircraft) if s.name == name)


def _check_before(run: dict, aircraft: str, sensor: str, t_on: float = T_ON_S) -> None:
    y, x, f = run["/sensors/measurements"], run["/truth/state"], run["/faults/active"]
    spec = _spec(aircraft, sensor)
    before = y["t_s"] < t_on
    # sample-and-hold: compare with the truth at the last sample instant
    decim = int(round(120 / spec.rate_hz))
    k = np.flatnonzero(before)
    k_sample = (k // decim) * decim
    dev = y[sensor][k] - x[sensor][k_sample]
    assert np.abs(dev).max() <= 6 * spec.noise_std + spec.quantum
    assert np.std(dev) == pytest.approx(np.hypot(spec.noise_std, spec.quantum / np.sqrt(12)), rel=0.35)
    cols = [c for c in f.fields if c.endswith("_active")]
    assert not f[cols[0]][before].any()
    assert f[cols[0]][~before].all()


def _error(run: dict) -> tuple[np.ndarray, np.ndarray]:
    f = run["/faults/active"]
    col = next(c for c in f.fields if c.endswith("_error"))
    return f["t_s"], f[col]


def _late_mean(run: dict, name: str, t0: float) -> float:
    x = run["/truth/state"]
    return float(x[name][x["t_s"] >= t0].mean())


def _held_airspeed_shift(t_s: float, error_kts: float) -> float:
    """How much of a steady airspeed-sensor error the speed hold has taken on at ``t_s`` [kt].

    The autopilot's speed is GNSS-referenced: air speed = |ground velocity - wind estimate|, the
    wind estimate following (GNSS - air data) with time constant tau_wind. A pitot error looks
    like a wind change, so it enters the held airspeed as error x (1 - exp(-(t - t_on) / tau_wind)).
    """
    from fdi_sim.pilot.autopilot import AutopilotGains

    tau = AutopilotGains.for_aircraft("DHC6").tau_wind_s
    return error_kts * (1.0 - math.exp(-(t_s - T_ON_S) / tau)) if tau > 0 else error_kts


def _mean_between(run: dict, name: str, a: float, b: float) -> float:
    x = run["/truth/state"]
    return float(x[name][(x["t_s"] >= a) & (x["t_s"] < b)].mean())


def test_airspeed_bias_changes_the_true_airspeed_held(tmp_path: Path) -> None:
    faults = [{"type": "sensor-bias-v1", "target": "vc_kts", "bias_kts": 5.0, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=250.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "vc_kts")
    t, err = _error(run)
    np.testing.assert_allclose(err[t >= T_ON_S], 5.0, atol=1e-9)
    # the hold keeps the *measured* airspeed: the aircraft slows by the part of the bias taken on
    for a, b in ((140.0, 160.0), (230.0, 250.0)):
        assert _mean_between(run, "vc_kts", a, b) == pytest.approx(120.0 - _held_airspeed_shift((a + b) / 2, 5.0), abs=0.5)
    assert _mean_between(run, "vc_kts", 230.0, 250.0) < 118.5


def test_airspeed_scale_factor(tmp_path: Path) -> None:
    faults = [{"type": "sensor-scale-v1", "target": "vc_kts", "scale": 0.95, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=250.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "vc_kts")
    t, err = _error(run)
    x = run["/truth/state"]
    on = t >= T_ON_S
    # error = (scale - 1) x at the sensor's sample instants (40 Hz), held: within one sample's change
    np.testing.assert_allclose(err[on], -0.05 * x["vc_kts"][on], atol=0.02)
    # reads 5 % low: the aircraft speeds up by the part of the error the hold has taken on
    for a, b in ((140.0, 160.0), (230.0, 250.0)):
        v = _mean_between(run, "vc_kts", a, b)
        assert v == pytest.approx(120.0 + _held_airspeed_shift((a + b) / 2, 0.05 * v), abs=0.5)


def test_altimeter_drift_makes_the_aircraft_descend(tmp_path: Path) -> None:
    faults = [{"type": "sensor-drift-v1", "target": "h_ft", "drift_fps": 2.0, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "f16", faults=faults, duration_s=40.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "f16", "h_ft")
    t, err = _error(run)
    y = run["/sensors/measurements"]
    on = t >= T_ON_S
    # 20 Hz baro: the drift is sampled and held, so within one sample's worth (0.1 ft) and 1 ft quantum
    np.testing.assert_allclose(err[on], 2.0 * (t[on] - T_ON_S), atol=0.1 + 1.0)
    # the altitude hold follows the drifting altimeter: the aircraft descends about 2 ft/s
    x = run["/truth/state"]
    h_end = x["h_ft"][-120:].mean()
    assert h_end == pytest.approx(10000.0 - 2.0 * (40.0 - T_ON_S), abs=25.0)
    assert np.abs(y["h_ft"][-120:].mean() - 10000.0) < 15.0  # while the altimeter reads the reference


@pytest.mark.parametrize("fault", ["sensor-stuck-v1", "sensor-dropout-v1"])
def test_frozen_altimeter_blinds_the_altitude_change(fault: str, tmp_path: Path) -> None:
    maneuvers = [{"type": "altitude-v1", "t_start_s": 12.0, "h_ft": 5200.0, "rate_fps": 10.0}]
    healthy = fly(tmp_path, "DHC6", maneuvers=maneuvers, duration_s=60.0, autopilot=True, sensors=NOISE_ONLY)
    faults = [{"type": fault, "target": "h_ft", "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, maneuvers=maneuvers, duration_s=60.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "h_ft")
    y = run["/sensors/measurements"]
    on = y["t_s"] >= T_ON_S
    assert np.ptp(y["h_ft"][on]) == 0.0  # frozen at the last output
    if fault == "sensor-dropout-v1":
        v = run["/sensors/valid"]
        assert not v["h_ft"][on].any() and v["h_ft"][~on].all()
        assert v["vc_kts"].all()
    # the healthy run settles near 5200 ft; the blind one keeps climbing (it never sees the climb)
    assert abs(_late_mean(healthy, "h_ft", 50.0) - 5200.0) < 30.0
    x = run["/truth/state"]
    assert x["h_ft"][-1] > 5350.0 and x["hdot_fps"][-120:].mean() > 3.0


def test_pitch_gyro_noise_shakes_the_elevator(tmp_path: Path) -> None:
    healthy = fly(tmp_path, "DHC6", duration_s=30.0, autopilot=True, sensors=NOISE_ONLY)
    faults = [{"type": "sensor-noise-v1", "target": "q_radps", "noise_std_degps": 1.0, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=30.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "q_radps")
    t, err = _error(run)
    assert np.std(err[t >= T_ON_S]) == pytest.approx(np.radians(1.0), rel=0.1)
    assert np.abs(err[t >= T_ON_S]).max() < 6 * np.radians(1.0)

    def elev_std(r: dict) -> float:
        c = r["/commands/pilot"]
        return float(np.std(np.diff(c["elevator_cmd_norm"][c["t_s"] >= T_ON_S])))

    assert elev_std(run) > 1.5 * elev_std(healthy)  # the pitch damper passes the noise to the elevator


def test_attitude_delay(tmp_path: Path) -> None:
    maneuvers = [{"type": "doublet-v1", "axis": "elevator", "t_start_s": 12.0, "amplitude_norm": 0.05, "pulse_s": 1.0}]
    faults = [{"type": "sensor-delay-v1", "target": "theta_rad", "delay_s": 0.5, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, maneuvers=maneuvers, duration_s=25.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "theta_rad")
    t, err = _error(run)
    y = run["/sensors/measurements"]["theta_rad"]
    healthy = y - err
    n = int(round(0.5 * 120))
    k = np.flatnonzero(t >= T_ON_S + 0.5)
    np.testing.assert_allclose(y[k], healthy[k - n], atol=1e-12)  # y(t) = healthy y(t - 0.5 s)
    assert np.abs(err[t >= 12.0]).max() > np.radians(0.3)  # it matters during the doublet


def test_alpha_vane_outliers(tmp_path: Path) -> None:
    faults = [{"type": "sensor-outlier-v1", "target": "alpha_rad", "rate_hz": 2.0, "size_deg": 5.0, "t_start_s": T_ON_S}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=70.0, autopilot=True, sensors=NOISE_ONLY)
    _check_before(run, "DHC6", "alpha_rad")
    t, err = _error(run)
    spikes = np.abs(err) > 1e-9
    assert np.allclose(np.abs(err[spikes]), np.radians(5.0))  # each spike is +-5 deg, held one 40 Hz sample
    n_spikes = np.count_nonzero(np.diff(spikes.astype(int)) == 1)
    expected = 2.0 * (70.0 - T_ON_S)
    assert abs(n_spikes - expected) < 4 * np.sqrt(expected)  # Poisson count
    assert not spikes[t < T_ON_S].any()

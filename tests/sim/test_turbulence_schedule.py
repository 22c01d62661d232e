"""Thresholds scheduled on the bank's own turbulence estimate (fdi_sim.bank.turbulence): the estimate,
the interpolation, any blocking giving the same bits, and a bank replaying a real log through it
giving exactly what the atlas generation computes from the same log."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.bank.turbulence import (
    ThresholdSchedule, scheduled_threshold, turbulence_estimate, turbulence_series,
)
from fdi_sim.errors import DesignError


def test_the_estimate_converges_and_any_blocking_gives_the_same_bits():
    rng = np.random.default_rng(11)
    rate = 20.0
    x = np.cumsum(rng.normal(0.0, 0.3, size=int(600 * rate)))  # increments of std 0.3
    ok = np.ones(x.size, dtype=bool)
    s = turbulence_series(x, ok, rate, 10.0, tau_s=30.0)
    assert s[0] == np.inf  # no increment yet: the highest threshold
    assert abs(s[100] / 0.3 - 1) < 0.2  # the running mean's start: usable when the bank arms (5 s)
    late = s[int(60 * rate):]
    assert abs(np.median(late) / 0.3 - 1) < 0.05 and late.min() > 0.3 * 0.75
    out = np.empty(x.size)
    state = np.zeros(4)
    i = 0
    for b in rng.integers(1, 37, size=x.size):
        sl = slice(i, min(x.size, i + int(b)))
        turbulence_estimate(x[sl], ok[sl], state, 1.0 / (30.0 * rate), 100.0, out[sl])
        i += int(b)
        if i >= x.size:
            break
    assert np.array_equal(out, s)


def test_a_failed_sample_and_a_step_do_not_move_it_far():
    rng = np.random.default_rng(12)
    x = np.cumsum(rng.normal(0.0, 0.3, size=4000))
    ok = np.ones(x.size, dtype=bool)
    ok[1000:1010] = False
    x[1000:1010] = np.nan
    x[2000:] += 50.0  # an accelerometer's bias step
    s = turbulence_series(x, ok, 20.0, 1.0, tau_s=30.0)
    assert np.all(np.isfinite(s[1:]))
    assert s[2000] <= np.sqrt(s[1999] ** 2 + (1.0 - s[1999] ** 2) / 600) + 1e-12  # one clipped increment


def test_the_schedule_interpolates_in_log_log_and_holds_beyond_the_ends():
    sch = ThresholdSchedule("nz_g", 30.0, 3.0, ("none", "light", "moderate"), (0.2, 0.4, 0.5),
                            {"a": (1.0, 10.0, 15.0), "b": (5.0, 4.0, 6.0)})
    sig = np.array([0.1, 0.2, np.sqrt(0.2 * 0.4), 0.4, 0.5, 0.9, np.inf, np.nan])
    out = np.empty(sig.size)
    scheduled_threshold(sig, *sch.log_tables("a"), out)
    assert np.allclose(out, [1.0, 1.0, np.sqrt(10.0), 10.0, 15.0, 15.0, 15.0, 15.0])
    scheduled_threshold(np.array([0.3, 0.45]), *sch.log_tables("b"), out[:2])  # made non-decreasing: 5, 5, 6
    assert out[0] == pytest.approx(5.0) and 5.0 < out[1] < 6.0
    with pytest.raises(DesignError, match="must rise with the level"):
        ThresholdSchedule("nz_g", 30.0, 3.0, ("none", "light"), (0.4, 0.4), {"a": (1.0, 2.0)})
    with pytest.raises(DesignError, match="a threshold per anchor"):
        ThresholdSchedule("nz_g", 30.0, 3.0, ("none", "light"), (0.2, 0.4), {"a": (1.0,)})
    assert ThresholdSchedule.from_dict(sch.to_dict()) == sch


def test_a_bank_replaying_a_log_schedules_as_the_generation_computes(tmp_path, monkeypatch):
    """A real flight (the F-16 hold-out scenario of the atlas tests, 40 s, light turbulence) replayed
    through its bank with a schedule: the attitude check's thresholds are the schedule at the
    estimate the atlas generation computes from the same log (fdi_sim.training.thresholds.sample_signal)."""
    from pathlib import Path

    from fdi_sim.flightlog import read_log
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly
    from fdi_sim.training.build import bank_for_log
    from fdi_sim.training.thresholds import _replay_log, sample_signal

    monkeypatch.setenv("FDI_SIM_CACHE", str(tmp_path / "cache"))
    text = (Path(__file__).resolve().parents[1] / "data" / "holdout" / "holdout_f16_roll_gyro_bias_7500ft.toml").read_text()
    res = fly(loads(text, "h.toml"), tmp_path / "runs", progress=False)
    log = read_log(res.log_path)
    bank = bank_for_log(log)
    from fdi_sim.bank.turbulence import TAU_S, estimate_spec

    spec = estimate_spec("f16")  # the F-16's shipped signal (the pitch gyro)
    sch = ThresholdSchedule(spec.signal, TAU_S, spec.clip, ("none", "light", "moderate"), (0.005, 0.01, 0.02),
                            {"kinematic-attitude-v1": (3.0, 4.0, 6.0)})
    bank.set_schedule(sch)
    assert bank.members[1].threshold == 3.0  # the stream isolates from the lowest, exactly
    _replay_log(bank, log)
    tr = bank.trace()["kinematic-attitude-v1"]
    sig = turbulence_series(*sample_signal(bank, log, spec.signal), bank.rate_hz, sch.clip, tau_s=sch.tau_s)
    assert np.array_equal(bank.sigma_trace(), sig)
    want = np.empty(sig.size)
    scheduled_threshold(sig, *sch.log_tables("kinematic-attitude-v1"), want)
    assert np.array_equal(tr["threshold"], want)
    assert np.all((tr["threshold"] >= 3.0) & (tr["threshold"] <= 6.0))
    other = bank.trace()["kinematic-altitude-v1"]["threshold"]
    assert np.all(other == other[0])  # a member the schedule does not name keeps its threshold
    with pytest.raises(DesignError, match="does not measure"):
        bank.set_schedule(ThresholdSchedule("no_such", 30.0, 3.0, ("a",), (1.0,), {"kinematic-attitude-v1": (1.0,)}))


def test_the_power_schedule_holds_below_the_reference_and_rises_as_its_power_above():
    from fdi_sim.bank.turbulence import ESTIMATES, NOISE_COVER, NOISE_EXPONENTS, POWER_SPAN, power_schedule

    for ac, spec in ESTIMATES.items():
        sch = power_schedule({"kalman-gust-v1": 400.0, "kinematic-altitude-v1": 4.0, "kinematic-airspeed-v1": 10.0},
                             0.5, spec)
        assert sch.signal == spec.signal and sch.clip == spec.clip, ac
        assert set(sch.thresholds) == {"kalman-gust-v1", "kinematic-airspeed-v1", "kinematic-altitude-v1"}
        sig = np.array([0.1, 0.5, 0.75, 1.0, 0.5 * POWER_SPAN, 100.0])
        out = np.empty(sig.size)
        scheduled_threshold(sig, *sch.log_tables("kinematic-airspeed-v1"), out)
        want = 10.0 * np.maximum(1.0, np.minimum(sig, 0.5 * POWER_SPAN) / 0.5) ** spec.exponents["kinematic-airspeed-v1"]
        assert np.allclose(out, want, rtol=1e-12)
        # the altitude check does not move with the turbulence; it covers the sensor noise (white noise: beta 1)
        assert NOISE_EXPONENTS["kinematic-altitude-v1"] == 1.0 and "kinematic-altitude-v1" not in spec.exponents
        scheduled_threshold(sig, *sch.log_tables("kinematic-altitude-v1"), out)
        assert np.allclose(out, 4.0 * NOISE_COVER, rtol=1e-12)
        assert sch.thresholds["kalman-gust-v1"][0] == 400.0  # the turbulence-driven members get no noise cover
    spec = ESTIMATES["f16"]
    assert power_schedule({"kinematic-altitude-v1": 4.0}, 0.5, spec, noise_cover=1.0).thresholds == {
        "kinematic-altitude-v1": (4.0, 4.0)}
    assert power_schedule({"other": 4.0}, 0.5, spec) is None
    with pytest.raises(DesignError, match="noise cover"):
        power_schedule({"kinematic-altitude-v1": 4.0}, 0.5, spec, noise_cover=0.9)

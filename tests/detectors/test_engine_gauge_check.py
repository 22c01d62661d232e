"""The engine-gauge check (fdi_sim.detectors.engine_gauges): design from the sensor suite, the
streaming contract, what it names on synthetic gauges with a known answer."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fdi_sim import registry
from fdi_sim.detectors.check import check_stream, contract_inputs
from fdi_sim.detectors.engine_gauges import (
    DETECTOR_ID, GAUGES, HYPOTHESES, LIMITER_ALLOWANCE, EngineGaugeStream, design_engine_gauges, make_engine_gauges,
    torque_limit_ftlb,
)
from fdi_sim.detectors.stream import BlockOutputs, StreamingDetector
from fdi_sim.errors import DesignError
from fdi_sim.sensors.suite import load_suite

RATE_HZ = 20.0
#: cruise-like gauge levels: Ng [%], torque [lbf ft], Np [rpm], engine 0 then 1 per gauge
LEVELS = np.array([89.2, 89.0, 1030.0, 1020.0, 1250.0, 1250.0])


def _gauges(n: int, rng: np.random.Generator, design=None) -> np.ndarray:
    """Fault-free gauges: each gauge's own white noise at the suite's std, rounded to its quantum."""
    specs = {s.name: s for s in load_suite("DHC6")}
    y = np.empty((n, 6))
    for c, nm in enumerate(GAUGES):
        s = specs[nm]
        v = LEVELS[c] + s.noise_std * rng.standard_normal(n)
        y[:, c] = np.round(v / s.quantum) * s.quantum if s.quantum > 0 else v
    return y


def _run(stream: EngineGaugeStream, y: np.ndarray, ok: np.ndarray | None = None, block: int = 10) -> BlockOutputs:
    n = len(y)
    ok = np.ones_like(y, dtype=bool) if ok is None else ok
    out = BlockOutputs.allocate(n, 3)
    stream.reset()
    t = np.arange(n) / RATE_HZ
    for a in range(0, n, block):
        b = min(a + block, n)
        part = BlockOutputs(*(getattr(out, f)[a:b] for f in ("statistic", "threshold", "valid", "hypothesis", "point",
                                                            "residual", "estimate", "cosine")))
        stream.process_block(t[a:b], np.zeros((b - a, 0)), y[a:b], ok[a:b], ok[a:b], part)
    return out


def test_design_scales_from_the_suite() -> None:
    d = design_engine_gauges("DHC6")
    specs = {s.name: s for s in load_suite("DHC6")}
    for k, kind in enumerate(("n1", "torque", "prop")):
        pair = [s for nm, s in specs.items() if nm.startswith(f"{kind}_")]
        assert len(pair) == 2
        assert d.scales[k] == pytest.approx(math.sqrt(sum(s.noise_std ** 2 + s.quantum ** 2 / 12 for s in pair)))
    assert d.n_avg == 4 and d.n_warm == 100


def test_single_engine_refused_with_the_missing_gauges() -> None:
    with pytest.raises(DesignError, match="n1_1_pct"):
        make_engine_gauges(aircraft="f16")
    with pytest.raises(DesignError, match="needs the aircraft"):
        make_engine_gauges()
    with pytest.raises(DesignError, match="average_s"):
        design_engine_gauges("DHC6", average_s=-1.0)


def test_registered_and_a_stream() -> None:
    s = registry.get("detector", DETECTOR_ID).factory(None, aircraft="DHC6")
    assert isinstance(s, StreamingDetector) and s.id == DETECTOR_ID and s.hypotheses == HYPOTHESES


def test_contract_checker_passes() -> None:
    s = make_engine_gauges(aircraft="DHC6")
    x = contract_inputs(s, None, n_samples=400)
    assert check_stream(s, x) == []


def test_fault_free_statistic_is_standard_normal() -> None:
    """Without a fault each z_g is N(0, 1) (the scale is the difference's std): its std within 5 %
    over 20,000 samples, and the maximum of |z| where the Gaussian puts it."""
    y = _gauges(20_000, np.random.default_rng(7))
    out = _run(make_engine_gauges(aircraft="DHC6"), y, block=37)
    v = out.valid
    assert not v[:99].any() and v[100:].all()  # the 5 s warm-up
    z = out.residual[v]
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.05)
    assert 3.0 < np.abs(z).max() < 5.5


def test_block_size_never_changes_a_number() -> None:
    y = _gauges(3000, np.random.default_rng(3))
    y[2000:, 2] -= 300.0
    s = make_engine_gauges(aircraft="DHC6")
    a, b = _run(s, y, block=3000), _run(s, y, block=7)
    for f in ("statistic", "valid", "hypothesis", "residual"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


@pytest.mark.parametrize(("engine", "sign"), [(0, -1.0), (1, -1.0)])
def test_a_thrust_loss_names_the_engine(engine: int, sign: float) -> None:
    """An engine that loses thrust: its torque drops 300 lbf ft and its Ng 1 % (z 35 and 25)."""
    y = _gauges(3000, np.random.default_rng(11 + engine))
    y[2000:, 0 + engine] += sign * 1.0
    y[2000:, 2 + engine] += sign * 300.0
    s = make_engine_gauges(aircraft="DHC6")
    out = _run(s, y)
    assert not (out.valid[:2000] & (out.statistic[:2000] > s.threshold)).any()
    hit = out.valid[2000:] & (out.statistic[2000:] > s.threshold)
    assert hit[1:].all()  # from the second faulty sample on (the first is one quarter of the mean)
    assert {HYPOTHESES[h] for h in out.hypothesis[2001:]} == {f"engine_{engine}"}


@pytest.mark.parametrize(("col", "delta"), [(0, 0.5), (1, -0.5), (3, 120.0)])
def test_one_gauge_names_that_gauge(col: int, delta: float) -> None:
    """A bias on one gauge (Ng 0.5 %, torque 120 lbf ft: 12-14 sigma of the 0.2 s mean) names that
    gauge of that engine, not the engine."""
    y = _gauges(3000, np.random.default_rng(20 + col))
    y[2000:, col] += delta
    out = _run(make_engine_gauges(aircraft="DHC6"), y)
    names = [HYPOTHESES[h] for h in out.hypothesis[2004:] if h >= 0]
    assert len(names) >= 990
    assert names.count(GAUGES[col]) / len(names) > 0.99


def test_invalid_gauges_are_left_out() -> None:
    """A gauge pair with a sample not ok in its window is left out of the maximum; with every pair
    out the sample is invalid (never a valid "no alarm"); NaN counts as not ok."""
    y = _gauges(600, np.random.default_rng(5))
    ok = np.ones_like(y, dtype=bool)
    ok[300:320, 2] = False          # one torque gauge drops out: the torque pair is left out
    y[400, :] = np.nan              # every gauge non-finite at one sample
    out = _run(make_engine_gauges(aircraft="DHC6"), y, ok)
    assert out.valid[300:323].all() and np.isnan(out.residual[300:323, 1]).all()
    assert np.isfinite(out.residual[300:323, [0, 2]]).all()
    assert not out.valid[400:404].any() and np.isnan(out.statistic[400:404]).all()
    assert out.valid[404:].all()


def test_an_engine_fault_is_right_only_when_the_engine_is_named() -> None:
    """The run summary's rule (fdi_sim.decision.outcome): an engine fault is isolated right as that
    engine or as the throttle (the gust filter's thrust hypothesis, which cannot tell engines apart);
    the other engine or one of the engine's gauges (a sensor fault) is wrong."""
    from fdi_sim.decision.outcome import _matches

    assert _matches("engine_0", "engine_0") and _matches("throttle_cmd_norm", "engine_0")
    assert not _matches("engine_1", "engine_0") and not _matches("torque_0_ftlb", "engine_0")
    assert _matches("torque_0_ftlb", "torque_0_ftlb") and not _matches("torque_1_ftlb", "torque_0_ftlb")
    assert _matches("engine_1", "throttle") and _matches("throttle_cmd_norm", "throttle")
    assert _matches(None, "engine_0") is None


def test_np_is_logged_not_tested() -> None:
    """A 40 rpm difference of the propellers' speeds (17 sigma of the 0.2 s mean; fault-free yaws
    make up to 26 rpm, module docstring) is in the logged residual and raises nothing; the check has
    no Np hypothesis, so a fault on an Np gauge is "not monitored" by it."""
    y = _gauges(3000, np.random.default_rng(24))
    y[2000:, 4] -= 40.0
    s = make_engine_gauges(aircraft="DHC6")
    out = _run(s, y)
    assert np.median(out.residual[2004:, 2]) < -14.0
    assert not (out.statistic[100:] > s.threshold).any() and (out.hypothesis == -1).all()
    assert not any(h.startswith("prop_") for h in HYPOTHESES)


def test_the_torque_limit_is_the_aircraft_s() -> None:
    """The DHC-6's limiter (its iced variant shares the engines); an aircraft without one has none."""
    assert design_engine_gauges("DHC6").torque_limit_ftlb == 1629.3
    assert torque_limit_ftlb("DHC6_iced") == 1629.3 and torque_limit_ftlb("f16") == math.inf


def _near_limit(n: int, seed: int) -> np.ndarray:
    """Fault-free gauges with both torques 20 lbf ft under the DHC-6's 1,629.3 limit (inside the
    40 lbf ft margin) over samples 1000-1999, 500 lbf ft under it elsewhere."""
    y = _gauges(n, np.random.default_rng(seed))
    y[:, 2:4] += 1629.3 - 500.0 - LEVELS[2:4].mean()
    y[1000:2000, 2:4] += 480.0
    return y


def test_within_the_limiter_s_window_its_allowance_is_not_counted() -> None:
    """Near the limit one engine held back by 3 % Ng and 300 lbf ft (what the limiter's latch made on
    the development flights) raises nothing; the same difference 5 s after the torques left the
    limit is an engine fault again, and so is a flameout-sized drop (1,000 lbf ft, 10 % Ng) near the
    limit. The allowance is the design's, not a blind window: the excess is tested."""
    s = make_engine_gauges(aircraft="DHC6")
    d = s.design
    assert d.n_hold == 100 and d.limiter_allowance == LIMITER_ALLOWANCE
    y = _near_limit(4000, 31)
    y[1200:1900, 1] -= 3.0
    y[1200:1900, 3] -= 300.0
    out = _run(s, y)
    assert not (out.statistic[100:2000] > s.threshold).any()
    # the window holds for n_hold samples after the last near-limit torque (sample 1999)
    y2 = y.copy()
    y2[2040:2090, 1] -= 3.0
    y2[2040:2090, 3] -= 300.0
    y2[2200:2300, 1] -= 3.0
    y2[2200:2300, 3] -= 300.0
    out = _run(s, y2)
    assert not (out.statistic[2000:2099] > s.threshold).any()
    assert (out.statistic[2204:2300] > s.threshold).all()
    assert {HYPOTHESES[h] for h in out.hypothesis[2204:2300]} == {"engine_1"}
    y3 = _near_limit(4000, 31)
    y3[1500:1900, 1] -= 10.0
    y3[1500:1900, 3] -= 1000.0
    out = _run(s, y3)
    assert (out.statistic[1504:1900] > s.threshold).all()
    assert {HYPOTHESES[h] for h in out.hypothesis[1504:1900]} == {"engine_1"}
    # e_g = z_g - a_g beyond the allowance: the excess 500 lbf ft over the 0.2 s mean's noise (engine 0
    # minus engine 1: positive when engine 1 reads low)
    a_t = d.limiter_allowance[1] / (d.scales[1] / math.sqrt(d.n_avg))
    z_t = 1000.0 / (d.scales[1] / math.sqrt(d.n_avg))
    assert np.median(out.residual[1504:1900, 1]) == pytest.approx(z_t - a_t, abs=1.0)


def test_an_unreadable_torque_opens_the_window() -> None:
    """With a torque gauge not ok the check cannot know the limiter is not acting: the allowance
    applies to Ng (the torque pair itself is left out)."""
    y = _gauges(3000, np.random.default_rng(33))
    ok = np.ones_like(y, dtype=bool)
    ok[1000:2000, 3] = False
    y[1200:1900, 1] -= 3.0
    out = _run(make_engine_gauges(aircraft="DHC6"), y, ok)
    assert (out.residual[1204:1900, 0] == 0.0).all()
    y[2300:2400, 1] -= 3.0  # 300 samples after the gauge came back: tested again
    s = make_engine_gauges(aircraft="DHC6")
    out = _run(s, y, ok)
    assert (out.residual[2304:2400, 0] > 50.0).all()
    # without a limiter there is nothing to allow for: an unreadable torque opens no window
    free = EngineGaugeStream(dataclasses.replace(s.design, torque_limit_ftlb=math.inf))
    out = _run(free, y, ok)
    assert (out.residual[1204:1900, 0] > 50.0).all()

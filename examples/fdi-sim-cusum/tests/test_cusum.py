"""Tests of the ``cusum-residual-v1`` example plugin on the F-16's real linearization.

The model is trimmed and linearized by JSBSim at the initial point of ``f16_stuck_elevator``
(about 1 s, once per module). The flights are simulated from that linear model with exactly the
design's noise model (white gusts, command noise, sensor noise), so the normalized residual must
be white with unit variance and the CUSUM's false-alarm behaviour is the textbook one.

Run from the repository root::

    PYTHONPATH=examples/fdi-sim-cusum/src .venv/bin/pytest -q examples/fdi-sim-cusum/tests -p no:cacheprovider
"""
from __future__ import annotations

import math
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.stream import BlockOutputs, StreamingDetector
from fdi_sim_cusum import make_cusum
from fdi_sim_cusum.design import DEFAULT_NOISE_STD

PACKAGE_DIR = Path(__file__).resolve().parents[1]
SCENARIO = "f16_stuck_elevator.toml"
RATE_HZ = 20.0
COMMANDS = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")


def _scenario_path() -> Path:
    import fdi_sim

    for p in (PACKAGE_DIR.parents[1] / "scenarios" / SCENARIO, Path(fdi_sim.__file__).parent / "_scenarios" / SCENARIO):
        if p.is_file():
            return p
    pytest.skip(f"scenario {SCENARIO} not found next to the example or in fdi_sim")


@pytest.fixture(scope="module")
def model():
    """The F-16 at 10 kft / 400 KTAS, discretized at 20 Hz in the samples' standard form."""
    from fdi_sim.scenario.loader import load
    from fdi_sim.training.models import model_for_scenario

    return model_for_scenario(load(str(_scenario_path())), RATE_HZ).model


@pytest.fixture(scope="module")
def det(model):
    return make_cusum(model)


def simulate(model, design, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` samples of the linear model with the design's noise model; absolute ``(t, u, y)``.

    ``x_{j+1} = A x_j + B_c (du_j + w_c) + B_g w_g``, ``dy_j = C x_j + D_c (du_j + w_c) + D_g w_g + v_j``
    with small sinusoidal commands ``du_j`` (logged without the noise ``w_c``).
    """
    rng = np.random.default_rng(seed)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (model.A, model.B, model.C, model.D))
    names_in = list(model.input_names)
    ci = [names_in.index(nm) for nm in design.input_names]
    gi = [i for i, nm in enumerate(names_in) if nm.endswith("_gust_body_fps")]
    yi = [list(model.output_names).index(nm) for nm in design.output_names]
    t = np.arange(1, n + 1) / RATE_HZ
    du = np.zeros((n, len(ci)))
    du[:, 0] = 0.01 * np.sin(2 * np.pi * 0.3 * t)  # elevator
    du[:, 1] = 0.005 * np.sin(2 * np.pi * 0.2 * t)  # aileron
    w_g = rng.standard_normal((n, len(gi))) * design.gust_std_fps
    w_c = rng.standard_normal((n, len(ci))) * design.command_std
    v = rng.standard_normal((n, len(yi))) * design.noise_std
    x = np.zeros(A.shape[0])
    dy = np.empty((n, len(yi)))
    for j in range(n):
        dc = du[j] + w_c[j]
        dy[j] = (C @ x + D[:, ci] @ dc + D[:, gi] @ w_g[j])[yi] + v[j]
        x = A @ x + B[:, ci] @ dc + B[:, gi] @ w_g[j]
    y = dy + np.asarray(model.y0, dtype=float)[yi]
    for k, nm in enumerate(design.output_names):
        if nm.startswith("psi") and nm.endswith("_rad"):
            y[:, k] = (y[:, k] + math.pi) % (2 * math.pi) - math.pi  # heading as measured
    u = du + np.asarray(model.u0, dtype=float)[ci]
    return t, u, y


@pytest.fixture(scope="module")
def flight(model, det):
    t, u, y = simulate(model, det.design, 4000, seed=2)
    return t, u, y, np.ones_like(y, dtype=bool)


def run(detector, t, u, y, ok, blocks=None) -> BlockOutputs:
    """All samples through ``detector`` (reset first), cut into blocks of the given sizes (cycled)."""
    n = len(t)
    out = BlockOutputs.allocate(n, len(detector.residual_names))
    detector.reset()
    if blocks is None:
        detector.process_block(t, u, y, ok, ok, out)
        return out
    scratch = BlockOutputs.allocate(max(blocks), len(detector.residual_names))
    i, k = 0, 0
    while i < n:
        s = min(blocks[k % len(blocks)], n - i)
        o = scratch.rows(s)
        detector.process_block(t[i:i + s], u[i:i + s], y[i:i + s], ok[i:i + s], ok[i:i + s], o)
        for name in ("statistic", "threshold", "valid", "hypothesis", "point", "residual", "estimate", "cosine"):
            getattr(out, name)[i:i + s] = getattr(o, name)
        i += s
        k += 1
    return out


def same_bits(a: BlockOutputs, b: BlockOutputs) -> bool:
    return all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
               for f in ("statistic", "threshold", "valid", "hypothesis", "point", "residual", "estimate", "cosine"))


# --- the contract ----------------------------------------------------------------------------------


def test_contract_attributes(model, det):
    assert isinstance(det, StreamingDetector)
    assert det.id == "cusum-residual-v1"
    assert det.hypotheses == ("q_radps",)
    assert det.input_names == COMMANDS
    assert det.output_names == tuple(model.output_names)
    assert det.residual_names == ("e_q_radps",)
    assert det.estimate_names == ()
    assert det.independent is False and det.fault_directions is False
    assert det.threshold == 10.0
    assert 0 < det.design.spectral_radius < 1
    assert det.design.settle_n == 20  # 1 s at 20 Hz


def test_design_key(model, det):
    key = det.design_key()
    assert isinstance(key, bytes) and len(key) == 32
    assert make_cusum(model).design_key() == key  # reproducible
    assert make_cusum(model, threshold=25.0).design_key() == key  # the threshold is calibrated, not designed
    for opts in ({"signal": "p_radps"}, {"drift": 0.25}, {"gust_std_fps": 5.0}, {"noise_std": {"q_radps": 0.003}},
                 {"outputs": ["q_radps", "theta_rad", "nz_g", "alpha_rad"]}, {"settle_s": 2.0}):
        assert make_cusum(model, **opts).design_key() != key, opts


def test_entry_point_declared():
    meta = tomllib.loads((PACKAGE_DIR / "pyproject.toml").read_text())
    eps = meta["project"]["entry-points"]["fdi_sim.detectors"]
    assert eps == {"cusum-residual-v1": "fdi_sim_cusum:make_cusum"}
    import importlib

    mod, _, attr = eps["cusum-residual-v1"].partition(":")
    assert getattr(importlib.import_module(mod), attr) is make_cusum
    summary = make_cusum.__doc__.strip().splitlines()[0]
    assert summary.endswith(".") and len(summary) < 100


# --- the numbers -----------------------------------------------------------------------------------


def test_residual_is_white_with_unit_variance(model, det, flight):
    """On the model's own flight the normalized prediction error is N(0, 1) and white."""
    out = run(det, *flight)
    e = out.residual[out.valid, 0]
    assert out.valid.sum() == len(flight[0]) - det.design.settle_n
    assert abs(e.mean()) < 0.06
    assert 0.95 < e.std() < 1.05
    assert abs(np.corrcoef(e[1:], e[:-1])[0, 1]) < 0.06
    assert np.all(out.hypothesis[out.statistic <= det.threshold] == -1)
    assert np.all(np.isnan(out.cosine)) and np.all(out.point == 0) and np.all(out.threshold == det.threshold)


def test_fault_free_below_threshold_bias_detected_quickly(model, det, flight):
    t, u, y, ok = flight
    iq = det.output_names.index("q_radps")
    clean = run(det, t, u, y, ok)
    assert clean.statistic[clean.valid].max() < det.threshold  # 200 s without a false alarm
    assert np.all(clean.hypothesis == -1)
    j0 = 2000
    sd = det.design.signal_std  # [rad/s]
    for bias in (0.01, -0.01):  # about 2 std of the prediction error, 5 std of the gyro noise
        yb = y.copy()
        yb[j0:, iq] += bias
        out = run(det, t, u, yb, ok)
        assert np.array_equal(out.statistic[:j0], clean.statistic[:j0])
        above = np.flatnonzero(out.valid & (out.statistic > det.threshold))
        assert above.size and above[0] >= j0
        delay_s = (above[0] - j0) / RATE_HZ
        assert delay_s < 1.0, (bias, bias / sd, delay_s)
        # once across it stays across, pointing at the gyro
        assert np.all(out.statistic[above[0]:] > det.threshold)
        assert np.all(out.hypothesis[above[0]:] == 0)
        assert np.all(out.hypothesis[:above[0]] == -1)


def test_other_signal_and_reduced_predictor(model, flight):
    """A bias on nz_g is seen by a CUSUM on nz_g built on a subset of the outputs."""
    subset = ["q_radps", "nz_g", "theta_rad", "alpha_rad", "vc_kts", "h_ft"]
    full = make_cusum(model)
    d = make_cusum(model, signal="nz_g", outputs=subset[::-1])
    assert d.output_names == tuple(nm for nm in model.output_names if nm in subset)  # the model's order
    assert d.hypotheses == ("nz_g",) and d.residual_names == ("e_nz_g",)
    t, u, y, ok = flight
    cols = [full.output_names.index(nm) for nm in d.output_names]
    ys, oks = y[:, cols].copy(), ok[:, cols]
    clean = run(d, t, u, ys, oks)
    assert clean.statistic[clean.valid].max() < d.threshold
    ys[2000:, d.output_names.index("nz_g")] += 6 * d.design.signal_std
    out = run(d, t, u, ys, oks)
    above = np.flatnonzero(out.valid & (out.statistic > d.threshold))
    assert above.size and 2000 <= above[0] < 2000 + RATE_HZ


# --- streaming -------------------------------------------------------------------------------------


def _messy(flight, det):
    """The flight with a gyro bias, a dropout of vc_kts, a NaN on q read as ok, and a heading wrap."""
    t, u, y, ok = flight
    y, ok = y.copy(), ok.copy()
    iq, iv = det.output_names.index("q_radps"), det.output_names.index("vc_kts")
    y[3000:, iq] += 0.01
    ok[1000:1050, iv] = False
    y[1000:1050, iv] = np.nan
    y[1500, iq] = np.nan  # not finite although flagged ok
    return t, u, y, ok


@pytest.mark.parametrize("blocks", [[1], [37], [1, 37, 5, 400, 2]])
def test_block_invariance(det, flight, blocks):
    data = _messy(flight, det)
    whole = run(det, *data)
    assert same_bits(run(det, *data, blocks=blocks), whole)


def test_invalid_samples(det, flight):
    t, u, y, ok = _messy(flight, det)
    out = run(det, t, u, y, ok)
    S = det.design.settle_n
    gap = np.zeros(len(t), dtype=bool)
    gap[1000:1050] = True
    gap[1500] = True
    assert not out.valid[gap].any()
    assert np.all(np.isnan(out.residual[gap, 0]))
    assert not out.valid[1050:1050 + S].any() and out.valid[1050 + S]  # settles, then tests again
    assert not out.valid[1501:1501 + S].any() and out.valid[1501 + S]
    assert np.all(np.isfinite(out.statistic))  # held through the gap, never NaN
    assert np.all(np.isfinite(out.residual[~gap, 0]))
    assert np.all(np.isfinite(det._x)) and np.all(np.isfinite(det._g))
    assert np.all(out.hypothesis[~out.valid] == -1)
    # the value behind a not-ok flag is never read
    y2 = y.copy()
    y2[1000:1050, det.output_names.index("vc_kts")] = 1e300
    assert same_bits(run(det, t, u, y2, ok), out)
    # after the gap the residual is its usual size again
    e = out.residual[1050 + S:1500, 0]
    assert np.abs(e).max() < 5.0
    # a non-finite command: predicted with du = 0 there, sample invalid, no NaN in the state
    u2 = u.copy()
    u2[2000, 0] = np.nan
    o2 = run(det, t, u2, y, ok)
    assert not o2.valid[2000] and np.all(np.isfinite(o2.statistic)) and np.all(np.isfinite(det._x))


def test_heading_wrapped(model, det, flight):
    t, u, y, ok = flight
    ip = det.output_names.index("psi_rad")
    y2 = y.copy()
    y2[:, ip] += 2 * np.pi * np.where(np.arange(len(t)) % 2 == 0, 1.0, -1.0)
    a, b = run(det, t, u, y, ok), run(det, t, u, y2, ok)
    np.testing.assert_allclose(b.residual, a.residual, atol=1e-6)
    np.testing.assert_allclose(b.statistic, a.statistic, atol=1e-5)


def test_reset_restores(model, det, flight):
    data = _messy(flight, det)
    first = run(det, *data)
    assert det.samples_seen == len(data[0]) and max(det.cusum) > 0
    det.reset()
    assert det.samples_seen == 0 and det.cusum == (0.0, 0.0) and not det._x.any()
    again = run(det, *data)
    assert same_bits(first, again)
    fresh = make_cusum(model)
    assert same_bits(run(fresh, *data), first)
    det.process_block(*(a[:10] for a in data[:3]), data[3][:10], data[3][:10], BlockOutputs.allocate(10, 1))
    det.start_at(10000.0, 349.0)
    assert det.samples_seen == 0 and det.cusum == (0.0, 0.0) and not det._x.any()


def test_threshold(det, flight):
    t, u, y, ok = _messy(flight, det)
    out = run(det, t, u, y, ok)
    try:
        det.set_threshold(1.0)
        low = run(det, t, u, y, ok)
        assert det.threshold == 1.0 and np.all(low.threshold == 1.0)
        assert np.array_equal(low.statistic, out.statistic)  # the statistic does not depend on it
        assert np.array_equal(low.hypothesis == 0, low.valid & (low.statistic > 1.0))
        assert (low.hypothesis == 0).sum() > (out.hypothesis == 0).sum()
        for bad in (0.0, -1.0, float("nan")):
            with pytest.raises(ValueError, match="threshold"):
                det.set_threshold(bad)
        det.set_threshold(float("inf"))  # the host's calibration replays at inf: never an alarm
        never = run(det, t, u, y, ok)
        assert np.array_equal(never.statistic, out.statistic) and np.all(never.hypothesis == -1)
    finally:
        det.set_threshold(10.0)


# --- bad input -------------------------------------------------------------------------------------


def test_unknown_signal_names_the_outputs(model):
    with pytest.raises(ValueError) as exc:
        make_cusum(model, signal="q_rads")
    msg = str(exc.value)
    assert "'q_rads'" in msg and "did you mean 'q_radps'" in msg
    assert all(nm in msg for nm in model.output_names)
    with pytest.raises(ValueError, match="did you mean 'nz_g'"):
        make_cusum(model, noise_std={"nz_gs": 0.01})
    with pytest.raises(ValueError, match="did you mean 'theta_rad'"):
        make_cusum(model, outputs=["q_radps", "theta_rads"])
    with pytest.raises(ValueError, match="must include the watched signal"):
        make_cusum(model, outputs=["theta_rad", "nz_g"])


@pytest.mark.parametrize("opts", [{"drift": -0.1}, {"threshold": 0.0}, {"gust_std_fps": 0.0},
                                  {"gust_std_fps": [1.0, 2.0]}, {"command_std": float("nan")},
                                  {"noise_std": {"q_radps": -1.0}}, {"settle_s": -1.0}])
def test_bad_options(model, opts):
    with pytest.raises(ValueError):
        make_cusum(model, **opts)


def test_bad_shapes(det):
    out = BlockOutputs.allocate(5, 1)
    with pytest.raises(ValueError, match="u must be"):
        det.process_block(np.zeros(5), np.zeros((5, 3)), np.zeros((5, 14)), np.ones((5, 14), bool),
                          np.ones((5, 14), bool), out)
    with pytest.raises(ValueError, match="y and ok"):
        det.process_block(np.zeros(5), np.zeros((5, 4)), np.zeros((5, 13)), np.ones((5, 13), bool),
                          np.ones((5, 13), bool), out)


def test_larger_out_keeps_later_rows(det, flight):
    t, u, y, ok = flight
    whole = run(det, t, u, y, ok)
    big = BlockOutputs.allocate(len(t) + 7, 1)
    big.statistic[-7:] = -1.0
    det.reset()
    det.process_block(t, u, y, ok, ok, big)
    assert same_bits(big.rows(len(t)), whole) and np.all(big.statistic[-7:] == -1.0)


def test_default_noise_covers_the_model(model):
    assert set(model.output_names) <= set(DEFAULT_NOISE_STD)


# --- cost ------------------------------------------------------------------------------------------


def test_cost_per_sample(model, det):
    """One kernel call per block: the cost of a 20,000-sample block, per sample."""
    n = 20_000
    rng = np.random.default_rng(0)
    d = det.design
    u = np.tile(d.u0, (n, 1)) + 0.001 * rng.standard_normal((n, len(d.u0)))
    y = np.tile(d.y0, (n, 1)) + d.noise_std * rng.standard_normal((n, len(d.y0)))
    ok = np.ones_like(y, dtype=bool)
    t = np.arange(1, n + 1) / RATE_HZ
    out = BlockOutputs.allocate(n, 1)
    det.reset()
    det.process_block(t[:10], u[:10], y[:10], ok[:10], ok[:10], out.rows(10))  # compiled (or loaded from cache)
    best = math.inf
    for _ in range(3):
        det.reset()
        t0 = time.perf_counter()
        det.process_block(t, u, y, ok, ok, out)
        best = min(best, time.perf_counter() - t0)
    us = best / n * 1e6
    print(f"\ncusum-residual-v1: {us:.3f} us/sample on a {n}-sample block "
          f"({len(d.output_names)} outputs, {d.A.shape[0]} states)")
    assert us < 20.0

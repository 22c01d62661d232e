"""The streaming kinematic checks (``fdi_sim.detectors.kinematic_stream``) against the batch path, on real flights.

Five short JSBSim flights (the F-16 pitch-gyro bias, the DHC-6 airspeed drift, the DHC-6 sticking
alpha vane with sensor dropouts added, fault-free F-16 in moderate and DHC-6 in light
turbulence) and a synthetic flight that reaches the corners a flight does not (heading through
+-pi, GNSS first seen late and missing for longer than the window, NaN values, alarms that freeze
the bias mean). Per flight and check: the stream gives ``KinematicDetector.run``'s numbers (bitwise
for the altitude check; within the ulp differences of numpy's AVX-512 ``tan``/``arctan2``/``arcsin``/
pow for the others, and bitwise once numpy uses the C library's, in a subprocess); block sizes
never change a number; the faults are detected and isolated as ``run`` does.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.catalogue_kinematic import KINDS, design
from fdi_sim.detectors.kinematic import (
    CHANNELS, HYPOTHESES, MEASUREMENTS, NEEDS, KinematicDetector, MeasurementSet, _euler_matrix, dcm_body_to_ned,
    vt_from_vc_fps,
)
from fdi_sim.detectors.kinematic_stream import KinematicStream
from fdi_sim.detectors.samples import Samples, log_samples
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import from_dict, load
from fdi_sim.sensors import load_suite
from fdi_sim.training import fly
from fdi_sim.training.flights import fault_free

REPO = Path(__file__).resolve().parents[2]
RATE_HZ = 20.0
#: statistic tolerance where numpy's SIMD transcendentals differ from the C library's by an ulp
RTOL, ATOL = 1e-9, 1e-12
#: (scenario, duration [s] or None, turbulence override, fault check and sensor or None, extra faults)
FLIGHTS = {
    "f16_gyro_bias": ("f16_pitch_gyro_bias.toml", 40.0, None, ("attitude", "q_radps"), []),
    "dhc6_airspeed_drift": ("dhc6_airspeed_drift.toml", None, None, ("airspeed", "vc_kts"), []),
    "dhc6_aoa_dropouts": ("dhc6_intermittent_aoa.toml", 40.0, None, ("flow-angles", "alpha_rad"), [
        {"type": "sensor-dropout-v1", "target": "theta_rad", "t_start_s": 12.0,
         "intermittent": {"duty_cycle": 0.2, "mean_dwell_s": 1.0}},
        {"type": "sensor-dropout-v1", "target": "v_down_fps", "t_start_s": 25.0, "t_end_s": 27.3},
        {"type": "sensor-dropout-v1", "target": "h_ft", "t_start_s": 33.0, "t_end_s": 33.4},
    ]),
    "f16_moderate": ("f16_cruise_doublets.toml", 60.0, "moderate", None, []),
    "dhc6_light": ("dhc6_cruise_doublets.toml", 60.0, "light", None, []),
}


class Flight:
    """One flown log, its detector samples and the raw measurements at the sample rows."""

    def __init__(self, log_path: Path, aircraft: str, turbulence: str) -> None:
        self.log_path = log_path
        self.aircraft = aircraft
        self.turbulence = turbulence
        self.log = read_log(log_path)
        rates = {s.name: s.rate_hz for s in load_suite(aircraft)}
        self.samples = log_samples(self.log, MeasurementSet(), RATE_HZ, sensor_rates_hz=rates)
        meas = self.log.topics["/sensors/measurements"]
        rows = self.samples.rows
        # the measurements as the loop sees them: heading unwrapped, a dropout's held value
        self.raw = {nm: np.asarray(meas[nm], dtype=float)[rows] for nm in MEASUREMENTS}

    def onset_s(self) -> float:
        a = self.log.topics["/faults/active"]
        on = np.any([np.asarray(a[f]) > 0.5 for f in a.fields if f.endswith("_active")], axis=0)
        return float(np.asarray(a.t_s)[np.argmax(on)])

    def detector(self, kind: str) -> KinematicDetector:
        return KinematicDetector(design(kind, self.aircraft, self.turbulence))


def _fly(name: str, out: Path) -> Flight:
    path, duration_s, turbulence, _, extra = FLIGHTS[name]
    sc = load(REPO / "scenarios" / path)
    if turbulence is not None:  # a fault-free flight of the scenario in this turbulence
        sc = fault_free(sc, sc.model.seed, duration_s or sc.model.duration_s)
        data = json.loads(sc.to_json())
        data["atmosphere"]["turbulence"] = turbulence
        sc = from_dict(data, source=f"{path} ({turbulence})")
    elif duration_s is not None:
        sc, _ = sc.shortened(duration_s)
    if extra:
        data = json.loads(sc.to_json())
        data["faults"] = data["faults"] + extra
        sc = from_dict(data, source=f"{path} (with dropouts)")
    res = fly(sc, out, progress=False)
    return Flight(Path(res.log_path), sc.aircraft, sc.model.atmosphere.turbulence)


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Flight]:
    return {name: _fly(name, tmp_path_factory.mktemp(name)) for name in FLIGHTS}


def _process(st: KinematicStream, t_s, y, ok, fresh, blocks=None) -> dict[str, np.ndarray]:
    """The stream over the rows from a fresh state, in the given block sizes (one call if None)."""
    n = len(t_s)
    out = {"statistic": np.full(n, -1.0), "valid": np.zeros(n, dtype=bool),
           "hypothesis": np.full(n, -7, dtype=np.int64), "residual": np.full((n, len(st.channels)), -1.0)}
    st.reset()
    edges = [0, n] if blocks is None else np.concatenate([[0], np.cumsum(blocks)])
    for a, b in zip(edges[:-1], edges[1:]):
        st.process(t_s[a:b], y[a:b], ok[a:b], fresh[a:b], out["statistic"][a:b], out["valid"][a:b],
                   out["hypothesis"][a:b], out["residual"][a:b])
    assert edges[-1] == n and st.samples_seen == n
    return out


def _raw_inputs(st: KinematicStream, f: Flight):
    s = f.samples
    cols = [s.output_names.index(nm) for nm in st.output_names]
    y = np.column_stack([f.raw[nm] for nm in st.output_names])
    return s.t_s, y, np.ascontiguousarray(s.valid[:, cols]), np.ascontiguousarray(s.fresh[:, cols])


def _hypotheses(st: KinematicStream, h: np.ndarray) -> list[str | None]:
    return [st.hypotheses[i] if i >= 0 else None for i in h]


def _compare(st: KinematicStream, out: dict, batch) -> dict[str, float]:
    """Assert the stream's output is ``run``'s (NaN positions, validity, isolations exact; values close)."""
    z, zb = out["statistic"], batch.statistic
    assert np.array_equal(np.isnan(z), np.isnan(zb))
    assert np.array_equal(out["valid"], batch.valid)
    assert _hypotheses(st, out["hypothesis"]) == list(batch.isolation)
    assert np.array_equal(out["valid"] & (z > st.threshold), batch.alarm)
    assert np.array_equal(np.isnan(out["residual"]), np.isnan(batch.r))
    f = np.isfinite(zb)
    np.testing.assert_allclose(z[f], zb[f], rtol=RTOL, atol=ATOL)
    rf = np.isfinite(batch.r)
    np.testing.assert_allclose(out["residual"][rf], batch.r[rf], rtol=RTOL, atol=ATOL)
    d = np.abs(z[f] - zb[f])
    return {"max_abs": float(d.max(initial=0.0)),
            "max_rel": float((d / np.maximum(np.abs(zb[f]), 1e-300)).max(initial=0.0)),
            "n_differ": int(np.sum(z[f] != zb[f])), "n_valid": int(f.sum())}


@pytest.mark.parametrize("kind", KINDS)
def test_attributes_are_the_detectors(kind: str) -> None:
    det = KinematicDetector(design(kind, "f16", "light"))
    st = KinematicStream(det)
    assert st.id == det.id == f"kinematic-{kind}-v1"
    assert st.hypotheses == HYPOTHESES[kind] and st.channels == CHANNELS[kind]
    assert st.output_names == NEEDS[kind] and st.threshold == det.design.threshold


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_stream_gives_the_batch_numbers(flights: dict[str, Flight], name: str) -> None:
    """Per check: NaN positions, validity, alarms and isolations exactly ``run``'s; statistic and residual
    within 1e-9 relative (ulps in practice), the altitude check bitwise. The raw loop inputs (heading
    unwrapped, a dropout's held value) and the offline ones (``inputs(samples)``) give the same bits."""
    f = flights[name]
    for kind in KINDS:
        det = f.detector(kind)
        st = KinematicStream(det)
        batch = det.run(f.samples)
        out = _process(st, *_raw_inputs(st, f))
        diff = _compare(st, out, batch)
        if kind == "altitude":  # no transcendental function: the same bits
            assert np.array_equal(out["statistic"], batch.statistic, equal_nan=True), diff
            assert np.array_equal(out["residual"], batch.r, equal_nan=True), diff
        x = st.inputs(f.samples)
        offline = _process(st, x.t_s, x.y, x.ok, x.fresh)
        for key in out:
            assert np.array_equal(out[key], offline[key], equal_nan=True), (kind, key)
        again = st.run(f.samples, block=5)  # the offline convenience: run's record
        for key, ref in (("statistic", out["statistic"]), ("valid", out["valid"]), ("r", out["residual"])):
            assert np.array_equal(getattr(again, key), ref, equal_nan=True), (kind, key)
        assert list(again.isolation) == _hypotheses(st, out["hypothesis"]), kind
        assert diff["n_valid"] > 0, kind


def test_dropouts_reach_the_checks(flights: dict[str, Flight]) -> None:
    """The added dropouts are in the samples (else the dropout paths above were not exercised)."""
    s = flights["dhc6_aoa_dropouts"].samples
    for nm in ("theta_rad", "v_down_fps", "h_ft"):
        assert not s.valid[:, s.output_names.index(nm)].all(), nm


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_block_size_never_changes_a_number(flights: dict[str, Flight], name: str) -> None:
    """process(all rows) == process over blocks of 1, 5, 7 and random sizes (0 included), bitwise."""
    f = flights[name]
    n = f.samples.n
    rng = np.random.default_rng(len(name))
    splits = {"1": [1] * n, "5": [5] * (n // 5) + [n % 5], "7": [7] * (n // 7) + [n % 7]}
    sizes = rng.integers(0, 40, size=n)
    splits["random"] = list(sizes[: int(np.searchsorted(np.cumsum(sizes), n))]) + [0]
    splits["random"][-1] = n - int(np.sum(splits["random"][:-1]))
    for kind in KINDS:
        st = KinematicStream(f.detector(kind))
        args = _raw_inputs(st, f)
        whole = _process(st, *args)
        for label, blocks in splits.items():
            part = _process(st, *args, blocks=blocks)
            for key in whole:
                assert np.array_equal(whole[key], part[key], equal_nan=True), (kind, label, key)


@pytest.mark.parametrize("name", [n for n, v in FLIGHTS.items() if v[3]])
def test_fault_detected_and_isolated_as_by_run(flights: dict[str, Flight], name: str) -> None:
    """The fault's own check: first alarm after the onset at the same sample as ``run``, isolated to the
    faulty sensor, every alarm isolated to it, no alarm before the onset."""
    f = flights[name]
    kind, sensor = FLIGHTS[name][3]
    det = f.detector(kind)
    st = KinematicStream(det)
    batch = det.run(f.samples)
    out = _process(st, *_raw_inputs(st, f), blocks=[5] * (f.samples.n // 5) + [f.samples.n % 5])
    alarm = out["valid"] & (out["statistic"] > st.threshold)
    onset = f.onset_s()
    t = f.samples.t_s
    assert alarm.any() and not np.any(alarm & (t < onset))
    first = int(np.argmax(alarm))
    assert first == int(np.argmax(batch.alarm))
    iso = _hypotheses(st, out["hypothesis"])
    assert iso[first] == batch.isolation[first] == sensor
    assert {iso[k] for k in np.flatnonzero(alarm)} == {sensor}


_EXACT_SCRIPT = r"""
import json, sys
from pathlib import Path
import numpy as np
sys.path.insert(0, sys.argv[1])
from test_kinematic_stream import KINDS, Flight, KinematicStream, _process, _raw_inputs
res = {}
for arg in sys.argv[2:]:
    path, ac, level = arg.split("|")
    f = Flight(Path(path), ac, level)
    for kind in KINDS:
        det = f.detector(kind)
        st = KinematicStream(det)
        b = det.run(f.samples)
        o = _process(st, *_raw_inputs(st, f))
        res[f"{Path(path).stem} {kind}"] = [bool(np.array_equal(o["statistic"], b.statistic, equal_nan=True)),
                                            bool(np.array_equal(o["residual"], b.r, equal_nan=True))]
print(json.dumps(res))
"""


def _c_library_numpy_env() -> dict[str, str]:
    """Environment in which numpy does not dispatch its AVX-512 (SVML) loops: its ``tan``, ``arctan2``,
    ``arcsin`` and pow are then the C library's, which numba calls. On a CPU without AVX-512 there
    is nothing to switch off: on the AMD EPYC (AVX2) machine of 2026-12-02 numpy's ``sin``, ``cos``,
    ``tan``, ``arcsin``, ``arctan2``, ``sqrt``, ``exp`` and pow equalled the C library's on 200 000
    arguments each (its CI failure was the BLAS 3x3 solve, now in closed form)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    off = [f for f in __cpu_dispatch__ if ("512" in f or f == "X86_V4") and __cpu_features__.get(f)]
    env = dict(os.environ)
    if off:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(off)
    return env


def test_bitwise_equal_to_run_with_the_c_library_functions(flights: dict[str, Flight]) -> None:
    """With numpy on the C library's transcendentals the stream reproduces ``run`` bit for bit, every
    check: the only differences in process are those functions' ulps (the remaining arithmetic,
    OpenBLAS's 3x3 solve included, is reproduced operation by operation)."""
    args = [f"{f.log_path}|{f.aircraft}|{f.turbulence}" for f in flights.values()]
    proc = subprocess.run([sys.executable, "-c", _EXACT_SCRIPT, str(Path(__file__).parent), *args],
                          env=_c_library_numpy_env(), capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res and all(all(v) for v in res.values()), {k: v for k, v in res.items() if not all(v)}


def _synthetic(n: int = 1100, seed: int = 5) -> Samples:
    """A consistent flight by formula at 20 Hz, steps at t = 36 s in q, vc and alpha and at 45 s in v_down:
    heading through +-pi, GNSS first fresh at row 260 then every other row but for a 220-row gap, a NaN
    flagged valid, dropouts of theta and v_down."""
    rng = np.random.default_rng(seed)
    t = (np.arange(n) + 1) / RATE_HZ
    col = {nm: np.zeros(n) for nm in MEASUREMENTS}
    phi, theta, psi = 0.3 * np.sin(0.2 * t), 0.05 + 0.002 * np.sin(0.5 * t), 3.0 + 0.01 * t  # psi through +pi
    ed = np.column_stack([0.06 * np.cos(0.2 * t), 0.001 * np.cos(0.5 * t), np.full(n, 0.01)])
    w = np.linalg.solve(_euler_matrix(phi, theta), ed[:, :, None])[:, :, 0]  # body rates of these angles
    col["phi_rad"], col["theta_rad"], col["psi_rad"] = np.array([phi, theta, psi]) + 2e-4 * rng.standard_normal((3, n))
    col["p_radps"], col["q_radps"], col["r_radps"] = (w + 1e-4 * rng.standard_normal((n, 3))).T
    col["q_radps"] += np.where(t > 36.0, 0.004, 0.0)
    h_ft = np.full(n, 5000.0)
    vc = 120.0 + 2.0 * np.sin(0.1 * t)
    alpha, beta = 0.05 + 0.01 * np.sin(0.3 * t), 0.005 * np.sin(0.7 * t)
    vt = vt_from_vc_fps(h_ft, vc)
    v_b = vt[:, None] * np.column_stack([np.cos(alpha) * np.cos(beta), np.sin(beta), np.sin(alpha) * np.cos(beta)])
    v_ned = np.einsum("nij,nj->ni", dcm_body_to_ned(phi, theta, psi), v_b) + [3.0, -2.0, 0.0]  # + wind
    col["v_north_fps"], col["v_east_fps"], col["v_down_fps"] = (v_ned + 0.1 * rng.standard_normal((n, 3))).T
    col["hdot_fps"] = -col["v_down_fps"] + 0.05 * rng.standard_normal(n)
    col["v_down_fps"] += np.where(t > 45.0, 1.5, 0.0)  # GNSS vertical velocity bias: both altitude relations
    col["h_ft"] = 5000.0 - np.cumsum(v_ned[:, 2]) / RATE_HZ + 0.5 * rng.standard_normal(n)
    col["vc_kts"] = vc + 0.2 * rng.standard_normal(n) + np.where(t > 36.0, 6.0, 0.0)
    col["alpha_rad"] = alpha + 2e-4 * rng.standard_normal(n) + np.where(t > 36.0, 0.01, 0.0)
    col["beta_rad"] = beta + 2e-4 * rng.standard_normal(n)
    y = np.column_stack([col[nm] for nm in MEASUREMENTS])
    valid = np.ones_like(y, dtype=bool)
    fresh = np.ones_like(y, dtype=bool)
    gnss = [MEASUREMENTS.index(nm) for nm in ("v_north_fps", "v_east_fps", "v_down_fps")]
    k = np.arange(n)
    fresh[:, gnss] = ((k % 2 == 1) & (k >= 260) & ~((k >= 400) & (k < 620)))[:, None]
    valid[300:310, MEASUREMENTS.index("theta_rad")] = False
    valid[500:505, MEASUREMENTS.index("v_down_fps")] = False
    y[min(777, n - 1), MEASUREMENTS.index("q_radps")] = np.nan  # not a measurement, whatever its flag says
    i_psi = MEASUREMENTS.index("psi_rad")
    y[:, i_psi] = (y[:, i_psi] + np.pi) % (2 * np.pi) - np.pi
    ok = valid & np.isfinite(y)
    return Samples(t, np.zeros((n, 0)), np.where(ok, y, 0.0), ok, fresh, (), MEASUREMENTS, RATE_HZ, 120.0,
                   6 * (k + 1), np.zeros(0), np.zeros(len(MEASUREMENTS)))


@pytest.mark.parametrize("kind", KINDS)
def test_synthetic_corners(kind: str) -> None:
    """Heading wrap, late and missing GNSS, NaN values, alarms freezing the bias mean (low threshold,
    debias on for every kind): still ``run``'s numbers, and block sizes still change nothing."""
    s = _synthetic()
    d = design(kind, "DHC6", "light")
    for dd in (d, replace(d, threshold=1.5, tau_bias_s=30.0, warmup_s=2.0)):
        det = KinematicDetector(dd)
        st = KinematicStream(det)
        batch = det.run(s)
        x = st.inputs(s)
        y, ok, fresh = x.y, x.ok, x.fresh
        out = _process(st, s.t_s, y, ok, fresh)
        _compare(st, out, batch)
        part = _process(st, s.t_s, y, ok, fresh, blocks=[3, 0, 1, 250, 11] + [5] * 167)
        for key in out:
            assert np.array_equal(out[key], part[key], equal_nan=True), key
        # the corners were reached: valid output, alarms (the bias mean frozen) and quiet samples
        if dd is not d or kind in ("attitude", "altitude"):  # (the shipped air-data thresholds are for turbulence)
            assert 0 < batch.alarm.sum() < batch.valid.sum(), batch.alarm.sum()
        if kind == "altitude" and dd is d:  # both relations out of bounds: the GNSS v_down
            assert "v_down_fps" in set(batch.isolation)


def test_reset_and_bad_shapes() -> None:
    st = KinematicStream(KinematicDetector(design("altitude", "f16", "none")))
    s = _synthetic(400)
    x = st.inputs(s)
    args = (x.t_s, x.y, x.ok, x.fresh)
    first = _process(st, *args)
    st.process(*(a[:50] for a in args), np.empty(50), np.empty(50, bool), np.empty(50, np.int64),
               np.empty((50, 2)))
    again = _process(st, *args)  # _process resets first
    for key in first:
        assert np.array_equal(first[key], again[key], equal_nan=True)
    with pytest.raises(ValueError, match="must agree"):
        st.process(s.t_s[:5], np.ascontiguousarray(args[1][:5, :2]), args[2][:5], args[3][:5], np.empty(5),
                   np.empty(5, bool), np.empty(5, np.int64), np.empty((5, 2)))


def test_a_block_costs_microseconds() -> None:
    """One process() of 5 samples (a 0.25 s block at 20 Hz), warm: a few microseconds (about 3 us
    measured); the bound only catches a fall back to Python-speed code."""
    s = _synthetic(600)
    for kind in KINDS:
        st = KinematicStream(KinematicDetector(design(kind, "f16", "light")))
        x = st.inputs(s)
        t_s, y, ok, fresh = x.t_s, x.y, x.ok, x.fresh
        oz, ov, oh, orr = np.empty(5), np.empty(5, bool), np.empty(5, np.int64), np.empty((5, len(st.channels)))
        st.process(t_s[:5], y[:5], ok[:5], fresh[:5], oz, ov, oh, orr)  # compile or load
        st.reset()
        t0 = time.perf_counter()
        for a in range(0, 600, 5):
            st.process(t_s[a:a + 5], y[a:a + 5], ok[a:a + 5], fresh[a:a + 5], oz, ov, oh, orr)
        us = (time.perf_counter() - t0) / 120 * 1e6
        assert us < 100.0, (kind, us)

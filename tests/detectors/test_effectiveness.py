"""The effectiveness estimator on the gust filter's innovations: exact on its own model, then real JSBSim flights.

The numbers these tests print (``pytest -s``) are the ones quoted in the module docstring of
``fdi_sim.detectors.effectiveness`` and in its report.
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.catalogue_observers import make_gust_kalman
from fdi_sim.detectors.effectiveness import EffectivenessEstimator, conservative_covariance
from fdi_sim.detectors.gust_kalman import analytic_calibration, calibrate
from fdi_sim.detectors.gust_kalman_stream import GustKalmanStream
from fdi_sim.detectors.samples import log_samples
from fdi_sim.detectors.scheduled import GustKalmanSchedule
from fdi_sim.errors import DesignError, SimulationDiverged
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import load
from fdi_sim.scenario.loader import from_dict
from fdi_sim.training import fly
from fdi_sim.training.flights import fault_free
from fdi_sim.training.models import model_for_scenario

ROOT = Path(__file__).resolve().parents[2]
RATE_HZ = 20.0
ELEVATOR = "elevator_cmd_norm"


# --- flights ---------------------------------------------------------------------------------------
def _scenario(path: Path | None = None, sc=None, **changes):
    """A scenario without its [fdi] section (the bank is not under test), with ``changes``."""
    sc = load(path) if sc is None else sc
    d = json.loads(sc.to_json())
    d.pop("fdi", None)
    d.update(changes)
    return from_dict(d, source=f"{sc.source} (test_effectiveness)")


def _design(sc):
    lm = model_for_scenario(sc, RATE_HZ)
    turb = sc.model.atmosphere.turbulence
    # as fdi_sim.training.gust.calibrated_gust_kalman: a calm-air design still carries light gusts
    return make_gust_kalman(lm.continuous(), rate_hz=RATE_HZ, sim_rate_hz=sc.model.rate_hz,
                            turbulence=turb if turb != "none" else "light").design


def _fly(sc, tmp: Path, design):
    log = read_log(fly(sc, tmp, progress=False).log_path)
    return log_samples(log, design.model, RATE_HZ)


class Streamed:
    """A flight through a stream: what the estimator is fed."""

    def __init__(self, stream: GustKalmanStream, s) -> None:
        N, p = s.n, stream.n_outputs
        cols = [list(s.input_names).index(nm) for nm in stream.input_names]
        self.t_s = s.t_s
        self.u = np.ascontiguousarray((s.du + s.u0)[:, cols])
        self.ok = s.valid
        out = dict(T=np.empty(N), thr=np.empty(N), valid=np.empty(N, bool), hyp=np.empty(N, np.int64),
                   cos=np.empty(N), point=np.empty(N, np.int64), nu=np.empty((N, p)), yhat=np.empty((N, p)))
        stream.reset()
        stream.process(self.u, s.dy + s.y0, s.valid, *out.values())
        self.nu, self.point = out["nu"], out["point"]
        self.stream = stream


def _estimate(f: Streamed, t_start_s: float, blocks=None, **kw):
    """Start an estimator at ``t_start_s`` and feed it the rest of the flight in ``blocks``
    (default 5 samples, the bank's 0.25 s); return it and its trace (t, e, std, excitation, usable)."""
    est = EffectivenessEstimator(f.stream, ELEVATOR, **kw)
    j = int(np.searchsorted(f.t_s, t_start_s - 1e-9))
    trace = []
    it = iter(blocks) if blocks is not None else None
    while j < len(f.t_s):
        b = int(next(it)) if it is not None else 5
        sl = slice(j, min(len(f.t_s), j + b))
        est.update(f.u[sl], f.nu[sl], f.point[sl], j)  # the stream's sample count at u[j] is j
        e, sd, ex = est.estimate
        trace.append((f.t_s[sl.stop - 1], e, sd, ex, est.usable()))
        j = sl.stop
    return est, np.array(trace)


def _report(label: str, est: EffectivenessEstimator, trace, t_onset_s: float) -> float | None:
    """Print the estimate over time and return the time after the onset it became usable [s]."""
    usable = trace[:, 4].astype(bool)
    first = float(trace[np.argmax(usable), 0]) - t_onset_s if usable.any() else None
    m = est.summary()
    print(f"\n{label}: e = {m.effectiveness:.3f} +- {m.std:.3f} (model {m.std_model:.3f}, sandwich "
          f"{m.std_sandwich:.3f}), excitation {m.excitation:.3g}, s^2 {m.residual_variance:.2f}, "
          f"nuisance {est.n_nuisance}; usable from onset + {first if first is None else round(first, 2)} s")
    for t in (1.5, 2, 3, 4, 5, 7, 10, 15, 20, 30, 45):
        k = int(np.searchsorted(trace[:, 0], t_onset_s + t - 1e-9))
        if k < len(trace):
            tt, e, sd, ex, ok = trace[k]
            print(f"   t = {tt:5.2f} s (onset + {tt - t_onset_s:5.2f}): e = {e:.3f} +- {sd:.3f}, excitation {ex:9.3g}"
                  f"{', usable' if ok else ''}")
    return first


@pytest.fixture(scope="module")
def dhc6(tmp_path_factory):
    """The shipped DHC-6 elevator loss, and the same flight without the fault, through one stream."""
    sc = _scenario(ROOT / "scenarios" / "dhc6_elevator_loss.toml")
    fault = sc.model.faults[0]
    design = _design(sc)
    stream = GustKalmanStream(GustKalmanSchedule.single(design, analytic_calibration(design, 1e-4)))
    tmp = tmp_path_factory.mktemp("eff_dhc6")
    flights = {"fault": _fly(sc, tmp / "fault", design), "free": _fly(_scenario(sc=sc, faults=[]), tmp / "free", design)}
    return {"design": design, "stream": stream, "t_onset_s": float(fault["t_start_s"]),
            "effectiveness": float(fault["effectiveness"]), "samples": flights}


# --- the estimator's own model: exact ----------------------------------------------------------
def _synthetic(design, a: float, t_trim: float, j_fault: int, N: int, rng, *, beta: float = 0.0, j_start: int = 0,
               tau_s: float = 1.0, dropout: bool = False):
    """The design's own linear plant, noise-free, with the fault ``f_j = a (u_j + t)`` on the
    elevator from sample ``j_fault`` (times ``1 - beta rho^(j - j_start)`` from ``j_start``:
    a deficit that dies out with ``tau_s``). Returns absolute u (N, m), absolute y, ok."""
    m = design.model
    cols = list(design.control_columns)
    A, C = np.asarray(m.A), np.asarray(m.C)
    B, D = np.asarray(m.B)[:, cols], np.asarray(m.D)[:, cols]
    u0, y0 = np.asarray(m.u0, dtype=float)[cols], np.asarray(m.y0, dtype=float)
    du = np.zeros((N, len(cols)))
    # a random staircase on the elevator (steps every 0.5 s) and small ones on the others
    du[:, 0] = np.repeat(rng.uniform(-0.05, 0.05, N // 10 + 1), 10)[:N]
    du[:, 1:3] = np.repeat(rng.uniform(-0.02, 0.02, (N // 10 + 1, 2)), 10, axis=0)[:N]
    u = u0 + du
    rho = np.exp(-1.0 / (tau_s * RATE_HZ))
    x = np.zeros(m.n_states)
    y = np.empty((N, m.n_outputs))
    for j in range(N):
        f = np.zeros(len(cols))
        if j >= j_fault:
            w = 1.0 - beta * rho ** (j - j_start) if j >= j_start else 1.0 - beta
            f[0] = w * a * (u[j, 0] + t_trim)
        y[j] = y0 + C @ x + D @ (du[j] + f)
        x = A @ x + B @ (du[j] + f)
    ok = np.ones_like(y, dtype=bool)
    if dropout:  # alpha vane and airspeed out for 2 s
        names = list(m.output_names)
        ok[N // 2: N // 2 + 40, [names.index("alpha_rad"), names.index("vc_kts")]] = False
    return u, y, ok


def _stream_arrays(stream, u, y, ok):
    N, p = len(u), stream.n_outputs
    out = dict(T=np.empty(N), thr=np.empty(N), valid=np.empty(N, bool), hyp=np.empty(N, np.int64), cos=np.empty(N),
               point=np.empty(N, np.int64), nu=np.empty((N, p)), yhat=np.empty((N, p)))
    stream.reset()
    stream.process(u, y, ok, *out.values())
    return out["nu"], out["point"]


@pytest.mark.parametrize("case", ["constant", "deficit", "dropout"])
def test_exact_on_the_filters_own_model(dhc6, case):
    """Noise-free, the design's own plant: the fault acted for 1 s before the start (while the gains
    still change, so the gain index matters), and the estimate is the truth to the vague prior's
    pull (a few 1e-6); the residual is zero to 1e-10. A gain index one sample off misses by far
    more (checked below)."""
    design, stream = dhc6["design"], dhc6["stream"]
    rng = np.random.default_rng(11)
    j_fault, j0, N = 20, 40, 400
    beta = 0.5 if case == "deficit" else 0.0
    u, y, ok = _synthetic(design, -0.4, 0.26, j_fault, N, rng, beta=beta, j_start=j0, dropout=case == "dropout")
    nu, point = _stream_arrays(stream, u, y, ok)
    est = EffectivenessEstimator(stream, ELEVATOR, nuisance_dim=20)  # (12 leave 1e-4)
    for k in range(j0, N, 7):
        sl = slice(k, min(N, k + 7))
        est.update(u[sl], nu[sl], point[sl], k, ok=ok[sl] if case == "dropout" else None)
    m = est.summary()
    assert abs(m.effectiveness - 0.6) < 1e-5, m
    assert abs(m.offset - (-0.4 * 0.26)) < 1e-5, m
    assert m.residual_variance < 1e-10, m
    # the gain index one sample off, or the steady gain throughout: the regressors are not the
    # filter's and the residual is no longer zero
    for g0 in (j0 + 1, 10 ** 6):
        off = EffectivenessEstimator(stream, ELEVATOR, nuisance_dim=20)
        off.update(u[j0:], nu[j0:], point[j0:], g0, ok=ok[j0:] if case == "dropout" else None)
        assert off.summary().residual_variance > 1e4 * m.residual_variance


def test_each_nuisance_is_needed_for_exactness(dhc6):
    """The same noise-free flight with a deficit: leaving out the initial-error nuisance (the
    fault's history before the start) or the deficit (the fault still growing) leaves a residual
    and an error 100 times the full estimator's (on this rich excitation a small one; on the real
    flight below the deficit is what matters)."""
    design, stream = dhc6["design"], dhc6["stream"]
    u, y, ok = _synthetic(design, -0.4, 0.26, 20, 400, np.random.default_rng(11), beta=0.5, j_start=40)
    nu, point = _stream_arrays(stream, u, y, ok)
    ests = {"full": EffectivenessEstimator(stream, ELEVATOR, nuisance_dim=20),
            "no deficit": EffectivenessEstimator(stream, ELEVATOR, settle_s=None, nuisance_dim=20),
            "no initial error": EffectivenessEstimator(stream, ELEVATOR, nuisance_dim=0)}
    for est in ests.values():
        est.update(u[40:], nu[40:], point[40:], 40)
    err = {k: abs(est.estimate[0] - 0.6) for k, est in ests.items()}
    assert err["full"] < 1e-5
    assert err["no deficit"] > 100 * err["full"] and err["no initial error"] > 100 * err["full"], err
    assert ests["no deficit"].summary().residual_variance > 1e-6
    assert ests["no initial error"].summary().residual_variance > 1e-6


# --- real flights ----------------------------------------------------------------------------------
def test_dhc6_elevator_loss(dhc6):
    """The shipped scenario, started 1 s after the onset (halfway up the 2 s ramp) as if isolated then."""
    f = Streamed(dhc6["stream"], dhc6["samples"]["fault"])
    t_on, truth = dhc6["t_onset_s"], dhc6["effectiveness"]
    est, tr = _estimate(f, t_on + 1.0)
    first = _report("DHC-6 elevator 0.5", est, tr, t_on)
    e, sd, ex = est.estimate
    assert abs(e - truth) <= 0.1
    assert abs(e - truth) <= 2.0 * sd  # the std covers the error
    assert est.usable() and first is not None and first < 3.0
    # every usable estimate on the way was good: within 0.1, or 2 std (one, at 16.45 s, the
    # doublet's first half second: 0.601 +- 0.056)
    usable = tr[:, 4].astype(bool)
    assert np.all(np.abs(tr[usable, 1] - truth) <= np.maximum(0.1, 2.0 * tr[usable, 2]))


def test_dhc6_fault_free(dhc6):
    """The same flight without the fault, started at the same time: near 1, and never a rescale."""
    f = Streamed(dhc6["stream"], dhc6["samples"]["free"])
    est, tr = _estimate(f, dhc6["t_onset_s"] + 1.0)
    _report("DHC-6 fault-free", est, tr, dhc6["t_onset_s"])
    e, sd, _ = est.estimate
    assert abs(e - 1.0) <= 0.1 or not est.usable()
    assert not tr[:, 4].astype(bool).any()


def test_dhc6_nuisances_on_the_real_flight(dhc6):
    """Started halfway up the ramp, a constant-fault model is far off; the deficit brings it back
    (the numbers of the module docstring)."""
    f = Streamed(dhc6["stream"], dhc6["samples"]["fault"])
    j0 = int(np.searchsorted(f.t_s, dhc6["t_onset_s"] + 1.0 - 1e-9))
    out = {}
    for label, kw in (("neither", dict(nuisance_dim=0, settle_s=None)), ("initial error", dict(settle_s=None)),
                      ("deficit", dict(nuisance_dim=0)), ("both", {})):
        est = EffectivenessEstimator(f.stream, ELEVATOR, **kw)
        est.update(f.u[j0:], f.nu[j0:], f.point[j0:], j0)
        out[label] = est.estimate[0]
    print("\nDHC-6 at 60 s, by nuisance: " + ", ".join(f"{k} {v:.3f}" for k, v in out.items()))
    assert abs(out["neither"] - 0.5) > 0.1 and abs(out["initial error"] - 0.5) > 0.1
    assert abs(out["both"] - 0.5) < 0.03


@pytest.mark.parametrize("which", ["fault", "free"])
def test_chunk_invariance(dhc6, which):
    """Blocks of 1, 5 and random lengths give the same bits as one block (estimate and state)."""
    f = Streamed(dhc6["stream"], dhc6["samples"][which])
    j0 = int(np.searchsorted(f.t_s, dhc6["t_onset_s"] + 1.0 - 1e-9))
    N = len(f.t_s)
    whole = EffectivenessEstimator(f.stream, ELEVATOR)
    whole.update(f.u[j0:], f.nu[j0:], f.point[j0:], j0)
    rng = np.random.default_rng(5)
    for blocks in ([1] * N, [5] * N, rng.integers(1, 40, size=N)):
        est, _ = _estimate(f, f.t_s[j0], blocks)
        assert est.summary() == whole.summary()
        for k in ("_X", "_M", "_h", "_Mb", "_hb", "_acc", "_Shh", "_SMh", "_SMM", "_st"):
            assert np.array_equal(getattr(est, k), getattr(whole, k)), k


def test_update_cost(dhc6):
    """One update of a 0.25 s block (5 samples) and one estimate, warm (printed; a loose bound)."""
    f = Streamed(dhc6["stream"], dhc6["samples"]["fault"])
    est = EffectivenessEstimator(f.stream, ELEVATOR)
    est.update(f.u[260:265], f.nu[260:265], f.point[260:265], 260)  # compiled (cached) by now
    n, t_up, t_est = 0, 0.0, 0.0
    for j in range(265, len(f.t_s) - 5, 5):
        t0 = time.perf_counter()
        est.update(f.u[j:j + 5], f.nu[j:j + 5], f.point[j:j + 5], j)
        t1 = time.perf_counter()
        est.estimate
        t_est += time.perf_counter() - t1
        t_up += t1 - t0
        n += 1
    print(f"\nupdate (5 samples, q = {est._q}): {1e6 * t_up / n:.0f} us; estimate: {1e6 * t_est / n:.0f} us")
    assert t_up / n < 5e-3


def test_switching_between_identical_points_changes_nothing(dhc6):
    """Two points with the same design: the point sequence moves no bit (matrices by point)."""
    f = Streamed(dhc6["stream"], dhc6["samples"]["fault"])
    d, cal = dhc6["design"], dhc6["stream"].schedule.calibrations[0]
    h0, v0 = GustKalmanSchedule.single(d, cal).points[0]
    two = GustKalmanStream(GustKalmanSchedule(np.array([[h0, v0], [h0, v0 + 10.0]]), np.array([2000.0, 40.0]),
                                              (d, d), (cal, cal)))
    j0 = 260
    one = EffectivenessEstimator(f.stream, ELEVATOR)
    one.update(f.u[j0:], f.nu[j0:], f.point[j0:], j0)
    alt = EffectivenessEstimator(two, ELEVATOR)
    pts = (np.arange(len(f.t_s) - j0) // 13 % 2).astype(np.int64)
    alt.update(f.u[j0:], f.nu[j0:], pts, j0)
    assert alt.summary() == one.summary()


def test_bad_input(dhc6):
    with pytest.raises(DesignError, match="did you mean 'elevator_cmd_norm'"):
        EffectivenessEstimator(dhc6["stream"], "elevator_cmd")
    with pytest.raises(DesignError, match="did you mean 'conservative'"):
        EffectivenessEstimator(dhc6["stream"], ELEVATOR, weights="conservativ")
    est = EffectivenessEstimator(dhc6["stream"], ELEVATOR)
    with pytest.raises(DesignError, match="update needs"):
        est.update(np.zeros((3, 4)), np.zeros((2, 14)), np.zeros(3, np.int64), 0)
    e, sd, ex = est.estimate  # nothing yet
    assert np.isnan(e) and np.isnan(sd) and ex == 0.0 and not est.usable()


def test_conservative_covariance():
    """Inflated where the measured one is larger, never below the design's."""
    rng = np.random.default_rng(2)
    Q = np.linalg.qr(rng.normal(size=(4, 4)))[0]
    S = Q @ np.diag([1.0, 2.0, 3.0, 4.0]) @ Q.T
    Sm = Q @ np.diag([0.5, 2.0, 30.0, 1.0]) @ Q.T
    Sc = conservative_covariance(S, Sm)
    assert np.all(np.linalg.eigvalsh(Sc - S) > -1e-12) and np.all(np.linalg.eigvalsh(Sc - Sm) > -1e-12)
    np.testing.assert_allclose(conservative_covariance(S, S), S, atol=1e-12)


# --- F-16 -----------------------------------------------------------------------------------------
F16_EXTRA_DOUBLETS_S = (18.0, 28.0, 52.0)


@pytest.fixture(scope="module")
def f16(tmp_path_factory):
    """f16_cruise_doublets (moderate turbulence) with elevator doublets also at 18, 28 and 52 s,
    and the elevator at 0.6 effectiveness from 15 s (ramped over 2 s); the filter calibrated on
    six fault-free 60 s flights of it (the bank calibrates on its own training flights)."""
    base = _scenario(ROOT / "scenarios" / "f16_cruise_doublets.toml")
    d = json.loads(base.to_json())
    elev = next(m for m in d["maneuvers"] if m["axis"] == "elevator")
    man = d["maneuvers"] + [dict(elev, t_start_s=t) for t in F16_EXTRA_DOUBLETS_S]
    free = _scenario(sc=base, maneuvers=man, faults=[])
    fault = _scenario(sc=base, maneuvers=man, faults=[{"type": "actuator-loss-v1", "target": "elevator",
                                                       "effectiveness": 0.6, "t_start_s": 15.0, "ramp_s": 2.0}])
    design = _design(free)
    tmp = tmp_path_factory.mktemp("eff_f16")
    try:
        s_fault = _fly(fault, tmp / "fault", design)
    except SimulationDiverged as exc:  # pragma: no cover - it stays controllable (measured)
        pytest.skip(f"the F-16 departs with the elevator at 0.6: {exc}")
    training = [_fly(fault_free(free, seed, 60.0), tmp / f"train{seed}", design) for seed in range(100, 106)]
    cal = calibrate(design, training, 5e-3, labels=[f"seed {s}" for s in range(100, 106)])
    stream = GustKalmanStream(GustKalmanSchedule.single(design, cal))
    return {"stream": stream, "design": design, "t_onset_s": 15.0,
            "samples": {"fault": s_fault, "free": _fly(free, tmp / "free", design)},
            "analytic": GustKalmanStream(GustKalmanSchedule.single(design, analytic_calibration(design, 1e-4)))}


def test_f16_elevator_loss(f16):
    """The F-16's fly-by-wire loop (q, nz, alpha through the same elevator, with an integrator) is
    inside the filter's model, so the surface's loss is not an additive command fault: the loop
    makes up part of it, and what is estimated is the command path's effectiveness in the model,
    between the surface's 0.6 and 1 (module docstring). It must show a significant loss."""
    f = Streamed(f16["stream"], f16["samples"]["fault"])
    est, tr = _estimate(f, f16["t_onset_s"] + 1.0)
    _report("F-16 elevator 0.6 (surface), conservative weights", est, tr, f16["t_onset_s"])
    e, sd, _ = est.estimate
    assert 0.5 <= e <= 0.9
    assert 1.0 - e >= 2.0 * sd


def test_f16_fault_free(f16):
    """Fault-free: near 1 or not usable, with the calibrated (conservative) weights; the design's
    weights alone are printed for the comparison of the module docstring."""
    f = Streamed(f16["stream"], f16["samples"]["free"])
    est, tr = _estimate(f, f16["t_onset_s"] + 1.0)
    _report("F-16 fault-free, conservative weights", est, tr, f16["t_onset_s"])
    e, sd, _ = est.estimate
    assert abs(e - 1.0) <= 0.1 or not est.usable()
    assert not tr[:, 4].astype(bool).any()
    for which in ("fault", "free"):
        g = Streamed(f16["analytic"], f16["samples"][which])
        est_d, tr_d = _estimate(g, f16["t_onset_s"] + 1.0)
        _report(f"F-16 {which}, design weights", est_d, tr_d, f16["t_onset_s"])

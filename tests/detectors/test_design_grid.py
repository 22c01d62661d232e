"""Every registered detector designs on both aircraft at the default-grid points, or refuses with its reason.

Issue 12: "Every registered detector designs on both aircraft at every default-grid point, or
refuses with its reason; a test forces a diverging design and checks that it is reported invalid."

Models are the user's default: ``ModelSchedule.model_at(op, dt_s=1/120)`` (ZOH at the 120 Hz
loop rate, accelerometers one step late) of the linearizer's default grids; the LMI filter,
designed in continuous time, gets ``ModelSchedule.continuous(i)`` and runs at 1/120 s. Noise is
each aircraft's sensor suite (``aircraft/<name>/sensors.toml``), as a user would pass it. PCA is
trained on a closed-loop run of the model that makes the relations the issue names: the aileron
is an exact linear function of the measured roll angle (an autopilot's ``u = K y``) and the
rudder and throttle commands are identically zero.

Once designed, a detector gets at least 30 steps at trim (``u0``, ``y0``; a windowed one until it is
valid, at most 10 s): a non-finite statistic must be marked invalid, the last step must be valid,
finite and without alarm.

The default suite runs three points per aircraft (first, middle, last of the grid); the whole
grid (20 F-16 and 30 DHC-6 points, every detector) is ``slow``. Measured on the development machine
(2 cores shared with other jobs, ``pytest -s -m slow tests/detectors/test_design_grid.py``): see
the table the slow test prints; every design takes well under the 120 Hz loop's budget to
*design* except the LMI filter (an SDP per detection eigenvalue, 1-6 s).
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from fdi_sim import registry
from fdi_sim.detectors.beard_jones_filter import BeardJonesFilter
from fdi_sim.detectors.catalogue_observers import make_kalman
from fdi_sim.detectors.catalogue_parity import make_parity
from fdi_sim.detectors.directional_observer import DiscreteObserver
from fdi_sim.detectors.noise import suite_sensor_std
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.schedule import ModelSchedule

DT_S = 1.0 / 120.0  # the default detector rate (the simulation's)
N_TRIM_STEPS = 30  # at least this many trim steps; windowed detectors run until valid, at most MAX_TRIM_STEPS
MAX_TRIM_STEPS = 1200  # 10 s at 120 Hz
N_TRAIN = 2000  # PCA training samples (16.7 s at 120 Hz; d = 3 * (14 + 4) = 54 columns)

#: the divergence tests overflow on purpose
OVERFLOW_OK = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning",
                                         "ignore:invalid value encountered:RuntimeWarning")

#: the registered detectors this test parameterizes (noise, training data, alternatives); any
#: other registered detector is built as ``factory(model)`` with the 120 Hz model
KNOWN_DETECTORS = {
    "adaptive-observer-v1", "beard-jones-v1", "kalman-mmae-v1", "kalman-nis-v1", "kalman-tv-nis-v1",
    "lmi-detection-v1", "parity-robust-v1", "parity-stochastic-v1", "parity-v1", "pca-v1",
}

#: (detector, aircraft) -> the reason every point refuses with. Empty: each refusal found for
#: issue 12 was a defect and is fixed at its cause, none is a property of the aircraft:
#: - pca-v1 on the F-16 ("exactly collinear"): exact software relations in the training data are
#:   now dropped with a note (fdi_sim.detectors.pca.exact_relations);
#: - beard-jones-v1 on the DHC-6 ("cannot place the completion poles"): C of the 120 Hz model has
#:   rank 13 for 14 outputs (theta_rad - alpha_rad = hdot_fps / V, a kinematic identity), so the
#:   completion pair's input matrix C1' lost a column and scipy's place_poles (which needs full
#:   column rank) failed; no mode was uncontrollable (scaled PBH margins >= 1.6e-4). The
#:   completion now uses range(C_i). The throttle then failed as "no unique generator": the Krylov
#:   matrix counted a direction at 2.5e-10 of its largest singular value as a second detection
#:   dimension; the detection space is now the orthogonal staircase of the balanced pair;
#: - lmi-detection-v1 on both ("not observable, rank 5 of 10"): the unscaled Krylov rank is
#:   replaced by a scaled PBH test (least margin on the grids 1.2e-3, tolerance 1e-8), and the
#:   default pole bound 20 rad/s, infeasible with these sensors, is now 100 rad/s.
#: The refusals left are of detectors that need signals a linear model does not have:
EXPECTED_REFUSALS: dict[tuple[str, str], str] = {
    # the kinematic checks compare air data with GNSS velocity (v_north/east/down_fps): signals of the
    # sensor suite and the log, not outputs of the linearizer's rigid-body model, so built from a model
    # they refuse and name the missing measurements (they are built from a log's signal names instead)
    **{(f"kinematic-{kind}-v1", ac): "needs the measurements v_" for kind in ("altitude", "airspeed", "flow-angles")
       for ac in ("f16", "DHC6")},
    # the engine-gauge check compares the two engines' gauges, which the linear model does not output
    **{("engine-gauges-v1", ac): "needs the measurements n1_0_pct" for ac in ("f16", "DHC6")},
}


def _closed_loop_training(md: LinearModel, sensor_std: np.ndarray, rng: np.random.Generator
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Absolute (u_controls, y) of a run with exact autopilot relations (module docstring)."""
    cols = md.control_columns()
    names = [md.input_names[i] for i in cols]
    i_el, i_ail = names.index("elevator_cmd_norm"), names.index("aileron_cmd_norm")
    i_phi = md.output_names.index("phi_rad")
    k_phi = 0.2  # aileron per roll-angle error [norm/rad]: a wing leveller, u = -K y exactly
    excite = 0.005 * rng.standard_normal(N_TRAIN)  # elevator excitation [norm]
    noise = sensor_std * rng.standard_normal((N_TRAIN, md.n_outputs))
    x = np.zeros(md.n_states)
    u_c = np.zeros((N_TRAIN, len(cols)))
    y = np.zeros((N_TRAIN, md.n_outputs))
    u = np.zeros(md.n_inputs)  # gusts stay 0
    for k in range(N_TRAIN):
        y_meas = md.C @ x + noise[k]  # D u enters below with this step's u
        u[:] = 0.0
        u[cols[i_el]] = excite[k]
        u[cols[i_ail]] = -k_phi * y_meas[i_phi]
        y[k] = y_meas + md.D @ u
        u_c[k] = u[cols]
        x = md.A @ x + md.B @ u
    return u_c + md.u0[cols], y + md.y0


def _design(detector: str, aircraft: str, sched: ModelSchedule, i: int, rng: np.random.Generator) -> tuple[Any, LinearModel]:
    """Build ``detector`` at point ``i`` (position in ``sched.points``); returns it and the runtime model."""
    p = sched.points[i]
    sm = sched.model_at(p.op, dt_s=DT_S)
    assert sm.indices == (i,)  # the model of this grid point, not a neighbour's
    md = sm.model
    sd = suite_sensor_std(md)
    factory = registry.get("detector", detector).factory
    if detector == "parity-v1":
        return factory(md, R=np.diag(sd**2)), md
    if detector == "parity-stochastic-v1":
        return factory(md, R=np.diag(sd**2)), md
    if detector == "parity-robust-v1":
        return factory(md, measurement_sqrt=np.diag(sd)), md
    if detector == "pca-v1":
        u_tr, y_tr = _closed_loop_training(md, sd, rng)
        return factory(md, train_u=u_tr, train_y=y_tr), md
    if detector == "kalman-mmae-v1":
        j = sched.ok_points.index(p)
        other = sched.ok_points[(j + 1) % len(sched.ok_points)]
        alt = sched.model_at(other.op, dt_s=DT_S).model
        return factory(md, alternatives={"neighbour": alt}, sensor_std=sd), md
    if detector == "lmi-detection-v1":
        return factory(sched.continuous(i), sensor_std=sd, dt_s=DT_S), md
    if detector in ("beard-jones-v1", "kalman-nis-v1", "kalman-tv-nis-v1", "adaptive-observer-v1"):
        return factory(md, sensor_std=sd), md
    return factory(md), md


def _check_at_trim(det: Any, md: LinearModel, rng: np.random.Generator) -> None:
    det.reset(rng)
    for k in range(MAX_TRIM_STEPS):
        res = det.step(k * DT_S, md.u0, md.y0)
        assert np.isfinite(res.statistic) or not res.valid, (det.id, k, res)  # a NaN while filling must say so
        if k + 1 >= N_TRIM_STEPS and res.valid:
            break
    assert res.valid and np.isfinite(res.statistic) and not res.alarm, (det.id, res)


def _run_grid(schedules: dict[str, ModelSchedule], points: dict[str, list[int]]) -> dict[tuple[str, str], dict[str, Any]]:
    """Design every registered detector at the given points; returns per (detector, aircraft) the
    refusals ``{point label: message}`` and the design times [s]."""
    ids = set(registry.ids("detector"))
    assert KNOWN_DETECTORS <= ids, f"{KNOWN_DETECTORS - ids} are no longer registered"
    out: dict[tuple[str, str], dict[str, Any]] = {}
    for detector in sorted(ids):
        for aircraft, sched in schedules.items():
            entry: dict[str, Any] = {"refused": {}, "times_s": []}
            for i in points[aircraft]:
                rng = np.random.default_rng(1000 + i)
                t0 = time.perf_counter()
                try:
                    det, md = _design(detector, aircraft, sched, i, rng)
                except DesignError as exc:
                    entry["refused"][sched.points[i].op.label()] = str(exc)
                    continue
                entry["times_s"].append(time.perf_counter() - t0)
                _check_at_trim(det, md, rng)
            out[(detector, aircraft)] = entry
    return out


def _assert_expected(result: dict[tuple[str, str], dict[str, Any]], n_points: dict[str, int]) -> None:
    for (detector, aircraft), entry in result.items():
        refused = entry["refused"]
        why = EXPECTED_REFUSALS.get((detector, aircraft))
        if why is None:
            assert not refused, f"{detector} on {aircraft} refused: {refused}"
        else:
            assert len(refused) == n_points[aircraft] and all(why in m for m in refused.values()), refused


def _table(result: dict[tuple[str, str], dict[str, Any]]) -> str:
    rows = ["detector                  aircraft designed refused  design time [s] median / max"]
    for (detector, aircraft), e in sorted(result.items()):
        t = np.array(e["times_s"]) if e["times_s"] else np.array([np.nan])
        rows.append(f"{detector:25s} {aircraft:8s} {len(e['times_s']):8d} {len(e['refused']):7d}  "
                    f"{np.median(t):.4f} / {t.max():.4f}")
    return "\n".join(rows)


def _ok_positions(sched: ModelSchedule) -> list[int]:
    return [i for i, p in enumerate(sched.points) if p.index >= 0]


def test_every_detector_designs_at_representative_points(default_schedules: dict[str, ModelSchedule]) -> None:
    # first, middle and last grid point of each aircraft (low/slow, mid, high/fast or flaps 10)
    points = {}
    for ac, s in default_schedules.items():
        ok = _ok_positions(s)
        assert len(ok) == len(s.points)  # every default point trims
        points[ac] = [ok[0], ok[len(ok) // 2], ok[-1]]
    result = _run_grid(default_schedules, points)
    print("\n" + _table(result))
    _assert_expected(result, {ac: len(p) for ac, p in points.items()})


@pytest.mark.slow
def test_every_detector_designs_at_every_default_grid_point(default_schedules: dict[str, ModelSchedule]) -> None:
    points = {ac: _ok_positions(s) for ac, s in default_schedules.items()}
    result = _run_grid(default_schedules, points)
    print("\n" + _table(result))
    _assert_expected(result, {ac: len(p) for ac, p in points.items()})


# --------------------------------------------------------------------------- divergence


def _assert_reported_invalid(results: list[Any]) -> None:
    """A run that diverges: some statistic is non-finite, and every such step is invalid without alarm."""
    bad = [r for r in results if not np.isfinite(r.statistic)]
    assert bad, "the forced design did not diverge"
    assert all(not r.valid and not r.alarm and r.isolation is None for r in bad)
    assert results[-1] is bad[-1]  # a diverged state stays diverged and stays reported


@OVERFLOW_OK
def test_diverging_kalman_filter_is_reported_invalid(default_schedules: dict[str, ModelSchedule]) -> None:
    # a Kalman filter whose model is mis-scaled (A doubled: every mode ~2 per step) and whose gain
    # is zero runs open loop on an unstable model: a 1e-3 command offset overflows in about 1000 steps
    sched = default_schedules["f16"]
    md = sched.model_at(sched.points[0].op, dt_s=DT_S).model
    det = make_kalman(md, sensor_std=suite_sensor_std(md))
    bad = replace(det.design, model=replace(md, A=2.0 * md.A), K=np.zeros_like(det.design.K))
    det = type(det)(bad, alpha=det.alpha)
    det.reset()
    u = md.u0 + 1e-3
    _assert_reported_invalid([det.step(k * DT_S, u, md.y0) for k in range(3000)])


@OVERFLOW_OK
def test_diverging_beard_jones_filter_is_reported_invalid(default_schedules: dict[str, ModelSchedule]) -> None:
    # a Beard-Jones filter designed on the DHC-6, then run open loop (zero gain) on its model with A
    # doubled: the runtime of a mis-scaled design, every mode but the lag states at ~2 per step
    sched = default_schedules["DHC6"]
    md = sched.model_at(sched.points[0].op, dt_s=DT_S).model
    det = registry.get("detector", "beard-jones-v1").factory(md, faults=["elevator_cmd_norm"], sensor_std=suite_sensor_std(md))
    assert isinstance(det, BeardJonesFilter)
    det.observer = DiscreteObserver.from_gain(2.0 * md.A, md.B, md.C, md.D, np.zeros_like(det.design.gain.L), md.u0, md.y0)
    det.reset()
    u = md.u0 + 1e-3
    _assert_reported_invalid([det.step(k * DT_S, u, md.y0) for k in range(3000)])


@OVERFLOW_OK
def test_hugely_mis_scaled_parity_model_is_refused(default_schedules: dict[str, ModelSchedule]) -> None:
    # parity relations of a model whose input matrices are 1e300 too large: the noise covariance of
    # the window overflows at design, and the design says so instead of running a NaN threshold
    sched = default_schedules["f16"]
    md = sched.model_at(sched.points[0].op, dt_s=DT_S).model
    R = np.diag(suite_sensor_std(md) ** 2)
    make_parity(md, order_s=1, R=R)  # the right model designs
    with pytest.raises(DesignError, match="not finite"):
        make_parity(replace(md, B=1e300 * md.B, D=1e300 * md.D), order_s=1, R=R, actuators=["elevator_cmd_norm"])


@OVERFLOW_OK
@pytest.mark.parametrize("detector", sorted(KNOWN_DETECTORS))  # the model-built ones
def test_overflowing_measurement_is_never_a_valid_no_alarm(detector: str, default_schedules: dict[str, ModelSchedule]) -> None:
    # every registered detector, fed a finite but absurd measurement (1e300 off trim on every
    # output): its statistic overflows, and the step must say invalid, not "valid, no alarm"
    sched = default_schedules["DHC6"]
    i = _ok_positions(sched)[0]
    det, md = _design(detector, "DHC6", sched, i, np.random.default_rng(7))
    det.reset(np.random.default_rng(7))
    y = md.y0 + 1e300
    results = [det.step(k * DT_S, md.u0, y) for k in range(5)]
    for r in results:
        if not np.isfinite(r.statistic):
            assert not r.valid and not r.alarm, (detector, r)
    assert not results[-1].valid, (detector, results[-1])  # the overflow is reported, whatever the statistic


# --------------------------------------------------------------------------- the causes, one by one


def test_pca_drops_the_exact_relations_the_autopilot_makes(default_schedules: dict[str, ModelSchedule]) -> None:
    # F-16 training data with a wing leveller (aileron = -K phi exactly) and rudder/throttle at 0:
    # the raw data are exactly collinear (what made pca-v1 refuse), the training drops those
    # directions with a note naming the zero columns
    from fdi_sim.detectors.pca import pca_train, series_windows

    sched = default_schedules["f16"]
    md = sched.model_at(sched.points[0].op, dt_s=DT_S).model
    u_tr, y_tr = _closed_loop_training(md, suite_sensor_std(md), np.random.default_rng(3))
    cols = md.control_columns()
    Z = series_windows(u_tr, y_tr, 3, md.u0[cols], md.y0)
    sv = np.linalg.svd(Z, compute_uv=False)
    assert sv[-1] < 1e-12 * sv[0]  # exactly collinear: the old eigenvalue test (1e-14 on sv^2) refused
    u_names = [md.input_names[i] for i in cols]
    names = [f"{n}[k-{2 - j}]" for sig in (md.output_names, u_names) for j in range(3) for n in sig]
    pca = pca_train(Z, 3 * md.n_outputs - md.n_states, column_names=names)
    assert "rudder_cmd_norm[k-0]" in pca.notes[0] and "throttle_cmd_norm[k-2]" in pca.notes[0]
    # 6 zero columns (rudder, throttle at 3 lags) + 3 aileron = -K phi relations
    assert pca.exact_relations.shape[1] == 9, pca.notes
    assert np.abs(Z @ pca.exact_relations).max() < 1e-9 * np.abs(Z).max()
    # the residual space has noise variance (7e-8 of 17 here), not rounding (the dropped ones: ~1e-32)
    assert pca.D_r.min() > 1e-12 * pca.eigenvalues[0]


def test_observability_is_tested_scaled(default_schedules: dict[str, ModelSchedule]) -> None:
    # the fully measured continuous F-16: the unscaled Krylov rank at 1e-9 (the old test) says
    # rank < 10, the scaled PBH test sees every mode; a state nothing couples to is refused
    import control

    from fdi_sim.detectors.beard_jones import check_observable, observability_margins

    m = default_schedules["f16"].continuous(0)
    s = np.linalg.svd(control.obsv(m.A, m.C), compute_uv=False)
    assert int(np.sum(s > 1e-9 * s[0])) < m.n_states
    check_observable(m.A, m.C)
    assert observability_margins(m.A, m.C)[1].min() > 1e-3
    # (without psi_rad the heading is still seen, weakly: A couples it to alpha by -1.5e-4 1/s, margin 6e-4)
    n = m.n_states
    A = np.zeros((n + 1, n + 1))
    A[:n, :n], A[n, n] = m.A, -1.0  # an extra stable state no output sees
    C = np.hstack([m.C, np.zeros((m.n_outputs, 1))])
    with pytest.raises(DesignError, match="not observable") as exc:
        check_observable(A, C)
    assert ", 1.0]" in str(exc.value) or ", -1.0]" in str(exc.value)  # its direction is the extra state


def test_dhc6_outputs_carry_an_exact_kinematic_relation(default_schedules: dict[str, ModelSchedule]) -> None:
    # why the Beard-Jones completion could not be placed on the DHC-6: C (120 Hz ZOH) has rank
    # n_outputs - 1, theta_rad - alpha_rad = hdot_fps / V; the design now works on range(C_i)
    sched = default_schedules["DHC6"]
    md = sched.model_at(sched.points[0].op, dt_s=DT_S).model
    u, s, _ = np.linalg.svd(md.C)
    assert s[-1] < 1e-12 * s[0] and md.C.shape[0] == len(s)
    w = dict(zip(md.output_names, u[:, -1] * np.sign(u[md.output_names.index("theta_rad"), -1])))
    assert w["theta_rad"] > 0.7 and w["alpha_rad"] < -0.7
    det = registry.get("detector", "beard-jones-v1").factory(md, sensor_std=suite_sensor_std(md))
    assert set(det.hypotheses) == {"elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm"}

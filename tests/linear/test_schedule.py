"""Model schedule: file round trip, refusal of foreign files, nearest and interpolated lookup, tracker."""
from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.schedule import ModelSchedule, SchedulePoint, ScheduleTracker
from fdi_sim.linear.transform import discretize
from fdi_sim.operating_point import OperatingPoint

OUTS = ("q_radps", "nz_g", "vc_kts", "h_ft")
NAMES = {"state_names": ("alpha_rad", "q_radps"), "input_names": ("elevator_cmd_norm", "w_gust_body_fps"),
         "input_kinds": ("control", "disturbance"), "output_names": OUTS, "lagged_outputs": ("nz_g",)}
RNG = np.random.default_rng(3)
A0, A1, A2 = RNG.normal(size=(2, 2)) - 2 * np.eye(2), RNG.normal(size=(2, 2)), RNG.normal(size=(2, 2))


def field_A(h: float, vc: float) -> np.ndarray:
    """A varies linearly with h and vc, so barycentric interpolation must be exact."""
    return A0 + (h / 10000.0) * A1 + (vc / 300.0) * A2


def make_schedule() -> ModelSchedule:
    pts, arr = [], {k: [] for k in ("A", "B", "C", "D", "x0", "u0", "y0")}
    for h in (5000.0, 10000.0, 15000.0):
        for vc in (280.0, 300.0, 320.0):
            arr["A"].append(field_A(h, vc))
            arr["B"].append(np.array([[0.0, 0.01], [-5.0, 0.0]]))
            arr["C"].append(np.array([[0.0, 1.0], [3.0, 0.5], [0.0, 0.0], [0.0, 0.0]]))
            arr["D"].append(np.array([[0.0, 0.0], [0.4, 0.01], [0.0, 0.1], [0.0, 0.0]]))
            arr["x0"].append(np.array([0.02, 0.0]))
            arr["u0"].append(np.zeros(2))
            arr["y0"].append(np.array([0.0, -1.0, vc, h]))
            op = OperatingPoint("f16", h, vc_kts=vc)
            pts.append(SchedulePoint(op=op, status="ok", index=len(arr["A"]) - 1,
                                     sched={"h_ft": h, "vc_kts": vc, "flaps_deg": 0.0, "icing_eta": 0.0},
                                     trim={"alpha_rad": 0.02}, info={"modes": []}))
    pts.append(SchedulePoint(op=OperatingPoint("f16", 20000.0, vc_kts=200.0), status="untrimmable",
                             reason="throttle at its limit"))
    return ModelSchedule("f16", pts, {k: np.array(v) for k, v in arr.items()}, NAMES, {"grid_source": "test"})


def test_round_trip(tmp_path: Path) -> None:
    s = make_schedule()
    path = s.save(tmp_path / "f16_schedule")
    assert path.suffix == ".npz"
    t0 = time.perf_counter()
    s2 = ModelSchedule.load(path, aircraft="f16")
    assert time.perf_counter() - t0 < 0.5  # loads fast
    for k in s.arrays:
        np.testing.assert_array_equal(s2.arrays[k], s.arrays[k])
    assert s2.names == {k: tuple(v) for k, v in NAMES.items()}
    assert [p.status for p in s2.points] == [p.status for p in s.points]
    assert s2.points[-1].reason == "throttle at its limit"
    assert s2.points[4].op == s.points[4].op


def test_foreign_files_are_refused(tmp_path: Path) -> None:
    path = make_schedule().save(tmp_path / "s.npz")
    with pytest.raises(DesignError, match="schedule for 'f16', not 'DHC6'"):
        ModelSchedule.load(path, aircraft="DHC6")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(DesignError, match="not an fdi-sim model schedule"):
        ModelSchedule.load(tmp_path / "other.npz")
    with pytest.raises(DesignError, match="not found"):
        ModelSchedule.load(tmp_path / "missing.npz")
    s = make_schedule()
    with pytest.raises(DesignError, match="schedule is for 'f16'"):
        s.model_at(OperatingPoint("DHC6", 5000.0, vc_kts=100.0))


def test_nearest_lookup_returns_that_points_discrete_model() -> None:
    s = make_schedule()
    r = s.model_at(OperatingPoint("f16", 10400.0, vc_kts=303.0))
    assert r.how == "nearest" and "designs are made per grid point" in r.why
    assert s.points[r.indices[0]].sched == {"h_ft": 10000.0, "vc_kts": 300.0, "flaps_deg": 0.0, "icing_eta": 0.0}
    ref = discretize(LinearModel(A=field_A(10000, 300), B=s.arrays["B"][4], C=s.arrays["C"][4], D=s.arrays["D"][4],
                                 output_names=OUTS, meta={"lagged_outputs": ["nz_g"]}), 1 / 120)
    np.testing.assert_allclose(r.model.A, ref.A, rtol=1e-12)
    assert r.model.dt_s == pytest.approx(1 / 120) and r.model.state_names[-1] == "nz_lag_g"
    assert s.model_at(OperatingPoint("f16", 10400.0, vc_kts=303.0)).model.A is r.model.A  # cached matrices


def test_interpolation_is_exact_for_a_linear_field() -> None:
    s = make_schedule()
    r = s.lookup([8000.0, 293.0, 0.0, 0.0], interpolate=True)
    assert r.how == "interpolated" and len(r.indices) == 3
    assert sum(r.weights) == pytest.approx(1.0) and min(r.weights) >= -1e-12
    cont = s._model(s._blend([s.points[i].index for i in r.indices], r.weights), None)
    np.testing.assert_allclose(cont.A, field_A(8000.0, 293.0), rtol=1e-10)
    out = s.lookup([16000.0, 300.0, 0.0, 0.0], interpolate=True)  # outside the hull: nearest, said so
    assert out.how == "nearest" and "outside" in out.why


def test_cached_lookups_name_their_own_operating_point() -> None:
    """Two lookups that land on the same grid point share its cached matrices but each answer
    carries the operating point it was asked for."""
    s = make_schedule()
    a, b = OperatingPoint("f16", 9800.0, vc_kts=301.0), OperatingPoint("f16", 10100.0, vc_kts=299.0)
    ra, rb = s.model_at(a), s.model_at(b)
    assert ra.indices == rb.indices and ra.model.A is rb.model.A
    assert ra.model.op is a and rb.model.op is b


def test_far_lookups_warn_then_refuse() -> None:
    s = make_schedule()
    with pytest.warns(UserWarning, match="grid spacings from the nearest point"):
        s.lookup([18000.0, 300.0, 0.0, 0.0])  # 0.6 spacings beyond the top row
    with pytest.raises(DesignError, match="beyond max_distance"):
        s.lookup([40000.0, 300.0, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s.lookup([10000.0, 300.0, 0.0, 0.0])  # on a point: silent
        r = s.lookup([7500.0, 310.0, 0.0, 0.0])  # mid-cell: far from every point, but inside the grid
        assert r.distance > 0.5 and s.outside_distance(np.array([7500.0, 310.0, 0.0, 0.0])) == 0.0


def test_tracker_follows_the_air_data_with_hysteresis() -> None:
    s = make_schedule()
    tr = ScheduleTracker(s)
    tr.reset(np.random.default_rng(0))
    y = np.array([0.0, -1.0, 300.0, 10000.0])
    first = tr.step(0.0, np.zeros(2), y)
    assert s.points[first.indices[0]].sched["h_ft"] == 10000.0
    y[3] = 7600.0  # just past the midpoint to 5000 ft: within the hysteresis, keep the model
    assert tr.step(0.01, np.zeros(2), y) is first  # no new record between switches
    y[3] = 6000.0
    assert s.points[tr.step(0.02, np.zeros(2), y).indices[0]].sched["h_ft"] == 5000.0
    y[3] = 40000.0
    with pytest.raises(DesignError, match="beyond max_distance"):
        tr.step(0.03, np.zeros(2), y)
    y[2] = np.nan
    with pytest.raises(DesignError, match="non-finite air data"):
        tr.step(0.04, np.zeros(2), y)


def _with_step(s: ModelSchedule) -> ModelSchedule:
    """The same schedule with step terms: two passes building up to A, B (both states integrated)."""
    K = s.arrays["A"].shape[0]
    Ax = np.stack([np.stack([0.5 * s.arrays["A"][k], s.arrays["A"][k]]) for k in range(K)])
    Bu = np.stack([np.stack([0.3 * s.arrays["B"][k], s.arrays["B"][k]]) for k in range(K)])
    Lf = np.tile(np.array([[0.0, 0.2]]), (K, 1, 1))
    arrays = {**s.arrays, "step_Ax": Ax, "step_Bu": Bu, "step_Lf": Lf}
    meta = {**s.meta, "step": {"dt_s": 1 / 120, "n_rigid": 2, "lagged_outputs": ["nz_g"]}}
    return ModelSchedule(s.aircraft, s.points, arrays, s.names, meta)


def test_step_terms_round_trip_and_lookup(tmp_path: Path) -> None:
    """Schedules carry the step terms when the models have them; older files without them still load."""
    from fdi_sim.linear.step import step_model

    s = _with_step(make_schedule())
    s2 = ModelSchedule.load(s.save(tmp_path / "with_step.npz"))
    assert s2.has_step
    for k in ("step_Ax", "step_Bu", "step_Lf"):
        np.testing.assert_array_equal(s2.arrays[k], s.arrays[k])
    op = OperatingPoint("f16", 10000.0, vc_kts=300.0)
    got = s2.model_at(op, method="step").model
    want = step_model(s2.continuous(4))
    assert got.dt_s == pytest.approx(1 / 120) and got.state_names == want.state_names
    np.testing.assert_array_equal(got.A, want.A)
    with pytest.raises(DesignError, match="multiples of the simulation step"):
        s2.model_at(op, dt_s=0.02, method="step")
    at20 = s2.model_at(op, dt_s=0.05, method="step").model  # six simulation steps per sample
    np.testing.assert_allclose(at20.A, np.linalg.matrix_power(want.A, 6), rtol=1e-9, atol=1e-12)
    plain = ModelSchedule.load(make_schedule().save(tmp_path / "plain.npz"))
    assert not plain.has_step and plain.continuous(4).step is None
    with pytest.raises(DesignError, match="no step terms"):
        plain.model_at(op, method="step")

"""Gain-schedule designs of kalman-gust-v1 (fdi_sim.training.schedule): the points a scenario crosses, one design
and one cached calibration per point, refusing or skipping a point that cannot be trimmed (real JSBSim)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdi_sim.errors import DesignError
from fdi_sim.scenario import load
from fdi_sim.training import flights, gust, schedule
from fdi_sim.training.schedule import DEFAULT_SPACING, design_schedule, DesignPoint, point_scenario, schedule_points

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"
#: a calibration that flies in a second: 3 x 40 s, 1e-2 per sample (3 x 760 samples give 22 exceedances)
TINY = dict(n_flights=3, duration_s=40.0, target=1e-2, progress=False)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("FDI_SIM_CACHE", str(tmp_path))
    return tmp_path / "fdi-sim" / "calibrations"


def _no_flights(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("flew a training flight although the calibration should come from the cache")

    for mod in (flights, gust, schedule):  # every module that flies them by that name
        if hasattr(mod, "fly_training"):
            monkeypatch.setattr(mod, "fly_training", refuse)


# ------------------------------------------------------------------------- schedule points
def test_cruise_gives_its_initial_point() -> None:
    (p,) = schedule_points(load(SCENARIOS / "f16_cruise_doublets.toml"))
    assert p.h_ft == 10000.0 and p.vc_kts == pytest.approx(348.6, abs=0.1) and p.flaps_deg == 0.0  # 400 KTAS


def test_climb_accelerate_crosses_at_least_three_points() -> None:
    sc = load(SCENARIOS / "f16_climb_accelerate.toml")
    pts = schedule_points(sc)
    assert len(pts) >= 3
    assert pts[0] == DesignPoint(10000.0, 300.0, 0.0) and pts[-1] == DesignPoint(16000.0, 340.0, 0.0)  # both ends
    dh, dv = DEFAULT_SPACING["f16"]
    for a, b in zip(pts[:-1], pts[1:]):  # a staircase: each step at most one spacing on each axis, never back
        assert 0.0 <= b.h_ft - a.h_ft <= dh and 0.0 <= b.vc_kts - a.vc_kts <= dv and a != b
    fine = schedule_points(sc, h_spacing_ft=dh / 2, vc_spacing_kts=dv / 2)
    assert len(fine) > len(pts) and set(p.h_ft for p in pts) <= set(p.h_ft for p in fine)


def test_dhc6_approach_points() -> None:
    pts = schedule_points(load(SCENARIOS / "dhc6_approach_flaps.toml"))
    dh = DEFAULT_SPACING["DHC6"][0]
    n = int(np.ceil(1500.0 / dh))  # 3000 -> 1500 ft at 80 KCAS, flaps 10, equal steps of at most dh
    assert pts == [DesignPoint(3000.0 - i * 1500.0 / n, 80.0, 10.0) for i in range(n + 1)]


def test_point_scenario_keeps_only_pulse_trains() -> None:
    sc = load(SCENARIOS / "f16_climb_accelerate.toml")
    ps = point_scenario(sc, (14000.0, 320.0))
    ini = ps.model.initial
    assert (ini.h_ft, ini.vc_kts, ini.vt_kts, ini.psi_deg) == (14000.0, 320.0, None, sc.model.initial.psi_deg)
    assert {m["type"] for m in ps.model.maneuvers} == {"doublet-v1"}
    assert len(ps.model.maneuvers) == sum(m["type"] == "doublet-v1" for m in sc.model.maneuvers)
    assert ps.model.atmosphere == sc.model.atmosphere and ps.model.sensors == sc.model.sensors
    assert not ps.model.faults and not ps.model.detectors
    banked = load(SCENARIOS / "f16_pitch_gyro_bias.toml")
    assert banked.model.fdi.bank == "default" and point_scenario(banked, (10000.0, 348.6)).model.fdi.bank == "none"


# ------------------------------------------------------------------------- designs and calibrations
def test_two_point_schedule_calibrated_and_cached(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sc = load(SCENARIOS / "f16_climb_accelerate.toml")
    pts = [(10000.0, 300.0), (12000.0, 320.0)]
    sch = design_schedule(sc, pts, **TINY)
    assert sch.n_points == 2 and sch.labels == ("h 10000 ft, vc 300 kt", "h 12000 ft, vc 320 kt")
    np.testing.assert_allclose(sch.points, [[10000.0, 300.0], [12000.0, 320.0]], atol=0.5)  # the trims' own values
    np.testing.assert_array_equal(sch.spacing, DEFAULT_SPACING["f16"])
    m0, m1 = (d.model for d in sch.designs)
    assert m0.state_names == m1.state_names and m0.output_names == m1.output_names
    assert not np.allclose(m0.A, m1.A), "two trim points, two models"
    c0, c1 = sch.calibrations
    assert not np.allclose(c0.sigma_m, c1.sigma_m) and c0.threshold != c1.threshold
    assert c0.n_samples == c1.n_samples == 3 * (800 - 40)  # 40 s at 20 Hz, first 2 s skipped
    assert all("seed 1000000" in c.flights[0] for c in sch.calibrations)
    entries = sorted(cache.glob("*.json"))
    assert len(entries) == 2 and not list(cache.glob("*.tmp*"))

    _no_flights(monkeypatch)  # the second call: every calibration from the cache, no flight
    again = design_schedule(sc, pts, **TINY)
    for a, b in zip(sch.calibrations, again.calibrations):
        np.testing.assert_array_equal(a.sigma_m, b.sigma_m)
        assert a.threshold == b.threshold
    assert sum("from the cache" in n for n in again.notes) == 2

    # a changed design option is another design: another key, so it would fly
    with pytest.raises(AssertionError, match="flew a training flight"):
        design_schedule(sc, pts[:1], params={"bias_drift": 2e-3}, **TINY)
    with pytest.raises(AssertionError, match="flew a training flight"):
        design_schedule(sc, pts[:1], **{**TINY, "target": 2e-2})


def test_untrimmable_point_refused_or_skipped(cache: Path) -> None:
    sc = load(SCENARIOS / "dhc6_cruise_doublets.toml")
    good, bad = (5000.0, 120.0), (10000.0, 145.0)  # the DHC-6 cannot trim 145 KCAS at 10 kft
    with pytest.raises(DesignError) as exc:
        design_schedule(sc, [good, bad], **TINY)
    msg = str(exc.value)
    assert "h 10000 ft, vc 145 kt" in msg and "vc_kts=145" in msg and "flaps_deg=0" in msg
    assert "untrimmable" in msg and "trim stopped at residual" in msg  # the trim's own reason
    assert not list(cache.glob("*.json")), "refused before any training flight"

    sch = design_schedule(sc, [good, bad], on_failure="skip", **TINY)
    assert sch.n_points == 1 and sch.labels == ("h 5000 ft, vc 120 kt",)
    (skip,) = [n for n in sch.notes if n.startswith("skipped")]
    assert "h 10000 ft, vc 145 kt" in skip and "trim stopped at residual" in skip

    with pytest.raises(DesignError, match="no schedule point could be designed"):
        design_schedule(sc, [bad], on_failure="skip", **TINY)


def test_outside_envelope_names_the_point(cache: Path) -> None:
    sc = load(SCENARIOS / "dhc6_cruise_doublets.toml")
    with pytest.raises(DesignError, match=r"h 5000 ft, vc 200 kt.*outside the linearization envelope"):
        design_schedule(sc, [(5000.0, 200.0)], **TINY)


def test_bad_options() -> None:
    sc = load(SCENARIOS / "f16_cruise_doublets.toml")
    with pytest.raises(NotImplementedError, match="calibration='scenario'"):
        design_schedule(sc, [(10000.0, 300.0)], calibration="scenario")
    with pytest.raises(DesignError, match="on_failure"):
        design_schedule(sc, [(10000.0, 300.0)], on_failure="ignore")
    with pytest.raises(DesignError, match="repeat"):
        design_schedule(sc, [(10000.0, 300.0), (10000.0, 300.0, 0.0)])
    with pytest.raises(DesignError, match="spacing must be positive"):
        schedule_points(sc, h_spacing_ft=0.0)

"""Gain-scheduled ``kalman-gust-v1`` for a scenario: its schedule points, designs and calibrations.

A scenario that climbs or accelerates leaves the trim point its detector was designed at. This
module finds the schedule points its flight crosses (:func:`schedule_points`), trims and
linearizes them, designs ``kalman-gust-v1`` at each with the options
:func:`fdi_sim.training.gust.calibrated_gust_kalman` uses, calibrates each on fault-free flights
at that point, and returns the :class:`~fdi_sim.detectors.scheduled.GustKalmanSchedule` that the
streaming kernel (:mod:`fdi_sim.detectors.gust_kalman_stream`) runs (:func:`design_schedule`).

Spacing (measured, the module's defaults :data:`DEFAULT_SPACING`)
----------------------------------------------------------------
A design made at point A was flown at point B: 16 fault-free 300 s flights (seeds 101-116) of the
calibration scenario at B (:func:`point_scenario`, moderate turbulence), tested with A's design
and A's calibration (24 x 300 s at A, 1e-4 per sample), the filter started from B's trim
(``dx = x0_B - x0_A``, as the kernel's bumpless transfer carries it). Two numbers per B: the
fraction of samples over A's threshold and the mean of ``T`` (``p = 14`` when ``Sigma_m`` fits;
the more sensitive one). A's own held-out flights give the baseline::

    F-16, A = 10000 ft / 300 KCAS (doublets at 5, 120, 260 s): baseline 2.6e-4, mean T 14.2
      dh [ft]  +1000 +2000 +3000 +4000 +6000 +8000 +10000 -4000   (vc kept)
      frac     2.8e-4 2.3e-4 2.4e-4 2.0e-4 1.9e-4 1.4e-4 1.7e-4 2.6e-4
      mean T   13.4  12.6  11.8  12.4  11.7  11.0  12.1  17.4
      dvc [kt]  +10   +20   +30   +40   +60   -20   -40         (h kept); +4000 ft +40 kt: 4.0e-4, 24.0
      frac     2.6e-4 4.7e-4 4.3e-4 4.1e-4 2.9e-3 4.5e-4 5.9e-4
      mean T   15.1  16.9  19.6  24.0  39.8  16.9  23.9
    DHC-6 clean, A = 5000 ft / 120 KCAS (dhc6_cruise_doublets): baseline 6.8e-4, mean T 16.3
      dh [ft]  +1000 +2000 +3000 -1000 -2000
      frac     6.0e-4 5.0e-4 3.8e-4 7.0e-4 3.7e-3
      mean T   15.6  14.6  13.6  17.3  35.9
      dvc [kt]  +2    +4    +8    +16   -2    -4    -8    -16
      frac     5.8e-4 2.6e-4 1.8e-3 0.10 5.8e-3 9.9e-3 3.2e-2 0.45
      mean T   16.5  19.5  34.0  110   40.0  49.3  79.5  208
    DHC-6 clean, A = 5000 ft / 110 KCAS: baseline 0 of 95,000, mean T 17.3; +4 kt: 0, 15.1; -4 kt: 9.8e-4, 26.8
    DHC-6 flaps 10, A = 3000 ft / 80 KCAS (dhc6_approach_flaps): baseline 6.3e-5, mean T 16.3
      dh -500 .. -2000 ft: frac <= 6.3e-5, mean T 15.7 .. 8.8 (lower air, weaker Dryden gusts)
      dvc +2 kt: 6.3e-5, 15.2; -2: 5.2e-5, 19.5; -5: 5.2e-5, 27.3; -10: 1.2e-4, 63.6
      (+5 kt: the training flights depart, alpha below -20 deg: 85 KCAS with flaps 10 does not fly)

With calibrated airspeed as the speed variable, altitude hardly matters (dynamic pressure
follows vc, not h): the F-16 design is at its baseline 10000 ft away (started from zero
instead of B's trim, 8000 ft away it was not: 8.8e-4, mean T 22.0). Speed does: the F-16
stays within 6 % of its mean ``T`` 10 kt away, 19 % at 20 kt, 69 % at 40 kt. The nearest-point
rule leaves the aircraft at most half a spacing from a design on each axis, so the defaults are
F-16 6000 ft / 20 kt (at most 3000 ft / 10 kt off: no measurable change) and DHC-6 2000 ft / 4 kt
(at most 1000 ft / 2 kt off; 2000 ft below was 2.2 times the baseline ``T``). The DHC-6 is
asymmetric: a design flown *slower* than its point mismatches far more than one flown faster
(120 KCAS design: -2 kt 2.5 times the baseline ``T``, +4 kt 1.2 times); even 4 kt spacing leaves
that. Taking the next point below (a floor rule on vc) instead of the nearest would suit it.

In the climb itself (:file:`scenarios/f16_climb_accelerate.toml`, seeds 101-108, 4 points at the
default spacing, every point's filter run over the whole flight): the initial point's design
alone put 44 samples (11 onsets) over its threshold, at the level-off (220 s) and at the aileron
doublet at 16000 ft / 340 KCAS; the nearest point's design 5 (3 onsets), 1.0e-4 per sample, the
target. Every exceedance of either fell after the level-off (220 s); 3000 ft / 10 kt (7 points),
the default (4) and 12000 ft / 40 kt (2 points: the two ends) gave the same counts, so in this
flight what matters is a design at the level flight it ends in; during the climb neither design
alarmed. With the aileron doublet in the climb instead (at 120 s), both alarmed there (60 and 67
samples), also with 3000 ft / 10 kt spacing and with the design at the aircraft's own h and vc:
the designs are level-flight trims, and the climb's attitude (theta about 5 deg, more thrust) is
not on the schedule's axes.

Scheduling on the *measured* airspeed: in moderate turbulence the pitot sees the longitudinal
gust, so the measured vc scatters about the steady-air speed by 5.2-5.4 kt (standard deviation;
1st-99th percentile about +-10 kt; F-16 and DHC-6 cruise, DHC-6 approach, seed 11), mostly at low
frequency (about its own 1 s mean only 0.7-1.7 kt). That is a quarter of the F-16 spacing and
more than the DHC-6's: a nearest-point rule on raw vc with a 0.1-spacing hysteresis would switch
among DHC-6 points all the time. The mismatch above is a function of the steady-air speed.

Caches
------
* Calibrations: ``$FDI_SIM_CACHE/fdi-sim/calibrations/<key>.json`` (the folder of
  :func:`fdi_sim.training.cache.cache_dir`), one entry per point, written to a temporary name and
  committed by rename. The key (:func:`fdi_sim.training.cache.calibration_key`) hashes the
  calibration scenario at that point (:func:`point_scenario`, fault-free: aircraft, initial
  point, atmosphere, autopilot, sensors, limits, rate, pulse-train maneuvers; name and
  description left out), the design (its model's A, B, C, D, u0, y0, the last gain, the
  signatures, the window and the gain-sequence length), the design options (turbulence and any
  ``params``), the detector rate, the number and length of the training flights, the target,
  the scenario's sensor suite file and the default one, and the package version. A second call
  with the same arguments flies nothing.
* Linearizations are not cached: trimming and linearizing a point costs 0.3-0.5 s (measured,
  F-16 and DHC-6, no validation) and the design 0.1 s; a call whose calibrations are all cached
  takes 2 s for the climb's 4 points, against 90 s flying them.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import replace
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim import registry
from fdi_sim.detectors.scheduled import SCHEDULE_SIGNALS, GustKalmanSchedule
from fdi_sim.errors import DesignError
from fdi_sim.isa import vc_from_vt
from fdi_sim.operating_point import OperatingPoint
from fdi_sim.pilot.maneuvers import PulseTrain, RefRamp
from fdi_sim.scenario import Scenario
from fdi_sim.scenario.loader import from_dict
from fdi_sim.training.cache import CachedCalibration
from fdi_sim.training.flights import DEFAULT_TARGET, DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S
from fdi_sim.training.gust import gust_kalman_calibration

#: grid spacing per aircraft, (h [ft], vc [kt]): how far a design stays acceptable (module docstring)
DEFAULT_SPACING: dict[str, tuple[float, float]] = {"f16": (6000.0, 20.0), "DHC6": (2000.0, 4.0)}
#: on_failure values of design_schedule
ON_FAILURE: tuple[str, ...] = ("refuse", "skip")
#: calibration values of design_schedule
CALIBRATIONS: tuple[str, ...] = ("points", "scenario")
#: time step of the reference path that schedule_points samples [s]
PATH_DT_S = 0.5


class DesignPoint(NamedTuple):
    """A schedule point: where one design is trimmed and calibrated.

    Attributes
    ----------
    h_ft : float
        Altitude [ft].
    vc_kts : float
        Calibrated airspeed [kt].
    flaps_deg : float
        Flap deflection [deg].
    """

    h_ft: float
    vc_kts: float
    flaps_deg: float = 0.0

    def label(self) -> str:
        """``"h 10000 ft, vc 300 kt"`` (and the flaps when set)."""
        out = f"h {self.h_ft:.0f} ft, vc {self.vc_kts:.0f} kt"
        return out + (f", flaps {self.flaps_deg:g} deg" if self.flaps_deg else "")


def default_spacing(aircraft: str) -> tuple[float, float]:
    """The aircraft's schedule spacing (h [ft], vc [kt]) (:data:`DEFAULT_SPACING`)."""
    if aircraft not in DEFAULT_SPACING:
        raise DesignError(f"no default schedule spacing for aircraft {aircraft!r}; give h_spacing_ft and "
                          f"vc_spacing_kts (known: {', '.join(DEFAULT_SPACING)})")
    return DEFAULT_SPACING[aircraft]


def _spacing(aircraft: str, h_spacing_ft: float | None, vc_spacing_kts: float | None) -> tuple[float, float]:
    """The given spacings, the aircraft's default for the missing ones [ft], [kt]."""
    if h_spacing_ft is None or vc_spacing_kts is None:
        dh, dv = default_spacing(aircraft)
        h_spacing_ft = dh if h_spacing_ft is None else h_spacing_ft
        vc_spacing_kts = dv if vc_spacing_kts is None else vc_spacing_kts
    dh, dv = float(h_spacing_ft), float(vc_spacing_kts)
    if not (dh > 0 and dv > 0):  # also refuses NaN
        raise DesignError(f"schedule spacing must be positive; got h {dh:g} ft, vc {dv:g} kt")
    return dh, dv


def initial_vc_kts(sc: Scenario) -> float:
    """The scenario's initial calibrated airspeed [kt] (from the true airspeed by the ISA when given so)."""
    ini = sc.model.initial
    return float(ini.vc_kts) if ini.vc_kts is not None else float(vc_from_vt(ini.h_ft, float(ini.vt_kts))[0])


def _built_maneuvers(sc: Scenario) -> list[tuple[Any, Any]]:
    """``(params, built object)`` per maneuver, in scenario order."""
    return [(p, registry.get("maneuver", ident).factory(p)) for ident, p in sc.maneuvers]


def reference_path(sc: Scenario, dt_s: float = PATH_DT_S) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                     NDArray[np.float64], list[float], list[float]]:
    """The autopilot's altitude and airspeed references over the flight.

    Each ramp starts from the reference the earlier ramps of its channel reached by its start
    (the rule of :class:`fdi_sim.pilot.autopilot.Autopilot`), from the initial point.

    Returns
    -------
    t_s, h_ft, vc_kts : NDArray
        Times 0 .. ``duration_s`` at ``dt_s`` (and the end) [s], references [ft], [kt].
    h_waypoints_ft, vc_waypoints_kts : list of float
        The initial and final references, their extremes, and every ramp target the reference
        reaches within the flight [ft], [kt].
    """
    h0, v0 = float(sc.model.initial.h_ft), initial_vc_kts(sc)
    t = np.unique(np.append(np.arange(0.0, sc.duration_s, dt_s), sc.duration_s))
    ramps = sorted((m for _, m in _built_maneuvers(sc) if isinstance(m, RefRamp)), key=lambda m: m.t_start_s)
    starts: list[float] = []
    for r in ramps:
        s = h0 if r.channel == "h_ft" else v0
        for q, qs in zip(ramps, starts):
            if q.channel == r.channel:
                s = q.value_at(r.t_start_s, qs, s)
        starts.append(s)
    h, v = np.full_like(t, h0), np.full_like(t, v0)
    for r, s in zip(ramps, starts):
        if r.channel == "h_ft":
            h = r.apply(t, h, s)
        else:
            v = r.apply(t, v, s)
    way = {}
    for ch, x in (("h_ft", h), ("vc_kts", v)):
        reached = [r.target for r in ramps if r.channel == ch and np.any(np.abs(x - r.target) < 1e-6)]
        way[ch] = [float(x[0]), float(x[-1]), float(x.min()), float(x.max())] + [float(y) for y in reached]
    return t, h, v, way["h_ft"], way["vc_kts"]


def _axis_nodes(values: Sequence[float], spacing: float) -> NDArray[np.float64]:
    """Every waypoint value, and between neighbours equal steps of at most ``spacing``."""
    w = np.unique(np.round(np.asarray(values, dtype=float), 6))
    out = [w[:1]]
    for a, b in zip(w[:-1], w[1:]):
        n = max(1, math.ceil((b - a) / spacing - 1e-9))  # steps: (b - a) / n <= spacing
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


def schedule_points(sc: Scenario, *, h_spacing_ft: float | None = None,
                    vc_spacing_kts: float | None = None) -> list[DesignPoint]:
    """The schedule points a scenario's flight crosses.

    The waypoints are the initial point and the references the ``altitude-v1`` / ``airspeed-v1``
    maneuvers reach within the flight (a ramp still under way at the end counts up to where it
    got). Each axis is gridded through its waypoint values, with equal steps of at most the
    spacing between neighbours (both ends included). The points are the grid nodes nearest the
    reference path (:func:`reference_path`, every :data:`PATH_DT_S`), in the order it reaches
    them: a cruise gives one point, a climb one per altitude step, a simultaneous climb and
    acceleration the staircase along the diagonal.

    Parameters
    ----------
    sc : Scenario
    h_spacing_ft, vc_spacing_kts : float, optional
        Largest step between points [ft], [kt]; default the aircraft's (:data:`DEFAULT_SPACING`).

    Returns
    -------
    list of DesignPoint
        ``(h_ft, vc_kts, flaps_deg)``; flaps are the initial ones (no maneuver moves them).
    """
    dh, dv = _spacing(sc.aircraft, h_spacing_ft, vc_spacing_kts)
    _, h, v, h_way, v_way = reference_path(sc)
    hn, vn = _axis_nodes(h_way, dh), _axis_nodes(v_way, dv)
    # nearest node of a product grid in the scaled distance = nearest value on each axis
    ih = np.argmin(np.abs(h[:, None] - hn[None, :]), axis=1)
    iv = np.argmin(np.abs(v[:, None] - vn[None, :]), axis=1)
    flaps = float(sc.model.initial.flaps_deg)
    seen: dict[tuple[int, int], None] = dict.fromkeys(zip(ih.tolist(), iv.tolist()))
    return [DesignPoint(float(hn[a]), float(vn[b]), flaps) for a, b in seen]


def point_scenario(sc: Scenario, point: Sequence[float]) -> Scenario:
    """The calibration scenario at one schedule point.

    ``initial`` moved to the point (h, calibrated airspeed, flaps; level and wings level; heading
    kept), only the pulse-train maneuvers kept (no altitude, airspeed, heading or turn changes),
    faults, detectors and the ``[fdi]`` bank removed; atmosphere, autopilot, sensors, limits, log
    and rate kept.
    """
    p = _as_point(point, sc)
    data = json.loads(sc.to_json())
    ini = dict(data["initial"])
    ini.update(h_ft=p.h_ft, vc_kts=p.vc_kts, vt_kts=None, flaps_deg=p.flaps_deg, gamma_deg=0.0, phi_deg=0.0)
    data["initial"] = ini
    built = _built_maneuvers(sc)  # the same order as the file's entries
    data["maneuvers"] = [e for e, (_, m) in zip(data.get("maneuvers", []), built) if isinstance(m, PulseTrain)]
    data.update(faults=[], detectors=[])
    data.pop("fdi", None)  # no bank in the loop: a calibration flight would need calibrating itself
    data["name"] = f"{sc.name}_at_h{p.h_ft:.0f}_vc{p.vc_kts:.0f}"[:120]
    return from_dict(data, source=f"{sc.source} (calibration at {p.label()})")


def _as_point(point: Sequence[float], sc: Scenario) -> DesignPoint:
    vals = [float(x) for x in point]
    if len(vals) == 2:
        vals.append(float(sc.model.initial.flaps_deg))
    if len(vals) != 3:
        raise DesignError(f"a schedule point is (h_ft, vc_kts[, flaps_deg]); got {tuple(point)!r}")
    return DesignPoint(*vals)


class _Failure(NamedTuple):
    point: DesignPoint
    reason: str


def _linearize_points(sc: Scenario, points: Sequence[DesignPoint]) -> tuple[list[Any], list[_Failure]]:
    """One ``linearize_grid`` call over a grid of exactly these points: per point its continuous
    model or None, and the failures (outside the envelope, untrimmable) with the trim's reason."""
    from fdi_sim.linear.grid import parse_grid_spec
    from fdi_sim.linear.linearize import linearize_grid

    fails: list[_Failure] = []
    specs: dict[int, Any] = {}
    for i, p in enumerate(points):
        spec = f"h_ft={p.h_ft!r};vc_kts={p.vc_kts!r};flaps_deg={p.flaps_deg!r}"
        try:
            specs[i] = parse_grid_spec(spec, sc.aircraft)  # the envelope check, no JSBSim
        except DesignError as exc:
            fails.append(_Failure(p, str(exc)))
    models: list[Any] = [None] * len(points)
    if not specs:
        return models, fails
    first = next(iter(specs.values()))
    grid = replace(first, points=tuple(g.points[0] for g in specs.values()),
                   source=f"schedule points of {sc.source}")
    sched = linearize_grid(grid, validate=False)
    for j, (i, sp) in enumerate(zip(specs, sched.points)):
        if sp.status != "ok":
            fails.append(_Failure(points[i], f"{sp.status}: {sp.reason}"))
        else:
            models[i] = replace(sched.continuous(j), op=_op(sc, points[i]))
    return models, fails


def _op(sc: Scenario, p: DesignPoint) -> OperatingPoint:
    return OperatingPoint(aircraft=sc.aircraft, h_ft=p.h_ft, vc_kts=p.vc_kts, flaps_deg=p.flaps_deg,
                          psi_deg=float(sc.model.initial.psi_deg))


def _failure_error(sc: Scenario, f: _Failure) -> DesignError:
    return DesignError(f"{sc.source}: schedule point {f.point.label()} (h_ft={f.point.h_ft:g}, "
                       f"vc_kts={f.point.vc_kts:g}, flaps_deg={f.point.flaps_deg:g}) has no kalman-gust-v1 design: "
                       f"{f.reason}. Leave it out (on_failure='skip') or move it inside what the aircraft can trim.")


def design_schedule(sc: Scenario, points: Sequence[Sequence[float]], *, rate_hz: float = 20.0,
                    params: Mapping[str, Any] | None = None, calibration: str = "points", on_failure: str = "refuse",
                    n_flights: int = DEFAULT_TRAINING_FLIGHTS, duration_s: float = DEFAULT_TRAINING_S,
                    target: float = DEFAULT_TARGET, use_cache: bool = True, progress: bool = True,
                    h_spacing_ft: float | None = None, vc_spacing_kts: float | None = None) -> GustKalmanSchedule:
    """``kalman-gust-v1`` designed and calibrated at each schedule point.

    Parameters
    ----------
    sc : Scenario
        The scenario to be tested (aircraft, atmosphere, sensors, autopilot, maneuvers).
    points : sequence of (h_ft, vc_kts[, flaps_deg])
        The schedule points [ft, kt, deg] (:func:`schedule_points`); flaps default to the
        scenario's.
    rate_hz : float
        Detector rate [Hz].
    params : mapping, optional
        Options of :func:`fdi_sim.detectors.catalogue_observers.make_gust_kalman`; ``turbulence``
        defaults to the scenario's ('light' in calm air), the simulation rate is the scenario's.
    calibration : str
        ``"points"``: each point on its own fault-free flights (:func:`point_scenario`, seeds
        1e6 + i). ``"scenario"`` (on the scenario's own flights through the kernel) is not yet
        written.
    on_failure : str
        A point that cannot be trimmed, designed or flown: ``"refuse"`` raises, ``"skip"`` leaves
        it out with a note (and raises when none is left).
    n_flights, duration_s, target : int, float, float
        Training flights per point, their length [s], per-sample false-alarm target.
    use_cache : bool
        Read and write the calibration cache (module docstring).
    progress : bool
        One line per calibration point on stderr (flights done, sim s per s, ETA) when it is a
        terminal.
    h_spacing_ft, vc_spacing_kts : float, optional
        The schedule's unit of distance [ft], [kt]; default the aircraft's :data:`DEFAULT_SPACING`.

    Returns
    -------
    GustKalmanSchedule
        Points at the trimmed (h_ft, vc_kts), in the order given (skipped ones left out).

    Raises
    ------
    DesignError
        A point that has no design, naming it (h, vc, flaps) and the reason (with "refuse"; with
        "skip" when none is left); no points; a bad option.
    NotImplementedError
        ``calibration="scenario"``.
    """
    if calibration not in CALIBRATIONS:
        raise DesignError(f"calibration={calibration!r}; use one of {', '.join(CALIBRATIONS)}")
    if calibration == "scenario":
        raise NotImplementedError("calibration='scenario' (every point calibrated on the scenario's own fault-free "
                                  "flights through the scheduled streaming kernel) is not written yet; use "
                                  "calibration='points'")
    if on_failure not in ON_FAILURE:
        raise DesignError(f"on_failure={on_failure!r}; use one of {', '.join(ON_FAILURE)}")
    pts = [_as_point(p, sc) for p in points]
    if not pts:
        raise DesignError(f"{sc.source}: no schedule points given")
    if len(set(pts)) != len(pts):
        raise DesignError(f"{sc.source}: schedule points repeat: {[p.label() for p in pts]}; give each point once")
    spacing = np.array(_spacing(sc.aircraft, h_spacing_ft, vc_spacing_kts))
    t0 = time.perf_counter()
    models, fails = _linearize_points(sc, pts)
    t_lin = time.perf_counter() - t0
    notes: list[str] = [f"designed by fdi_sim.training.schedule.design_schedule for {sc.source} ({sc.aircraft}, "
                        f"{sc.model.atmosphere.turbulence} turbulence), {len(pts)} points linearized in {t_lin:.1f} s",
                        f"calibration 'points': {n_flights} x {duration_s:g} s fault-free flights at each point "
                        f"(seeds 1e6 + i, pulse-train maneuvers only), target {target:g} per sample at {rate_hz:g} Hz"]

    def failed(f: _Failure) -> None:
        if on_failure == "refuse":
            raise _failure_error(sc, f)
        notes.append(f"skipped {f.point.label()} (flaps {f.point.flaps_deg:g} deg): {f.reason}")

    for f in fails:
        failed(f)
    todo = [(i, p) for i, p in enumerate(pts) if models[i] is not None]
    done: list[tuple[DesignPoint, CachedCalibration, Any]] = []
    for k, (i, p) in enumerate(todo):
        label = f"point {k + 1}/{len(todo)} ({p.label()}): "
        try:
            res = gust_kalman_calibration(point_scenario(sc, p), models[i], rate_hz=rate_hz, n_flights=n_flights,
                                          duration_s=duration_s, target=target, params=params, use_cache=use_cache,
                                          progress=progress, progress_label=label)
        except DesignError as exc:  # an unstable filter, or a training flight that diverged at this point
            failed(_Failure(p, str(exc)))
            continue
        if progress and res.cached and sys.stderr.isatty():
            print(f"{label}calibration cached ({res.key})", file=sys.stderr)
        c = res.detector.calibration
        notes.append(f"{p.label()}: threshold {c.threshold:.4g} (analytic {c.threshold_analytic:.4g}), calibration "
                     f"{res.key} {'from the cache' if res.cached else f'flown in {res.wall_s:.0f} s'}")
        done.append((p, res, models[i]))
    if not done:
        raise DesignError(f"{sc.source}: no schedule point could be designed ({len(pts)} tried): "
                          + "; ".join(n for n in notes if n.startswith("skipped")))
    y_names = list(done[0][1].detector.design.model.output_names)
    sched_pts = []
    for p, res, _ in done:
        y0 = np.asarray(res.detector.design.model.y0, dtype=float)
        sched_pts.append([y0[y_names.index(s)] for s in SCHEDULE_SIGNALS])  # the trim's own h_ft, vc_kts
    return GustKalmanSchedule(np.array(sched_pts), spacing, tuple(r.detector.design for _, r, _ in done),
                              tuple(r.detector.calibration for _, r, _ in done),
                              tuple(p.label() for p, _, _ in done), notes=tuple(notes))


def design_scenario(sc: Scenario) -> Scenario:
    """The scenario the bank is designed and calibrated on (:func:`design_choice`)."""
    return design_choice(sc)[0]


def design_choice(sc: Scenario) -> tuple[Scenario, str]:
    """The scenario the bank is designed and calibrated on, and a note for the log saying which.

    With ``[fdi.design] point = "auto"`` (the default) and no other design field: the calibrated
    design of the aircraft's shipped atlas (:func:`atlas_design`) when it covers the flight, else
    the flight itself (the note says why). Otherwise :func:`_design_scenario`.
    """
    d = sc.model.fdi.design
    if d.point == "auto":
        if all(v is None for v in (d.turbulence, d.wind_speed_kts, d.wind_from_deg, d.noise_scale, d.maneuvers)):
            des, note = atlas_design(sc)
            if des is not None:
                return des, note
            return _design_scenario(sc), f"designed at the flight's own point and conditions: {note}"
    return _design_scenario(sc), ""


def atlas_design(sc: Scenario) -> tuple[Scenario | None, str]:
    """The calibrated design of the flight's node in the aircraft's atlas (:mod:`fdi_sim.training.atlas`):
    the atlas's reference scenario at the flight's initial point, with the flight's sensor suite,
    simulation rate, ``[fdi]`` settings and detectors, designed at the grid node in the atlas's
    conditions (:data:`fdi_sim.training.atlas.CONDITIONS`); None and why when the atlas does not
    cover the flight (none shipped, a flight crossing several schedule points, a node or settings
    the atlas was not made for).
    """
    from fdi_sim.data import shown_path
    from fdi_sim.training.atlas import load_atlas, scenario_digest

    atlas = load_atlas(sc.aircraft)
    if atlas is None:
        return None, f"no calibration atlas for the {sc.aircraft} (fdi_sim.training.atlas)"
    if sc.model.fdi.schedule == "auto":
        pts = schedule_points(sc)
        if len(pts) > 1:
            return None, (f"the flight crosses {len(pts)} schedule points ({'; '.join(p.label() for p in pts[:4])}"
                          f"{'; ...' if len(pts) > 4 else ''}): the atlas covers flights at one node")
    own = json.loads(sc.to_json()).get("maneuvers", [])
    if own:
        from fdi_sim.scenario.loader import load
        from fdi_sim.scenario.shipped import shipped_dir

        ref = json.loads(load(shipped_dir() / f"{atlas.reference}.toml").to_json()).get("maneuvers", [])
        if own != ref:  # thresholds come from flights with the flight's own maneuvers, or none
            return None, (f"the flight's maneuvers are neither none nor {atlas.reference}'s (those of the atlas's "
                          "training flights; in calm air the gust filter's threshold depends on them)")
    des = calibrated_design(sc, atlas.reference)
    node = atlas.node_for(scenario_digest(json.loads(des.to_json())))
    ini = sc.model.initial
    h, vc = des.model.initial.h_ft, des.model.initial.vc_kts
    level = des.model.atmosphere.turbulence
    man = "doublets" if des.maneuvers else "steady"
    where = f"node h {h:g} ft, vc {vc:g} kt, flaps {float(ini.flaps_deg):g} deg, {level} turbulence, {man} flights"
    if node is None:
        inside = any((n.h_ft, n.vc_kts, n.flaps_deg, n.turbulence, n.maneuvers) == (h, vc, float(ini.flaps_deg),
                                                                                  level, man) for n in atlas.nodes)
        why = ("its sensors, simulation rate or [fdi] settings differ from those the atlas was made with"
               if inside else f"the atlas has no such node (its envelope: {atlas.envelope})")
        return None, f"{atlas.path} does not cover this flight ({where}): {why}"
    if node.status != "ok":
        return None, f"{atlas.path}: {where} has no calibration ({node.status})"
    told = sc.model.atmosphere.turbulence
    flights = f"{atlas.reference}'s maneuvers, as the flight's" if des.maneuvers else "no maneuvers, as the flight"
    return des, (f"calibrated design of {shown_path(atlas.path)} at {where} (training flights: {flights}, no wind, noise "
                 f"scale 1; {atlas.training}; the turbulence level is the scenario's"
                 + ("" if told == level else f" ({told}: the atlas's nearest level below)") + ")")


def calibrated_design(sc: Scenario, reference: str) -> Scenario:
    """The calibrated design scenario of a flight: the shipped scenario ``reference`` at the flight's
    initial point (h, calibrated airspeed, flaps), with the flight's sensor section, simulation
    rate, ``[fdi]`` settings and detectors, no faults, designed at the nearest grid node in the
    atlas conditions (:data:`fdi_sim.training.atlas.CONDITIONS`). The atlas is made of these
    (:mod:`fdi_sim.study.atlas`), so it depends on nothing else of the flight."""
    from fdi_sim.scenario.loader import load
    from fdi_sim.scenario.shipped import shipped_dir
    from fdi_sim.training.atlas import CONDITIONS, design_turbulence

    ref = load(shipped_dir() / f"{reference}.toml")
    data = json.loads(ref.to_json())
    flight = json.loads(sc.to_json())
    if not sc.maneuvers:  # a flight without maneuvers: steady training flights (fdi_sim.training.atlas.MANEUVERS)
        data["maneuvers"] = []
    ini = sc.model.initial
    data["initial"] = {**data["initial"], "h_ft": float(ini.h_ft), "vc_kts": initial_vc_kts(sc), "vt_kts": None,
                       "flaps_deg": float(ini.flaps_deg)}
    for k in ("sensors", "detectors", "rate_hz"):
        if k in flight:
            data[k] = flight[k]
        else:
            data.pop(k, None)
    data["fdi"] = {**flight.get("fdi", {}), "design": {**CONDITIONS,
                                                       "turbulence": design_turbulence(sc.model.atmosphere.turbulence)}}
    data["faults"] = []
    return _design_scenario(from_dict(data, source=f"{sc.source} (calibrated design on {reference})"))


def _design_scenario(sc: Scenario) -> Scenario:
    """The scenario the bank is designed and calibrated on: ``sc`` itself unless ``[fdi.design]``
    moves the point to the schedule grid's nearest node or sets the training flights' turbulence,
    wind or sensor noise.

    The grid is the aircraft's (:data:`fdi_sim.training.schedule.DEFAULT_SPACING`): nodes at whole
    multiples of the spacing in altitude [ft] and calibrated airspeed [kt], so runs of a study
    that sample the point continuously share one design per node (the gain scheduling of a real
    bank), and each node is designed and calibrated once (cached).
    """
    d = sc.model.fdi.design
    if d.point != "grid" and all(v is None for v in (d.turbulence, d.wind_speed_kts, d.wind_from_deg, d.noise_scale,
                                                     d.maneuvers)):
        return sc
    data = json.loads(sc.to_json())
    what = []
    if d.maneuvers is not None:
        # the training flights fly these (cut at their own length by training.flights.fault_free); the
        # design scenario is long enough to hold them (its duration is no part of the design: fault_free
        # sets the training flights' own)
        man = [dict(m) for m in d.maneuvers]
        last = max((float(m.get("t_start_s", 0.0)) for m in man), default=0.0)
        data["duration_s"] = max(float(data["duration_s"]), float(sc.model.fdi.calibration_duration_s), last + 1.0)
        data["maneuvers"] = man
    if d.point == "grid":
        dh, dv = default_spacing(sc.aircraft)
        h = max(dh, round(sc.model.initial.h_ft / dh) * dh)
        vc = max(dv, round(initial_vc_kts(sc) / dv) * dv)
        data["initial"] = {**data["initial"], "h_ft": h, "vc_kts": vc, "vt_kts": None}
        what.append(f"grid node h {h:g} ft, vc {vc:g} kt")
    atm = dict(data.get("atmosphere", {}))
    if d.turbulence is not None:
        atm["turbulence"] = d.turbulence
        what.append(f"{d.turbulence} turbulence")
    if d.wind_speed_kts is not None:
        atm["wind_speed_kts"] = d.wind_speed_kts
        what.append(f"wind {d.wind_speed_kts:g} kt")
    if d.wind_from_deg is not None:
        atm["wind_from_deg"] = d.wind_from_deg
    if float(atm.get("wind_speed_kts", 0.0)) == 0.0:
        atm["wind_from_deg"] = 0.0  # no wind has no direction: one design, whatever the flight's
    data["atmosphere"] = atm
    if d.noise_scale is not None:
        data["sensors"] = {**data.get("sensors", {}), "noise_scale": d.noise_scale}
        what.append(f"noise scale {d.noise_scale:g}")
    # the design conditions are the design; a flight-specific name, seed or duration is not
    data["fdi"] = {**data["fdi"], "design": {"point": "flight"}}
    data.update(name=f"{sc.aircraft}_design", description="", seed=0, faults=[])
    return from_dict(data, source=f"{sc.source} (bank design at {', '.join(what)})")


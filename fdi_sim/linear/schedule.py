"""Model schedule: every grid point's linear model with its operating point, in one file.

Gain scheduling as in Miller & Ribbens, US 6,643,569 B2 (``002_d6038a6910cf5866.txt``): "the
state estimator matrices (A, B, C, D, L) are supplied by the FDF controller block (e.g., via table
look-up) ... based upon the nominal operating point". The schedule is that table.

File format (``.npz``, numpy, no pickle; loads in milliseconds)
----------------------------------------------------------------
``meta``  JSON string: format name and version, aircraft, names of states, inputs (and their
          kinds) and outputs, provenance (jsbsim and fdi-sim versions, settings), and one entry
          per grid point: operating point, status and reason, trim values, scheduling values,
          named modes, validation errors, FGLinearization check, and ``index`` into the arrays
          (-1 for points without a model).
``A, B, C, D, x0, u0, y0``  stacked continuous-time matrices and trim values of the points with
          a model, shapes (K, n, n), (K, n, m), (K, p, n), (K, p, m), (K, n), (K, m), (K, p).
``step_Ax, step_Bu, step_Lf``  (optional) the step terms of every model
          (:class:`~fdi_sim.linear.model.StepTerms`: how the derivatives build up within JSBSim's
          step), shapes (K, P, r, n), (K, P, r, m), (K, q, r); ``meta["meta"]["step"]`` holds their
          ``dt_s``, ``n_rigid`` and ``lagged_outputs``. With them ``method="step"`` gives the
          discrete model of the simulation step (at the simulation's ``dt_s`` or a multiple of it).

Lookup
------
Points are looked up by the scheduling variables the aircraft measures at every step:
altitude ``h_ft`` and calibrated airspeed ``vc_kts`` (air data), plus the configuration
``flaps_deg`` and ``icing_eta``. Distances are measured in grid spacings. By default the
*nearest* point's model is returned, because detector designs (parity bases, filter gains,
thresholds) are made per grid point and the model must be the one the design was made from.
``interpolate=True`` blends the continuous matrices of the enclosing triangle (barycentric, in
the (h, vc) plane of the same flaps/eta) before discretizing: smoother, but no design exists for
it. A lookup farther than ``max_distance`` spacings from every point is refused; more than half a
spacing outside the box of the grid it warns with the distance (inside, the nearest point of a
full grid is at most half a cell diagonal away, which is what a schedule is built for).
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError
from fdi_sim.isa import vc_from_vt
from fdi_sim.linear.model import LinearModel, StepTerms
from fdi_sim.linear.transform import DEFAULT_DT_S, discretize, reduce
from fdi_sim.operating_point import OperatingPoint

FORMAT = "fdi-sim-model-schedule"
VERSION = 1
#: the scheduling variables, in the order of distances and spacings
SCHEDULE_VARS: tuple[str, ...] = ("h_ft", "vc_kts", "flaps_deg", "icing_eta")
#: smallest spacing used for each variable (a grid with one value on an axis uses this)
_MIN_SPACING: dict[str, float] = {"h_ft": 1000.0, "vc_kts": 10.0, "flaps_deg": 10.0, "icing_eta": 0.05}
#: lookups farther than this from every point are refused [grid spacings]
MAX_DISTANCE: float = 1.5
#: the stacked arrays of a schedule file
ARRAYS: tuple[str, ...] = ("A", "B", "C", "D", "x0", "u0", "y0")
#: the optional stacked step terms (present when every model has them, with the same passes)
STEP_ARRAYS: tuple[str, ...] = ("step_Ax", "step_Bu", "step_Lf")


@dataclass(frozen=True)
class SchedulePoint:
    """One grid point of a schedule.

    Attributes
    ----------
    op : OperatingPoint
        The requested operating point.
    status : str
        ``"ok"``, ``"untrimmable"`` or ``"skipped"``.
    reason : str
        Why the point has no model (empty when ``ok``).
    index : int
        Row in the stacked arrays, -1 without a model.
    sched : dict
        Scheduling values at the trim (``h_ft``, ``vc_kts``, ``flaps_deg``, ``icing_eta``).
    trim : dict
        Trimmed values (angles, speeds, commands, residual).
    info : dict
        Everything else recorded for the report: ``modes``, ``validation``, ``fglin``, ``timing_s``.
    """

    op: OperatingPoint
    status: str
    reason: str = ""
    index: int = -1
    sched: dict[str, float] = field(default_factory=dict)
    trim: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class ScheduledModel:
    """The answer of a lookup.

    Attributes
    ----------
    model : LinearModel
        Discrete-time model (``dt_s`` and method as asked).
    how : str
        ``"nearest"`` or ``"interpolated"``.
    why : str
        One sentence on the choice (and any fallback).
    indices : tuple of int
        Schedule points used (positions in ``ModelSchedule.points``).
    weights : tuple of float
        Their weights (1.0 for nearest).
    distance : float
        Distance to the nearest point in grid spacings [-].
    """

    model: LinearModel
    how: str
    why: str
    indices: tuple[int, ...]
    weights: tuple[float, ...]
    distance: float


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, complex):
        return [x.real, x.imag]
    return x


class ModelSchedule:
    """Linear models over an operating-point grid, with lookup by scheduling variables.

    Build with :func:`fdi_sim.linear.linearize.linearize_grid` or :meth:`load`.

    Parameters
    ----------
    aircraft : str
        JSBSim model name.
    points : sequence of SchedulePoint
        Every grid point, with or without a model.
    arrays : mapping
        ``A, B, C, D, x0, u0, y0`` stacked over the points with a model (and optionally
        :data:`STEP_ARRAYS`).
    names : mapping
        ``state_names``, ``input_names``, ``input_kinds``, ``output_names``, ``lagged_outputs``.
    meta : mapping
        Provenance; ``step`` (``dt_s``, ``n_rigid``, ``lagged_outputs``) with step arrays.
    """

    def __init__(self, aircraft: str, points: Sequence[SchedulePoint], arrays: Mapping[str, NDArray[np.float64]],
                 names: Mapping[str, Sequence[str]], meta: Mapping[str, Any] | None = None) -> None:
        self.aircraft = aircraft
        self.points = tuple(points)
        self.arrays = {k: np.asarray(v, dtype=float) for k, v in arrays.items()}
        for v in self.arrays.values():
            v.setflags(write=False)
        self.names = {k: tuple(v) for k, v in names.items()}
        self.meta = dict(meta or {})
        self._ok = [i for i, p in enumerate(self.points) if p.index >= 0]
        self._cache: dict[tuple[Any, ...], LinearModel] = {}
        X = np.array([[self.points[i].sched[k] for k in SCHEDULE_VARS] for i in self._ok]).reshape(-1, len(SCHEDULE_VARS))
        self._X = X
        self._spacing = np.array([max(_axis_spacing(X[:, j]), _MIN_SPACING[k]) for j, k in enumerate(SCHEDULE_VARS)])

    # ------------------------------------------------------------------ access
    @property
    def ok_points(self) -> tuple[SchedulePoint, ...]:
        """Points with a model."""
        return tuple(self.points[i] for i in self._ok)

    def continuous(self, i: int) -> LinearModel:
        """Continuous-time model of point ``i`` (position in :attr:`points`)."""
        p = self.points[i]
        if p.index < 0:
            raise DesignError(f"point {i} ({p.op.label()}) has no model: {p.status}, {p.reason}")
        return self._model(self._blend([p.index], [1.0]), p.op)

    @property
    def has_step(self) -> bool:
        """True when the models carry step terms (``method="step"`` works)."""
        return all(k in self.arrays for k in STEP_ARRAYS) and "step" in self.meta

    def _blend(self, rows: Sequence[int], w: Sequence[float]) -> dict[str, NDArray[np.float64]]:
        keys = ARRAYS + (STEP_ARRAYS if self.has_step else ())
        return {k: sum(wi * self.arrays[k][r] for r, wi in zip(rows, w)) for k in keys}

    def _model(self, m: Mapping[str, NDArray[np.float64]], op: OperatingPoint | None) -> LinearModel:
        step = None
        if self.has_step:
            st = self.meta["step"]
            step = StepTerms(Ax=m["step_Ax"], Bu=m["step_Bu"], Lf=m["step_Lf"], lagged_outputs=tuple(st["lagged_outputs"]),
                             dt_s=float(st["dt_s"]), n_rigid=int(st["n_rigid"]))
        return LinearModel(
            A=m["A"], B=m["B"], C=m["C"], D=m["D"], dt_s=0.0, state_names=self.names["state_names"],
            input_names=self.names["input_names"], output_names=self.names["output_names"],
            input_kinds=self.names["input_kinds"], x0=m["x0"], u0=m["u0"], y0=m["y0"], op=op,
            meta={"aircraft": self.aircraft, "lagged_outputs": list(self.names.get("lagged_outputs", ()))},
            step=step,
        )

    # ------------------------------------------------------------------ lookup
    def sched_of(self, op: OperatingPoint) -> NDArray[np.float64]:
        """Scheduling values (h_ft, vc_kts, flaps_deg, icing_eta) of an operating point."""
        vc = op.vc_kts if op.vc_kts is not None else vc_from_vt(op.h_ft, float(op.vt_kts))[0]  # type: ignore[arg-type]
        return np.array([op.h_ft, float(vc), op.flaps_deg, op.icing_eta])

    def distances(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance of scheduling values ``s`` to every point with a model [grid spacings]."""
        return np.sqrt(np.sum(((self._X - s) / self._spacing) ** 2, axis=1))

    def outside_distance(self, s: NDArray[np.float64]) -> float:
        """How far scheduling values ``s`` lie outside the box of the grid's points [grid spacings] (0 inside)."""
        lo, hi = self._X.min(axis=0), self._X.max(axis=0)
        return float(np.sqrt(np.sum((np.maximum(0.0, np.maximum(lo - s, s - hi)) / self._spacing) ** 2)))

    def continuous_at(self, op: OperatingPoint) -> LinearModel:
        """The continuous model of the grid point nearest ``op`` (before any discretization).

        For designs that change the continuous model first (e.g. adding the rotational
        turbulence columns of :func:`fdi_sim.detectors.disturbance.rotational_turbulence_inputs`).
        """
        found = self.model_at(op, dt_s=DEFAULT_DT_S)
        (row,) = found.indices
        return replace(self._model(self._blend([self.points[row].index], [1.0]), op), op=op)

    def model_at(self, op: OperatingPoint, dt_s: float = DEFAULT_DT_S, method: str = "zoh",
                 interpolate: bool = False, max_distance: float = MAX_DISTANCE, reduced: bool = False
                 ) -> ScheduledModel:
        """The discrete-time model for ``op`` (nearest point, or interpolated).

        Parameters
        ----------
        op : OperatingPoint
            Where the aircraft is; its ``aircraft`` must match the schedule's.
        dt_s : float
            Detector sample time [s] (default 1/120 s, the simulation's rate).
        method : str
            ``"zoh"``, ``"euler"`` or ``"step"`` (the model of the simulation step, at its
            ``dt_s`` or a multiple of it; see :func:`fdi_sim.linear.transform.discretize`).
        interpolate : bool
            Blend the enclosing triangle's models instead of taking the nearest.
        max_distance : float
            Refuse lookups farther than this from every point [grid spacings].
        reduced : bool
            Balanced truncation of the discrete model (:func:`fdi_sim.linear.transform.reduce`,
            default tolerance), scaled by the point's validation: the doublet amplitudes and the
            RMS of JSBSim's responses (:meth:`signal_scales`). Meant for the step model (51-84
            states -> about 21).

        Raises
        ------
        DesignError
            Another aircraft, an empty schedule, a lookup too far from the grid, or ``reduced``
            on a schedule made without validation.
        """
        if op.aircraft != self.aircraft:
            raise DesignError(f"the schedule is for {self.aircraft!r}, the operating point for {op.aircraft!r}; "
                              f"load the {op.aircraft} schedule")
        return self.lookup(self.sched_of(op), dt_s=dt_s, method=method, interpolate=interpolate,
                           max_distance=max_distance, op=op, reduced=reduced)

    def signal_scales(self, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Typical input and output sizes at point ``i`` from its validation [units of the signals].

        Inputs: the doublet amplitudes; outputs: the RMS of JSBSim's doublet responses over all
        runs (outputs no run moved get the smallest positive RMS).

        Raises
        ------
        DesignError
            The schedule was made without validation (``--no-validate``).
        """
        amps = self.meta.get("validation", {}).get("amplitudes", {})
        # any discretization's entry: rms_nl is of JSBSim's runs, the same for all
        val = next(iter(self.points[i].info.get("validation", {}).values()), None)
        if val is None or not amps:
            raise DesignError("signal scales come from the validation; this schedule was made without it "
                              "(re-run fdi-sim linearize without --no-validate, or give reduce() the scales)")
        su = np.array([float(amps[n]) for n in self.names["input_names"]])
        rms = np.sqrt(np.mean(np.asarray(val["rms_nl"], dtype=float) ** 2, axis=0))
        return su, np.where(rms > 0, rms, np.min(rms[rms > 0]))

    def lookup(self, s: Sequence[float], dt_s: float = DEFAULT_DT_S, method: str = "zoh", interpolate: bool = False,
               max_distance: float = MAX_DISTANCE, op: OperatingPoint | None = None, reduced: bool = False
               ) -> ScheduledModel:
        """:meth:`model_at` from raw scheduling values ``(h_ft, vc_kts, flaps_deg, icing_eta)``.

        A running simulation uses :class:`ScheduleTracker`, which calls this only when it
        switches points.
        """
        if not self._ok:
            raise DesignError(f"the {self.aircraft} schedule has no trimmed point; re-run `fdi-sim linearize`")
        s = np.asarray(s, dtype=float).reshape(len(SCHEDULE_VARS))
        d = self.distances(s)
        near = int(np.argmin(d))
        dist = float(d[near])
        where = ", ".join(f"{k}={v:g}" for k, v in zip(SCHEDULE_VARS, s))
        if dist > max_distance:
            raise DesignError(f"lookup at {where} is {dist:.2f} grid spacings from the nearest {self.aircraft} point "
                              f"({self.points[self._ok[near]].op.label()}), beyond max_distance={max_distance}; "
                              "extend the grid or fly inside it")
        rows, w, how = [self._ok[near]], [1.0], "nearest"
        why = ("nearest grid point: detector designs are made per grid point, so the model matches the design "
               f"(distance {dist:.2f} spacings)")
        if interpolate:
            tri = self._triangle(s)
            if tri is None:
                why = f"interpolation asked for but the point is outside the grid's (h, vc) hull: nearest instead ({why})"
            else:
                rows, w, how = tri[0], tri[1], "interpolated"
                why = "barycentric blend of the enclosing triangle's continuous models in (h_ft, vc_kts)"
        outside = self.outside_distance(s)
        if outside > 0.5:  # inside the grid the nearest point is at most half a cell diagonal away
            warnings.warn(f"{self.aircraft} schedule lookup at {where} is {dist:.2f} grid spacings from the nearest "
                          f"point, {outside:.2f} outside the grid; the linear model may not represent the aircraft "
                          "there", stacklevel=2)
        key = (tuple(rows), tuple(round(x, 12) for x in w), dt_s, method, reduced)
        model = self._cache.get(key)
        if model is None:
            cont = self._model(self._blend([self.points[r].index for r in rows], w), op or self.points[rows[0]].op)
            model = discretize(cont, dt_s, method=method)
            if reduced:
                su, sy = self.signal_scales(rows[int(np.argmax(w))])
                model = reduce(model, input_scale=su, output_scale=sy)
            if len(self._cache) < 512:
                self._cache[key] = model
        if op is not None and model.op is not op:  # the cache is per grid point; the answer names this lookup's point
            model = replace(model, op=op)
        return ScheduledModel(model=model, how=how, why=why, indices=tuple(rows), weights=tuple(w), distance=dist)

    def _triangle(self, s: NDArray[np.float64]) -> tuple[list[int], list[float]] | None:
        from scipy.spatial import Delaunay, QhullError

        same = [j for j, i in enumerate(self._ok)
                if abs(self._X[j, 2] - s[2]) < 1e-9 and abs(self._X[j, 3] - s[3]) < 1e-9]
        if len(same) < 3:
            return None
        P = self._X[same][:, :2] / self._spacing[:2]
        try:
            tri = Delaunay(P)
        except QhullError:
            return None
        q = s[:2] / self._spacing[:2]
        k = int(tri.find_simplex(q))
        if k < 0:
            return None
        T = tri.transform[k]
        b = T[:2] @ (q - T[2])
        bary = np.r_[b, 1 - b.sum()]
        return [self._ok[same[v]] for v in tri.simplices[k]], [float(x) for x in bary]

    # ------------------------------------------------------------------ file
    def save(self, path: str | Path) -> Path:
        """Write the schedule (``.npz``); returns the path written."""
        p = Path(path)
        if p.suffix != ".npz":
            p = p.with_suffix(".npz")
        p.parent.mkdir(parents=True, exist_ok=True)
        meta = {
            "format": FORMAT, "version": VERSION, "aircraft": self.aircraft, "names": self.names, "meta": self.meta,
            "points": [{"op": asdict(pt.op), "status": pt.status, "reason": pt.reason, "index": pt.index,
                        "sched": pt.sched, "trim": pt.trim, "info": pt.info} for pt in self.points],
        }
        np.savez(p, meta=np.array(json.dumps(_jsonable(meta))), **self.arrays)
        return p

    @classmethod
    def load(cls, path: str | Path, aircraft: str | None = None) -> "ModelSchedule":
        """Read a schedule file.

        Raises
        ------
        DesignError
            Not a schedule file, a newer version, or (with ``aircraft``) a file from another aircraft.
        """
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in ARRAYS + STEP_ARRAYS if k in z.files or k in ARRAYS}
        except FileNotFoundError:
            raise DesignError(f"schedule file {p} not found; create it with `fdi-sim linearize`") from None
        except (OSError, KeyError, ValueError, json.JSONDecodeError) as exc:
            raise DesignError(f"{p} is not an fdi-sim model schedule ({exc})") from None
        if meta.get("format") != FORMAT:
            raise DesignError(f"{p} is not an fdi-sim model schedule (format {meta.get('format')!r})")
        if int(meta.get("version", 0)) > VERSION:
            raise DesignError(f"{p} has schedule version {meta['version']}; this fdi-sim reads up to {VERSION}")
        if aircraft is not None and meta["aircraft"] != aircraft:
            raise DesignError(f"{p} is a schedule for {meta['aircraft']!r}, not {aircraft!r}; "
                              f"use the {aircraft} schedule")
        points = [SchedulePoint(op=OperatingPoint(**d["op"]), status=d["status"], reason=d["reason"],
                                index=int(d["index"]), sched=d["sched"], trim=d["trim"], info=d["info"])
                  for d in meta["points"]]
        return cls(meta["aircraft"], points, arrays, meta["names"], meta.get("meta", {}))


def _axis_spacing(v: NDArray[np.float64]) -> float:
    """Median gap between the distinct values of one scheduling variable (0 if one value)."""
    u = np.unique(np.round(v, 9))
    return float(np.median(np.diff(u))) if u.size > 1 else 0.0


class ScheduleTracker:
    """Follows the operating point of a running simulation and picks the schedule point.

    ``step(t_s, u, y)`` reads ``h_ft`` and ``vc_kts`` from the measurement ``y`` (in the
    schedule's output order) and returns the :class:`ScheduledModel` in use. A new point is
    taken only when it is nearer than the current one by ``hysteresis`` grid spacings, so
    noise on the air data does not switch models back and forth. Between switches a step
    creates no objects: the distances go into preallocated buffers and the current model is
    returned as it is.

    Parameters
    ----------
    schedule : ModelSchedule
        The schedule.
    flaps_deg, icing_eta : float
        Configuration (not measured).
    dt_s : float
        Detector sample time [s].
    method : str
        Discretization.
    reduced : bool
        Balanced truncation of each model (:meth:`ModelSchedule.model_at`).
    hysteresis : float
        Switching margin [grid spacings].
    max_distance : float
        Refuse measurements farther than this from every point [grid spacings].
    """

    def __init__(self, schedule: ModelSchedule, flaps_deg: float = 0.0, icing_eta: float = 0.0,
                 dt_s: float = DEFAULT_DT_S, method: str = "zoh", hysteresis: float = 0.1,
                 max_distance: float = MAX_DISTANCE, reduced: bool = False) -> None:
        self.schedule, self.dt_s, self.method, self.reduced = schedule, dt_s, method, reduced
        self.hysteresis, self.max_distance = hysteresis, max_distance
        outs = schedule.names.get("output_names", ())
        if "h_ft" not in outs or "vc_kts" not in outs:
            raise DesignError("ScheduleTracker needs h_ft and vc_kts among the schedule's outputs")
        self._ih, self._iv = outs.index("h_ft"), outs.index("vc_kts")
        self._s = np.array([math.nan, math.nan, flaps_deg, icing_eta])
        self._diff = np.empty_like(schedule._X)
        self._d = np.empty(len(schedule._X))
        self._cur = -1  # position of the current point among the schedule's points with a model
        self.current: ScheduledModel | None = None

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Forget the current point (no randomness is used)."""
        self.current, self._cur = None, -1

    def step(self, t_s: float, u: NDArray[np.float64], y: NDArray[np.float64]) -> ScheduledModel:
        """Pick the model for the measured operating point at time ``t_s`` [s].

        Raises
        ------
        DesignError
            Non-finite air data, or a point beyond ``max_distance`` from the grid.
        """
        h_ft, vc_kts = y[self._ih], y[self._iv]
        if not (math.isfinite(h_ft) and math.isfinite(vc_kts)):
            raise DesignError(f"t = {t_s:.3f} s: non-finite air data h_ft = {h_ft}, vc_kts = {vc_kts} "
                              "for the schedule lookup")
        s, d, diff = self._s, self._d, self._diff
        s[0], s[1] = h_ft, vc_kts
        np.subtract(self.schedule._X, s, out=diff)  # d = |(X - s) / spacing| per point, as ModelSchedule.distances
        np.divide(diff, self.schedule._spacing, out=diff)
        np.square(diff, out=diff)
        np.sqrt(np.sum(diff, axis=1, out=d), out=d)
        near = int(np.argmin(d))
        if d[near] > self.max_distance or self._cur < 0 or (near != self._cur and d[near] + self.hysteresis < d[self._cur]):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the distance warning is for one-off lookups
                # raises beyond max_distance, with the distance and the nearest point
                self.current = self.schedule.lookup(s, self.dt_s, self.method, max_distance=self.max_distance,
                                                    reduced=self.reduced)
            self._cur = near
        assert self.current is not None
        return self.current

"""Building the in-loop FDI bank of a scenario: which detectors, their designs and thresholds.

``[fdi] bank = "default"`` gives every aircraft the detectors ``docs/detectors.md`` finds working
on it (:data:`DEFAULT_BANKS`); ``[[detectors]]`` entries add to it (or make the bank on their
own). Any registered detector, built in or a plugin, runs in the loop through the one streaming
contract (:mod:`fdi_sim.detectors.stream`; :func:`member_stream`).

Designs: ``kalman-gust-v1`` at the schedule points the flight crosses
(:func:`fdi_sim.sim.designs.schedule_points`, gain-scheduled when there is more than one and
``schedule = "auto"``), each calibrated (``Sigma_m``) on fault-free training flights; the
kinematic checks from their catalogue. Thresholds: the bank's design false-alarm rate
``far_per_h`` is split evenly over its detectors (a union bound), and each detector's threshold is
the level whose alarm episodes come ``far_per_h / detectors`` times per flight hour on the
fault-free training flights: the k-of-n decision applied exactly
(:func:`fdi_sim.decision.tail.persistence_series`), the episodes' peaks fitted by a generalized
Pareto (or exponential) tail and extrapolated (:func:`fdi_sim.decision.tail.episode_threshold`),
taken at its 95 % bootstrap bound over the training flights
(:func:`fdi_sim.decision.tail.confident_episode_threshold`). The angle-magnitude rule, whose
exceedance also needs a fault direction, keeps the per-sample quantile
``p = far_per_h / (detectors x rate_hz x 3600)`` (:func:`fdi_sim.decision.tail.confident_tail_threshold`).
"""
from __future__ import annotations

import difflib
import hashlib
import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from fdi_sim import __version__, registry
from fdi_sim.errors import DesignError, ScenarioError
from fdi_sim.scenario import Scenario
from fdi_sim.threads import single_blas_thread
from fdi_sim.units import S_PER_H


#: the detectors a new user gets, per aircraft (``docs/detectors.md``: the ones that work on it)
#: (the flow-angle check watches the vanes, which nothing else isolates; in turbulence its threshold,
#: set on the scenario's flights, is large and it only catches gross vane faults)
DEFAULT_BANKS: dict[str, tuple[str, ...]] = {
    ac: ("kalman-gust-v1", "kinematic-attitude-v1", "kinematic-altitude-v1", "kinematic-airspeed-v1",
         "kinematic-flow-angles-v1") for ac in ("f16", "DHC6")
}
#: thresholds meet the per-sample target with this confidence (flight-level bootstrap)
THRESHOLD_CONFIDENCE = 0.95
#: per-process memo of gust-filter schedules (design scenario -> schedule, note), or None (off): a
#: Monte Carlo worker turns it on (fdi_sim.study.execute.fly_run): the design (DARE, linearization,
#: 0.25 s) was 3/4 of a short run's set-up; off elsewhere, so a changed cache is always read again
DESIGN_MEMO: dict[str, tuple[Any, str]] | None = None
#: keys of a [[detectors]] entry that are not design options
ENTRY_KEYS = ("type", "n_flights", "duration_s", "target")


@dataclass(frozen=True)
class MemberSpec:
    """One detector of a scenario's bank: id and design options."""

    id: str
    params: dict[str, Any]
    source: str  # "bank" or "detectors[i]"


def bank_members(sc: Scenario) -> list[MemberSpec]:
    """The detectors a scenario's bank runs (empty: no bank): any registered detector, built in or
    a plugin (``fdi-sim plugins``).

    Raises
    ------
    ScenarioError
        An id that is not registered (with a "did you mean"), or two entries of the same id.
    """
    from fdi_sim.errors import RegistryError

    out: list[MemberSpec] = []
    f = sc.model.fdi
    if f.bank != "none":
        out += [MemberSpec(i, {}, "bank") for i in DEFAULT_BANKS[sc.aircraft]]
    seen: dict[str, str] = {}
    for i, (tid, params) in enumerate(sc.detectors):
        key = f"detectors[{i}]"
        try:
            registry.get("detector", tid)
        except RegistryError as e:
            raise ScenarioError(sc.source, f"{key}.type", str(e), "`fdi-sim plugins` lists every registered detector "
                                "(an installed plugin package registers its own)") from None
        if tid in seen:
            raise ScenarioError(sc.source, f"{key}.type", f"{tid!r} is already {seen[tid]}: detector ids in a bank "
                                "must be unique", "remove one of the two entries")
        seen[tid] = key
        p = dict(params) if isinstance(params, dict) else dict(getattr(params, "model_dump", lambda: {})())
        p = {k: v for k, v in p.items() if k != "type"}
        spec = MemberSpec(tid, p, key)
        out = [m for m in out if m.id != tid] + [spec]  # an entry replaces the bank's detector of that id
    return out


def per_sample_target(far_per_h: float, n_detectors: int, rate_hz: float) -> float:
    """``far_per_h / (n_detectors rate_hz 3600)``: each detector's per-sample exceedance probability
    that keeps the bank's alarm onsets below ``far_per_h`` per flight hour (union bound)."""
    return float(far_per_h) / (max(1, n_detectors) * float(rate_hz) * S_PER_H)


@single_blas_thread
def build_bank(sc: Scenario, *, meas_names: Sequence[str], cmd_names: Sequence[str],
               sensor_rates_hz: dict[str, float], pilot_sensors: Sequence[str], progress: bool = True,
               training_logs: Sequence[Any] | None = None) -> Any:
    """The scenario's :class:`~fdi_sim.sim.bank.FdiBank`, designed and calibrated (cached on disk).

    Raises
    ------
    ScenarioError
        A detector that cannot run in the loop.
    DesignError
        A detector that cannot be designed (``on_design_failure = "refuse"``), with where and why.
    """
    from fdi_sim.sim.bank import DecisionConfig, FdiBank

    members = bank_members(sc)
    if not members:
        return None
    sc = design_scenario(sc)  # designs, training flights and thresholds: at the design conditions
    f = sc.model.fdi
    # the training flights are flown at most once, and only if some calibration is not cached
    logs = training_logs if training_logs is not None else LazyTraining(sc, progress)
    ctx = MemberContext(sc, tuple(cmd_names), tuple(meas_names), progress, logs)
    streams, notes = [], []
    for m in members:
        stream, note = member_stream(ctx, m)
        streams.append(stream)
        notes.append(note)
    if f.decision == "angle-magnitude":
        bad = [s.id for s in streams if not s.fault_directions]
        if bad:
            raise ScenarioError(sc.source, "fdi.decision", f"angle-magnitude needs fault directions (C D_f), which "
                                f"{', '.join(bad)} do not give", 'use decision = "persistence", or members with '
                                "fault directions only ([[detectors]] without bank = \"default\")")
    S = int(round(f.block_s * f.rate_hz))
    decision = DecisionConfig(f.persistence_k, f.persistence_n, max(1, int(round(f.confirm_s * f.rate_hz))), f.decision)
    bank = FdiBank(streams, cmd_names=cmd_names, meas_names=meas_names, sensor_rates_hz=sensor_rates_hz,
                   sim_rate_hz=float(sc.model.rate_hz), rate_hz=f.rate_hz, block_samples=S, decision=decision,
                   reconfigure=f.reconfigure, pilot_sensors=pilot_sensors, notes=tuple(notes), arm_s=f.arm_s)
    p = per_sample_target(f.far_per_h, len(streams), f.rate_hz)
    path, explicit = thresholds_source(sc)
    if path is not None:
        trained: list[bool] = []

        def retrain() -> None:  # the bank's trained thresholds, once (the file's match on another CPU)
            if not trained:
                calibrate_thresholds(sc, bank, p, training_logs=logs, progress=progress)
                trained.append(True)

        note = apply_study_thresholds(sc, bank, path, explicit=explicit, retrain=retrain)
        if note is None:  # the default's file does not cover this design: trained, and the log says why
            retrain()
            bank.calibration = {**bank.calibration, "source": "trained", "note": note_no_match(sc, path)}
    else:
        calibrate_thresholds(sc, bank, p, training_logs=logs, progress=progress)
    return bank


# --- thresholds from a calibration study ------------------------------------------------------------
#: ``[fdi] thresholds = "default"`` per aircraft: "trained" (the bank's own training flights) or
#: "shipped" (:func:`shipped_thresholds_path`, where it covers the bank's design; trained elsewhere)
DEFAULT_THRESHOLDS: dict[str, str] = {"f16": "shipped", "DHC6": "shipped"}


def shipped_thresholds_path(aircraft: str) -> Path:
    """``aircraft/<aircraft>/fdi_thresholds.toml``: the thresholds the aircraft's calibration study gave."""
    from fdi_sim.data import aircraft_file
    from fdi_sim.sim.calibrate import THRESHOLDS_FILE

    return aircraft_file(aircraft, THRESHOLDS_FILE)


def thresholds_source(sc: Scenario) -> tuple[Path | None, bool]:
    """Where ``[fdi] thresholds`` takes the thresholds from: a thresholds file (None: the training
    flights), and whether the scenario named it (a mismatch is then an error, not trained thresholds).

    Raises
    ------
    ScenarioError
        ``"shipped"`` for an aircraft without a shipped file.
    """
    mode = sc.model.fdi.thresholds
    explicit = mode != "default"
    if mode == "default":
        mode = DEFAULT_THRESHOLDS.get(sc.aircraft, "trained")
    if mode == "trained":
        return None, explicit
    if mode == "shipped":
        path = shipped_thresholds_path(sc.aircraft)
        if not path.is_file():
            if not explicit:
                return None, False
            raise ScenarioError(sc.source, "fdi.thresholds", f"no shipped thresholds file for the {sc.aircraft} "
                                f"({path} does not exist)", 'use thresholds = "trained", or give the path of a file '
                                "written by `fdi-sim study STUDY --calibrate OUT.toml`")
        return path, explicit
    # a relative path: beside the scenario file (its source, before any " (bank design at ...)"
    # suffix), else from the working directory; a missing file is reported by read_thresholds
    path = Path(mode)
    if not path.is_absolute() and not path.is_file():
        beside = Path(sc.source.split(" (")[0]).parent / path
        if beside.is_file():
            path = beside
    return path, True


def design_hash(bank: Any) -> str:
    """Hash of what the members' statistics depend on (not their thresholds): per member its id and
    its stream's ``design_key()``; and the bank's rate and measurement columns."""
    h = hashlib.sha256()
    h.update(json.dumps([bank.rate_hz, list(bank.meas_names)], default=str).encode())
    from fdi_sim.detectors.stream import stream_design_key

    for mem in bank.members:
        h.update(mem.id.encode())
        h.update(stream_design_key(mem.stream))
    return h.hexdigest()[:24]


def design_node(sc: Scenario) -> dict[str, Any]:
    """The bank's design conditions (of :func:`design_scenario`): node, turbulence, wind, noise scale."""
    from fdi_sim.sim.designs import initial_vc_kts

    d = design_scenario(sc)
    return {"h_ft": float(d.model.initial.h_ft), "vc_kts": round(float(initial_vc_kts(d)), 6),
            "turbulence": d.model.atmosphere.turbulence, "wind_speed_kts": float(d.model.atmosphere.wind_speed_kts),
            "noise_scale": float(d.model.sensors.noise_scale)}


def note_no_match(sc: Scenario, path: Path) -> str:
    n = design_node(sc)
    return (f"thresholds = \"default\": {path} does not cover this bank's design (h {n['h_ft']:g} ft, vc "
            f"{n['vc_kts']:g} kt, {n['turbulence']} turbulence): trained thresholds")


#: a thresholds file whose design hash differs from the bank's still covers it when every member's
#: trained threshold is within this relative distance of the file's: measured between two CPUs
#: (the file made on an AMD EPYC without FMA, the bank on an Intel Xeon with AVX-512 and FMA, the
#: same code): design hashes differ (libm and BLAS round differently, the turbulent training
#: flights diverge from their last bits), the five DHC-6 trained thresholds by 0.2-0.9 %
TRAINED_MATCH_REL = 0.05


def apply_study_thresholds(sc: Scenario, bank: Any, path: Path, *, explicit: bool = True,
                           retrain: Callable[[], Any] | None = None) -> str | None:
    """Set the members' thresholds from a thresholds file where it matches the bank (aircraft,
    design node, member ids, rate and k-of-n rule; then the design hash, or, on a machine that
    rounds differently, the members' trained thresholds within :data:`TRAINED_MATCH_REL` of the
    file's, from ``retrain()``, which sets them on the bank); record the method per member.

    The calibrated thresholds describe the members' fault-free statistics, so the trained
    thresholds (the same statistics' tails on the bank's own training flights) are the test of
    whether the file still describes this bank: a bit-exact design hash ties a file to the CPU
    that made it.

    Returns None (nothing set) for a mismatch when ``explicit`` is False (``thresholds = "default"``).

    Raises
    ------
    ScenarioError
        A mismatch when the scenario named the file (``explicit``): names the file, the key, what
        differs and the fix.
    """
    from fdi_sim.sim.calibrate import read_thresholds

    t = read_thresholds(path)
    f = sc.model.fdi
    node = design_node(sc)
    want = {"aircraft": (t.aircraft, sc.aircraft),
            "design node": ((t.design_h_ft, t.design_vc_kts, t.design_turbulence, t.design_wind_speed_kts,
                             t.design_noise_scale),
                            (node["h_ft"], node["vc_kts"], node["turbulence"], node["wind_speed_kts"],
                             node["noise_scale"])),
            "members": ([m.id for m in t.members], [m.id for m in bank.members]),
            "decision": ((t.rate_hz, t.persistence_k, t.persistence_n),
                         (float(f.rate_hz), f.persistence_k, f.persistence_n))}
    bad = [(k, a, b) for k, (a, b) in want.items() if (round(a, 6) if isinstance(a, float) else a) !=
           (round(b, 6) if isinstance(b, float) else b)]
    matched = "design hash"
    if not bad:
        h = design_hash(bank)
        if h != t.design_hash:
            bad = [("design hash", t.design_hash, h)]
            if retrain is not None:
                retrain()
                rel = [abs(mem.threshold - m.trained_threshold) / abs(m.trained_threshold)
                       for mem, m in zip(bank.members, t.members)]
                worst = int(np.argmax(rel))
                if rel[worst] <= TRAINED_MATCH_REL:
                    bad = []
                    matched = (f"trained thresholds within {rel[worst]:.2%} of the file's (design hash {h}, the "
                               f"file's {t.design_hash}: another CPU's rounding, or a design change too small to move them)")
                else:
                    bad = [(f"{t.members[worst].id} trained threshold", t.members[worst].trained_threshold,
                            f"{bank.members[worst].threshold} ({rel[worst]:.1%} apart, more than "
                            f"{TRAINED_MATCH_REL:.0%}; design hash {h}, the file's {t.design_hash})")]
    if bad:
        if not explicit:
            return None
        k, a, b = bad[0]
        raise ScenarioError(sc.source, "fdi.thresholds", f"the thresholds file {path} does not match this bank: its "
                            f"{k} is {a}, the bank's is {b} (the file holds thresholds of study {t.study}'s bank, "
                            f"designed at h {t.design_h_ft:g} ft, vc {t.design_vc_kts:g} kt, {t.design_turbulence} "
                            "turbulence)", 'use thresholds = "trained" (the bank\'s own training flights), set [fdi.design] '
                            f"to the file's design (e.g. design = {{ point = \"grid\", turbulence = \"{t.design_turbulence}\" }} "
                            "at a point of that node), or calibrate a study at this bank's design with "
                            "`fdi-sim study STUDY --calibrate OUT.toml`")
    rec = {"source": "study", "file": str(path), "study": t.study, "study_identity": t.study_identity,
           "runs": t.runs, "flight_h": t.flight_h, "design_hash": t.design_hash, "far_per_h": t.far_per_h,
           "matched_by": matched, "members": []}
    for mem, m in zip(bank.members, t.members):
        mem.set_threshold(float(m.threshold))
        rec["members"].append({"id": m.id, "threshold": m.threshold, "method": t.member_method(m.id),
                               "trained_threshold": m.trained_threshold})
    bank.calibration = rec
    bank.keep_trace(False)
    bank.reset()
    return rec["members"][0]["method"] if rec["members"] else ""


def design_scenario(sc: Scenario) -> Scenario:
    """The scenario the bank is designed and calibrated on: ``sc`` itself unless ``[fdi.design]``
    moves the point to the schedule grid's nearest node or sets the training flights' turbulence,
    wind or sensor noise.

    The grid is the aircraft's (:data:`fdi_sim.sim.designs.DEFAULT_SPACING`): nodes at whole
    multiples of the spacing in altitude [ft] and calibrated airspeed [kt], so runs of a study
    that sample the point continuously share one design per node (the gain scheduling of a real
    bank), and each node is designed and calibrated once (cached).
    """
    from fdi_sim.scenario.loader import from_dict
    from fdi_sim.sim.designs import default_spacing, initial_vc_kts

    d = sc.model.fdi.design
    if d.point == "flight" and all(v is None for v in (d.turbulence, d.wind_speed_kts, d.wind_from_deg, d.noise_scale)):
        return sc
    data = json.loads(sc.to_json())
    what = []
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
    data["fdi"] = {**data["fdi"], "design": {}}
    data.update(name=f"{sc.aircraft}_design", description="", seed=0, faults=[])
    return from_dict(data, source=f"{sc.source} (bank design at {', '.join(what)})")


class LazyTraining:
    """The scenario's fault-free training flights, flown on first use (then kept)."""

    def __init__(self, sc: Scenario, progress: bool) -> None:
        self.sc, self.progress = sc, progress
        self.n = sc.model.fdi.calibration_flights
        self._logs: list[Any] | None = None

    def __len__(self) -> int:
        return self.n

    def __iter__(self):
        if self._logs is None:
            from fdi_sim.sim.calibrate import fly_training, training_seeds

            f = self.sc.model.fdi
            self._logs = fly_training(self.sc, training_seeds(self.n), f.calibration_duration_s,
                                      progress=self.progress)
        return iter(self._logs)


@dataclass
class MemberContext:
    """What designing one member of a scenario's bank may use.

    Attributes
    ----------
    sc : Scenario
        The design scenario (:func:`design_scenario`).
    cmd_names, meas_names : tuple of str
        The commands and measurements the loop logs (a member reads a subset).
    progress : bool
        Show progress bars (training flights, schedule designs).
    training_logs : sequence
        The fault-free training flights (lazy: flown on first use).
    """

    sc: Scenario
    cmd_names: tuple[str, ...]
    meas_names: tuple[str, ...]
    progress: bool
    training_logs: Any
    _lm: Any = None

    def log_model(self) -> Any:
        """The scenario's initial point trimmed and linearized (:func:`fdi_sim.sim.detect.model_for_scenario`),
        made once: ``.model`` at the bank's rate in the samples' form, ``.continuous()``."""
        if self._lm is None:
            from fdi_sim.sim.detect import model_for_scenario

            self._lm = model_for_scenario(self.sc, self.sc.model.fdi.rate_hz)
        return self._lm

    def model(self) -> Any:
        """The linear model at the scenario's initial point, at the bank's rate, in the samples' form."""
        return self.log_model().model


def member_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """One member's :class:`~fdi_sim.detectors.stream.StreamingDetector` and a note for the log.

    How a detector is *designed* differs by family; how it *runs* does not. The gust filter is
    gain-scheduled over the flight's points and calibrated on training flights
    (:func:`_gust_stream`); the kinematic checks take the aircraft and turbulence
    (:func:`_kinematic_stream`); every other detector, built in or a plugin, is built by its
    registered factory from the linear model at the initial point (:func:`_model_stream`).
    """
    builder = _DESIGNERS.get(m.id, _model_stream)
    return builder(ctx, m)


def _continuous_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """A detector designed on the continuous linearization, run at the bank's rate (lmi-detection-v1:
    its LMI is a continuous-time design; the detector card designs it the same way)."""
    return _model_stream(ctx, m, design_model=ctx.log_model().continuous(),
                         extra={"dt_s": 1.0 / float(ctx.sc.model.fdi.rate_hz)})


def _pca_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """pca-v1: its residual space is learned from data, the first fault-free training flight (the
    same flights the thresholds are set on; the detector card trains it the same way)."""
    from fdi_sim.detectors.samples import log_samples

    model = ctx.model()
    first = next(iter(ctx.training_logs))
    s = log_samples(first, model, float(ctx.sc.model.fdi.rate_hz))
    cols = [list(model.input_names).index(nm) for nm in s.input_names]
    u_abs = s.du + np.asarray(model.u0, dtype=float)[cols]
    return _model_stream(ctx, m, extra={"train_u": u_abs, "train_y": s.dy + s.y0})


def _model_stream(ctx: MemberContext, m: MemberSpec, *, design_model: Any = None,
                  extra: dict[str, Any] | None = None) -> tuple[Any, str]:
    """A detector designed by its registry factory from the initial point's model. A factory that
    returns a :class:`~fdi_sim.detectors.stream.StreamingDetector` (a plugin's) runs as it is; a
    per-sample detector runs through its compiled stream where one exists
    (:func:`fdi_sim.detectors.seed_streams.compiled_stream`), else through
    :class:`~fdi_sim.detectors.step_stream.StepStream`."""
    from fdi_sim.detectors.step_stream import StepStream
    from fdi_sim.detectors.stream import StreamingDetector
    from fdi_sim.sim.detect import DetectorSpec, build_detector

    sc = ctx.sc
    params = {k: v for k, v in m.params.items() if k not in ENTRY_KEYS}
    model = ctx.model()
    where = f"h {sc.model.initial.h_ft:g} ft"
    try:
        det = build_detector(DetectorSpec(m.id, {**(extra or {}), **params}),
                             model if design_model is None else design_model)
    except DesignError as exc:
        raise DesignError(f"{sc.source}: {m.id} cannot be designed at the initial point ({where}): {exc}") from None
    if isinstance(det, StreamingDetector):
        stream, how = det, "its own stream"
    else:
        stream = None
        try:
            from fdi_sim.detectors.seed_streams import compiled_stream
        except ImportError:  # pragma: no cover - a partial install
            compiled_stream = None
        if compiled_stream is not None:
            stream = compiled_stream(det, model, ctx.cmd_names, m.id)
        how = "compiled stream"
        if stream is None:
            stream, how = StepStream(det, model, ctx.cmd_names, params, id=m.id), "per-sample step (Python)"
    if str(getattr(stream, "id", "")) != m.id:
        raise DesignError(f"{m.id}: the factory returned a detector whose id is {getattr(stream, 'id', None)!r}; a "
                          "member's id is its registered id")
    origin = registry.get("detector", m.id).origin
    if origin != "fdi-sim":  # a plugin: checked before it flies (the built-ins are checked by the suite)
        from fdi_sim.detectors.check import CORRECTNESS, check_stream, contract_inputs

        fails = check_stream(stream, contract_inputs(stream, model, rate_hz=sc.model.fdi.rate_hz))
        wrong = [f for f in fails if f.check in CORRECTNESS]
        if wrong:
            raise DesignError(f"{sc.source}: plugin detector {m.id} ({origin}) fails its contract check: "
                              + "; ".join(str(f) for f in wrong))
        how = f"plugin from {origin}" + "".join(f"; {f}" for f in fails)
    return stream, f"{m.id}: one design at the initial point ({where}), {how}"


def _gust_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """kalman-gust-v1: gain-scheduled over the flight's points, ``Sigma_m`` from training flights."""
    sc, progress, training_logs = ctx.sc, ctx.progress, ctx.training_logs
    from fdi_sim.detectors.gust_kalman_stream import GustKalmanStream
    from fdi_sim.detectors.scheduled import GustKalmanSchedule
    from fdi_sim.sim.calibrate import calibrated_gust_kalman
    from fdi_sim.sim.detect import CALIBRATION_OPTIONS, model_for_scenario

    f = sc.model.fdi
    # the bank sets the threshold itself (calibrate_thresholds); of the filter's own calibration it
    # uses Sigma_m only, so its quantile target just has to be one the flights can give
    n_samples = f.calibration_flights * max(1.0, f.calibration_duration_s - 5.0) * f.rate_hz
    cal_opts = {"n_flights": f.calibration_flights, "duration_s": f.calibration_duration_s,
                "target": max(1e-4, 20.0 / n_samples)}
    cal_opts.update({k: v for k, v in m.params.items() if k in CALIBRATION_OPTIONS})
    design_opts = {k: v for k, v in m.params.items() if k not in CALIBRATION_OPTIONS + ("rate_hz", "min_cosine")}
    min_cos = float(m.params.get("min_cosine", 0.7))
    from fdi_sim.sim.designs import design_schedule, schedule_points

    memo_key = None
    if DESIGN_MEMO is not None:  # a study worker: the same design for many runs, made once per process
        from fdi_sim.sim.calibrate import cache_dir

        d = json.loads(sc.to_json())
        for k in ("seed", "name", "description", "faults"):  # the design sees no faults
            d.pop(k, None)
        memo_key = hashlib.sha256(json.dumps([d, m.id, sorted(m.params.items()), str(cache_dir())], sort_keys=True,
                                             default=str).encode()).hexdigest()
        if memo_key in DESIGN_MEMO:
            sched, note = DESIGN_MEMO[memo_key]
            return GustKalmanStream(sched, min_cosine=min_cos, id=m.id), note
    points = schedule_points(sc) if f.schedule == "auto" else []
    if len(points) > 1:
        sched = design_schedule(sc, points, rate_hz=f.rate_hz, params=design_opts, on_failure=f.on_design_failure,
                                progress=progress, **cal_opts)
        note = f"{m.id}: gain-scheduled over {sched.n_points} points ({'; '.join(sched.label(i) for i in range(sched.n_points))})"
    else:
        try:
            lm = model_for_scenario(sc, f.rate_hz)
            det = calibrated_gust_kalman(sc, lm.continuous(), rate_hz=f.rate_hz, params=design_opts, progress=progress,
                                         training_logs=training_logs, **cal_opts)
        except DesignError as exc:
            raise DesignError(f"{sc.source}: {m.id} cannot be designed at the initial point "
                              f"(h {sc.model.initial.h_ft:g} ft): {exc}") from None
        sched = GustKalmanSchedule.single(det.design, det.calibration)
        note = f"{m.id}: one design at the initial point ({sched.label(0)})"
    if memo_key is not None:
        DESIGN_MEMO[memo_key] = (sched, note)  # the stream copies what it needs: the schedule is not changed
    return GustKalmanStream(sched, min_cosine=min_cos, id=m.id), note


def _kinematic_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """A kinematic check: its catalogue design for the aircraft and the turbulence level."""
    sc = ctx.sc
    from fdi_sim.detectors.kinematic_stream import KinematicStream
    from fdi_sim.sim.detect import DetectorSpec, build_detector

    params = {"turbulence": sc.model.atmosphere.turbulence, "aircraft": sc.aircraft,
              **{k: v for k, v in m.params.items() if k not in ENTRY_KEYS}}
    det = build_detector(DetectorSpec(m.id, params), None)
    return KinematicStream(det), f"{m.id}: {det.design.kind} check ({sc.model.atmosphere.turbulence} turbulence)"


#: how each detector family is designed for a bank (:func:`member_stream`); every other id: its factory
_DESIGNERS: dict[str, Callable[[MemberContext, MemberSpec], tuple[Any, str]]] = {
    "kalman-gust-v1": _gust_stream,
    "lmi-detection-v1": _continuous_stream,
    "pca-v1": _pca_stream,
    **{f"kinematic-{k}-v1": _kinematic_stream for k in ("attitude", "altitude", "airspeed", "flow-angles")},
}


# --- thresholds from the training flights ---------------------------------------------------------
def _cache_path(key: str) -> Path:
    from fdi_sim.sim.calibrate import cache_dir

    return cache_dir() / f"bank-{key}.json"


def _thresholds_key(sc: Scenario, bank: Any, p: float) -> str:
    from fdi_sim.detectors.stream import stream_design_key
    from fdi_sim.sim.calibrate import fault_free

    f = sc.model.fdi
    ff = json.loads(fault_free(sc, 0, f.calibration_duration_s).to_json())
    ff.pop("name", None)
    ff.pop("description", None)
    ff.pop("fdi", None)
    h = hashlib.sha256()
    for mem in bank.members:
        h.update(mem.id.encode())
        h.update(stream_design_key(mem.stream))
    blob = json.dumps({"scenario": ff, "p": p, "arm_s": f.arm_s, "confidence": THRESHOLD_CONFIDENCE, "n": f.calibration_flights, "T": f.calibration_duration_s,
                       "decision": [f.persistence_k, f.persistence_n], "method": "episodes-v5", "version": __version__, "members": h.hexdigest()},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def calibrate_thresholds(sc: Scenario, bank: Any, p: float, *, training_logs: Sequence[Any] | None = None,
                         progress: bool = True, use_cache: bool = True) -> dict[str, Any]:
    """Set each member's threshold from its statistic on the fault-free training flights (the same
    flights the filters were calibrated on): the level of ``far_per_h / members`` alarm episodes per
    flight hour under the bank's k-of-n rule (module docstring); for the angle-magnitude rule, and
    where the flights hold too few episodes to fit, the ``1 - p`` per-sample quantile.

    Returns the record stored in the cache (thresholds, method, training samples per member).
    """
    from fdi_sim.decision.tail import confident_episode_threshold, confident_tail_threshold, persistence_series
    from fdi_sim.sim.calibrate import cache_lock, fly_training, read_entry, training_seeds, write_entry

    f = sc.model.fdi
    key = _thresholds_key(sc, bank, p)
    path = _cache_path(key)
    with cache_lock(path, use_cache):  # another process computing this entry: wait, then read it
        rec = read_entry(path, use_cache)
        try:
            if rec is not None and [r["id"] for r in rec["members"]] != [m.id for m in bank.members]:
                rec = None
        except (KeyError, TypeError):
            rec = None  # a damaged entry is recomputed
        if rec is None:
            logs = training_logs
            if logs is None:
                logs = fly_training(sc, training_seeds(f.calibration_flights), f.calibration_duration_s, progress=progress)
            logs = list(logs)
            d = bank.decision
            episodes = d.rule == "persistence"  # the angle rule's exceedance also needs a direction
            stats: list[list[np.ndarray]] = [[] for _ in bank.members]
            series: list[list[np.ndarray]] = [[] for _ in bank.members]
            hours: list[list[float]] = [[] for _ in bank.members]
            for lg in logs:
                _replay_log(bank, lg, raw_thresholds=True)
                for i, mem in enumerate(bank.members):
                    st, ok = mem.trace_series()
                    stats[i].append(st[ok])
                    if episodes:
                        series[i].append(persistence_series(st, ok, d.k, d.n))
                        hours[i].append(float(ok.sum()) / (float(f.rate_hz) * S_PER_H))
            rate = float(f.far_per_h) / max(1, len(bank.members))
            rec = {"p_per_sample": p, "episodes_per_h": rate if episodes else None,
                   "confidence": THRESHOLD_CONFIDENCE, "members": []}
            rng = np.random.default_rng(0)  # the bootstrap's resampling: fixed, so a calibration is reproducible
            for i, (mem, s) in enumerate(zip(bank.members, stats)):
                s = [x[np.isfinite(x)] for x in s]
                x = np.concatenate(s)
                if x.size < 2:
                    raise DesignError(f"{sc.source}: {mem.id} gave {x.size} valid statistic samples on its "
                                      f"{len(logs)} fault-free training flights (armed from {f.arm_s:g} s): no "
                                      "threshold can be set; its design does not settle on this aircraft")
                if episodes:
                    try:
                        thr, method = confident_episode_threshold(series[i], rate, hours[i], rng,
                                                                  level=THRESHOLD_CONFIDENCE)
                    except DesignError as e:  # short training flights: too few episodes to fit
                        thr, method = confident_tail_threshold(s, p, rng, level=THRESHOLD_CONFIDENCE)
                        method = f"per-sample ({e}): {method}"
                else:
                    thr, method = confident_tail_threshold(s, p, rng, level=THRESHOLD_CONFIDENCE)
                rec["members"].append({"id": mem.id, "threshold": thr, "method": method, "samples": int(x.size),
                                       "max_training": float(x.max()) if x.size else None})
            write_entry(path, rec, use_cache)
    for mem, r in zip(bank.members, rec["members"]):
        mem.set_threshold(float(r["threshold"]))
    bank.calibration = rec
    bank.keep_trace(False)  # the replays kept every block; a flight must not
    bank.reset()
    return rec


def _replay_log(bank: Any, log: Any, *, raw_thresholds: bool = False) -> None:
    """Run the bank over a log's rows (trace kept per member)."""
    from fdi_sim.flightlog import TOPIC_COMMANDS, TOPIC_SENSORS, TOPIC_SENSORS_VALID

    cmd = log.topics[TOPIC_COMMANDS]
    meas = log.topics[TOPIC_SENSORS]
    K = min(len(cmd.t_s), len(meas.t_s))
    u = np.column_stack([cmd[nm][:K] for nm in bank.cmd_names])
    y = np.column_stack([meas[nm][:K] for nm in bank.meas_names])
    valid = None
    if TOPIC_SENSORS_VALID in log.topics:
        vt = log.topics[TOPIC_SENSORS_VALID]
        valid = np.column_stack([vt[nm][:K] > 0.5 if nm in vt.fields else np.ones(K, bool) for nm in bank.meas_names])
    bank.reset()
    bank.keep_trace(True)
    if raw_thresholds:
        for mem in bank.members:
            mem.set_threshold(np.inf)
    dt = float(np.median(np.diff(np.asarray(meas.t_s[:K]))))
    bank.replay(u, y, valid, dt, t_rows_s=np.asarray(meas.t_s[:K], dtype=float))


def bank_for_log(log: Any, *, progress: bool = False, bank: str | None = None) -> Any:
    """The bank a log's scenario flew with (or, with ``bank="default"``, the default bank for that
    scenario), rebuilt: designs and thresholds from the cache, or computed the same way, with the
    log's measurement and command columns.

    Raises
    ------
    LogError
        The log has no scenario metadata, or its scenario has no bank.
    """
    from fdi_sim.errors import LogError
    from fdi_sim.flightlog import METADATA_SCENARIO, TOPIC_COMMANDS, TOPIC_SENSORS
    from fdi_sim.scenario.loader import from_dict

    meta = log.metadata.get(METADATA_SCENARIO)
    if not meta or "json" not in meta:
        raise LogError(str(log.path), "no 'scenario' metadata record: not a log written by `fdi-sim run`")
    data = json.loads(meta["json"])
    if bank is not None:
        data["fdi"] = {**data.get("fdi", {}), "bank": bank}
    sc = from_dict(data, source=f"{log.path} (scenario metadata)")
    if not bank_members(sc):
        raise LogError(str(log.path), "its scenario has no FDI bank ([fdi] bank or [[detectors]]); give --detector "
                       "or --bank default instead")
    for topic in (TOPIC_COMMANDS, TOPIC_SENSORS):
        if topic not in log.topics:
            raise LogError(str(log.path), f"no {topic} topic (a run logged with [log] per_step = false cannot be "
                           "replayed: its FDI topics are the record)")
    meas_names = tuple(f for f in log.topics[TOPIC_SENSORS].fields if f != "t_s")
    cmd_names = tuple(f for f in log.topics[TOPIC_COMMANDS].fields if f != "t_s")
    from fdi_sim.sim.run import build_sensors

    suite = build_sensors(sc, sc.dt_s).specs  # the scenario's overrides too (a rate changes the freshness)
    return build_bank(sc, meas_names=meas_names, cmd_names=cmd_names,
                      sensor_rates_hz={s.name: s.rate_hz for s in suite}, pilot_sensors=meas_names, progress=progress)


def replay_log(log: Any, bank: Any | None = None) -> dict[str, dict[str, np.ndarray]]:
    """Replay a log through its scenario's bank: per member id, the per-sample arrays
    (:data:`fdi_sim.sim.bank.TRACE_FIELDS` and ``t_s``). For a log flown with the bank these equal
    its ``/fdi/<id>/statistic`` topics bit for bit (the kernels do not depend on the blocking)."""
    bank = bank if bank is not None else bank_for_log(log)
    _replay_log(bank, log)
    out = bank.trace()
    n = bank.n
    t_rows = np.asarray(log.topics["/sensors/measurements"].t_s, dtype=float)
    t = t_rows[n * np.arange(1, bank.samples_done + 1)]
    for v in out.values():
        v["t_s"] = t
    return out

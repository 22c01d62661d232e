"""The fault injector: every fault of a run, bound to the aircraft and the sensor suite.

Per simulation step at time ``t_s`` the loop calls, in order:

1. :meth:`FaultInjector.begin_step` -- the level of every fault's profile at ``t_s`` (onsets
   and clears become events);
2. :meth:`FaultInjector.sensors` -- sensor faults turn the healthy measurement into the one the
   pilot and the detectors see;
3. :meth:`FaultInjector.commands` -- throttle faults and DHC-6 power losses act on the commands;
4. :meth:`FaultInjector.plant` -- surface faults hold the surfaces (WRITE-attribute trick, one
   frame behind the healthy actuator), engines flame out or lose thrust, icing sets eta;

then JSBSim steps. :meth:`FaultInjector.truth_row` gives the ground truth of the step for the
log: per fault ``<label>_active`` (0/1), ``<label>_level`` (profile level 0..1) and
``<label>_error`` (faulty minus healthy value of the corrupted signal, native unit: rad for a
surface, normalized for the throttle, the sensor's unit, thrust fraction lost for an engine,
eta for icing).

Sensor faults act at the sensor's own sample instants and hold between them, like the suite. A
dropout holds the last output and clears the sensor's flag in :attr:`FaultInjector.valid`: that
is how detectors see it (stale value plus a validity bit, as on an ARINC 429 / ARINC 664 bus).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from fdi_sim.faults.laws import actuator_value
from fdi_sim.faults.params import FaultParams
from fdi_sim.faults.profile import Profile, make_profile, ramp_level
from fdi_sim.faults.quantities import target_unit, to_native

#: fastest throttle-lever travel assumed for a hard-over [1/s] (full travel in 0.5 s)
THROTTLE_RATE_NORMPS = 2.0
#: surface -> (local flow angle it floats with, sign of delta_float = sign r angle) (laws.py docstring)
FLOAT_FLOW: dict[str, tuple[str, float]] = {"elevator": ("alpha_rad", -1.0), "rudder": ("beta_rad", 1.0)}


def _blend_clip(v: float, healthy: float, level: float, c: dict) -> float:
    """Ramp-in blend with the healthy value (exactly ``v`` at full level), clipped to the stops."""
    if level < 1.0:
        v = healthy + level * (v - healthy)
    return min(max(v, c["lo"]), c["hi"])


@dataclass(frozen=True)
class FaultDef:
    """A fault as declared in a scenario, not yet bound to a run.

    Attributes
    ----------
    type_id : str
        Registered id (``"actuator-stuck-v1"``).
    family : str
        ``"actuator"``, ``"engine"``, ``"sensor"`` or ``"airframe"``.
    law : str
        The law within the family (``"stuck"``, ``"bias"``, ...).
    params : FaultParams
    """

    type_id: str
    family: str
    law: str
    params: FaultParams

    @property
    def target(self) -> str:
        return self.params.target


def default_labels(defs: Sequence[FaultDef]) -> list[str]:
    """``label`` if given, else ``<target>_<law>``; repeats get ``_2``, ``_3`` ..."""
    out: list[str] = []
    for d in defs:
        base = d.params.label or f"{d.target}_{d.law}".replace("-", "_").lower()
        name, n = base, 2
        while name in out:
            name, n = f"{base}_{n}", n + 1
        out.append(name)
    return out


class _Bound:
    """One fault bound to a run: its profile, level and the state of its law."""

    def __init__(self, d: FaultDef, label: str) -> None:
        self.d = d
        self.label = label
        self.law = d.law
        self.profile = Profile(())
        self.level = 0.0
        self.active = False  # inside an on-window (the level may still be 0 at the first step of a ramp)
        self.onset = False  # a window starts at this step
        self.cleared = False  # a window ended at this step
        self.error = 0.0
        self.t_on = 0.0
        self._i = 0
        # level and activity stay as they are (and no onset or clear comes) while t_s < steady_until_s [s]
        self.steady_until_s = -math.inf
        self.c: dict[str, Any] = {}  # the law's constants and state, native units (set by the injector)
        self.rng = np.random.default_rng(0)

    def reset_profile(self, duration_s: float, rng: np.random.Generator) -> None:
        self.profile = make_profile(self.d.params, duration_s, rng)
        self.level, self.error, self.t_on, self._i = 0.0, 0.0, 0.0, 0
        self.active = self.onset = self.cleared = False
        self.steady_until_s = -math.inf

    def update(self, t_s: float) -> None:
        """Level, activity and onset/clear flags at ``t_s`` [s] (windows walked incrementally, time
        never going back), and until when they stay so (:attr:`steady_until_s`)."""
        w = self.profile.windows
        was = self.active
        while self._i < len(w) and t_s >= w[self._i][1]:
            self._i += 1
        self.active = self._i < len(w) and t_s >= w[self._i][0]
        self.level = 0.0
        if self.active:
            a = w[self._i][0]
            self.level = ramp_level(t_s - a, self.profile.ramp_s)
            if not was:
                self.t_on = a
        self.onset = self.active and not was
        self.cleared = was and not self.active
        if self.onset or self.cleared or (self.active and self.level < 1.0):  # the flags drop / the ramp moves next step
            self.steady_until_s = -math.inf
        elif self.active:  # at full level until the window ends
            self.steady_until_s = w[self._i][1]
        else:  # off until the next window starts
            self.steady_until_s = w[self._i][0] if self._i < len(w) else math.inf


class FaultInjector:
    """All faults of one run (``reset`` then, per step, ``begin_step``/``sensors``/``commands``/``plant``).

    Parameters
    ----------
    defs : sequence of FaultDef
        Validated against the aircraft and suite by :func:`fdi_sim.faults.check.check_faults`.
    aircraft : fdi_sim.aircraft.Aircraft
        Loaded with ``icing=True`` if there is an icing fault.
    sensor_names : sequence of str
        Order of the measurement vector.
    sensor_rates_hz : sequence of float
        Sample rate of each sensor [Hz].
    truth_names : sequence of str
        Order of the truth vector.
    dt_s, duration_s : float
    """

    def __init__(self, defs: Sequence[FaultDef], aircraft: Any, sensor_names: Sequence[str],
                 sensor_rates_hz: Sequence[float], truth_names: Sequence[str], dt_s: float, duration_s: float) -> None:
        self.dt_s = float(dt_s)
        self.duration_s = float(duration_s)
        self.labels = default_labels(defs)
        self.faults = [_Bound(d, lab) for d, lab in zip(defs, self.labels)]
        self.sensor_names = tuple(sensor_names)
        self._decim = [max(1, int(round(1.0 / (r * dt_s)))) for r in sensor_rates_hz]
        self._truth_idx = {n: i for i, n in enumerate(truth_names)}
        self.valid = np.ones(len(sensor_names))
        self.has_dropout = any(d.law == "dropout" for d in defs)
        self._row = [0.0] * (3 * len(self.faults))
        self.events: list[tuple[float, dict]] = []
        self._throttle = 0.0  # the (faulty) throttle command of the step, for after_commands
        # the faults each per-step method acts on, in scenario order (bound once: no per-step dispatch by family)
        self._sensor: list[_Bound] = []
        self._throttle_faults: list[_Bound] = []  # actuator faults on the throttle (commands)
        self._power_loss: list[_Bound] = []  # propeller thrust losses: the engine's lever (after_commands)
        self._surface: list[_Bound] = []  # surface faults (plant)
        self._flameout: list[_Bound] = []  # (plant)
        self._thrust_loss: list[_Bound] = []  # jet thrust losses: the thrust multiplier (plant)
        self._icing: list[_Bound] = []  # (plant)
        for f in self.faults:
            self._bind(f, aircraft)

    # ------------------------------------------------------------------ binding
    def _bind(self, f: _Bound, ac: Any) -> None:
        d, p = f.d, f.d.params
        c: dict[str, Any] = {}
        if d.family == "sensor":
            j = self.sensor_names.index(d.target)
            native = target_unit(d.family, d.target)
            c.update(j=j, d=self._decim[j], ti=self._truth_idx[d.target])
            for key, rate in (("bias", False), ("drift", True), ("value", False), ("noise_std", False), ("size", False)):
                m = p.magnitude(key)
                c[key] = to_native(m[0], m[1], native, rate) if m else None
            c.update(scale=getattr(p, "scale", 1.0), delay_steps=int(round(getattr(p, "delay_s", 0.0) / self.dt_s)),
                     p_spike=getattr(p, "rate_hz", 0.0) * c["d"] * self.dt_s)  # outlier probability per sample instant
            self._sensor.append(f)
        elif d.family == "actuator":
            self._bind_actuator(f, ac, c)
        elif d.family == "engine":
            i = int(d.target.rsplit("_", 1)[1])
            c["loss"] = getattr(p, "loss", 1.0)
            if d.law == "flameout":
                c["cut"] = lambda on, i=i: ac.set_engine_cutoff(i, on)
                self._flameout.append(f)
            else:
                scaler = ac.thrust_scaler(i)
                if scaler is not None:  # exact thrust multiplier (jet)
                    c["scale"] = scaler
                    self._thrust_loss.append(f)
                else:  # propeller: the engine's power lever is scaled
                    c["throttle"] = ac.node(f"fcs/throttle-cmd-norm[{i}]").set_double_value
                    self._power_loss.append(f)
        elif d.family == "airframe":
            from fdi_sim.aircraft import icing

            ac.set_icing_k(icing.k_values(ac.name, p.region))
            c["set_eta"] = ac.icing_writer()
            c["eta_final"] = p.eta_final
            self._icing.append(f)
        else:
            raise ValueError(f"unknown fault family {d.family!r}")
        f.c = c

    def _bind_actuator(self, f: _Bound, ac: Any, c: dict) -> None:
        d, p = f.d, f.d.params
        native = target_unit(d.family, d.target)
        c["flow_i"], c["float_sign"] = None, 0.0
        if d.target == "throttle":
            lo, hi, fastest = 0.0, 1.0, THROTTLE_RATE_NORMPS
            self._throttle_faults.append(f)
        else:
            h = ac.surface(d.target)
            spec = h.spec
            lo, hi = math.radians(spec.min_deg), math.radians(spec.max_deg)
            fastest = math.radians(spec.rate_degps)
            c["handle"] = h
            if d.target in FLOAT_FLOW:  # the local flow angle a released surface trails with (laws.py)
                signal, c["float_sign"] = FLOAT_FLOW[d.target]
                c["flow_i"] = self._truth_idx[signal]
            self._surface.append(f)
        c.update(lo=lo, hi=hi)
        for key in ("position", "bias", "amplitude"):
            m = p.magnitude(key)
            c[key] = to_native(m[0], m[1], native) if m else None
        m = p.magnitude("rate")
        rate = to_native(m[0], m[1], native, rate=True) if m else None
        if d.law == "hard-over":
            c["stop"] = hi if p.direction == "max" else lo
            c["rate"] = abs(rate) if rate is not None else fastest
        elif d.law == "runaway":
            c["stop"] = hi if rate > 0 else lo
            c["rate"] = abs(rate)
        elif d.law == "rate-limit":
            c["rate"] = abs(rate)
        c.update(effectiveness=getattr(p, "effectiveness", 1.0), frequency_hz=getattr(p, "frequency_hz", 0.0),
                 float_ratio=getattr(p, "float_ratio", 0.0), tau_s=getattr(p, "tau_s", 1.0))
        c["p"] = c["p0"] = 0.0  # throttle: last faulty command and onset command

    # ------------------------------------------------------------------ run
    def reset(self, rng: np.random.Generator) -> None:
        """Draw every fault's windows (one child stream per fault, in scenario order) and clear state."""
        for f in self.faults:
            f.reset_profile(self.duration_s, np.random.default_rng(rng.integers(2**63)))
            f.rng = np.random.default_rng(rng.integers(2**63))
            # a delay's healthy outputs of the last delay_steps + 1 steps (the oldest is the output now)
            f.c["buf"] = deque(maxlen=f.c["delay_steps"] + 1) if f.law == "delay" else None
        self.valid[:] = 1.0
        self.events = [(0.0, {"event": "catalog", "faults": self.catalog()})]

    def catalog(self) -> list[dict]:
        """Every fault: label, type, target, parameters as written, windows [s]."""
        return [{"label": f.label, "type": f.d.type_id, "target": f.d.target,
                 "params": f.d.params.model_dump(mode="json", exclude_none=True),
                 "windows_s": [list(w) for w in f.profile.windows]} for f in self.faults]

    @property
    def truth_fields(self) -> tuple[str, ...]:
        return tuple(f"{lab}_{s}" for lab in self.labels for s in ("active", "level", "error"))

    def truth_row(self) -> list[float]:
        """``active, level, error`` of every fault now (one list, refilled each step)."""
        out = self._row
        for i, f in enumerate(self.faults):
            out[3 * i], out[3 * i + 1], out[3 * i + 2] = (1.0 if f.active else 0.0), f.level, f.error
        return out

    def begin_step(self, t_s: float) -> None:
        """Every fault's level and onset/clear at ``t_s`` [s]; onsets and clears become events."""
        for f in self.faults:
            if t_s < f.steady_until_s:  # level and activity as in the last step, no onset or clear
                continue
            f.update(t_s)
            if f.onset or f.cleared:
                self.events.append((t_s, {"event": "onset" if f.onset else "clear", "label": f.label,
                                          "type": f.d.type_id, "target": f.d.target}))

    def sensors(self, t_s: float, k: int, y: Any, x: Any) -> Any:
        """Faulty measurements from the healthy ones ``y`` and the truth ``x`` (arrays or lists of floats).

        ``y`` is changed in place (the suite returns a new array or list every step) and returned.
        """
        for f in self._sensor:
            c = f.c
            j = c["j"]
            yh = float(y[j])
            buf = c["buf"]
            if buf is not None:  # a delay: remember every healthy output
                buf.append(yh)
            if f.cleared and f.law == "dropout":
                self.valid[j] = 1.0
            if not f.active:
                f.error = 0.0
                c["last"] = yh
                continue
            if f.onset or k % c["d"] == 0:
                c["out"] = self._sensor_value(f, t_s, yh, x, f.onset)
            y[j] = c["out"]
            f.error = c["out"] - yh
            c["last"] = c["out"]
        return y

    def _sensor_value(self, f: _Bound, t_s: float, yh: float, x: Any, onset: bool) -> float:
        c, w, law = f.c, f.level, f.law
        if law == "bias":
            return yh + w * c["bias"]
        if law == "drift":
            return yh + w * c["drift"] * (t_s - f.t_on)
        if law == "stuck":
            if onset:
                c["held"] = c["value"] if c["value"] is not None else yh
            return c["held"] + (1.0 - w) * (yh - c["held"])
        if law == "noise":
            return yh + w * c["noise_std"] * f.rng.standard_normal()
        if law == "scale":
            return yh + w * (c["scale"] - 1.0) * float(x[c["ti"]])
        if law == "dropout":
            if onset:
                c["held"] = c.get("last", yh)
            self.valid[c["j"]] = 0.0
            return c["held"]
        if law == "delay":
            return c["buf"][0]
        if law == "outlier":
            if f.rng.random() < c["p_spike"]:
                return yh + w * c["size"] * (1.0 if f.rng.random() < 0.5 else -1.0)
            return yh
        raise ValueError(f"unknown sensor law {law!r}")

    def commands(self, t_s: float, el: float, ai: float, ru: float, th: float) -> tuple[float, float, float, float]:
        """Faulty commands (throttle faults); DHC-6 power losses write the engine's lever directly.

        Call after the pilot and before the command writer; :meth:`after_commands` after it.
        """
        for f in self._throttle_faults:
            c = f.c
            if not f.active:
                f.error = 0.0
                c["p"] = th
                continue
            if f.onset:
                c["p0"] = c["p"]
            v = _blend_clip(actuator_value(f.law, c, t_s, f.t_on, th, c["p"], c["p0"], self.dt_s, 0.0), th, f.level, c)
            f.error = v - th
            c["p"] = v
            th = v
        self._throttle = th
        return el, ai, ru, th

    def after_commands(self) -> None:
        """Scale the power lever of engines with a power loss (after the command writer)."""
        for f in self._power_loss:
            c, w = f.c, f.level
            c["throttle"](self._throttle * (1.0 - w * c["loss"]))
            f.error = w * c["loss"]

    def plant(self, t_s: float, x: Any) -> None:
        """Surfaces, engines and icing for the coming JSBSim step (``x``: truth, array or list of floats)."""
        for f in self._surface:
            c = f.c
            h = c["handle"]
            if not f.active:
                if h.held:
                    h.release()
                f.error = 0.0
                continue
            healthy, p = h.healthy(), h.position()
            if f.onset:
                c["p0"] = p
            flow = float(x[c["flow_i"]]) if c["flow_i"] is not None else 0.0
            v = _blend_clip(actuator_value(f.law, c, t_s, f.t_on, healthy, p, c["p0"], self.dt_s, flow), healthy, f.level, c)
            h.hold(v)
            f.error = v - healthy
        for f in self._flameout:
            if f.onset:
                f.c["cut"](True)
            elif f.cleared:
                f.c["cut"](False)
            f.error = 1.0 if f.active else 0.0
        for f in self._thrust_loss:
            c = f.c
            c["scale"](1.0 - f.level * c["loss"])
            f.error = f.level * c["loss"]
        for f in self._icing:
            eta = f.level * f.c["eta_final"]
            if eta != f.error or f.onset or f.cleared:
                f.c["set_eta"](eta)
            f.error = eta

    def initial_icing_eta(self) -> float:
        """Icing severity at t = 0 (for the trim), after :meth:`reset`."""
        return sum(f.c["eta_final"] * f.profile.level(0.0) for f in self._icing)

    @property
    def icing_eta(self) -> float:
        """Current icing severity (0 without an icing fault; faults on one target do not overlap)."""
        for f in self._icing:
            if f.active:
                return f.error
        return 0.0

    def pop_events(self) -> list[tuple[float, dict]]:
        ev, self.events = self.events, []
        return ev

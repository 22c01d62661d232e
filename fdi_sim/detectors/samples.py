"""From a flight log (or arrays) to detector samples: the one time convention, applied once.

Time convention (measured; DESIGN.md "Time convention")
--------------------------------------------------------
Row ``k`` of a log, at ``t_k = k dt``, holds the measurement ``y(t_k)``, taken *before* JSBSim's
step ``k``, and the command ``u_k`` written before that step, which acts *during* it. ``u_k``
first shows in ``y(t_{k+1})``. The linear models are validated the same way (``fdi_sim.linear``:
y read after the JSBSim run that used u), so a detector at the simulation rate pairs

    sample k = (u_{k-1}, y_k).

At a detector rate ``R = f_sim / n`` (``n`` a whole number), detector sample ``j`` covers the
simulation steps ``(j-1) n .. j n - 1``:

    u^det_j = mean(u_{(j-1) n}, ..., u_{j n - 1})      (the command averaged over the interval)
    y^det_j = y_{j n}                                    (the measurement after its last step)

which is exactly what the lifted step model (``fdi_sim.linear.step.lift``) predicts for a
command held over the interval, and its first-order extension when the command moves inside
it. Sample ``j = 0`` has no command before it and is not produced: the first sample is at
``t = n dt``.

Which model form goes with these pairs depends on how the model was discretized. Measured on a
calm-air F-16 doublet flight (open-loop simulation of the linear model from the pairs, rms error
of q [rad/s] and nz [g] over 7 s; ``tests/detectors/test_samples.py``):

==========  =============  ===============  ================
rate [Hz]   step model     ZOH, as is       ZOH, paired
==========  =============  ===============  ================
120         0.0023 0.068   0.0019 0.069     0.0023 0.150
60          0.0024 0.090   0.0023 0.129     0.0023 0.093
40          0.0023 0.057   0.0032 0.164     0.0022 0.055
20          0.0022 0.086   0.0062 0.161     0.0020 0.086
10          0.0021 0.109   0.0129 0.175     0.0019 0.109
==========  =============  ===============  ================

- The step model (``discretize(..., method="step")``, lifted to ``n`` steps) is built on this
  pairing at every rate: ``dy_j = C x_j + D du_j``, ``x_{j+1} = A x_j + B du_j``.
- A ZOH (or Euler) model of the continuous dynamics holds the command *from* ``t_j``. Over an
  interval of ``n >= 2`` steps most of the interval's command acts inside it, so the state
  reaches ``t_j`` through the command of the interval before: ``x_j = A x_{j-1} + B du_j``,
  ``dy_j = C x_j + D du_j``; :func:`paired_model` rewrites that in the standard form with
  ``z_j = x_{j-1}``: ``(A, B, C A, C B + D)``. At the simulation rate itself (``n = 1``) JSBSim's
  one-pass delay (the surface command of row ``k`` reaches the aerodynamics in the next step)
  makes the model as it is the better one, and :func:`paired_model` leaves it.

So every detector keeps the standard form ``x_{j+1} = A x_j + B u_j, y_j = C x_j + D u_j``, is
designed from ``paired_model(model, sim_rate_hz)`` and is fed ``(du_j, dy_j)``.

Measurements keep their own rates: a 40 Hz air-data channel in a 120 Hz log holds its value for
three rows. ``fresh[j, i]`` says whether output ``i`` was sampled at row ``j n`` (it is at
every sample when ``R`` divides every sensor's rate, as at the default 20 Hz; at 120 Hz a held
value is flagged stale, so a filter can skip it instead of treating it as news). ``valid[j, i]``
is False while a dropout fault holds output ``i`` (``/sensors/valid``; a dropout is not a
measurement) and wherever the value is not finite.

Deviations: ``du = u - u0``, ``dy = y - y0`` with the model's trim values; heading and every
other output named ``psi*_rad`` is wrapped to [-pi, pi) after the subtraction (the DHC-6 model's
``psi_rad`` trim is 6.28319 while the log's heading is near 0). Signals are matched by name, so
any model works with any log that has its signals.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

#: topics of the flight log this adaptor reads (names as in ``fdi_sim.flightlog.schemas``)
TOPIC_COMMANDS = "/commands/pilot"
TOPIC_SENSORS = "/sensors/measurements"
TOPIC_SENSORS_VALID = "/sensors/valid"
def is_wrapped(name: str) -> bool:
    """An output that is an angle on a circle (a heading ``psi*_rad``): wrapped after trim subtraction."""
    return name.startswith("psi") and name.endswith("_rad")
#: signals a model may use that the log holds per engine: their mean (the linearizer's engine
#: state is one N1 for both PT6As; a measured input for a model with ``state_as_input``)
DERIVED_MEASUREMENTS: dict[str, tuple[str, ...]] = {"n1_pct": ("n1_0_pct", "n1_1_pct"), "prop_rpm": ("prop_0_rpm", "prop_1_rpm")}


class SampleError(DesignError):
    """A log or array set cannot be turned into detector samples (missing signal, bad rate)."""


@dataclass(frozen=True, eq=False)
class Samples:
    """Detector samples at one rate, paired by the time convention of this module.

    Attributes
    ----------
    t_s : NDArray
        Sample times (N,) [s]: the time of the measurement.
    du : NDArray
        (N, m) command deviations ``u - u0``, averaged over the interval before ``t_s``.
    dy : NDArray
        (N, p) measurement deviations ``y - y0`` at ``t_s`` (angles wrapped).
    valid : NDArray of bool
        (N, p) False where output ``i`` is not a measurement (dropout fault, non-finite).
    fresh : NDArray of bool
        (N, p) True where output ``i`` was sampled at this row (not a held value).
    input_names, output_names : tuple of str
    rate_hz : float
        Detector rate [Hz].
    sim_rate_hz : float
        Rate of the log [Hz].
    rows : NDArray of int
        The log row of each measurement (``j n``).
    u0, y0 : NDArray
        The trim values subtracted.
    """

    t_s: NDArray[np.float64]
    du: NDArray[np.float64]
    dy: NDArray[np.float64]
    valid: NDArray[np.bool_]
    fresh: NDArray[np.bool_]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    rate_hz: float
    sim_rate_hz: float
    rows: NDArray[np.intp]
    u0: NDArray[np.float64]
    y0: NDArray[np.float64]

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.t_s)

    @property
    def dt_s(self) -> float:
        """Detector sample period [s]."""
        return 1.0 / self.rate_hz

    def output(self, name: str) -> NDArray[np.float64]:
        """One output's deviation column by name."""
        return self.dy[:, _index(self.output_names, name, "output")]

    def input(self, name: str) -> NDArray[np.float64]:
        """One input's deviation column by name."""
        return self.du[:, _index(self.input_names, name, "input")]

    def select(self, start: int = 0, stop: int | None = None) -> Samples:
        """The samples ``start:stop`` (a view, same names and trim)."""
        s = slice(start, stop)
        return Samples(self.t_s[s], self.du[s], self.dy[s], self.valid[s], self.fresh[s], self.input_names,
                       self.output_names, self.rate_hz, self.sim_rate_hz, self.rows[s], self.u0, self.y0)


def _index(names: Sequence[str], name: str, what: str) -> int:
    try:
        return list(names).index(name)
    except ValueError:
        raise SampleError(f"no {what} {name!r}; the samples have {', '.join(names)}") from None


#: discretizations whose command is held from the sample time on (need :func:`paired_model`)
HOLD_FROM_SAMPLE = ("zoh", "euler", "foh", "tustin", "bilinear")


def paired_model(model: Any, sim_rate_hz: float) -> Any:
    """The model in the standard form for this module's pairs ``(du_j, dy_j)``.

    Step models (``meta["discretized"] == "step"``), models at the simulation rate and models
    already paired come back as they are. A model discretized with the command held from the
    sample time (ZOH, Euler) over ``n >= 2`` simulation steps becomes ``(A, B, C A, C B + D)`` in
    the state ``z_j = x_{j-1}`` (module docstring, with the measured table). Continuous models are
    refused.

    Parameters
    ----------
    model : LinearModel
        Discrete.
    sim_rate_hz : float
        Rate of the simulation the samples come from [Hz] (``Samples.sim_rate_hz``).

    Returns
    -------
    LinearModel
        ``meta["paired"] = True``.
    """
    from dataclasses import replace

    if not getattr(model, "is_discrete", False):
        raise SampleError("a continuous model has no sample pairing; discretize it at the detector rate first")
    meta = dict(getattr(model, "meta", {}) or {})
    if meta.get("paired"):
        return model
    how = meta.get("discretized", "zoh")
    n = int(round(model.dt_s * sim_rate_hz))
    if how in HOLD_FROM_SAMPLE and n >= 2:
        A, B, C, D = (np.asarray(a, dtype=float) for a in (model.A, model.B, model.C, model.D))
        return replace(model, C=C @ A, D=C @ B + D, meta={**meta, "paired": True})
    return replace(model, meta={**meta, "paired": True})


def decimation(sim_rate_hz: float, rate_hz: float) -> int:
    """Steps per detector sample, ``n = sim_rate_hz / rate_hz``.

    Raises
    ------
    SampleError
        ``rate_hz`` is not positive or does not divide the simulation rate.
    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise SampleError(f"detector rate {rate_hz!r} Hz must be a positive number")
    d = sim_rate_hz / rate_hz
    n = int(round(d))
    if n < 1 or abs(d - n) > 1e-9 * max(1.0, d):
        divisors = [sim_rate_hz / k for k in range(1, int(sim_rate_hz) + 1)
                    if abs(sim_rate_hz / k - round(sim_rate_hz / k)) < 1e-9]
        raise SampleError(f"detector rate {rate_hz:g} Hz does not divide the simulation rate {sim_rate_hz:g} Hz; "
                          f"use one of {', '.join(f'{r:g}' for r in divisors[:12])} Hz")
    return n


def pair_samples(u: NDArray[np.float64], y: NDArray[np.float64], n: int) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Apply the time convention to row-aligned arrays.

    Parameters
    ----------
    u : NDArray
        (K, m) commands, row k written before simulation step k.
    y : NDArray
        (K, p) measurements, row k read before simulation step k.
    n : int
        Simulation steps per detector sample.

    Returns
    -------
    rows : NDArray of int
        (N,) the measurement rows ``j n``, j = 1 .. N.
    u_mean : NDArray
        (N, m) the commands averaged over rows ``(j-1) n .. j n - 1``.
    """
    K = len(y)
    if len(u) != K:
        raise SampleError(f"commands ({len(u)} rows) and measurements ({K} rows) are not aligned")
    J = (K - 1) // n
    rows = n * np.arange(1, J + 1, dtype=np.intp)
    if J == 0:
        return rows, np.zeros((0, u.shape[1]))
    u_mean = u[: J * n].reshape(J, n, u.shape[1]).mean(axis=1)
    return rows, u_mean


def samples_from_arrays(sim_rate_hz: float, u_names: Sequence[str], u: NDArray[np.float64], y_names: Sequence[str],
                        y: NDArray[np.float64], model: Any, rate_hz: float, *,
                        valid: NDArray[np.bool_] | None = None,
                        sensor_rates_hz: Mapping[str, float] | None = None, t0_s: float = 0.0) -> Samples:
    """Detector samples from row-aligned arrays at the simulation rate.

    Parameters
    ----------
    sim_rate_hz : float
        Rate of the rows [Hz].
    u_names, u : sequence of str, NDArray (K, mu)
        Logged commands (any superset of the model's control inputs).
    y_names, y : sequence of str, NDArray (K, py)
        Logged measurements (any superset of the model's outputs).
    model : LinearModel
        Gives the signal names (``input_names`` of kind ``"control"``, ``output_names``) and the
        trim ``u0`` / ``y0``.
    rate_hz : float
        Detector rate [Hz]; must divide ``sim_rate_hz``.
    valid : NDArray of bool, optional
        (K, py) validity of each logged measurement (True everywhere if None).
    sensor_rates_hz : mapping, optional
        Sampling rate of each measured signal [Hz] (the ``fresh`` flags); every row fresh if None.
    t0_s : float
        Time of row 0 [s].

    Returns
    -------
    Samples
    """
    n = decimation(sim_rate_hz, rate_hz)
    kinds = tuple(getattr(model, "input_kinds", ()) or ())
    m_inputs = tuple(model.input_names)
    ctrl = [i for i, nm in enumerate(m_inputs) if (kinds[i] == "control" if kinds else True)]
    in_names = tuple(m_inputs[i] for i in ctrl)
    out_names = tuple(model.output_names)
    # a known input is a logged command, or else a measured signal (an engine gauge used as the
    # input of the airframe model): both are averaged over the interval ending at t_j
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    from_y = [nm for nm in in_names if nm not in u_names and nm in y_names]
    if from_y:
        u = np.hstack([u, y[:, [list(y_names).index(nm) for nm in from_y]]])
        u_names = tuple(u_names) + tuple(from_y)
    ui = _columns(u_names, in_names, "command", TOPIC_COMMANDS)
    yi = _columns(y_names, out_names, "measurement", TOPIC_SENSORS)
    rows, u_mean = pair_samples(u[:, ui], y[:, yi], n)
    u0 = np.asarray(model.u0, dtype=float)[ctrl]
    y0 = np.asarray(model.y0, dtype=float)
    du = u_mean - u0
    dy = y[rows][:, yi] - y0
    for j, nm in enumerate(out_names):
        if is_wrapped(nm):
            dy[:, j] = (dy[:, j] + math.pi) % (2.0 * math.pi) - math.pi
    ok = np.isfinite(dy)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)[rows][:, yi]
    fresh = np.ones_like(ok)
    if sensor_rates_hz:
        for j, nm in enumerate(out_names):
            r = sensor_rates_hz.get(nm)
            if r:
                every = int(round(sim_rate_hz / r))
                fresh[:, j] = rows % every == 0
    dy = np.where(ok, dy, 0.0)  # an invalid value never enters arithmetic; `valid` says so
    return Samples(t0_s + rows / sim_rate_hz, du, dy, ok, fresh, in_names, out_names, float(rate_hz),
                   float(sim_rate_hz), rows, u0, y0)


def _columns(have: Sequence[str], need: Sequence[str], what: str, topic: str) -> list[int]:
    have = list(have)
    missing = [nm for nm in need if nm not in have]
    if missing:
        raise SampleError(f"the log has no {what} {', '.join(repr(m) for m in missing)} on {topic} "
                          f"(it has {', '.join(have)}); design the detector from a model with the logged signals")
    return [have.index(nm) for nm in need]


def log_samples(log: Any, model: Any, rate_hz: float, *,
                sensor_rates_hz: Mapping[str, float] | None = None) -> Samples:
    """Detector samples from a flight log (:class:`fdi_sim.flightlog.FlightLog`).

    Reads ``/commands/pilot``, ``/sensors/measurements`` and, when present, ``/sensors/valid``.

    Parameters
    ----------
    log : FlightLog
    model : LinearModel
    rate_hz : float
        Detector rate [Hz]; must divide the log's rate.
    sensor_rates_hz : mapping, optional
        Sampling rate per measured signal [Hz] (see :func:`samples_from_arrays`).

    Raises
    ------
    SampleError
        A topic or signal is missing (named), the rate does not divide the log's rate, or the
        log is too short for one sample.
    """
    for topic in (TOPIC_COMMANDS, TOPIC_SENSORS):
        if topic not in log.topics:
            raise SampleError(f"{getattr(log, 'path', 'the log')}: no {topic} topic; detectors need the logged "
                              "commands and measurements (a log written by `fdi-sim run`)")
    cmd = log.topics[TOPIC_COMMANDS]
    meas = log.topics[TOPIC_SENSORS]
    K = min(len(cmd.t_s), len(meas.t_s))
    if K < 2:
        raise SampleError(f"{getattr(log, 'path', 'the log')}: {K} logged rows; at least two are needed")
    t = np.asarray(meas.t_s[:K], dtype=float)
    dt = float(np.median(np.diff(t)))
    sim_rate_hz = float(round(1.0 / dt, 6))
    u_names = tuple(f for f in cmd.fields if f != "t_s")
    y_names = tuple(f for f in meas.fields if f != "t_s")
    u = np.column_stack([cmd[f][:K] for f in u_names])
    cols = [meas[f][:K] for f in y_names]
    for name, parts in DERIVED_MEASUREMENTS.items():
        if name not in y_names and all(p in y_names for p in parts):
            cols.append(np.mean([meas[p][:K] for p in parts], axis=0))
            y_names = y_names + (name,)
    y = np.column_stack(cols)
    valid = None
    if TOPIC_SENSORS_VALID in log.topics:
        vt = log.topics[TOPIC_SENSORS_VALID]
        valid = np.ones_like(y, dtype=bool)
        kv = min(K, len(vt.t_s))
        for i, f in enumerate(y_names):
            for src in DERIVED_MEASUREMENTS.get(f, (f,)):
                if src in vt.fields:
                    valid[:kv, i] &= vt[src][:kv] > 0.5
    return samples_from_arrays(sim_rate_hz, u_names, u, y_names, y, model, rate_hz, valid=valid,
                               sensor_rates_hz=sensor_rates_hz, t0_s=float(t[0]))

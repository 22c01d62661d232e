"""Validation of a linear model against JSBSim: small doublets on each input, per-output errors.

For each input a doublet (``+a`` for ``w`` seconds, then ``-a`` for ``w`` seconds) is flown from
the trim in JSBSim and through the discrete linear model. The nonlinear response is taken
relative to an unforced run from the same trim, so slow trim drift and fuel burn cancel. The
error of output ``i`` is the normalized RMS over all doublet runs together::

    nrmse_i = sqrt( sum_runs sum_k (y_lin - y_nl)^2 ) / sqrt( sum_runs sum_k y_nl^2 )

so each output is judged on the runs that excite it. The per-run, per-output matrix is kept as
well (``nrmse_pair``), with the response size (``rms_nl``) to tell a real error from noise on a
barely excited pair.

Engine lag (DHC-6)
------------------
The PT6A gas generator follows the throttle with a 1 s lag up and a 2.4 s lag down
(``FGTurboProp`` ExpSeek). That is not linear at any amplitude: a throttle doublet raises N1
quickly and lowers it slowly, so N1 stays above the trim and the aircraft gains energy, where any
linear model answers a zero-mean doublet with a near zero-mean response (measured: 40-95 % error on
every output of the throttle run). The linear model's ``n1_pct`` row holds the mean rate.
``compare(..., engine_lag=True)`` scores the model with that one row replaced by the exact
asymmetric lag identified from JSBSim at the trim
(:func:`~fdi_sim.aircraft.linearize_response.identify_engine_lag`), which tells whether the rest
of the model (propeller, airframe, outputs) is right; ``compare(...)`` scores the linear model
as it is. In the step model (:mod:`fdi_sim.linear.step`) the N1 state is the value of the
previous step and the forces of a step use the linear in-pass update; the lag replaces the value
carried to the next step, so the forces see the asymmetric N1 one step late (a difference of
``dt |1/tau_up - 1/tau_down| / 2``, 0.25 %, of the N1 excursion for that one step).

Timing convention (that of the simulation loop and of the detectors): the input row ``u_k`` is
set before JSBSim step ``k``; the outputs read after the step are ``y_k = C x_k + D u_k`` with
``x_{k+1} = A_d x_k + B_d u_k`` and ``x_0 = 0`` (JSBSim integrates at the start of a step with the
derivatives of the previous ones, then evaluates forces with the new input). Any discrete model
can be scored: ZOH (the detectors' default) or the step model of JSBSim's own step, on which the
bar is judged (``fdi_sim.linear.report.bar_method``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

if TYPE_CHECKING:  # the JSBSim side, imported where it is flown
    from fdi_sim.aircraft.linearize_response import EngineLag
    from fdi_sim.aircraft.linearize_state import TrimState
    from fdi_sim.aircraft.model import Aircraft

#: the bar of issue 4: normalized RMS error per output below 5 %
NRMSE_BAR: float = 0.05

#: a slope jump (:func:`~fdi_sim.aircraft.linearize_response.slope_jumps`) at least this large
#: within a doublet's excursion is a kink of JSBSim's model there, which no linear model holds [-]
NONSMOOTH_JUMP: float = 0.05

#: the point-info key of the validation flown with the identified N1 lag (turboprops)
ENGINE_LAG_KEY: str = "validation_engine_lag"


@dataclass(frozen=True)
class DoubletSpec:
    """A doublet on one input.

    Attributes
    ----------
    input_name : str
        The model input (``elevator_cmd_norm``, ``w_gust_body_fps``, ...).
    amplitude : float
        Height of each half [units of the input].
    start_s : float
        Start time [s].
    width_s : float
        Length of each half [s].
    """

    input_name: str
    amplitude: float
    start_s: float = 0.5
    width_s: float = 1.0


@dataclass(frozen=True)
class ValidationSettings:
    """The ``[validation]`` table of a grid file: one doublet per model input.

    Attributes
    ----------
    amplitudes : dict
        Input name -> doublet amplitude [units of the input].
    duration_s : float
        Length of each run [s].
    width_s : float
        Length of each half of a doublet [s].
    start_s : float
        Start of each doublet [s].
    """

    amplitudes: dict[str, float] = field(default_factory=dict)
    duration_s: float = 10.0
    width_s: float = DoubletSpec.width_s
    start_s: float = DoubletSpec.start_s


def doublet_signal(n_steps: int, dt_s: float, spec: DoubletSpec) -> NDArray[np.float64]:
    """Sampled doublet: ``u_k`` for the step from ``k dt`` to ``(k+1) dt`` [units of the input]."""
    if n_steps < 1 or not dt_s > 0:
        raise DesignError(f"doublet needs n_steps >= 1 and dt_s > 0, got {n_steps}, {dt_s}")
    t = np.arange(n_steps) * dt_s + 1e-9
    u = np.zeros(n_steps)
    u[(t >= spec.start_s) & (t < spec.start_s + spec.width_s)] = spec.amplitude
    u[(t >= spec.start_s + spec.width_s) & (t < spec.start_s + 2 * spec.width_s)] = -spec.amplitude
    return u


def simulate_linear(model: LinearModel, du: NDArray[np.float64], engine_lag: EngineLag | None = None
                    ) -> NDArray[np.float64]:
    """Output deviations of a discrete model from ``x_0 = 0`` for input deviations ``du`` (N, m).

    ``y_k = C x_k + D u_k``, ``x_{k+1} = A x_k + B u_k``.

    Parameters
    ----------
    model : LinearModel
        Discrete model.
    du : NDArray
        Input deviations, shape (N, m) [units of the inputs].
    engine_lag : EngineLag, optional
        Replace the linear update of ``engine_lag.state_name`` by the asymmetric lag toward the
        target ``K u``: ``z_{k+1} = K u_k + (z_k - K u_k) exp(-dt / tau)``, ``tau`` the up or down
        time constant as ``z_k`` is below or above the target. ``K`` is the model's own static gain
        of that row, ``B_ij / (1 - A_ii)``; the row must depend on nothing but its state and input.

    Raises
    ------
    DesignError
        A continuous model, a column count that does not match, or an engine-lag row that
        depends on other states or inputs.
    """
    if not model.is_discrete:
        raise DesignError("simulate_linear needs a discrete model; call discretize(model, dt_s) first")
    du = np.atleast_2d(np.asarray(du, dtype=float))
    if du.shape[1] != model.n_inputs:
        raise DesignError(f"du has {du.shape[1]} columns, the model has {model.n_inputs} inputs")
    return _simulate_batch(model, du[None], engine_lag)[0]


def _simulate_batch(model: LinearModel, du: NDArray[np.float64], engine_lag: EngineLag | None = None
                    ) -> NDArray[np.float64]:
    """:func:`simulate_linear` of several equally long input sequences at once, ``du`` (R, N, m) -> (R, N, p).

    All runs are the columns of one state matrix, so each step is one matrix product.
    """
    R, N, _ = du.shape
    bu = model.B @ du.transpose(1, 2, 0)  # B u_k of every run, (N, n, R)
    A = model.A
    xs = np.empty((N, model.n_states, R))
    xs[:1] = 0.0
    if engine_lag is not None:
        # the lag row depends on its state and input only (lag_row checks): its trajectory comes first
        i, j, K = lag_row(model, engine_lag)
        n1 = expseek(K * du[:, :, j].T, model.dt_s, engine_lag)  # z_1 .. z_N, (N, R)
    for k in range(N - 1):  # x_{k+1} = A x_k + B u_k
        x = xs[k + 1]
        np.matmul(A, xs[k], out=x)
        x += bu[k]
        if engine_lag is not None:
            x[i] = n1[k]
    return (model.C @ xs).transpose(2, 0, 1) + du @ model.D.T


def expseek(target: NDArray[np.float64], dt_s: float, lag: EngineLag) -> NDArray[np.float64]:
    """FGTurboProp's ExpSeek from 0 toward ``target`` (deviations, shape (N, ...)) [units of the target].

    ``z_{k+1} = t_k + (z_k - t_k) exp(-dt / tau)``, ``tau = lag.tau_up_s`` while ``z_k < t_k``,
    else ``lag.tau_down_s``; ``z_0 = 0``. Returns ``z_1 .. z_N``.
    """
    target = np.asarray(target, dtype=float)
    r_up, r_down = math.exp(-dt_s / lag.tau_up_s), math.exp(-dt_s / lag.tau_down_s)
    out = np.empty_like(target)
    z = np.zeros(target.shape[1:])
    for k, t in enumerate(target):
        z = out[k] = t + (z - t) * np.where(z < t, r_up, r_down)
    return out


def lag_row(model: LinearModel, lag: EngineLag) -> tuple[int, int, float]:
    """State index, input index and static gain of the engine-lag row.

    The gain is ``B_ij / (1 - A_ii)`` for a discrete model and ``-B_ij / A_ii`` for a continuous one.
    """
    if lag.state_name not in model.state_names or lag.input_name not in model.input_names:
        raise DesignError(f"engine lag on {lag.state_name!r} <- {lag.input_name!r}: the model has no such "
                          f"state or input (states {', '.join(model.state_names)})")
    i, j = model.state_names.index(lag.state_name), model.input_names.index(lag.input_name)
    a_row, b_row = np.delete(model.A[i], i), np.delete(model.B[i], j)
    scale = max(abs(model.B[i, j]), 1e-300)
    if np.max(np.abs(a_row), initial=0.0) > 1e-6 or np.max(np.abs(b_row), initial=0.0) > 1e-6 * scale:
        raise DesignError(f"the {lag.state_name} row depends on other states or inputs; the engine lag "
                          "replaces a first-order row driven by one input only")
    if model.is_discrete:
        return i, j, float(model.B[i, j] / (1.0 - model.A[i, i]))
    return i, j, float(-model.B[i, j] / model.A[i, i])


def nrmse(y_lin: NDArray[np.float64], y_nl: NDArray[np.float64], axis: int | tuple[int, ...] = 0) -> NDArray[np.float64]:
    """``sqrt(sum (y_lin - y_nl)^2) / sqrt(sum y_nl^2)`` along ``axis`` (inf where ``y_nl`` is 0) [-]."""
    num = np.sqrt(np.sum((np.asarray(y_lin) - np.asarray(y_nl)) ** 2, axis=axis))
    den = np.sqrt(np.sum(np.asarray(y_nl) ** 2, axis=axis))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)


def aggregate(nrmse_pair: NDArray[np.float64], rms_nl: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per-output error over several equally long runs from their per-run errors and RMS [-].

    ``sum_k e^2 = N (nrmse_r rms_r)^2`` and ``sum_k y^2 = N rms_r^2`` for each run ``r``.
    """
    err = np.nan_to_num(np.asarray(nrmse_pair) * np.asarray(rms_nl), posinf=0.0)
    den = np.sqrt(np.sum(np.asarray(rms_nl) ** 2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.sqrt(np.sum(err**2, axis=0)) / np.where(den > 0, den, 1.0), np.inf)


@dataclass(frozen=True, eq=False)
class DoubletRuns:
    """Nonlinear doublet responses from one trim (reusable for several linear models).

    Attributes
    ----------
    label : str
        The operating point.
    doublets : tuple of DoubletSpec
        One per run.
    du : NDArray
        Input signal of each run, shape (runs, N) [units of the input].
    dy : NDArray
        Output deviations from the unforced run, shape (runs, N, p) [units of the outputs].
    output_names : tuple of str
        Output order of ``dy``.
    dt_s : float
        Step [s].
    engine_lag : EngineLag or None
        The asymmetric N1 lag identified at the trim (None without a gas-generator state).
    """

    label: str
    doublets: tuple[DoubletSpec, ...]
    du: NDArray[np.float64]
    dy: NDArray[np.float64]
    output_names: tuple[str, ...]
    dt_s: float
    engine_lag: EngineLag | None = None

    @property
    def input_names(self) -> tuple[str, ...]:
        """The input of each run."""
        return tuple(d.input_name for d in self.doublets)

    @property
    def duration_s(self) -> float:
        """Length of each run [s]."""
        return self.dy.shape[1] * self.dt_s


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """Linear against nonlinear doublet responses at one operating point.

    Attributes
    ----------
    runs : DoubletRuns
        The nonlinear runs (operating point, inputs, outputs, step).
    y_lin : NDArray
        The discrete linear model's responses to the same inputs, shape (runs, N, p)
        [units of the outputs].
    engine_lag : EngineLag or None
        Set when the model was flown with the asymmetric N1 lag in place of its ``n1_pct`` row
        (``compare(..., engine_lag=True)``); None for the linear model as it is.
    """

    runs: DoubletRuns
    y_lin: NDArray[np.float64]
    engine_lag: EngineLag | None = None

    @cached_property
    def nrmse(self) -> NDArray[np.float64]:
        """Per output, over all runs [-]."""
        return nrmse(self.y_lin, self.runs.dy, axis=(0, 1))

    @cached_property
    def nrmse_pair(self) -> NDArray[np.float64]:
        """Per run and output, shape (runs, outputs) [-]."""
        return nrmse(self.y_lin, self.runs.dy, axis=1)

    @cached_property
    def rms_nl(self) -> NDArray[np.float64]:
        """RMS of the nonlinear response per run and output, shape (runs, outputs) [units of the output]."""
        return np.sqrt(np.mean(self.runs.dy**2, axis=1))

    @property
    def worst(self) -> tuple[str, float]:
        """The output with the largest aggregate error and that error."""
        i = int(np.argmax(self.nrmse))
        return self.runs.output_names[i], float(self.nrmse[i])

    def passed(self, bar: float = NRMSE_BAR) -> bool:
        """Every output's aggregate error below ``bar``."""
        return bool(np.all(self.nrmse < bar))

    def nrmse_without(self, inputs: Sequence[str]) -> NDArray[np.float64]:
        """Per-output aggregate error leaving out the runs on ``inputs`` [-]."""
        keep = [i for i, n in enumerate(self.runs.input_names) if n not in inputs]
        return aggregate(self.nrmse_pair[keep], self.rms_nl[keep])


def compare(model_d: LinearModel, runs: DoubletRuns, engine_lag: bool = False) -> ValidationResult:
    """Score the discrete model ``model_d`` against nonlinear doublet runs (pure).

    Parameters
    ----------
    model_d : LinearModel
        Discrete model at the runs' step.
    runs : DoubletRuns
        The nonlinear runs.
    engine_lag : bool
        Fly the model with the asymmetric N1 lag of ``runs.engine_lag`` in place of its
        ``n1_pct`` row (see the module notes). Without an identified lag (F-16) the model is
        flown as it is and the result says so (``engine_lag`` None).

    Raises
    ------
    DesignError
        Different step or outputs, or a doublet input the model does not have.
    """
    if not model_d.is_discrete or abs(model_d.dt_s - runs.dt_s) > 1e-12:
        raise DesignError(f"the model must be discrete at the runs' step {runs.dt_s} s (got dt_s = {model_d.dt_s})")
    if tuple(model_d.output_names) != tuple(runs.output_names):
        raise DesignError(f"model outputs {model_d.output_names} differ from the runs' {runs.output_names}")
    lag = runs.engine_lag if engine_lag else None
    U = np.zeros((len(runs.doublets), runs.du.shape[1], model_d.n_inputs))
    for r, (name, u) in enumerate(zip(runs.input_names, runs.du)):
        if name not in model_d.input_names:
            raise DesignError(f"doublet input {name!r} is not a model input ({', '.join(model_d.input_names)})")
        U[r, :, model_d.input_names.index(name)] = u
    return ValidationResult(runs=runs, y_lin=_simulate_batch(model_d, U, lag), engine_lag=lag)


def default_doublets(model: LinearModel, settings: ValidationSettings) -> tuple[DoubletSpec, ...]:
    """One doublet per model input, with the amplitude and timing of ``settings``.

    Raises
    ------
    DesignError
        A model input has no amplitude (every input must be validated).
    """
    missing = [n for n in model.input_names if n not in settings.amplitudes]
    if missing:
        raise DesignError(f"no doublet amplitude for inputs {missing}; add them to the [validation] table")
    return tuple(DoubletSpec(n, float(settings.amplitudes[n]), settings.start_s, settings.width_s)
                 for n in model.input_names)


def fly_doublets(ac: Aircraft, ts: TrimState, doublets: Sequence[DoubletSpec], output_names: Sequence[str],
                 duration_s: float = ValidationSettings.duration_s) -> DoubletRuns:
    """Fly each doublet in JSBSim from the trim ``ts``; responses relative to an unforced run.

    Also identifies the asymmetric N1 lag at the trim for aircraft with a gas-generator state
    (``DoubletRuns.engine_lag``; 6 extra steps).

    Parameters
    ----------
    ac : fdi_sim.aircraft.Aircraft
        The aircraft (put back at the trim before every run; fuel frozen).
    ts : fdi_sim.aircraft.linearize_state.TrimState
        The trim the model was linearized about.
    doublets : sequence of DoubletSpec
        One run per entry.
    output_names : sequence of str
        Outputs to record (``psi_rad`` comes unwrapped about the trim heading, so its
        deviation is continuous).
    duration_s : float
        Length of each run [s].
    """
    from fdi_sim.aircraft.linearize_response import identify_engine_lag, simulate_inputs  # JSBSim side

    n = int(round(duration_s / ac.dt_s))
    names = tuple(output_names)
    base = simulate_inputs(ac, ts, [], np.zeros((n, 0)), names).y
    us = np.array([doublet_signal(n, ac.dt_s, spec) for spec in doublets])
    dy = np.array([simulate_inputs(ac, ts, [spec.input_name], u[:, None], names).y - base
                   for spec, u in zip(doublets, us)])
    return DoubletRuns(label=ts.op.label(), doublets=tuple(doublets), du=us, dy=dy, output_names=names,
                       dt_s=float(ac.dt_s), engine_lag=identify_engine_lag(ac, ts))

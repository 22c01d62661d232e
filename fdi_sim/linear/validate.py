"""Validation of a linear model against JSBSim: small doublets on each input, per-output errors.

For each input a doublet (``+a`` for ``w`` seconds, then ``-a`` for ``w`` seconds) is flown from
the trim in JSBSim and through the discrete linear model. The nonlinear response is taken
relative to an unforced run from the same trim, so slow trim drift and fuel burn cancel. The
error of output ``i`` is the normalized RMS over all doublet runs together::

    nrmse_i = sqrt( sum_runs sum_k (y_lin - y_nl)^2 ) / sqrt( sum_runs sum_k y_nl^2 )

so each output is judged on the runs that excite it. The per-run, per-output matrix is kept as
well (``nrmse_pair``), with the response size (``rms_nl``) to tell a real error from noise on a
barely excited pair.

Timing convention (that of the simulation loop and of the detectors): the input row ``u_k`` is
set before JSBSim step ``k``; the outputs read after the step are ``y_k = C x_k + D u_k`` with
``x_{k+1} = A_d x_k + B_d u_k`` and ``x_0 = 0`` (JSBSim integrates at the start of a step with the
derivatives of the previous one, then evaluates forces with the new input).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

if TYPE_CHECKING:  # the JSBSim side, imported where it is flown
    from fdi_sim.aircraft.linearize_state import TrimState
    from fdi_sim.aircraft.model import Aircraft

#: the bar of issue 4: normalized RMS error per output below 5 %
NRMSE_BAR: float = 0.05


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


def simulate_linear(model: LinearModel, du: NDArray[np.float64]) -> NDArray[np.float64]:
    """Output deviations of a discrete model from ``x_0 = 0`` for input deviations ``du`` (N, m).

    ``y_k = C x_k + D u_k``, ``x_{k+1} = A x_k + B u_k``.
    """
    if not model.is_discrete:
        raise DesignError("simulate_linear needs a discrete model; call discretize(model, dt_s) first")
    du = np.atleast_2d(np.asarray(du, dtype=float))
    if du.shape[1] != model.n_inputs:
        raise DesignError(f"du has {du.shape[1]} columns, the model has {model.n_inputs} inputs")
    x = np.zeros(model.n_states)
    xs = np.empty((du.shape[0], model.n_states))
    A, B = model.A, model.B
    for k in range(du.shape[0]):
        xs[k] = x
        x = A @ x + B @ du[k]
    return xs @ model.C.T + du @ model.D.T


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
    """

    label: str
    doublets: tuple[DoubletSpec, ...]
    du: NDArray[np.float64]
    dy: NDArray[np.float64]
    output_names: tuple[str, ...]
    dt_s: float

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
    """

    runs: DoubletRuns
    y_lin: NDArray[np.float64]

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


def compare(model_d: LinearModel, runs: DoubletRuns) -> ValidationResult:
    """Score the discrete model ``model_d`` against nonlinear doublet runs (pure).

    Raises
    ------
    DesignError
        Different step or outputs, or a doublet input the model does not have.
    """
    if not model_d.is_discrete or abs(model_d.dt_s - runs.dt_s) > 1e-12:
        raise DesignError(f"the model must be discrete at the runs' step {runs.dt_s} s (got dt_s = {model_d.dt_s})")
    if tuple(model_d.output_names) != tuple(runs.output_names):
        raise DesignError(f"model outputs {model_d.output_names} differ from the runs' {runs.output_names}")
    y_lin = []
    for name, u in zip(runs.input_names, runs.du):
        if name not in model_d.input_names:
            raise DesignError(f"doublet input {name!r} is not a model input ({', '.join(model_d.input_names)})")
        U = np.zeros((len(u), model_d.n_inputs))
        U[:, model_d.input_names.index(name)] = u
        y_lin.append(simulate_linear(model_d, U))
    return ValidationResult(runs=runs, y_lin=np.array(y_lin))


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
    from fdi_sim.aircraft.linearize_response import simulate_inputs  # JSBSim side

    n = int(round(duration_s / ac.dt_s))
    names = tuple(output_names)
    base = simulate_inputs(ac, ts, [], np.zeros((n, 0)), names).y
    us = np.array([doublet_signal(n, ac.dt_s, spec) for spec in doublets])
    dy = np.array([simulate_inputs(ac, ts, [spec.input_name], u[:, None], names).y - base
                   for spec, u in zip(doublets, us)])
    return DoubletRuns(label=ts.op.label(), doublets=tuple(doublets), du=us, dy=dy, output_names=names,
                       dt_s=float(ac.dt_s))

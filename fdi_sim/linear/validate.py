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
from typing import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

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
class ValidationResult:
    """Linear against nonlinear doublet responses at one operating point.

    Attributes
    ----------
    label : str
        The operating point.
    input_names : tuple of str
        The input of each doublet run.
    output_names : tuple of str
        Output order.
    dt_s, duration_s : float
        Sample time and length of each run [s].
    nrmse : NDArray
        Per output, over all runs [-].
    nrmse_pair : NDArray
        Per run and output, shape (runs, outputs) [-].
    rms_nl : NDArray
        RMS of the nonlinear response per run and output [units of the output].
    traces : dict
        ``{"t_s", "y_nl", "y_lin", "du"}`` arrays when kept (for figures), else empty.
    """

    label: str
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    dt_s: float
    duration_s: float
    nrmse: NDArray[np.float64]
    nrmse_pair: NDArray[np.float64]
    rms_nl: NDArray[np.float64]
    traces: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    @property
    def worst(self) -> tuple[str, float]:
        """The output with the largest aggregate error and that error."""
        i = int(np.argmax(self.nrmse))
        return self.output_names[i], float(self.nrmse[i])

    def passed(self, bar: float = NRMSE_BAR) -> bool:
        """Every output's aggregate error below ``bar``."""
        return bool(np.all(self.nrmse < bar))

    def nrmse_without(self, inputs: Sequence[str]) -> NDArray[np.float64]:
        """Per-output aggregate error leaving out the runs on ``inputs`` [-]."""
        keep = [i for i, n in enumerate(self.input_names) if n not in inputs]
        return aggregate(self.nrmse_pair[keep], self.rms_nl[keep])

    def excited_pairs(self, rel: float = 0.1) -> NDArray[np.bool_]:
        """Runs that move an output by at least ``rel`` times its largest response over all runs."""
        peak = np.max(self.rms_nl, axis=0, keepdims=True)
        return self.rms_nl >= rel * np.where(peak > 0, peak, np.inf)


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


def compare(model_d: LinearModel, runs: DoubletRuns, keep_traces: bool = False) -> ValidationResult:
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
    for spec, u in zip(runs.doublets, runs.du):
        if spec.input_name not in model_d.input_names:
            raise DesignError(f"doublet input {spec.input_name!r} is not a model input ({', '.join(model_d.input_names)})")
        U = np.zeros((len(u), model_d.n_inputs))
        U[:, model_d.input_names.index(spec.input_name)] = u
        y_lin.append(simulate_linear(model_d, U))
    YL, YN = np.array(y_lin), runs.dy  # (runs, N, p)
    traces = {}
    if keep_traces:
        traces = {"t_s": np.arange(1, YN.shape[1] + 1) * model_d.dt_s, "y_nl": YN, "y_lin": YL, "du": runs.du}
    return ValidationResult(
        label=runs.label, input_names=tuple(d.input_name for d in runs.doublets), output_names=model_d.output_names,
        dt_s=model_d.dt_s, duration_s=YN.shape[1] * model_d.dt_s, nrmse=nrmse(YL, YN, axis=(0, 1)),
        nrmse_pair=nrmse(YL, YN, axis=1), rms_nl=np.sqrt(np.mean(YN**2, axis=1)), traces=traces,
    )


def default_doublets(model: LinearModel, amplitudes: Mapping[str, float], width_s: float = 1.0,
                     start_s: float = 0.5) -> tuple[DoubletSpec, ...]:
    """One doublet per model input that has an amplitude in ``amplitudes``.

    Raises
    ------
    DesignError
        A model input has no amplitude (every input must be validated).
    """
    missing = [n for n in model.input_names if n not in amplitudes]
    if missing:
        raise DesignError(f"no doublet amplitude for inputs {missing}; add them to the [validation] table")
    return tuple(DoubletSpec(n, float(amplitudes[n]), start_s, width_s) for n in model.input_names)


def fly_doublets(ac: object, ts: object, doublets: Sequence[DoubletSpec], output_names: Sequence[str],
                 duration_s: float = 10.0) -> DoubletRuns:
    """Fly each doublet in JSBSim from the trim ``ts``; responses relative to an unforced run.

    Parameters
    ----------
    ac : fdi_sim.aircraft.Aircraft
        The aircraft (put back at the trim before every run; fuel frozen).
    ts : fdi_sim.aircraft.linearize.TrimState
        The trim the model was linearized about.
    doublets : sequence of DoubletSpec
        One run per entry.
    output_names : sequence of str
        Outputs to record.
    duration_s : float
        Length of each run [s].
    """
    from fdi_sim.aircraft.linearize import simulate_inputs  # JSBSim side

    dt = float(ac.dt_s)  # type: ignore[attr-defined]
    n = int(round(duration_s / dt))
    names = tuple(output_names)
    base = simulate_inputs(ac, ts, [], np.zeros((n, 0)), names).y  # type: ignore[arg-type]
    wrap = [i for i, nm in enumerate(names) if nm == "psi_rad"]
    us, dys = [], []
    for spec in doublets:
        u = doublet_signal(n, dt, spec)
        r = simulate_inputs(ac, ts, [spec.input_name], u[:, None], names)  # type: ignore[arg-type]
        dy = r.y - base
        dy[:, wrap] = (dy[:, wrap] + np.pi) % (2 * np.pi) - np.pi
        us.append(u)
        dys.append(dy)
    label = ts.op.label() if hasattr(ts, "op") else ""
    return DoubletRuns(label=label, doublets=tuple(doublets), du=np.array(us), dy=np.array(dys),
                       output_names=names, dt_s=dt)


def validate_point(ac: object, ts: object, model_d: LinearModel, doublets: Sequence[DoubletSpec],
                   duration_s: float = 10.0, keep_traces: bool = False) -> ValidationResult:
    """:func:`fly_doublets` then :func:`compare` for one discrete model (at the simulation step)."""
    if not model_d.is_discrete or abs(model_d.dt_s - ac.dt_s) > 1e-12:  # type: ignore[attr-defined]
        raise DesignError(f"validation compares step by step: discretize the model at the simulation step "
                          f"{ac.dt_s} s (got dt_s = {model_d.dt_s})")  # type: ignore[attr-defined]
    runs = fly_doublets(ac, ts, doublets, model_d.output_names, duration_s)
    return compare(model_d, runs, keep_traces=keep_traces)

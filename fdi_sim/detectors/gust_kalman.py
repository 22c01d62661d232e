"""A Kalman innovation detector that knows JSBSim's turbulence and the sensors' turn-on biases.

Why (measured, ``docs/detectors.md``): a Kalman filter whose only disturbance model is white
process noise alarms on most fault-free samples in turbulence, because the gusts are coloured
(1/e times 1.2-12 s) and 20-55 times the gyro noise. This detector:

1. takes the continuous linearization, adds the rotational-turbulence columns
   (:func:`fdi_sim.detectors.disturbance.rotational_turbulence_inputs`), discretizes it at the
   detector rate and puts it in the standard form of the samples' time convention
   (:func:`fdi_sim.detectors.samples.paired_model`);
2. appends JSBSim's Dryden gust states (:func:`~fdi_sim.detectors.disturbance.augment_with_gusts`)
   and one random-constant bias state per output (turn-on biases, ``bias_std`` of the sensor
   suite, a slow random walk so that the filter keeps adapting);
3. runs the *time-varying* Kalman filter from the known trim (plant covariance 0, bias
   covariance ``bias_std^2``): the gains are data-independent, so the sequence is computed once
   at design time until it has settled, then the steady gain is used. The turn-on biases are
   estimated within seconds instead of leaving a slow transient in the innovations (with the
   steady-state gain and a flight's-own-baseline instead, 4 % of held-out F-16 samples alarmed,
   all in the first minute);
4. tests the mean of the innovations over a window of ``window_s`` (1 s):
   ``T = m' Sigma_m^-1 m``. ``Sigma_m`` is measured on fault-free training flights
   (:func:`calibrate`): the linear model is not exact (the autopilot's doublets, the DHC-6's
   table kinks), and the innovation covariance it predicts misses the cross-correlations that
   matter (F-16, moderate: the whitened innovations had variance 201 along q - p). The
   threshold is the empirical ``1 - target`` quantile of ``T`` on the training flights; the
   analytic one is the chi-square quantile with ``p`` degrees of freedom, which holds only if
   ``m`` were Gaussian with covariance ``Sigma_m`` and independent between samples.

Isolation: each hypothesis (an additive fault on one control input, or a bias step on one sensor)
has a signature, the mean innovation over the first window after a unit step, computed from the
filter's own dynamics. The alarm is isolated to the hypothesis whose signature is closest in
angle in the metric ``Sigma_m^-1`` (cosine >= ``min_cosine``); otherwise rejected (``None``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.detectors.disturbance import (
    _as_augmented, augment_with_gusts, augment_with_sensor_biases, dryden_parameters, rotational_turbulence_inputs,
)
from fdi_sim.detectors.samples import Samples, is_wrapped, paired_model
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.transform import discretize
from fdi_sim.threads import single_blas_thread

#: per-step random walk of the bias states, as a fraction of the turn-on spread
DEFAULT_BIAS_DRIFT = 1e-3
#: allowed excess of the filter's spectral radius over 1 (marginal unobservable modes, rounding)
RHO_MARGIN = 1e-4
#: gains that change by less than this (relative, max abs) over one second count as settled
GAIN_SETTLED = 1e-6


@dataclass(frozen=True)
class SensorNoise:
    """Noise of one measured output: white noise and turn-on bias standard deviations, quantum."""

    noise_std: float
    bias_std: float = 0.0
    quantum: float = 0.0


@dataclass(frozen=True, eq=False)
class GustKalmanDesign:
    """The filter of :class:`GustKalmanDetector`.

    Attributes
    ----------
    model : LinearModel
        Paired, augmented discrete model (plant, gust and bias states).
    gains : NDArray
        (J, n, p) the time-varying gains for samples 0 .. J-1; the last one is used after.
    control_columns : tuple of int
        Columns of ``model.B``/``D`` that are the logged commands (in ``input_names`` order).
    window_n : int
        Samples in the test window.
    signatures : NDArray
        (h, W, p) window-mean innovation of each hypothesis' unit step by onset (:func:`_signatures`).
    hypotheses : tuple of str
    turbulence : str
    rate_hz : float
    """

    model: LinearModel
    gains: NDArray[np.float64]
    control_columns: tuple[int, ...]
    window_n: int
    signatures: NDArray[np.float64]
    hypotheses: tuple[str, ...]
    turbulence: str
    rate_hz: float
    S: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class Calibration:
    """Test statistic calibration from fault-free flights.

    Attributes
    ----------
    sigma_m : NDArray
        (p, p) covariance of the windowed mean innovation.
    threshold : float
        Empirical ``1 - target`` quantile of ``T`` on the training samples.
    threshold_analytic : float
        ``chi2.ppf(1 - target, p)``.
    target_per_sample : float
    n_samples : int
        Training samples used.
    flights : tuple of str
        What the training flights were (seeds, conditions).
    """

    sigma_m: NDArray[np.float64]
    threshold: float
    threshold_analytic: float
    target_per_sample: float
    n_samples: int
    flights: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"sigma_m": self.sigma_m.tolist(), "threshold": self.threshold,
                "threshold_analytic": self.threshold_analytic, "target_per_sample": self.target_per_sample,
                "n_samples": self.n_samples, "flights": list(self.flights)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Calibration:
        return cls(np.asarray(d["sigma_m"], dtype=float), float(d["threshold"]), float(d["threshold_analytic"]),
                   float(d["target_per_sample"]), int(d["n_samples"]), tuple(d.get("flights", ())))


@single_blas_thread  # the same bits in a study worker and in a shell (fdi_sim.threads)
def design_gust_kalman(model: LinearModel, *, rate_hz: float, sim_rate_hz: float = 120.0, turbulence: str = "moderate",
                       wingspan_ft: float, sensors: Mapping[str, SensorNoise], psiw_rad: float = 0.0,
                       bias_drift: float = DEFAULT_BIAS_DRIFT, window_s: float = 1.0, max_gain_s: float = 120.0
                       ) -> GustKalmanDesign:
    """Design the filter (module docstring, steps 1-3) and the isolation signatures.

    Parameters
    ----------
    model : LinearModel
        The continuous linearization at the operating point (states ``vt_fps alpha_rad ...``,
        gust columns ``u/v/w_gust_body_fps``); a discrete one is used at its own rate without the
        rotational-turbulence columns (``notes`` says so).
    rate_hz : float
        Detector rate [Hz] (ignored for a discrete model).
    sim_rate_hz : float
        Simulation rate [Hz].
    turbulence : str
        ``none | light | moderate | severe``: the Dryden intensities of the design.
    wingspan_ft : float
        Wing span [ft] (JSBSim's ``metrics/bw-ft``; sets the rotational turbulence).
    sensors : mapping
        :class:`SensorNoise` per output name.
    psiw_rad : float
        Azimuth of JSBSim's turbulence axes [rad] (the mean wind's direction; 0 without wind).
    bias_drift : float
        Per-step random walk of the bias states as a fraction of their turn-on spread.
    window_s : float
        Test window [s].
    max_gain_s : float
        Longest time-varying gain sequence kept [s].

    Raises
    ------
    DesignError
        A discrete model, an output without a sensor entry, an unstable filter.
    """
    missing = [o for o in model.output_names if o not in sensors]
    if missing:
        raise DesignError(f"no sensor noise for outputs {missing}; give sensors={{name: SensorNoise(...)}}")
    notes = []
    if model.is_discrete:  # the rotational columns need the continuous model: left out, and said so
        notes.append("designed from a discrete model: no rotational-turbulence columns")
        rate_hz = 1.0 / model.dt_s
        cont = model
        disc = paired_model(model, sim_rate_hz)
    else:
        cont = rotational_turbulence_inputs(model)
        disc = paired_model(discretize(cont, 1.0 / rate_hz), sim_rate_hz)
    names = list(cont.state_names)
    if "vt_fps" not in names or "h_ft" not in names:
        raise DesignError("kalman-gust-v1 needs the states vt_fps and h_ft (the Dryden intensities depend on them)")
    vt = float(cont.x0[names.index("vt_fps")])
    h = float(cont.x0[names.index("h_ft")])
    par = dryden_parameters(h, vt, turbulence, wingspan_ft)
    aug = augment_with_gusts(disc, par, psiw_rad=psiw_rad) if par.active else _as_augmented(disc)
    if not par.active:
        notes.append("turbulence none: no gust states")
    outs = disc.output_names
    b_sig = [max(float(sensors[o].bias_std), 1e-9) for o in outs]
    aug = augment_with_sensor_biases(aug, outs, b_sig, drift_sigma=[b * bias_drift for b in b_sig])
    m = aug.model
    R = np.diag([sensors[o].noise_std ** 2 + sensors[o].quantum ** 2 / 12.0 for o in outs])
    n = m.n_states
    A, C = np.asarray(m.A), np.asarray(m.C)
    Q = aug.Q + 1e-14 * np.eye(n)  # keeps P positive definite in directions nothing excites
    P = np.asarray(aug.P0, dtype=float).copy()
    gains = []
    J_max = int(round(max_gain_s * rate_hz))
    per_s = int(round(rate_hz))
    for j in range(J_max):
        S = C @ P @ C.T + R
        K = np.linalg.solve(S.T, (P @ C.T).T).T  # K = P C' S^-1
        gains.append(K)
        P = A @ (P - K @ C @ P) @ A.T + Q
        P = 0.5 * (P + P.T)
        if j >= 2 * per_s and np.max(np.abs(gains[-1] - gains[-1 - per_s])) <= GAIN_SETTLED * np.max(np.abs(K)):
            break
    S_steady = C @ P @ C.T + R  # the design's innovation covariance (steady)
    G = np.asarray(gains)
    Acl = A @ (np.eye(n) - G[-1] @ C)
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    # Unobservable random-constant biases (a baro bias beside the altitude state, which only their
    # sum reaches) keep eigenvalues at 1: they never reach the innovations. A double eigenvalue at 1
    # moves by about sqrt(eps) ~ 1e-5 under rounding, so the test allows 1 + RHO_MARGIN.
    if not rho <= 1.0 + RHO_MARGIN:
        raise DesignError(f"the filter is not stable (spectral radius {rho:.6f} of A(I - KC)); "
                          "check the model's observability")
    notes.append(f"spectral radius of A(I - KC): {rho:.6f}")
    if len(gains) == J_max:
        notes.append(f"gains still changing after {max_gain_s:g} s: the last one is used from then on")
    ctrl = tuple(int(i) for i in np.flatnonzero([k == "control" for k in m.input_kinds]))
    window_n = max(1, int(round(window_s * rate_hz)))
    hyps, sig = _signatures(m, G[-1], ctrl, window_n)
    return GustKalmanDesign(m, G, ctrl, window_n, sig, hyps, turbulence, float(rate_hz), 0.5 * (S_steady + S_steady.T),
                            tuple(notes))


def analytic_calibration(design: GustKalmanDesign, target_per_sample: float) -> Calibration:
    """The calibration the design itself predicts: white innovations with covariance ``S``, so
    the window mean has ``Sigma_m = S / W`` and ``T`` is chi-square with ``p`` degrees of freedom.
    What fault-free flights say about it is in ``docs/detectors.md`` (it is far too low)."""
    thr = float(chi2.ppf(1.0 - target_per_sample, design.model.n_outputs))
    return Calibration(design.S / design.window_n, thr, thr, float(target_per_sample), 0, ("analytic: design covariance",))


def _signatures(m: LinearModel, K: NDArray[np.float64], ctrl: Sequence[int], W: int
                ) -> tuple[tuple[str, ...], NDArray[np.float64]]:
    """Window-mean innovation of each hypothesis' unit step, for every onset inside the window.

    Returns ``(hypotheses, sig)`` with ``sig[i, k - 1]`` the mean over a ``W``-sample window of
    the innovations of a unit step of hypothesis ``i`` that started ``k`` samples before the
    window's end (``k = 1 .. W``; steady gain): ``(1/W) sum_{l<k} nu_i(l)``. Matching over ``k`` is
    the onset search of a GLR test: an alarm raised two samples after the onset is compared with
    the first two samples of each response, not with a whole window of it.
    """
    A, B, C, D = (np.asarray(a, dtype=float) for a in (m.A, m.B, m.C, m.D))
    n, p = m.n_states, m.n_outputs
    hyps, rows = [], []

    def response(b: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
        # plant with the fault, filter without: e(k+1) = A (e - K nu) + b f, nu = C e + d f
        e = np.zeros(n)
        out = np.empty((W, p))
        for k in range(W):
            nu = C @ e + d
            out[k] = nu
            e = A @ (e - K @ nu) + b
        return np.cumsum(out, axis=0) / W

    for i in ctrl:  # an additive fault on a control input
        hyps.append(m.input_names[i])
        rows.append(response(B[:, i], D[:, i]))
    for j, name in enumerate(m.output_names):  # a bias step on a sensor
        unit = np.zeros(p)
        unit[j] = 1.0
        hyps.append(name)
        rows.append(response(np.zeros(n), unit))
    return tuple(hyps), np.asarray(rows)


def _on_circle(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles [rad] in [-pi, pi); those already there are returned as they are (the same bits: a
    flight that never wraps gives the numbers it gave before the wrap was added)."""
    out = a.copy()
    off = (out < -math.pi) | (out >= math.pi)
    out[off] = (out[off] + math.pi) % (2.0 * math.pi) - math.pi
    return out


def innovations(design: GustKalmanDesign, samples: Samples) -> NDArray[np.float64]:
    """Run the filter over samples; return the innovations (N, p).

    ``nu_j = dy_j - C x_j - D du_j``, ``x_{j+1} = A (x_j + K_j nu_j) + B du_j``; invalid
    measurements (dropouts) enter as zero innovation for that output; the heading's innovation is
    wrapped to [-pi, pi), and so is the heading state (a cyclic coordinate: after a full orbit it is
    where it started).
    """
    m = design.model
    if tuple(samples.output_names) != tuple(m.output_names):
        raise DesignError(f"samples have outputs {samples.output_names}, the design {m.output_names}")
    A, C = np.asarray(m.A), np.asarray(m.C)
    cols = list(design.control_columns)
    B, D = np.asarray(m.B)[:, cols], np.asarray(m.D)[:, cols]
    G = design.gains
    J = len(G) - 1
    x = np.zeros(m.n_states)
    out = np.empty((samples.n, m.n_outputs))
    du, dy, ok = samples.du, samples.dy, samples.valid
    wrap = np.array([is_wrapped(nm) for nm in m.output_names])
    wrap_x = np.array([is_wrapped(nm) for nm in m.state_names])
    for j in range(samples.n):
        nu = dy[j] - C @ x - D @ du[j]
        nu[wrap] = _on_circle(nu[wrap])  # a heading's innovation is an angle
        nu = np.where(ok[j], nu, 0.0)
        out[j] = nu
        x = A @ (x + G[min(j, J)] @ nu) + B @ du[j]
        x[wrap_x] = _on_circle(x[wrap_x])  # the heading state: on the circle
    return out


def window_means(nu: NDArray[np.float64], W: int) -> NDArray[np.float64]:
    """Mean of the last ``W`` innovations at each sample (NaN for the first ``W - 1``)."""
    c = np.cumsum(np.vstack([np.zeros(nu.shape[1]), nu]), axis=0)
    out = np.full_like(nu, np.nan)
    if len(nu) >= W:
        out[W - 1:] = (c[W:] - c[:-W]) / W
    return out


def statistic(mw: NDArray[np.float64], sigma_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """``T = m' Sigma_m^-1 m`` per sample."""
    L = np.linalg.cholesky(np.linalg.inv(sigma_m))
    z = mw @ L
    return np.sum(z * z, axis=1)


def settle_samples(design: GustKalmanDesign, settle_s: float = 2.0) -> int:
    """Samples skipped at the start of a flight (filter start, first window) [samples]."""
    return max(design.window_n, int(round(settle_s * design.rate_hz)))


@single_blas_thread  # the same bits in a study worker and in a shell (fdi_sim.threads)
def calibrate(design: GustKalmanDesign, flights: Sequence[Samples], target_per_sample: float,
              labels: Sequence[str] = ()) -> Calibration:
    """Measure ``Sigma_m`` and the empirical threshold on fault-free training flights.

    Parameters
    ----------
    design : GustKalmanDesign
    flights : sequence of Samples
        Fault-free flights at the design's rate (their first :func:`settle_samples` skipped).
    target_per_sample : float
        False-alarm probability per sample, in (0, 1).
    labels : sequence of str
        What each flight was (seed, turbulence), stored with the calibration.
    """
    if not 0.0 < target_per_sample < 1.0:
        raise DesignError(f"target_per_sample {target_per_sample} must be in (0, 1)")
    k0 = settle_samples(design)
    ms = [window_means(innovations(design, s), design.window_n)[k0:] for s in flights]
    M = np.vstack(ms)
    if len(M) * target_per_sample < 10:
        raise DesignError(f"{len(M)} training samples give fewer than 10 exceedances at {target_per_sample:g}; "
                          "fly more or longer training flights")
    sigma = np.cov(M.T)
    T = np.concatenate([statistic(x, sigma) for x in ms])
    thr = float(np.quantile(T, 1.0 - target_per_sample))
    return Calibration(sigma, thr, float(chi2.ppf(1.0 - target_per_sample, M.shape[1])), float(target_per_sample),
                       int(len(T)), tuple(labels))


@dataclass(frozen=True, eq=False)
class GustKalmanTrace:
    """A whole flight through the detector, at the detector rate."""

    t_s: NDArray[np.float64]
    statistic: NDArray[np.float64]
    alarm: NDArray[np.bool_]
    valid: NDArray[np.bool_]
    isolation: tuple[str | None, ...]
    cosine: NDArray[np.float64]


def isolate(design: GustKalmanDesign, m: NDArray[np.float64], sigma_m: NDArray[np.float64],
            min_cosine: float, since_s: float | None = None, *,
            sigma_inv: NDArray[np.float64] | None = None) -> tuple[str | None, float]:
    """The hypothesis whose signature is closest in angle to ``m`` (metric ``Sigma_m^-1``), or None.

    Parameters
    ----------
    m : NDArray
        The window-mean innovation at the alarm.
    since_s : float, optional
        Time since the alarm began [s]: onsets more than one window before it are not searched
        (the fault is then older than the window: ``k = W``).
    """
    Si = np.linalg.inv(sigma_m) if sigma_inv is None else sigma_inv
    g = design.signatures  # (h, W, p)
    W = g.shape[1]
    if since_s is not None and since_s * design.rate_hz >= W:
        g = g[:, -1:, :]
    num = np.einsum("hwp,pq,q->hw", g, Si, m)
    den = np.sqrt(np.einsum("hwp,pq,hwq->hw", g, Si, g) * float(m @ Si @ m))
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(num) / den
    best = np.nanmax(cos, axis=1)
    k = int(np.nanargmax(best))
    c = float(best[k])
    return (design.hypotheses[k] if c >= min_cosine else None), c


class GustKalmanDetector:
    """``kalman-gust-v1``: the filter, the windowed test and the isolation (module docstring).

    ``reset(rng)`` / ``step(t_s, u, y)`` with absolute ``u`` (the model's full input vector) and
    ``y`` (its outputs), as every detector; :meth:`run` does a whole :class:`Samples` at once.
    """

    id = "kalman-gust-v1"

    def __init__(self, design: GustKalmanDesign, calibration: Calibration | None = None, *,
                 min_cosine: float = 0.7, use_analytic_threshold: bool = False) -> None:
        self.design = design
        # without flights to calibrate on, the design's own prediction (analytic_calibration)
        self.calibration = calibration if calibration is not None else analytic_calibration(design, 1e-4)
        self.min_cosine = float(min_cosine)
        self.use_analytic = bool(use_analytic_threshold)
        self.hypotheses = design.hypotheses
        self.reset()

    @property
    def threshold(self) -> float:
        if self.calibration is None:
            return math.nan
        return self.calibration.threshold_analytic if self.use_analytic else self.calibration.threshold

    def reset(self, rng: np.random.Generator | None = None) -> None:
        d, m = self.design, self.design.model
        cols = list(d.control_columns)
        # everything the per-sample step needs, built once
        self._A, self._C = np.asarray(m.A), np.asarray(m.C)
        self._B, self._D = np.asarray(m.B)[:, cols].copy(), np.asarray(m.D)[:, cols].copy()
        self._u0 = np.asarray(m.u0, dtype=float)[cols].copy()
        self._y0 = np.asarray(m.y0, dtype=float)
        self._wrap = np.array([is_wrapped(nm) for nm in m.output_names])
        self._wrap_x = np.array([is_wrapped(nm) for nm in m.state_names])
        self._cols = np.asarray(cols)
        self._k0 = settle_samples(d)
        self._J = len(d.gains) - 1
        self._x = np.zeros(m.n_states)
        self._buf = np.zeros((d.window_n, m.n_outputs))
        self._j = 0
        self._alarm_j = 0
        self._Si = np.linalg.inv(self.calibration.sigma_m) if self.calibration is not None else None
        self._L = np.linalg.cholesky(self._Si) if self._Si is not None else None

    def step(self, t_s: float, u: NDArray[np.float64], y: NDArray[np.float64]) -> Residual:
        """One sample: absolute ``u`` (the model's inputs) and ``y`` (its outputs, raw: the
        heading is wrapped here); a non-finite measurement is a missing one (zero innovation for
        that output, as :func:`innovations` does for ``Samples.valid``)."""
        d, m = self.design, self.design.model
        du = np.asarray(u, dtype=float)[self._cols] - self._u0
        dy = np.asarray(y, dtype=float) - self._y0
        dy[self._wrap] = (dy[self._wrap] + math.pi) % (2.0 * math.pi) - math.pi
        ok = np.isfinite(dy)
        nu = dy - self._C @ self._x - self._D @ du
        nu[self._wrap] = _on_circle(nu[self._wrap])  # as innovations()
        nu = np.where(ok, nu, 0.0)
        self._x = self._A @ (self._x + d.gains[min(self._j, self._J)] @ nu) + self._B @ du
        self._x[self._wrap_x] = _on_circle(self._x[self._wrap_x])  # as innovations()
        self._buf[self._j % d.window_n] = nu
        self._j += 1
        if self._L is None or self._j <= self._k0:
            return finite_or_invalid(Residual(t_s, nu, 0.0, m.n_outputs, self.threshold, False, valid=False))
        mean = self._buf.mean(axis=0)
        z = mean @ self._L
        T = float(z @ z)
        alarm = T > self.threshold
        if alarm and not self._alarm_j:
            self._alarm_j = self._j
        if not alarm:
            self._alarm_j = 0
        since = (self._j - self._alarm_j) / d.rate_hz if alarm else None
        iso = isolate(d, mean, self.calibration.sigma_m, self.min_cosine, since_s=since, sigma_inv=self._Si)[0] if alarm else None
        return finite_or_invalid(Residual(t_s, mean, T, m.n_outputs, self.threshold, alarm, iso))

    def run(self, samples: Samples) -> GustKalmanTrace:
        """The whole flight: statistic, alarm, validity and isolation per sample."""
        if self.calibration is None:
            raise DesignError("kalman-gust-v1 needs a calibration (calibrate() on fault-free flights) to test")
        d = self.design
        nu = innovations(d, samples)
        mw = window_means(nu, d.window_n)
        k0 = settle_samples(d)
        T = np.full(samples.n, np.nan)
        T[k0:] = statistic(mw[k0:], self.calibration.sigma_m)
        valid = np.isfinite(T)
        alarm = valid & (np.nan_to_num(T, nan=-1.0) > self.threshold)
        iso: list[str | None] = [None] * samples.n
        cos = np.full(samples.n, np.nan)
        start = 0
        for j in np.flatnonzero(alarm):
            if j == 0 or not alarm[j - 1]:
                start = j
            iso[j], cos[j] = isolate(d, mw[j], self.calibration.sigma_m, self.min_cosine,
                                     since_s=(j - start) / d.rate_hz, sigma_inv=self._Si)
        return GustKalmanTrace(samples.t_s, T, alarm, valid, tuple(iso), cos)

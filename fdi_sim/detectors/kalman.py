"""Kalman-filter innovation tests and a multiple-model bank (Sidar 1982 sec. II-III; patent's model selection).

For a Kalman filter matched to the plant the innovations ``nu(k) = y(k) - C xh(k|k-1) - D u(k)`` are
zero-mean (Sidar eq. 10a), white (eq. 10b) and Gaussian with covariance ``S = C P C' + R``; a fault
or a model mismatch (Sidar sec. III, eq. 11-20) breaks one of these. Tests here:

* NIS, the normalized innovation squared ``nu' S^-1 nu ~ chi2(m)`` per sample;
* bias (eq. 10a) over a window of N innovations: ``N zbar' zbar ~ chi2(m)``, ``z = S^-1/2 nu``;
* whiteness (eq. 10b) over the window: ``N sum_j |R_z(j)|_F^2 ~ chi2(m^2 L)``, lags ``j = 1..L``,
  ``R_z(j) = (1/N) sum_k z(k) z(k-j)'`` (Mehra & Peschon's test, Sidar ref. 11).

Filters: the steady-state filter (gain from the discrete algebraic Riccati equation) and the
time-varying one (covariance recursion, Joseph form; models can be swapped between steps for gain
scheduling). filterpy 2.0 is the reference the tests compare against.

:class:`MultipleModelBank` runs one steady-state filter per model (e.g. clean and iced Twin
Otter) and updates the hypothesis probabilities ``p_i(k) ~ p_i(k-1) N(nu_i(k); 0, S_i)`` with a
floor ``p_min`` so a later change can still win: the patent's "select the model that fits" way of
detecting icing (claims 18, 36).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal, Sequence

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray
from scipy.stats import chi2

from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.detectors.directional_observer import DiscreteObserver
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

Array = NDArray[np.float64]


# ----------------------------------------------------------------------------- design


@dataclass(frozen=True)
class KalmanDesign:
    """A steady-state discrete Kalman filter.

    Attributes
    ----------
    model : LinearModel
        The discrete model.
    K : NDArray
        (n, m) update gain, ``xh(k|k) = xh(k|k-1) + K nu(k)``.
    P_prior, P_post : NDArray
        Steady-state prediction and update covariances.
    S : NDArray
        (m, m) innovation covariance ``C P_prior C' + R``.
    Qd, Rd : NDArray
        Process noise covariance (state coordinates, per step) and measurement-noise covariance.
    """

    model: LinearModel
    K: Array
    P_prior: Array
    P_post: Array
    S: Array
    Qd: Array
    Rd: Array

    @property
    def predictor_gain(self) -> Array:
        """``A K``: the gain of the same filter written as an observer ``xh+ = A xh + B u + A K nu``."""
        return np.asarray(self.model.A) @ self.K


def _discrete(model: LinearModel, dt_s: float | None) -> LinearModel:
    if model.is_discrete:
        return model
    if dt_s is None or dt_s <= 0:
        raise DesignError("a continuous model needs dt_s > 0 for a discrete Kalman filter")
    return model.discretize(dt_s)


def steady_state_kalman(model: LinearModel, Qd: NDArray, Rd: NDArray, G: NDArray | None = None, dt_s: float | None = None) -> KalmanDesign:
    """Steady-state Kalman filter of ``x(k+1) = A x + B u + G w``, ``y = C x + D u + v``.

    ``P = A P A' - A P C' (C P C' + R)^-1 C P A' + G Q G'`` (DARE, scipy), ``S = C P C' + R``,
    ``K = P C' S^-1``.

    Parameters
    ----------
    model : LinearModel
        Discrete model, or continuous with ``dt_s`` (zero-order hold).
    Qd : array
        Process-noise covariance per step: (q, q) with ``G``, else (n, n) in state coordinates.
    Rd : (m, m) array
        Measurement-noise covariance, positive definite.
    G : (n, q) array, optional
        Process-noise input matrix.
    dt_s : float, optional
        Sample time for a continuous model [s].

    Raises
    ------
    DesignError
        Non-PD ``Rd``, non-PSD ``Qd``, undetectable ``(A, C)`` (the DARE has no stabilizing solution).
    """
    md = _discrete(model, dt_s)
    A, C = np.asarray(md.A), np.asarray(md.C)
    n, m = md.n_states, md.n_outputs
    Rd = np.atleast_2d(np.asarray(Rd, float))
    Qd = np.atleast_2d(np.asarray(Qd, float))
    if Rd.shape != (m, m) or np.min(np.linalg.eigvalsh(0.5 * (Rd + Rd.T))) <= 0:
        raise DesignError(f"Rd must be a positive definite ({m}x{m}) measurement-noise covariance")
    Gm = np.eye(n) if G is None else np.asarray(G, float).reshape(n, -1)
    if Qd.shape != (Gm.shape[1], Gm.shape[1]) or np.min(np.linalg.eigvalsh(0.5 * (Qd + Qd.T))) < -1e-12:
        raise DesignError(f"Qd must be a positive semidefinite ({Gm.shape[1]}x{Gm.shape[1]}) covariance")
    Qx = Gm @ Qd @ Gm.T
    try:
        P = sla.solve_discrete_are(A.T, C.T, Qx, Rd)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(f"no stabilizing Kalman filter: the Riccati equation failed ({exc}); is (A, C) detectable?") from exc
    P = 0.5 * (P + P.T)
    S = C @ P @ C.T + Rd
    K = P @ C.T @ np.linalg.inv(S)
    Ppost = (np.eye(n) - K @ C) @ P
    Acl = A @ (np.eye(n) - K @ C)
    if np.max(np.abs(np.linalg.eigvals(Acl))) >= 1:
        raise DesignError("the Kalman filter is not stable: (A, C) is not detectable with this noise model")
    return KalmanDesign(md, K, P, 0.5 * (Ppost + Ppost.T), 0.5 * (S + S.T), Qx, Rd)


def observer_residual_covariance(Acl: Array, C: Array, L: Array, Q: NDArray | None, R: NDArray | None) -> Array:
    """Steady-state covariance of the residual ``r = C e + v`` of a discrete observer.

    ``P = Acl P Acl' + Q + L R L'`` (discrete Lyapunov), ``S = C P C' + R``; identity if no noise is given.
    """
    n, m = Acl.shape[0], C.shape[0]
    if Q is None and R is None:
        return np.eye(m)
    Qm = np.zeros((n, n)) if Q is None else np.asarray(Q, float)
    Rm = np.zeros((m, m)) if R is None else np.asarray(R, float)
    if np.max(np.abs(np.linalg.eigvals(Acl))) >= 1.0:
        raise DesignError("residual covariance needs a stable filter (|z| < 1)")
    P = sla.solve_discrete_lyapunov(Acl, Qm + L @ Rm @ L.T)
    S = C @ P @ C.T + Rm
    S = 0.5 * (S + S.T)
    if np.min(np.linalg.eigvalsh(S)) <= 0:
        raise DesignError("residual covariance is singular: give a measurement-noise covariance R > 0")
    return S


# ----------------------------------------------------------------------------- tests (pure functions)


def nis(nu: NDArray, S: NDArray) -> float:
    """Normalized innovation squared ``nu' S^-1 nu``."""
    nu = np.asarray(nu, float)
    return float(nu @ np.linalg.solve(S, nu))


@dataclass(frozen=True)
class WindowTest:
    """A windowed innovation test.

    Attributes
    ----------
    statistic : float
    dof : int
    threshold : float
    p_value : float
    reject : bool
        ``statistic > threshold``.
    """

    statistic: float
    dof: int
    threshold: float
    p_value: float
    reject: bool


def _whitener(S: NDArray) -> Array:
    """``W = L^-1`` with ``S = L L'``: ``z = W nu`` has identity covariance."""
    return np.linalg.inv(np.linalg.cholesky(S))


def _bias_statistic(Z: Array) -> float:
    """``N zbar' zbar`` of whitened innovations ``Z`` (N, m) (Sidar eq. 10a)."""
    zbar = Z.mean(axis=0)
    return float(Z.shape[0] * zbar @ zbar)


def _whiteness_statistic(Z: Array, n_lags: int) -> float:
    """``N sum_{j=1..L} |R_z(j)|_F^2``, ``R_z(j) = (1/N) sum_k z(k) z(k-j)'`` of whitened ``Z`` (N, m) (eq. 10b)."""
    N = Z.shape[0]
    return float(sum(np.sum((Z[j:].T @ Z[:-j]) ** 2) for j in range(1, n_lags + 1)) / N)


def _window_test(stat: float, dof: int, alpha: float) -> WindowTest:
    thr = chi2_threshold(dof, alpha)
    return WindowTest(stat, dof, thr, float(chi2.sf(stat, dof)), stat > thr)


def _check_lags(n_lags: int, window_n: int) -> None:
    if not 1 <= n_lags < window_n:
        raise DesignError(f"n_lags must be in [1, {window_n - 1}] for a window of {window_n}, got {n_lags}")


def bias_test(nu_window: NDArray, S: NDArray, alpha: float) -> WindowTest:
    """Zero-mean test of Sidar eq. 10a: ``N zbar' zbar ~ chi2(m)`` for whitened innovations.

    Parameters
    ----------
    nu_window : (N, m) array
        Innovations, oldest first.
    S : (m, m) array
        Their covariance under no fault.
    alpha : float
        False-alarm probability of the test.
    """
    Z = np.atleast_2d(np.asarray(nu_window, float)) @ _whitener(S).T
    return _window_test(_bias_statistic(Z), Z.shape[1], alpha)


def whiteness_test(nu_window: NDArray, S: NDArray, n_lags: int, alpha: float) -> WindowTest:
    """Whiteness test of Sidar eq. 10b: ``N sum_{j=1..L} |R_z(j)|_F^2 ~ chi2(m^2 L)``.

    ``R_z(j) = (1/N) sum_k z(k) z(k-j)'`` with ``z = S^-1/2 nu`` (known covariance, so no mean or
    variance is estimated; a bias also shows here).
    """
    Z = np.atleast_2d(np.asarray(nu_window, float)) @ _whitener(S).T
    N, m = Z.shape
    _check_lags(n_lags, N)
    return _window_test(_whiteness_statistic(Z, n_lags), m * m * n_lags, alpha)


# ----------------------------------------------------------------------------- detectors


class KalmanInnovationDetector:
    """Steady-state Kalman filter with an innovation test (``reset(rng)`` / ``step(t_s, u, y)``).

    The filter runs in predictor form ``xh(k+1) = A xh + B u + A K nu``
    (:class:`~fdi_sim.detectors.directional_observer.DiscreteObserver`); the whitened innovations
    ``z = S^-1/2 nu`` of the last ``window_n`` samples are kept in a preallocated ring buffer.

    Parameters
    ----------
    design : KalmanDesign
    alpha : float
        False-alarm probability per decision.
    test : {"nis", "bias", "whiteness"}
        Which statistic the ``Residual`` carries; the windowed ones are ``valid`` once the window is full.
    window_n : int
        Window length for the bias and whiteness tests [samples].
    n_lags : int
        Lags of the whiteness test.
    """

    def __init__(self, design: KalmanDesign, alpha: float = 1e-3, test: Literal["nis", "bias", "whiteness"] = "nis",
                 window_n: int = 200, n_lags: int = 5, id: str = "kalman-nis-v1") -> None:
        if test not in ("nis", "bias", "whiteness"):
            raise DesignError(f"test must be 'nis', 'bias' or 'whiteness', got {test!r}")
        _check_lags(n_lags, window_n)
        self.design, self.alpha, self.test, self.window_n, self.n_lags, self.id = design, alpha, test, window_n, n_lags, id
        self.hypotheses: tuple[str, ...] = ()
        md = design.model
        self._observer = DiscreteObserver.from_gain(md.A, md.B, md.C, md.D, design.predictor_gain, md.u0, md.y0)
        self._W = _whitener(design.S)
        m = md.n_outputs
        self._dof = m if test != "whiteness" else m * m * n_lags
        self.threshold = chi2_threshold(self._dof, alpha)
        # every z is stored at k % N and k % N + N, so the last N samples are always one contiguous slice
        self._z2 = np.zeros((2 * window_n, m))
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Zero estimate and empty window (deterministic; ``rng`` unused)."""
        self._observer.reset()
        self._n_seen = 0
        self.innovation = np.zeros(self._observer.n_outputs)

    def innovate(self, u: NDArray, y: NDArray) -> float:
        """Filter one sample; keep the innovation (``self.innovation``) and return its NIS ``nu' S^-1 nu``."""
        nu = self._observer.residual(u, y, np.empty(self._observer.n_outputs))
        self.innovation = nu
        i = self._n_seen % self.window_n
        z = np.dot(self._W, nu, out=self._z2[i])
        self._z2[i + self.window_n] = z
        self._n_seen += 1
        return float(z @ z)

    def _window(self) -> Array | None:
        """The whitened innovations of the last ``window_n`` samples, oldest first (a view), or None."""
        if self._n_seen < self.window_n:
            return None
        i = (self._n_seen - 1) % self.window_n
        return self._z2[i + 1:i + 1 + self.window_n]

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """One sample: time [s], absolute ``u``, ``y``."""
        stat = self.innovate(u, y)
        valid = True
        if self.test != "nis":
            Z = self._window()
            valid = Z is not None
            stat = 0.0 if Z is None else _bias_statistic(Z) if self.test == "bias" else _whiteness_statistic(Z, self.n_lags)
        res = Residual(float(t_s), self.innovation, stat, self._dof, self.threshold, valid and stat > self.threshold, None, None, valid)
        # a diverged state gives a NaN/inf statistic (stat = |W nu|^2 or a window of them): never a valid "no alarm"
        return res if math.isfinite(stat) else finite_or_invalid(res)

    def window_tests(self) -> tuple[WindowTest, WindowTest] | None:
        """Bias and whiteness tests on the current window, or None until it is full."""
        Z = self._window()
        if Z is None:
            return None
        m = Z.shape[1]
        return (_window_test(_bias_statistic(Z), m, self.alpha),
                _window_test(_whiteness_statistic(Z, self.n_lags), m * m * self.n_lags, self.alpha))


class TimeVaryingKalmanDetector:
    """Time-varying Kalman filter (covariance recursion) with the NIS test.

    ``S_k = C P C' + R``, ``K_k = P C' S_k^-1``, ``P+ = (I-KC) P (I-KC)' + K R K'`` (Joseph form),
    ``P <- A P+ A' + Q``. :meth:`set_model` swaps the model (gain scheduling) keeping ``xh`` and ``P``.

    Parameters
    ----------
    model : LinearModel
        Discrete model.
    Qd : (n, n) array
        Process-noise covariance in state coordinates.
    Rd : (m, m) array
    P0 : (n, n) array, optional
        Initial covariance (default ``Qd`` scaled by 100 plus a small identity).
    alpha : float
        Per-sample false-alarm probability.
    """

    def __init__(self, model: LinearModel, Qd: NDArray, Rd: NDArray, P0: NDArray | None = None, alpha: float = 1e-3,
                 id: str = "kalman-tv-nis-v1") -> None:
        if not model.is_discrete:
            raise DesignError("TimeVaryingKalmanDetector needs a discrete model (LinearModel.discretize)")
        self.id, self.alpha, self.hypotheses = id, alpha, ()
        self.Qd, self.Rd = np.asarray(Qd, float), np.asarray(Rd, float)
        n = model.n_states
        self._P0 = (100.0 * self.Qd + 1e-6 * np.eye(n)) if P0 is None else np.asarray(P0, float)
        self._I = np.eye(n)
        self.set_model(model)
        self.threshold = chi2_threshold(model.n_outputs, alpha)
        self.reset()

    def set_model(self, model: LinearModel) -> None:
        """Use another discrete model from the next step on (same state and signal dimensions)."""
        self.model = model
        self._A, self._B, self._C, self._D = model.A, model.B, model.C, model.D
        self._u0, self._y0 = model.u0, model.y0

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Zero estimate, initial covariance."""
        self._x = np.zeros(self._A.shape[0])
        self.P = self._P0.copy()
        self.S = self._C @ self.P @ self._C.T + self.Rd

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """One sample: time [s], absolute ``u``, ``y``."""
        du = np.subtract(u, self._u0)
        C, P, R = self._C, self.P, self.Rd
        nu = np.subtract(y, self._y0) - C @ self._x - self._D @ du
        S = C @ P @ C.T + R  # S = C P C' + R
        K = np.linalg.solve(S, C @ P).T  # K = P C' S^-1
        I_KC = self._I - K @ C
        Pu = I_KC @ P @ I_KC.T + K @ R @ K.T  # Joseph form
        self._x = self._A @ (self._x + K @ nu) + self._B @ du
        self.P = self._A @ Pu @ self._A.T + self.Qd
        self.S = S
        stat = float(nu @ np.linalg.solve(S, nu))
        return finite_or_invalid(Residual(float(t_s), nu, stat, len(nu), self.threshold, stat > self.threshold))


class MultipleModelBank:
    """Bank of steady-state Kalman filters with recursive hypothesis probabilities.

    ``log p_i += log N(nu_i; 0, S_i)``, normalised, floored at ``p_min`` (so a change can still be
    followed), the most probable model is "the model that fits". The statistic is the largest
    probability of a non-nominal model, against ``alarm_probability``.

    Parameters
    ----------
    designs : sequence of KalmanDesign
        One per model (same sample time and signals); ``designs[nominal]`` is the no-fault model.
    names : sequence of str
        Hypothesis names.
    nominal : int
        Index of the no-fault model.
    p_min : float
        Probability floor.
    alarm_probability : float
        Alarm when a non-nominal model is this probable.
    """

    def __init__(self, designs: Sequence[KalmanDesign], names: Sequence[str], nominal: int = 0, p_min: float = 1e-4,
                 alarm_probability: float = 0.95, prior: NDArray | None = None, id: str = "kalman-mmae-v1") -> None:
        if len(designs) < 2 or len(designs) != len(names):
            raise DesignError("a multiple-model bank needs at least two designs and one name per design")
        if not 0 <= nominal < len(designs):
            raise DesignError(f"nominal index {nominal} out of range")
        if not 0 < p_min < 1.0 / len(designs):
            raise DesignError(f"p_min must be in (0, 1/{len(designs)})")
        self.id, self.hypotheses, self.nominal, self.p_min = id, tuple(names), nominal, p_min
        self.threshold = float(alarm_probability)
        self.filters = [KalmanInnovationDetector(d, test="nis") for d in designs]
        self._logdet = np.array([np.linalg.slogdet(2 * np.pi * d.S)[1] for d in designs])
        self._prior = np.full(len(designs), 1.0 / len(designs)) if prior is None else np.asarray(prior, float) / np.sum(prior)
        self._others = np.array([i for i in range(len(designs)) if i != nominal])
        self._nis = np.empty(len(designs))
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Reset every filter and the probabilities to the prior."""
        for f in self.filters:
            f.reset(rng)
        self.probabilities = self._prior.copy()

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """Step every filter; Bayes update of the model probabilities."""
        for i, f in enumerate(self.filters):
            self._nis[i] = f.innovate(u, y)
        logp = np.log(self.probabilities) - 0.5 * (self._nis + self._logdet)  # + log N(nu; 0, S)
        p = np.exp(logp - np.max(logp))
        p /= p.sum()
        np.maximum(p, self.p_min, out=p)
        p /= p.sum()
        self.probabilities = p  # a new array every step: the record below may keep it
        best = int(np.argmax(p))
        j = int(self._others[np.argmax(p[self._others])])
        stat = float(p[j])
        alarm = stat > self.threshold
        res = Residual(float(t_s), self.filters[best].innovation, stat, 0, self.threshold, alarm,
                       self.hypotheses[j] if alarm else None, p)
        # a diverged filter has NIS inf or NaN: its probability would drop to the floor (or NaN
        # everything) and the bank would blame another model; the whole step is invalid instead
        return res if np.isfinite(self._nis).all() else replace(res, alarm=False, isolation=None, valid=False)


# ----------------------------------------------------------------------------- simulation helper


@dataclass(frozen=True)
class LinearRun:
    """A simulated run of a discrete linear model with noise.

    Attributes
    ----------
    t_s : NDArray
        (N,) times [s].
    u, y, x : NDArray
        (N, p) absolute inputs, (N, m) absolute measurements, (N, n) state deviations.
    """

    t_s: Array
    u: Array
    y: Array
    x: Array


def simulate_discrete(model: LinearModel, u_dev: NDArray, Qd: NDArray, Rd: NDArray, rng: np.random.Generator,
                      x0: NDArray | None = None) -> LinearRun:
    """Simulate ``x+ = A x + B u + w``, ``y = C x + D u + v`` (deviations), returning absolute signals.

    Parameters
    ----------
    model : LinearModel
        Discrete model.
    u_dev : (N, p) array
        Input deviations from trim.
    Qd : (n, n) array
        Process-noise covariance per step (state coordinates).
    Rd : (m, m) array
        Measurement-noise covariance.
    rng : numpy.random.Generator
    x0 : (n,) array, optional
        Initial state deviation.
    """
    if not model.is_discrete:
        raise DesignError("simulate_discrete needs a discrete model")
    A, B, C, D = (np.asarray(X, float) for X in (model.A, model.B, model.C, model.D))
    U = np.atleast_2d(np.asarray(u_dev, float))
    N, n, m = U.shape[0], A.shape[0], C.shape[0]
    W = rng.multivariate_normal(np.zeros(n), Qd, size=N, method="cholesky" if np.all(np.linalg.eigvalsh(Qd) > 0) else "eigh")
    Vn = rng.multivariate_normal(np.zeros(m), Rd, size=N)
    x = np.zeros(n) if x0 is None else np.asarray(x0, float)
    X, Y = np.empty((N, n)), np.empty((N, m))
    for k in range(N):
        X[k] = x
        Y[k] = C @ x + D @ U[k] + Vn[k]
        x = A @ x + B @ U[k] + W[k]
    t = np.arange(N) * model.dt_s
    return LinearRun(t, U + np.asarray(model.u0), Y + np.asarray(model.y0), X)

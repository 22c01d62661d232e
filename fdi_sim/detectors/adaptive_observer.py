"""Sidar's adaptive tracking observer (Sidar 1982, NASA TM-84240, sec. IV-VI, eq. 22-36).

A full-order observer ``dxh/dt = A0 xh + B0 u + K eps``, ``eps = y - C xh - D u`` (eq. 2, 4) whose
matrices adapt by

* continuous (eq. 22):  ``dA0/dt = M eps xh'``,  ``dB0/dt = N eps u'``
* discrete (eq. 23):    ``A0(k) = A0(k-1) + M eps(k) xh(k)'``,  ``B0(k) = B0(k-1) + N eps(k) u(k)'``,
  applied at the sample it is computed from: ``xh(k+1) = A0(k) xh(k) + B0(k) u(k) + K eps(k)``

so that the observer stays matched to a drifting plant (sec. III: a mismatch makes the residual
coloured and biased and ruins the false-alarm rate) and its parameter estimates become a
detection signal for slow degradations such as icing. ``mask_A`` / ``mask_B`` restrict the
adaptation to the entries that are unknown (Sidar's examples adapt only a, b, c); the full law is
the all-true mask.

Gains: Sidar's conditions (eq. 34, proved in his Appendix) are checked on
``W = A - K C - |xh|^2 M C - |u|^2 N C`` (eq. 27) over a box of ``|xh|^2``, ``|u|^2`` by
:func:`check_sidar_conditions`, which also looks for a general common Lyapunov matrix (an LMI):
``W`` is affine in the two scalars, so ``Q W + W' Q < 0`` at the four corners proves eq. 31 on the
whole box. Note the conditions concern eq. 24, which substitutes the update for the mismatch; they
are Sidar's heuristic argument, not a convergence proof of the parameter estimates.

A state that stops being finite (the unnormalized law diverges when ``gain * |regressor|^2`` is
too large) marks every later ``Residual`` invalid (``valid=False``, no alarm) until ``reset``;
``diverged_t_s`` says when. Continuous models are integrated between samples by RK4 with ``y`` interpolated linearly and ``u``
held (``input_hold="zoh"``) or interpolated (``"foh"``); discrete models use eq. 23 directly.
Sidar's sec. VI examples and the readings study are in :mod:`fdi_sim.papers.sidar_examples`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

Array = NDArray[np.float64]


# ----------------------------------------------------------------------------- conditions (eq. 27, 34)


def sidar_W(A: NDArray, K: NDArray, C: NDArray, M: NDArray, N: NDArray, xhat_norm2: float, u_norm2: float) -> Array:
    """``W = A - K C - |xh|^2 M C - |u|^2 N C`` (Sidar eq. 27)."""
    A, K, C, M, N = (np.asarray(X, float) for X in (A, K, C, M, N))
    return A - K @ C - xhat_norm2 * (M @ C) - u_norm2 * (N @ C)


@dataclass(frozen=True)
class SidarConditions:
    """Sidar's eq. 34 evaluated over a box of ``|xh|^2`` and ``|u|^2``.

    Attributes
    ----------
    corners : tuple of (float, float)
        The ``(|xh|^2, |u|^2)`` points checked (box corners plus a 5x5 grid for eq. 34d).
    q_diag : NDArray
        Diagonal of Sidar's Lyapunov matrix ``Q`` (eq. 28).
    diag_ok : NDArray
        (n,) eq. 34b/34c: ``q_ii w_ii <= -c`` at every point.
    cross_ok : NDArray
        (n, n) eq. 34d: ``sqrt(q_ii w_ii q_jj w_jj) >= (q_ii w_ij + q_jj w_ji)/2`` at every point.
    satisfied : bool
        All of eq. 34 holds.
    negative_definite : bool
        ``Q W + W' Q < 0`` at every corner with Sidar's diagonal ``Q`` (eq. 31, exact test).
    lyapunov_Q : NDArray or None
        A general ``Q > 0`` with ``Q W + W' Q < 0`` at the four corners (LMI), if one exists.
    failing : tuple of str
        Human-readable list of what fails (empty if nothing).
    """

    corners: tuple[tuple[float, float], ...]
    q_diag: Array
    diag_ok: NDArray[np.bool_]
    cross_ok: NDArray[np.bool_]
    satisfied: bool
    negative_definite: bool
    lyapunov_Q: Array | None
    failing: tuple[str, ...]


def check_sidar_conditions(
    A: NDArray, K: NDArray, C: NDArray, M: NDArray, N: NDArray, xhat_norm2_max: float, u_norm2_max: float,
    q_diag: NDArray | None = None, c_margin: float = 1e-6, find_lyapunov: bool = True,
) -> SidarConditions:
    """Check Sidar's eq. 34 (and the exact eq. 31) for given gains.

    Parameters
    ----------
    A, K, C : arrays
        Observer model and gain.
    M, N : (n, m) arrays
        Adaptation gains of eq. 22.
    xhat_norm2_max, u_norm2_max : float
        Largest ``|xh|^2`` and ``|u|^2`` expected in operation (the box).
    q_diag : (n,) array, optional
        Sidar's diagonal ``Q`` (default ones).
    c_margin : float
        Sidar's constant C > 0 of eq. 34b-c.
    find_lyapunov : bool
        Also search a general common Lyapunov ``Q`` by an LMI (cvxpy/Clarabel).
    """
    A = np.asarray(A, float)
    n = A.shape[0]
    q = np.ones(n) if q_diag is None else np.asarray(q_diag, float)
    if np.any(q <= 0):
        raise DesignError("q_diag must be positive (Sidar eq. 28: Q diagonal, positive definite)")
    pts = [(a, b) for a in np.linspace(0, xhat_norm2_max, 5) for b in np.linspace(0, u_norm2_max, 5)]
    corners = [(0.0, 0.0), (xhat_norm2_max, 0.0), (0.0, u_norm2_max), (xhat_norm2_max, u_norm2_max)]
    diag_ok = np.ones(n, bool)
    cross_ok = np.ones((n, n), bool)
    negdef = True
    Q = np.diag(q)
    for a, b in pts:
        W = sidar_W(A, K, C, M, N, a, b)
        qw = q * np.diag(W)
        diag_ok &= qw <= -c_margin  # eq. 34b, 34c
        prod = np.sqrt(np.clip(np.outer(qw, qw), 0, None))
        cross = 0.5 * (q[:, None] * W + (q[:, None] * W).T)  # (q_ii w_ij + q_jj w_ji)/2
        ok = prod >= cross  # eq. 34d as printed
        np.fill_diagonal(ok, True)
        cross_ok &= ok
        if (a, b) in corners:
            negdef &= bool(np.max(np.linalg.eigvalsh(Q @ W + W.T @ Q)) < 0)
    failing = [f"eq. 34b/c fails for state {i} (w_ii = {sidar_W(A, K, C, M, N, 0, 0)[i, i]:.4g} at |xh| = |u| = 0)"
               for i in np.flatnonzero(~diag_ok)]
    failing += [f"eq. 34d fails for states ({i}, {j})" for i, j in zip(*np.nonzero(np.triu(~cross_ok, 1)))]
    lyap = _common_lyapunov([sidar_W(A, K, C, M, N, a, b) for a, b in corners]) if find_lyapunov else None
    return SidarConditions(tuple(pts), q, diag_ok, cross_ok, bool(diag_ok.all() and cross_ok.all()), negdef, lyap, tuple(failing))


def _common_lyapunov(Ws: list[Array]) -> Array | None:
    """``Q > 0`` with ``Q W + W' Q < 0`` for every W (an LMI feasibility problem), or None."""
    import cvxpy as cp

    n = Ws[0].shape[0]
    Q = cp.Variable((n, n), symmetric=True)
    cons = [Q >> np.eye(n)]
    for W in Ws:
        X = Q @ W
        cons.append(0.5 * ((X + X.T) + (X + X.T).T) << -1e-6 * np.eye(n))
    prob = cp.Problem(cp.Minimize(cp.trace(Q)), cons)
    try:
        prob.solve(solver="CLARABEL")
    except cp.error.SolverError:
        return None
    if prob.status != "optimal" or Q.value is None:
        return None
    Qv = 0.5 * (Q.value + Q.value.T)
    ok = all(np.max(np.linalg.eigvalsh(Qv @ W + W.T @ Qv)) < 0 for W in Ws) and np.min(np.linalg.eigvalsh(Qv)) > 0
    return Qv if ok else None


@dataclass(frozen=True)
class AdaptiveGains:
    """Gains of eq. 22 with the adaptation masks.

    Attributes
    ----------
    M, N : NDArray
        (n, m) adaptation gains.
    mask_A : NDArray
        (n, n) bool, entries of ``A0`` that adapt.
    mask_B : NDArray
        (n, p) bool, entries of ``B0`` that adapt.
    conditions : SidarConditions
        The check of eq. 34 for these gains.
    """

    M: Array
    N: Array
    mask_A: NDArray[np.bool_]
    mask_B: NDArray[np.bool_]
    conditions: SidarConditions


def choose_sidar_gains(
    A: NDArray, K: NDArray, C: NDArray, m_gain: float | NDArray, n_gain: float | NDArray, xhat_norm2_max: float,
    u_norm2_max: float,
    mask_A: NDArray | None = None, mask_B: NDArray | None = None, n_inputs: int | None = None,
    dt_s: float | None = None,
) -> AdaptiveGains:
    """``M = diag(m) C^+``, ``N = diag(n) C^+`` (``M C``, ``N C`` PSD for scalar gains), checked against eq. 34.

    With ``C^+ C = I`` (all states measured) ``W = A - K C - (m |xh|^2 + n |u|^2) I``: eq. 34 holds
    on the whole box as soon as it holds for ``A - K C``, so the adaptation only adds damping.

    Parameters
    ----------
    A, K, C : arrays
    m_gain, n_gain : float or (n,) array
        Adaptation gains (Sidar's m and n), >= 0; an array gives one gain per state row, to balance
        rows whose regressors differ in size (an unnormalized gradient law diverges when
        ``gain * |regressor|^2`` is too large).
    xhat_norm2_max, u_norm2_max : float
        The box of ``|xh|^2``, ``|u|^2`` for the check.
    mask_A, mask_B : bool arrays, optional
        Adapted entries (default all).
    n_inputs : int, optional
        Number of inputs (needed when ``mask_B`` is not given).
    dt_s : float, optional
        For a discrete observer (eq. 23): the conditions are checked on the continuous-time
        equivalent ``(A - I)/dt``, ``K/dt``, ``M/dt``, ``N/dt`` (``W_d = I + dt W`` to first order).
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    n = A.shape[0]
    mg = np.broadcast_to(np.asarray(m_gain, float), (n,))
    ng = np.broadcast_to(np.asarray(n_gain, float), (n,))
    if np.any(mg < 0) or np.any(ng < 0):
        raise DesignError("adaptation gains m and n must be >= 0")
    Cp = np.linalg.pinv(C)
    M, N = mg[:, None] * Cp, ng[:, None] * Cp
    mA = np.ones((n, n), bool) if mask_A is None else np.asarray(mask_A, bool)
    if mask_B is None and n_inputs is None:
        raise DesignError("give mask_B or n_inputs")
    mB = np.ones((n, n_inputs), bool) if mask_B is None else np.asarray(mask_B, bool)
    if dt_s is None:
        cond = check_sidar_conditions(A, K, C, M, N, xhat_norm2_max, u_norm2_max)
    else:
        Kc = np.asarray(K, float) / dt_s
        cond = check_sidar_conditions((A - np.eye(n)) / dt_s, Kc, C, M / dt_s, N / dt_s, xhat_norm2_max, u_norm2_max)
    return AdaptiveGains(M, N, mA, mB, cond)


# ----------------------------------------------------------------------------- the observer


@dataclass(frozen=True)
class ParameterEstimates:
    """The adapted observer matrices at one time.

    Attributes
    ----------
    t_s : float
        Time [s].
    A, B : NDArray
        Current ``A0``, ``B0``.
    relative_change : NDArray
        Per adapted entry, ``(theta - theta_nominal) / |theta_nominal|`` (absolute change where nominal is 0);
        for a discrete model ``A0 - I`` is compared (first order: the continuous-time relative change).
    names : tuple of str
        ``"A[row,col]"`` / ``"B[row,col]"`` names with the model's signal names.
    """

    t_s: float
    A: Array
    B: Array
    relative_change: Array
    names: tuple[str, ...]


class AdaptiveObserver:
    """Sidar's adaptive tracking observer as a detector (``reset(rng)`` / ``step(t_s, u, y)``).

    Parameters
    ----------
    model : LinearModel
        Nominal model (continuous: eq. 22 integrated by RK4; discrete: eq. 23).
    K : (n, m) array
        Observer gain (for a discrete Kalman filter in predictor form, ``A K_f``).
    M, N : (n, m) arrays
        Adaptation gains.
    mask_A, mask_B : bool arrays, optional
        Adapted entries (default all).
    S : (m, m) array, optional
        Residual covariance for the chi-square statistic ``eps' S^-1 eps``; without it the
        statistic is ``eps' eps`` against ``threshold``.
    alpha : float
        Per-sample false-alarm probability (with ``S``).
    threshold : float, optional
        Threshold on ``eps' eps`` when ``S`` is not given.
    input_hold : {"zoh", "foh"}
        How ``u`` varies between samples (continuous models).
    A0, B0 : arrays, optional
        Initial observer matrices (default the model's).
    x0_hat : array, optional
        Initial state estimate (deviation from trim).
    normalized : bool
        Divide each update by ``1 + |xh|^2 + |u|^2`` (normalized gradient law; not in Sidar).
        The unnormalized law's error loop has the per-step gain ``m |xh|^2`` (eq. 24 with
        ``M C = m I``) and diverges once it passes 2; normalized, the gain stays below ``m``
        whatever the units of the states (JSBSim models: ``|xh|^2`` of 25-300 in ft, ft/s, rad).
    """

    def __init__(
        self, model: LinearModel, K: NDArray, M: NDArray, N: NDArray, mask_A: NDArray | None = None,
        mask_B: NDArray | None = None, S: NDArray | None = None, alpha: float = 1e-3, threshold: float | None = None,
        input_hold: Literal["zoh", "foh"] = "zoh", A0: NDArray | None = None, B0: NDArray | None = None,
        x0_hat: NDArray | None = None, id: str = "adaptive-observer-v1", normalized: bool = False,
    ) -> None:
        n, p, m = model.n_states, model.n_inputs, model.n_outputs
        self.model, self.id, self.normalized = model, id, bool(normalized)
        self.K = np.asarray(K, float).reshape(n, m)
        self.M, self.N = np.asarray(M, float).reshape(n, m), np.asarray(N, float).reshape(n, m)
        self.mask_A = np.ones((n, n), bool) if mask_A is None else np.asarray(mask_A, bool).reshape(n, n)
        self.mask_B = np.ones((n, p), bool) if mask_B is None else np.asarray(mask_B, bool).reshape(n, p)
        if input_hold not in ("zoh", "foh"):
            raise DesignError(f"input_hold must be 'zoh' or 'foh', got {input_hold!r}")
        self.input_hold = input_hold
        self._A_nom = np.asarray(model.A if A0 is None else A0, float).copy()
        self._B_nom = np.asarray(model.B if B0 is None else B0, float).copy()
        self._C, self._D = np.asarray(model.C, float), np.asarray(model.D, float)
        self._u0, self._y0 = np.asarray(model.u0), np.asarray(model.y0)
        self._x0 = np.zeros(n) if x0_hat is None else np.asarray(x0_hat, float).reshape(n)
        if S is not None:
            self._Sinv = np.linalg.inv(np.asarray(S, float))
            self.threshold = chi2_threshold(m, alpha)
            self._dof = m
        else:
            self._Sinv = np.eye(m)
            self.threshold = float(np.inf if threshold is None else threshold)
            self._dof = 0
        sn, inn = model.state_names, model.input_names
        self._iA = np.flatnonzero(self.mask_A.ravel())  # adapted entries, flat indices
        self._iB = np.flatnonzero(self.mask_B.ravel())
        self._rowA, self._colA = np.divmod(self._iA, n)
        self._rowB, self._colB = np.divmod(self._iB, p)
        self.hypotheses: tuple[str, ...] = tuple(
            [f"A[{sn[r]},{sn[c]}]" for r, c in zip(self._rowA, self._colA)]
            + [f"B[{sn[r]},{inn[c]}]" for r, c in zip(self._rowB, self._colB)]
        )
        # relative change of the adapted entries: (theta - nominal) / |nominal|; for a discrete model
        # A0 - I is compared (= dt * continuous A to first order), so a diagonal change is not hidden by the 1
        self._eye_A = np.eye(n).ravel()[self._iA] if model.is_discrete else np.zeros(self._iA.size)
        self._nominal = np.concatenate([self._A_nom.ravel()[self._iA] - self._eye_A, self._B_nom.ravel()[self._iB]])
        self._den = np.where(self._nominal != 0, np.abs(self._nominal), 1.0)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Back to the nominal matrices and initial estimate (deterministic; ``rng`` unused)."""
        self.A0, self.B0 = self._A_nom.copy(), self._B_nom.copy()
        self.x_hat = self._x0.copy()
        self._prev: tuple[float, Array, Array] | None = None
        self._t = 0.0
        #: time [s] of the first sample at which the state or matrices were not finite, or None
        self.diverged_t_s: float | None = None

    # -- continuous-time right-hand side: z = [xh, A0 (masked entries), B0 (masked entries)]
    def _rhs(self, xh: Array, A0: Array, B0: Array, u: Array, y: Array) -> tuple[Array, Array, Array]:
        eps = y - self._C @ xh - self._D @ u  # eq. 4
        dx = A0 @ xh + B0 @ u + self.K @ eps  # eq. 2 with the adapted matrices
        s = self._scale(xh, u)
        dA = np.outer(s * (self.M @ eps), xh) * self.mask_A  # eq. 22a
        dB = np.outer(s * (self.N @ eps), u) * self.mask_B  # eq. 22b
        return dx, dA, dB

    def _scale(self, xh: Array, u: Array) -> float:
        """1, or ``1 / (1 + |xh|^2 + |u|^2)`` for the normalized law."""
        return 1.0 / (1.0 + float(xh @ xh) + float(u @ u)) if self.normalized else 1.0

    def _integrate(self, t0: float, u0: Array, y0: Array, t1: float, u1: Array, y1: Array) -> None:
        h = t1 - t0
        if h <= 0:
            raise DesignError(f"time must increase: {t0} -> {t1}")

        def inputs(f: float) -> tuple[Array, Array]:
            u = u0 if self.input_hold == "zoh" else u0 + f * (u1 - u0)
            return u, y0 + f * (y1 - y0)

        x, A0, B0 = self.x_hat, self.A0, self.B0
        k1 = self._rhs(x, A0, B0, *inputs(0.0))
        k2 = self._rhs(x + h / 2 * k1[0], A0 + h / 2 * k1[1], B0 + h / 2 * k1[2], *inputs(0.5))
        k3 = self._rhs(x + h / 2 * k2[0], A0 + h / 2 * k2[1], B0 + h / 2 * k2[2], *inputs(0.5))
        k4 = self._rhs(x + h * k3[0], A0 + h * k3[1], B0 + h * k3[2], *inputs(1.0))
        self.x_hat = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        self.A0 = A0 + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.B0 = B0 + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """One sample: time [s], absolute ``u`` and ``y``; returns the output error and parameter scores."""
        du = np.asarray(u, float) - self._u0
        dy = np.asarray(y, float) - self._y0
        self._t = float(t_s)
        if self.diverged_t_s is not None:  # NaN from here on; skip the arithmetic (and its overflow warnings)
            nan = np.full(self._C.shape[0], np.nan)
            return Residual(float(t_s), nan, np.nan, self._dof, self.threshold, False, None,
                            np.full(len(self.hypotheses), np.nan), valid=False)
        with np.errstate(over="ignore", invalid="ignore"):  # a divergence is reported below, not warned
            if self.model.is_discrete:
                eps = dy - self._C @ self.x_hat - self._D @ du
                xh = self.x_hat
                sc = self._scale(xh, du)
                # eq. 23 at its own sample, adapted entries only: A0[i, j] += (M eps)_i xh_j, B0[i, j] += (N eps)_i u_j
                self.A0.flat[self._iA] += sc * (self.M @ eps)[self._rowA] * xh[self._colA]
                self.B0.flat[self._iB] += sc * (self.N @ eps)[self._rowB] * du[self._colB]
                self.x_hat = self.A0 @ xh + self.B0 @ du + self.K @ eps  # eq. 2, discrete, with A0(k), B0(k)
            else:
                if self._prev is not None:
                    self._integrate(*self._prev, t_s, du, dy)
                self._prev = (float(t_s), du, dy)
                eps = dy - self._C @ self.x_hat - self._D @ du
            stat = float(eps @ self._Sinv @ eps)
            scores = self._relative_change()
        if not (np.isfinite(self.x_hat).all() and np.isfinite(self.A0).all() and np.isfinite(self.B0).all()):
            self.diverged_t_s = float(t_s)
            scores = np.full(len(self.hypotheses), np.nan)
            return Residual(float(t_s), eps, stat, self._dof, self.threshold, False, None, scores, valid=False)
        alarm = stat > self.threshold
        iso = self.hypotheses[int(np.argmax(np.abs(scores)))] if alarm and scores.size else None
        return finite_or_invalid(Residual(float(t_s), eps, stat, self._dof, self.threshold, alarm, iso, scores))

    def _relative_change(self) -> Array:
        cur = np.concatenate([self.A0.ravel()[self._iA] - self._eye_A, self.B0.ravel()[self._iB]])
        cur -= self._nominal
        cur /= self._den
        return cur

    def estimates(self) -> ParameterEstimates:
        """Current ``A0``, ``B0`` and the relative change of every adapted entry from nominal."""
        return ParameterEstimates(self._t, self.A0.copy(), self.B0.copy(), self._relative_change(), self.hypotheses)

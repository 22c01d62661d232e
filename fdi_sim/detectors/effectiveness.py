"""Effectiveness of one actuator from the innovations of ``kalman-gust-v1`` (recursive weighted least squares).

When the bank has isolated an actuator (hypothesis ``<surface>_cmd_norm``), its command can be
rescaled by the actuator's effectiveness ``e`` where the estimate allows. A loss of effectiveness
delivers ``v = e h`` (:mod:`fdi_sim.faults.laws`, ``h`` the healthy position, trim included). In
the filter's input coordinates (the pilot's commands) that is an additive fault on input ``i``::

    f_j = (e - 1) (u_j + t) = a u_j + c,     a = e - 1,  c = a t

with ``u_j`` the absolute command of input ``i`` (averaged over the sample's interval, the time
convention of :mod:`fdi_sim.detectors.samples`) and ``t`` an unknown trim offset in command units
(the DHC-6's pitch trim, 0.26). The filter (:mod:`fdi_sim.detectors.gust_kalman_stream`) is
linear, so the innovations the fault adds are ``a phi_j + c psi_j``, the responses of the filter's
error dynamics to ``u_j`` and to 1 on input ``i``. With the plant ``x+ = A x + B (du + f)``,
``y = C x + D (du + f)`` and the filter ``x^+ = A (x^ + K nu) + B du``, the error ``err = x - x^``
obeys, per sample in the kernel's order (predict and innovate with the state before the update,
then update; the active point ``c`` and the gain ``K = G_c(min(j, J))`` the filter used at that
sample)::

    nu_f(j)   = C_c err(j) + d_c f_j            (0 for a missing or excluded measurement)
    err(j+1)  = A_c (err(j) - K nu_f(j)) + b_c f_j

(``b_c``, ``d_c`` the columns of input ``i`` of the paired model's ``B`` and ``D``; a point switch
moves the filter's and the plant's deviation alike, so ``err`` carries over.)

Two nuisances, for an estimator started after the onset (at the isolation) of a fault whose growth
it does not know (the shipped DHC-6 loss ramps over 2 s from 12 s; started at 13 s):

- *Before the start.* What the fault did before the start sits in the filter's error state
  ``err(j0)``, whose free response (the transition of ``A (I - K_j C)``) is in every later
  innovation. ``err(j0) = V z`` is estimated beside ``(a, c)``: ``V`` holds the ``R`` (12)
  directions of the error state that a fault on input ``i`` reaches and that the innovations then
  show, the leading Hankel singular vectors of the error dynamics with the gains the filter uses
  around ``j0`` (30 s each way, computed at the first :meth:`~EffectivenessEstimator.update`,
  :func:`initial_error_basis`; each scaled to unit whitened output energy).
- *After the start.* The fault may still be growing. A deficit that dies out with the time
  constant ``settle_s`` (1 s), ``f_j += rho^(j - j0) (a' u_j + c')``, is estimated beside them
  (two more regressors, driven by ``rho^(j - j0) u_j`` and ``rho^(j - j0)``).

On the filter's own linear model (noise-free) the estimate is then exact (1e-6, the prior's pull)
however the fault grew before the start; without either nuisance it is not. On the real flight
(at 60 s): neither ``e = 0.33``, the initial error only 0.36, the deficit only 0.49, both 0.51.

Regression, ``theta = (a, c, a', c', z)``, ``X_j`` (p x q) the regressors' innovations::

    M = sum_j X_j' W_j X_j + Lambda,    h = sum_j X_j' W_j nu_j,    theta = M^-1 h

``W_j = S_w^-1`` of the active point (at a dropout the inverse of the present rows' block).
``Lambda`` is a vague prior (std 10 on ``a, c, a', c'``, 1e4 on ``z``) so that ``M`` is invertible
before the data identify it; it is negligible once they do.

Weights (``weights``). ``"design"``: ``S_w = design.S``, the innovation covariance the filter
predicts; were its model right, the innovations would be white with that covariance and this
least squares the maximum-likelihood (GLR) estimate of the fault (Willsky & Jones 1976).
``"conservative"`` (default): ``S_w = S^1/2 max(I, S^-1/2 (W Sigma_m) S^-1/2) S^1/2`` (eigenvalues
clamped at 1), ``Sigma_m`` the calibration's covariance of the ``W``-sample window mean: the
design's covariance, inflated in the directions where the fault-free training flights measured
more (model error, colored gusts), never deflated (a window mean's variance is below ``S / W``
when the innovations are negatively correlated, which says nothing about their size).
``"calibration"``: ``S_w = W Sigma_m`` alone. With the analytic calibration (``Sigma_m = S / W``)
all three are the design's. Measured (estimate at 60 s, started 1 s after the onset; ``Sigma_m``
from six 60 s fault-free flights; free = the same flight without the fault)::

    weights        DHC-6 0.5   DHC-6 free   F-16 0.6 (moderate turb.)   F-16 free
    design         0.51        0.94         0.59                        0.79 (usable)
    calibration    0.46        0.87 (usable) 0.76                        1.08
    conservative   0.50        0.96         0.73                        1.03

The F-16's design weights trust channels (theta, h, hdot) whose 1 s window means vary 30-230 times
more than ``S / W`` says in moderate turbulence: the fault-free estimate is 0.79, usable, wrong.

Why 0.73 and not 0.6 on the F-16: its linear model holds the fly-by-wire pitch loop (q, nz and
alpha fed back through the same elevator, with an integrator), so a loss of the *surface* is not
an additive fault on the *command*: the loop makes up part of it. What is estimated is the
effectiveness of the command path in the filter's model (the aircraft's q and nz responses to
the doublets drop by only 5-10 %). That is the number a command rescale needs, but it depends on
the maneuvers' frequencies (0.68 at 30 s, 0.78 at 60 s over eight seeds).

Standard deviation: ``M^-1`` assumes white innovations of covariance ``S_w``; the real ones are
correlated in time and larger. The std reported is the larger of ``sqrt((M^-1)_aa max(1, s^2))``,
``s^2`` the weighted residual variance per scalar degree of freedom, and the batch-means
sandwich::

    cov = M^-1 (sum_b g_b g_b') M^-1,   g_b = h_b - M_b theta

over consecutive batches of ``batch_s`` (2 s) counted from the start (``h_b``, ``M_b`` the batch's
sums; the open batch included). It needs ``sum_b h_b h_b'``, ``sum_b M_b (x) h_b`` and
``sum_b M_b (x) M_b``, kept as running sums, so every number is a sum over samples and batches in
their order: the results do not depend on how the samples are cut into :meth:`update` calls
(bitwise). Over ten seeds of the DHC-6 loss the spread at 60 s was 0.019 against a mean std of
0.017, but the mean was 0.52 (0.55 at 20 s): a bias of model error and of the ramp that no std of
this kind covers. Fault-free (ten seeds): mean 0.98, spread 0.038, mean std 0.029. F-16 (eight
seeds, conservative weights): 0.78 (spread 0.037, std 0.061) and fault-free 1.06 (0.039, 0.070).

Excitation: the information on ``a`` with the other parameters marginalized, ``1 / (M^-1)_aa``
[-] (whitened innovation energy per unit ``a^2``; the prior adds 0.01). :meth:`usable` asks for
a std below ``max_std``, an estimate in ``[lo, hi]`` and a significant loss, ``1 - e >= 2 std``
(the DHC-6's fault-free estimate wanders to 0.94 +- 0.045 by 60 s: below ``hi``, not a loss).

Cost (measured, warm, q = 16): 80-120 us per :meth:`update` of a 0.25 s block (5 samples),
60-180 us per :attr:`estimate` (after an update; cached until the next), 10-40 ms once, at the
first update (the nuisance basis), and the kernels' first compilation (cached on disk).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

#: length of a batch of the sandwich covariance [s]
DEFAULT_BATCH_S = 2.0
#: time constant of the post-start deficit (a fault still growing) [s]
DEFAULT_SETTLE_S = 1.0
#: leading Hankel directions of the initial-error nuisance (the DHC-6's estimates agree to 0.006
#: for 6 to 20 of them; the cost grows with (4 + R)^2 per sample and (4 + R)^4 per batch)
DEFAULT_NUISANCE_DIM = 12
#: Hankel singular values at or below this fraction of the largest are dropped (numerical rank) [-]
NUISANCE_RANK_TOL = 1e-9
#: past and future horizon of the Hankel operator [s]
HANKEL_HORIZON_S = 30.0
#: prior standard deviations of the fault parameters (a, c, a', c') [-] and of the nuisance z [-]
PRIOR_STD_FAULT = 10.0
PRIOR_STD_Z = 1e4
#: the weightings of the regression (module docstring)
WEIGHTS = ("conservative", "design", "calibration")


@numba.njit(cache=True, nogil=True)
def _gramians(A, b, C, d, G, WhC, j0, n_past, n_steps, Wc, Wo):  # pragma: no cover - compiled
    """``Wc = R R'``, ``R[:, k] = Phi(j0, m + 1) bt_m`` (``m = j0 - 1 - k``), and ``Wo = O' O``,
    ``O[k] = S^-1/2 C Phi(j0 + k, j0)`` (:func:`initial_error_basis`), with ``Phi`` the products
    of ``Acl_j = A - A K_j C``."""
    n = A.shape[0]
    J = G.shape[0] - 1
    Phi = np.eye(n)
    for k in range(n_past):
        m = j0 - 1 - k
        AK = np.dot(A, np.ascontiguousarray(G[min(m, J)]))
        r = np.dot(Phi, b - np.dot(AK, d))  # bt_m = b - A K_m d
        Wc += np.outer(r, r)
        Phi = np.dot(Phi, A - np.dot(AK, C))
    Phi = np.eye(n)
    for k in range(n_steps):
        Ok = np.dot(WhC, Phi)
        Wo += np.dot(Ok.T, Ok)
        AK = np.dot(A, np.ascontiguousarray(G[min(j0 + k, J)]))
        Phi = np.dot(A - np.dot(AK, C), Phi)


def _sqrt_factor(W: NDArray[np.float64]) -> NDArray[np.float64]:
    """``L`` with ``L L' = W`` for a positive semi-definite ``W`` (eigenvalues below 0 as 0)."""
    lam, U = np.linalg.eigh(0.5 * (W + W.T))
    return U * np.sqrt(np.maximum(lam, 0.0))


def initial_error_basis(A: NDArray[np.float64], b: NDArray[np.float64], C: NDArray[np.float64],
                        d: NDArray[np.float64], G: NDArray[np.float64], S: NDArray[np.float64], j0: int, n_steps: int,
                        n_dirs: int, rel_tol: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Directions of the filter's error state at sample ``j0`` that a past fault on one input leaves
    and the later innovations show.

    The error dynamics of the filter with the gains it uses (``K_j = G[min(j, J)]``) and a fault
    ``f`` on the input with columns ``b``, ``d``: ``err(j+1) = Acl_j err(j) + bt_j f_j``,
    ``Acl_j = A (I - K_j C)``, ``bt_j = b - A K_j d``; the whitened innovation of a free response
    is ``S^-1/2 C err``. The Hankel operator from the fault samples ``j0 - n_steps .. j0 - 1`` (from
    0 if ``j0`` is smaller) to the innovations ``j0 .. j0 + n_steps - 1`` is ``O R``, with
    ``R = [bt_{j0-1}, Acl_{j0-1} bt_{j0-2}, ...]`` and ``O = [S^-1/2 C; S^-1/2 C Acl_{j0}; ...]``;
    its ``k``-th right singular vector ``w_k`` gives the state ``R w_k``, whose free response has
    the energy ``sigma_k^2``.

    Parameters
    ----------
    A, b, C, d, S : NDArray
        (n, n), (n,), (p, n), (p,), (p, p): the paired model, the input's columns and the
        innovation covariance of the weighting.
    G : NDArray
        (J + 1, n, p) the filter's gains by sample (the last one from then on).
    j0 : int
        The filter's sample count at the start.
    n_steps : int
        Past and future horizon [samples].
    n_dirs : int
        Directions returned.
    rel_tol : float
        Directions with ``sigma_k <= rel_tol sigma_0`` are returned as zero columns.

    Returns
    -------
    V : NDArray
        (n, n_dirs) the states ``R w_k / sigma_k`` (unit whitened output energy over the
        horizon), largest ``sigma`` first; zero columns past the rank (none at all for ``j0 = 0``:
        nothing came before).
    sigma : NDArray
        The Hankel singular values [whitened innovation / command unit].
    """
    n, p = A.shape[0], C.shape[0]
    V = np.zeros((n, n_dirs))
    n_past = min(int(n_steps), int(j0))
    if n_past == 0:
        return V, np.zeros(0)
    Wh = np.linalg.cholesky(np.linalg.inv(S)).T  # Wh' Wh = S^-1
    Wc, Wo = np.zeros((n, n)), np.zeros((n, n))
    _gramians(np.ascontiguousarray(A), np.ascontiguousarray(b), np.ascontiguousarray(C), np.ascontiguousarray(d),
              np.ascontiguousarray(G), np.ascontiguousarray(Wh @ C), int(j0), n_past, int(n_steps), Wc, Wo)
    Lc = _sqrt_factor(Wc)  # R = Lc Q' for an orthonormal Q
    Fo = _sqrt_factor(Wo).T  # Fo' Fo = O' O
    _, sig, vt = np.linalg.svd(Fo @ Lc)  # the singular values of O R
    for k in range(min(n_dirs, len(sig))):
        if sig[k] > rel_tol * sig[0] and sig[k] > 0.0:
            V[:, k] = Lc @ vt[k] / sig[k]  # R w_k / sigma_k
    return V, sig


def conservative_covariance(S: NDArray[np.float64], S_measured: NDArray[np.float64]) -> NDArray[np.float64]:
    """``S^1/2 max(I, S^-1/2 S_m S^-1/2) S^1/2``: ``S`` inflated where ``S_m`` is larger, never deflated.

    Parameters
    ----------
    S : NDArray
        (p, p) the design's innovation covariance.
    S_measured : NDArray
        (p, p) a measured one (``W Sigma_m``).
    """
    L = np.linalg.cholesky(S)
    Li = np.linalg.inv(L)
    Wm = Li @ S_measured @ Li.T
    lam, Q = np.linalg.eigh(0.5 * (Wm + Wm.T))
    out = L @ ((Q * np.maximum(lam, 1.0)) @ Q.T) @ L.T
    return 0.5 * (out + out.T)


@numba.njit(cache=True, nogil=True)
def _update(A, b, C, d, G, Wt, S, V, cu, c1, rho, u, nu, ok, point, g0, L,
            X, wk, st, Mb, hb, M, h, acc, Shh, SMh, SMM):  # pragma: no cover - compiled
    """Regressors and sufficient statistics for ``N`` samples (module docstring).

    Fault regressor ``a < F`` is driven by ``f = (cu_a u + c1_a) wk_a``, ``wk_a = rho_a^(j - j0)``;
    the last ``R`` regressors are the nuisance's free responses. ``X`` (q, n) their error states;
    ``st`` = [started, samples, position in batch, closed batches, scalar observations];
    ``acc`` = [sum nu'W nu of the closed batches, of the open batch].
    """
    n = A.shape[1]
    p = C.shape[1]
    q = X.shape[0]
    R = V.shape[1]
    F = q - R
    J = G.shape[1] - 1
    N = u.shape[0]
    v = np.empty((q, p))
    wv = np.empty((q, p))
    tmp = np.empty(n)
    Wm = np.empty((p, p))
    y = np.empty(p)
    idx = np.empty(p, dtype=np.int64)
    for j in range(N):
        c = point[j]
        if st[0] == 0:  # the start: fault regressors from zero, the nuisance from the start's basis
            for a in range(q):
                for k in range(n):
                    X[a, k] = 0.0
            for r in range(R):
                for k in range(n):
                    X[F + r, k] = V[k, r]
            for a in range(F):
                wk[a] = 1.0
            st[0] = 1
        g = g0 + j  # the filter's gain index at this sample, min(j, J)
        if g > J:
            g = J
        # --- weight: S_w^-1, or the inverse of the present rows' block ---------------------------
        m_ok = 0
        for r in range(p):
            if ok[j, r]:
                idx[m_ok] = r
                m_ok += 1
        if m_ok == p:
            for r in range(p):
                for s in range(p):
                    Wm[r, s] = Wt[c, r, s]
        else:
            for r in range(p):
                for s in range(p):
                    Wm[r, s] = 0.0
            if m_ok > 0:
                sub = np.empty((m_ok, m_ok))
                for r in range(m_ok):
                    for s in range(m_ok):
                        sub[r, s] = S[c, idx[r], idx[s]]
                inv = np.linalg.inv(sub)
                for r in range(m_ok):
                    for s in range(m_ok):
                        Wm[idx[r], idx[s]] = inv[r, s]
        for r in range(p):
            y[r] = nu[j, r] if ok[j, r] else 0.0
        # --- regressors: nu_f = C err + d f;  err = A (err - K nu_f) + b f ----------------------------
        for a in range(q):
            f = (cu[a] * u[j] + c1[a]) * wk[a] if a < F else 0.0
            for r in range(p):
                if ok[j, r]:
                    s_ = 0.0
                    for k in range(n):
                        s_ += C[c, r, k] * X[a, k]
                    v[a, r] = s_ + d[c, r] * f
                else:
                    v[a, r] = 0.0
            for k in range(n):
                s_ = X[a, k]
                for r in range(p):
                    s_ -= G[c, g, k, r] * v[a, r]
                tmp[k] = s_
            for k in range(n):
                s_ = 0.0
                for m in range(n):
                    s_ += A[c, k, m] * tmp[m]
                X[a, k] = s_ + b[c, k] * f
        for a in range(F):
            wk[a] *= rho[a]
        # --- open batch: M_b += X' W X, h_b += X' W nu, nu' W nu -----------------------------------
        for a in range(q):
            for r in range(p):
                s_ = 0.0
                for s in range(p):
                    s_ += Wm[r, s] * v[a, s]
                wv[a, r] = s_
        for a in range(q):
            for a2 in range(a, q):
                s_ = 0.0
                for r in range(p):
                    s_ += wv[a, r] * v[a2, r]
                Mb[a, a2] += s_
                if a2 != a:
                    Mb[a2, a] = Mb[a, a2]
            s_ = 0.0
            for r in range(p):
                s_ += wv[a, r] * y[r]
            hb[a] += s_
        s_ = 0.0
        for r in range(p):
            t_ = 0.0
            for s in range(p):
                t_ += Wm[r, s] * y[s]
            s_ += y[r] * t_
        acc[1] += s_
        st[1] += 1
        st[4] += m_ok
        st[2] += 1
        if st[2] == L:  # close the batch: the sandwich's sums, then fold it into M and h
            for a in range(q):
                for a2 in range(q):
                    Shh[a, a2] += hb[a] * hb[a2]
                    for k in range(q):
                        SMh[a, k, a2] += Mb[a, k] * hb[a2]
                        for l in range(q):
                            SMM[a, k, a2, l] += Mb[a, k] * Mb[a2, l]
            for a in range(q):
                h[a] += hb[a]
                hb[a] = 0.0
                for a2 in range(q):
                    M[a, a2] += Mb[a, a2]
                    Mb[a, a2] = 0.0
            acc[0] += acc[1]
            acc[1] = 0.0
            st[2] = 0
            st[3] += 1


@dataclass(frozen=True)
class EffectivenessSummary:
    """The estimate with what it rests on (module docstring).

    Attributes
    ----------
    effectiveness : float
        ``e = 1 + a`` [-] (NaN before the first sample).
    std : float
        Its standard deviation [-]: the larger of ``std_model`` and ``std_sandwich``.
    excitation : float
        Information on ``a``, ``1 / (M^-1)_aa`` [-].
    offset : float
        ``c = (e - 1) t`` [command units].
    std_model : float
        ``sqrt((M^-1)_aa max(1, s^2))`` [-].
    std_sandwich : float
        Batch-means sandwich standard deviation of ``a`` [-].
    residual_variance : float
        ``s^2``, weighted residual energy per scalar degree of freedom [-] (1 for white
        innovations of covariance ``S_w``).
    n_samples : int
        Samples since the start.
    n_batches : int
        Closed batches of the sandwich.
    """

    effectiveness: float
    std: float
    excitation: float
    offset: float
    std_model: float
    std_sandwich: float
    residual_variance: float
    n_samples: int
    n_batches: int


class EffectivenessEstimator:
    """Effectiveness of one input of a :class:`GustKalmanStream` from its innovations (module docstring).

    Start it (construct or :meth:`reset`) when the actuator is isolated, then give every later
    block of the stream to :meth:`update`, after the stream's ``process`` of that block.

    Parameters
    ----------
    stream : GustKalmanStream
        The filter whose innovations are fed. Its matrices, gains, design covariances and
        calibrations are read (the private arrays ``_A``, ``_B``, ``_C``, ``_D``, ``_G``: the
        stream exposes no public view of them), never changed.
    input_name : str
        One of ``stream.input_names`` (``"elevator_cmd_norm"``).
    weights : str
        ``"conservative"`` (default), ``"design"`` or ``"calibration"`` (module docstring).
    settle_s : float or None
        Time constant of the post-start deficit [s]; None: no deficit (the fault is taken as
        constant from the start).
    batch_s : float
        Batch length of the sandwich covariance [s].
    nuisance_dim : int
        Leading Hankel directions of the initial-error nuisance (0: none, the fault's history
        before the start ignored).

    Raises
    ------
    DesignError
        An input the stream does not have or an unknown weighting (with a "did you mean"), a
        non-positive time.
    """

    def __init__(self, stream: Any, input_name: str, *, weights: str = "conservative",
                 settle_s: float | None = DEFAULT_SETTLE_S, batch_s: float = DEFAULT_BATCH_S,
                 nuisance_dim: int = DEFAULT_NUISANCE_DIM) -> None:
        names = tuple(stream.input_names)
        _check_choice(input_name, names, f"{stream.id} has no input")
        _check_choice(weights, WEIGHTS, "no weighting")
        if not batch_s > 0.0 or (settle_s is not None and not settle_s > 0.0):
            raise DesignError(f"batch_s ({batch_s}) and settle_s ({settle_s}) must be > 0 s")
        if not 0 <= int(nuisance_dim) <= stream._A.shape[1]:
            raise DesignError(f"nuisance_dim {nuisance_dim} must be in 0 .. {stream._A.shape[1]} (the filter's states)")
        self.stream = stream
        self.input_name = input_name
        self.input_index = i = names.index(input_name)
        self.weights = weights
        self.batch_n = max(1, int(round(float(batch_s) * stream.rate_hz)))
        self._A = stream._A
        self._b = np.ascontiguousarray(stream._B[:, :, i])
        self._C = stream._C
        self._d = np.ascontiguousarray(stream._D[:, :, i])
        self._G = stream._G
        designs, cals = stream.schedule.designs, stream.schedule.calibrations
        covs = []
        for dz, cz in zip(designs, cals):
            S0 = np.asarray(dz.S, dtype=float)
            Sm = np.asarray(cz.sigma_m, dtype=float) * dz.window_n  # W Sigma_m
            covs.append({"design": S0, "calibration": Sm}.get(weights) if weights != "conservative"
                        else conservative_covariance(S0, Sm))
        self._S = np.ascontiguousarray(np.stack(covs))
        self._Wt = np.ascontiguousarray(np.stack([np.linalg.inv(c) for c in self._S]))
        self._n_steps = int(round(HANKEL_HORIZON_S * stream.rate_hz))
        #: nuisance directions (the initial error's, computed at the start)
        self.n_nuisance = R = int(nuisance_dim)
        # fault regressors: a (u), c (1), and the deficit a' (rho^k u), c' (rho^k)
        cu, c1, rho = [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]
        if settle_s is not None:
            r_ = math.exp(-1.0 / (float(settle_s) * stream.rate_hz))
            cu, c1, rho = cu + [1.0, 0.0], c1 + [0.0, 1.0], rho + [r_, r_]
        self._cu, self._c1, self._rho = np.array(cu), np.array(c1), np.array(rho)
        F = len(cu)
        self._q = F + R
        self._prior = np.diag([PRIOR_STD_FAULT ** -2] * F + [PRIOR_STD_Z ** -2] * R)
        self.reset()

    def reset(self) -> None:
        """Forget every sample: the next :meth:`update` is the start."""
        q, n = self._q, self._A.shape[1]
        self._X = np.zeros((q, n))
        self._wk = np.ones(len(self._cu))
        self._st = np.zeros(5, dtype=np.int64)
        self._Mb = np.zeros((q, q))
        self._hb = np.zeros(q)
        self._M = np.zeros((q, q))
        self._h = np.zeros(q)
        self._acc = np.zeros(2)
        self._Shh = np.zeros((q, q))
        self._SMh = np.zeros((q, q, q))
        self._SMM = np.zeros((q, q, q, q))
        self._summary: EffectivenessSummary | None = None
        self._V = np.zeros((self._A.shape[1], self.n_nuisance))
        #: the Hankel singular values of the start (what the nuisance keeps, and drops)
        self.hankel_sigma = np.zeros(0)

    def update(self, u: NDArray[np.float64], nu: NDArray[np.float64], point: NDArray[np.int64],
               gain_index_start: int, ok: NDArray[np.bool_] | None = None) -> None:
        """``N`` samples after the estimator was started: the commands the stream got, the
        innovations and active points it output.

        Parameters
        ----------
        u : NDArray
            (N, len(stream.input_names)) absolute commands, as given to ``stream.process``.
        nu : NDArray
            (N, p) the stream's innovations (``out_innovation``).
        point : NDArray of int64
            (N,) the active points (``out_point``).
        gain_index_start : int
            The stream's sample count at ``u[0]`` (samples since its reset; its gain index before
            the cap at the steady gain). The stream keeps it in ``stream._st[0]``: read it before
            the ``process`` call, or count the samples given to it.
        ok : NDArray of bool, optional
            (N, p) usable measurements (the ``ok`` given to the stream). Default: ``nu != 0`` (the
            stream writes an exact 0 for a missing or excluded measurement, and a measured one is
            exactly 0 with probability 0).
        """
        nu = np.ascontiguousarray(nu, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        N, p, m = nu.shape[0], self._C.shape[1], len(self.stream.input_names)
        if nu.shape != (N, p) or u.shape != (N, m):
            raise DesignError(f"update needs u (N, {m}) and nu (N, {p}) with the same N; got {u.shape} and {nu.shape}")
        pt = np.ascontiguousarray(point, dtype=np.int64)
        okm = (nu != 0.0) if ok is None else np.ascontiguousarray(ok, dtype=np.bool_)
        if pt.shape != (N,) or okm.shape != (N, p):
            raise DesignError(f"update needs point ({N},) and ok ({N}, {p}); got {pt.shape} and {okm.shape}")
        if N == 0:
            return
        if self._st[0] == 0 and self.n_nuisance:  # the start: the initial error's directions
            c = int(pt[0])
            self._V, self.hankel_sigma = initial_error_basis(
                self._A[c], self._b[c], self._C[c], self._d[c], self._G[c], self._S[c], int(gain_index_start),
                self._n_steps, self.n_nuisance, NUISANCE_RANK_TOL)
        _update(self._A, self._b, self._C, self._d, self._G, self._Wt, self._S, self._V, self._cu, self._c1,
                self._rho, np.ascontiguousarray(u[:, self.input_index]), nu, okm, pt, int(gain_index_start),
                self.batch_n, self._X, self._wk, self._st, self._Mb, self._hb, self._M, self._h, self._acc,
                self._Shh, self._SMh, self._SMM)
        self._summary = None

    @property
    def n_samples(self) -> int:
        """Samples since the start."""
        return int(self._st[1])

    def summary(self) -> EffectivenessSummary:
        """The estimate and what it rests on (module docstring); computed once per update."""
        if self._summary is not None:
            return self._summary
        nan = math.nan
        N = int(self._st[1])
        if N == 0:
            self._summary = EffectivenessSummary(nan, nan, 0.0, nan, nan, nan, nan, 0, 0)
            return self._summary
        q = self._q
        Mb, hb = self._Mb, self._hb
        Mt = self._M + Mb
        ht = self._h + hb
        P = np.linalg.inv(Mt + self._prior)
        P = 0.5 * (P + P.T)
        th = P @ ht
        # weighted residual energy: nu'W nu - 2 theta'h + theta'M theta
        rss = float(self._acc[0] + self._acc[1] - 2.0 * th @ ht + th @ Mt @ th)
        dof = int(self._st[4]) - q
        s2 = rss / dof if dof > 0 else nan
        var_m = float(P[0, 0])
        # sandwich meat sum_b g_b g_b', g_b = h_b - M_b theta: the closed batches from their sums, then the open one
        Mh = np.tensordot(self._SMh, th, axes=([1], [0]))  # sum_b (M_b theta) h_b'
        MM = np.tensordot(np.tensordot(self._SMM, th, axes=([3], [0])), th, axes=([1], [0]))  # sum_b M_b theta theta' M_b
        Om = self._Shh - Mh - Mh.T + MM
        if self._st[2] > 0:
            g = hb - Mb @ th
            Om = Om + np.outer(g, g)
        var_s = float(P[0] @ Om @ P[0])
        std_m = math.sqrt(var_m * max(1.0, s2)) if math.isfinite(s2) else math.sqrt(var_m)
        std_s = math.sqrt(max(var_s, 0.0))
        self._summary = EffectivenessSummary(1.0 + float(th[0]), max(std_m, std_s), 1.0 / var_m, float(th[1]),
                                             std_m, std_s, s2, N, int(self._st[3]))
        return self._summary

    @property
    def estimate(self) -> tuple[float, float, float]:
        """``(effectiveness [-], std [-], excitation [-])`` (:meth:`summary` has more)."""
        s = self.summary()
        return s.effectiveness, s.std, s.excitation

    def usable(self, max_std: float = 0.1, lo: float = 0.2, hi: float = 0.97, z: float = 2.0) -> bool:
        """The estimate allows a rescale: known to ``max_std`` [-], in ``[lo, hi]`` [-], and a
        significant loss, ``1 - e >= z std`` (a healthy actuator whose estimate has wandered
        below ``hi`` is not rescaled)."""
        e, sd, _ = self.estimate
        return bool(math.isfinite(e) and math.isfinite(sd) and sd <= max_std and lo <= e <= hi
                    and 1.0 - e >= z * sd)


def _check_choice(value: str, choices: tuple[str, ...], what: str) -> None:
    if value not in choices:
        close = difflib.get_close_matches(str(value), choices, n=1, cutoff=0.5)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise DesignError(f"{what} {value!r} (one of: {', '.join(choices)}){hint}")

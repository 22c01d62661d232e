"""The per-sample loop of ``cusum-residual-v1``: one compiled call per block of samples.

Per detector sample ``j`` (``u_j`` the command averaged over the interval ending at ``t_j``,
``y_j`` the measurement at ``t_j``; ``fdi_sim.detectors.samples``), with the predicted state
``xhat = xhat_{j|j-1}`` carried in ``x`` (deviation from trim)::

    du_j   = u_j - u0                                     (gusts: deviation 0)
    yhat_j = C xhat + D du_j                              predicted output deviation
    nu_j   = wrap(y_j - y0) - yhat_j                      innovation (headings wrapped to [-pi, pi))
    xhat  <- A xhat + B du_j + K nu_j                     steady-state predictor (design.py)
    e_j    = nu_j[i] / sqrt(Sigma_ii)                     normalized residual of the signal [-]
    g+_j   = max(0, g+_{j-1} + e_j - k)                   two-sided CUSUM (Page 1954;
    g-_j   = max(0, g-_{j-1} - e_j - k)                    Basseville & Nikiforov 1993, sec. 2.2)
    T_j    = max(g+_j, g-_j)                              statistic [-], alarm when T_j > h

A sample with any used measurement not ``ok`` or not finite (or a command not finite) has no
innovation: ``xhat <- A xhat + B du_j`` (a non-finite command counts as 0), ``e_j = NaN``, the
CUSUM is held and the sample is invalid. After a reset and after every such sample the next
``settle_n`` samples update the filter but not the CUSUM (also invalid): the prediction error
covariance is back near its steady state ``Sigma`` before ``e_j`` is tested again.

State, all in arrays owned by the detector (so any cut of a flight into blocks gives the same
bits): ``x`` (n,) the predicted state, ``g`` (2,) ``(g+, g-)``, ``st`` (2,) ``(samples since reset,
settle samples left)``.
"""
from __future__ import annotations

import math

import numba
import numpy as np

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, nogil=True)
def cusum_block(A, B, C, D, K, u0, y0, wrap, i_sig, inv_sd, drift, thr, settle_n, x, g, st,
                u, y, ok, out_stat, out_thr, out_valid, out_hyp, out_point, out_res, out_cos):  # pragma: no cover
    """Process ``N = u.shape[0]`` samples in place (module docstring for the equations).

    Parameters
    ----------
    A, B, C, D, K : NDArray
        Predictor matrices (n, n), (n, m), (p, n), (p, m), (n, p).
    u0, y0 : NDArray
        (m,) trim commands [-], (p,) trim outputs [output units].
    wrap : NDArray of bool
        (p,) wrap the output's deviation to [-pi, pi).
    i_sig : int
        Column of the watched signal.
    inv_sd : float
        ``1 / sqrt(Sigma_ii)`` [1 / signal units].
    drift, thr : float
        CUSUM drift ``k`` [-] and threshold ``h`` [-].
    settle_n : int
        Samples that only update the filter after a reset or a gap.
    x, g, st : NDArray
        State (module docstring), updated in place.
    u, y, ok : NDArray
        (N, m) absolute commands, (N, p) absolute measurements, (N, p) usable flags.
    out_stat, out_thr, out_valid, out_hyp, out_point, out_res, out_cos : NDArray
        ``BlockOutputs`` rows ``0 .. N-1`` (``out_res`` is (N, 1)).
    """
    n = A.shape[0]
    m = B.shape[1]
    p = C.shape[0]
    N = u.shape[0]
    du = np.empty(m)
    nu = np.empty(p)
    xn = np.empty(n)
    for j in range(N):
        finite_u = True
        for b in range(m):
            d = u[j, b] - u0[b]
            if math.isfinite(d):
                du[b] = d
            else:
                du[b] = 0.0
                finite_u = False
        usable = finite_u
        for r in range(p):
            # nu_r = wrap(y_r - y0_r) - (C xhat + D du)_r
            yr = y[j, r]
            if not (ok[j, r] and math.isfinite(yr)):
                usable = False
                nu[r] = 0.0
                continue
            pred = 0.0
            for a in range(n):
                pred += C[r, a] * x[a]
            for b in range(m):
                pred += D[r, b] * du[b]
            dy = yr - y0[r]
            if wrap[r]:
                dy = (dy + math.pi) % TWO_PI - math.pi
            nu[r] = dy - pred
        # xhat <- A xhat + B du (+ K nu when every used measurement is there)
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += A[a, c] * x[c]
            for b in range(m):
                acc += B[a, b] * du[b]
            if usable:
                for r in range(p):
                    acc += K[a, r] * nu[r]
            xn[a] = acc
        for a in range(n):
            x[a] = xn[a]
        st[0] += 1
        out_thr[j] = thr
        out_point[j] = 0
        out_cos[j] = np.nan
        out_hyp[j] = -1
        if not usable:
            st[1] = settle_n  # the prediction error grew: settle again once the measurements are back
            out_res[j, 0] = np.nan
            out_stat[j] = max(g[0], g[1])
            out_valid[j] = False
            continue
        e = nu[i_sig] * inv_sd
        out_res[j, 0] = e
        if st[1] > 0:
            st[1] -= 1
            out_stat[j] = max(g[0], g[1])
            out_valid[j] = False
            continue
        # g+ = max(0, g+ + e - k),  g- = max(0, g- - e - k),  T = max(g+, g-)
        gp = g[0] + e - drift
        gm = g[1] - e - drift
        g[0] = gp if gp > 0.0 else 0.0
        g[1] = gm if gm > 0.0 else 0.0
        T = g[0] if g[0] > g[1] else g[1]
        out_stat[j] = T
        out_valid[j] = math.isfinite(T)
        if T > thr:
            out_hyp[j] = 0

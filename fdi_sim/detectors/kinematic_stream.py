"""Streaming, chunk-invariant form of the kinematic sensor checks (``fdi_sim.detectors.kinematic``), in numba.

:class:`KinematicStream` wraps one :class:`~fdi_sim.detectors.kinematic.KinematicDetector` and
gives the numbers of its vectorised :meth:`~fdi_sim.detectors.kinematic.KinematicDetector.run`
(not of its ``step``, where the two differ) for blocks of any size: one compiled call per block,
all state in preallocated arrays, a sequential loop over the rows. The block size never changes
a number: process(all N rows) equals process() over any split of them, bitwise.

How each batch operation is reproduced sequentially (same operands, same order of operations):

- ``np.cumsum`` (the Euler-rate integral, the v_down integral, the moving mean's running sum) is
  a sequential sum from row 0: carried as one running value, its past values in a ring buffer
  (``I_k - I_{k-n}`` is then the same subtraction of the same two numbers).
- ``np.interp`` of v_down between its GNSS samples needs the next sample: the rows between two
  GNSS samples are integrated when the second arrives (``v = s (k - k1) + v1``,
  ``s = (v2 - v1) / (k2 - k1)``, numpy's formula); before the first sample v_down is the first
  sample (numpy's left value). The residual is only evaluated at GNSS samples, so this is causal.
- ``E^-1 e`` (the equivalent gyro bias) is the closed form of
  :func:`fdi_sim.detectors.kinematic.euler_inverse_apply`, the same elementwise operations in the
  same order (it replaced ``np.linalg.solve``, whose rounding depends on the BLAS kernel the CPU
  gets: fused multiply-adds in the triangular solves on one machine, none on another).
- ``np.einsum("nij,nj->ni")`` sums ``(a0 b0 + a2 b2) + a1 b1``; ``"nji,nj->ni"`` and
  ``np.linalg.norm(axis=1)`` sum in order (measured on numpy 2.4).

What cannot be reproduced: numpy on an AVX-512 CPU evaluates ``tan``, ``arctan2``, ``arcsin``
and ``**`` (pow) with its SVML loops, which differ from the C library's (what numba calls) by
one ulp in 0.5 to 8 % of the arguments (``sin``, ``cos``, ``sqrt`` agree). The altitude check
uses none of them and equals ``run`` bitwise. The others differ by ulps: on the test flights
the attitude check (``tan``) in 1 sample of 5 500 (1e-16 relative), the airspeed check (pow) in
most samples by at most 1.1e-13 kt (relative 1.7e-10 where its statistic is near 0), the
flow-angle check (pow, ``arctan2``, ``arcsin``) by at most 1.6e-13 (relative 9e-13); alarms
and isolations are the same. With numpy's AVX-512 loops switched off
(``NPY_DISABLE_CPU_FEATURES``) all four equal ``run`` bitwise
(``tests/detectors/test_kinematic_stream.py``).

Cost (measured, warm, one core): about 2 us per :meth:`KinematicStream.process` call plus 0.2 us
per sample (3 us for a 0.25 s block of 5 samples at 20 Hz), against 120-460 us per sample for
``step`` and 130-380 us for ``run`` on 5 samples. The kernels compile on first use (3-7 s for the
four, cold) and are cached on disk (``cache=True``; then about 0.5 s, numba's own start-up).

Input per sample (the columns of :attr:`KinematicStream.output_names`): the absolute measurement,
its validity (False during a dropout; a non-finite value counts as invalid, and an invalid value
enters the arithmetic as 0, as in :func:`fdi_sim.detectors.samples.samples_from_arrays`) and its
freshness (the sensor produced a new sample at this detector sample). GNSS freshness comes from
these flags, as in ``run``; ``t_s`` is not used by the numbers (``step`` instead infers it from
``t_s``, the two agree when the log starts at t = 0 and the GNSS rate is the design's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors import kinematic as _kin
from fdi_sim.detectors.kinematic import CHANNELS, GNSS, HYPOTHESES, NEEDS, KinematicDetector, KinematicRun
from fdi_sim.detectors.samples import Samples, is_wrapped
from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.errors import DesignError
from fdi_sim.isa import isa
from fdi_sim.units import KT_PER_FPS

__all__ = ["KinematicStream", "StreamInputs"]

_TWO_PI = 2.0 * math.pi

# --- layout of the parameter and state arrays (indices; shared by the kernels) ---------------
# float parameters
_P_THR, _P_DT, _P_T_WIN, _P_G_BIAS, _P_G_WIND, _P_T0, _P_P0, _P_A0, _P_KT, _P_SCALES = range(10)
# int parameters
_Q_N_WIN, _Q_N_AVG, _Q_N_VALID, _Q_N_WARM, _Q_DEBIAS, _Q_SHARED, _Q_NCOL, _Q_PSI, _Q_G_LO, _Q_G_HI = range(10)
# int state
_S_K, _S_LAST_BAD, _S_N_MEAN, _S_N_GNSS, _S_HAS_LAST, _S_J1, _S_NANC = range(7)  # _S_NANC: one per channel
# float state: the bias mean first (one per channel), then per kind
_F_MEAN = 0


@numba.njit(cache=True, error_model="numpy")
def _wrap(a):
    # (a + pi) mod 2 pi - pi, the batch path's rule (float modulo with Python's sign convention)
    return (a + math.pi) % _TWO_PI - math.pi


@numba.njit(cache=True, error_model="numpy")
def _check(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, ncol, nchan):
    n = y.shape[0]
    if (t_s.shape[0] != n or y.shape[1] != ncol or ok.shape[0] != n or ok.shape[1] != ncol
            or fresh.shape[0] != n or fresh.shape[1] != ncol or out_z.shape[0] != n or out_valid.shape[0] != n
            or out_hyp.shape[0] != n or out_r.shape[0] != n or out_r.shape[1] != nchan):
        raise ValueError("KinematicStream.process: t_s (N,), y, ok, fresh (N, len(output_names)), "
                         "out_statistic, out_valid, out_hypothesis (N,) and out_residual (N, len(channels)) "
                         "must agree")


@numba.njit(cache=True, error_model="numpy")
def _row(y, ok, fresh, j, vals, iprm, ist, k):
    """Read row ``j`` into ``vals`` (invalid -> 0, heading wrapped); returns (row valid, GNSS fresh)."""
    good = True
    for c in range(iprm[_Q_NCOL]):
        v = y[j, c]
        if ok[j, c] and math.isfinite(v):
            vals[c] = v
        else:
            vals[c] = 0.0  # an invalid value never enters arithmetic (samples_from_arrays)
            good = False
    c = iprm[_Q_PSI]
    if c >= 0:
        # log_samples wraps once, absolute() again; the wrap is idempotent on its own output
        vals[c] = _wrap(_wrap(vals[c]))
    gnss = True
    for c in range(iprm[_Q_G_LO], iprm[_Q_G_HI]):
        gnss = gnss and fresh[j, c]
    if not good:
        ist[_S_LAST_BAD] = k
    return good, gnss


@numba.njit(cache=True, error_model="numpy")
def _window_ok(ist, k, n):
    # rows k - n .. k exist and are valid (KinematicDetector._valid_window)
    return k >= n and ist[_S_LAST_BAD] < k - n


@numba.njit(cache=True, error_model="numpy")
def _debias(r, prm, iprm, fs, ist):
    """``r - m`` after the warm-up, ``m <- m + g (r - m)``, ``g = max(1/n, dt/tau)``, frozen in alarm (in place).

    KinematicDetector._debias row by row: a non-finite row is skipped; during the warm-up the mean
    learns and the output is NaN; an alarmed sample does not teach the mean.
    """
    m = r.shape[0]
    for i in range(m):
        if not math.isfinite(r[i]):
            for i2 in range(m):
                r[i2] = math.nan
            return
    n_mean = ist[_S_N_MEAN]
    live = n_mean >= 1 and n_mean >= iprm[_Q_N_WARM]
    if live:
        z = -math.inf
        for i in range(m):
            zi = abs(r[i] - fs[_F_MEAN + i]) / prm[_P_SCALES + i]
            if zi > z:
                z = zi
        if z > prm[_P_THR]:
            for i in range(m):
                r[i] = r[i] - fs[_F_MEAN + i]
            return
    n_mean += 1
    ist[_S_N_MEAN] = n_mean
    g = max(1.0 / n_mean, prm[_P_G_BIAS])
    for i in range(m):
        d = r[i] - fs[_F_MEAN + i]  # with the mean before this row
        fs[_F_MEAN + i] = r[i] if n_mean == 1 else fs[_F_MEAN + i] + g * d
        r[i] = d if live else math.nan


@numba.njit(cache=True, error_model="numpy")
def _finish(j, r, prm, iprm, fs, ist, out_z, out_valid, out_hyp, out_r):
    """Debias (if designed), then the test ``z = max |r_i| / s_i`` and the hypothesis (KinematicDetector._test)."""
    m = r.shape[0]
    if iprm[_Q_DEBIAS]:
        _debias(r, prm, iprm, fs, ist)
    thr = prm[_P_THR]
    z = -math.inf
    best = 0
    n_over = 0
    finite = True
    for i in range(m):
        zi = abs(r[i]) / prm[_P_SCALES + i]
        if not math.isfinite(zi):
            finite = False
        if zi > z:
            z, best = zi, i  # the first of equal maxima, as argmax
        if zi > thr:
            n_over += 1
        out_r[j, i] = r[i]
    if not finite:
        z, best = math.nan, -1
    elif not z > thr:
        best = -1
    elif iprm[_Q_SHARED] >= 0 and n_over == m:
        best = iprm[_Q_SHARED]  # every relation out of bounds: the sensor they share
    out_z[j] = z
    out_valid[j] = finite
    out_hyp[j] = best


@numba.njit(cache=True, error_model="numpy")
def _moving_mean(j_slot, k, z, i, na, ring, col_s, col_n, fs, f_s, ist):
    """Mean of the last ``na`` values of channel ``i`` (NaN until ``na`` rows, or with a NaN among them).

    ``S_k = S_{k-1} + z_k`` (NaN counted, not summed), the mean ``(S_k - S_{k-na}) / na``: the
    batch path's cumulative-sum difference, same operands.
    """
    L = ring.shape[0]
    bad = not math.isfinite(z)
    s = fs[f_s + i]
    if k == 0:
        s = 0.0 if bad else z
    elif not bad:
        s = s + z
    nanc = ist[_S_NANC + i] + (1 if bad else 0)
    fs[f_s + i] = s
    ist[_S_NANC + i] = nanc
    ring[j_slot, col_s + i] = s
    ring[j_slot, col_n + i] = nanc
    if k < na - 1:
        return math.nan
    if k >= na:
        s0 = ring[(k - na) % L, col_s + i]
        n0 = ring[(k - na) % L, col_n + i]
    else:
        s0 = 0.0
        n0 = 0.0
    if nanc - n0 != 0:
        return math.nan
    return (s - s0) / na


# --- attitude -----------------------------------------------------------------------------
# float state after the mean (3): last Euler rates (3), the integral I (3); ring: phi, theta, psi, I (3)
_FA_ED, _FA_I = 3, 6


@numba.njit(cache=True, error_model="numpy")
def _attitude(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, prm, iprm, fs, ist, ring, vals, r):
    _check(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, iprm[_Q_NCOL], 3)
    n = iprm[_Q_N_WIN]
    L = ring.shape[0]
    dt = prm[_P_DT]
    k = ist[_S_K]
    for j in range(y.shape[0]):
        _row(y, ok, fresh, j, vals, iprm, ist, k)
        phi, theta, psi, p, q, rr = vals[0], vals[1], vals[2], vals[3], vals[4], vals[5]
        sp, cp, tt, ct = math.sin(phi), math.cos(phi), math.tan(theta), math.cos(theta)
        qs = q * sp + rr * cp  # q sin(phi) + r cos(phi)
        ed0, ed1, ed2 = p + tt * qs, q * cp - rr * sp, qs / ct  # [phi, theta, psi]_dot = E w
        if k == 0:
            i0, i1, i2 = 0.0, 0.0, 0.0
        else:  # trapezoid: I_k = I_{k-1} + (ed_k + ed_{k-1}) dt / 2
            i0 = fs[_FA_I] + 0.5 * (ed0 + fs[_FA_ED]) * dt
            i1 = fs[_FA_I + 1] + 0.5 * (ed1 + fs[_FA_ED + 1]) * dt
            i2 = fs[_FA_I + 2] + 0.5 * (ed2 + fs[_FA_ED + 2]) * dt
        fs[_FA_ED], fs[_FA_ED + 1], fs[_FA_ED + 2] = ed0, ed1, ed2
        fs[_FA_I], fs[_FA_I + 1], fs[_FA_I + 2] = i0, i1, i2
        s = k % L
        ring[s, 0], ring[s, 1], ring[s, 2] = phi, theta, psi
        ring[s, 3], ring[s, 4], ring[s, 5] = i0, i1, i2
        r[0], r[1], r[2] = math.nan, math.nan, math.nan
        if k >= n:
            s0 = (k - n) % L
            # e = [phi, theta, psi](t) - [phi, theta, psi](t - T) - int E w dt (heading increment wrapped)
            e0 = (phi - ring[s0, 0]) - (i0 - ring[s0, 3])
            e1 = (theta - ring[s0, 1]) - (i1 - ring[s0, 4])
            e2 = _wrap(psi - ring[s0, 2]) - (i2 - ring[s0, 5])
            if math.isfinite(e0) and math.isfinite(e1) and math.isfinite(e2) and _window_ok(ist, k, n):
                # b_hat = E^-1 e / T, the equivalent gyro bias [rad/s]
                st = math.sin(theta)  # E^-1 e in closed form (kinematic.euler_inverse_apply)
                b0, b1, b2 = e0 - st * e2, cp * e1 + (sp * ct) * e2, (cp * ct) * e2 - sp * e1
                T = prm[_P_T_WIN]
                r[0], r[1], r[2] = b0 / T, b1 / T, b2 / T
        _finish(j, r, prm, iprm, fs, ist, out_z, out_valid, out_hyp, out_r)
        k += 1
        ist[_S_K] = k


# --- altitude -----------------------------------------------------------------------------
# float state after the mean (2): I at the last GNSS row, v_down there, held residual (2), running sum (1)
_FH_I, _FH_V1, _FH_HELD, _FH_SUM = 2, 3, 4, 6
# ring: h, I, running sum, NaN count
_RH_H, _RH_I, _RH_S, _RH_N = 0, 1, 2, 3


@numba.njit(cache=True, error_model="numpy")
def _altitude(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, prm, iprm, fs, ist, ring, vals, r):
    _check(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, iprm[_Q_NCOL], 2)
    n, na, nv = iprm[_Q_N_WIN], iprm[_Q_N_AVG], iprm[_Q_N_VALID]
    L = ring.shape[0]
    dt = prm[_P_DT]
    k = ist[_S_K]
    for j in range(y.shape[0]):
        good, gnss = _row(y, ok, fresh, j, vals, iprm, ist, k)
        h, hd, v2 = vals[0], vals[1], vals[2]
        s = k % L
        ring[s, _RH_H] = h
        if gnss and good:
            # integrate v_down over the rows since the last GNSS sample, linear between the two
            # (np.interp: v = s (k - k1) + v1); before the first sample v_down is that sample
            j1 = ist[_S_J1]
            if j1 < 0:
                iv = 0.0
                ring[0 % L, _RH_I] = iv
                for i in range(1, k + 1):
                    iv = iv + 0.5 * (v2 + v2) * dt
                    ring[i % L, _RH_I] = iv
            else:
                v1 = fs[_FH_V1]
                iv = fs[_FH_I]
                slope = (v2 - v1) / (float(k) - float(j1))
                v_prev = v1
                for i in range(j1 + 1, k + 1):
                    vi = v2 if i == k else slope * (float(i) - float(j1)) + v1
                    iv = iv + 0.5 * (vi + v_prev) * dt
                    ring[i % L, _RH_I] = iv
                    v_prev = vi
            fs[_FH_I], fs[_FH_V1] = iv, v2
            ist[_S_J1] = k
            if k >= n:
                s0 = (k - n) % L
                raw0 = (h - ring[s0, _RH_H]) + (iv - ring[s0, _RH_I])  # dh + int v_down dt [ft]
                raw1 = hd + v2  # hdot + v_down [ft/s]
                if math.isfinite(raw0) and math.isfinite(raw1):
                    fs[_FH_HELD], fs[_FH_HELD + 1] = raw0, raw1
                    ist[_S_HAS_LAST] = 1
        held0 = fs[_FH_HELD] if ist[_S_HAS_LAST] else math.nan  # held between GNSS samples
        held1 = fs[_FH_HELD + 1] if ist[_S_HAS_LAST] else math.nan
        r[0] = held0
        r[1] = _moving_mean(s, k, held1, 0, na, ring, _RH_S, _RH_N, fs, _FH_SUM, ist)
        if not _window_ok(ist, k, nv):
            r[0], r[1] = math.nan, math.nan
        _finish(j, r, prm, iprm, fs, ist, out_z, out_valid, out_hyp, out_r)
        k += 1
        ist[_S_K] = k


# --- airspeed and flow angles ---------------------------------------------------------------
# float state after the mean (<= 2): wind (3), held residual (2), running sums (2)
_FW_WIND, _FW_HELD, _FW_SUM = 2, 5, 7


@numba.njit(cache=True, error_model="numpy")
def _vt_fps(h_ft, vc_kts, prm):
    """True airspeed [ft/s] from vc [kt] at pressure altitude [ft] (kinematic.vt_from_vc_fps)."""
    h = h_ft
    if h < -2000.0:
        h = -2000.0
    elif h > 36089.0:
        h = 36089.0
    t0, p0, a0 = prm[_P_T0], prm[_P_P0], prm[_P_A0]
    T = t0 - 0.00356616 * h  # troposphere: T = T0 - L h, p = p0 (T/T0)^5.2559
    p = p0 * (T / t0) ** 5.25588
    a = a0 * math.sqrt(T / t0)
    x = vc_kts / prm[_P_KT] / a0
    qc = p0 * ((1.0 + 0.2 * (x * x)) ** 3.5 - 1.0)  # qc = p0 ((1 + 0.2 (vc/a0)^2)^3.5 - 1)
    if qc < 0.0:
        qc = 0.0
    mach = math.sqrt(5.0 * ((qc / p + 1.0) ** (2.0 / 7.0) - 1.0))  # M = sqrt(5 ((qc/p + 1)^(2/7) - 1))
    return mach * a


@numba.njit(cache=True, error_model="numpy")
def _air(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, prm, iprm, fs, ist, ring, vals, r, flow):
    m = 2 if flow else 1
    _check(t_s, y, ok, fresh, out_z, out_valid, out_hyp, out_r, iprm[_Q_NCOL], m)
    na = iprm[_Q_N_AVG]
    L = ring.shape[0]
    k = ist[_S_K]
    for j in range(y.shape[0]):
        good, gnss = _row(y, ok, fresh, j, vals, iprm, ist, k)
        if gnss and good:
            vc, h, phi, theta, psi, al, be, vn, ve, vd = (vals[0], vals[1], vals[2], vals[3], vals[4], vals[5],
                                                         vals[6], vals[7], vals[8], vals[9])
            vt = _vt_fps(h, vc, prm)
            ca, sa, cb, sb = math.cos(al), math.sin(al), math.cos(be), math.sin(be)
            u0, u1, u2 = vt * (ca * cb), vt * sb, vt * (sa * cb)  # vt [cos a cos b, sin b, sin a cos b]
            sf, cf, st, ct, ss, cs = (math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta),
                                      math.sin(psi), math.cos(psi))
            r00, r01, r02 = ct * cs, sf * st * cs - cf * ss, cf * st * cs + sf * ss  # v_ned = R v_body
            r10, r11, r12 = ct * ss, sf * st * ss + cf * cs, cf * st * ss - sf * cs
            r20, r21, r22 = -st, sf * ct, cf * ct
            if ist[_S_N_GNSS] > 0:  # the wind before this row
                an, ae, ad = vn - fs[_FW_WIND], ve - fs[_FW_WIND + 1], vd - fs[_FW_WIND + 2]  # v_g - w_hat
                if flow:  # R' v_a (einsum "nji,nj->ni" sums in order)
                    b0 = (r00 * an + r10 * ae) + r20 * ad
                    b1 = (r01 * an + r11 * ae) + r21 * ad
                    b2 = (r02 * an + r12 * ae) + r22 * ad
                    speed = math.sqrt((b0 * b0 + b1 * b1) + b2 * b2)
                    sb_kin = b1 / speed
                    if sb_kin < -1.0:
                        sb_kin = -1.0
                    elif sb_kin > 1.0:
                        sb_kin = 1.0
                    raw0 = al - math.atan2(b2, b0)  # alpha - atan2(w_b, u_b)
                    raw1 = be - math.asin(sb_kin)  # beta - asin(v_b / |v_a|)
                    fin = math.isfinite(raw0) and math.isfinite(raw1)
                else:
                    raw0 = (vt - math.sqrt((an * an + ae * ae) + ad * ad)) * prm[_P_KT]  # vt - |v_g - w_hat| [kt]
                    raw1 = 0.0
                    fin = math.isfinite(raw0)
                if fin:
                    fs[_FW_HELD], fs[_FW_HELD + 1] = raw0, raw1
                    ist[_S_HAS_LAST] = 1
            # w_raw = v_g - R v_b (einsum "nij,nj->ni" sums (a0 b0 + a2 b2) + a1 b1)
            w0 = vn - ((r00 * u0 + r02 * u2) + r01 * u1)
            w1 = ve - ((r10 * u0 + r12 * u2) + r11 * u1)
            w2 = vd - ((r20 * u0 + r22 * u2) + r21 * u1)
            if math.isfinite(w0) and math.isfinite(w1) and math.isfinite(w2):
                # w <- w + g (w_raw - w), g = max(1/n, dt_gnss/tau): the mean, then first order
                ng = ist[_S_N_GNSS] + 1
                ist[_S_N_GNSS] = ng
                if ng == 1:
                    fs[_FW_WIND], fs[_FW_WIND + 1], fs[_FW_WIND + 2] = w0, w1, w2
                else:
                    g = max(1.0 / ng, prm[_P_G_WIND])
                    fs[_FW_WIND] = fs[_FW_WIND] + g * (w0 - fs[_FW_WIND])
                    fs[_FW_WIND + 1] = fs[_FW_WIND + 1] + g * (w1 - fs[_FW_WIND + 1])
                    fs[_FW_WIND + 2] = fs[_FW_WIND + 2] + g * (w2 - fs[_FW_WIND + 2])
        s = k % L
        win = _window_ok(ist, k, na)
        for i in range(m):
            held = fs[_FW_HELD + i] if ist[_S_HAS_LAST] else math.nan  # held between GNSS samples
            r[i] = _moving_mean(s, k, held, i, na, ring, 0, m, fs, _FW_SUM, ist)
            if not win:
                r[i] = math.nan
        _finish(j, r, prm, iprm, fs, ist, out_z, out_valid, out_hyp, out_r)
        k += 1
        ist[_S_K] = k


class KinematicStream:
    """Streaming form of one :class:`~fdi_sim.detectors.kinematic.KinematicDetector` (same design, same numbers).

    Parameters
    ----------
    det : KinematicDetector
        The check; its design (kind, rate, windows, scales, threshold) is copied.

    Attributes
    ----------
    id : str
        ``det.id``.
    hypotheses : tuple of str
        ``det.hypotheses`` (sensor names); ``out_hypothesis`` indexes it.
    output_names : tuple of str
        The measurements read, in the order of the columns of ``y``, ``ok`` and ``fresh``
        (``kinematic.NEEDS[kind]``).
    channels : tuple of str
        Residual channel names (``kinematic.CHANNELS[kind]``), the columns of ``out_residual``.
    threshold : float
        Alarm threshold on the statistic [-].
    rate_hz : float
        Detector rate [Hz]; one row of ``process`` is one sample at this rate.
    """

    def __init__(self, det: KinematicDetector) -> None:
        d = det.design
        kind = d.kind
        self.design = d
        self.id = det.id
        self.kind = kind
        self.hypotheses: tuple[str, ...] = tuple(HYPOTHESES[kind])
        self.output_names: tuple[str, ...] = tuple(NEEDS[kind])
        self.channels: tuple[str, ...] = tuple(CHANNELS[kind])
        self.threshold = float(d.threshold)
        self.rate_hz = float(d.rate_hz)
        m = len(self.channels)
        dt_s = 1.0 / d.rate_hz  # the batch path's numbers, computed the same way
        n_win = max(1, int(round(d.window_s * d.rate_hz)))
        n_avg = max(1, int(round(d.average_s * d.rate_hz)))
        prm = [float(d.threshold), dt_s, n_win * dt_s, dt_s / d.tau_bias_s if d.tau_bias_s > 0 else 0.0,
               1.0 / (d.tau_wind_s * d.gnss_rate_hz), isa(0.0).temperature_R, _kin._P0_PSF, _kin._A0_FPS,
               KT_PER_FPS]
        self._prm = np.array(prm + [float(s) for s in d.scales], dtype=np.float64)
        names = self.output_names
        gnss = [names.index(nm) for nm in GNSS if nm in names]
        if gnss and gnss != list(range(gnss[0], gnss[-1] + 1)):
            raise DesignError(f"{self.id}: the GNSS columns must be adjacent in {names}")  # NEEDS guarantees it
        psi = [i for i, nm in enumerate(names) if is_wrapped(nm)]
        n_valid = {"attitude": n_win, "altitude": max(n_win, n_avg)}.get(kind, n_avg)
        shared = self.hypotheses.index("v_down_fps") if kind == "altitude" else -1
        self._iprm = np.array([n_win, n_avg, n_valid, int(round(d.warmup_s * d.rate_hz)), int(d.tau_bias_s > 0),
                               shared, len(names), psi[0] if psi else -1, gnss[0] if gnss else 0,
                               gnss[-1] + 1 if gnss else 0], dtype=np.int64)
        # ring buffers: as many rows as the longest look-back plus the current one
        self._ring_shape = {"attitude": (n_win + 1, 6), "altitude": (max(n_win, n_avg) + 1, 4)}.get(
            kind, (n_avg + 1, 2 * m))
        self._n_fs = {"attitude": 3 + 6, "altitude": 2 + 5}.get(kind, 2 + 7)
        self._kernel = {"attitude": _attitude, "altitude": _altitude}.get(kind, _air)
        self._extra = () if kind in ("attitude", "altitude") else (kind == "flow-angles",)
        self.reset()

    def reset(self) -> None:
        """Fresh state (as :meth:`KinematicDetector.reset`): empty windows, no wind, no bias mean."""
        self._fs = np.zeros(self._n_fs, dtype=np.float64)
        self._ist = np.zeros(_S_NANC + len(self.channels), dtype=np.int64)
        self._ist[_S_LAST_BAD] = -1
        self._ist[_S_J1] = -1
        self._ring = np.zeros(self._ring_shape, dtype=np.float64)
        self._vals = np.zeros(len(self.output_names), dtype=np.float64)
        self._r = np.zeros(len(self.channels), dtype=np.float64)

    @property
    def samples_seen(self) -> int:
        """Rows processed since the last :meth:`reset`."""
        return int(self._ist[_S_K])

    # --- the streaming contract (fdi_sim.detectors.stream.StreamingDetector) -----------------
    #: the checks read measurements only
    input_names: tuple[str, ...] = ()
    #: no filter: nothing a failed sensor could be replaced by
    estimate_names: tuple[str, ...] = ()
    #: a residual per sensor, no fault direction (the angle-magnitude rule cannot use it)
    fault_directions = False
    #: the statistic's form, for the threshold's tail (fdi_sim.decision.tail.episode_threshold):
    #: max |r_i| / scale_i of residuals that are windowed linear functions of Gaussian sensor noise
    #: and turbulence, whose upcrossings fall as exp(-x^2 / 2 s^2) (Rice): exponential in x^2
    tail_power = 2.0
    #: ... and light-tailed (no heavier tail is fitted: the residuals are kinematic relations
    #: between sensors, no aerodynamic model whose mismatch could fatten them); the studies check it
    tail_heavy = False

    @property
    def residual_names(self) -> tuple[str, ...]:
        """The residual's columns (:attr:`channels`)."""
        return self.channels

    @property
    def independent(self) -> bool:
        """The check compares one sensor group with an independent one (gyros with the AHRS, baro
        and pitot with GNSS), so its isolation alone may reconfigure; the flow-angle check leans on
        the pitot and the AHRS as well (a drifting airspeed makes it name the alpha vane, measured
        on the DHC-6 pitot drift), so it is not."""
        return self.kind != "flow-angles"

    def set_threshold(self, value: float) -> None:
        """Set the alarm threshold [-] (the kernel isolates above it)."""
        self.threshold = float(value)
        self._prm[0] = float(value)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """The checks have no operating point: a reset."""
        self.reset()

    def design_key(self) -> bytes:
        """The design the numbers come from (its repr: kind, rate, windows, scales, threshold)."""
        return repr(self.design).encode()

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """The streaming contract's call: :meth:`process` into ``out``, the threshold written per
        sample (``u`` unused)."""
        self.process(t_s, y, ok, fresh, out.statistic, out.valid, out.hypothesis, out.residual)
        out.threshold[:] = self._prm[0]

    def process(self, t_s: NDArray[np.float64], y: NDArray[np.float64], ok: NDArray[np.bool_],
                fresh: NDArray[np.bool_], out_statistic: NDArray[np.float64], out_valid: NDArray[np.bool_],
                out_hypothesis: NDArray[np.int64], out_residual: NDArray[np.float64]) -> None:
        """Process ``N`` consecutive detector samples (any ``N >= 0``; the split never changes a number).

        Parameters
        ----------
        t_s : NDArray
            (N,) sample times [s] (checked for shape, not used by the numbers).
        y : NDArray
            (N, len(output_names)) float64 absolute measurements (the heading as measured; it is
            wrapped to [-pi, pi) here).
        ok : NDArray of bool
            (N, len(output_names)) validity (False during a dropout).
        fresh : NDArray of bool
            (N, len(output_names)) the sensor produced a new sample at this detector sample (the
            10 Hz GNSS velocities every other 20 Hz sample).
        out_statistic : NDArray
            (N,) float64, written: ``max_i |r_i| / scale_i`` [-], NaN where invalid.
        out_valid : NDArray of bool
            (N,) written: the statistic is finite.
        out_hypothesis : NDArray of int64
            (N,) written: index into :attr:`hypotheses` where ``statistic > threshold``, -1 elsewhere.
        out_residual : NDArray
            (N, len(channels)) float64, written: the residual (channel units), NaN where invalid.

        Raises
        ------
        ValueError
            The shapes disagree.
        """
        self._kernel(t_s, y, ok, fresh, out_statistic, out_valid, out_hypothesis, out_residual, self._prm,
                     self._iprm, self._fs, self._ist, self._ring, self._vals, self._r, *self._extra)

    # --- offline use ------------------------------------------------------------------------
    def inputs(self, samples: Samples) -> StreamInputs:
        """The :meth:`process` inputs of detector samples (absolute values, this stream's columns).

        ``samples`` as :meth:`KinematicDetector.run` takes them (``log_samples(log, MeasurementSet(), ...)``).
        """
        idx = [samples.output_names.index(nm) for nm in self.output_names]
        y = np.ascontiguousarray(samples.dy[:, idx] + np.asarray(samples.y0, dtype=float)[idx])
        return StreamInputs(np.ascontiguousarray(samples.t_s, dtype=np.float64), y,
                            np.ascontiguousarray(samples.valid[:, idx]), np.ascontiguousarray(samples.fresh[:, idx]))

    def run(self, samples: Samples, block: int | None = None) -> KinematicRun:
        """The whole flight from a fresh state in blocks of ``block`` rows (one call if None), as
        :meth:`KinematicDetector.run` reports it."""
        x = self.inputs(samples)
        n = samples.n
        z, valid = np.empty(n), np.empty(n, dtype=bool)
        hyp, r = np.empty(n, dtype=np.int64), np.empty((n, len(self.channels)))
        self.reset()
        step = max(int(block), 1) if block else max(n, 1)
        for a in range(0, n, step):
            b = min(a + step, n)
            self.process(x.t_s[a:b], x.y[a:b], x.ok[a:b], x.fresh[a:b], z[a:b], valid[a:b], hyp[a:b], r[a:b])
        alarm = valid & (z > self.threshold)
        isolation = np.array([self.hypotheses[h] if h >= 0 else None for h in hyp], dtype=object)
        return KinematicRun(x.t_s, r, z, alarm, isolation, valid)


@dataclass(frozen=True, eq=False)
class StreamInputs:
    """What :meth:`KinematicStream.process` reads, for N samples (:meth:`KinematicStream.inputs`).

    Attributes
    ----------
    t_s : NDArray
        (N,) sample times [s].
    y : NDArray
        (N, p) absolute measurements in ``output_names`` order (0 where invalid).
    ok : NDArray of bool
        (N, p) validity.
    fresh : NDArray of bool
        (N, p) a new sensor sample at this row.
    """

    t_s: NDArray[np.float64]
    y: NDArray[np.float64]
    ok: NDArray[np.bool_]
    fresh: NDArray[np.bool_]

"""Streaming, block-invariant form of the discrete observers: directional filters and the steady Kalman filter.

One compiled call per block runs, per sample ``j`` and per observer ``f`` (the
:class:`~fdi_sim.detectors.directional_observer.DiscreteObserver` of each), on deviations from
trim (heading deviations wrapped to [-pi, pi))::

    z = [xh_f ; du_j ; dy_j],   r_f = H_f z = dy_j - C xh_f - D du_j,   xh_f <- F_f z = Phi xh_f + Gam_u du_j + Gam_y dy_j

and the test of the detector it was built from, with the numbers of its ``step``:

- :class:`~fdi_sim.detectors.directional_observer.DirectionalObserver` (``beard-jones-v1``'s
  :class:`~fdi_sim.detectors.beard_jones_filter.BeardJonesFilter`, ``lmi-detection-v1``):
  ``|W r|^2`` (``W' W = S^-1``) against the chi-square threshold; on alarm the smallest whitened
  angle ``atan2(|rw - (d'rw) d|, |d'rw|)`` to each fault's unit output direction ``d`` isolates
  if below ``max_angle_rad`` (Miller & Ribbens, US 6,643,569 B2, App. A; App. B for the LMI filter).
- :class:`~fdi_sim.detectors.beard_jones_filter.BeardJonesBank`: every filter on the sample,
  statistic ``max_f |W_f r_f|^2 / threshold_f`` against 1, isolation in the filter of the largest ratio.
- :class:`~fdi_sim.detectors.kalman.KalmanInnovationDetector` (``kalman-nis-v1``, predictor form
  ``xh+ = A xh + B du + A K nu``): the NIS ``z'z``, ``z = W nu`` (Sidar 1982, sec. II), or over the
  last ``N = window_n`` samples (0 and invalid until full) the bias statistic ``N zbar' zbar``
  (eq. 10a) or the whiteness statistic ``(1/N) sum_{l=1..L} |sum_k z_{k+l} z_k'|_F^2`` (eq. 10b).

``cosine`` (directional filters, alarm samples) is the cosine of the smallest angle, also when it
is above ``max_angle_rad`` and no hypothesis is written; NaN otherwise.

Invalid measurements: a sample with any output not ``ok`` or not finite (or a non-finite command,
which then enters as 0) gets no measurement correction: each observer makes the open-loop update
``xh+ = A_d xh + B_d du`` with the discrete plant it predicts with (Beard-Jones, Kalman: their
design model, ``Phi + Gam_y C = A``). The sample is invalid (statistic NaN, no isolation), its
residual NaN in the bad channels; the Kalman window tests leave it out of the windows that hold
it (its ``z`` stored as 0, the statistics taken over the good samples: :func:`_push_window`). The LMI filter is the ZOH of a continuous observer and keeps
no plant: the plant's ZOH is recovered from the observer's matrices (matrix logarithm,
:func:`_plant_of`; equal to the continuous model's ZOH to 4e-12 on the F-16). Where that fails
the update is the observer fed its own prediction (``Phi + Gam_y C``, ``Gam_u + Gam_y D``: for a
ZOH observer *not* the plant's prediction); :attr:`ObserverStream.open_loop_exact` says which.
The detectors' own ``step`` has no such path (a NaN poisons its state).

Numbers agree with ``step`` to rounding (sums in another order than numpy's BLAS); cutting a
flight into blocks of any size never changes a bit. ``fresh`` is not used (a held value is a valid
measurement); model inputs that are not logged commands (the gust inputs) are held at the model's
trim (:func:`fdi_sim.offline.detect.run_detector`).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numba
import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from fdi_sim.detectors.beard_jones_filter import BeardJonesBank, BeardJonesFilter
from fdi_sim.detectors.directional_observer import DirectionalObserver, DiscreteObserver
from fdi_sim.detectors.kalman import KalmanInnovationDetector
from fdi_sim.detectors.lmi_filter import LmiDetectionFilter
from fdi_sim.detectors.samples import is_wrapped
from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.detectors.stream import command_columns, hash_arrays
from fdi_sim.errors import DesignError

__all__ = ["ObserverStream", "observer_stream"]

_TWO_PI = 2.0 * math.pi
#: the test after the observers
MODE_DIRECTIONAL, MODE_NIS, MODE_BIAS, MODE_WHITENESS = range(4)
_KALMAN_MODES = {"nis": MODE_NIS, "bias": MODE_BIAS, "whiteness": MODE_WHITENESS}


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lag_sums(zring, s0, lags):  # pragma: no cover - compiled
    """``lags[l-1] = sum_k Z[k+l] Z[k]'`` over the full ring, oldest first at slot ``s0`` (from scratch)."""
    N, m = zring.shape
    lags[:] = 0.0
    for l in range(1, lags.shape[0] + 1):
        for k in range(N - l):
            ra, rb = (s0 + k + l) % N, (s0 + k) % N
            for a in range(m):
                for b in range(m):
                    lags[l - 1, a, b] += zring[ra, a] * zring[rb, b]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _push_window(mode, z, good, zring, zbad, lags, ist):  # pragma: no cover - compiled
    """Push one whitened innovation into the window; return the bias (Sidar eq. 10a) or whiteness
    (eq. 10b) statistic: 0 until the window is full, NaN for a bad sample (its ``z`` stored as 0).

    Bad samples in the window are left out: with ``n`` good ones, ``n |zbar|^2``, ``zbar`` their
    mean, and ``sum_l |S_l|^2 / n`` (pairs with a bad sample add 0 to ``S_l``): chi-square as the
    full window's under no fault (the whiteness one conservative); the detector's numbers when
    ``n = N``.

    Whiteness keeps the lag sums ``R_l = sum_k z_{k+l} z_k'`` as running sums (the pair leaving
    with the oldest sample out, the pairs of the new one in), recomputed from scratch whenever the
    sample count is a multiple of the window length, so rounding cannot build up.
    """
    N, m = zring.shape
    t = ist[0]
    slot = t % N
    for a in range(m):
        good = good and math.isfinite(z[a])
    for l in range(1, lags.shape[0] + 1 if t >= N else 1):  # whiteness: the pairs (z_{t-N+l}, z_{t-N}) leave
        ra = (slot + l) % N
        for a in range(m):
            for b in range(m):
                lags[l - 1, a, b] -= zring[ra, a] * zring[slot, b]
    for a in range(m):
        zring[slot, a] = z[a] if good else 0.0  # a bad sample: 0, counted
    ist[1] += (0 if good else 1) - zbad[slot]
    zbad[slot] = 0 if good else 1
    for l in range(1, min(lags.shape[0], t) + 1):  # the pairs (z_t, z_{t-l}) enter
        rb = (t - l) % N
        for a in range(m):
            for b in range(m):
                lags[l - 1, a, b] += zring[slot, a] * zring[rb, b]
    t += 1
    ist[0] = t
    if lags.shape[0] and t % N == 0:
        _lag_sums(zring, 0, lags)  # the oldest sample is at slot 0
    n_good = N - ist[1]
    if t < N:
        return 0.0
    if not good or n_good == 0:
        return np.nan
    if mode == MODE_BIAS:
        s0 = t % N  # the oldest slot
        stat = 0.0
        for a in range(m):
            acc = 0.0
            for k in range(s0, N):
                acc += zring[k, a]
            for k in range(s0):
                acc += zring[k, a]
            zbar = acc / n_good
            stat += zbar * zbar
        return n_good * stat
    total = 0.0
    for l in range(lags.shape[0]):
        for a in range(m):
            for b in range(m):
                total += lags[l, a, b] * lags[l, a, b]
    return total / n_good


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _observer_kernel(mode, ratio, F, Fo, H, u0, y0, uhold, ucol, wrap, W, dirs, n_dirs, h_off, max_angle, thr_f, thr,
                     xh, zring, zbad, lags, ist, u, y, ok,
                     out_stat, out_thr, out_valid, out_hyp, out_point, out_res, out_cos):  # pragma: no cover - compiled
    """``N`` samples through every observer and the test (module docstring); ``xh``, ``zring``,
    ``zbad``, ``ist`` (samples seen, bad samples in the window) updated in place."""
    nf, n, nz = F.shape
    m = y0.shape[1]
    p = u0.shape[1]
    N = y.shape[0]
    if (u.shape[0] != N or ok.shape[0] != N or ok.shape[1] != m or y.shape[1] != m or out_stat.shape[0] != N
            or out_res.shape[0] != N or out_res.shape[1] != nf * m):
        raise ValueError("ObserverStream.process_block: u, y, ok and the outputs must have one row per sample")
    z = np.empty(nz)
    xn = np.empty(n)
    r = np.empty((nf, m))
    rw = np.empty((nf, m))
    stat_f = np.empty(nf)
    nrm_f = np.empty(nf)
    rn = np.empty(m)
    ang = np.empty(dirs.shape[1])
    yok = np.empty(m, dtype=np.bool_)
    for j in range(N):
        good = True
        for i in range(m):
            yok[i] = ok[j, i] and math.isfinite(y[j, i])
            good = good and yok[i]
        for b in range(p):
            c = ucol[b]
            if not math.isfinite(u[j, c] if c >= 0 else uhold[b]):
                good = False
        # --- the observers ------------------------------------------------------------------
        for f in range(nf):
            for a in range(n):
                z[a] = xh[f, a]
            for b in range(p):
                c = ucol[b]
                d = (u[j, c] if c >= 0 else uhold[b]) - u0[f, b]
                z[n + b] = d if math.isfinite(d) else 0.0  # a non-finite command enters as 0
            for i in range(m):
                d = y[j, i] - y0[f, i] if yok[i] else 0.0  # a bad value never enters the arithmetic
                z[n + p + i] = (d + math.pi) % _TWO_PI - math.pi if wrap[i] else d
            for i in range(m):
                acc = 0.0
                for k in range(nz):
                    acc += H[f, i, k] * z[k]
                r[f, i] = acc if yok[i] else np.nan
                out_res[j, f * m + i] = r[f, i]
            for a in range(n):
                acc = 0.0
                if good:  # xh+ = Phi xh + Gam_u du + Gam_y dy
                    for k in range(nz):
                        acc += F[f, a, k] * z[k]
                else:  # no measurement: xh+ = A xh + B du
                    for k in range(n + p):
                        acc += Fo[f, a, k] * z[k]
                xn[a] = acc
            for a in range(n):
                xh[f, a] = xn[a]
        out_thr[j] = thr
        out_point[j] = 0
        out_hyp[j] = -1
        out_cos[j] = np.nan
        # --- the statistic ---------------------------------------------------------------------
        finite = good
        for f in range(nf):
            sq = 0.0
            for i in range(m):
                acc = 0.0
                for k in range(m):
                    acc += W[f, i, k] * r[f, k]
                rw[f, i] = acc
                sq += acc * acc
            nrm_f[f] = math.sqrt(sq)
            if mode == MODE_DIRECTIONAL:
                sq = nrm_f[f] * nrm_f[f]  # DirectionalObserver.advance returns |rw|^2 as its norm squared
            stat_f[f] = sq
            if not math.isfinite(sq):
                finite = False
        if mode != MODE_DIRECTIONAL:
            if mode == MODE_NIS:
                stat = stat_f[0] if good else np.nan
                out_valid[j] = finite
            else:
                stat = _push_window(mode, rw[0], good, zring, zbad, lags, ist)
                out_valid[j] = ist[0] >= zring.shape[0] and math.isfinite(stat)
            out_stat[j] = stat
            continue
        fb = 0
        if ratio:  # a bank: the largest stat_f / threshold_f (the first of equal ones)
            best = -np.inf
            for f in range(nf):
                q = stat_f[f] / thr_f[f]
                if q > best:
                    best, fb = q, f
            stat = stat_f[fb] / thr_f[fb]
        else:
            stat = stat_f[0]
        if not good:
            stat = np.nan
        out_stat[j] = stat
        out_valid[j] = finite
        if not (finite and stat > thr) or stat_f[fb] == 0.0:
            continue
        # --- isolation: the smallest whitened angle in filter fb ---------------------------------
        for i in range(m):
            rn[i] = rw[fb, i] / nrm_f[fb]
        hb = -1
        for h in range(n_dirs[fb]):
            c = 0.0
            for i in range(m):
                c += dirs[fb, h, i] * rn[i]
            s2 = 0.0
            for i in range(m):
                e = rn[i] - dirs[fb, h, i] * c
                s2 += e * e
            ang[h] = math.atan2(math.sqrt(s2), abs(c))
            if ang[h] == ang[h] and (hb < 0 or ang[h] < ang[hb]):
                hb = h  # nanargmin: the first smallest, NaN (a zero direction) never wins
        if hb >= 0:
            out_cos[j] = math.cos(ang[hb])
            if ang[hb] < max_angle[fb]:
                out_hyp[j] = h_off[fb] + hb


def _parts(o: DiscreteObserver) -> tuple[NDArray, ...]:
    """``Phi, Gam_u, Gam_y, C, D`` of an observer (``F = [Phi, Gam_u, Gam_y]``, ``H = [-C, -D, I]``)."""
    n, p = o._F.shape[0], o._F.shape[1] - o._F.shape[0] - o._H.shape[0]
    return o._F[:, :n], o._F[:, n:n + p], o._F[:, n + p:], -o._H[:, :n], -o._H[:, n:n + p]


def _held_prediction(o: DiscreteObserver) -> NDArray[np.float64]:
    """``[Phi + Gam_y C, Gam_u + Gam_y D]``: the observer fed its own prediction ``C xh + D du``."""
    Phi, Gu, Gy, C, D = _parts(o)
    return np.hstack([Phi + Gy @ C, Gu + Gy @ D])


def _plant_of(o: DiscreteObserver, model: Any, zoh: bool, rtol: float = 1e-9) -> tuple[NDArray, NDArray] | None:
    """The discrete plant ``(A_d, B_d)`` an observer predicts with, or None where it is not shown exactly.

    ``zoh`` (:class:`~fdi_sim.detectors.lmi_filter.LmiDetectionFilter`, the ZOH of ``dxh/dt = Acl xh
    + (B - L D) u + L y``): the real principal logarithm of ``[[Phi, Gam], [0, I]]`` is ``[[Acl, B -
    L D, L] dt; 0]`` (exact when the observer's poles are below the Nyquist rate, ``|Im s| dt <
    pi``), so ``[A, B] dt = [Acl + L C, B - L D + L D] dt`` and the plant's ZOH is the exponential
    of ``[[A, B] dt; 0]`` (no ``dt`` needed); with a continuous ``model`` of the observer's size the
    recovered ``[A, B] dt`` must also be ``dt`` times the model's (which checks the branch). Any
    other observer: ``model``'s discrete ``(A, B)`` if they equal ``Phi + Gam_y C``, ``Gam_u + Gam_y D``.
    """
    Phi, Gu, Gy, C, D = _parts(o)
    n, p, m = Phi.shape[0], Gu.shape[1], C.shape[0]
    A, B = np.asarray(model.A, float), np.asarray(model.B, float)
    fits = A.shape == (n, n) and B.shape == (n, p) and np.asarray(model.C).shape == (m, n)
    ref = np.hstack([A, B]) if fits else None
    close = lambda a, b: bool(np.all(np.isfinite(a)) and np.linalg.norm(a - b) <= rtol * max(np.linalg.norm(b), 1e-300))  # noqa: E731
    if not zoh:
        return (A, B) if fits and model.is_discrete and close(_held_prediction(o), ref) else None
    E = np.eye(n + p + m)
    E[:n] = o._F
    try:
        Lg = sla.logm(E)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not (np.all(np.isfinite(Lg)) and np.abs(np.imag(Lg)).max() <= rtol * np.abs(Lg).max()):
        return None
    Lg = np.real(Lg)
    if not close(sla.expm(Lg), E):
        return None
    L = Lg[:n, n + p:]
    Z = np.zeros((n + p, n + p))
    Z[:n] = np.hstack([Lg[:n, :n] + L @ C, Lg[:n, n:n + p] + L @ D])  # [A, B] dt
    if fits and not model.is_discrete:
        dt = float(np.sum(Z[:n] * ref) / np.sum(ref * ref))
        if not (dt > 0 and close(Z[:n], dt * ref)):
            return None
    Ed = sla.expm(Z)
    return Ed[:n, :n], Ed[:n, n:]


class ObserverStream:
    """Directional observers, a Beard-Jones bank or a steady Kalman filter, block by block (module docstring).

    Parameters
    ----------
    det : DirectionalObserver, BeardJonesBank or KalmanInnovationDetector
        The designed detector (``beard-jones-v1``, ``lmi-detection-v1``, ``kalman-nis-v1``).
    model : LinearModel
        The model it was designed from (input and output names; the trim the non-command inputs
        are held at).
    command_names : sequence of str
        The commands the loop logs.
    id : str, optional
        The member id (default ``det.id``).
    """

    independent = False
    estimate_names: tuple[str, ...] = ()

    def __init__(self, det: Any, model: Any, command_names: Sequence[str], id: str | None = None) -> None:
        self.id = str(id or det.id)
        self.hypotheses: tuple[str, ...] = tuple(det.hypotheses)
        self.output_names: tuple[str, ...] = tuple(model.output_names)
        self.input_names, col = command_columns(model, command_names)
        self._ratio = isinstance(det, BeardJonesBank)
        self.window_n, self.n_lags = 1, 0
        m, p = len(self.output_names), len(model.input_names)
        if isinstance(det, KalmanInnovationDetector):
            self.mode = _KALMAN_MODES[det.test]
            obs, Ws, plants = [det._observer], [det._W], [(det.design.model.A, det.design.model.B)]
            dirs, angles, thr_f = [np.zeros((0, m))], [0.0], [float(det.threshold)]
            if self.mode != MODE_NIS:
                self.window_n, self.n_lags = int(det.window_n), int(det.n_lags)
        elif isinstance(det, (DirectionalObserver, BeardJonesBank)):
            self.mode = MODE_DIRECTIONAL
            filters = list(det.filters) if self._ratio else [det]
            obs, Ws = [f.observer for f in filters], [f._W for f in filters]
            # an LMI filter keeps no discrete plant model: recovered from its ZOH observer (module docstring)
            plants = [(f.design.model.A, f.design.model.B) if isinstance(f, BeardJonesFilter) else
                      _plant_of(f.observer, model, isinstance(f, LmiDetectionFilter)) for f in filters]
            dirs = [np.asarray(f._dirs, float).T for f in filters]
            angles, thr_f = [float(f.max_angle_rad) for f in filters], [float(f.threshold) for f in filters]
        else:
            raise DesignError(f"ObserverStream covers DirectionalObserver, BeardJonesBank and KalmanInnovationDetector, "
                              f"not {type(det).__name__}")
        self._thr = 1.0 if self._ratio else float(det.threshold)
        self.fault_directions = self.mode == MODE_DIRECTIONAL
        shapes = {(o._F.shape, o._H.shape) for o in obs}
        n = obs[0]._F.shape[0]
        if len(shapes) != 1 or obs[0]._H.shape != (m, n + p + m):
            raise DesignError(f"{self.id}: every observer must have the model's {p} inputs and {m} outputs, and a bank's "
                              f"filters the same states; got F, H shapes {sorted(shapes)}")
        stack = lambda arrs, shape: np.ascontiguousarray(np.stack([np.asarray(a, float).reshape(shape) for a in arrs]))  # noqa: E731
        self._F, self._H = stack([o._F for o in obs], (n, n + p + m)), stack([o._H for o in obs], (m, n + p + m))
        #: per observer: the update without a measurement is the plant's exact prediction
        self.open_loop_exact: tuple[bool, ...] = tuple(pl is not None for pl in plants)
        self._Fo = stack([np.hstack(pl) if pl is not None else _held_prediction(o) for o, pl in zip(obs, plants)],
                         (n, n + p))
        self._u0, self._y0 = stack([o._u0 for o in obs], (p,)), stack([o._y0 for o in obs], (m,))
        self._uhold = np.ascontiguousarray(np.asarray(model.u0, dtype=float).reshape(p))
        self._ucol = np.ascontiguousarray(col, dtype=np.int64)
        self._wrap = np.array([is_wrapped(nm) for nm in self.output_names], dtype=np.bool_)
        self._W = stack(Ws, (m, m))
        self._dirs = np.zeros((len(obs), max(1, max(d.shape[0] for d in dirs)), m))
        for k, d in enumerate(dirs):
            self._dirs[k, : d.shape[0]] = d
        self._n_dirs = np.array([d.shape[0] for d in dirs], dtype=np.int64)
        self._h_off = np.concatenate([[0], np.cumsum(self._n_dirs)[:-1]]).astype(np.int64)
        self._max_angle, self._thr_f = np.array(angles, dtype=float), np.array(thr_f, dtype=float)
        self.residual_names: tuple[str, ...] = (self.output_names if len(obs) == 1 else
                                                tuple(f"f{k}.{nm}" for k in range(len(obs)) for nm in self.output_names))
        self.reset()

    @property
    def threshold(self) -> float:
        """The alarm threshold [-]: on ``r' S^-1 r`` (a filter), the window statistic (Kalman), or on
        ``max_f stat_f / threshold_f`` (a bank, 1 as designed)."""
        return self._thr

    def set_threshold(self, value: float) -> None:
        """Set the threshold [-] (the kernel isolates above it; a bank's per-filter scales stay)."""
        self._thr = float(value)

    def reset(self) -> None:
        """Every estimate at trim (zero deviation), the innovation window empty."""
        self._xh = np.zeros(self._F.shape[:2])
        self._zring = np.zeros((self.window_n, len(self.output_names)))
        self._zbad = np.zeros(self.window_n, dtype=np.int64)
        m = len(self.output_names)
        self._lags = np.zeros((self.n_lags if self.mode == MODE_WHITENESS else 0, m, m))
        self._ist = np.zeros(2, dtype=np.int64)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """One design point: a reset (``h_ft`` [ft], ``vc_kts`` [kt] unused)."""
        self.reset()

    def design_key(self) -> bytes:
        """sha256 of every matrix, trim, direction, per-filter scale and window setting (not the threshold)."""
        return hash_arrays("ObserverStream", (self._F, self._Fo, self._H, self._u0, self._y0, self._uhold, self._ucol,
                                              self._wrap, self._W, self._dirs, self._n_dirs, self._max_angle, self._thr_f),
                           (self.mode, self._ratio, self.window_n, self.n_lags, self.input_names, self.output_names,
                            self.hypotheses))

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """``N`` samples (:meth:`fdi_sim.detectors.stream.StreamingDetector.process_block`); ``t_s`` [s]
        and ``fresh`` are not used."""
        _observer_kernel(self.mode, self._ratio, self._F, self._Fo, self._H, self._u0, self._y0, self._uhold, self._ucol,
                         self._wrap, self._W, self._dirs, self._n_dirs, self._h_off, self._max_angle, self._thr_f,
                         self._thr, self._xh, self._zring, self._zbad, self._lags, self._ist, u, y, ok,
                         out.statistic, out.threshold, out.valid, out.hypothesis, out.point, out.residual, out.cosine)


def observer_stream(det: Any, model: Any, command_names: Sequence[str], id: str | None = None) -> ObserverStream | None:
    """The compiled stream of a directional observer (Beard-Jones, LMI), a Beard-Jones bank or a steady
    Kalman innovation detector; None for any other detector."""
    if isinstance(det, (DirectionalObserver, BeardJonesBank, KalmanInnovationDetector)):
        return ObserverStream(det, model, command_names, id)
    return None

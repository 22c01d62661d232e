"""The streaming kernel of gain-scheduled ``kalman-gust-v1`` (one numba call per block of samples).

Per detector sample ``j`` (the time convention of :mod:`fdi_sim.detectors.samples`: ``u_j`` the
command averaged over the interval ending at ``t_j``, ``y_j`` measured at ``t_j``), with the active
schedule point ``c`` (:mod:`fdi_sim.detectors.scheduled`)::

    schedule s_j = s_{j-1} + (y_s,j - s_{j-1}) / (tau rate)      (measured h, vc, low-passed; a
             missing or excluded one replaced by the filter's last prediction of it)
    switch   i = argmin_i d_i(s_j);  if d_c - d_i > hysteresis:  x += x0_c - x0_i,  c = i
             (the heading state's difference wrapped to [-pi, pi): one heading, however its trim reads)
    predict  yhat_j = y0_c + C_c x + D_c (u_j - u0_c)
    innovate nu_j = y_j - yhat_j          (0 for a missing or excluded measurement; the heading's
             wrapped to [-pi, pi): after a full orbit the filter's heading state is 2 pi on)
    update   x = A_c (x + K_c(j) nu_j) + B_c (u_j - u0_c)     (the heading state wrapped to [-pi, pi))
    test     m_j = (1/W) sum_{l<W} nu_{j-l},   T_j = m_j' Sigma_c^-1 m_j  vs  threshold_c

(gust_kalman.py eq. for ``innovations``, ``window_means`` and ``statistic``). While
``T_j > threshold_c`` the window mean is matched against every hypothesis' signature
(:func:`fdi_sim.detectors.gust_kalman.isolate`: the largest cosine in the metric
``Sigma_c^-1``, onsets up to one window before the exceedance started; ``-1`` below
``min_cosine``).

Every state lives in arrays created by :meth:`GustKalmanStream.reset`; :meth:`process` makes one
compiled call whatever the block length, and the result does not depend on how a flight is cut
into blocks (the window sum is taken in ring order, never as a running difference). The numbers
agree with :meth:`GustKalmanDetector.run` to rounding (that one uses numpy's matrix products and
cumulative sums).
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.gust_kalman import settle_samples
from fdi_sim.detectors.samples import is_wrapped
from fdi_sim.detectors.scheduled import SCHEDULE_SIGNALS, GustKalmanSchedule
from fdi_sim.detectors.stream import BlockOutputs

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, nogil=True)
def _process(A, B, C, D, G, u0, y0, x0, L, Si_g, g_Si_g, Si, thr, points, spacing, hyst, min_cos, wrap,
             wrap_x, i_sched, k0, a_sched, s_f, x, buf, st, u, y, ok,
             out_T, out_thr, out_valid, out_hyp, out_cos, out_point, out_nu, out_yhat):  # pragma: no cover
    P, n, _ = A.shape
    p = C.shape[1]
    mc = B.shape[2]
    J = G.shape[1] - 1
    W = buf.shape[0]
    H = Si_g.shape[1]
    S = points.shape[1]
    N = u.shape[0]
    du = np.empty(mc)
    nu = np.empty(p)
    xk = np.empty(n)
    m = np.empty(p)
    for j in range(N):
        c = st[1]
        # --- schedule: nearest point with hysteresis, bumpless transfer ---------------------
        if P > 1:
            for s in range(S):  # first-order low pass: turbulence moves vc by ~5 kt rms
                # a missing or excluded scheduling sensor is replaced by the filter's last prediction
                v = y[j, i_sched[s]] if ok[j, i_sched[s]] else s_f[S + s]
                s_f[s] += a_sched * (v - s_f[s])
            best = 0
            dbest = 1e300
            dc = 0.0
            for i in range(P):
                d2 = 0.0
                for s in range(S):
                    e = (s_f[s] - points[i, s]) / spacing[s]
                    d2 += e * e
                d = math.sqrt(d2)
                if d < dbest:
                    dbest = d
                    best = i
                if i == c:
                    dc = d
            if best != c and dc - dbest > hyst:
                for a in range(n):
                    dx0 = x0[c, a] - x0[best, a]
                    if wrap_x[a] and not -math.pi <= dx0 < math.pi:
                        # a heading trim is an angle: 0 and 2 pi are one trim (JSBSim reports psi in
                        # [0, 2 pi), so a trim a hair left of north reads 6.2832); carrying the
                        # unwrapped difference put a 2 pi step into the heading innovation
                        dx0 = (dx0 + math.pi) % TWO_PI - math.pi
                    x[a] += dx0
                c = best
                st[1] = c
        # --- filter --------------------------------------------------------------------------
        for b in range(mc):
            du[b] = u[j, b] - u0[c, b]
        jj = st[0]
        jg = jj if jj < J else J
        for r in range(p):
            pred = 0.0
            for a in range(n):
                pred += C[c, r, a] * x[a]
            for b in range(mc):
                pred += D[c, r, b] * du[b]
            out_yhat[j, r] = y0[c, r] + pred
            for s in range(S):
                if i_sched[s] == r:
                    s_f[S + s] = y0[c, r] + pred  # the prediction a later sample may schedule on
            if ok[j, r]:
                dy = y[j, r] - y0[c, r]
                if wrap[r]:
                    dy = (dy + math.pi) % TWO_PI - math.pi
                nu[r] = dy - pred
                if wrap[r] and not -math.pi <= nu[r] < math.pi:
                    # an angle's innovation (the filter's heading may have turned past pi); wrapped
                    # only when outside, so that a flight that never wraps keeps its bits
                    nu[r] = (nu[r] + math.pi) % TWO_PI - math.pi
            else:
                nu[r] = 0.0
            out_nu[j, r] = nu[r]
        for a in range(n):
            acc = x[a]
            for r in range(p):
                acc += G[c, jg, a, r] * nu[r]
            xk[a] = acc
        for a in range(n):
            acc = 0.0
            for b in range(n):
                acc += A[c, a, b] * xk[b]
            for b in range(mc):
                acc += B[c, a, b] * du[b]
            if wrap_x[a] and not -math.pi <= acc < math.pi:  # the heading deviation: on the circle
                acc = (acc + math.pi) % TWO_PI - math.pi
            x[a] = acc
        slot = jj % W
        for r in range(p):
            buf[slot, r] = nu[r]
        jj += 1
        st[0] = jj
        out_point[j] = c
        out_thr[j] = thr[c]
        out_hyp[j] = -1
        out_cos[j] = np.nan
        if jj <= k0:
            out_T[j] = np.nan
            out_valid[j] = False
            st[2] = 0
            continue
        # --- windowed test ---------------------------------------------------------------------
        for r in range(p):
            acc = 0.0
            for l in range(W):
                acc += buf[l, r]
            m[r] = acc / W
        T = 0.0
        for r in range(p):
            z = 0.0
            for q in range(p):
                z += m[q] * L[c, q, r]
            T += z * z
        out_T[j] = T
        out_valid[j] = math.isfinite(T)
        if not (T > thr[c]):
            st[2] = 0
            continue
        if st[2] == 0:
            st[2] = jj  # the sample count at which the exceedance began
        since = jj - st[2]
        # --- isolation: cosine to each signature, onsets within the window ------------------------
        mSm = 0.0
        for r in range(p):
            acc = 0.0
            for q in range(p):
                acc += Si[c, r, q] * m[q]
            mSm += m[r] * acc
        w0 = W - 1 if since >= W else 0
        best_h = -1
        best_c = -1.0
        for h in range(H):
            for w in range(w0, W):
                num = 0.0
                for r in range(p):
                    num += Si_g[c, h, w, r] * m[r]
                den = math.sqrt(g_Si_g[c, h, w] * mSm)
                if den > 0.0:
                    cs = abs(num) / den
                    if cs > best_c:
                        best_c = cs
                        best_h = h
        out_cos[j] = best_c
        if best_c >= min_cos:
            out_hyp[j] = best_h


class GustKalmanStream:
    """A :class:`GustKalmanSchedule` run sample by sample, in blocks (module docstring).

    Parameters
    ----------
    schedule : GustKalmanSchedule
    min_cosine : float
        Isolation reject level [-] (the detector's ``min_cosine``).
    id : str
        Detector id for logs and reports.
    """

    def __init__(self, schedule: GustKalmanSchedule, *, min_cosine: float = 0.7, id: str = "kalman-gust-v1") -> None:
        self.schedule = schedule
        self.id = id
        self.min_cosine = float(min_cosine)
        d0 = schedule.designs[0]
        m0 = d0.model
        cols = list(d0.control_columns)
        self.input_names: tuple[str, ...] = tuple(m0.input_names[i] for i in cols)
        self.output_names: tuple[str, ...] = tuple(m0.output_names)
        self.hypotheses: tuple[str, ...] = tuple(d0.hypotheses)
        self.rate_hz = float(d0.rate_hz)
        P, n, p = schedule.n_points, m0.n_states, m0.n_outputs
        Jmax = max(len(d.gains) for d in schedule.designs)
        self._A = np.empty((P, n, n))
        self._B = np.empty((P, n, len(cols)))
        self._C = np.empty((P, p, n))
        self._D = np.empty((P, p, len(cols)))
        self._G = np.empty((P, Jmax, n, p))
        self._u0 = np.empty((P, len(cols)))
        self._y0 = np.empty((P, p))
        self._x0 = np.empty((P, n))
        self._L = np.empty((P, p, p))
        self._Si = np.empty((P, p, p))
        H, W = d0.signatures.shape[:2]
        self._Si_g = np.empty((P, H, W, p))
        self._g_Si_g = np.empty((P, H, W))
        for i, (d, cal) in enumerate(zip(schedule.designs, schedule.calibrations)):
            m = d.model
            self._A[i] = m.A
            self._B[i] = np.asarray(m.B)[:, cols]
            self._C[i] = m.C
            self._D[i] = np.asarray(m.D)[:, cols]
            g = np.asarray(d.gains)
            self._G[i, : len(g)] = g
            self._G[i, len(g):] = g[-1]  # the steady gain from then on (as min(j, J) in the detector)
            self._u0[i] = np.asarray(m.u0, dtype=float)[cols]
            self._y0[i] = np.asarray(m.y0, dtype=float)
            self._x0[i] = np.asarray(m.x0, dtype=float)
            Si = np.linalg.inv(cal.sigma_m)
            self._Si[i] = Si
            self._L[i] = np.linalg.cholesky(Si)
            self._Si_g[i] = np.einsum("pq,hwq->hwp", Si, d.signatures)
            self._g_Si_g[i] = np.einsum("hwp,hwp->hw", self._Si_g[i], d.signatures)
        self._thr = schedule.thresholds.astype(float)
        self._wrap = np.array([is_wrapped(nm) for nm in self.output_names])
        self._wrap_x = np.array([is_wrapped(nm) for nm in m0.state_names])  # the heading state
        self._i_sched = np.array([self.output_names.index(s) for s in SCHEDULE_SIGNALS], dtype=np.int64)
        self._k0 = settle_samples(d0)
        self.window_n = d0.window_n
        self._a_sched = 1.0 / max(1.0, schedule.tau_s * self.rate_hz)  # low pass of the scheduling signals
        self.reset()

    #: the streaming contract (:class:`fdi_sim.detectors.stream.StreamingDetector`): the residual is
    #: the innovation, the estimate the predicted measurement; the filter compares the sensors through
    #: a model (not independent), and isolates by fault direction (the cosine)
    independent = False
    fault_directions = True
    #: the statistic's form, for the threshold's tail (fdi_sim.decision.tail.episode_threshold): a
    #: windowed quadratic form of the innovations (chi-square-like), exponential in the statistic
    tail_power = 1.0

    @property
    def n_outputs(self) -> int:
        return len(self.output_names)

    @property
    def residual_names(self) -> tuple[str, ...]:
        """The innovation's columns (one per measurement)."""
        return self.output_names

    @property
    def estimate_names(self) -> tuple[str, ...]:
        """The predicted measurements' columns (reconfiguration substitutes them)."""
        return self.output_names

    @property
    def threshold(self) -> float:
        """The alarm threshold on the statistic [-] (every schedule point alike: each point's
        statistic is normalized by its own ``Sigma_m``)."""
        return float(self._thr[0])

    def set_threshold(self, value: float) -> None:
        """Set the threshold of every schedule point [-]."""
        self._thr[:] = float(value)

    @property
    def samples_seen(self) -> int:
        """Samples processed since the last reset (the gain index of the next one)."""
        return int(self._st[0])

    def effectiveness_estimator(self, actuator: str):
        """An estimator of ``actuator``'s effectiveness from this filter's innovations (reconfiguration
        of a confirmed actuator fault; :class:`~fdi_sim.detectors.effectiveness.EffectivenessEstimator`)."""
        from fdi_sim.detectors.effectiveness import EffectivenessEstimator

        return EffectivenessEstimator(self, actuator)

    def design_key(self) -> bytes:
        """What the statistic depends on (not the threshold): the matrices, gains, ``Sigma_m^-1`` and
        schedule points, and the window (the bytes the shipped thresholds files' design hashes were
        made of, :func:`fdi_sim.bank.members.design_hash`)."""
        parts = [np.ascontiguousarray(a, dtype=np.float64).tobytes()
                 for a in (self._A, self._B, self._C, self._D, self._L, self._G, self._Si, self.schedule.points)]
        return b"".join(parts) + str(self.window_n).encode()

    def design_arrays(self) -> tuple[NDArray[np.float64], ...]:
        """The floating-point results :meth:`design_key` hashes (the shipped atlas compares them within
        a tolerance, :mod:`fdi_sim.training.atlas`: another CPU rounds them differently)."""
        return (self._A, self._B, self._C, self._D, self._L, self._G, self._Si, self.schedule.points)

    def design_key_exact(self) -> bytes:
        """What :meth:`design_key` depends on that is not a floating-point result: the window and the
        arrays' shapes."""
        return (str(self.window_n) + repr([a.shape for a in self.design_arrays()])).encode()

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """The streaming contract's call (:meth:`process` into ``out``; ``t_s`` and ``fresh`` unused:
        a held value is a valid measurement of the filter's sample)."""
        self.process(u, y, ok, out.statistic, out.threshold, out.valid, out.hypothesis, out.cosine, out.point,
                     out.residual, out.estimate)

    def reset(self, point: int | None = None) -> None:
        """Fresh filter at the trim of ``point`` (default: the nearest to the first design's trim, 0)."""
        P, n = self._x0.shape
        self._x = np.zeros(n)
        self._buf = np.zeros((self.window_n, self.n_outputs))
        self._st = np.array([0, 0 if point is None else int(point), 0], dtype=np.int64)  # j, active point, alarm start
        pt = self.schedule.points[int(self._st[1])].astype(float)
        self._s_f = np.concatenate([pt, pt])  # the low-passed (h_ft, vc_kts), then the last predictions

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """Reset at the point nearest the given scheduling values (the flight's start)."""
        self.reset(self.schedule.nearest((h_ft, vc_kts)))
        self._s_f[:] = (h_ft, vc_kts, h_ft, vc_kts)

    def process(self, u: NDArray[np.float64], y: NDArray[np.float64], ok: NDArray[np.bool_],
                out_statistic: NDArray[np.float64], out_threshold: NDArray[np.float64], out_valid: NDArray[np.bool_],
                out_hypothesis: NDArray[np.int64], out_cosine: NDArray[np.float64], out_point: NDArray[np.int64],
                out_innovation: NDArray[np.float64], out_estimate: NDArray[np.float64]) -> None:
        """``N`` samples: absolute ``u`` (N, inputs) in :attr:`input_names` order, absolute ``y``
        (N, outputs) in :attr:`output_names` order (heading as measured), ``ok`` (N, outputs) a
        usable measurement. Writes the statistic [-], threshold [-], validity, isolated hypothesis
        (index into :attr:`hypotheses`, -1: none), its cosine [-], the active point, the innovation
        and the predicted measurement (the filter's estimate of each sensor, in its units)."""
        _process(self._A, self._B, self._C, self._D, self._G, self._u0, self._y0, self._x0, self._L, self._Si_g,
                 self._g_Si_g, self._Si, self._thr, self.schedule.points, self.schedule.spacing,
                 float(self.schedule.hysteresis), self.min_cosine, self._wrap, self._wrap_x, self._i_sched, self._k0,
                 self._a_sched, self._s_f, self._x, self._buf, self._st, u, y, ok,
                 out_statistic, out_threshold, out_valid, out_hypothesis, out_cosine, out_point, out_innovation,
                 out_estimate)

"""Streaming, block-invariant form of the parity window (:class:`~fdi_sim.detectors.window_detector.WindowParityDetector`).

The runtime of ``parity-v1``, ``parity-robust-v1``, ``parity-stochastic-v1`` and ``pca-v1``
(:mod:`fdi_sim.detectors.catalogue_parity`) as one compiled call per block of samples. Per
sample ``j`` (the time convention of :mod:`fdi_sim.detectors.samples`), the same numbers as the
detector's ``step``::

    row      w_j   = [y_j - y0 ; u_k,j - u0_k]              (heading deviations wrapped to [-pi, pi))
    window   W_j   = [w_{j-s} ; ... ; w_j]                  (oldest first, Lou, Willsky & Verghese 1986, eq. 4-8)
    residual rw_j  = G W_j,  G = S^-1/2 [Py' | Pu']         (whitened parity residual)
    test     T_j   = rw_j' rw_j  vs  threshold               (chi-square, Hagenblad et al. eq. 13)
    isolate  h_j   = argmax_i  mu_i' rw_j / |rw_j|          (smallest angle, Hagenblad et al. Algorithm 1)

``T_j`` is 0 and invalid until the window holds ``s + 1`` samples. The isolated hypothesis is
written on every valid sample with ``T_j > threshold`` (the detector isolates only on alarm),
-1 otherwise and when the smallest angle exceeds the reject angle or every hypothesis is
undetectable. The parity window has no fault directions in the sense of the angle-magnitude rule
(``cosine`` is NaN).

Invalid measurements: a sample with any output not ``ok`` (dropout, excluded) or not finite, or a
non-finite command, enters the window as zeros and is counted; every window that contains it is
invalid (statistic NaN, residual NaN, no isolation). The window state stays finite, so the
detector is valid again ``s + 1`` samples after the last bad one. (The detector's ``step`` raises
on a non-finite input instead.)

Model inputs that are not logged commands (the gust inputs ``u_gust_body_fps`` ...) are held at
the model's trim, as :func:`fdi_sim.offline.detect.run_detector` does. ``fresh`` is not used: a held
value is a valid measurement at the sample.

Numbers: the products are summed in a different order than numpy's BLAS (``G @ window``), so the
statistic agrees with ``step`` to rounding (relative 2e-13 at most, measured over 20 000 samples of
the F-16 model's response), not bitwise; the
block size never changes a bit (all state in arrays, one sequential loop).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.samples import is_wrapped
from fdi_sim.detectors.stream import command_columns, hash_arrays
from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.detectors.window_detector import WindowParityDetector
from fdi_sim.errors import DesignError

__all__ = ["WindowParityStream", "window_parity_stream"]

_TWO_PI = 2.0 * math.pi
# int state
_S_SEEN, _S_POS, _S_NBAD = range(3)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _parity_kernel(G, dirs, cos_mask, y0, u0k, uhold, ucol, wrap, thr, reject_rad, buf, bad, ist, u, y, ok,
                   out_stat, out_thr, out_valid, out_hyp, out_point, out_res, out_cos):  # pragma: no cover - compiled
    """``N`` samples through the window (module docstring); state ``buf``, ``bad``, ``ist`` in place."""
    L, ncol = buf.shape
    n_y = y0.shape[0]
    n_u = u0k.shape[0]
    p = G.shape[0]
    H = dirs.shape[0]
    N = y.shape[0]
    if (u.shape[0] != N or ok.shape[0] != N or ok.shape[1] != n_y or y.shape[1] != n_y or out_stat.shape[0] != N
            or out_res.shape[0] != N or out_res.shape[1] != p):
        raise ValueError("WindowParityStream.process_block: u, y, ok and the outputs must have one row per sample")
    rw = np.empty(p)
    for j in range(N):
        pos = ist[_S_POS]
        good = True
        for i in range(n_y):
            v = y[j, i]
            if ok[j, i] and math.isfinite(v):
                d = v - y0[i]
                if wrap[i]:
                    d = (d + math.pi) % _TWO_PI - math.pi
                buf[pos, i] = d
            else:
                buf[pos, i] = 0.0  # a bad value never enters the arithmetic
                good = False
        for k in range(n_u):
            c = ucol[k]
            d = (u[j, c] if c >= 0 else uhold[k]) - u0k[k]
            if not math.isfinite(d):
                d = 0.0
                good = False
            buf[pos, n_y + k] = d
        ist[_S_NBAD] += (0 if good else 1) - bad[pos]
        bad[pos] = 0 if good else 1
        pos = (pos + 1) % L
        ist[_S_POS] = pos  # now the oldest sample of the window
        ist[_S_SEEN] += 1
        # rw = G @ window, the window's rows oldest first
        sq = 0.0
        for a in range(p):
            acc = 0.0
            for l in range(L):
                row = (pos + l) % L
                for c in range(ncol):
                    acc += G[a, l * ncol + c] * buf[row, c]
            rw[a] = acc
            sq += acc * acc
        full = ist[_S_SEEN] >= L
        clean = ist[_S_NBAD] == 0
        out_thr[j] = thr
        out_point[j] = 0
        out_cos[j] = np.nan
        out_hyp[j] = -1
        for a in range(p):
            out_res[j, a] = rw[a] if clean else np.nan
        if not full:
            out_stat[j] = 0.0
            out_valid[j] = False
            continue
        if not clean:
            out_stat[j] = np.nan
            out_valid[j] = False
            continue
        valid = math.isfinite(sq)
        out_stat[j] = sq
        out_valid[j] = valid
        if not (valid and sq > thr) or H == 0 or sq == 0.0:
            continue
        # isolation: the largest cosine among the detectable hypotheses (first of equal maxima)
        inv = 1.0 / math.sqrt(sq)
        best = -1
        best_m = -np.inf
        best_c = 0.0
        for h in range(H):
            acc = 0.0
            for a in range(p):
                acc += dirs[h, a] * rw[a]
            cs = acc * inv
            m = cs + cos_mask[h]
            if best < 0 or m > best_m:
                best, best_m, best_c = h, m, cs
        if best_m == -np.inf:  # every hypothesis undetectable
            continue
        if math.acos(min(max(best_c, -1.0), 1.0)) <= reject_rad:
            out_hyp[j] = best


class WindowParityStream:
    """A :class:`WindowParityDetector` run block by block in one compiled call (module docstring).

    Parameters
    ----------
    det : WindowParityDetector
        The designed detector (parity, robust parity, stochastic parity or PCA).
    model : LinearModel
        The model it was designed from (input and output names, the trim the non-command inputs
        are held at).
    command_names : sequence of str
        The commands the loop logs (e.g. ``("elevator_cmd_norm", "aileron_cmd_norm",
        "rudder_cmd_norm", "throttle_cmd_norm")``).
    id : str, optional
        The member id (default ``det.id``).
    """

    #: the streaming contract (:class:`fdi_sim.detectors.stream.StreamingDetector`)
    independent = False
    fault_directions = False
    estimate_names: tuple[str, ...] = ()

    def __init__(self, det: WindowParityDetector, model: Any, command_names: Sequence[str], id: str | None = None) -> None:
        if not isinstance(det, WindowParityDetector):
            raise DesignError(f"WindowParityStream needs a WindowParityDetector, got {type(det).__name__}")
        if len(model.output_names) != det.y0.size:
            raise DesignError(f"{det.id}: the model has {len(model.output_names)} outputs, the detector {det.y0.size}")
        if det.u0.size != len(model.input_names):
            raise DesignError(f"{det.id}: the model has {len(model.input_names)} inputs, the detector's trim {det.u0.size}")
        self.id = str(id or det.id)
        self.hypotheses: tuple[str, ...] = tuple(det.hypotheses)
        self.input_names, col = command_columns(model, command_names)
        self.output_names: tuple[str, ...] = tuple(model.output_names)
        known = np.array(det.known_inputs, dtype=np.int64)
        self.order_s = int(det.order_s)
        self._G = np.ascontiguousarray(det._G, dtype=float)
        self.residual_names: tuple[str, ...] = tuple(f"r{i}" for i in range(self._G.shape[0]))
        self._dirs = np.ascontiguousarray(det._dirs, dtype=float).reshape(len(self.hypotheses), self._G.shape[0])
        self._cos_mask = np.ascontiguousarray(det._cos_mask, dtype=float).reshape(len(self.hypotheses))
        self._y0 = np.ascontiguousarray(det.y0, dtype=float)
        self._u0k = np.ascontiguousarray(det.u0[known], dtype=float)
        self._uhold = np.ascontiguousarray(np.asarray(model.u0, dtype=float)[known])  # non-commands held at trim
        self._ucol = np.ascontiguousarray(col[known])
        self._wrap = np.array([is_wrapped(nm) for nm in self.output_names], dtype=np.bool_)
        self._reject_rad = float(det.reject_angle_rad)
        self._thr = float(det.threshold)
        self.reset()

    @property
    def threshold(self) -> float:
        """The alarm threshold on ``rw' rw`` [-] (chi-square with ``p`` dof when whitened)."""
        return self._thr

    def set_threshold(self, value: float) -> None:
        """Set the threshold [-] (the kernel isolates above it)."""
        self._thr = float(value)

    def reset(self) -> None:
        """Empty the window."""
        L = self.order_s + 1
        self._buf = np.zeros((L, self._y0.size + self._u0k.size))
        self._bad = np.zeros(L, dtype=np.int64)
        self._ist = np.zeros(3, dtype=np.int64)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """One design point: a reset (``h_ft`` [ft], ``vc_kts`` [kt] unused)."""
        self.reset()

    def design_key(self) -> bytes:
        """sha256 of the projection, directions, trims, input mapping and reject angle (not the threshold)."""
        return hash_arrays("WindowParityStream", (self._G, self._dirs, self._cos_mask, self._y0, self._u0k, self._uhold,
                                                  self._ucol, self._wrap),
                           (self.order_s, self._reject_rad, self.input_names, self.output_names, self.hypotheses))

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """``N`` samples (:meth:`fdi_sim.detectors.stream.StreamingDetector.process_block`); ``t_s`` [s]
        and ``fresh`` are not used."""
        _parity_kernel(self._G, self._dirs, self._cos_mask, self._y0, self._u0k, self._uhold, self._ucol, self._wrap,
                       self._thr, self._reject_rad, self._buf, self._bad, self._ist, u, y, ok, out.statistic,
                       out.threshold, out.valid, out.hypothesis, out.point, out.residual, out.cosine)


def window_parity_stream(det: Any, model: Any, command_names: Sequence[str], id: str | None = None) -> WindowParityStream | None:
    """The compiled stream of a :class:`WindowParityDetector` (parity, robust/stochastic parity, PCA); None otherwise."""
    if not isinstance(det, WindowParityDetector):
        return None
    return WindowParityStream(det, model, command_names, id)

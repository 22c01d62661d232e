"""fdi-sim-zscore: the benchmark's trivial baseline as a detector plugin (``zscore-v1``).

Per detector sample ``j`` (``y_j`` the measurement at ``t_j``: ``fdi_sim.detectors.samples``)::

    m     = (y_1 + ... + y_W) / W           the mean of the samples with t_j <= warmup_s, summed in order
    z_j   = |y_j - m| / scale               statistic [-], valid for t_j > warmup_s and a usable y_j

The sum runs sample by sample (never pairwise), so a twin outside fdi-sim that sums in the same
order gets the same bits. Implements ``fdi_sim.detectors.stream.StreamingDetector``: one compiled
call per block, state in arrays reset by :meth:`ZScoreDetector.reset`.
"""
from __future__ import annotations

import hashlib
import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["DETECTOR_ID", "ZScoreDetector", "__version__", "make_zscore"]
__version__ = "0.1.0"

DETECTOR_ID = "zscore-v1"
#: default scale per signal unit suffix [the signal's unit]
_SCALE = (("_radps", 0.01), ("_g", 0.05), ("_rad", 0.01), ("_kts", 2.0), ("_fps", 5.0), ("_ft", 20.0))


@numba.njit(cache=True, nogil=True)
def zscore_block(warmup_s, inv_scale, thr, st, t_s, y, ok, out_stat, out_thr, out_valid, out_hyp, out_point,
                 out_res, out_cos):  # pragma: no cover - compiled
    """``st`` = (sum, count) of the warm-up samples; rows 0 .. N-1 written (module docstring)."""
    for j in range(t_s.shape[0]):
        v = y[j]
        good = ok[j] and math.isfinite(v)
        out_thr[j] = thr
        out_point[j] = 0
        out_cos[j] = math.nan
        out_hyp[j] = -1
        if t_s[j] <= warmup_s:
            if good:
                st[0] += v
                st[1] += 1.0
            out_stat[j] = 0.0
            out_valid[j] = False
            out_res[j, 0] = math.nan
            continue
        if not good or st[1] == 0.0:
            out_stat[j] = math.nan
            out_valid[j] = False
            out_res[j, 0] = math.nan
            continue
        e = (v - st[0] / st[1]) * inv_scale
        z = abs(e)
        out_stat[j] = z
        out_valid[j] = True
        out_res[j, 0] = e
        if z > thr:
            out_hyp[j] = 0


class ZScoreDetector:
    """The z-score of one sensor against its warm-up mean (module docstring).

    Parameters
    ----------
    signal : str
        The watched measurement (a model output), e.g. ``"q_radps"``.
    warmup_s : float
        The samples at or before this flight time make the mean [s].
    scale : float
        The z-score's unit [the signal's unit].
    threshold : float
        Alarm threshold on ``z`` [-]; the host calibrates it on fault-free flights.
    """

    independent: bool = True
    fault_directions: bool = False

    def __init__(self, signal: str, warmup_s: float, scale: float, *, threshold: float = 5.0,
                 id: str = DETECTOR_ID) -> None:
        if not warmup_s > 0 or not scale > 0:
            raise ValueError(f"{id}: warmup_s and scale must be positive, got {warmup_s!r}, {scale!r}")
        self.signal, self.warmup_s, self.scale = signal, float(warmup_s), float(scale)
        self.id = id
        self.hypotheses: tuple[str, ...] = (signal,)
        self.input_names: tuple[str, ...] = ()
        self.output_names: tuple[str, ...] = (signal,)
        self.residual_names: tuple[str, ...] = ("z_" + signal,)
        self.estimate_names: tuple[str, ...] = ()
        self._threshold = 0.0
        self.set_threshold(threshold)
        self.reset()

    @property
    def threshold(self) -> float:
        """The alarm threshold on ``z`` [-]."""
        return self._threshold

    def set_threshold(self, value: float) -> None:
        """Set the threshold [-] (positive; ``inf``: never an alarm, how the host records calibration flights)."""
        v = float(value)
        if not v > 0:
            raise ValueError(f"{self.id}: threshold must be a positive number, got {value!r}")
        self._threshold = v

    def reset(self) -> None:
        """Warm-up sum and count at 0."""
        self._st = np.zeros(2)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """Reset at the flight's initial condition (no design point: as :meth:`reset`)."""
        self.reset()

    def design_key(self) -> bytes:
        """sha256 of the signal, warm-up, scale and version (not the threshold)."""
        return hashlib.sha256(f"{DETECTOR_ID} {__version__} {self.signal} {self.warmup_s!r} {self.scale!r}".encode()
                              ).digest()

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: Any) -> None:
        """Process ``N`` samples (one kernel call); ``y`` (N, 1) the signal, ``ok`` its usability."""
        n = t_s.shape[0]
        if y.shape != (n, 1) or ok.shape != (n, 1):
            raise ValueError(f"{self.id}: y and ok must be ({n}, 1) ({self.signal}), got {y.shape} and {ok.shape}")
        zscore_block(self.warmup_s, 1.0 / self.scale, self._threshold, self._st, np.ascontiguousarray(t_s),
                     np.ascontiguousarray(y[:, 0]), np.ascontiguousarray(ok[:, 0]), out.statistic, out.threshold,
                     out.valid, out.hypothesis, out.point, out.residual, out.cosine)

    def __repr__(self) -> str:
        return f"ZScoreDetector(signal={self.signal!r}, warmup_s={self.warmup_s}, scale={self.scale})"


def make_zscore(model: Any, *, signal: str = "q_radps", warmup_s: float = 5.0, scale: float | None = None,
                threshold: float = 5.0) -> ZScoreDetector:
    """The z-score of ``signal`` against its mean over the first ``warmup_s`` seconds; isolates it.

    Parameters
    ----------
    model : LinearModel
        The aircraft's model at the design point: only its output names are used (``signal`` must be one).
    signal : str
    warmup_s : float
        [s]
    scale : float, optional
        [the signal's unit]; default by unit suffix (0.01 rad/s, 0.05 g, 0.01 rad, 2 kt, 5 ft/s, 20 ft).
    threshold : float
        [-]; the host calibrates it.

    Raises
    ------
    ValueError
        ``signal`` is not a model output (the message lists them), or an option is not positive.
    """
    outputs = tuple(getattr(model, "output_names", ()) or ())
    if outputs and signal not in outputs:
        raise ValueError(f"{DETECTOR_ID}: signal {signal!r} is not an output of the model; outputs: {', '.join(outputs)}")
    if scale is None:
        scale = next((s for suf, s in _SCALE if signal.endswith(suf)), 1.0)
    return ZScoreDetector(signal, warmup_s, float(scale), threshold=threshold)

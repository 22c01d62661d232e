"""``cusum-residual-v1``: a two-sided CUSUM on one sensor's Kalman prediction error, as a bank member.

Implements the streaming contract of ``fdi_sim.detectors.stream`` (``StreamingDetector``):
``process_block`` makes one call of the compiled kernel (:mod:`fdi_sim_cusum.kernel`) whatever
the block's length; every state lives in arrays reset by :meth:`CusumResidualDetector.reset`.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim_cusum.design import CusumDesign, design_cusum
from fdi_sim_cusum.kernel import cusum_block

__all__ = ["DETECTOR_ID", "CusumResidualDetector", "make_cusum"]

#: the entry-point name (registry id) of this detector
DETECTOR_ID = "cusum-residual-v1"


class CusumResidualDetector:
    """Two-sided CUSUM on the normalized one-step prediction error of one measurement.

    Parameters
    ----------
    design : CusumDesign
        From :func:`fdi_sim_cusum.design.design_cusum`.
    threshold : float
        Alarm threshold ``h`` on the statistic [-].
    id : str
        Detector id within a bank (``/fdi/<id>/...`` topics).

    Attributes
    ----------
    id : str
    hypotheses : tuple of str
        ``(signal,)``: an alarm points at the watched sensor.
    input_names : tuple of str
        The model's command inputs (``*_cmd_norm``), absolute [-].
    output_names : tuple of str
        The outputs the predictor uses, absolute [their units].
    residual_names : tuple of str
        ``("e_<signal>",)``: the normalized prediction error [-].
    estimate_names : tuple of str
        ``()``: no reconstructed measurement.
    independent : bool
        False (model-based, not a comparison of independent sensor groups).
    fault_directions : bool
        False (``cosine`` is NaN).
    design : CusumDesign
    """

    independent: bool = False
    fault_directions: bool = False

    def __init__(self, design: CusumDesign, *, threshold: float = 10.0, id: str = DETECTOR_ID) -> None:
        self.design = design
        self.id = id
        self.hypotheses: tuple[str, ...] = (design.signal,)
        self.input_names: tuple[str, ...] = design.input_names
        self.output_names: tuple[str, ...] = design.output_names
        self.residual_names: tuple[str, ...] = ("e_" + design.signal,)
        self.estimate_names: tuple[str, ...] = ()
        self._threshold = 0.0
        self.set_threshold(threshold)
        self._inv_sd = 1.0 / design.signal_std
        self.reset()

    # --- thresholds ------------------------------------------------------------------------------
    @property
    def threshold(self) -> float:
        """The alarm threshold ``h`` on the statistic [-]."""
        return self._threshold

    def set_threshold(self, value: float) -> None:
        """Set the alarm threshold ``h`` [-] (positive; ``inf``, never an alarm, is how the host
        records the raw statistic of its calibration flights)."""
        v = float(value)
        if not v > 0:  # (False for NaN too)
            raise ValueError(f"{self.id}: threshold must be a positive number, got {value!r}")
        self._threshold = v

    # --- state -----------------------------------------------------------------------------------
    def reset(self) -> None:
        """Predictor at trim (``xhat = 0``), CUSUM sums at 0, the settle count restarted."""
        self._x = np.zeros(self.design.A.shape[0])
        self._g = np.zeros(2)  # (g+, g-) [-]
        self._st = np.array([0, self.design.settle_n], dtype=np.int64)  # samples since reset, settle left

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """Reset at the flight's initial condition (one design point: the same as :meth:`reset`)."""
        self.reset()

    def design_key(self) -> bytes:
        """sha256 of the model matrices, trims, selected signals and options (not the threshold)."""
        return self.design.key

    @property
    def samples_seen(self) -> int:
        """Samples processed since the last reset."""
        return int(self._st[0])

    @property
    def cusum(self) -> tuple[float, float]:
        """The current ``(g+, g-)`` [-]."""
        return float(self._g[0]), float(self._g[1])

    # --- the block -------------------------------------------------------------------------------
    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: Any) -> None:
        """Process ``N`` consecutive samples (one kernel call).

        Parameters
        ----------
        t_s : NDArray
            (N,) sample times [s] (not used: the detector runs at the rate it was designed for).
        u : NDArray
            (N, len(input_names)) absolute commands [-], averaged over each sample's interval.
        y : NDArray
            (N, len(output_names)) absolute measurements at ``t_s`` [their units].
        ok : NDArray of bool
            (N, len(output_names)) the measurement is usable.
        fresh : NDArray of bool
            (N, len(output_names)) not used: at the 20 Hz design rate every sensor is fresh at
            every sample; a held value is used as a measurement.
        out : BlockOutputs
            Rows ``0 .. N-1`` written (later rows untouched): statistic ``max(g+, g-)`` [-],
            threshold [-], valid, hypothesis (0 while the statistic exceeds the threshold on a
            valid sample, else -1), point 0, residual ``e_j`` [-] (NaN on a sample without the
            measurements), cosine NaN.
        """
        N = u.shape[0]
        p = len(self.output_names)
        if u.ndim != 2 or u.shape[1] != len(self.input_names):
            raise ValueError(f"{self.id}: u must be (N, {len(self.input_names)}) in the order "
                             f"{self.input_names}, got {u.shape}")
        if y.shape != (N, p) or ok.shape != (N, p):
            raise ValueError(f"{self.id}: y and ok must be ({N}, {p}) in the order {self.output_names}, "
                             f"got {y.shape} and {ok.shape}")
        if out.statistic.shape[0] < N or out.residual.shape[0] < N or out.residual.shape[1] != 1:
            raise ValueError(f"{self.id}: out must have at least {N} rows and 1 residual column "
                             f"(BlockOutputs.allocate(S, 1).rows(N)), got {out.statistic.shape[0]} rows, "
                             f"residual {out.residual.shape}")
        d = self.design
        cusum_block(d.A, d.B, d.C, d.D, d.K, d.u0, d.y0, d.wrap, d.signal_index, self._inv_sd, d.drift,
                    self._threshold, d.settle_n, self._x, self._g, self._st,
                    u, y, ok, out.statistic, out.threshold, out.valid, out.hypothesis, out.point, out.residual,
                    out.cosine)

    def __repr__(self) -> str:
        d = self.design
        return (f"CusumResidualDetector(id={self.id!r}, signal={d.signal!r}, drift={d.drift}, "
                f"threshold={self._threshold}, outputs={len(self.output_names)})")


def make_cusum(model: Any, *, signal: str = "q_radps", drift: float = 0.5, threshold: float = 10.0,
               gust_std_fps: float | Sequence[float] = 10.0, command_std: float = 0.002,
               noise_std: Mapping[str, float] | None = None, outputs: Sequence[str] | None = None,
               settle_s: float = 1.0) -> CusumResidualDetector:
    """Two-sided CUSUM on one sensor's Kalman prediction error; isolates that sensor.

    Page's CUSUM (Page 1954; Basseville & Nikiforov 1993, ch. 2) on ``e_j``, the one-step-ahead
    prediction error of ``signal`` from a steady-state Kalman predictor of ``model``, normalized
    by its predicted std: ``g+_j = max(0, g+_{j-1} + e_j - drift)``, ``g-_j = max(0, g-_{j-1} -
    e_j - drift)``, statistic ``max(g+_j, g-_j)`` [-]. A statistic above ``threshold`` points at
    ``signal`` (the one hypothesis).

    Parameters
    ----------
    model : LinearModel
        The aircraft's linearization at the scenario's initial point, discretized at the detector
        rate in the standard form of the detector samples (with ``*_gust_body_fps`` inputs).
    signal : str
        The watched measurement (a model output), e.g. ``"q_radps"``.
    drift : float
        CUSUM drift ``k`` [-], in units of the residual's std (>= 0).
    threshold : float
        Alarm threshold ``h`` on the statistic [-]; the host calibrates it on fault-free flights
        (:meth:`CusumResidualDetector.set_threshold`).
    gust_std_fps : float or sequence of 3 floats
        Std of the white gust noise per sample on the gust inputs [ft/s].
    command_std : float
        Std of the white noise on the command inputs per sample [-].
    noise_std : mapping, optional
        Measurement-noise std per output [output units]; defaults: gyros 0.002 rad/s,
        accelerometers 0.005 g, angles 0.003 rad, vc 0.5 kt, h 3 ft, hdot 1 ft/s.
    outputs : sequence of str, optional
        Outputs the predictor uses (default: all of the model's); must include ``signal``.
    settle_s : float
        Filter-only time after a reset or a gap in the measurements [s].

    Returns
    -------
    CusumResidualDetector

    Raises
    ------
    ValueError
        ``signal`` (or an entry of ``outputs`` / ``noise_std``) is not a model output (the
        message lists the outputs, with a "did you mean"), an option is out of range, or the
        noise model admits no stable predictor.
    """
    design = design_cusum(model, signal=signal, drift=drift, gust_std_fps=gust_std_fps, command_std=command_std,
                          noise_std=noise_std, outputs=outputs, settle_s=settle_s)
    return CusumResidualDetector(design, threshold=threshold)

"""fdi-sim-cusum: a worked example of an fdi-sim detector plugin.

Registers ``cusum-residual-v1`` in the entry-point group ``fdi_sim.detectors``
(``pyproject.toml``): a two-sided CUSUM on the normalized one-step prediction error of one
sensor from a steady-state Kalman predictor of the aircraft's linear model. The factory is
:func:`make_cusum`; the detector implements ``fdi_sim.detectors.stream.StreamingDetector``.
"""
from __future__ import annotations

from fdi_sim_cusum.design import DEFAULT_NOISE_STD, CusumDesign, design_cusum
from fdi_sim_cusum.detector import DETECTOR_ID, CusumResidualDetector, make_cusum

__all__ = ["DEFAULT_NOISE_STD", "DETECTOR_ID", "CusumDesign", "CusumResidualDetector", "design_cusum", "make_cusum",
           "__version__"]

__version__ = "0.1.0"

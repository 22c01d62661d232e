"""Default measurement noise for detector designs: the aircraft's own sensor suite.

A factory called with only a model used to take unit noise (1 rad/s on a gyro whose noise is
0.0014 rad/s) or refuse. The suite (``aircraft/<name>/sensors.toml``) says what the sensors
really do: per output ``sqrt(noise_std^2 + quantum^2 / 12)`` (white noise plus the uniform
rounding error of the quantizer) in the output's units. Turn-on biases are not noise: detectors
that must survive them model them (``kalman-gust-v1``) or are calibrated on flights.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError


def suite_sensor_std(model: Any, suite: str = "default") -> NDArray[np.float64] | None:
    """Per-output measurement noise [output units] of the model's aircraft, or None if unknown.

    Raises
    ------
    DesignError
        The model names an aircraft but an output has no sensor in its suite.
    """
    aircraft = (getattr(model, "meta", None) or {}).get("aircraft")
    if not aircraft:
        return None
    from fdi_sim.sensors import load_suite

    specs = {s.name: s for s in load_suite(aircraft, suite)}
    missing = [o for o in model.output_names if o not in specs]
    if missing:
        raise DesignError(f"outputs {missing} have no sensor in the {aircraft} suite {suite!r}; give the noise explicitly")
    return np.array([math.sqrt(specs[o].noise_std ** 2 + (specs[o].quantum or 0.0) ** 2 / 12.0)
                     for o in model.output_names])

"""Default noise and disturbance sizes for detector designs: the aircraft's own sensor suite and
JSBSim's turbulence at the model's point.

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


#: wing spans [ft] as JSBSim's ``metrics/bw-ft`` reports them (the rotational turbulence scales
#: with them; checked against JSBSim in tests/detectors/test_gust_kalman.py)
WINGSPAN_FT: dict[str, float] = {"f16": 30.0, "DHC6": 65.0}


def gust_sqrt(model: Any, turbulence: str) -> NDArray[np.float64] | None:
    """``diag(sigma_u, sigma_v, sigma_w)`` [ft/s] of JSBSim's Dryden gusts at the model's trim, in the
    order of its ``*_gust_body_fps`` disturbance columns (the white-noise size a design that cannot
    carry gust states gives them), or None when the model has no gust columns or trim speed.
    """
    from fdi_sim.detectors.disturbance import GUST_INPUTS, dryden_parameters

    names = list(getattr(model, "state_names", ()))
    cols = [n for n in model.input_names if n in GUST_INPUTS]
    if not cols or "vt_fps" not in names or "h_ft" not in names:
        return None
    aircraft = (getattr(model, "meta", None) or {}).get("aircraft")
    p = dryden_parameters(float(model.x0[names.index("h_ft")]), float(model.x0[names.index("vt_fps")]), turbulence,
                          WINGSPAN_FT.get(aircraft, 0.0))
    sig = {"u_gust_body_fps": p.sigma_u_fps, "v_gust_body_fps": p.sigma_v_fps, "w_gust_body_fps": p.sigma_w_fps}
    return np.diag([sig[c] for c in cols])

"""Sensor suite models (noise, bias, sample rate, quantization)."""
from __future__ import annotations

from fdi_sim.sensors.suite import Measurement, SensorSpec, SensorSuite, apply_overrides, load_suite

__all__ = ["Measurement", "SensorSpec", "SensorSuite", "apply_overrides", "load_suite"]

"""Registered sensor models."""
from __future__ import annotations

from fdi_sim.registry import register
from fdi_sim.sensors.suite import SensorSpec

register("sensor", "sampled-noisy-v1", "truth + turn-on bias + white noise, sample-and-hold at rate_hz, quantized", SensorSpec)

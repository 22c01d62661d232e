"""Shared fixtures: scenario texts and a quiet, temporary output folder."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault("JSBSIM_DEBUG", "0")

F16_BASE = """
name = "t_f16"
aircraft = "f16"
duration_s = 10.0
seed = 7
[initial]
h_ft = 10000.0
vt_kts = 400.0
[atmosphere]
turbulence = "moderate"
[[maneuvers]]
type = "doublet-v1"
axis = "elevator"
t_start_s = 2.0
amplitude_norm = 0.1
pulse_s = 1.0
"""


@pytest.fixture
def f16_text() -> str:
    return F16_BASE

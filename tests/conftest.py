"""Shared fixtures: scenario texts and a quiet, temporary output folder."""
from __future__ import annotations

import os
import signal

import pytest

os.environ.setdefault("JSBSIM_DEBUG", "0")

# A command put in the background by a non-interactive shell (`make test &`, a CI step's `cmd &`)
# starts with SIGINT ignored (POSIX sec. 2.11), its children inherit that, and Python then installs
# no KeyboardInterrupt handler: the tests that send SIGINT to a child saw it finish normally
# (measured: two tests, exit 0, in a `make test` started with `&`). A caught signal is reset to
# its default at exec, so catching it here gives every child the default SIGINT.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

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

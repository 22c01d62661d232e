"""Real flight logs for the review tests, flown once per test session.

``review_logs`` maps a stable name to an MCAP path (other suites rely on these names):

- ``fault``: F-16 pitch-gyro bias (``scenarios/f16_pitch_gyro_bias.toml``) shortened to 30 s,
  the default bank in the loop (detection, isolation, reconfiguration).
- ``fault_b``: the same scenario and seed with ``[fdi] reconfigure = false`` (the comparison).
- ``fault_seed``: the same scenario with another seed (13).
- ``fault_free``: DHC-6 cruise, moderate turbulence, the default bank, no fault (20 s).
- ``no_bank``: F-16 doublet, no ``[fdi]`` table (10 s).
- ``repaired``: an F-16 bank run SIGKILLed in flight, then ``fdi-sim repair``-ed.
- ``unrepaired``: the cut-off file itself (``read_log`` refuses it; review repairs a copy).
- ``diverged``: DHC-6, autopilot off, severe turbulence: status ``diverged``.
- ``interrupted``: an F-16 bank run stopped by its wall-clock limit: status ``interrupted``.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GYRO = ROOT / "scenarios" / "f16_pitch_gyro_bias.toml"

DHC6_FREE = """
name = "review_dhc6_fault_free"
aircraft = "DHC6"
duration_s = 20.0
seed = 3
[initial]
h_ft = 5000.0
vc_kts = 120.0
[atmosphere]
turbulence = "moderate"
[fdi]
bank = "default"
"""

F16_NO_BANK = """
name = "review_f16_no_bank"
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

DHC6_DIVERGE = """
name = "review_dhc6_diverge"
aircraft = "DHC6"
duration_s = 300.0
seed = 1
[initial]
h_ft = 5000.0
vc_kts = 120.0
[atmosphere]
turbulence = "severe"
[autopilot]
altitude = false
airspeed = false
lateral = false
[limits]
phi_max_deg = 60.0
"""


def _fly(text: str, log: Path, **kw: object) -> Path:
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly

    fly(loads(text), log.parent, log_path=log, progress=False, force=True, **kw)
    return log


def _gyro_text(duration_s: float, **replace: str) -> str:
    text = GYRO.read_text().replace("duration_s = 60.0", f"duration_s = {duration_s}")
    for old, new in replace.items():
        text = text.replace(old, new)
    return text


def _killed(folder: Path) -> Path:
    """A bank run SIGKILLed once its log holds a few flushed seconds (the unrepaired file)."""
    scn = folder / "killed.toml"
    scn.write_text(_gyro_text(600.0))
    log = folder / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ})
    try:
        deadline = time.time() + 180
        while time.time() < deadline and (not log.exists() or log.stat().st_size < 600_000):
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    return log


@pytest.fixture(scope="session")
def review_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Name -> path of real MCAP logs (see the module docstring); flown once per session, shared by
    the xdist workers (``tests/flown_once.py``)."""
    from flown_once import flown_once

    return flown_once(tmp_path_factory, "review_logs", _fly_review_logs)


def _fly_review_logs(d: Path) -> dict[str, Path]:
    """The logs of :func:`review_logs`, flown into ``d``."""
    from fdi_sim.flightlog import repair_log

    logs: dict[str, Path] = {}
    short = _gyro_text(30.0, **{'t_start_s = 30.0': 't_start_s = 20.0'})  # keep the rudder doublet inside 30 s
    logs["fault"] = _fly(short, d / "gyro.mcap")
    logs["fault_b"] = _fly(short.replace('bank = "default"', 'bank = "default"\nreconfigure = false'),
                           d / "gyro_noreconf.mcap")
    logs["fault_seed"] = _fly(short.replace("seed = 12", "seed = 13"), d / "gyro_seed13.mcap")
    logs["fault_free"] = _fly(DHC6_FREE, d / "dhc6_free.mcap")
    logs["no_bank"] = _fly(F16_NO_BANK, d / "no_bank.mcap")
    logs["diverged"] = _fly(DHC6_DIVERGE, d / "diverged.mcap")
    logs["interrupted"] = _fly(_gyro_text(600.0), d / "interrupted.mcap", wall_limit_s=1.0)
    logs["unrepaired"] = _killed(d)
    logs["repaired"] = d / "killed.repaired.mcap"
    repair_log(logs["unrepaired"], logs["repaired"])
    return logs

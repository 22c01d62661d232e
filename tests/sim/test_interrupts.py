"""Every way a run ends leaves a complete log; a failed start leaves the log path alone (issue 11).

The real CLI in subprocesses, stopped with real signals at random moments of a long DHC-6 flight
(with a fault, so that fault topics and events are in the file), read back with ``read_log`` and
with the ``mcap`` reader validating every chunk CRC. The default run interrupts
``N_DEFAULT`` flights per signal; ``-m slow`` interrupts 50 per signal (the issue's bar).
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from fdi_sim.flightlog import read_log, verify_log

REPO = Path(__file__).resolve().parents[2]
N_DEFAULT = 4
N_BAR = 50
RATE_HZ = 120.0

LONG_SCENARIO = (REPO / "scenarios" / "dhc6_cruise_doublets.toml").read_text().replace(
    "duration_s = 60.0", "duration_s = 3000.0") + """
[[faults]]
type = "sensor-bias-v1"
target = "vc_kts"
bias_kts = 3.0
t_start_s = 2.0
"""
assert "duration_s = 3000.0" in LONG_SCENARIO
#: the same flight without its fault: it flies the compiled chunk core (issue 26), whose chunks end
#: between two steps; a stop must still land there with a whole log
LONG_FAULT_FREE = LONG_SCENARIO.split("[[faults]]")[0]


def _start(scn: Path, log: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)


def _wait_for_flight(proc: subprocess.Popen[str], log: Path, timeout_s: float = 60.0) -> None:
    """The log appears at its path when the flight starts (it is written under a temporary name before)."""
    deadline = time.monotonic() + timeout_s
    while not log.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the flight did not start"
        time.sleep(0.005)


def _check_interrupted_log(log: Path, stdout: str, stderr: str, rc: int, faulty: bool = True) -> dict[str, float]:
    assert rc == 1, (rc, stderr)
    assert "Traceback" not in stderr, stderr
    assert "status     interrupted" in stdout, stdout
    steps = int(re.search(r"(\d+) steps\)", stdout).group(1))
    flown_s = float(re.search(r"flown\s+([\d.]+) s", stdout).group(1))
    fl = read_log(log)
    truth = fl.topics["/truth/state"]
    n = len(truth.t_s)
    assert steps == n, f"summary counts {steps} steps, the log holds {n} rows"
    assert flown_s == pytest.approx(truth.t_s[-1], abs=0.006)
    # nothing lost: every step from 0 to the last one, on every per-step topic
    assert np.allclose(truth.t_s, np.arange(n) / RATE_HZ, rtol=0.0, atol=1e-9)  # log_time is whole ns
    assert ("core       Python loop" if faulty else "core       compiled chunk core") in stdout, stdout
    for topic in ("/sensors/measurements", "/commands/pilot", "/truth/operating_point", "/truth/surfaces") + (
            ("/faults/active",) if faulty else ()):
        assert len(fl.topics[topic].t_s) == n, topic
    assert [e.payload["status"] for e in fl.topics["/sim/status"].events] == ["running", "interrupted"]
    # the mcap reader, checking every chunk CRC, reads every message the summary counts
    with open(log, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        stats = reader.get_summary().statistics
        count = sum(1 for _ in reader.iter_messages())
    assert count == stats.message_count
    rep = verify_log(log)  # and every other CRC (Data End, summary) and index
    assert rep.ok, rep.format()
    return {"t_s": float(truth.t_s[-1]), "rows": n}


def _interrupt_many(tmp_path: Path, sig: signal.Signals, n_runs: int, seed: int, faulty: bool = True
                    ) -> list[dict[str, float]]:
    scn = tmp_path / "long.toml"
    scn.write_text(LONG_SCENARIO if faulty else LONG_FAULT_FREE)
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_runs):
        log = tmp_path / f"run{i}.mcap"
        proc = _start(scn, log)
        try:
            _wait_for_flight(proc, log)
            time.sleep(float(rng.uniform(0.0, 2.0)))  # any moment: inside a step, a flush, a fault event
            proc.send_signal(sig)
            stdout, stderr = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        out.append(_check_interrupted_log(log, stdout, stderr, proc.returncode, faulty))
        assert f"SIG{'INT' if sig == signal.SIGINT else 'TERM'}" in stdout
        log.unlink()
    # the moments really were spread over the flight (several flush periods)
    t = np.array([o["t_s"] for o in out])
    assert t.max() - t.min() > 1.0, t
    return out


@pytest.mark.parametrize("faulty", [True, False], ids=["python-loop", "compiled-core"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_at_random_moments_leaves_complete_logs(tmp_path: Path, sig: signal.Signals, faulty: bool) -> None:
    _interrupt_many(tmp_path, sig, N_DEFAULT, seed=int(sig), faulty=faulty)


@pytest.mark.slow
@pytest.mark.parametrize("faulty", [True, False], ids=["python-loop", "compiled-core"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_bar_fifty_moments(tmp_path: Path, sig: signal.Signals, faulty: bool) -> None:
    """The issue's bar: 50 or more random moments per signal (each loop)."""
    res = _interrupt_many(tmp_path, sig, N_BAR, seed=100 + int(sig), faulty=faulty)
    print(f"{sig.name}: {len(res)} runs, t from {min(r['t_s'] for r in res):.2f} to {max(r['t_s'] for r in res):.2f} s")


def _good_log(tmp_path: Path) -> bytes:
    scn = tmp_path / "short.toml"
    scn.write_text(LONG_SCENARIO.replace("duration_s = 3000.0", "duration_s = 1.0").split("[[maneuvers]]")[0])
    log = tmp_path / "keep.mcap"
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    return log.read_bytes()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_before_the_flight_leaves_the_old_log(tmp_path: Path, sig: signal.Signals) -> None:
    """A signal during the imports or the trim: exit 1, no traceback, the file at --log unchanged."""
    old = _good_log(tmp_path)
    log = tmp_path / "keep.mcap"
    scn = tmp_path / "long.toml"
    scn.write_text(LONG_SCENARIO)
    rng = np.random.default_rng(int(sig))
    for _ in range(4):
        proc = _start(scn, log)
        time.sleep(float(rng.uniform(0.05, 0.8)))  # imports take ~1 s, the trim follows
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
        if proc.returncode == -sig:  # it landed before Python ran any of our code: nothing to handle
            assert log.read_bytes() == old
            continue
        if stderr.startswith("Fatal Python error: init_import_site"):
            # it landed while the interpreter itself ran the venv's .pth files (setuptools's
            # distutils-precedence.pth imports _distutils_hack): CPython's own start-up, before
            # any of our code, which no handler of ours can reach. Nothing was written.
            assert proc.returncode == 1 and log.read_bytes() == old
            continue
        assert proc.returncode == 1, stderr
        assert "Traceback" not in stderr, stderr
        if "before the flight started" in stderr or stdout == "":
            assert log.read_bytes() == old
        else:  # the signal came after take-off: then it is a complete interrupted log
            _check_interrupted_log(log, stdout, stderr, proc.returncode)
            log.write_bytes(old)
    assert not [p for p in tmp_path.iterdir() if ".starting-" in p.name]  # no temporary file left


def test_failed_start_leaves_the_old_log(tmp_path: Path) -> None:
    """An untrimmable point exits 2 naming the file and [initial], and the log at --log is unchanged."""
    old = _good_log(tmp_path)
    log = tmp_path / "keep.mcap"
    scn = tmp_path / "bad.toml"
    scn.write_text(LONG_SCENARIO.replace("vc_kts = 120.0", "vc_kts = 50.0"))
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert f"{scn}: initial: cannot trim" in r.stderr and "Fix:" in r.stderr, r.stderr
    assert log.read_bytes() == old
    assert not [p for p in tmp_path.iterdir() if ".starting-" in p.name]


def test_log_path_that_is_not_a_log_is_refused(tmp_path: Path) -> None:
    """`--log` never replaces the scenario itself, nor a non-MCAP file without --force."""
    scn = tmp_path / "s.toml"
    scn.write_text(LONG_SCENARIO.replace("duration_s = 3000.0", "duration_s = 1.0").split("[[maneuvers]]")[0])
    text = scn.read_text()
    for extra in ((), ("--force",)):
        r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(scn), "--quiet", *extra],
                           capture_output=True, text=True, cwd=REPO)
        assert r.returncode == 2 and "scenario file itself" in r.stderr, r.stderr
        assert scn.read_text() == text
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(notes), "--quiet"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2 and "--force" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert notes.read_text() == "my notes"
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(notes), "--quiet", "--force"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert read_log(notes).topics["/truth/state"].t_s[-1] == pytest.approx(1.0)
    # an existing MCAP log is simply replaced (a rerun)
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(notes), "--quiet"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr


def test_no_temporary_file_after_a_run(tmp_path: Path) -> None:
    scn = tmp_path / "s.toml"
    scn.write_text(LONG_SCENARIO.replace("duration_s = 3000.0", "duration_s = 0.5").split("[[maneuvers]]")[0])
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--out", str(tmp_path), "--quiet"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dhc6_cruise_doublets_seed3.mcap", "s.toml"]


def test_a_stop_whose_exception_was_dropped_still_stops_the_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``fdi-sim``'s SIGTERM handler raises KeyboardInterrupt, which Python drops when it lands in a
    weakref callback during an import (seen: 1 of 60 runs signalled 0.05-1.8 s after the start flew
    its 3000 s scenario to the end and exited 0). The handler records the request first
    (``fdi_sim.signals``): a run started after such a drop stops before take-off, the old log kept."""
    from fdi_sim import signals
    from fdi_sim.scenario import load
    from fdi_sim.sim.run import RunInterrupted
    from fdi_sim.training import fly

    old = _good_log(tmp_path)
    scn = tmp_path / "long.toml"
    scn.write_text(LONG_SCENARIO)
    monkeypatch.setattr(signals, "pending_reason", "stopped by SIGTERM")
    with pytest.raises(RunInterrupted, match="SIGTERM"):
        fly(load(scn), log_path=tmp_path / "keep.mcap", progress=False)
    assert (tmp_path / "keep.mcap").read_bytes() == old


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_the_command_handler_records_the_stop_before_raising(sig: signal.Signals,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Both stop signals go through ``fdi_sim.cli``'s handler, which records the request before it
    raises (the fresh clone of session 10 failed the SIGINT case of the test above: a dropped Ctrl-C,
    exit 0); the next command starts with no request left over."""
    from fdi_sim import cli, signals

    monkeypatch.setattr(signals, "pending_reason", "")
    with pytest.raises(KeyboardInterrupt):
        cli._stop(int(sig), None)
    assert signals.pending_reason == signals.REASONS[sig]
    assert cli.main(["scenarios"]) == 0  # a new command: the old request is gone, it is not interrupted
    assert not signals.stop_requested()

"""The bad-input corpus (issue 11): every case through the real CLI in a subprocess.

Each bad input exits 2 with one paragraph naming the file, the key (where there is one) and a
fix, never a traceback. An unusable cache folder is not bad input: the run flies on a private
temporary copy of the JSBSim models, says so in one warning line, and writes a readable log.
The untrimmable points are also tested on :func:`fdi_sim.aircraft.trim` directly.
"""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path
from typing import Callable

import pytest

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.errors import TrimError
from fdi_sim.flightlog import read_log
from fdi_sim.operating_point import OperatingPoint

REPO = Path(__file__).resolve().parents[1]
ICING = REPO / "scenarios" / "dhc6_tail_icing.toml"
ICING_TEXT = ICING.read_text()
_EXE = Path(sys.executable).with_name("fdi-sim")
FDI_SIM = [str(_EXE)] if _EXE.exists() else [sys.executable, "-m", "fdi_sim.cli"]


def _fdi_sim(args: list[str], tmp_path: Path, env: dict[str, str] | None = None,
             timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run the installed ``fdi-sim`` (a hang fails the test through the timeout)."""
    base = {**os.environ, "JSBSIM_DEBUG": "0", "MPLCONFIGDIR": str(tmp_path / "mpl")}
    base.update(env or {})
    base = {k: v for k, v in base.items() if v is not None and v != "<unset>"}
    return subprocess.run(FDI_SIM + args, capture_output=True, text=True, timeout=timeout_s, cwd=tmp_path, env=base)


def _assert_bad_input(proc: subprocess.CompletedProcess[str], *needles: str) -> None:
    err = proc.stderr
    assert proc.returncode == 2, f"exit {proc.returncode}\n{err}"
    assert "Traceback" not in err, err
    assert "Fix:" in err, err  # every message says what to do
    for n in needles:
        assert n in err, f"{n!r} not in:\n{err}"


# ---------------------------------------------------------------- scenario files that are not usable TOML
def _write(name: str, data: bytes) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        p = d / name
        p.write_bytes(data)
        return p
    return make


def _symlink_to(target: str) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        p = d / "link.toml"
        p.symlink_to(target)
        return p
    return make


def _fifo(d: Path) -> Path:
    p = d / "pipe.toml"
    os.mkfifo(p)
    return p


def _directory(d: Path) -> Path:
    p = d / "folder.toml"
    p.mkdir()
    return p


def _unreadable(d: Path) -> Path:
    p = d / "secret.toml"
    p.write_text(ICING_TEXT)
    if os.geteuid() != 0:
        p.chmod(0)
        return p
    # root reads any mode: a write-only kernel file refuses even root
    target = Path("/proc/sys/vm/compact_memory")
    try:
        target.open("rb").close()
    except PermissionError:
        p.unlink()
        p.symlink_to(target)
        return p
    except OSError:
        pass
    pytest.skip("running as root and no file here refuses root a read")


CASES: dict[str, tuple[Callable[[Path], Path], tuple[str, ...]]] = {
    # a BOM is accepted: the error is the typo behind it, not "Invalid statement (at line 1)"
    "bom": (_write("bom.toml", b"\xef\xbb\xbf" + ICING_TEXT.replace("h_ft", "h_fz").encode()),
            ("initial.h_fz", "unknown key 'h_fz' (did you mean 'h_ft'?)")),
    "nested-5000": (_write("deep.toml", b"x = " + b"[" * 5000 + b"]" * 5000 + b"\n"), ("nests too deeply", "flatten")),
    "dev-zero": (_symlink_to("/dev/zero"), ("is a character device, not a regular file",)),
    "fifo": (_fifo, ("is a FIFO (named pipe), not a regular file",)),
    "directory": (_directory, ("is a directory, not a regular file",)),
    "unreadable": (_unreadable, ("permission denied", "chmod")),
    "invalid-utf8": (_write("latin1.toml", ICING_TEXT.replace("tailplane", "tailplane \u00e9").encode("latin-1")),
                     ("not UTF-8 text: byte 0xe9 at line 2", "save the file as UTF-8")),
    "over-1-MiB": (_write("big.toml", ICING_TEXT.encode() + b"#" * (1 << 20)), ("larger than 1048576 bytes",)),
    "typo-required-fault-key": (_write("typo.toml", ICING_TEXT.replace("t_start_s = 10.0", "t_strat_s = 10.0").encode()),
                                ("faults[0].t_strat_s", "unknown key 't_strat_s' (did you mean 't_start_s'?)")),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_scenario_file_exits_2_naming_file_key_and_fix(tmp_path: Path, case: str) -> None:
    make, needles = CASES[case]
    path = make(tmp_path)
    proc = _fdi_sim(["run", "--quiet", "--log", str(tmp_path / "x.mcap"), str(path)], tmp_path, timeout_s=60.0)
    _assert_bad_input(proc, f"fdi-sim run: {path}: ", *needles)
    assert "Invalid statement" not in proc.stderr


@pytest.mark.parametrize("aircraft,initial,needles", [
    # the example: beyond full throttle; once said "cannot trim DHC6 at DHC6 ..."
    ("DHC6", "h_ft = 5000.0\nvc_kts = 150.0", ("cannot trim DHC6 at h=5000 ft VC=150 kt", "throttle_cmd_norm = 1.000 at its limit",
                                              "upper stop of its range [0, 1]", "fly slower")),
    # once only "Trim Failed": now the axes JSBSim did not trim, the flight condition and the way back
    ("f16", "h_ft = 45000.0\nvt_kts = 200.0", ("cannot trim f16 at h=45000 ft VT=200 kt", "not trimmed: wdot = ",
                                              "at least 250 KCAS", "initial.h_ft at most 25000")),
], ids=["DHC6-too-fast", "f16-too-slow-and-high"])
def test_untrimmable_point_exits_2_naming_file_key_and_fix(tmp_path: Path, aircraft: str, initial: str,
                                                           needles: tuple[str, ...]) -> None:
    text = ICING_TEXT.replace('aircraft = "DHC6"', f'aircraft = "{aircraft}"').replace("h_ft = 5000.0\nvc_kts = 100.0", initial)
    text = text[: text.index("[[maneuvers]]")]  # no icing fault (the F-16 has no tail-ice model) nor maneuvers
    path = tmp_path / "untrimmable.toml"
    path.write_text(text)
    proc = _fdi_sim(["run", "--quiet", "--log", str(tmp_path / "x.mcap"), str(path)], tmp_path)
    _assert_bad_input(proc, f"{path}: initial: ", *needles)
    assert f"{aircraft} at {aircraft}" not in proc.stderr and "[0.0, 0.5]" not in proc.stderr


# ---------------------------------------------------------------- unusable cache folder: fly on a temporary copy
def _plain_file(d: Path) -> dict[str, str]:
    (d / "cache").write_text("not a folder")
    return {"FDI_SIM_CACHE": str(d / "cache")}


def _under_plain_file(d: Path) -> dict[str, str]:
    (d / "cache").write_text("not a folder")
    return {"FDI_SIM_CACHE": str(d / "cache" / "sub")}


@pytest.mark.parametrize("setup,variable", [
    (_plain_file, "FDI_SIM_CACHE"),
    (_under_plain_file, "FDI_SIM_CACHE"),
    # root writes through any mode bits: /proc refuses even root a new folder ("not writable")
    (lambda d: {"FDI_SIM_CACHE": "/proc/fdi-sim-cache"}, "FDI_SIM_CACHE"),
    (lambda d: {"FDI_SIM_CACHE": "<unset>", "XDG_CACHE_HOME": "<unset>", "HOME": "/proc/no-home"}, "HOME"),
], ids=["plain-file", "under-plain-file", "unwritable", "unwritable-home"])
def test_unusable_cache_folder_flies_on_a_temporary_copy(tmp_path: Path, setup: Callable[[Path], dict[str, str]],
                                                         variable: str) -> None:
    """The DHC-6 icing scenario (the iced overlay is built in the cache) for 2 s, without its FDI
    bank (with an unusable cache the bank would fly its 2 hours of training flights first: 50-120 s
    of the suite per case, none of it about the cache folder)."""
    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    log = tmp_path / "icing.mcap"
    icing = tmp_path / "dhc6_tail_icing.toml"
    icing.write_text(ICING_TEXT.split("[fdi]")[0])
    env = {**setup(tmp_path), "TMPDIR": str(tmpdir)}
    proc = _fdi_sim(["run", "--quiet", "--duration", "2", "--log", str(log), str(icing)], tmp_path, env)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    warnings = [ln for ln in proc.stderr.splitlines() if ln.startswith("fdi-sim: warning: cache folder")]
    assert len(warnings) == 1, proc.stderr
    assert f"now chosen by {variable}" in warnings[0] and "set FDI_SIM_CACHE to a writable folder" in warnings[0]
    assert not any(p.name.startswith("fdi-sim-cache-") for p in tmpdir.iterdir())  # removed at exit
    info = _fdi_sim(["info", str(log)], tmp_path, env)
    assert info.returncode == 0 and "Traceback" not in info.stderr, info.stderr
    assert read_log(log).duration_s == pytest.approx(2.0, abs=0.05)


# ---------------------------------------------------------------- the trim messages, on fdi_sim.aircraft.trim
def _trim_error(op: OperatingPoint) -> TrimError:
    with pytest.raises(TrimError) as ei:
        trim(Aircraft(op.aircraft), op)
    return ei.value


def test_dhc6_too_slow_names_the_residual_and_the_envelope() -> None:
    e = _trim_error(OperatingPoint("DHC6", 5000.0, vc_kts=45.0))
    assert str(e).startswith("cannot trim DHC6 at h=5000 ft VC=45 kt: the running-engine trim stopped at residual ")
    assert "largest: wdot = " in e.reason and "best point (no command at its limit): alpha" in e.reason
    assert "at least 65 KCAS" in e.fix and "initial.flaps_deg" in e.fix  # from aircraft/DHC6/grid.toml


def test_dhc6_too_high_names_the_throttle_stop() -> None:
    e = _trim_error(OperatingPoint("DHC6", 25000.0, vc_kts=120.0))
    assert "throttle_cmd_norm = 1.000 at its limit (the upper stop of its range [0, 1]: full throttle" in e.reason
    assert "lower (initial.h_ft)" in e.fix


def test_f16_failed_jsbsim_trim_reports_its_axes() -> None:
    e = _trim_error(OperatingPoint("f16", 45000.0, vt_kts=200.0))
    assert "JSBSim's trim reported 'Trim Failed': not trimmed: " in e.reason  # the linear grid reports key on it
    # the lift axis did not converge: wdot of the order of g, far above JSBSim's tolerance
    wdot_fps2 = float(e.reason.split("wdot = ")[1].split(" ")[0])
    assert wdot_fps2 > 10.0
    assert "with angle of attack" in e.reason and "VC 89 kt" in e.reason
    assert "at least 250 KCAS" in e.fix and "at most 25000" in e.fix


def test_f16_afterburner_is_not_called_a_limit_it_is_at() -> None:
    """The F-16 check is 0.5 (afterburner detent), not the command's range: 0.717 is *above* it."""
    e = _trim_error(OperatingPoint("f16", 10000.0, vt_kts=800.0))
    assert "is above 0.5, the afterburner detent (range [0, 1])" in e.reason
    assert "at its limit" not in e.reason and "fly slower" in e.fix


def test_trim_error_with_source_and_pickle() -> None:
    e = TrimError("DHC6", "h=5000 ft VC=150 kt", "throttle_cmd_norm = 1.000 at its limit", "fly slower")
    w = e.with_source("runs/x.toml", "initial")
    assert str(w) == "runs/x.toml: initial: cannot trim DHC6 at h=5000 ft VC=150 kt: throttle_cmd_norm = 1.000 at its limit Fix: fly slower"
    assert (w.source, w.key, w.reason, w.fix) == ("runs/x.toml", "initial", e.reason, e.fix)
    assert isinstance(w, RuntimeError) and str(e).startswith("cannot trim DHC6")
    back = pickle.loads(pickle.dumps(w))
    assert str(back) == str(w) and back.key == "initial"


@pytest.mark.parametrize("command", ["info", "verify", "repair"])
def test_log_commands_refuse_devices_and_folders(tmp_path: Path, command: str) -> None:
    """A log path that is a link to /dev/zero (it used to hang `info`) or a folder: exit 2 at once."""
    zero = tmp_path / "zero.mcap"
    zero.symlink_to("/dev/zero")
    for path, expected in ((zero, "not a regular file"), (tmp_path, "is a folder")):
        r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", command, str(path)], capture_output=True, text=True,
                           cwd=REPO, timeout=60)
        assert r.returncode == 2, (command, r.stderr)
        assert expected in r.stderr and "Traceback" not in r.stderr, r.stderr

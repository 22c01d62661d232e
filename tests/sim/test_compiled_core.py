"""Issue 26: the compiled chunk core (fdi_sim.sim._chunk over fdi_sim.aircraft.native) gives the
Python loop's log byte for byte, and every check of the binding, forced to fail, makes the run say
why in one line and fly the Python loop."""
from __future__ import annotations

import ctypes
import hashlib
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.aircraft import native
from fdi_sim.scenario.loader import from_dict, load
from fdi_sim.sim.run import run
from fdi_sim.training import fly
from fdi_sim.training.flights import fly_training, training_seeds

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml"))
#: a faulty flight flies the Python loop in both modes (the fault injector works on lists), so its byte
#: comparison checks one loop against itself and the fallback's message: one per aircraft in the default
#: run, the rest with the long studies (make test-slow; six of them cost about 3 min of the suite)
FAULTY_KEPT = {"f16_engine_flameout", "dhc6_engine_flameout"}


def _shipped_params() -> list:
    """Every shipped scenario; the faulty ones (as the loader reads them) not in FAULTY_KEPT marked slow."""
    faulty = {name for name in SHIPPED if load(ROOT / "scenarios" / f"{name}.toml").faults}
    assert FAULTY_KEPT <= faulty, FAULTY_KEPT - faulty  # a kept one that lost its fault would keep nothing
    return [pytest.param(name, marks=pytest.mark.slow) if name in faulty - FAULTY_KEPT else name for name in SHIPPED]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _both(monkeypatch, tmp_path: Path, sc, flyer=fly):
    out = {}
    for mode in ("python", "auto"):
        monkeypatch.setenv("FDI_SIM_CORE", mode)
        res = flyer(sc, tmp_path / mode, progress=False)
        out[mode] = (res, _digest(Path(res.log_path)))
    return out


@pytest.mark.parametrize("name", _shipped_params())
def test_every_shipped_scenario_logs_the_same_bytes(monkeypatch, tmp_path, name) -> None:
    sc = load(ROOT / "scenarios" / f"{name}.toml")
    out = _both(monkeypatch, tmp_path, sc)
    (rp, dp), (rc, dc) = out["python"], out["auto"]
    # a faulty flight flies the Python loop in both (the injector works on lists), and says so
    faulty = "python: a faulty flight (the fault injector works on lists)"
    assert rp.summary.core == (faulty if sc.faults else "python: FDI_SIM_CORE=python")
    assert rc.summary.core == (faulty if sc.faults else "compiled")
    assert (rp.status, rp.summary.steps) == (rc.status, rc.summary.steps)
    assert dp == dc


def _variant(name: str, **fdi_log) -> object:
    d = json.loads(load(ROOT / "scenarios" / f"{name}.toml").to_json())
    d["fdi"] = {"bank": "default"}
    d["log"] = {"per_step": fdi_log.get("per_step", True)}
    d["duration_s"] = 30.0
    d["maneuvers"] = [m for m in d.get("maneuvers", []) if m.get("t_start_s", 0.0) < 30.0]
    return from_dict(d, source=f"{name} with the default bank")


@pytest.mark.parametrize("name", ["f16_cruise_doublets", "dhc6_cruise_doublets"])
@pytest.mark.parametrize("per_step", [True, False])
def test_with_the_bank_the_same_bytes(monkeypatch, tmp_path, name, per_step) -> None:
    """The bank's blocks run between two chunks; its topics and the per-step ones interleave in the
    log's chunks as the Python loop wrote them (a study's log: per_step false)."""
    out = _both(monkeypatch, tmp_path, _variant(name, per_step=per_step))
    assert out["auto"][0].summary.core == "compiled"
    assert out["python"][1] == out["auto"][1]


def test_training_flights_the_same_rows(monkeypatch) -> None:
    sc = load(ROOT / "scenarios" / "dhc6_cruise_doublets.toml")
    rows = {}
    for mode in ("python", "auto"):
        monkeypatch.setenv("FDI_SIM_CORE", mode)
        logs = fly_training(sc, training_seeds(2), 20.0, progress=False)
        rows[mode] = [{t: lg.topics[t].data.copy() for t in lg.topics} for lg in logs]
    for a, b in zip(rows["python"], rows["auto"]):
        assert a.keys() == b.keys()
        for t in a:
            assert np.array_equal(a[t], b[t]), t


def test_a_departure_ends_at_the_same_step(monkeypatch, tmp_path) -> None:
    """The issue-25 approach whose seed 1000002 departs at 88 s: the divergence is found at the same
    step with the same message, the log as long."""
    d = json.loads(load(ROOT / "scenarios" / "dhc6_approach_flaps.toml").to_json())
    d["initial"].update(vc_kts=85.0)
    d.update(seed=1_000_002, duration_s=100.0)
    out = _both(monkeypatch, tmp_path, from_dict(d, source="approach at 85 KIAS"), flyer=run)
    (rp, dp), (rc, dc) = out["python"], out["auto"]
    assert rc.status == rp.status == "diverged" and rc.summary.reason == rp.summary.reason
    assert rc.summary.core == "compiled" and dp == dc


# --- every check, forced to fail ------------------------------------------------------------------
def _fly_short(tmp_path: Path):
    sc = load(ROOT / "scenarios" / "f16_cruise_doublets.toml")
    d = json.loads(sc.to_json())
    d.update(duration_s=2.0, maneuvers=[])
    return run(from_dict(d, source="short"), tmp_path, progress=False)


@pytest.mark.parametrize(("patch", "reason"), [
    (lambda m: m.setitem(native.SYMBOLS, "run", "_ZN6JSBSim9FGFDMExec9NotThereEv"), "does not export"),
    (lambda m: m.setattr(native, "FDM_OFFSETS", (16, 32)), "not one FGFDMExec*"),
    (lambda m: m.setattr(native, "NODE_OFFSET", 16), "through its pointer"),
    (lambda m: m.setattr(native.platform, "python_implementation", lambda: "PyPy"), "object addresses are CPython's"),
    (lambda m: m.setattr(native.sys, "platform", "win32"), "Itanium C++ ABI"),
])
def test_a_failed_check_flies_the_python_loop_and_says_why(monkeypatch, tmp_path, patch, reason) -> None:
    monkeypatch.setenv("FDI_SIM_CORE", "auto")
    good = _fly_short(tmp_path / "good")
    patch(monkeypatch)
    res = _fly_short(tmp_path / "bad")
    assert good.summary.core == "compiled"
    assert res.summary.core.startswith("python: ") and reason in res.summary.core, res.summary.core
    assert "core       Python loop (" in res.summary.format()
    assert _digest(Path(res.log_path)) == _digest(Path(good.log_path))


def test_no_compiler_for_the_shim(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("FDI_SIM_CORE", "auto")
    monkeypatch.setenv("FDI_SIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(native, "_SHIM", None)
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(native.shutil, "which", lambda _: None)
    res = _fly_short(tmp_path)
    assert "no C++ compiler" in res.summary.core


def test_required_core_that_cannot_run_is_an_error(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("FDI_SIM_CORE", "compiled")
    monkeypatch.setattr(native, "FDM_OFFSETS", (16, 32))
    with pytest.raises(native.NativeUnavailable, match="FDI_SIM_CORE=compiled, but"):
        _fly_short(tmp_path)
    monkeypatch.setenv("FDI_SIM_CORE", "fast")
    with pytest.raises(native.FdiSimError, match="use auto, python or compiled"):
        native.core_mode()


@pytest.mark.parametrize("core", ["compiled", "bogus"])
def test_required_core_exits_2_from_the_command_line(tmp_path, core) -> None:
    """``FDI_SIM_CORE=compiled`` where the core cannot run (no compiler for its shim, none cached),
    or a value it does not know: exit 2 (bad input), the reason on stderr."""
    import os
    import sys

    env = {k: v for k, v in os.environ.items() if k != "CXX"}
    env.update(FDI_SIM_CORE=core, PATH=str(tmp_path / "no-tools"), FDI_SIM_CACHE=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(ROOT / "scenarios" / "f16_cruise_doublets.toml"),
                        "--duration", "1", "--log", str(tmp_path / "x.mcap"), "--quiet"], env=env, capture_output=True,
                       text=True)
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert ("no C++ compiler" if core == "compiled" else "use auto, python or compiled") in r.stderr


def test_the_shim_turns_a_cpp_exception_into_a_message(tmp_path) -> None:
    """Run() is called through the shim: a C++ exception comes back as -1 and its message (a
    function that throws stands in for a JSBSim that throws)."""
    cxx = next((c for c in ("c++", "g++", "clang++") if shutil.which(c)), None)
    if cxx is None:
        pytest.skip("no C++ compiler")
    src = tmp_path / "thrower.cpp"
    src.write_text('#include <stdexcept>\nextern "C" bool thrower(void*) { throw std::runtime_error("boom in Run"); }\n'
                   'extern "C" bool fine(void*) { return true; }\n')
    lib = tmp_path / "libthrower.so"
    subprocess.run([cxx, "-shared", "-fPIC", "-o", str(lib), str(src)], check=True)
    t = ctypes.CDLL(str(lib))
    shim = native.RUN_SHIM(ctypes.cast(native._shim().fdi_sim_run, ctypes.c_void_p).value)
    msg = np.zeros(native.MESSAGE_BYTES, dtype=np.uint8)
    assert shim(ctypes.cast(t.fine, ctypes.c_void_p).value, 0, msg.ctypes.data, len(msg)) == 1
    assert shim(ctypes.cast(t.thrower, ctypes.c_void_p).value, 0, msg.ctypes.data, len(msg)) == -1
    assert bytes(msg).split(b"\0")[0] == b"boom in Run"


def test_the_set_up_loads_the_kernel_the_flight_calls(monkeypatch, tmp_path) -> None:
    """``_chunk.prime`` (in the set-up) passes the argument types the flight passes: one compiled
    signature, so numba's first call never lands inside a flight (a full log, and a study's log
    with the bank)."""
    import fdi_sim.sim._chunk as _chunk

    monkeypatch.setenv("FDI_SIM_CORE", "auto")
    assert _fly_short(tmp_path / "a").summary.core == "compiled"
    assert fly(_variant("dhc6_cruise_doublets", per_step=False), tmp_path / "b", progress=False).summary.core == "compiled"
    assert len(_chunk.run_chunk.signatures) == 1, _chunk.run_chunk.signatures

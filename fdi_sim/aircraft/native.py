"""JSBSim's own compiled functions, called from compiled loops (issue 26): the jsbsim wheel's symbols.

The jsbsim wheel's ``_jsbsim`` extension exports its C++ symbols (about 3,600 ``JSBSim::``
entries). Under the Itanium C++ ABI (Linux, macOS) a non-virtual member function is a C function
taking ``this`` first, so a compiled loop can call

- ``JSBSim::FGFDMExec::Run()`` (``bool (FGFDMExec*)``),
- ``JSBSim::FGFDMExec::GetSimTime() const`` (``double (const FGFDMExec*)``),
- ``SGPropertyNode::getDoubleValue() const`` (``double (const SGPropertyNode*)``),
- ``SGPropertyNode::setDoubleValue(double)`` (``bool (SGPropertyNode*, double)``)

by address, with no JSBSim build, no header and no link step. The ``this`` pointers are the
fields of the binding's Cython objects: ``FGFDMExec`` holds ``baseptr`` (its ``FGJSBBase``) and
``thisptr`` right after the object header, ``FGPropertyNode`` holds its ``SGSharedPtr`` after
the header and the Cython method table (:data:`FDM_OFFSETS`, :data:`NODE_OFFSET`: read off
jsbsim 1.3.3's ``_jsbsim.pyx``).

Nothing of this is assumed: :func:`bind` checks, before a loop may use it, that the platform is
one this applies to, that every symbol is exported, that the objects are large enough to hold
the fields, that ``baseptr == thisptr`` (single inheritance), that the simulation time read
through the pointer equals the binding's two answers (``get_sim_time()`` and the property
``simulation/sim-time-sec``), and, per property node, that the value read through the pointer
equals the binding's and that a second wrapper of the same property gives the same pointer. A
failed check gives its reason (:class:`NativeUnavailable`); the caller flies the Python loop.

A C++ exception thrown inside ``Run()`` would call ``std::terminate`` through a caller that is
not C++: ``Run()`` is called through a three-line C++ shim compiled at first use
(:func:`_shim`, needs a C++ compiler: ``c++``, ``g++`` or ``clang++``) that catches it and
returns -1 with its message; the run then ends ``diverged`` with that message and the log ends whole.

jsbsim's logger calls back into Python, so a loop calling these holds the GIL (numba's default).
``FDI_SIM_CORE=python`` forces the Python loop; ``FDI_SIM_CORE=compiled`` makes an unavailable
core an error (:func:`core_mode`).
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jsbsim
import jsbsim._jsbsim as _jsb
import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import FdiSimError

__all__ = ["FDM_OFFSETS", "NODE_OFFSET", "NativeBinding", "NativeUnavailable", "bind",
           "core_mode"]

#: mangled names (Itanium ABI) of the member functions the compiled loop calls
SYMBOLS: dict[str, str] = {
    "run": "_ZN6JSBSim9FGFDMExec3RunEv",
    "sim_time": "_ZNK6JSBSim9FGFDMExec10GetSimTimeEv",
    "get": "_ZNK14SGPropertyNode14getDoubleValueEv",
    "set": "_ZN14SGPropertyNode14setDoubleValueEd",
}
#: byte offsets of ``FGJSBBase.baseptr`` and ``FGFDMExec.thisptr`` in the binding's ``FGFDMExec``
#: object (after the 16-byte object header)
FDM_OFFSETS = (16, 24)
#: byte offset of the ``SGPropertyNode*`` in the binding's ``FGPropertyNode`` object (after the
#: header and the Cython method table)
NODE_OFFSET = 24
#: the C++ shim that calls Run() and catches what it throws
_SHIM_SOURCE = r"""
#include <cstring>
#include <exception>
extern "C" int fdi_sim_run(unsigned long run, void* fdm, char* msg, int n) {
    try {
        return reinterpret_cast<bool (*)(void*)>(run)(fdm) ? 1 : 0;
    } catch (const std::exception& e) {
        std::strncpy(msg, e.what(), n - 1); msg[n - 1] = 0; return -1;
    } catch (...) {
        std::strncpy(msg, "an exception that is not a std::exception", n - 1); msg[n - 1] = 0; return -1;
    }
}
"""
#: bytes of the shim's message buffer
MESSAGE_BYTES = 512

RUN_SHIM = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_int)
GET = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_size_t)
SET = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_size_t, ctypes.c_double)


class NativeUnavailable(FdiSimError):
    """The compiled core cannot be used here; the message says which check failed."""


def core_mode() -> str:
    """``FDI_SIM_CORE``: ``"auto"`` (default: the compiled core where :func:`bind` allows it),
    ``"python"`` (always the Python loop) or ``"compiled"`` (an unavailable core is an error)."""
    mode = os.environ.get("FDI_SIM_CORE", "auto").strip().lower() or "auto"
    if mode not in ("auto", "python", "compiled"):
        raise FdiSimError(f"FDI_SIM_CORE={mode!r}: use auto, python or compiled")
    return mode


@dataclass(frozen=True, eq=False)
class NativeBinding:
    """What a compiled loop needs to drive one ``FGFDMExec``.

    Attributes
    ----------
    fdm : int
        The ``FGFDMExec*``.
    run_shim : ctypes function
        ``int (run address, fdm, message buffer, its size)``: 1 ok, 0 JSBSim asked to stop, -1 a
        C++ exception (its message in the buffer).
    run : int
        Address of ``FGFDMExec::Run()``.
    get, set : ctypes function
        ``SGPropertyNode::getDoubleValue`` / ``setDoubleValue`` by node address.
    message : NDArray of uint8
        The shim's message buffer.
    owner : Any
        The binding's ``FGFDMExec`` object (kept alive while the pointers are used).
    """

    fdm: int
    run_shim: Any
    run: int
    get: Any
    set: Any
    message: NDArray[np.uint8]
    owner: Any

    def node_pointers(self, nodes: Sequence[Any]) -> NDArray[np.uintp]:
        """The ``SGPropertyNode*`` of the binding's nodes, each checked (module docstring).

        Raises
        ------
        NativeUnavailable
            A node whose pointer does not read the binding's value.
        """
        out = np.empty(len(nodes), dtype=np.uintp)
        for i, n in enumerate(nodes):
            p = _node_pointer(n)
            a, b = self.get(p), n.get_double_value()
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                raise NativeUnavailable(f"property node {i}: {a!r} read through its pointer, {b!r} through the "
                                        "binding (the FGPropertyNode layout differs from the one this core knows)")
            out[i] = p
        return out

    def exception_message(self) -> str:
        """The last exception's message (after the shim returned -1)."""
        return bytes(self.message).split(b"\0", 1)[0].decode("utf-8", "replace")


def _field(obj: Any, offset: int) -> int:
    """The pointer-sized field at ``offset`` bytes into a CPython object (``id`` is its address)."""
    if type(obj).__basicsize__ < offset + ctypes.sizeof(ctypes.c_void_p):
        raise NativeUnavailable(f"{type(obj).__name__} objects are {type(obj).__basicsize__} bytes: no field at "
                                f"offset {offset}")
    return int(ctypes.c_void_p.from_address(id(obj) + offset).value or 0)


def _node_pointer(node: Any) -> int:
    p = _field(node, NODE_OFFSET)
    if p == 0 or p % 8:
        raise NativeUnavailable(f"a property node's pointer field holds {p:#x}, not an object address")
    return p


_LIB: Any = None
_SHIM: Any = None


def _library() -> Any:
    global _LIB
    if _LIB is None:
        _LIB = ctypes.CDLL(_jsb.__file__)  # the already loaded extension: the same handle
    return _LIB


def _symbol(name: str) -> int:
    try:
        fn = getattr(_library(), SYMBOLS[name])
    except AttributeError:
        raise NativeUnavailable(f"jsbsim {jsbsim.__version__}'s {Path(_jsb.__file__).name} does not export "
                                f"{SYMBOLS[name]} ({name})") from None
    return int(ctypes.cast(fn, ctypes.c_void_p).value)


def _cache_dir() -> Path:
    base = os.environ.get("FDI_SIM_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fdi-sim" / "native"


def _shim() -> Any:
    """The Run() shim, compiled once per machine and shim source (cached beside the other caches)."""
    global _SHIM
    if _SHIM is not None:
        return _SHIM
    tag = hashlib.sha256((_SHIM_SOURCE + platform.machine() + sys.platform).encode()).hexdigest()[:16]
    lib_path = _cache_dir() / f"fdi_sim_run_{tag}.so"
    try:
        lib_path.parent.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=lib_path.parent)  # writable? (an unusable cache folder)
        probe.close()
    except OSError:  # a cache folder that cannot be used: build in a temporary folder of this process
        lib_path = Path(tempfile.mkdtemp(prefix="fdi-sim-native-")) / lib_path.name
    if not lib_path.exists():
        cxx = next((c for c in (os.environ.get("CXX"), "c++", "g++", "clang++") if c and shutil.which(c)), None)
        if cxx is None:
            raise NativeUnavailable("no C++ compiler (c++, g++ or clang++; or $CXX) to build the exception shim")
        with tempfile.TemporaryDirectory(dir=lib_path.parent) as tmp:
            src = Path(tmp) / "shim.cpp"
            src.write_text(_SHIM_SOURCE)
            out = Path(tmp) / lib_path.name
            res = subprocess.run([cxx, "-O2", "-shared", "-fPIC", "-o", str(out), str(src)], capture_output=True,
                                 text=True)
            if res.returncode != 0:
                raise NativeUnavailable(f"{cxx} could not build the exception shim: {res.stderr.strip()[:300]}")
            os.replace(out, lib_path)  # atomic: a concurrent worker sees the whole file or none
    _SHIM = ctypes.CDLL(str(lib_path))
    _SHIM.fdi_sim_run.restype = ctypes.c_int
    return _SHIM


def bind(fdm: Any) -> NativeBinding:
    """Check every assumption (module docstring) on a loaded, initialized ``jsbsim.FGFDMExec``.

    Raises
    ------
    NativeUnavailable
        The first check that fails, in one line.
    """
    if platform.python_implementation() != "CPython":
        raise NativeUnavailable(f"{platform.python_implementation()}: object addresses are CPython's")
    if sys.platform not in ("linux", "darwin") or ctypes.sizeof(ctypes.c_void_p) != 8:
        raise NativeUnavailable(f"{sys.platform}, {8 * ctypes.sizeof(ctypes.c_void_p)}-bit: the Itanium C++ ABI on a "
                                "64-bit Linux or macOS is assumed")
    if not isinstance(fdm, jsbsim.FGFDMExec):
        raise NativeUnavailable(f"not a jsbsim.FGFDMExec: {type(fdm).__name__}")
    addr = {k: _symbol(k) for k in SYMBOLS}
    base, this = (_field(fdm, off) for off in FDM_OFFSETS)
    if this == 0 or this != base:
        raise NativeUnavailable(f"FGFDMExec fields at {FDM_OFFSETS}: {base:#x} and {this:#x}, not one FGFDMExec*")
    sim_time = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_size_t)(addr["sim_time"])
    t_ptr, t_py, t_prop = sim_time(this), float(fdm.get_sim_time()), float(fdm["simulation/sim-time-sec"])
    if not (t_ptr == t_py == t_prop):
        raise NativeUnavailable(f"simulation time {t_ptr!r} through the pointer, {t_py!r} and {t_prop!r} through the "
                                "binding")
    b = NativeBinding(this, RUN_SHIM(ctypes.cast(_shim().fdi_sim_run, ctypes.c_void_p).value), addr["run"],
                      GET(addr["get"]), SET(addr["set"]), np.zeros(MESSAGE_BYTES, dtype=np.uint8), fdm)
    pm = fdm.get_property_manager()
    probe = [pm.get_node(p, False) for p in ("simulation/sim-time-sec", "simulation/dt")]
    again = [pm.get_node(p, False) for p in ("simulation/sim-time-sec", "simulation/dt")]
    ptrs, ptrs2 = b.node_pointers(probe), b.node_pointers(again)
    if not np.array_equal(ptrs, ptrs2) or ptrs[0] == ptrs[1]:
        raise NativeUnavailable("two wrappers of one property give different pointers (or two properties one)")
    if b.get(int(ptrs[1])) != float(fdm.get_delta_t()):
        raise NativeUnavailable("simulation/dt through its node's pointer is not the binding's dt")
    return b

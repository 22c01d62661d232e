"""Patched copies of the JSBSim models shipped with the ``jsbsim`` wheel.

fdi-sim never edits the wheel. It builds a JSBSim root folder (``aircraft/``, ``engine/``,
``systems/``) in a cache: the wheel's ``engine`` and ``systems`` are linked, each aircraft is a
copy of the wheel's folder with the XML patches listed here applied. The folder name carries a
hash of the jsbsim version, of this module's patch list and of each generator's module and data
files, so a changed patch, generator or data file builds anew.

Patches
-------
``f16``: ``fcs/yaw-load-pid`` writes its output into ``fcs/rudder-pos-norm``, the node the
rudder kinematic integrates from, so any non-zero yaw-PID output (turns, sideslip, rudder
inputs) makes the rudder jump (JSBSIM_NOTES sec. 1.2, bug 1). The patch removes that
``<output>``: the PID's value still reaches the rudder through ``fcs/yaw-scheduler``.
"""
from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Callable

import jsbsim

from fdi_sim.errors import CacheError


def _patch_f16(root: ET.Element) -> None:
    for pid in root.iter("pid"):
        if pid.get("name") == "fcs/yaw-load-pid":
            out = pid.find("output")
            if out is not None and (out.text or "").strip() == "fcs/rudder-pos-norm":
                pid.remove(out)
                return
    raise RuntimeError("f16.xml: fcs/yaw-load-pid output not found; the wheel's model changed")


#: aircraft folder -> (xml file, patch function)
PATCHES: dict[str, tuple[str, Callable[[ET.Element], None]]] = {
    "f16": ("f16.xml", _patch_f16),
}

# Extra aircraft generators (e.g. the iced DHC-6) register here: name -> builder(wheel_root, dst_root);
# a builder's optional ``data_files`` attribute names the files it reads (part of the cache key)
GENERATORS: dict[str, Callable[[Path, Path], None]] = {}


def _cache_base() -> Path:
    base = os.environ.get("FDI_SIM_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fdi-sim"


def _cache_variable() -> str:
    """Which setting chose the cache folder (for messages)."""
    if os.environ.get("FDI_SIM_CACHE"):
        return "FDI_SIM_CACHE"
    return "XDG_CACHE_HOME" if os.environ.get("XDG_CACHE_HOME") else "HOME"


def _fingerprint() -> str:
    h = hashlib.sha256()
    h.update(jsbsim.__version__.encode())
    h.update(Path(__file__).read_bytes())
    for gen in GENERATORS.values():
        mod = getattr(gen, "__module__", "")
        f = getattr(sys.modules.get(mod), "__file__", None)
        if f:
            h.update(Path(f).read_bytes())
        # data a generator reads (e.g. aircraft/<name>/icing.toml): an edit must rebuild the root
        for data in sorted(str(p) for p in getattr(gen, "data_files", ())):
            h.update(Path(data).read_bytes() if Path(data).exists() else b"")  # contents only: clones share a root
    return h.hexdigest()[:16]


#: roots built in a private temporary folder because the cache was unusable: fingerprint -> root
_FALLBACK_ROOTS: dict[str, Path] = {}


def jsbsim_root() -> Path:
    """The JSBSim root folder holding the patched aircraft, built once per fingerprint [path].

    It lives in ``$FDI_SIM_CACHE/fdi-sim`` (else ``$XDG_CACHE_HOME``, else ``~/.cache``). When
    that folder cannot be used (a plain file in the path, no write permission, a read-only or
    missing HOME), the root is built once per process in a private temporary folder, removed
    at exit, and a one-line warning on stderr names the variable to set; the run still flies.

    Raises
    ------
    CacheError
        Neither the cache folder nor the temporary folder (``TMPDIR``) is usable.
    """
    fp = _fingerprint()
    base = _cache_base()
    dst = base / f"jsbsim-root-{fp}"
    try:
        if (dst / ".complete").exists():
            return dst
        return _build(dst)
    except OSError as exc:  # PermissionError, NotADirectoryError, FileNotFoundError, read-only file system
        if fp in _FALLBACK_ROOTS:
            return _FALLBACK_ROOTS[fp]
        try:
            tmp_base = Path(tempfile.mkdtemp(prefix="fdi-sim-cache-"))
            atexit.register(shutil.rmtree, tmp_base, ignore_errors=True)
            root = _build(tmp_base / f"jsbsim-root-{fp}")
        except OSError as exc2:
            raise CacheError(
                f"cannot build the JSBSim models: the cache folder {base} is unusable "
                f"({exc.strerror or exc}) and so is the temporary folder ({exc2.strerror or exc2}). "
                f"Fix: set FDI_SIM_CACHE to a writable folder (now chosen by {_cache_variable()}), "
                "or TMPDIR to a writable temporary folder") from None
        _FALLBACK_ROOTS[fp] = root
        print(f"fdi-sim: warning: cache folder {base} is unusable ({exc.strerror or exc}); built the JSBSim models "
              f"in {tmp_base} for this run only (set FDI_SIM_CACHE to a writable folder, now chosen by "
              f"{_cache_variable()})", file=sys.stderr)
        return root


def _build(dst: Path) -> Path:
    """Build the root at ``dst`` through a temporary sibling renamed into place (atomic) [path]."""
    wheel = Path(jsbsim.get_default_root_dir())
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="jsbsim-root-", dir=dst.parent))
    try:
        for sub in ("engine", "systems"):
            os.symlink(wheel / sub, tmp / sub)
        (tmp / "aircraft").mkdir()
        for name in ("f16", "DHC6"):
            shutil.copytree(wheel / "aircraft" / name, tmp / "aircraft" / name)
            if name in PATCHES:
                fname, fn = PATCHES[name]
                path = tmp / "aircraft" / name / fname
                tree = ET.parse(path)
                fn(tree.getroot())
                tree.write(path, encoding="utf-8", xml_declaration=True)
        for gen in GENERATORS.values():
            gen(wheel, tmp)
        (tmp / ".complete").write_text(jsbsim.__version__)
        try:
            os.rename(tmp, dst)  # atomic; another process may have won the race
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
            if not (dst / ".complete").exists():
                raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dst

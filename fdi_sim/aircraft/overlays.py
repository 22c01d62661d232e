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

import hashlib
import os
import shutil
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Callable

import jsbsim


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


def jsbsim_root() -> Path:
    """The JSBSim root folder holding the patched aircraft, built once per fingerprint [path]."""
    wheel = Path(jsbsim.get_default_root_dir())
    dst = _cache_base() / f"jsbsim-root-{_fingerprint()}"
    if (dst / ".complete").exists():
        return dst
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
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dst

"""The shipped calibration atlas: the default bank designed and calibrated at every schedule-grid
node of an aircraft's envelope, flown once by the project so that a user's flight needs none.

Why
---
A bank's thresholds (and the gust filter's ``Sigma_m``) come from fault-free training flights at
its design conditions (:mod:`fdi_sim.training.thresholds`, :mod:`fdi_sim.training.gust`): 24 x
300 s, 35-40 s of set-up before a new scenario's own flight starts. Those flights depend only on
the design conditions, never on the user's flight: with ``[fdi.design] point = "auto"`` (the
default) a flight inside the atlas is designed at the *calibrated design* of its node
(:func:`atlas_design`): the aircraft's reference scenario (its calibration studies' base, with its
pulse-train maneuvers) at the nearest grid node, moderate turbulence, no wind, sensor-noise
scale 1, with the flight's own sensor suite and ``[fdi]`` settings. The atlas holds, for each node,
the two cache entries those training flights give (the gust filter's calibration and the members'
thresholds), so the flight takes off without flying any.

How an entry is found (CPU-tolerant)
------------------------------------
The on-disk cache keys (:func:`fdi_sim.training.cache.calibration_key`,
``fdi_sim.training.thresholds._thresholds_key``) hash the design's matrices bit for bit; another
CPU's libm and BLAS round the trim and the linearization differently, so those keys would never
match off the machine that made the atlas. An atlas entry is keyed instead by everything the
entry depends on *except* numbers computed in floating point (the design scenario, the options,
the rate, the training flights, the target, the sensor suite files, the package version, the tail
method, and the members' non-numeric design keys), and carries a fingerprint of the design's
matrices (:func:`fingerprint`). It is used when the key matches and every matrix is within
:data:`DESIGN_RTOL` of the fingerprint (:func:`fingerprint_distance`); otherwise the bank trains
as before and its log says why.

``FDI_SIM_ATLAS=off`` turns the atlas off (the atlas's own generation runs that way:
:mod:`fdi_sim.study.atlas`).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.data import aircraft_file, shown_path
from fdi_sim.errors import DesignError

#: the atlas file in ``aircraft/<aircraft>/``
ATLAS_FILE = "fdi_atlas.json"
#: largest relative difference of a design matrix from its fingerprint at which an atlas entry still
#: holds [-]. Not measured across CPUs (one machine here); the on-disk cache's comment
#: (fdi_sim.training.thresholds.TRAINED_MATCH_REL) measured 0.2-0.9 % between two CPUs in the
#: *trained thresholds*, which came from flights that diverge from their last bits; a trim and a
#: linearization of the same code differ by far less. A design change that matters (a new default,
#: another linearizer) moves the matrices by more than this.
DESIGN_RTOL = 1e-4
#: the calibrated design conditions: the grid node, no wind, noise scale 1, and the flight's turbulence
#: level where the atlas has it (:data:`LEVELS`), else the nearest below (:func:`design_turbulence`)
CONDITIONS: Mapping[str, Any] = {"point": "grid", "wind_speed_kts": 0.0, "noise_scale": 1.0}
#: the turbulence levels the atlas is made for: those the kinematic checks have a design for
#: (fdi_sim.detectors.catalogue_kinematic.LEVELS); a severe flight is designed at moderate
LEVELS = ("none", "light", "moderate")


#: the atlas's flights: the reference scenario's pulse-train maneuvers ("doublets"), or none
#: ("steady"), for a flight that flies none (in calm air the doublets' responses, which a linear
#: model does not follow exactly, set the gust filter's threshold)
MANEUVERS = ("steady", "doublets")


def design_turbulence(level: str) -> str:
    """The atlas level a flight in ``level`` is designed at: its own, or moderate for severe."""
    return level if level in LEVELS else LEVELS[-1]
#: fixed projection vectors of the fingerprints (a constant basis, not randomness of a run)
_FP_BASIS_KEY = 20261204
_FP_PROJECTIONS = 4
#: where the atlas's entries are recorded while it is made (fdi_sim.study.atlas); None elsewhere
RECORDER: list[dict[str, Any]] | None = None


def atlas_enabled() -> bool:
    """False when ``FDI_SIM_ATLAS`` is ``off`` (or ``0``/``no``/``false``)."""
    return os.environ.get("FDI_SIM_ATLAS", "on").strip().lower() not in ("off", "0", "no", "false")


def atlas_path(aircraft: str) -> Path:
    """``aircraft/<aircraft>/fdi_atlas.json``."""
    return aircraft_file(aircraft, ATLAS_FILE)


# --- fingerprints -------------------------------------------------------------------------------
def fingerprint(arrays: Sequence[Any]) -> list[list[float]]:
    """Per array: its shape's size, its Frobenius norm and :data:`_FP_PROJECTIONS` fixed projections
    ``v_i . vec(X)`` with unit vectors ``v_i`` (a constant basis per size).

    Two arrays within ``eps`` in Frobenius norm have every projection within ``eps``; a change of
    the design moves the norm or a projection unless it is orthogonal to all five (measure zero).
    """
    out = []
    for a in arrays:
        x = np.ascontiguousarray(a, dtype=np.float64).ravel()
        x = np.where(np.isfinite(x), x, 0.0)
        out.append([float(x.size), float(np.linalg.norm(x))] + [float(v @ x) for v in _basis(x.size)])
    return out


@functools.lru_cache(maxsize=64)
def _basis(n: int) -> NDArray[np.float64]:
    """The projection vectors for arrays of ``n`` values (read-only; kept: drawing them was half of
    a study run's atlas lookup, 0.23 s of 0.4 s, measured on an F-16 envelope run)."""
    if n == 0:
        v = np.zeros((_FP_PROJECTIONS, 0))
    else:
        v = np.random.default_rng([_FP_BASIS_KEY, n]).standard_normal((_FP_PROJECTIONS, n))
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
    v.flags.writeable = False
    return v


def fingerprint_distance(fp: Sequence[Sequence[float]], ref: Sequence[Sequence[float]]) -> float:
    """Largest difference of a norm or projection relative to the reference array's norm [-]
    (``inf`` when the arrays' number or sizes differ)."""
    if len(fp) != len(ref):
        return float("inf")
    worst = 0.0
    for a, b in zip(fp, ref):
        if len(a) != len(b) or a[0] != b[0]:
            return float("inf")
        scale = max(abs(b[1]), 1e-300)
        worst = max(worst, max(abs(x - y) for x, y in zip(a[1:], b[1:])) / scale)
    return worst


def inputs_key(parts: Mapping[str, Any]) -> str:
    """sha256 (24 hex) of the JSON of what an entry depends on besides floating-point results."""
    blob = json.dumps(dict(parts), sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def scenario_digest(data: Mapping[str, Any]) -> str:
    """Digest of a design scenario's JSON without its name, description and seed."""
    d = {k: v for k, v in data.items() if k not in ("name", "description", "seed")}
    return inputs_key({"scenario": d})


# --- the file ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AtlasNode:
    """One grid node of the atlas.

    Attributes
    ----------
    h_ft, vc_kts, flaps_deg : float
        The node [ft], [kt], [deg].
    turbulence : str
        The design's turbulence level (:data:`LEVELS`).
    maneuvers : str
        The training flights' maneuvers (:data:`MANEUVERS`).
    design_digest : str
        :func:`scenario_digest` of the calibrated design scenario made there.
    status : str
        ``"ok"``, or why the node has no entries (``"failed: ..."``: it does not trim, a member
        cannot be designed).
    """

    h_ft: float
    vc_kts: float
    flaps_deg: float
    turbulence: str
    maneuvers: str
    design_digest: str
    status: str


@dataclass(frozen=True, eq=False)
class Atlas:
    """An aircraft's atlas (:data:`ATLAS_FILE`), read.

    Attributes
    ----------
    path : Path
    aircraft : str
    reference : str
        The shipped scenario whose flights calibrate every node (its pulse trains).
    envelope : dict
        The box the nodes were made for (``h_ft``, and ``vc_kts`` or ``vt_kts``: [min, max]).
    conditions : dict
        :data:`CONDITIONS` when it was made.
    training : str
        The training flights per node (number, length, seeds), for the log.
    stamp : dict
        Code version, command and inputs digest of the generation (:mod:`fdi_sim.stamp`).
    nodes : tuple of AtlasNode
    entries : dict
        ``"<kind>:<key>"`` -> ``{"fingerprint": ..., "entry": ..., "node": [h, vc, flaps]}``.
    """

    path: Path
    aircraft: str
    reference: str
    envelope: Mapping[str, Any]
    conditions: Mapping[str, Any]
    training: str
    stamp: Mapping[str, Any]
    nodes: tuple[AtlasNode, ...]
    entries: Mapping[str, Mapping[str, Any]] = field(repr=False)

    def node_for(self, digest: str) -> AtlasNode | None:
        """The node whose calibrated design scenario has this digest (None: not in the atlas)."""
        for n in self.nodes:
            if n.design_digest == digest:
                return n
        return None

    def summary(self, node: AtlasNode | None = None) -> dict[str, Any]:
        """What a log records of the atlas (and of one node)."""
        out: dict[str, Any] = {"file": shown_path(self.path), "aircraft": self.aircraft, "reference": self.reference,
                               "conditions": dict(self.conditions), "training": self.training,
                               "commit": self.stamp.get("commit"), "made": self.stamp.get("date")}
        if node is not None:
            out["node"] = {"h_ft": node.h_ft, "vc_kts": node.vc_kts, "flaps_deg": node.flaps_deg,
                           "turbulence": node.turbulence, "maneuvers": node.maneuvers}
        return out


_LOADED: dict[tuple[str, float], Atlas] = {}


def read_atlas(path: Path, aircraft: str | None = None) -> Atlas:
    """Read an atlas file.

    Raises
    ------
    DesignError
        Not an atlas file, a damaged one, or one of another aircraft than ``aircraft`` (names the
        file, the key and the fix).
    """
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise DesignError(f"{path}: not a readable atlas file ({exc}); regenerate it with "
                          "`python -m fdi_sim.study.atlas AIRCRAFT`") from None
    if not isinstance(d, dict) or d.get("kind") != "fdi-atlas":
        raise DesignError(f"{path}: key 'kind' is {d.get('kind') if isinstance(d, dict) else None!r}, not 'fdi-atlas': "
                          "not an atlas file; regenerate it with `python -m fdi_sim.study.atlas AIRCRAFT`")
    if aircraft is not None and d.get("aircraft") != aircraft:
        raise DesignError(f"{path}: key 'aircraft' is {d.get('aircraft')!r}, this flight's aircraft is {aircraft!r}: "
                          f"an atlas of another aircraft; put the {aircraft}'s atlas at {atlas_path(aircraft)}")
    try:
        nodes = tuple(AtlasNode(float(n["h_ft"]), float(n["vc_kts"]), float(n["flaps_deg"]), str(n["turbulence"]),
                                str(n["maneuvers"]), str(n["design_digest"]), str(n["status"])) for n in d["nodes"])
        return Atlas(Path(path), str(d["aircraft"]), str(d["reference"]), dict(d["envelope"]), dict(d["conditions"]),
                     str(d["training"]), dict(d.get("stamp", {})), nodes, dict(d["entries"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise DesignError(f"{path}: damaged atlas file (key {exc}); regenerate it with "
                          "`python -m fdi_sim.study.atlas AIRCRAFT`") from None


def load_atlas(aircraft: str) -> Atlas | None:
    """The aircraft's shipped atlas (None: none shipped, or ``FDI_SIM_ATLAS=off``), read once per
    file version."""
    if not atlas_enabled():
        return None
    path = atlas_path(aircraft)
    try:
        mtime = path.stat().st_mtime
    except OSError:
        return None
    key = (str(path), mtime)
    if key not in _LOADED:
        _LOADED.clear()
        _LOADED[key] = read_atlas(path, None)
    atlas = _LOADED[key]
    base_ok = atlas.aircraft == aircraft or (aircraft.startswith("DHC6") and atlas.aircraft.startswith("DHC6"))
    if not base_ok:
        raise DesignError(f"{path}: key 'aircraft' is {atlas.aircraft!r}, this flight's aircraft is {aircraft!r}: "
                          f"an atlas of another aircraft; regenerate it with `python -m fdi_sim.study.atlas {aircraft}`")
    return atlas


def lookup(aircraft: str, kind: str, key: str, fp: Sequence[Sequence[float]]) -> tuple[dict[str, Any] | None, str]:
    """The atlas entry ``kind:key`` if its design fingerprint is within :data:`DESIGN_RTOL` of ``fp``.

    Returns
    -------
    entry : dict or None
        ``{"entry": ..., "node": ..., "atlas": Atlas.summary(...)}``.
    note : str
        Why not, when None (no atlas, no such key, or the design moved: how far).
    """
    atlas = load_atlas(aircraft)
    if atlas is None:
        return None, "no atlas"
    e = atlas.entries.get(f"{kind}:{key}")
    if e is None:
        return None, f"{atlas.path} has no {kind} entry for this design's inputs"
    dist = fingerprint_distance(fp, e["fingerprint"])
    if not dist <= DESIGN_RTOL:
        return None, (f"{atlas.path}: the {kind} entry's design differs from this one by {dist:.2g} (relative), more "
                      f"than {DESIGN_RTOL:g}: a changed design; regenerate the atlas")
    key_node = tuple(e["node"])
    node = next((n for n in atlas.nodes if (n.h_ft, n.vc_kts, n.flaps_deg, n.turbulence, n.maneuvers) == key_node), None)
    return {"entry": e["entry"], "node": e["node"], "distance": dist, "atlas": atlas.summary(node)}, ""


def record(kind: str, key: str, fp: Sequence[Sequence[float]], entry: Any) -> None:
    """Keep an entry for the atlas being made (:data:`RECORDER`; nothing elsewhere)."""
    if RECORDER is not None:
        RECORDER.append({"kind": kind, "key": key, "fingerprint": [list(map(float, r)) for r in fp], "entry": entry})

"""Operating-point grids: file format, command-line specs, envelope checks (no JSBSim here).

Grid file (``aircraft/<name>/grid.toml``)
-----------------------------------------
::

    aircraft = "f16"
    [envelope]                      # a point outside is bad input, refused before any trim
    h_ft = [0.0, 25000.0]
    vc_kts = [250.0, 600.0]         # any of vc_kts, vt_kts, mach, flaps_deg, icing_eta
    mach = [0.0, 0.72]
    [[block]]                       # each block is a Cartesian product of its axes
    h_ft = [5000, 10000, 15000, 20000]
    vt_kts = [350, 370, 390, 410, 430]   # or vc_kts (exactly one speed axis per block)
    flaps_deg = [0]                 # optional, default [0]
    icing_eta = [0]                 # optional, default [0]: a grid axis like any other
    [validation]                    # doublets of fdi_sim.linear.validate
    duration_s = 10.0
    width_s = 1.0
    [validation.amplitudes]
    elevator_cmd_norm = 0.01        # one per model input

Several blocks let the speed range depend on the flap setting (the DHC-6 flies 10 deg flaps
only at low speed). A command-line spec is one block: ``"h_ft=5000,10000;vt_kts=350:430:20"``
(``start:stop:step`` includes ``stop``), checked against the aircraft's default envelope.

The envelope needs Mach and calibrated airspeed of each point before any trim, and the model
schedule needs calibrated airspeed for a point given by true airspeed; both come from the 1976
standard atmosphere (``fdi_sim.isa``, troposphere and lower stratosphere). It is written in fdi-sim rather than
read from JSBSim because ``fdi_sim.linear`` does not import JSBSim (STYLE rule 2) and JSBSim's
``FGAtmosphere`` exists only inside a loaded aircraft; ``test_grid.py`` checks it against the
1976 tables and ``test_isa_calibrated_airspeed_matches_jsbsim`` against JSBSim's own air data.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import Any, Mapping

from fdi_sim.data import aircraft_file  # aircraft/ in a checkout, packaged in a wheel
from fdi_sim.errors import DesignError
from fdi_sim.isa import vc_from_vt, vt_from_vc
from fdi_sim.linear.validate import ValidationSettings
from fdi_sim.operating_point import OperatingPoint

#: axes a grid block may have
AXES: tuple[str, ...] = ("h_ft", "vt_kts", "vc_kts", "flaps_deg", "icing_eta")
#: quantities an envelope may limit
ENVELOPE_KEYS: tuple[str, ...] = ("h_ft", "vt_kts", "vc_kts", "mach", "flaps_deg", "icing_eta")

# ---------------------------------------------------------------------- grid
@dataclass(frozen=True)
class Envelope:
    """Limits of an aircraft's linearization envelope.

    Attributes
    ----------
    limits : dict
        ``name -> (low, high)`` for names in :data:`ENVELOPE_KEYS` [units of the name].
    why : str
        The reason for the limits (cited in error messages).
    """

    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    why: str = ""

    def problems(self, op: OperatingPoint) -> list[str]:
        """What is outside the envelope at ``op`` (empty when inside)."""
        speed_kind = "vt_kts" if op.vt_kts is not None else "vc_kts"
        speed = float(op.vt_kts if op.vt_kts is not None else op.vc_kts)  # type: ignore[arg-type]
        if speed_kind == "vt_kts":
            vt, (vc, mach) = speed, vc_from_vt(op.h_ft, speed)
        else:
            vc, (vt, mach) = speed, vt_from_vc(op.h_ft, speed)
        values = {"h_ft": op.h_ft, "vt_kts": vt, "vc_kts": vc, "mach": mach, "flaps_deg": op.flaps_deg,
                  "icing_eta": op.icing_eta}
        out = []
        for key, (lo, hi) in self.limits.items():
            v = values[key]
            if not lo - 1e-9 <= v <= hi + 1e-9:
                out.append(f"{key} = {v:.4g} outside [{lo:g}, {hi:g}]")
        return out


@dataclass(frozen=True)
class GridSpec:
    """A grid of operating points with its envelope and validation settings.

    Attributes
    ----------
    aircraft : str
        JSBSim model name.
    points : tuple of OperatingPoint
        Every point, in file order (block by block; h, speed, flaps, eta nested).
    envelope : Envelope
        Limits every point was checked against.
    validation : ValidationSettings
        The doublets of the ``[validation]`` table.
    source : str
        File path or the command-line spec.
    """

    aircraft: str
    points: tuple[OperatingPoint, ...]
    envelope: Envelope
    validation: ValidationSettings
    source: str


def _values(key: str, v: Any, source: str) -> list[float]:
    vals = v if isinstance(v, list) else [v]
    try:
        out = [float(x) for x in vals]
    except (TypeError, ValueError):
        raise DesignError(f"{source}: axis {key!r} must be a number or a list of numbers, got {v!r}") from None
    if not out:
        raise DesignError(f"{source}: axis {key!r} is empty; give at least one value")
    return out


def _block_points(aircraft: str, block: Mapping[str, Any], source: str) -> list[OperatingPoint]:
    unknown = [k for k in block if k not in AXES]
    if unknown:
        raise DesignError(f"{source}: unknown grid axis {unknown}; axes are {', '.join(AXES)}")
    speeds = [k for k in ("vt_kts", "vc_kts") if k in block]
    if len(speeds) != 1 or "h_ft" not in block:
        raise DesignError(f"{source}: each block needs h_ft and exactly one of vt_kts, vc_kts (got {sorted(block)})")
    sk = speeds[0]
    axes = [_values(k, block.get(k, [0.0]), source) for k in ("h_ft", sk, "flaps_deg", "icing_eta")]
    return [OperatingPoint(aircraft=aircraft, h_ft=h, flaps_deg=f, icing_eta=e, **{sk: v})
            for h, v, f, e in product(*axes)]


def _envelope(data: Mapping[str, Any], source: str) -> Envelope:
    limits: dict[str, tuple[float, float]] = {}
    why = str(data.get("why", ""))
    for key, v in data.items():
        if key == "why":
            continue
        if key not in ENVELOPE_KEYS:
            raise DesignError(f"{source}: unknown envelope key {key!r}; keys are {', '.join(ENVELOPE_KEYS)}")
        vals = _values(key, v, source)
        if len(vals) != 2 or vals[0] > vals[1]:
            raise DesignError(f"{source}: envelope.{key} must be [low, high], got {v!r}")
        limits[key] = (vals[0], vals[1])
    return Envelope(limits=limits, why=why)


def _number(key: str, v: Any, source: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DesignError(f"{source}: {key} must be a number, got {v!r}")
    return float(v)


def _validation(data: Mapping[str, Any], source: str) -> ValidationSettings:
    keys = ("amplitudes", "duration_s", "width_s", "start_s")
    unknown = [k for k in data if k not in keys]
    if unknown:
        raise DesignError(f"{source}: unknown [validation] keys {unknown}; keys are {', '.join(keys)}")
    amps = data.get("amplitudes", {})
    if not isinstance(amps, Mapping):
        raise DesignError(f"{source}: [validation.amplitudes] must be a table of input = amplitude")
    times = {k: _number(f"validation.{k}", data[k], source) for k in keys[1:] if k in data}
    for k, v in times.items():
        if v < 0 or (v == 0 and k != "start_s"):
            raise DesignError(f"{source}: validation.{k} = {v:g} s; give a positive time")
    return ValidationSettings(amplitudes={k: _number(f"validation.amplitudes.{k}", v, source) for k, v in amps.items()},
                              **times)


def check_envelope(points: tuple[OperatingPoint, ...], envelope: Envelope, source: str) -> None:
    """Refuse points outside the envelope (one message listing all of them).

    Raises
    ------
    DesignError
        With each offending point and limit, and the envelope's reason.
    """
    bad = [f"{op.label()}: {'; '.join(p)}" for op in points if (p := envelope.problems(op))]
    if bad:
        why = f" ({envelope.why})" if envelope.why else ""
        shown = "; ".join(bad[:5]) + (f"; and {len(bad) - 5} more" if len(bad) > 5 else "")
        raise DesignError(f"{source}: {len(bad)} grid point(s) outside the linearization envelope{why}: {shown}. "
                          "Move them inside or widen [envelope] in the grid file if the model supports it.")


def grid_from_dict(data: Mapping[str, Any], source: str, aircraft: str | None = None) -> GridSpec:
    """Build a :class:`GridSpec` from parsed TOML (see the module docstring for the format)."""
    ac = data.get("aircraft", aircraft)
    if not isinstance(ac, str) or not ac:
        raise DesignError(f"{source}: missing 'aircraft = \"f16\"' (or DHC6) at the top")
    if aircraft is not None and ac != aircraft:
        raise DesignError(f"{source}: grid is for aircraft {ac!r}, but {aircraft!r} was asked for")
    unknown = [k for k in data if k not in ("aircraft", "envelope", "block", "validation", "description")]
    if unknown:
        raise DesignError(f"{source}: unknown top-level keys {unknown}; use aircraft, envelope, block, validation")
    blocks = data.get("block")
    if not isinstance(blocks, list) or not blocks:
        raise DesignError(f"{source}: no [[block]] of grid axes; add one with h_ft and vt_kts or vc_kts")
    points: list[OperatingPoint] = []
    for b in blocks:
        points += _block_points(ac, b, source)
    env = _envelope(data.get("envelope", {}), source)
    check_envelope(tuple(points), env, source)
    val = _validation(data.get("validation", {}), source)
    return GridSpec(aircraft=ac, points=tuple(points), envelope=env, validation=val, source=source)


def default_grid_path(aircraft: str) -> Path:
    """``aircraft/<aircraft>/grid.toml``."""
    return aircraft_file(aircraft, "grid.toml")


def load_grid(path: str | Path, aircraft: str | None = None) -> GridSpec:
    """Read a grid file.

    Raises
    ------
    DesignError
        Missing or unreadable file, bad TOML, a bad axis, or a point outside the envelope.
    """
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise DesignError(f"grid file {p} not found; give a grid.toml or a spec like 'h_ft=5000,10000;vt_kts=350:430:20'") from None
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise DesignError(f"grid file {p}: {exc}") from None
    return grid_from_dict(data, str(p), aircraft)


def _parse_values(text: str, key: str, spec: str) -> list[float]:
    try:
        if ":" in text:
            parts = [float(x) for x in text.split(":")]
            if len(parts) != 3 or parts[2] <= 0 or parts[1] < parts[0]:
                raise ValueError
            start, stop, step = parts
            n = int(math.floor((stop - start) / step + 1e-9)) + 1
            return [start + i * step for i in range(n)]
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise DesignError(f"grid spec {spec!r}: cannot read {key}={text!r}; use a list '5000,10000' or "
                          "'start:stop:step' with step > 0") from None


def parse_grid_spec(spec: str, aircraft: str) -> GridSpec:
    """A grid from ``"h_ft=5000,10000;vt_kts=350:430:20[;flaps_deg=0,10][;icing_eta=0,0.05]"``.

    The envelope and validation settings are those of the aircraft's default grid file.
    """
    block: dict[str, list[float]] = {}
    for part in filter(None, (s.strip() for s in spec.split(";"))):
        key, sep, text = part.partition("=")
        key = key.strip()
        if not sep:
            raise DesignError(f"grid spec {spec!r}: {part!r} is not 'axis=values'")
        if key not in AXES:
            raise DesignError(f"grid spec {spec!r}: unknown axis {key!r}; axes are {', '.join(AXES)}")
        block[key] = _parse_values(text.strip(), key, spec)
    base_path = default_grid_path(aircraft)
    base: dict[str, Any] = {}
    if base_path.exists():
        base = tomllib.loads(base_path.read_text())
    data = {"aircraft": aircraft, "envelope": base.get("envelope", {}), "block": [block],
            "validation": base.get("validation", {})}
    return grid_from_dict(data, f"grid spec {spec!r}", aircraft)


def named_grids(aircraft: str) -> dict[str, Path]:
    """The aircraft's shipped grids: ``default`` (``grid.toml``) and ``<name>`` (``grid_<name>.toml``)."""
    folder = aircraft_file(aircraft, "")
    out = {"default": default_grid_path(aircraft)} if default_grid_path(aircraft).exists() else {}
    out.update({f.stem.removeprefix("grid_"): f for f in sorted(folder.glob("grid_*.toml"))})
    return out


def resolve_grid(text: str | None, aircraft: str) -> GridSpec:
    """A grid file path, a spec string, a shipped grid's name (``iced``), or None for the default grid.

    Raises
    ------
    DesignError
        Neither a spec, nor an existing file, nor a shipped grid name (the message lists them).
    """
    if text is None:
        return load_grid(default_grid_path(aircraft), aircraft)
    if "=" in text:
        return parse_grid_spec(text, aircraft)
    named = named_grids(aircraft)
    if text in named and not Path(text).exists():
        return load_grid(named[text], aircraft)
    if not Path(text).exists() and not text.endswith(".toml"):
        raise DesignError(f"grid {text!r} is not a file, a spec like 'h_ft=5000,10000;vt_kts=350:430:20' or a "
                          f"grid shipped for {aircraft} ({', '.join(named) or 'none'})")
    return load_grid(text, aircraft)

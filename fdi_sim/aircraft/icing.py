"""The icing overlay: iced copies of the DHC-6 and the F-16 in which eta scales the aero model.

Model (Bragg et al., AIAA 2000-0360; the UIUC Smart Icing Systems simulator, ``uiuc_ice.cpp``)::

    C_iced = C_clean (1 + eta k_C)

with the icing severity ``eta`` [-] (0 = clean) and one sensitivity ``k_C`` [-] per coefficient.
The builders registered in :data:`fdi_sim.aircraft.overlays.GENERATORS` copy ``DHC6`` and ``f16``
from the patched JSBSim root to ``DHC6_iced`` and ``f16_iced`` and change two things (JSBSIM_NOTES
sec. 5.3):

* an inline ``<system name="icing">`` declares ``icing/eta`` (default 0) and one
  ``icing/k-<X>`` per scaled coefficient (default: the whole-aircraft k, ``persistent`` so a
  JSBSim reset keeps a region chosen from Python);
* one increment function per scaled part, added to the axis of the function it scales::

      aero/coefficient/<F>_ice = icing/eta * icing/k-<X> * P

  where ``P`` is the whole function ``F`` or only the part the k applies to (see :data:`PARTS`).
  The original functions are untouched, so with ``eta = 0`` every increment is exactly 0 and the
  iced model flies exactly as the clean one.

The data (which k scales which part of which function, the k of each region, the largest
``eta``) is in ``aircraft/<name>/icing.toml``; :func:`k_values` and :func:`eta_max` serve it to
the icing fault. The DHC-6 k are the UIUC Twin Otter values; the F-16 k are the same values
mapped by derivative kind and are generic, not fitted (``docs/icing.md``).
"""
from __future__ import annotations

import copy
import difflib
import functools
import shutil
import tomllib
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import numpy as np

from fdi_sim.aircraft.model import iced_model_name
from fdi_sim.aircraft.overlays import GENERATORS
from fdi_sim.data import aircraft_file  # aircraft/ in a checkout, packaged in a wheel
from fdi_sim.errors import FdiSimError

#: aircraft with an icing overlay -> JSBSim model name of the overlay
ICED_MODELS: Mapping[str, str] = MappingProxyType({n: iced_model_name(n) for n in ("DHC6", "f16")})
#: the parts of an aero function a k can scale; ``T`` is the function's one table
PARTS: Mapping[str, str] = MappingProxyType({
    "whole": "the whole function",
    "alpha": "T(alpha) - T(alpha = 0): the alpha-dependent part of a 1-D alpha table",
    "beta": "T(beta, alpha) - T(beta = 0, alpha): the sideslip-dependent part",
    "zero": "T(0, 0): the value at zero alpha and elevator (zero-lift drag)",
    "alpha_at_zero_elevator": "T(alpha, 0) - T(0, 0): the alpha-dependent part at zero elevator",
    "elevator": "T(alpha, de) - T(alpha, 0): the elevator-dependent part",
})
#: independent variable set to zero by each split part (first: the one the reference is taken at)
_SPLIT_VARS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "alpha": ("aero/alpha-rad",),
    "beta": ("aero/beta-rad",),
    "elevator": ("fcs/elevator-pos-rad",),
    "alpha_at_zero_elevator": ("fcs/elevator-pos-rad", "aero/alpha-rad"),
    "zero": ("fcs/elevator-pos-rad", "aero/alpha-rad"),
})
ETA_PROPERTY = "icing/eta"


class IcingDataError(FdiSimError, ValueError):
    """An icing data file or request is invalid (unknown region, missing k, bad mapping)."""


@dataclass(frozen=True)
class IcingTerm:
    """One eta-scaled increment added to the iced model.

    Attributes
    ----------
    k_name : str
        The ``<X>`` of the property ``icing/k-<X>`` that scales it.
    function : str
        The JSBSim aero function it scales (``aero/coefficient/CmDe``).
    part : str
        Which part of the function (a key of :data:`PARTS`).
    increment : str
        Name of the added function (``aero/coefficient/CmDe_ice``): its value is the increment of
        the force [lbf] or moment [lbf ft] at the current eta.
    """

    k_name: str
    function: str
    part: str
    increment: str


@dataclass(frozen=True)
class IcingRegion:
    """The k of one icing region (whole aircraft, tail, wing).

    Attributes
    ----------
    name : str
        ``"all"``, ``"tail"`` or ``"wing"``.
    description : str
        One line.
    source : str
        Where the values come from.
    k : Mapping[str, float]
        ``<X>`` of ``icing/k-<X>`` -> k [-] (read-only).
    """

    name: str
    description: str
    source: str
    k: Mapping[str, float]


@dataclass(frozen=True)
class IcingData:
    """Contents of ``aircraft/<name>/icing.toml``.

    Attributes
    ----------
    aircraft : str
        ``"DHC6"`` or ``"f16"``.
    generic : bool
        True when the k are not fitted to this aircraft (the F-16).
    eta_max : float
        Largest eta the k are meant for [-].
    sources : tuple of str
        References.
    terms : tuple of IcingTerm
        Every increment of the overlay, in file order.
    regions : Mapping[str, IcingRegion]
        By name; ``"all"`` gives the defaults of the ``icing/k-<X>`` properties.
    uiuc_names : Mapping[str, str]
        ``<X>`` -> the name of its k in the UIUC files (``kCm_de``).
    """

    aircraft: str
    generic: bool
    eta_max: float
    sources: tuple[str, ...]
    terms: tuple[IcingTerm, ...]
    regions: Mapping[str, IcingRegion]
    uiuc_names: Mapping[str, str]

    @property
    def k_names(self) -> tuple[str, ...]:
        """The ``<X>`` of every ``icing/k-<X>`` property, in file order."""
        return tuple(dict.fromkeys(t.k_name for t in self.terms))


# ---------------------------------------------------------------------- data files
def data_path(aircraft: str) -> Path:
    """``aircraft/<name>/icing.toml`` [path]."""
    return aircraft_file(aircraft, "icing.toml")


@functools.lru_cache(maxsize=None)
def icing_data(aircraft: str) -> IcingData:
    """Read and check ``aircraft/<aircraft>/icing.toml``.

    Raises
    ------
    IcingDataError
        The aircraft has no icing data, or the file is inconsistent (a region without a k, an
        unknown part).
    """
    if aircraft not in ICED_MODELS:
        raise IcingDataError(f"no icing overlay for aircraft {aircraft!r}; aircraft with one: {', '.join(ICED_MODELS)}")
    path = data_path(aircraft)
    raw = tomllib.loads(path.read_text())
    where = str(path)
    scaled: list[tuple[str, str, str]] = []  # (k name, function, part) in file order
    uiuc: dict[str, str] = {}
    for k_name, spec in raw["coefficients"].items():
        uiuc[k_name] = str(spec.get("uiuc", ""))
        for function, part in spec["functions"]:
            if part not in PARTS:
                raise IcingDataError(f"{where}: coefficients.{k_name}: unknown part {part!r}; parts: {', '.join(PARTS)}")
            scaled.append((k_name, function, part))
    # one increment per (function, k): '<F>_ice', or '<F>_ice_<X>' when one function is split
    per_function = Counter(function for _, function, _ in scaled)
    terms = [IcingTerm(k_name, function, part,
                       f"{function}_ice" if per_function[function] == 1 else f"{function}_ice_{k_name}")
             for k_name, function, part in scaled]
    k_names = tuple(dict.fromkeys(k_name for k_name, _, _ in scaled))
    regions: dict[str, IcingRegion] = {}
    for name, reg in raw["regions"].items():
        k = {n: float(v) for n, v in reg["k"].items()}
        missing, extra = set(k_names) - set(k), set(k) - set(k_names)
        if missing or extra:
            raise IcingDataError(f"{where}: regions.{name}.k: missing {sorted(missing)}, unknown {sorted(extra)}; "
                                 f"give exactly the coefficients {', '.join(k_names)}")
        regions[name] = IcingRegion(name, str(reg.get("description", "")), str(reg.get("source", "")),
                                    MappingProxyType(k))
    if "all" not in regions:
        raise IcingDataError(f"{where}: no [regions.all] (it gives the defaults of the icing/k-* properties)")
    eta = float(raw["eta_max"])
    if not 0.0 < eta <= 1.0:
        raise IcingDataError(f"{where}: eta_max = {eta} outside (0, 1]")
    return IcingData(aircraft=aircraft, generic=bool(raw.get("generic", False)), eta_max=eta,
                     sources=tuple(raw.get("sources", ())), terms=tuple(terms),
                     regions=MappingProxyType(regions), uiuc_names=MappingProxyType(uiuc))


def regions(aircraft: str) -> tuple[str, ...]:
    """Names of the icing regions of an aircraft (``("all", "tail", "wing")``)."""
    return tuple(icing_data(aircraft).regions)


def k_values(aircraft: str, region: str = "all") -> dict[str, float]:
    """The k of one region: ``<X>`` of ``icing/k-<X>`` -> k [-] (a new dict; pass it to ``Aircraft.set_icing_k``).

    Raises
    ------
    IcingDataError
        Unknown region (with the closest name).
    """
    regs = icing_data(aircraft).regions
    if region not in regs:
        close = difflib.get_close_matches(region, list(regs), n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise IcingDataError(f"{aircraft} has no icing region {region!r}; regions: {', '.join(regs)}.{hint}")
    return dict(regs[region].k)


def eta_max(aircraft: str) -> float:
    """Largest icing severity the aircraft's k are meant for [-] (the UIUC files: about 0.4)."""
    return icing_data(aircraft).eta_max


# ---------------------------------------------------------------------- JSBSim tables
@dataclass(frozen=True)
class _Table:
    """A 1-D or 2-D JSBSim table: ``values[i, j]`` at ``(rows[i], cols[j])``."""

    row_var: str
    col_var: str | None
    rows: np.ndarray
    cols: np.ndarray | None
    values: np.ndarray  # (n_rows,) or (n_rows, n_cols)

    def at_zero(self, var: str) -> "_Table | float":
        """The table with ``var`` set to 0 (JSBSim interpolates linearly and clamps at the ends)."""
        if self.col_var is None:
            if var != self.row_var:
                raise IcingDataError(f"table over {self.row_var} has no variable {var}")
            return float(np.interp(0.0, self.rows, self.values))
        if var == self.col_var:
            v = np.array([np.interp(0.0, self.cols, r) for r in self.values])
            return _Table(self.row_var, None, self.rows, None, v)
        if var == self.row_var:
            v = np.array([np.interp(0.0, self.rows, c) for c in self.values.T])
            return _Table(self.col_var, None, self.cols, None, v)
        raise IcingDataError(f"table over ({self.row_var}, {self.col_var}) has no variable {var}")

    def element(self) -> ET.Element:
        """A JSBSim ``<table>`` element of a 1-D table."""
        if self.col_var is not None:
            raise IcingDataError("only 1-D tables are written")
        t = ET.Element("table")
        ET.SubElement(t, "independentVar").text = self.row_var
        # repr() round-trips every double, so JSBSim reads back exactly these numbers
        rows = "\n".join(f"          {x!r} {y!r}" for x, y in zip(self.rows.tolist(), self.values.tolist()))
        ET.SubElement(t, "tableData").text = f"\n{rows}\n        "
        return t


def _parse_table(el: ET.Element) -> _Table:
    """Read a 1-D or 2-D ``<table>`` element (3-D tables with breakpoints are refused)."""
    ivars = el.findall("independentVar")
    datas = el.findall("tableData")
    if len(datas) != 1 or datas[0].get("breakPoint") is not None or len(ivars) not in (1, 2):
        raise IcingDataError("only 1-D and 2-D tables can be split into parts; use part = 'whole'")
    lines = [ln.split() for ln in (datas[0].text or "").strip().splitlines() if ln.strip()]
    if len(ivars) == 1:
        a = np.array(lines, dtype=float)
        return _Table(ivars[0].text.strip(), None, a[:, 0], None, a[:, 1])
    by_lookup = {v.get("lookup", "row" if i == 0 else "column"): v.text.strip() for i, v in enumerate(ivars)}
    cols = np.array(lines[0], dtype=float)
    body = np.array(lines[1:], dtype=float)
    return _Table(by_lookup["row"], by_lookup["column"], body[:, 0], cols, body[:, 1:])


def _value(x: float) -> ET.Element:
    v = ET.Element("value")
    v.text = repr(float(x))
    return v


def _part_factors(function: ET.Element, part: str) -> list[ET.Element]:
    """The factors whose product is ``part`` of an aero function (a ``<product>`` of properties,
    values and one table), as new elements."""
    prod = function.find("product")
    if prod is None:
        raise IcingDataError(f"{function.get('name')}: not a <product>; use part = 'whole'")
    tables = [c for c in prod if c.tag == "table"]
    if len(tables) != 1:
        raise IcingDataError(f"{function.get('name')}: {len(tables)} tables in the product; need exactly one to split")
    others = [copy.deepcopy(c) for c in prod if c.tag not in ("table", "description")]
    table = copy.deepcopy(tables[0])
    table.attrib.pop("name", None)  # a named table would tie its property a second time
    t = _parse_table(table)
    ref: _Table | float = t
    for var in _SPLIT_VARS[part]:
        assert isinstance(ref, _Table)
        ref = ref.at_zero(var)
    if part == "zero":  # T(0, 0)
        assert not isinstance(ref, _Table)
        return others + [_value(ref)]
    if part == "alpha_at_zero_elevator":  # T(alpha, 0) - T(0, 0)
        t_alpha = t.at_zero("fcs/elevator-pos-rad")
        assert isinstance(t_alpha, _Table) and not isinstance(ref, _Table)
        diff = ET.Element("difference")
        diff.extend([t_alpha.element(), _value(ref)])
        return others + [diff]
    diff = ET.Element("difference")  # T - T(split var = 0)
    diff.extend([table, ref.element() if isinstance(ref, _Table) else _value(ref)])
    return others + [diff]


def _increment(term: IcingTerm, function: ET.Element) -> ET.Element:
    """``<function name=increment>`` = eta * k * part."""
    f = ET.Element("function", name=term.increment)
    ET.SubElement(f, "description").text = (
        f"Icing increment: eta k-{term.k_name} x ({PARTS[term.part]} of {term.function}); Bragg et al. AIAA 2000-0360")
    prod = ET.SubElement(f, "product")
    ET.SubElement(prod, "property").text = ETA_PROPERTY
    ET.SubElement(prod, "property").text = f"icing/k-{term.k_name}"
    if term.part == "whole":
        ET.SubElement(prod, "property").text = term.function
    else:
        part = ET.SubElement(prod, "product")
        part.extend(_part_factors(function, term.part))
    return f


def add_icing(root: ET.Element, data: IcingData) -> None:
    """Add the icing system and the increment functions to a parsed JSBSim model (in place).

    Raises
    ------
    IcingDataError
        A function named in the data is not in the model, or the model already has an icing system.
    """
    aero = root.find("aerodynamics")
    if aero is None:
        raise IcingDataError(f"{data.aircraft}: the model has no <aerodynamics>")
    if any(s.get("name") == "icing" for s in root.findall("system")):
        raise IcingDataError(f"{data.aircraft}: the model already has an icing system")
    where: dict[str, tuple[ET.Element, ET.Element]] = {}
    for axis in aero.findall("axis"):
        for fn in axis.findall("function"):
            where[fn.get("name", "")] = (axis, fn)
    # declarations: JSBSim loads <system> before <aerodynamics>, wherever it sits in the file
    system = ET.Element("system", name="icing")
    ET.SubElement(system, "description").text = (
        "Icing severity eta and the sensitivities k of C_iced = C (1 + eta k) (fdi_sim.aircraft.icing)")
    ET.SubElement(system, "property", value="0").text = ETA_PROPERTY
    defaults = data.regions["all"].k
    for name in data.k_names:
        ET.SubElement(system, "property", value=repr(defaults[name]), persistent="true").text = f"icing/k-{name}"
    first_aux = next((i for i, c in enumerate(root) if c.tag in ("system", "flight_control", "autopilot", "aerodynamics")),
                     len(root))
    ET.indent(system, space="  ", level=1)
    system.tail = root[first_aux - 1].tail if first_aux else "\n"
    root.insert(first_aux, system)
    for term in data.terms:
        if term.function not in where:
            raise IcingDataError(f"{data.aircraft}: no aero function {term.function!r} in the model (coefficient {term.k_name})")
        axis, fn = where[term.function]
        inc = _increment(term, fn)
        ET.indent(inc, space="  ", level=3)
        if len(axis):
            axis[-1].tail = "\n      "
        inc.tail = "\n    "
        axis.append(inc)


def _build(aircraft: str, dst_root: Path) -> None:
    """Copy ``dst_root/aircraft/<aircraft>`` (already patched) to its iced model and add the icing."""
    data = icing_data(aircraft)
    iced = ICED_MODELS[aircraft]
    src = dst_root / "aircraft" / aircraft
    dst = dst_root / "aircraft" / iced
    shutil.copytree(src, dst)  # Engines/, Systems/ come along: JSBSim looks for them next to the XML
    (dst / f"{aircraft}.xml").rename(dst / f"{iced}.xml")
    path = dst / f"{iced}.xml"
    tree = ET.parse(path)
    add_icing(tree.getroot(), data)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def _builder(aircraft: str) -> Callable[[Path, Path], None]:
    """Overlay builder (:data:`~fdi_sim.aircraft.overlays.GENERATORS`) of ``aircraft/<aircraft>_iced``."""
    def build(wheel_root: Path, dst_root: Path) -> None:
        _build(aircraft, dst_root)

    # what the builder reads: the overlay cache key includes it, so an edited icing.toml rebuilds the root
    build.data_files = (data_path(aircraft),)  # type: ignore[attr-defined]
    return build


GENERATORS.update({iced: _builder(name) for name, iced in ICED_MODELS.items()})

"""The JSBSim adapter: one ``Aircraft`` per simulation, the only place ``jsbsim`` is driven.

It loads a model from the patched JSBSim root (:mod:`fdi_sim.aircraft.overlays`), starts the
engines, trims (:mod:`fdi_sim.aircraft.trim`), sets the atmosphere, reads signals by their
suffixed names through cached property nodes, and steps. Units at this boundary are the
suffixed names of :mod:`fdi_sim.aircraft.properties`.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

os.environ.setdefault("JSBSIM_DEBUG", "0")  # silence the banner before the first FGFDMExec
import jsbsim  # noqa: E402

from fdi_sim.aircraft.overlays import jsbsim_root  # noqa: E402
from fdi_sim.aircraft.properties import Scaled, SurfaceSpec, property_map, surfaces  # noqa: E402
from fdi_sim.errors import FdiSimError  # noqa: E402
from fdi_sim.units import FPS_PER_KT  # noqa: E402

#: JSBSim model names fdi-sim knows, with a one-line description
AIRCRAFT: dict[str, str] = {
    "f16": "General Dynamics F-16 (JSBSim f16, FBW pitch/roll/yaw loops, F100 turbofan)",
    "DHC6": "de Havilland Canada DHC-6 Twin Otter (JSBSim DHC6, two PT6A-27 turboprops)",
}

#: MIL-F-8785C turbulence levels: JSBSim probability-of-exceedance index and wind at 20 ft [kt]
TURBULENCE_LEVELS: dict[str, tuple[int, float]] = {
    "none": (0, 0.0),
    "light": (3, 15.0),
    "moderate": (4, 30.0),
    "severe": (6, 45.0),
}


class UnknownAircraftError(FdiSimError, KeyError):
    """The aircraft name is not one of :data:`AIRCRAFT`."""

    def __str__(self) -> str:
        return str(self.args[0])


def wind_ned_fps(wind_from_deg: float, wind_speed_kts: float) -> tuple[float, float, float]:
    """Velocity of the air mass (north, east, down) for a wind blowing *from* ``wind_from_deg`` [ft/s]."""
    to_rad = math.radians(wind_from_deg + 180.0)  # the air moves toward from + 180 deg
    spd = wind_speed_kts * FPS_PER_KT
    return spd * math.cos(to_rad), spd * math.sin(to_rad), 0.0


@dataclass(frozen=True)
class Atmosphere:
    """Steady wind and MIL-F-8785C (Dryden, JSBSim ``ttMilspec``) turbulence.

    Attributes
    ----------
    turbulence : str
        One of :data:`TURBULENCE_LEVELS`.
    wind_from_deg : float
        Direction the steady wind blows from [deg true].
    wind_speed_kts : float
        Steady wind speed [kt].
    """

    turbulence: str = "none"
    wind_from_deg: float = 0.0
    wind_speed_kts: float = 0.0


def iced_model_name(name: str) -> str:
    """JSBSim model name of the icing overlay of ``name`` (built by :mod:`fdi_sim.aircraft.icing`)."""
    return f"{name}_iced"


#: the node attribute a held surface clears (FGPropertyNode WRITE flag)
_WRITE = jsbsim.Attribute.WRITE


class SurfaceHandle:
    """Takes a control surface away from the FCS (JSBSIM_NOTES sec. 3.4, the WRITE-attribute trick).

    While held, the FCS's writes to the position nodes fail silently, so the aero model flies the
    value given to :meth:`hold`. The FCS keeps computing the healthy position in its component's
    own node (``healthy()``); a value set before ``run()`` from the healthy value of the last
    frame lags the healthy actuator by one step.
    """

    def __init__(self, spec: SurfaceSpec, nodes: list, healthy: object) -> None:
        self.spec = spec
        # per node: its attribute setter, value setter and scale (bound once: hold runs every step)
        self._writes = [(n.set_attribute, n.set_double_value, spec.scale(i)) for i, n in enumerate(nodes)]
        self.healthy: Callable[[], float] = healthy.get_double_value  # what the healthy FCS commands now [rad]
        self.position: Callable[[], float] = nodes[0].get_double_value  # the value the aero model flies [rad]
        self.held = False

    def hold(self, value_rad: float) -> None:
        """Fly ``value_rad`` [rad] until the next call or :meth:`release`."""
        for set_attribute, set_value, scale in self._writes:
            set_attribute(_WRITE, True)
            set_value(value_rad * scale)
            set_attribute(_WRITE, False)
        self.held = True

    def release(self) -> None:
        """Give the surface back to the FCS (it writes the healthy value from the next step on)."""
        for set_attribute, _, _ in self._writes:
            set_attribute(_WRITE, True)
        self.held = False


class Aircraft:
    """A JSBSim aircraft ready to trim and fly.

    Parameters
    ----------
    name : str
        ``"f16"`` or ``"DHC6"``.
    dt_s : float
        Integration step [s] (JSBSim's default is 1/120 s).
    icing : bool
        Load the icing overlay (:func:`iced_model_name`): the same model with every iced aero
        coefficient scaled by ``1 + eta k`` through the properties ``icing/eta`` and
        ``icing/k-<coefficient>``; with ``eta = 0`` it flies as the clean model.
    """

    def __init__(self, name: str, dt_s: float = 1.0 / 120.0, *, icing: bool = False) -> None:
        if name not in AIRCRAFT:
            raise UnknownAircraftError(f"unknown aircraft {name!r}; known: {', '.join(AIRCRAFT)}")
        self.name = name
        self.icing = bool(icing)
        self.dt_s = float(dt_s)
        self.fdm = jsbsim.FGFDMExec(str(jsbsim_root()))
        self.fdm.set_debug_level(0)
        model = iced_model_name(name) if icing else name
        if not self.fdm.load_model(model):
            raise UnknownAircraftError(f"JSBSim could not load {model!r}")
        self.fdm.set_dt(self.dt_s)
        # Third-order Adams-Bashforth for all four FGPropagate integrators. JSBSim's defaults
        # (rectangular Euler for body rates and attitude, AB2 for velocity) are first-order on the
        # rotation: at 120 Hz they shift an oscillatory mode's real part by about omega^2 dt / 2
        # (DHC-6 Dutch roll 4.4 rad/s: 0.08 1/s of its 0.41), so the simulation strays from its own
        # equations and from every model discretized from them. With AB3 the zero-order-hold models
        # of the linearizer fit the small-doublet runs (F-16 grid: 17/20 points below 5 % on every
        # output instead of 14/20; tests/linear/test_linearize_jsbsim.py).
        # Codes: 0 none, 1 rectangular Euler, 2 trapezoidal, 3 AB2, 4 AB3, 5 AB4.
        for kind in ("rate/rotational", "rate/translational", "position/rotational", "position/translational"):
            self.fdm[f"simulation/integrator/{kind}"] = 4
        self.n_engines = self.fdm.get_propulsion().get_num_engines()
        self._pm = self.fdm.get_property_manager()
        self._map = property_map(name)
        self._node_cache: dict[str, object] = {}

    # ------------------------------------------------------------------ properties
    def __getitem__(self, prop: str) -> float:
        """Raw JSBSim property read (adapter-internal and tests)."""
        return float(self.fdm[prop])

    def __setitem__(self, prop: str, value: float) -> None:
        self.fdm[prop] = value

    def node(self, prop: str) -> object:
        """Cached ``FGPropertyNode`` for a JSBSim property (fast reads and writes)."""
        n = self._node_cache.get(prop)
        if n is None:
            n = self._pm.get_node(prop, False)
            if n is None:
                raise KeyError(f"{self.name} has no property {prop!r}")
            self._node_cache[prop] = n
        return n

    def signal_names(self) -> tuple[str, ...]:
        return tuple(self._map)

    def _signal_props(self, name: str) -> tuple[str, ...]:
        """The JSBSim properties of one signal (several: the signal is their sum)."""
        if name not in self._map:
            raise KeyError(f"unknown signal {name!r} for {self.name}")
        props = self._map[name]
        if isinstance(props, Scaled):
            return (props.prop,)
        return (props,) if isinstance(props, str) else props

    def _signal_factor(self, name: str) -> float | None:
        """The constant a :class:`Scaled` signal multiplies its property by; None for the others."""
        spec = self._map[name]
        return spec.factor if isinstance(spec, Scaled) else None

    def reader(self, names: Sequence[str]) -> Callable[[], NDArray[np.float64]]:
        """A fast closure returning the named signals as a new float64 array.

        Signals mapped to several properties are their sum (DHC-6 thrust of both engines).
        """
        getters: list[Callable[[], float]] = []
        for name in names:
            parts = [self.node(p).get_double_value for p in self._signal_props(name)]
            factor = self._signal_factor(name)
            if factor is not None:
                getters.append(lambda g=parts[0], f=factor: f * g())
            elif len(parts) == 1:
                getters.append(parts[0])
            else:
                getters.append(lambda parts=parts: sum(g() for g in parts))
        n = len(getters)

        def read() -> NDArray[np.float64]:
            return np.fromiter((g() for g in getters), dtype=np.float64, count=n)

        return read

    def list_reader(self, names: Sequence[str]) -> Callable[[], list[float]]:
        """A faster closure returning the named signals as a new list of Python floats.

        The same values as :meth:`reader`, bit for bit (a summed signal is ``sum`` of its parts, a
        scaled one ``factor * value``, as there). One ``map`` of the unbound node getter over the
        cached nodes: about 1.8 us for the 29 truth signals against 4.7 us for :meth:`reader`
        (numpy.fromiter over a generator).
        """
        nodes: list[object] = []
        sums: list[tuple[int, int]] = []  # summed signals: (first, end) index into the flat reads
        scales: list[tuple[int, float]] = []  # scaled signals: (index into the flat reads, factor)
        for name in names:
            props = self._signal_props(name)
            factor = self._signal_factor(name)
            if factor is not None:
                scales.append((len(nodes), factor))
            if len(props) > 1:
                sums.append((len(nodes), len(nodes) + len(props)))
            nodes.extend(self.node(p) for p in props)
        get = jsbsim.FGPropertyNode.get_double_value
        if not sums and not scales:
            def read() -> list[float]:
                return list(map(get, nodes))
            return read
        # rebuild the output from the flat reads: scaled signals (one node each) in place, then the
        # summed ones back to front so that the indexes of the others hold
        plan = sorted(sums, reverse=True)

        def read_combined() -> list[float]:
            v = list(map(get, nodes))
            for i, f in scales:
                v[i] = f * v[i]
            for a, b in plan:
                v[a:b] = [sum(v[a:b])]
            return v

        return read_combined

    def flat_reader(self, names: Sequence[str], extra: Sequence[str] = ()
                    ) -> tuple[Callable[[], list[float]], list[tuple[int, int, float | None]]]:
        """The properties behind the named signals, read flat, then the ``extra`` properties.

        Returns ``(read, plan)``: ``read()`` gives the raw property values as a new list of
        Python floats (one ``map`` of the node getter, nothing combined); ``plan`` gives per signal
        its reads ``[first, end)`` and its factor (None: unscaled). A signal is the sum of its reads
        (Python's ``sum``), times its factor: :meth:`list_reader`'s value (the loop's compiled core,
        :mod:`fdi_sim.sim._core`, combines them).
        """
        nodes, plan = self.flat_nodes(names, extra)
        get = jsbsim.FGPropertyNode.get_double_value

        def read() -> list[float]:
            return list(map(get, nodes))

        return read, plan

    def flat_nodes(self, names: Sequence[str], extra: Sequence[str] = ()
                   ) -> tuple[list[object], list[tuple[int, int, float | None]]]:
        """The property nodes :meth:`flat_reader` reads, in its order, and its plan."""
        nodes: list[object] = []
        plan: list[tuple[int, int, float | None]] = []
        for name in names:
            props = self._signal_props(name)
            plan.append((len(nodes), len(nodes) + len(props), self._signal_factor(name)))
            nodes.extend(self.node(p) for p in props)
        nodes.extend(self.node(p) for p in extra)
        return nodes, plan

    def command_nodes(self) -> list[object]:
        """The nodes :meth:`command_writer` writes: elevator, aileron, rudder, then every engine's throttle."""
        return ([self.node(p) for p in ("fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm")]
                + [self.node(f"fcs/throttle-cmd-norm[{i}]") for i in range(self.n_engines)])

    def native(self) -> object:
        """The compiled core's access to this model's JSBSim (:func:`fdi_sim.aircraft.native.bind`,
        every assumption checked; raises ``NativeUnavailable`` with the reason). Bound anew at each
        call: a reloaded model has new pointers."""
        from fdi_sim.aircraft.native import bind

        return bind(self.fdm)

    def read(self, names: Sequence[str]) -> NDArray[np.float64]:
        """Read the named signals once (slow path; use :meth:`reader` in loops)."""
        return self.reader(names)()

    def get(self, name: str) -> float:
        """One signal by its suffixed name."""
        return float(self.read([name])[0])

    def command_writer(self) -> Callable[[float, float, float, float], None]:
        """A fast closure ``write(elevator, aileron, rudder, throttle)`` of normalized commands.

        The throttle goes to every engine.
        """
        e = self.node("fcs/elevator-cmd-norm").set_double_value
        a = self.node("fcs/aileron-cmd-norm").set_double_value
        r = self.node("fcs/rudder-cmd-norm").set_double_value
        thr = [self.node(f"fcs/throttle-cmd-norm[{i}]").set_double_value for i in range(self.n_engines)]

        if len(thr) == 1:
            t0 = thr[0]

            def write(el: float, ai: float, ru: float, th: float) -> None:
                e(el); a(ai); r(ru); t0(th)  # noqa: E702
        else:
            def write(el: float, ai: float, ru: float, th: float) -> None:
                e(el); a(ai); r(ru)  # noqa: E702
                for t in thr:
                    t(th)

        return write

    # ------------------------------------------------------------------ fault injection
    def surface(self, target: str) -> SurfaceHandle:
        """A handle that can hold one control surface (``"elevator"``, ``"aileron"``, ``"rudder"``)."""
        specs = surfaces(self.name)
        if target not in specs:
            raise KeyError(f"{self.name} has no surface {target!r}; it has {', '.join(specs)}")
        spec = specs[target]
        return SurfaceHandle(spec, [self.node(p) for p in spec.positions], self.node(spec.healthy))

    def set_engine_cutoff(self, engine: int, cutoff: bool) -> None:
        """Cut the fuel of one engine (flame-out) or restore it and relight at once.

        JSBSim's cutoff acts on ``propulsion/active_engine`` (-1 = all), so one engine is selected
        for the write and the selection restored.
        """
        fdm = self.fdm
        fdm["propulsion/active_engine"] = int(engine)
        fdm["propulsion/cutoff_cmd"] = 1 if cutoff else 0
        if not cutoff:
            fdm["propulsion/starter_cmd"] = 1
            fdm[f"propulsion/engine[{engine}]/set-running"] = 1
        fdm["propulsion/active_engine"] = -1

    def thrust_scaler(self, engine: int) -> Callable[[float], None] | None:
        """A closure ``set(fraction)`` scaling the thrust of one engine, or None if the model has none.

        Direct (jet) thrusters apply ``thrust cos(reverser angle)`` along the engine axis
        (FGThruster), so ``fraction = cos(angle)`` is an exact thrust multiplier. Propellers ignore
        the reverser angle (measured on the DHC-6): None.
        """
        if self.name != "f16":
            return None
        set_angle = self.node(f"propulsion/engine[{engine}]/reverser-angle-rad").set_double_value

        def set_fraction(fraction: float) -> None:
            set_angle(float(np.arccos(min(max(fraction, 0.0), 1.0))))

        return set_fraction

    def _require_icing(self) -> None:
        if not self.icing:
            raise FdiSimError(f"{self.name} was loaded without the icing overlay: use Aircraft({self.name!r}, icing=True)")

    def icing_writer(self) -> Callable[[float], None]:
        """A closure ``set(eta)`` of the icing severity (icing overlay only)."""
        self._require_icing()
        return self.node("icing/eta").set_double_value

    def set_icing_k(self, k: dict[str, float]) -> None:
        """Set the icing factors ``icing/k-<coefficient>`` (e.g. ``{"CmDe": -1.48}``; icing overlay only)."""
        self._require_icing()
        for name, value in k.items():
            self.node(f"icing/k-{name}").set_double_value(float(value))

    # ------------------------------------------------------------------ atmosphere and stepping
    def set_atmosphere(self, atm: Atmosphere, seed: int) -> None:
        """Set steady wind and turbulence; ``seed`` seeds JSBSim's own random generator.

        A trimmed aircraft is first re-initialized in the wind by
        :func:`~fdi_sim.aircraft.wind.hold_trim_in_wind` (switching the wind on alone moves the air
        data by the wind vector). JSBSim generates the MIL-F-8785C turbulence in the axes of the
        mean wind (``FGWinds::Turbulence`` turns it by the azimuth the wind blows toward), so the
        same seed with another wind direction gives the same gusts turned: a run with a wind and
        one without part from the first steps (measured: DHC-6 120 KCAS, moderate, 20 kt from 45 deg:
        1.4 kt apart after 3 steps).
        """
        fdm = self.fdm
        fdm["simulation/randomseed"] = int(seed) % (2**31 - 1)
        poe, w20_kts = TURBULENCE_LEVELS[atm.turbulence]
        fdm["atmosphere/turb-type"] = 3 if poe else 0  # 3 = ttMilspec (Dryden, MIL-F-8785C)
        fdm["atmosphere/turbulence/milspec/severity"] = poe
        fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = w20_kts * FPS_PER_KT
        wn, we, _ = wind_ned_fps(atm.wind_from_deg, atm.wind_speed_kts)
        fdm["atmosphere/wind-north-fps"] = wn
        fdm["atmosphere/wind-east-fps"] = we

    def step(self) -> bool:
        """One JSBSim step of ``dt_s``; False if JSBSim asked to stop."""
        return bool(self.fdm.run())

    def stepper(self) -> Callable[[], object]:
        """:meth:`step` without its Python frame, for the loop: a callable whose result is falsy
        when JSBSim asked to stop (``FGFDMExec.run`` bound; ~0.1 us a step less)."""
        return self.fdm.run

    @property
    def t_s(self) -> float:
        return float(self.fdm.get_sim_time())

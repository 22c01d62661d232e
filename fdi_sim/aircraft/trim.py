"""Trim both aircraft to an operating point (JSBSIM_NOTES sec. 0-2).

* F-16: engines running, gear up, FBW on, JSBSim's full trim (mode 1) or turn trim (mode 5).
* DHC-6: JSBSim's trim misses the propeller reaction torque (``FGTurboProp`` gives 0 HP at
  dt = 0), so it is refined by :func:`trim_running`: Newton's method on the body accelerations
  evaluated with a tiny *real* step, over z = [alpha, phi, throttle, pitch trim, aileron, rudder],
  with beta held at -0.3 deg to keep off the |beta| kink of the DHC-6 ``Clb`` table.

Every trim is checked afterwards: the accelerations of a tiny real step must be small, or a
:class:`~fdi_sim.errors.TrimError` says which point and why.
"""
from __future__ import annotations

import contextlib
import ctypes
import math
import os
import re
import sys
import tempfile
import tomllib
from dataclasses import dataclass

import jsbsim
import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.model import Aircraft
from fdi_sim.data import aircraft_base, aircraft_file
from fdi_sim.errors import TrimError
from fdi_sim.operating_point import OperatingPoint
from fdi_sim.units import G0_FPS2, RAD_PER_DEG

_ACC = (
    "accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2", "accelerations/wdot-ft_sec2",
    "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2",
)
# residual weights: [udot, vdot, wdot] in ft/s^2, [pdot, qdot, rdot] x 100 (JSBSIM_NOTES 2.2)
_ACC_W = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])
#: a trim is accepted when max |weighted acceleration| is below this
TRIM_TOL = 0.05
DHC6_BETA_RAD = -0.3 * RAD_PER_DEG
# running trim: Newton iterations; largest move per iteration [alpha rad, phi rad, throttle, pitch
# trim, aileron, rudder] (2 deg, 0.1); a clipped step moving z by less than _Z_STALL ends the search
_MAX_ITER = 30
_MAX_STEP = np.array([0.035, 0.035, 0.1, 0.1, 0.1, 0.1])
_Z_STALL = 1e-9


@dataclass(frozen=True)
class TrimResult:
    """A trimmed operating point.

    Attributes
    ----------
    op : OperatingPoint
        What was asked for.
    alpha_rad, beta_rad, phi_rad, theta_rad : float
        Trimmed angles [rad].
    vt_fps : float
        True airspeed [ft/s].
    vc_kts : float
        Calibrated airspeed [kt].
    elevator_cmd_norm, aileron_cmd_norm, rudder_cmd_norm, throttle_cmd_norm : float
        Trimmed pilot commands [-] (the autopilot flies deviations about these).
    pitch_trim_cmd_norm : float
        Pitch-trim setting held during the run [-].
    psidot_radps : float
        Turn rate of a steady turn [rad/s] (0 when wings level).
    residual : float
        Max weighted body acceleration after the trim (ft/s^2; rad/s^2 x 100).
    method : str
        ``"jsbsim"`` or ``"running"``.
    """

    op: OperatingPoint
    alpha_rad: float
    beta_rad: float
    phi_rad: float
    theta_rad: float
    vt_fps: float
    vc_kts: float
    elevator_cmd_norm: float
    aileron_cmd_norm: float
    rudder_cmd_norm: float
    throttle_cmd_norm: float
    pitch_trim_cmd_norm: float
    psidot_radps: float
    residual: float
    method: str

    @property
    def u0(self) -> NDArray[np.float64]:
        """Trim commands [elevator, aileron, rudder, throttle] [-]."""
        return np.array([self.elevator_cmd_norm, self.aileron_cmd_norm, self.rudder_cmd_norm, self.throttle_cmd_norm])


def trim(ac: Aircraft, op: OperatingPoint) -> TrimResult:
    """Trim ``ac`` at ``op``; the aircraft is left at the trimmed state, time 0.

    With the icing overlay (``Aircraft(..., icing=True)``) ``icing/eta`` is set to
    ``op.icing_eta`` first and stays at that value.

    Raises
    ------
    TrimError
        The point cannot be trimmed (reason says why: JSBSim's message, a control at its
        limit, the residual reached), or ``op.icing_eta > 0`` on an aircraft loaded without
        the icing overlay.
    """
    point = _point(op)
    if op.aircraft != ac.name:
        raise TrimError(ac.name, point, f"the operating point is for {op.aircraft!r}", f"load Aircraft({op.aircraft!r})")
    if ac.icing:
        ac.icing_writer()(op.icing_eta)  # the iced model trims at the point's eta (0 flies clean)
    elif op.icing_eta:
        raise TrimError(ac.name, point, f"icing_eta = {op.icing_eta:g} needs the icing overlay",
                        f"load Aircraft({ac.name!r}, icing=True)")
    fdm = ac.fdm
    fdm["aero/alpha-min-rad"] = ALPHA_MIN_RAD  # JSBSim searches alpha in [-5, 20] deg by default; flaps need less
    fdm["aero/alpha-max-rad"] = ALPHA_MAX_RAD
    _set_ic(ac, op)
    if ac.name == "f16":
        fdm["gear/gear-cmd-norm"] = 0.0  # the FCS starts with the gear down (CDgear 0.027)
        fdm["gear/gear-pos-norm"] = 0.0
        fdm["fcs/fbw-override"] = 0.0
    else:
        fdm["fcs/flap-cmd-norm"] = op.flaps_deg / 40.0  # DHC-6 flap command: deg / 40
    fdm["propulsion/set-running"] = -1  # start all engines (else no thrust after the trim)
    fdm.set_trim_status(True)
    fdm.run_ic()  # actuators (flaps, gear) jump to their commands while trim status is on
    fdm.set_trim_status(False)
    mode = 5 if (op.phi_deg and ac.name == "f16") else 1
    jsb_error = ""
    # JSBSim's trimmer reports through its logger (jsbsim >= 1.3.3, else C stdout): keep it for the message
    with _captured_stdout() as out, _captured_jsbsim_log() as log:
        level = fdm.get_debug_level()
        if out.active or log.active:
            fdm.set_debug_level(1)  # level 1 reports each axis of a failed trim (FGTrimAxis::AxisReport)
        try:
            fdm["simulation/do_simple_trim"] = mode
        except jsbsim.TrimFailureError as exc:
            jsb_error = str(exc) or "JSBSim trim failed"
        finally:
            fdm.set_debug_level(level)
    report = log.text + out.text
    if ac.name == "f16":
        if jsb_error:
            raise TrimError(ac.name, point, _jsbsim_failure(ac, jsb_error, report),
                            _envelope_fix(ac, op))
        fdm.get_propulsion().get_steady_state()
        res = float(np.max(np.abs(_tiny_step_accelerations(ac))))
        result = _result(ac, op, res, "jsbsim", psidot=_turn_rate_radps(op.phi_deg, ac["velocities/vt-fps"]))
    else:
        fdm.get_propulsion().get_steady_state()  # avoid the N1 -> idle reset on the first step
        result = trim_running(ac, op, jsb_error)
    limit, limit_fix = _at_limit(result)
    if not result.residual < TRIM_TOL:
        # a control at its limit is the likely cause (e.g. the iced DHC-6 at 120 KIAS: throttle 1.0)
        acc = _tiny_step_accelerations(ac) / _ACC_W  # at the best point (the state is left there)
        worst = np.argsort(-np.abs(acc * _ACC_W))[:2]
        left = ", ".join(f"{_ACC_NAMES[i]} = {acc[i]:.3g} {_ACC_UNITS[i]}" for i in worst)
        method = ("the running-engine trim stopped at" if result.method == "running"
                  else "JSBSim's trim passed, but a tiny real step after it shows")
        jsb = f"JSBSim's own trim: {jsb_error}" if jsb_error else "JSBSim's own trim passed"
        if limit:
            why, fix = f"best point: {limit}", limit_fix
        else:
            why = (f"best point (no command at its limit): alpha {math.degrees(result.alpha_rad):.2f} deg, "
                   f"throttle_cmd_norm {result.throttle_cmd_norm:.3f}, elevator_cmd_norm {result.elevator_cmd_norm:.3f}, "
                   f"pitch_trim_cmd_norm {result.pitch_trim_cmd_norm:.3f}")
            fix = _envelope_fix(ac, op)
        raise TrimError(ac.name, point,
                        f"{method} residual {result.residual:.3g} (weighted body accelerations; accepted "
                        f"below {TRIM_TOL}; largest: {left}; {jsb}); {why}", fix)
    if limit:
        raise TrimError(ac.name, point, limit, limit_fix)
    return result


def _envelope_fix(ac: Aircraft, op: OperatingPoint) -> str:
    """What to change when no single command explains a failed trim: the way back into the trim
    envelope of ``aircraft/<name>/grid.toml`` (read here, so the message and the grid agree)."""
    name = ac.name
    try:
        env = tomllib.loads(aircraft_file(name, "grid.toml").read_text(encoding="utf-8")).get("envelope", {})
    except (OSError, ValueError):  # no grid file for this aircraft: a generic fix
        env = {}
    vc_kts, mach = ac.fdm["velocities/vc-kts"], ac.fdm["velocities/mach"]  # at the point asked for (or the best one)
    (vc_lo, vc_hi), (h_lo, h_hi) = env.get("vc_kts", (0.0, math.inf)), env.get("h_ft", (0.0, math.inf))
    mach_hi = env.get("mach", (0.0, 0.0))[1] or math.inf
    flaps = name.startswith("DHC6")
    todo = []
    if vc_kts < vc_lo:
        todo.append(f"fly faster: at least {vc_lo:g} KCAS (initial.vc_kts, or vt_kts)"
                    + (" or add initial.flaps_deg (up to 20)" if flaps else ""))
    if vc_kts > vc_hi or mach > mach_hi:
        todo.append(f"fly slower: at most {vc_hi:g} KCAS" + (f" and Mach {mach_hi:g}" if mach_hi < math.inf else ""))
    if op.h_ft > h_hi:
        todo.append(f"fly lower: initial.h_ft at most {h_hi:g}")
    where = f"aircraft/{aircraft_base(name)}/grid.toml"
    if not env:
        return "try a lower initial.h_ft or another speed (initial.vc_kts / vt_kts)"
    span = f"{vc_lo:g}-{vc_hi:g} KCAS, {h_lo:g}-{h_hi:g} ft" + (f", Mach <= {mach_hi:g}" if mach_hi < math.inf else "")
    if todo:
        return "; ".join(todo) + f" (the trim envelope in {where}: {span}{'' if flaps else '; the F-16 has no pilot flaps'})"
    return (f"the point is inside the trim envelope in {where} ({span}) but does not trim here: try a nearby speed "
            "(initial.vc_kts / vt_kts) or altitude (initial.h_ft)" + (", or initial.flaps_deg" if flaps else ""))


_ACC_NAMES = ("udot", "vdot", "wdot", "pdot", "qdot", "rdot")
_ACC_UNITS = ("ft/s^2", "ft/s^2", "ft/s^2", "rad/s^2", "rad/s^2", "rad/s^2")
#: alpha search range of the trims [rad] (-14.3 to 20.1 deg)
ALPHA_MIN_RAD = -0.25
ALPHA_MAX_RAD = 0.35


def _point(op: OperatingPoint) -> str:
    """The operating point without its aircraft id (the error names the aircraft once)."""
    return op.label().removeprefix(f"{op.aircraft} ")


@dataclass(frozen=True)
class TrimAxisReport:
    """One line of JSBSim's report of a failed trim (``FGTrimAxis::AxisReport``).

    Attributes
    ----------
    control : str
        JSBSim's control name (``"Angle of Attack"``, ``"Throttle"``, ``"Pitch Trim"``).
    control_value : float
        The control's last value [deg for angles, normalized otherwise].
    state : str
        The acceleration it trims (``"udot"``, ``"wdot"``, ``"qdot"``, ...).
    state_value : float
        That acceleration [ft/s^2 for udot/vdot/wdot, rad/s^2 for pdot/qdot/rdot].
    tolerance : float
        JSBSim's tolerance on it [same unit].
    passed : bool
        Whether JSBSim counted the axis as trimmed.
    """

    control: str
    control_value: float
    state: str
    state_value: float
    tolerance: float
    passed: bool


_AXIS_LINE = re.compile(
    r"^\s*(?P<control>[A-Za-z][A-Za-z ]*?)\s*:\s*(?P<cval>\S+)\s+(?P<state>[a-z]+)\s*:\s*(?P<sval>\S+)"
    r"\s+Tolerance:\s*(?P<tol>\S+)\s+(?P<status>Passed|Failed)\s*$", re.MULTILINE)


def parse_trim_report(text: str) -> tuple[TrimAxisReport, ...]:
    """The axis lines of JSBSim's trim report (empty when it printed none, e.g. another JSBSim version)."""
    out = []
    for m in _AXIS_LINE.finditer(text):
        try:
            out.append(TrimAxisReport(m["control"], float(m["cval"]), m["state"], float(m["sval"]), float(m["tol"]),
                                      m["status"] == "Passed"))
        except ValueError:  # a value JSBSim printed as nan or garbled: skip the line, keep the others
            continue
    return tuple(out)


def _jsbsim_failure(ac: Aircraft, jsb_error: str, report: str) -> str:
    """Why JSBSim's trim failed: the axes it did not trim (from its ``report``), and the flight condition."""
    fdm = ac.fdm
    axes = parse_trim_report(report)
    cond = (f"the point is VC {fdm['velocities/vc-kts']:.0f} kt, Mach {fdm['velocities/mach']:.2f}, "
            f"dynamic pressure {fdm['aero/qbar-psf']:.0f} psf")
    failed = [a for a in axes if not a.passed]
    if not failed:
        return f"JSBSim's trim reported {jsb_error!r} (no axis report); {cond}"
    unit = {"udot": "ft/s^2", "vdot": "ft/s^2", "wdot": "ft/s^2"}
    parts = "; ".join(
        f"{a.state} = {a.state_value:.3g} {unit.get(a.state, 'rad/s^2')} (tolerance {a.tolerance:g}) with "
        f"{a.control.lower()} {a.control_value:g}{' deg' if a.control in _ANGLE_CONTROLS else ''}" for a in failed)
    hint = "".join(f"; {_AXIS_HINTS[a.state]}" for a in failed[:1] if a.state in _AXIS_HINTS)
    # e.g. "Sorry, wdot doesn't appear to be trimmable": the axis with no sign change over its control range
    sorry = "".join(f" ({ln.strip()})" for ln in report.splitlines() if ln.strip().startswith("Sorry,"))
    return f"JSBSim's trim reported {jsb_error!r}{sorry}: not trimmed: {parts} (its last iterate){hint}; {cond}"


_ANGLE_CONTROLS = {"Angle of Attack", "Roll Angle", "Beta", "Flight Path Angle", "Heading", "Theta"}
_AXIS_HINTS = {
    "wdot": "the wing cannot carry the weight within the alpha range (too slow or too high)",
    "udot": "thrust and drag do not balance (too fast, too slow or too high for the engine)",
    "qdot": "the pitch trim cannot balance the pitching moment",
}


def _flush_c_stdout() -> None:
    """``fflush(NULL)``: JSBSim writes through C stdio, whose buffer Python's ``sys.stdout.flush`` does not touch."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library to load by name (Windows): unbuffered enough there
        pass


class _LogCollector(getattr(jsbsim, "FGLogger", object)):  # type: ignore[misc]
    """A JSBSim logger that keeps the text of every record."""

    def __init__(self) -> None:
        super().__init__()
        self.parts: list[str] = []

    def message(self, message: str) -> None:
        self.parts.append(message)


@contextlib.contextmanager
def _captured_jsbsim_log():
    """Route JSBSim's log (this thread) to a collector for the duration; the text is in ``.text`` after."""
    cap = _Captured()
    if not hasattr(jsbsim, "set_logger"):  # older wheels print to C stdout: _captured_stdout has it
        yield cap
        return
    previous = jsbsim.get_logger()
    collector = _LogCollector()
    jsbsim.set_logger(collector)
    cap.active = True
    try:
        yield cap
    finally:
        jsbsim.set_logger(previous)
        cap.text = "".join(collector.parts)


class _Captured:
    """What :func:`_captured_stdout` caught: ``active`` when fd 1 was redirected, then ``text``."""

    def __init__(self) -> None:
        self.active = False
        self.text = ""


@contextlib.contextmanager
def _captured_stdout():
    """Capture C-level stdout (file descriptor 1) for the duration; the text is in ``.text`` after."""
    cap = _Captured()
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):  # no real fd 1 (e.g. captured in a notebook): leave it
        yield cap
        return
    with tempfile.TemporaryFile() as buf:
        try:
            os.dup2(buf.fileno(), 1)
            cap.active = True
            yield cap
        finally:
            _flush_c_stdout()  # stdout to a file or pipe is block-buffered in libc: empty it into buf, not later
            os.dup2(saved, 1)
            os.close(saved)
            buf.seek(0)
            cap.text = buf.read(1 << 20).decode("utf-8", errors="replace")  # the report is a few hundred bytes


def _set_ic(ac: Aircraft, op: OperatingPoint) -> None:
    fdm = ac.fdm
    fdm["ic/h-sl-ft"] = op.h_ft
    if op.vt_kts is not None:
        fdm["ic/vt-kts"] = op.vt_kts
    else:
        fdm["ic/vc-kts"] = op.vc_kts
    fdm["ic/gamma-deg"] = op.gamma_deg
    fdm["ic/phi-deg"] = op.phi_deg
    fdm["ic/psi-true-deg"] = op.psi_deg
    fdm["ic/beta-deg"] = 0.0


def _turn_rate_radps(phi_deg: float, vt_fps: float) -> float:
    """Coordinated turn: psidot = g tan(phi) / V [rad/s]."""
    return G0_FPS2 * math.tan(phi_deg * RAD_PER_DEG) / max(vt_fps, 1.0)


def _tiny_step_accelerations(ac: Aircraft) -> NDArray[np.float64]:
    """Weighted body accelerations of a 1e-6 s real step from the current state.

    At dt = 0 the turboprop gives no power (JSBSIM_NOTES sec. 0); a tiny real step includes the
    engine torque while integrating a negligible amount.
    """
    fdm = ac.fdm
    dt0 = fdm.get_delta_t()
    fdm.set_dt(1e-6)
    fdm.run()
    fdm.set_dt(dt0)
    return np.array([fdm[p] for p in _ACC]) * _ACC_W


# ---------------------------------------------------------------------- running-engine trim (DHC-6)
def _init_state(ac: Aircraft, st: dict[str, float], z: NDArray[np.float64]) -> None:
    fdm = ac.fdm
    alpha, phi, thr, ptrim, ail, rud = z
    fdm["ic/h-sl-ft"] = st["h_ft"]
    fdm["ic/vt-fps"] = st["vt_fps"]
    fdm["ic/psi-true-rad"] = st["psi_rad"]
    fdm["ic/phi-rad"] = phi
    fdm["ic/gamma-rad"] = st["gamma_rad"]
    fdm["ic/alpha-rad"] = alpha
    fdm["ic/beta-rad"] = st["beta_rad"]
    psidot = st["psidot_radps"]
    theta = fdm["ic/theta-rad"]
    # steady coordinated turn: body rates from the Euler rate psidot
    fdm["ic/p-rad_sec"] = -psidot * math.sin(theta)
    fdm["ic/q-rad_sec"] = psidot * math.sin(phi) * math.cos(theta)
    fdm["ic/r-rad_sec"] = psidot * math.cos(phi) * math.cos(theta)
    for i in range(ac.n_engines):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = thr
    fdm["fcs/pitch-trim-cmd-norm"] = ptrim
    fdm["fcs/elevator-cmd-norm"] = 0.0
    fdm["fcs/aileron-cmd-norm"] = ail
    fdm["fcs/rudder-cmd-norm"] = rud
    fdm.set_trim_status(True)
    fdm.run_ic()  # actuators jump to their commands
    fdm.set_trim_status(False)
    fdm.get_propulsion().get_steady_state()  # engine and propeller at steady state, phase tpRun


def _running_residual(ac: Aircraft, st: dict[str, float], z: NDArray[np.float64]) -> NDArray[np.float64]:
    _init_state(ac, st, z)
    return _tiny_step_accelerations(ac)


def trim_running(ac: Aircraft, op: OperatingPoint, jsb_error: str = "") -> TrimResult:
    """Running-engine trim of the DHC-6 (JSBSIM_NOTES sec. 2.2): Newton with a central-difference Jacobian.

    Starts from JSBSim's trim when it succeeded, else from a generic guess.
    """
    fdm = ac.fdm
    if op.vt_kts is None:
        fdm["ic/vc-kts"] = op.vc_kts  # JSBSim converts calibrated to true airspeed at this altitude
        vt_fps = fdm["ic/vt-fps"]
    else:
        vt_fps = op.speed_fps
    psidot = _turn_rate_radps(op.phi_deg, vt_fps)
    st = {
        "h_ft": op.h_ft, "vt_fps": vt_fps, "psi_rad": op.psi_deg * RAD_PER_DEG,
        "gamma_rad": op.gamma_deg * RAD_PER_DEG, "beta_rad": DHC6_BETA_RAD, "psidot_radps": psidot,
    }
    if jsb_error:
        z = np.array([0.0, op.phi_deg * RAD_PER_DEG, 0.7, 0.2, 0.0, -0.08])
    else:
        z = np.array([
            fdm["aero/alpha-rad"], op.phi_deg * RAD_PER_DEG, fdm["fcs/throttle-cmd-norm[0]"],
            fdm["fcs/pitch-trim-cmd-norm"], fdm["fcs/aileron-cmd-norm"], fdm["fcs/rudder-cmd-norm"],
        ])
    h = np.array([1e-4, 1e-4, 1e-3, 1e-3, 1e-3, 1e-3])
    lo = np.array([ALPHA_MIN_RAD, -1.2, 0.0, -1.0, -1.0, -1.0])
    hi = np.array([ALPHA_MAX_RAD, 1.2, 1.0, 1.0, 1.0, 1.0])
    best = (np.inf, z.copy())
    for _ in range(_MAX_ITER):
        r = _running_residual(ac, st, z)
        nr = float(np.max(np.abs(r)))
        if nr < best[0]:
            best = (nr, z.copy())
        if nr < 1e-4:
            break
        J = np.empty((6, 6))
        for j in range(6):
            dz = np.zeros(6)
            dz[j] = h[j]
            J[:, j] = (_running_residual(ac, st, z + dz) - _running_residual(ac, st, z - dz)) / (2 * h[j])
        step, *_ = np.linalg.lstsq(J, -r, rcond=None)
        # damped step: never move alpha/phi by more than 2 deg, controls by 0.1 per iteration
        scale = min(1.0, float(np.min(_MAX_STEP / (np.abs(step) + 1e-12))))
        z_new = np.clip(z + scale * step, lo, hi)
        if float(np.max(np.abs(z_new - z))) < _Z_STALL:
            break  # a fixed point (typically a control clipped at its stop): later iterations repeat this residual
        z = z_new
    res, z = best
    _init_state(ac, st, z)
    return _result(ac, op, res, "running", psidot=psidot)


def _result(ac: Aircraft, op: OperatingPoint, res: float, method: str, psidot: float) -> TrimResult:
    fdm = ac.fdm
    return TrimResult(
        op=op,
        alpha_rad=fdm["aero/alpha-rad"], beta_rad=fdm["aero/beta-rad"], phi_rad=fdm["attitude/phi-rad"],
        theta_rad=fdm["attitude/theta-rad"], vt_fps=fdm["velocities/vt-fps"], vc_kts=fdm["velocities/vc-kts"],
        elevator_cmd_norm=fdm["fcs/elevator-cmd-norm"], aileron_cmd_norm=fdm["fcs/aileron-cmd-norm"],
        rudder_cmd_norm=fdm["fcs/rudder-cmd-norm"], throttle_cmd_norm=fdm["fcs/throttle-cmd-norm[0]"],
        pitch_trim_cmd_norm=fdm["fcs/pitch-trim-cmd-norm"], psidot_radps=psidot, residual=res, method=method,
    )


#: F-16 throttle command above which the F100 is in afterburner [-] (not a cruise trim)
F16_AFTERBURNER_THROTTLE_NORM = 0.5
#: a command this close to a stop counts as at it [-]
_AT_STOP = 1e-3
_SLOWER_OR_LOWER = "fly slower (initial.vc_kts / vt_kts) or lower (initial.h_ft)"
_BANK = "a smaller bank (initial.phi_deg) or a higher speed"
_PITCH = "change the speed (initial.vc_kts / vt_kts), or initial.flaps_deg on the DHC-6"
#: command -> (range [-], what the upper stop means, what the lower stop means, fix at the upper, fix at the lower)
_STOPS: dict[str, tuple[tuple[float, float], str, str, str, str]] = {
    "throttle_cmd_norm": ((0.0, 1.0), "full throttle is not enough thrust", "idle is still too much thrust",
                          _SLOWER_OR_LOWER, "a climb (initial.gamma_deg > 0) or a higher speed"),
    "pitch_trim_cmd_norm": ((-1.0, 1.0), "the pitch trim cannot balance the pitching moment",
                            "the pitch trim cannot balance the pitching moment", _PITCH, _PITCH),
    "aileron_cmd_norm": ((-1.0, 1.0), "the ailerons cannot hold the bank", "the ailerons cannot hold the bank",
                         _BANK, _BANK),
    "rudder_cmd_norm": ((-1.0, 1.0), "the rudder cannot hold the sideslip", "the rudder cannot hold the sideslip",
                        _BANK, _BANK),
}


def _at_limit(t: TrimResult) -> tuple[str, str]:
    """``(problem, fix)`` for the first command at a stop of its range, or ``("", "")``.

    The F-16's throttle is also refused above :data:`F16_AFTERBURNER_THROTTLE_NORM`: that is not
    a stop of the command (its range is [0, 1]) but the afterburner detent, and is said so.
    """
    for name, ((lo, hi), up, down, fix_up, fix_down) in _STOPS.items():
        v = getattr(t, name)
        if v >= hi - _AT_STOP:
            return f"{name} = {v:.3f} at its limit (the upper stop of its range [{lo:g}, {hi:g}]: {up})", fix_up
        if v <= lo + _AT_STOP:
            return f"{name} = {v:.3f} at its limit (the lower stop of its range [{lo:g}, {hi:g}]: {down})", fix_down
    if t.op.aircraft == "f16" and t.throttle_cmd_norm > F16_AFTERBURNER_THROTTLE_NORM + _AT_STOP:
        return (f"throttle_cmd_norm = {t.throttle_cmd_norm:.3f} is above {F16_AFTERBURNER_THROTTLE_NORM:g}, the "
                "afterburner detent (range [0, 1]): the point needs afterburner thrust, which is not a cruise trim",
                "fly slower (initial.vt_kts / vc_kts) or higher (initial.h_ft); aircraft/f16/grid.toml gives the trim envelope")
    return "", ""

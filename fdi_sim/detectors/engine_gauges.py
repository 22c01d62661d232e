"""Engine-gauge consistency of a twin: each engine's gauges against the other engine's.

Both engines of a twin get the same power-lever command (the autopilot moves both levers
together) and fly in the same air, so their gas-generator speed Ng, shaft torque and propeller
speed Np differ mostly by the gauges' turn-on offsets and noise. Measured on six fault-free 300 s
DHC-6 development flights (seeds 900-905: 2,500-7,500 ft, 97-133 KCAS, light to severe
turbulence, wind 0-20 kt), the differences' per-sample standard deviations were 0.081-0.092 % Ng,
16.9-17.6 lbf ft and 4.7-5.1 rpm, against the sensors' own ``sqrt(2 (noise^2 + quantum^2 / 12))``
of 0.082 %, 17.0 lbf ft and 4.7 rpm. An engine fault (a flameout, a thrust loss) moves one
engine's gauges and not the other's: the shipped DHC-6 flameout drops the left torque by
1,040 lbf ft and its Ng by 0.8 % within 0.05 s (z 30 at the first sample, 120 after 0.2 s).

Two physical differences are not faults (development study seed 15102: 180 fault-free 600 s
flights, 29.8 h, 2-8 kft, 95-135 KCAS, no to severe turbulence, reflown with full logs; the
engines' truth gauges, 0.2 s means as the check takes them):

- **The torque limiter.** The model's IELU (:data:`TORQUE_LIMITS_FTLB`) acts on each engine by
  itself: above 1,629.3 lbf ft with its lever not moving back, it pulls that engine's throttle
  down, then holds it below the lever until the lever comes back below it. In a yaw the engines'
  torques differ by a few lbf ft, so one engine latches and the other does not. Within 5 s of
  either measured torque coming within ``limiter_margin_ftlb`` of the limit (42 % of the flight
  time there, near full power), the engines differed by up to 2.97 % Ng and 322 lbf ft (73 and 38
  times the 0.2 s mean's noise); 5 s or more after it, by 0.053 % Ng and 30 lbf ft (1.3 and 3.5
  times), 10 s or more after it, by 0.042 % and 16 lbf ft. The check cannot know the limiter's
  latch (it turns on a difference below the gauges' noise), so within ``limiter_hold_s`` of a
  near-limit torque it allows ``limiter_allowance`` (1.5 x the largest difference above) before it
  counts a difference: a flameout (1,000 lbf ft or more) or a lever loss of 20 % or more at full
  power (8 % Ng) still exceeds it by far, a gauge bias below it is seen only away from the limit.
- **The propellers' speed.** The governors hold Np; in a yaw the propellers' inflows differ and
  the difference follows the yaw rate (its 1 s lag explains a third of it: 66 rpm per rad/s), up
  to 26 rpm anywhere in the envelope (11 times the noise). Np is therefore not tested: its
  normalized difference is logged (``z_prop``), and the check names no Np gauge (a fault on one is
  "not monitored" by this member). A thrust fault shows in Ng and torque first.

The check, per detector sample ``j`` and tested gauge ``g`` (Ng, torque)::

    d_g(j)  = x_g,0(j) - x_g,1(j)                         engine 0 minus engine 1
    b_g     = mean of d_g over the first n_warm valid samples      (turn-on offsets)
    m_g(j)  = mean of d_g over the last n_avg samples
    z_g(j)  = (m_g(j) - b_g) / (s_g / sqrt(n_avg))        ~ N(0, 1) without a fault
    a_g(j)  = A_g / (s_g / sqrt(n_avg)) within n_hold samples of a torque above
              limit - margin (either engine, or a torque gauge not ok), else 0
    e_g(j)  = sign(z_g) max(0, |z_g| - a_g)               the difference the limiter cannot explain
    stat(j) = max_g |e_g(j)|

``s_g`` is the difference's per-sample standard deviation from the sensor suite (above). A gauge
pair with a sample not ``ok`` (a dropout, a gauge excluded) in its window is left out of the
maximum; with none left the sample is invalid. ``b_g`` is learned once per flight (a fault
before the warm-up ends is absorbed into it: the check is blind to it).

Isolation, where ``stat > threshold``:

- **engine**: both tested gauges with ``|z_g| > ISOLATION_Z`` (before the allowance: a lever loss
  near the limit can leave the torque inside it) and the sign of the largest ``e_g``: the engine
  whose gauges read low is named (``engine_0`` for ``e < 0``). A thrust fault lowers the failed
  engine's gauges (flameout, thrust loss); the check has no hypothesis for an engine that runs
  high.
- **gauge**: one gauge alone: the gauge of the engine whose reading moved further from its own
  warm-up mean (``n1_0_pct`` ...). This is a guess where the power changed since the warm-up by
  more than the fault (a common-mode change larger than the fault can name the other engine's
  gauge); nothing else tells the two gauges of a pair apart without an engine model.

Input: absolute measurements in :data:`GAUGES` order (``n1_0_pct``, ``n1_1_pct``,
``torque_0_ftlb``, ``torque_1_ftlb``, ``prop_0_rpm``, ``prop_1_rpm``), their ``ok`` flags; no
command. The kernel is compiled (numba) and block invariant: a ring buffer of the last
``n_avg`` differences, the warm-up sums and the samples since a near-limit torque carry across
blocks.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.errors import DesignError
from fdi_sim.registry import register

__all__ = ["DETECTOR_ID", "GAUGES", "GAUGE_KINDS", "HYPOTHESES", "ISOLATION_Z", "LIMITER_ALLOWANCE", "TESTED",
           "TORQUE_LIMITS_FTLB", "EngineGaugeDesign", "EngineGaugeStream", "design_engine_gauges", "make_engine_gauges",
           "torque_limit_ftlb"]

DETECTOR_ID = "engine-gauges-v1"
#: the gauges per engine (``aircraft/<aircraft>/sensors.toml`` names with ``{i}`` the engine index)
GAUGE_KINDS: tuple[str, ...] = ("n1_{i}_pct", "torque_{i}_ftlb", "prop_{i}_rpm")
#: the measurements read, in column order: per gauge kind, engine 0 then engine 1
GAUGES: tuple[str, ...] = tuple(k.format(i=i) for k in GAUGE_KINDS for i in (0, 1))
#: the gauge kinds tested (Ng, torque); Np is logged only (module docstring)
TESTED = 2
#: the faults it names: the two engines, then each tested gauge (``BlockOutputs.hypothesis`` indexes it)
HYPOTHESES: tuple[str, ...] = ("engine_0", "engine_1") + GAUGES[:2 * TESTED]
#: a gauge takes part in the engine vote above this ``|z|`` [-] (3 sigma: a fault-free gauge
#: crosses it in 0.27 % of samples, so a one-gauge fault is rarely called an engine)
ISOLATION_Z = 3.0
#: the difference the torque limiter may make near its limit, per tested gauge kind [% Ng, lbf ft]:
#: 1.5 x the largest on the development study (seed 15102, module docstring: 2.97 % and 322 lbf ft)
LIMITER_ALLOWANCE: tuple[float, float] = (4.5, 500.0)
#: bumped when the kernel computes different numbers from the same design (in design_key)
KERNEL_VERSION = "engine-gauges-kernel-3"  # the tail form is in design_key too


#: the engines' torque limiter per aircraft [lbf ft]: the JSBSim engine file's ``<ielumaxtorque>``
#: (the DHC-6's Engines/PT6A-27.xml; tests/aircraft/test_engine_limits.py checks it against the model).
#: FGTurboProp's IELU acts on each engine by itself: while an engine's torque is above it and its lever
#: is not moving back, it pulls that engine's throttle down at 0.1 per s, then holds it, creeping up at
#: 0.05 per s, until the lever comes back below it (src/models/propulsion/FGTurboProp.cpp, Calculate)
TORQUE_LIMITS_FTLB: dict[str, float] = {"DHC6": 1629.3}


def torque_limit_ftlb(aircraft: str) -> float:
    """The engines' torque limiter [lbf ft] (:data:`TORQUE_LIMITS_FTLB`; ``"DHC6..."`` variants share
    the DHC-6's engines); ``inf`` for an aircraft without one."""
    from fdi_sim.data import aircraft_base

    return TORQUE_LIMITS_FTLB.get(aircraft_base(aircraft), math.inf)


@dataclass(frozen=True)
class EngineGaugeDesign:
    """The numbers the check runs on.

    Attributes
    ----------
    aircraft : str
        The aircraft whose sensor suite gave ``scales``.
    scales : tuple of float
        Per gauge kind, the per-sample standard deviation of the engines' difference
        [% Ng, lbf ft, rpm].
    rate_hz : float
        Detector rate [Hz].
    average_s : float
        Moving-mean window [s].
    warmup_s : float
        Warm-up over which the offsets ``b_g`` are averaged [s].
    threshold : float
        Alarm threshold on ``max |e_g|`` [-] (the bank sets it from its far_per_h rule).
    torque_limit_ftlb : float
        The engines' torque limiter [lbf ft] (``inf``: none).
    limiter_margin_ftlb : float
        A measured torque this close to the limit opens the limiter's window [lbf ft] (40: 3.3 x
        one torque gauge's noise).
    limiter_hold_s : float
        The window lasts this long after the last near-limit torque [s].
    limiter_allowance : tuple of float
        The difference allowed within the window, per tested gauge kind [% Ng, lbf ft].
    """

    aircraft: str
    scales: tuple[float, float, float]
    rate_hz: float = 20.0
    average_s: float = 0.2
    warmup_s: float = 5.0
    threshold: float = 6.0
    torque_limit_ftlb: float = math.inf
    limiter_margin_ftlb: float = 40.0
    limiter_hold_s: float = 5.0
    limiter_allowance: tuple[float, float] = LIMITER_ALLOWANCE

    @property
    def n_avg(self) -> int:
        """Samples in the moving mean."""
        return max(1, int(round(self.average_s * self.rate_hz)))

    @property
    def n_warm(self) -> int:
        """Samples in the warm-up mean."""
        return max(1, int(round(self.warmup_s * self.rate_hz)))

    @property
    def n_hold(self) -> int:
        """Samples the limiter's window lasts after the last near-limit torque."""
        return max(1, round(self.limiter_hold_s * self.rate_hz))


def design_engine_gauges(aircraft: str, *, rate_hz: float = 20.0, average_s: float = 0.2, warmup_s: float = 5.0,
                         threshold: float = 6.0, suite: str = "default", limiter_margin_ftlb: float = 40.0,
                         limiter_hold_s: float = 5.0) -> EngineGaugeDesign:
    """The design for an aircraft with two engines, the scales from its sensor suite and its engines'
    torque limit (:func:`torque_limit_ftlb`).

    Raises
    ------
    DesignError
        The suite has no pair of every gauge (one engine, or gauges not measured), or an option is
        out of range.
    """
    from fdi_sim.sensors.suite import load_suite

    specs = {s.name: s for s in load_suite(aircraft, suite)}
    missing = [g for g in GAUGES if g not in specs]
    if missing:
        raise DesignError(f"{DETECTOR_ID} compares two engines' gauges; the {aircraft} sensor suite {suite!r} has no "
                          f"{', '.join(missing)} (a single-engine aircraft, or engine gauges not measured)")
    for nm, v in (("rate_hz", rate_hz), ("average_s", average_s), ("warmup_s", warmup_s), ("threshold", threshold),
                  ("limiter_margin_ftlb", limiter_margin_ftlb), ("limiter_hold_s", limiter_hold_s)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise DesignError(f"{DETECTOR_ID}: {nm} must be a positive number, got {v!r}")
    scales = []
    for kind in GAUGE_KINDS:
        var = 0.0
        for i in (0, 1):  # the difference of two independent gauges: the variances add
            s = specs[kind.format(i=i)]
            var += s.noise_std ** 2 + s.quantum ** 2 / 12.0  # white noise plus uniform rounding
        scales.append(math.sqrt(var))
    return EngineGaugeDesign(aircraft, (scales[0], scales[1], scales[2]), float(rate_hz), float(average_s),
                             float(warmup_s), float(threshold), torque_limit_ftlb(aircraft), float(limiter_margin_ftlb),
                             float(limiter_hold_s))


# --- the kernel ------------------------------------------------------------------------------------------
# int state: samples seen, ring position, per gauge kind the warm-up count, samples since the last
# near-limit torque
_S_K, _S_POS, _S_WARM, _S_SINCE = 0, 1, 2, 5
# float state per gauge g (3 gauges): the warm-up sums of engine 0 and engine 1 (the offset b_g is
# their means' difference)
_F_BASE0, _F_BASE1 = 0, 3


@numba.njit(cache=True, error_model="numpy")
def _kernel(y, ok, out_z, out_valid, out_hyp, out_r, thr, scales, n_avg, n_warm, iso_z, tq_open, n_hold, allow,
            ist, fs, ring, ring_ok):  # pragma: no cover (compiled)
    n = y.shape[0]
    if ok.shape[0] != n or y.shape[1] != 6 or ok.shape[1] != 6 or out_z.shape[0] != n or out_r.shape[1] != 3:
        raise ValueError("EngineGaugeStream.process: y, ok (N, 6), out_* (N,) and out_residual (N, 3) must agree")
    sq = math.sqrt(n_avg)
    has_limiter = tq_open < math.inf
    for j in range(n):
        pos = ist[_S_POS]
        for g in range(3):
            a, b = y[j, 2 * g], y[j, 2 * g + 1]
            good = ok[j, 2 * g] and ok[j, 2 * g + 1] and math.isfinite(a) and math.isfinite(b)
            ring_ok[pos, g] = good
            ring[pos, g] = a - b if good else 0.0  # an invalid value never enters arithmetic
            if good and ist[_S_WARM + g] < n_warm:
                fs[_F_BASE0 + g] += a
                fs[_F_BASE1 + g] += b
                ist[_S_WARM + g] += 1
        # the limiter's window: a torque near the limit, or one the check cannot read (it might be);
        # never without a limiter (tq_open inf: has_limiter, set once above the loop)
        near = False
        for e in range(2 if has_limiter else 0):
            v = y[j, 2 + e]
            if not (ok[j, 2 + e] and math.isfinite(v)) or v > tq_open:
                near = True
        if near:
            ist[_S_SINCE] = 0
        elif ist[_S_SINCE] < n_hold:
            ist[_S_SINCE] += 1
        limited = ist[_S_SINCE] < n_hold
        ist[_S_POS] = (pos + 1) % n_avg
        ist[_S_K] += 1
        best, arg = -1.0, -1
        raw0, raw1 = math.nan, math.nan  # z_g before the allowance (Ng, torque): the isolation's vote
        for g in range(3):
            usable = ist[_S_WARM + g] >= n_warm and ist[_S_K] >= n_avg
            if usable:
                for r in range(n_avg):
                    if not ring_ok[r, g]:
                        usable = False
            if not usable:
                out_r[j, g] = math.nan
                continue
            m = 0.0
            for r in range(n_avg):  # oldest first: the same sum whatever the blocks
                m += ring[(ist[_S_POS] + r) % n_avg, g]
            m = m / n_avg
            z = (m - (fs[_F_BASE0 + g] - fs[_F_BASE1 + g]) / n_warm) / (scales[g] / sq)
            if g == 0:
                raw0 = z
            elif g == 1:
                raw1 = z
            if g < 2 and limited:  # e_g = sign(z) max(0, |z| - a_g)
                a_g = allow[g] / (scales[g] / sq)
                z = 0.0 if abs(z) <= a_g else (z - a_g if z > 0.0 else z + a_g)
            out_r[j, g] = z
            if g < 2 and abs(z) > best:  # Np (g = 2) is logged, not tested
                best, arg = abs(z), g
        out_valid[j] = arg >= 0
        out_z[j] = best if arg >= 0 else math.nan
        out_hyp[j] = -1
        if arg >= 0 and best > thr:
            zmax = out_r[j, arg]
            same = 0
            for z in (raw0, raw1):  # both gauges moved the same way: before the allowance (which is
                # for detection: a lever loss near the limit can leave the torque inside it)
                if z == z and abs(z) > iso_z and (z > 0.0) == (zmax > 0.0):
                    same += 1
            if same >= 2:
                out_hyp[j] = 0 if zmax < 0.0 else 1  # the engine whose gauges read low
            else:  # one gauge: the engine whose reading left its own warm-up mean further
                d0 = abs(y[j, 2 * arg] - fs[_F_BASE0 + arg] / n_warm)
                d1 = abs(y[j, 2 * arg + 1] - fs[_F_BASE1 + arg] / n_warm)
                out_hyp[j] = 2 + 2 * arg + (0 if d0 >= d1 else 1)


class EngineGaugeStream:
    """The engine-gauge check as a bank member (:class:`fdi_sim.detectors.stream.StreamingDetector`).

    Parameters
    ----------
    design : EngineGaugeDesign
        The numbers it runs on.
    id : str
        Its id in the bank.
    """

    #: the gauges only: no command
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = GAUGES
    hypotheses: tuple[str, ...] = HYPOTHESES
    #: the normalized differences beyond the limiter's allowance ``e_g`` (Ng, torque) and Np's
    #: ``z`` (logged, not tested) [-]
    residual_names: tuple[str, ...] = ("z_n1", "z_torque", "z_prop")
    #: nothing a failed gauge could be replaced by (no engine model)
    estimate_names: tuple[str, ...] = ()
    fault_directions = False
    #: the engines' gauges against each other, no model: its isolation may stand alone
    independent = True
    #: the statistic's tail form for the threshold (fdi_sim.decision.tail.episode_threshold):
    #: exponential in x, light-tailed. Gaussian gauge noise alone would be exponential in x^2 (Rice),
    #: but the engines also differ physically (module docstring); with the x^2 form the DHC-6
    #: atlas's thresholds came out below the 2 h training maxima, with the heavier tail allowed the
    #: first calm-air calibration's 95 % bound came out at 1.4e9 (point estimate 4.63). Before the
    #: limiter's window and Np's exclusion, neither form held on the envelope development study
    #: (seed 15102: 11 episodes in 29.6 h, statistic up to 9.3)
    tail_power = 1.0
    tail_heavy = False

    def __init__(self, design: EngineGaugeDesign, id: str = DETECTOR_ID) -> None:
        self.design = design
        self.id = id
        self.threshold = float(design.threshold)
        self._scales = np.array(design.scales, dtype=np.float64)
        self._allow = np.array(design.limiter_allowance, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        """No warm-up, an empty window."""
        n = self.design.n_avg
        self._ist = np.zeros(6, dtype=np.int64)
        self._ist[_S_SINCE] = self.design.n_hold  # no limiter seen yet
        self._fs = np.zeros(6, dtype=np.float64)
        self._ring = np.zeros((n, 3), dtype=np.float64)
        self._ring_ok = np.zeros((n, 3), dtype=np.bool_)

    @property
    def samples_seen(self) -> int:
        """Rows processed since the last :meth:`reset`."""
        return int(self._ist[_S_K])

    def set_threshold(self, value: float) -> None:
        """The alarm threshold [-] (``inf`` accepted)."""
        self.threshold = float(value)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """No operating point: a reset."""
        self.reset()

    def design_key(self) -> bytes:
        """The design, the kernel's version and the tail form (the thresholds' cache keys hold the
        design key, not the tail flags)."""
        return f"{KERNEL_VERSION} {self.design!r} tail {self.tail_power} heavy {self.tail_heavy}".encode()

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """``N`` samples into ``out`` (the streaming contract; ``t_s``, ``u``, ``fresh`` unused: the
        gauges sample at the detector rate)."""
        d = self.design
        _kernel(y, ok, out.statistic, out.valid, out.hypothesis, out.residual, self.threshold, self._scales,
                d.n_avg, d.n_warm, ISOLATION_Z, d.torque_limit_ftlb - d.limiter_margin_ftlb, d.n_hold, self._allow,
                self._ist, self._fs, self._ring, self._ring_ok)
        out.threshold[:] = self.threshold


def make_engine_gauges(model: Any = None, aircraft: str | None = None, rate_hz: float | None = None,
                       average_s: float = 0.2, warmup_s: float = 5.0, threshold: float = 6.0,
                       suite: str = "default", limiter_margin_ftlb: float = 40.0,
                       limiter_hold_s: float = 5.0) -> EngineGaugeStream:
    """The registered factory: ``aircraft`` (or ``model.meta["aircraft"]``) and the options of
    :func:`design_engine_gauges` (``rate_hz`` [Hz] defaults to the model's, else 20)."""
    names = tuple(getattr(model, "output_names", ()) or ())
    if model is not None and not set(GAUGES) <= set(names):  # a linearizer's model: no engine gauges
        raise DesignError(f"{DETECTOR_ID} needs the measurements {', '.join(g for g in GAUGES if g not in names)}, "
                          "which the model does not output (build it from the log's measurements: the bank and "
                          "`fdi-sim detect` do)")
    ac = aircraft or (getattr(model, "meta", None) or {}).get("aircraft")
    if not ac:
        raise DesignError(f"{DETECTOR_ID} needs the aircraft (aircraft = \"DHC6\", or a model that names it)")
    if rate_hz is None:
        rate_hz = 1.0 / float(model.dt_s) if getattr(model, "is_discrete", False) else 20.0
    return EngineGaugeStream(design_engine_gauges(str(ac), rate_hz=rate_hz, average_s=average_s, warmup_s=warmup_s,
                                                  threshold=threshold, suite=suite,
                                                  limiter_margin_ftlb=limiter_margin_ftlb,
                                                  limiter_hold_s=limiter_hold_s))


register("detector", DETECTOR_ID, "twin engines' Ng and torque against each other, the torque limiter allowed "
         "for; isolates an engine or a gauge", make_engine_gauges)

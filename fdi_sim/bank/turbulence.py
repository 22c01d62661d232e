"""Thresholds scheduled on the bank's own estimate of the turbulence.

Why
---
A real aircraft is not told the turbulence level. A bank whose thresholds are set in moderate
turbulence false-alarms in severe (measured on the F-16 at 6000 ft / 360 KCAS, development seeds
201-203 x 300 s x noise 0.7/1.0/1.3: the flow-angle check's 3-of-5 peak statistic reached 1.58 x its
threshold, 31 episodes in 0.75 h; the airspeed check 1.35 x, 6) and is deaf in calm air (the
shipped DHC-6 elevator loss, engine flameout and rudder hard-over, flown in calm air at the moderate
design, went undetected by every member). The increments of an inertial sensor tell the levels
apart: the standard deviation of the 20 Hz increments of the pitch gyro (F-16) or the vertical
accelerometer (DHC-6) over 30 s. Which one is measured per aircraft (:data:`ESTIMATES`): the
accelerometer's sensor-noise floor hides severe air on the F-16 at altitude, the gyro's response
hides it on the DHC-6 at low speed.

The method
----------
Estimate (per bank sample ``j``, :func:`turbulence_estimate`; ``z`` the aircraft's signal)::

    x_j = z_j - z_{j-1}                          (both usable; clipped: x^2 <= clip^2)
    v_j = v_{j-1} + a_j (x_j^2 - v_{j-1}),  a_j = max(1 / k_j, 1 / (tau_s rate_hz))
    sigma_j = sqrt(v_j)                          (k_j: increments so far; +inf before the first)

a running mean that becomes an exponential average of time constant ``tau_s`` (so the estimate is
usable when the bank arms). The clip (0.3 rad/s for the gyro, 5 times its increments' standard
deviation in severe air; 3 g for the accelerometer) keeps a step of a failed sensor from raising
every threshold for ``tau_s`` (a gyro step of 0.3 rad/s adds 12 % to a moderate-air estimate for
30 s). A maneuver raises the estimate too: the reference is taken on flights with the flight's own
maneuvers (the atlas's variants).

Schedule (per member, :func:`scheduled_threshold`; the shipped one is :func:`power_schedule`):
anchors ``sigma_L`` with the member's threshold ``c_L`` at each, interpolated linearly in
``(log sigma, log c)`` and held below the first and above the last; the thresholds are made
non-decreasing in ``sigma`` (a cumulative maximum). :func:`power_schedule` has two anchors: the
calibrated threshold at the reference ``sigma_ref`` (the estimate's :data:`REFERENCE_QUANTILE` at the
design conditions) and ``c (POWER_SPAN)^gamma`` at ``POWER_SPAN sigma_ref``: below the reference the
calibrated threshold, above it the power law ``c (sigma / sigma_ref)^gamma``. The cost is detection
in air rougher than the design's, and a lag of about ``tau_s`` when the turbulence changes in
flight (not covered by the calibration: its flights keep one level). Before that, the members whose
statistic is white sensor noise (attitude, altitude) get ``c NOISE_COVER^beta``: the thresholds
cover sensors up to :data:`NOISE_COVER` times as noisy as the calibration's, which the bank is not
told either (the cost: those checks detect as if the sensors were that noisy).

Measured, not kept: thresholds trained in each level on the moderate design's flights and
interpolated between the levels' anchors suited the kinematic checks but not the gust filter (its
calm-air thresholds with a moderate-air ``Sigma_m`` came out an order of magnitude above the
moderate one: F-16 6000 ft / 360 kt, 88,601 calm and 72,893 light against 6,235), so a
non-decreasing schedule over all levels made it deaf.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

#: the averaging time constant [s] of the shipped schedules
TAU_S = 30.0
#: the reference of the power schedule (:func:`power_schedule`): this quantile of the estimate over
#: the armed samples of flights at the design conditions; rougher air raises the thresholds
REFERENCE_QUANTILE = 0.9


@dataclass(frozen=True)
class EstimateSpec:
    """Which measurement an aircraft's bank estimates the turbulence from, and how its members'
    thresholds follow it (:func:`power_schedule`).

    Attributes
    ----------
    signal : str
        The measurement whose 20 Hz increments are averaged.
    clip : float
        Largest increment counted [the signal's unit].
    exponents : mapping
        Member id -> ``gamma``: threshold x (sigma / sigma_ref)^gamma above the reference [-].
    why : str
        What measured the choice.
    """

    signal: str
    clip: float
    exponents: Mapping[str, float]
    why: str


#: Per aircraft, each measured on its own development runs (severe runs flown again in moderate air
#: at the same point: the q0.99 of each member's statistic against the estimate's median).
#:
#: F-16: the pitch gyro. The vertical accelerometer's sensor-noise floor compressed its estimate: in
#: the first F-16 envelope hold-out (seed 15001, now development) severe air raised it 1.54-1.66 x over
#: moderate at the same point, 1.09 x the node's reference in run 98 (14,800 ft, noise 0.87), while the
#: airspeed and flow-angle statistics rose 2.3-2.9 x: 24 false alarms in 10.2 severe-air hours. The
#: pitch gyro's increments rose 2.0-2.6 x with them (runs 60, 98, 222), the gust filter's statistic
#: 6.7-11.1 x: gamma 1.07-1.20 (air data) and 2.2-2.7 (gust filter); 1.5 and 3 are taken, 0.5 for the
#: attitude check (its peak rose 1.29-1.42 x where the accelerometer's estimate rose 1.58 x). The
#: F-16 envelope development study (seed 15101) then gave 0 alarms in 29.8 h (severe 4.1 h).
#:
#: DHC-6: the vertical accelerometer. The pitch gyro underestimates severe air at low speed: in its
#: envelope development study (seed 15102) the gyro schedule gave 364 episodes in 5.8 severe-air hours
#: (gust filter 327; runs at 101-105 KCAS), its increments rising 1.73-2.05 x where the gust filter's
#: statistic rose 5.4-11.4 x (runs 10, 18, 48, 117); the accelerometer's rose 2.22-2.57 x. Its
#: exponents were measured on development seeds 201-203 (300 s, noise 0.7/1.0/1.3) at DHC-6 4000 ft
#: / 112 kt and the F-16's points (the 3-of-5 peak of statistic/threshold from moderate to severe
#: against the estimate's ratio: airspeed, flow angles 0.9-2.1, gust filter 3.6-6.4; the larger
#: taken, the air-data checks then raised to 3.5 by the F-16 development study at 2.4: 24 -> 2
#: episodes in 4.1 severe hours); the attitude check 1.0. With them the DHC-6's first envelope
#: hold-out (seed 15002) gave 2 alarms in 49.4 h.
#:
#: The engine-gauge check (DHC-6 only: two engines) gets 1.0: on six 300 s development flights
#: (seeds 900-905) the 0.999 quantile of its statistic was 3.5-3.9 in light and moderate air and
#: 4.7-7.0 in severe air (at most 1.9 x), where the accelerometer's estimate rises 2.2-2.6 x.
#:
#: The altitude check does not move with the turbulence (no exponent) on either.
ESTIMATES: Mapping[str, EstimateSpec] = {
    "f16": EstimateSpec("q_radps", 0.3, {"kalman-gust-v1": 3.0, "kinematic-airspeed-v1": 1.5,
                                         "kinematic-flow-angles-v1": 1.5, "kinematic-attitude-v1": 0.5},
                        "pitch-gyro increments: the accelerometer's noise floor hid severe air at altitude"),
    "DHC6": EstimateSpec("nz_g", 3.0, {"kalman-gust-v1": 5.0, "kinematic-airspeed-v1": 3.5,
                                       "kinematic-flow-angles-v1": 3.5, "kinematic-attitude-v1": 1.0,
                                       "engine-gauges-v1": 1.0},
                         "vertical-accelerometer increments: the pitch gyro's hid severe air at low speed"),
}


def estimate_spec(aircraft: str) -> EstimateSpec | None:
    """The aircraft's :class:`EstimateSpec`, or None (no schedule: its thresholds hold as calibrated)."""
    return ESTIMATES.get(aircraft)


#: the sensor-noise scale the thresholds cover, relative to their calibration's (flown at the
#: design's scale, 1 in the atlas): a bank is not told its sensors' noise either. Per member, the
#: exponent ``beta`` of the statistic's growth with the scale: the threshold at the reference is
#: ``c NOISE_COVER^beta``. Measured by ``tools/noise_scaling.py`` (the same flights at noise 1.3 and
#: 1.0, development seeds 201-203 x 300 s, q0.999 of the armed statistic): the attitude and
#: altitude checks are white sensor noise (ratios 1.25-1.30 and 1.27-1.31 for a scale ratio of 1.3,
#: F-16 and DHC-6 reference scenarios in light and moderate air), the gust filter, airspeed and
#: flow-angle checks are the aircraft's response to turbulence (0.97-1.035, 0.998-1.001,
#: 0.999-1.000), so they get none. Why: in the DHC-6 envelope development study (seed
#: 15102) every attitude-check false alarm (18) and the altitude check's 3 in moderate air came from
#: runs with a noise scale above 1.1 (61 of 180 runs). The engine-gauge check is the gauges' white
#: noise by construction (its scale is the suite's noise; the rounding part does not grow, so 1 is
#: an upper bound).
NOISE_COVER = 1.3
NOISE_EXPONENTS: Mapping[str, float] = {"kinematic-attitude-v1": 1.0, "kinematic-altitude-v1": 1.0,
                                         "engine-gauges-v1": 1.0}
#: the power schedule's second anchor, this many times the reference (held beyond) [-]
POWER_SPAN = 8.0


@dataclass(frozen=True)
class ThresholdSchedule:
    """Members' thresholds as a function of the estimated turbulence (module docstring).

    Attributes
    ----------
    signal : str
        The measurement whose increments are averaged (``q_radps``).
    tau_s : float
        Averaging time constant [s].
    clip : float
        Largest increment counted [the signal's unit].
    levels : tuple of str
        The anchors' names.
    sigma : tuple of float
        The anchors, ascending: standard deviations of the increments [the signal's unit].
    thresholds : mapping
        Member id -> its threshold at each anchor [-].
    """

    signal: str
    tau_s: float
    clip: float
    levels: tuple[str, ...]
    sigma: tuple[float, ...]
    thresholds: Mapping[str, tuple[float, ...]]

    def __post_init__(self) -> None:
        s = np.asarray(self.sigma, dtype=float)
        if s.ndim != 1 or s.size < 1 or len(self.levels) != s.size or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise DesignError(f"a threshold schedule needs one positive finite anchor per level; got levels "
                              f"{self.levels}, sigma {self.sigma}")
        if np.any(np.diff(s) <= 0):
            raise DesignError(f"the schedule's anchors must rise with the level; got {dict(zip(self.levels, self.sigma))}"
                              " (two levels the estimate cannot tell apart)")
        for mid, c in self.thresholds.items():
            c = np.asarray(c, dtype=float)
            if c.shape != s.shape or not np.all(c > 0):
                raise DesignError(f"{mid}: a threshold per anchor, each positive; got {tuple(c)}")

    def log_tables(self, member: str) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(log sigma, log threshold, threshold)`` of a member, the thresholds made non-decreasing
        (the thresholds themselves too: at and beyond the ends they are used exactly)."""
        c = np.maximum.accumulate(np.asarray(self.thresholds[member], dtype=float))
        return np.log(np.asarray(self.sigma, dtype=float)), np.log(c), c

    def to_dict(self) -> dict[str, Any]:
        return {"signal": self.signal, "tau_s": self.tau_s, "clip": self.clip, "levels": list(self.levels),
                "sigma": list(self.sigma), "thresholds": {k: list(v) for k, v in self.thresholds.items()}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ThresholdSchedule:
        return cls(str(d["signal"]), float(d["tau_s"]), float(d["clip"]), tuple(map(str, d["levels"])),
                   tuple(map(float, d["sigma"])), {str(k): tuple(map(float, v)) for k, v in d["thresholds"].items()})

    def describe(self) -> str:
        """One line for the log."""
        a = ", ".join(f"{lv} {s:.3g}" for lv, s in zip(self.levels, self.sigma))
        return (f"thresholds scheduled on the estimated turbulence: std of {self.signal} increments over "
                f"{self.tau_s:g} s, anchors {a}")


@numba.njit(cache=True, nogil=True)
def turbulence_estimate(z, ok, state, alpha_min, clip2, out):  # pragma: no cover - compiled
    """The estimate per sample (module docstring); ``state`` = [last z, v, k, has last], carried
    from block to block (so any blocking gives the same bits)."""
    for j in range(z.shape[0]):
        if ok[j] and math.isfinite(z[j]):
            if state[3] > 0.5:
                x = z[j] - state[0]
                x2 = x * x
                if x2 > clip2:
                    x2 = clip2
                k = state[2] + 1.0
                a = 1.0 / k
                if a < alpha_min:
                    a = alpha_min
                state[1] += a * (x2 - state[1])
                state[2] = k
            state[0] = z[j]
            state[3] = 1.0
        out[j] = math.sqrt(state[1]) if state[2] > 0.5 else math.inf


@numba.njit(cache=True, nogil=True)
def scheduled_threshold(sigma, log_s, log_c, c, out):  # pragma: no cover - compiled
    """``out[j]``: the threshold at ``sigma[j]`` (log-log interpolation, held beyond the ends, where
    the thresholds ``c`` are used as they are)."""
    L = log_s.shape[0]
    for j in range(sigma.shape[0]):
        s = sigma[j]
        if not (s > 0.0) or not math.isfinite(s):
            out[j] = c[L - 1] if not (s <= 0.0) else c[0]
            continue
        ls = math.log(s)
        if ls <= log_s[0]:
            out[j] = c[0]
        elif ls >= log_s[L - 1]:
            out[j] = c[L - 1]
        else:
            i = 0
            while log_s[i + 1] < ls:
                i += 1
            w = (ls - log_s[i]) / (log_s[i + 1] - log_s[i])
            out[j] = math.exp(log_c[i] + w * (log_c[i + 1] - log_c[i]))


def turbulence_series(z: NDArray[np.float64], ok: NDArray[np.bool_], rate_hz: float, clip: float,
                      tau_s: float = TAU_S) -> NDArray[np.float64]:
    """The estimate over a whole series of bank samples (what the bank computes block by block)."""
    out = np.empty(len(z))
    state = np.zeros(4)
    turbulence_estimate(np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(ok, dtype=np.bool_), state,
                        1.0 / (tau_s * rate_hz), clip * clip, out)
    return out


def power_schedule(thresholds: Mapping[str, float], sigma_ref: float, spec: EstimateSpec, *,
                   noise_cover: float = NOISE_COVER, noise_exponents: Mapping[str, float] = NOISE_EXPONENTS,
                   tau_s: float = TAU_S) -> ThresholdSchedule | None:
    """Thresholds that hold below the reference ``sigma_ref`` [the signal's unit] and rise as
    ``(sigma / sigma_ref)^gamma`` above it (two anchors, ``sigma_ref`` and :data:`POWER_SPAN` times
    it: the log-log interpolation between them is that power law), each first raised to cover the
    sensor noise, ``c noise_cover^beta`` (:data:`NOISE_EXPONENTS`), for the members with either
    exponent; None when no member has one."""
    if not (noise_cover >= 1.0 and math.isfinite(noise_cover)):
        raise DesignError(f"the noise cover is a scale of at least 1 (thresholds only rise); got {noise_cover}")
    rows = {}
    for mid, c in thresholds.items():
        gamma, beta = float(spec.exponents.get(mid, 0.0)), float(noise_exponents.get(mid, 0.0))
        if (gamma > 0 or beta > 0) and np.isfinite(c):
            c0 = float(c) * noise_cover ** beta
            rows[mid] = (c0, c0 * POWER_SPAN ** gamma)
    if not rows:
        return None
    return ThresholdSchedule(spec.signal, tau_s, spec.clip, ("reference", f"{POWER_SPAN:g} x reference"),
                             (float(sigma_ref), float(sigma_ref) * POWER_SPAN), rows)


def reference_sigma(series: Sequence[NDArray[np.float64]], arm_samples: int) -> float:
    """:data:`REFERENCE_QUANTILE` of the estimate [the signal's unit] over the armed samples of flights at the design
    conditions."""
    x = np.concatenate([np.asarray(s[arm_samples:], dtype=float) for s in series])
    x = x[np.isfinite(x)]
    if x.size == 0:
        raise DesignError("no finite turbulence estimate on the reference flights (no usable measurement)")
    return float(np.quantile(x, REFERENCE_QUANTILE))

"""Analytical redundancy from kinematics: sensor checks a flight-control engineer uses.

Four detectors, each comparing one sensor group with what the rest of the suite implies through
exact kinematics (no aerodynamic model, so no model error and no trim dependence):

``attitude``
    AHRS attitude increment over a window of ``T`` against the gyro rates integrated through the
    Euler kinematics (trapezoid rule), per axis::

        phi_dot   = p + tan(theta) (q sin(phi) + r cos(phi))
        theta_dot = q cos(phi) - r sin(phi)
        psi_dot   = (q sin(phi) + r cos(phi)) / cos(theta)
        e = [phi, theta, psi](t) - [phi, theta, psi](t - T) - int_{t-T}^{t} E(phi, theta) w dt

    A constant attitude bias cancels in the increment; a gyro bias ``b`` gives ``e = E b T``, so
    the residual is the equivalent gyro bias ``b_hat = E^-1 e / T`` [rad/s] and the hypothesis is
    the gyro with the largest normalized ``|b_hat|``.
``altitude``
    baro altitude increment against the integrated GNSS vertical velocity,
    ``e_h = h(t) - h(t - T) + int v_down dt`` [ft], and the air-data vertical speed against it,
    ``e_hdot = mean(hdot + v_down)`` [ft/s], both at the GNSS samples (``v_down`` linear between
    them) and held in between; one of them out of bounds points at that sensor, both
    at the GNSS ``v_down_fps``.
``airspeed``
    true airspeed from ``vc_kts`` through the standard atmosphere at the baro altitude (no
    temperature is measured; density altitude = pressure altitude) against the GNSS ground
    velocity minus the steady wind, ``e = vt - |v_g - w_hat|`` [kt].
``flow-angles``
    vane alpha and beta against the air-relative velocity ``v_g - w_hat`` rotated into body axes
    by the AHRS attitude: ``alpha_kin = atan2(w_b, u_b)``, ``beta_kin = asin(v_b / |v_a|)``.

The steady wind ``w_hat`` (NED, 3 components) is the running mean, then a first-order average
with time constant ``tau_wind_s``, of ``v_g - R(phi, theta, psi) vt [cos a cos b, sin b, sin a cos b]``
at the GNSS samples; it also absorbs the steady parts of the heading, vane and airspeed biases
(so a steady bias is not detected, a change is). Turbulence is the noise of these two checks.
A drift of rate ``d`` in a checked sensor shows as about ``d tau_wind_s`` once the wind estimate
follows it.

Input: absolute measurements (``Samples.dy + Samples.y0``, heading wrapped; :func:`absolute`).
GNSS channels are used only at their own samples (``Samples.fresh``; a stale row holds the last
residual), every other channel at every detector sample. Every detector offers the contract
``reset(rng)`` / ``step(t_s, u, y) -> Residual`` (``u`` ignored, ``y`` absolute in the order of
``output_names``) and a vectorised :meth:`KinematicDetector.run` over a whole :class:`Samples`;
both give the same numbers (the step path is the batch path on one row with a carried tail).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.detectors.samples import Samples
from fdi_sim.errors import DesignError
from fdi_sim.isa import isa
from fdi_sim.units import KT_PER_FPS

__all__ = [
    "MEASUREMENTS", "MeasurementSet", "KinematicDesign", "KinematicRun", "KinematicDetector", "absolute",
    "euler_rates", "vt_from_vc_fps", "dcm_body_to_ned", "empirical_threshold",
]

#: the measured signals these checks read (names of ``aircraft/*/sensors.toml``)
MEASUREMENTS: tuple[str, ...] = (
    "p_radps", "q_radps", "r_radps", "nx_g", "ny_g", "nz_g", "phi_rad", "theta_rad", "psi_rad", "vc_kts",
    "alpha_rad", "beta_rad", "h_ft", "hdot_fps", "v_north_fps", "v_east_fps", "v_down_fps",
)
GNSS = ("v_north_fps", "v_east_fps", "v_down_fps")
_P0_PSF = isa(0.0).pressure_psf
_A0_FPS = isa(0.0).sound_speed_fps


@dataclass(frozen=True)
class MeasurementSet:
    """A stand-in "model" for :func:`fdi_sim.detectors.samples.log_samples` that keeps absolute values.

    No inputs, zero trim: ``Samples.dy`` is then the measurement itself (heading wrapped to
    [-pi, pi)).
    """

    output_names: tuple[str, ...] = MEASUREMENTS
    input_names: tuple[str, ...] = ()
    input_kinds: tuple[str, ...] = ()
    u0: tuple[float, ...] = ()

    @property
    def y0(self) -> NDArray[np.float64]:
        """Zero trim (p,)."""
        return np.zeros(len(self.output_names))


def absolute(samples: Samples) -> NDArray[np.float64]:
    """Absolute measurements ``dy + y0`` (N, p), ``psi*_rad`` wrapped to [-pi, pi)."""
    y = samples.dy + np.asarray(samples.y0, dtype=float)[None, :]
    for i, nm in enumerate(samples.output_names):
        if nm.startswith("psi") and nm.endswith("_rad"):
            y[:, i] = _wrap(y[:, i])
    return y


def _wrap(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def euler_rates(phi_rad: NDArray, theta_rad: NDArray, p_radps: NDArray, q_radps: NDArray,
                r_radps: NDArray) -> NDArray[np.float64]:
    """Euler angle rates (N, 3) [rad/s] from body rates (3-2-1 Euler kinematics)."""
    sp, cp, tt, ct = np.sin(phi_rad), np.cos(phi_rad), np.tan(theta_rad), np.cos(theta_rad)
    qs = q_radps * sp + r_radps * cp  # q sin(phi) + r cos(phi)
    return np.column_stack([p_radps + tt * qs, q_radps * cp - r_radps * sp, qs / ct])


def _euler_matrix(phi_rad: NDArray, theta_rad: NDArray) -> NDArray[np.float64]:
    """E (N, 3, 3) with ``[phi_dot, theta_dot, psi_dot] = E [p, q, r]``."""
    sp, cp, tt, ct = np.sin(phi_rad), np.cos(phi_rad), np.tan(theta_rad), np.cos(theta_rad)
    E = np.zeros((len(phi_rad), 3, 3))
    E[:, 0, 0] = 1.0
    E[:, 0, 1], E[:, 0, 2] = tt * sp, tt * cp
    E[:, 1, 1], E[:, 1, 2] = cp, -sp
    E[:, 2, 1], E[:, 2, 2] = sp / ct, cp / ct
    return E


def euler_inverse_apply(phi_rad: NDArray, theta_rad: NDArray, e: NDArray[np.float64]) -> NDArray[np.float64]:
    """``E^-1 e`` (N, 3) for the Euler-rate matrix ``E`` of :func:`_euler_matrix`, in closed form.

    ``E^-1 = [[1, 0, -sin(theta)], [0, cos(phi), sin(phi) cos(theta)], [0, -sin(phi), cos(phi) cos(theta)]]``
    (the body rates of the Euler rates, 3-2-1). Elementwise, so each number is the same sequence of
    IEEE operations on every CPU and BLAS, which the streaming check
    (:mod:`fdi_sim.detectors.kinematic_stream`) repeats bit for bit; ``np.linalg.solve`` rounds as its
    BLAS kernel does, which differs between CPUs (with and without fused multiply-adds: measured on
    OpenBLAS 0.3.31's Haswell kernels on an Intel AVX-512 and an AMD EPYC machine).
    """
    sp, cp, st, ct = np.sin(phi_rad), np.cos(phi_rad), np.sin(theta_rad), np.cos(theta_rad)
    e0, e1, e2 = e[:, 0], e[:, 1], e[:, 2]
    return np.column_stack([e0 - st * e2, cp * e1 + (sp * ct) * e2, (cp * ct) * e2 - sp * e1])


def dcm_body_to_ned(phi_rad: NDArray, theta_rad: NDArray, psi_rad: NDArray) -> NDArray[np.float64]:
    """Direction-cosine matrices (N, 3, 3), ``v_ned = R v_body`` (3-2-1 rotation)."""
    sf, cf, st, ct, ss, cs = (np.sin(phi_rad), np.cos(phi_rad), np.sin(theta_rad), np.cos(theta_rad),
                              np.sin(psi_rad), np.cos(psi_rad))
    R = np.empty((len(phi_rad), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = ct * cs, sf * st * cs - cf * ss, cf * st * cs + sf * ss
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = ct * ss, sf * st * ss + cf * cs, cf * st * ss - sf * cs
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -st, sf * ct, cf * ct
    return R


def vt_from_vc_fps(h_ft: NDArray, vc_kts: NDArray) -> NDArray[np.float64]:
    """True airspeed [ft/s] from calibrated airspeed [kt] at pressure altitude ``h_ft`` (subsonic).

    ``qc = p0 ((1 + 0.2 (vc/a0)^2)^3.5 - 1)``, ``M = sqrt(5 ((qc/p + 1)^(2/7) - 1))``, ``vt = M a(h)``
    (the inverse of :func:`fdi_sim.isa.vc_from_vt`, vectorised; standard atmosphere, so the
    density altitude is the pressure altitude).
    """
    h = np.clip(np.asarray(h_ft, dtype=float), -2000.0, 36089.0)
    # troposphere: T = T0 - L h, p = p0 (T/T0)^5.2559
    T0 = isa(0.0).temperature_R
    T = T0 - 0.00356616 * h
    p = _P0_PSF * (T / T0) ** 5.25588
    a = _A0_FPS * np.sqrt(T / T0)
    vc_fps = np.asarray(vc_kts, dtype=float) / KT_PER_FPS
    qc = _P0_PSF * ((1.0 + 0.2 * (vc_fps / _A0_FPS) ** 2) ** 3.5 - 1.0)
    mach = np.sqrt(5.0 * ((np.maximum(qc, 0.0) / p + 1.0) ** (2.0 / 7.0) - 1.0))
    return mach * a


def empirical_threshold(statistics: Sequence[NDArray[np.float64]], p_false_alarm: float) -> float:
    """The ``1 - p_false_alarm`` empirical quantile of the pooled finite statistics of fault-free runs."""
    pooled = np.concatenate([np.asarray(s, dtype=float)[np.isfinite(s)] for s in statistics])
    if pooled.size == 0 or not 0.0 < p_false_alarm < 1.0:
        raise DesignError(f"cannot calibrate: {pooled.size} finite statistics, p_false_alarm = {p_false_alarm!r}")
    if pooled.size * p_false_alarm < 1.0:
        raise DesignError(f"{pooled.size} calibration samples cannot resolve p_false_alarm = {p_false_alarm:g}; "
                          f"fly at least {math.ceil(1.0 / p_false_alarm)} samples")
    return float(np.quantile(pooled, 1.0 - p_false_alarm, method="higher"))


@dataclass(frozen=True)
class KinematicDesign:
    """The numbers of one kinematic check.

    Attributes
    ----------
    kind : str
        ``"attitude"``, ``"altitude"``, ``"airspeed"`` or ``"flow-angles"``.
    rate_hz : float
        Detector rate [Hz].
    scales : tuple of float
        Per-channel residual scale (channel units), the statistic is ``max |r_i| / scales_i``.
    threshold : float
        Alarm threshold on the statistic [-].
    window_s : float
        Integration window ``T`` of the attitude and altitude increments [s].
    average_s : float
        Moving average of the residual [s] (hdot, airspeed, flow angles).
    tau_wind_s : float
        Time constant of the steady-wind average [s].
    gnss_rate_hz : float
        GNSS velocity rate [Hz] (freshness in :meth:`KinematicDetector.step`).
    tau_bias_s : float
        If positive, the residual's own slow mean (running mean, then first order with this time
        constant [s]; not updated while the statistic is over the threshold) is subtracted: it
        removes the sensors' turn-on biases (gyro 0.05 deg/s, vertical speed 0.2 ft/s), which would
        otherwise set the threshold. A step fault is then detected at its onset and stays detected
        (the mean is frozen during the alarm).
    warmup_s : float
        With ``tau_bias_s``, the residual is invalid until this long of valid residuals is averaged [s].
    """

    kind: str
    rate_hz: float = 20.0
    scales: tuple[float, ...] = ()
    threshold: float = 5.0
    window_s: float = 2.0
    average_s: float = 1.0
    tau_wind_s: float = 60.0
    gnss_rate_hz: float = 10.0
    tau_bias_s: float = 0.0
    warmup_s: float = 5.0


#: channels and hypotheses per kind
CHANNELS: dict[str, tuple[str, ...]] = {
    "attitude": ("p_bias_radps", "q_bias_radps", "r_bias_radps"),
    "altitude": ("h_increment_ft", "hdot_error_fps"),
    "airspeed": ("vt_error_kts",),
    "flow-angles": ("alpha_error_rad", "beta_error_rad"),
}
HYPOTHESES: dict[str, tuple[str, ...]] = {
    "attitude": ("p_radps", "q_radps", "r_radps"),
    "altitude": ("h_ft", "hdot_fps", "v_down_fps"),
    "airspeed": ("vc_kts",),
    "flow-angles": ("alpha_rad", "beta_rad"),
}
#: signals each kind reads
NEEDS: dict[str, tuple[str, ...]] = {
    "attitude": ("phi_rad", "theta_rad", "psi_rad", "p_radps", "q_radps", "r_radps"),
    "altitude": ("h_ft", "hdot_fps", "v_down_fps"),
    "airspeed": ("vc_kts", "h_ft", "phi_rad", "theta_rad", "psi_rad", "alpha_rad", "beta_rad") + GNSS,
    "flow-angles": ("vc_kts", "h_ft", "phi_rad", "theta_rad", "psi_rad", "alpha_rad", "beta_rad") + GNSS,
}


@dataclass(frozen=True, eq=False)
class KinematicRun:
    """A whole run of one detector (:meth:`KinematicDetector.run`).

    Attributes
    ----------
    t_s : NDArray
        (N,) sample times [s].
    r : NDArray
        (N, k) residuals (channel units, :data:`CHANNELS`); NaN while the window fills.
    statistic : NDArray
        (N,) ``max_i |r_i| / scale_i`` [-]; NaN where invalid.
    alarm : NDArray of bool
        (N,) ``statistic > threshold``.
    isolation : NDArray of object
        (N,) the hypothesis (sensor name) at an alarm, None elsewhere.
    valid : NDArray of bool
        (N,).
    """

    t_s: NDArray[np.float64]
    r: NDArray[np.float64]
    statistic: NDArray[np.float64]
    alarm: NDArray[np.bool_]
    isolation: NDArray[np.object_]
    valid: NDArray[np.bool_]


@dataclass
class _State:
    """What the batch path carries between calls: the last rows and the wind average."""

    tail: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    wind_ned_fps: NDArray[np.float64] | None = None
    n_gnss: int = 0
    last_r: NDArray[np.float64] | None = None
    r_mean: NDArray[np.float64] | None = None
    n_mean: int = 0


class KinematicDetector:
    """One kinematic check with the detector contract and a vectorised :meth:`run`.

    Parameters
    ----------
    design : KinematicDesign
    output_names : sequence of str
        Order of ``y`` in :meth:`step` (absolute values).
    id : str
        Registry id.
    """

    def __init__(self, design: KinematicDesign, output_names: Sequence[str] = MEASUREMENTS, id: str = "") -> None:
        if design.kind not in CHANNELS:
            raise DesignError(f"unknown kinematic check {design.kind!r}; one of {', '.join(CHANNELS)}")
        k = len(CHANNELS[design.kind])
        if len(design.scales) != k or not all(s > 0 for s in design.scales):
            raise DesignError(f"{design.kind}: scales must be {k} positive numbers ({', '.join(CHANNELS[design.kind])})")
        missing = [n for n in NEEDS[design.kind] if n not in output_names]
        if missing:
            raise DesignError(f"{design.kind} check needs the measurements {', '.join(missing)} "
                              f"(outputs are {', '.join(output_names)})")
        self.design = design
        self.id = id or f"kinematic-{design.kind}-v1"
        self.hypotheses = HYPOTHESES[design.kind]
        self.output_names = tuple(output_names)
        self._cols = {n: self.output_names.index(n) for n in NEEDS[design.kind]}
        self._dt_s = 1.0 / design.rate_hz
        self._n_win = max(1, int(round(design.window_s * design.rate_hz)))
        self._n_avg = max(1, int(round(design.average_s * design.rate_hz)))
        self._state = _State()

    # --- contract ---------------------------------------------------------------------------
    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Clear the windows and the wind estimate (no randomness is used)."""
        self._state = _State()

    def step(self, t_s: float, u: NDArray[np.float64], y: NDArray[np.float64]) -> Residual:
        """One sample: time [s], ``u`` (unused), absolute ``y`` in ``output_names`` order."""
        y = np.asarray(y, dtype=float)
        cols = {n: y[None, i] for n, i in self._cols.items()}
        if "psi_rad" in cols:
            cols["psi_rad"] = _wrap(cols["psi_rad"])
        # a GNSS sample exists where t_s is a whole number of GNSS periods (the log's rows)
        k = t_s * self.design.gnss_rate_hz
        gnss_fresh = np.array([abs(k - round(k)) < 1e-6])
        ok = np.array([all(np.isfinite(v[0]) for v in cols.values())])
        r, self._state = self._batch(cols, ok, gnss_fresh, self._state)
        z, iso = self._test(r)
        res = Residual(float(t_s), r[0], float(z[0]), 0, self.design.threshold, bool(z[0] > self.design.threshold),
                       iso[0], np.abs(r[0]) / np.asarray(self.design.scales), bool(np.isfinite(z[0])))
        return finite_or_invalid(res)

    def run(self, samples: Samples) -> KinematicRun:
        """The whole run at once (statistic, alarm, isolation per sample), from a fresh state."""
        if abs(samples.rate_hz - self.design.rate_hz) > 1e-9:
            raise DesignError(f"{self.id} is designed at {self.design.rate_hz:g} Hz; the samples are at "
                              f"{samples.rate_hz:g} Hz")
        y = absolute(samples)
        idx = {n: samples.output_names.index(n) for n in self._cols if n in samples.output_names}
        missing = [n for n in self._cols if n not in idx]
        if missing:
            raise DesignError(f"{self.id} needs {', '.join(missing)}; the samples have {', '.join(samples.output_names)}")
        cols = {n: y[:, i] for n, i in idx.items()}
        ok = samples.valid[:, list(idx.values())].all(axis=1)
        gi = [idx[n] for n in GNSS if n in idx]
        gnss_fresh = samples.fresh[:, gi].all(axis=1) if gi else np.ones(samples.n, dtype=bool)
        r, _ = self._batch(cols, ok, gnss_fresh, _State())
        z, iso = self._test(r)
        valid = np.isfinite(z)
        alarm = valid & (z > self.design.threshold)
        return KinematicRun(samples.t_s, r, z, alarm, np.where(alarm, iso, None), valid)

    # --- the test ---------------------------------------------------------------------------
    def _test(self, r: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.object_]]:
        """Statistic ``max |r_i|/s_i`` and the hypothesis per row."""
        zi = np.abs(r) / np.asarray(self.design.scales)[None, :]
        with np.errstate(invalid="ignore"):
            z = np.where(np.isfinite(zi).all(axis=1), np.max(np.nan_to_num(zi, nan=0.0), axis=1), np.nan)
        best = np.argmax(np.nan_to_num(zi, nan=-1.0), axis=1)
        iso = np.array([self.hypotheses[b] for b in best], dtype=object)
        if self.design.kind == "altitude":
            # both relations out of bounds: the sensor they share, the GNSS vertical velocity
            both = (zi > self.design.threshold).all(axis=1)
            iso[both] = "v_down_fps"
        iso[~(z > self.design.threshold)] = None
        return z, iso

    # --- the residuals ----------------------------------------------------------------------
    def _batch(self, cols: Mapping[str, NDArray], ok: NDArray[np.bool_], gnss_fresh: NDArray[np.bool_],
               state: _State) -> tuple[NDArray[np.float64], _State]:
        """Residuals of the new rows, with the carried tail prepended; returns the new state."""
        kind = self.design.kind
        new = {n: np.asarray(v, dtype=float) for n, v in cols.items()}
        new["_ok"] = np.asarray(ok, dtype=float)
        new["_gnss"] = np.asarray(gnss_fresh, dtype=float)
        state = _State(dict(state.tail), None if state.wind_ned_fps is None else state.wind_ned_fps.copy(),
                       state.n_gnss, None if state.last_r is None else state.last_r.copy(),
                       None if state.r_mean is None else state.r_mean.copy(), state.n_mean)
        if kind in ("airspeed", "flow-angles"):
            new.update(self._air_rows(new, state))  # the wind average is recursive: rows in order
        m = len(new["_ok"])
        full = {n: np.concatenate([state.tail[n], v]) if n in state.tail else v for n, v in new.items()}
        full.update({n: v for n, v in state.tail.items() if n not in new})  # held residuals of the tail
        L0 = len(full["_ok"]) - m  # rows of carried tail
        r_full = getattr(self, "_r_" + kind.replace("-", "_"))(full, state, L0)
        keep = self._n_win + self._n_avg + 1
        state.tail = {n: v[-keep:] for n, v in full.items()}
        r = r_full[L0:]
        if self.design.tau_bias_s > 0:
            r = self._debias(r, state)
        return r, state

    def _debias(self, r: NDArray[np.float64], state: _State) -> NDArray[np.float64]:
        """``r - m``, ``m <- m + g (r - m)``, ``g = max(1/n, dt/tau)``; m frozen while the statistic alarms."""
        out = np.full_like(r, np.nan)
        scales = np.asarray(self.design.scales)
        g_floor = self._dt_s / self.design.tau_bias_s
        n_warm = int(round(self.design.warmup_s * self.design.rate_hz))
        for k in range(len(r)):  # recursive, in row order
            if not np.all(np.isfinite(r[k])):
                continue
            if state.r_mean is not None and state.n_mean >= n_warm:
                out[k] = r[k] - state.r_mean
                if np.max(np.abs(out[k]) / scales) > self.design.threshold:
                    continue  # an alarmed sample does not teach the mean
            state.n_mean += 1
            g = max(1.0 / state.n_mean, g_floor)
            state.r_mean = r[k].copy() if state.r_mean is None else state.r_mean + g * (r[k] - state.r_mean)
        return out

    def _r_attitude(self, c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray[np.float64]:
        n, dt = self._n_win, self._dt_s
        phi, theta, psi = c["phi_rad"], c["theta_rad"], c["psi_rad"]
        ed = euler_rates(phi, theta, c["p_radps"], c["q_radps"], c["r_radps"])
        # trapezoid: I_k = sum_{i<=k} (ed_i + ed_{i-1}) dt / 2
        inc = np.vstack([np.zeros((1, 3)), 0.5 * (ed[1:] + ed[:-1]) * dt])
        I = np.cumsum(inc, axis=0)
        att = np.column_stack([phi, theta, psi])
        e = np.full_like(att, np.nan)
        if len(att) > n:
            d_att = att[n:] - att[:-n]
            d_att[:, 2] = _wrap(d_att[:, 2])
            e[n:] = d_att - (I[n:] - I[:-n])
        # e = E b T  ->  b_hat = E^-1 e / T (the equivalent gyro bias); only the new rows are returned
        b = np.full_like(e, np.nan)
        b[L0:] = euler_inverse_apply(phi[L0:], theta[L0:], np.nan_to_num(e[L0:])) / (n * dt)
        b[~np.isfinite(e).all(axis=1)] = np.nan
        b[~self._valid_window(c["_ok"], n)] = np.nan
        return b

    def _r_altitude(self, c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray[np.float64]:
        n, na, dt = self._n_win, self._n_avg, self._dt_s
        h, hd = c["h_ft"], c["hdot_fps"]
        fresh = (c["_gnss"] > 0.5) & (c["_ok"] > 0.5)
        rows = np.flatnonzero(fresh)
        # v_down between its own samples: linear (the GNSS rate is below the detector rate; using the
        # held value would add a lag of up to one GNSS period, 0.8 ft/s in a 0.5 g pull-up)
        vd = np.interp(np.arange(len(h)), rows, c["v_down_fps"][rows]) if rows.size else np.full(len(h), np.nan)
        I = np.cumsum(np.concatenate([[0.0], 0.5 * (vd[1:] + vd[:-1]) * dt]))
        raw = np.full((len(h), 2), np.nan)
        if len(h) > n:
            raw[n:, 0] = h[n:] - h[:-n] + (I[n:] - I[:-n])  # dh = -int v_down dt
        raw[:, 1] = hd + vd
        raw[~fresh] = np.nan  # evaluated at GNSS samples only, held between them
        held = self._hold(raw, c, state, L0)
        r = np.column_stack([held[:, 0], _moving_mean(held[:, 1], na)])
        r[~self._valid_window(c["_ok"], max(n, na)), :] = np.nan
        return r

    def _hold(self, raw: NDArray[np.float64], c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray:
        """Forward fill of the finite rows of ``raw`` over the new rows; the tail keeps its held values."""
        held = np.full_like(raw, np.nan)
        if L0:
            held[:L0] = np.column_stack([c[f"_h{i}"][:L0] for i in range(raw.shape[1])])
        good = np.isfinite(raw).all(axis=1)
        last = state.last_r
        for k in range(L0, len(raw)):  # forward fill over the new rows only
            if good[k]:
                last = raw[k]
            if last is not None:
                held[k] = last
        state.last_r = last
        for i in range(raw.shape[1]):  # carried with the tail so the next call's window sees it
            c[f"_h{i}"] = held[:, i]  # type: ignore[index]
        return held

    def _air_rows(self, c: Mapping[str, NDArray], state: _State) -> dict[str, NDArray]:
        """Per new row: true airspeed, measured air velocity (NED) and the wind average before the row."""
        vt = vt_from_vc_fps(c["h_ft"], c["vc_kts"])
        a, b = c["alpha_rad"], c["beta_rad"]
        v_b = vt[:, None] * np.column_stack([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])
        R = dcm_body_to_ned(c["phi_rad"], c["theta_rad"], c["psi_rad"])
        v_g = np.column_stack([c["v_north_fps"], c["v_east_fps"], c["v_down_fps"]])
        w_raw = v_g - np.einsum("nij,nj->ni", R, v_b)
        w_prior = np.full_like(w_raw, np.nan)
        gain_floor = 1.0 / (self.design.tau_wind_s * self.design.gnss_rate_hz)
        for k in range(len(vt)):  # w <- w + g (w_raw - w), g = max(1/n, dt_gnss/tau): mean, then first order
            if state.wind_ned_fps is not None:
                w_prior[k] = state.wind_ned_fps
            if c["_gnss"][k] > 0.5 and c["_ok"][k] > 0.5 and np.all(np.isfinite(w_raw[k])):
                state.n_gnss += 1
                g = max(1.0 / state.n_gnss, gain_floor)
                state.wind_ned_fps = w_raw[k].copy() if state.wind_ned_fps is None else \
                    state.wind_ned_fps + g * (w_raw[k] - state.wind_ned_fps)
        return {"_vt": vt, "_wn": w_prior[:, 0], "_we": w_prior[:, 1], "_wd": w_prior[:, 2]}

    def _air_relative(self, c: Mapping[str, NDArray]) -> NDArray[np.float64]:
        """Air-relative velocity ``v_g - w_hat`` (N, 3) [ft/s], NED."""
        return np.column_stack([c["v_north_fps"] - c["_wn"], c["v_east_fps"] - c["_we"], c["v_down_fps"] - c["_wd"]])

    def _r_airspeed(self, c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray[np.float64]:
        raw = (c["_vt"] - np.linalg.norm(self._air_relative(c), axis=1))[:, None] * KT_PER_FPS
        return self._air_finish(raw, c, state, L0)

    def _r_flow_angles(self, c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray[np.float64]:
        v_a = self._air_relative(c)
        R = dcm_body_to_ned(c["phi_rad"], c["theta_rad"], c["psi_rad"])
        v_b = np.einsum("nji,nj->ni", R, v_a)  # R' v_a
        speed = np.linalg.norm(v_b, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha_kin = np.arctan2(v_b[:, 2], v_b[:, 0])
            beta_kin = np.arcsin(np.clip(v_b[:, 1] / speed, -1.0, 1.0))
        raw = np.column_stack([c["alpha_rad"] - alpha_kin, c["beta_rad"] - beta_kin])
        return self._air_finish(raw, c, state, L0)

    def _air_finish(self, raw: NDArray, c: Mapping[str, NDArray], state: _State, L0: int) -> NDArray:
        """Evaluate at GNSS samples, hold between them, average."""
        fresh = (c["_gnss"] > 0.5) & (c["_ok"] > 0.5)
        held = self._hold(np.where(fresh[:, None], raw, np.nan), c, state, L0)
        out = np.column_stack([_moving_mean(held[:, i], self._n_avg) for i in range(raw.shape[1])])
        out[~self._valid_window(c["_ok"], self._n_avg)] = np.nan
        return out

    def _valid_window(self, ok: NDArray[np.float64], n: int) -> NDArray[np.bool_]:
        """True where the rows ``k - n .. k`` exist and are valid."""
        bad = np.concatenate([[0], np.cumsum(ok < 0.5)])
        idx = np.arange(len(ok))
        lo = idx - n
        return (lo >= 0) & (bad[idx + 1] - bad[np.maximum(lo, 0)] == 0)


def _moving_mean(x: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Mean of the last ``n`` values (NaN for the first ``n - 1`` rows and wherever one is NaN)."""
    out = np.full(len(x), np.nan)
    if len(x) >= n:
        bad = ~np.isfinite(x)
        c = np.concatenate([[0.0], np.cumsum(np.where(bad, 0.0, x))])  # a NaN must not poison later sums
        nb = np.concatenate([[0], np.cumsum(bad)])
        out[n - 1:] = np.where(nb[n:] - nb[:-n] == 0, (c[n:] - c[:-n]) / n, np.nan)
    return out

"""The loop's per-step core, compiled: truth signals, divergence checks, sensors, pilot, statistics.

One numba call per step does what the loop of :mod:`fdi_sim.sim.run` did in five pieces of
Python around two compiled calls (issue 13: the DHC-6 loop with the default bank was at 0.37-0.38
of bare JSBSim against a goal of 0.4; measured per step on a trimmed DHC-6: the truth list copied
into the kernels' array 0.77 us, the divergence checks 0.55 us, the deviation statistics 0.35 us,
the scaled signals 0.2 us, and a numba dispatch 0.35 us plus about 0.1 us an array argument).

The loop reads the JSBSim properties of the truth signals flat (one ``map`` of the node getter,
the AGL altitude last) and packs them into ``x[n:]`` (``struct.pack_into``: 0.44 us against 0.77 us
for a ctypes slice assignment); :func:`step` then

- ``TRUTH``: builds the truth ``x[:n]`` from the flat reads (``Aircraft.list_reader``'s values, bit
  for bit: a summed signal is ``0 + a + b`` as Python's ``sum``, a scaled one ``factor * value``)
  and checks it, in the loop's order: non-finite (the sum of the truth), ground (AGL altitude <= 0),
  alpha, bank angle, body rates, airspeed;
- ``MEASURE``: the sensors (:func:`fdi_sim.sensors._kernels.measure`);
- ``PILOT``: the pilot (:func:`fdi_sim.pilot._kernels.step`) on ``y``, into ``u``;
- ``STATS``: the deviations from the pilot's references (``run._loop``'s definitions), their
  maxima kept in ``aux``.

``mode`` says which (bits). A step with a bank sample (the bank takes the measurement before the
pilot, and may reconfigure the pilot's input) calls ``TRUTH | MEASURE``, then the bank, then
``PILOT | STATS`` on the pilot's input; a faulty flight (the injector works on lists) calls
``TRUTH`` and ``STATS`` only. The return value is ``OK``; ``REFILL`` (the sensors need a new
noise block: nothing was measured, nothing after it was done; the checks may run again) or one of
the divergence codes (nothing after the check was done), for which :func:`divergence_reason`
gives the loop's message.

numba's cache does not notice a change in another file's compiled function that a cached one
calls (a limitation numba's caching notes list: changes in symbols defined in another file go
unnoticed), and :func:`step` calls the sensors' and the pilot's kernels: at import
the hash of their source files is compared with the one stored beside the cache, and the cache
index is emptied when they differ (:func:`_fresh_cache`).
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Callable, Sequence

import numba
import numpy as np
from numpy.typing import NDArray

from fdi_sim.pilot import _kernels as pilot_kernels
from fdi_sim.sensors import _kernels as sensor_kernels
from fdi_sim.units import DEG_PER_RAD

#: ``mode`` bits
TRUTH, MEASURE, PILOT, STATS = 1, 2, 4, 8
ALL = TRUTH | MEASURE | PILOT | STATS
#: return codes: OK, a new sensor-noise block needed, then the divergences in the order checked
OK, REFILL, NONFINITE, GROUND, ALPHA, BANK, RATE, AIRSPEED = range(8)

#: ``aux`` layout: limits, steady wind, the running maxima, truth indexes, then the signal table
A_LO, A_HI, PHI_MAX, RATE_MAX, VC_MIN, WN, WE, MAX_DH, MAX_DV, MAX_DPHI = range(10)
I_ALPHA, I_PHI, I_P, I_Q, I_R, I_VC, I_VN, I_VE, I_VD, I_VT, I_H, N_TRUTH, N_FLAT = range(10, 23)
TABLE = 23  # then per truth signal: first flat index, end flat index, factor (NaN: none)
#: the pilot's outputs (``run.PILOT_FIELDS``): the references the statistics use
U_H_REF, U_VC_REF, U_PHI_REF = 4, 5, 7


@numba.njit(cache=True)
def step(mode: int, t_s: float, x: NDArray[np.float64], y: NDArray[np.float64], u: NDArray[np.float64],
         s_tab: NDArray[np.float64], s_off: NDArray[np.float64], p_state: NDArray[np.float64],
         p_par: NDArray[np.float64], aux: NDArray[np.float64]) -> int:  # pragma: no cover (compiled)
    """One step of the loop's core (module docstring).

    Parameters
    ----------
    mode : int
        ``TRUTH``, ``MEASURE``, ``PILOT``, ``STATS`` bits.
    t_s : float
        Time [s].
    x : ndarray, float64, shape (n + n_flat,)
        ``x[n:]`` the flat property reads, AGL altitude [ft] last (written by the loop); ``x[:n]``
        the truth (written here).
    y : ndarray, float64
        The measurements (written by ``MEASURE``; the pilot's input for ``PILOT``).
    u : ndarray, float64, shape (>= 8,)
        The pilot's outputs (``PILOT``; read by ``STATS``).
    s_tab, s_off : ndarray
        The sensor suite's arrays (:meth:`fdi_sim.sensors.SensorSuite.compiled`).
    p_state, p_par : ndarray
        The pilot's arrays (:meth:`fdi_sim.pilot.autopilot.Pilot.compiled`).
    aux : ndarray, float64
        Limits, wind, maxima and tables (module constants; :func:`make_aux`).

    Returns
    -------
    int
        ``OK``, ``REFILL`` or a divergence code.
    """
    if mode & TRUTH:
        n, m = int(aux[N_TRUTH]), int(aux[N_FLAT])
        total = 0.0
        for i in range(n):
            a, b, f = int(aux[TABLE + 3 * i]), int(aux[TABLE + 3 * i + 1]), aux[TABLE + 3 * i + 2]
            if b - a == 1:
                v = x[n + a]
            else:  # Python's sum: 0 + a + b (so -0.0 alone would give 0.0)
                v = 0.0
                for j in range(a, b):
                    v += x[n + j]
            if f == f:  # a scaled signal
                v = f * v
            x[i] = v
            total += v
        if not math.isfinite(total):  # one NaN or inf makes the sum non-finite
            return NONFINITE
        if x[n + m - 1] <= 0.0:
            return GROUND
        alpha = x[int(aux[I_ALPHA])]
        if not (aux[A_LO] <= alpha <= aux[A_HI]):
            return ALPHA
        if abs(x[int(aux[I_PHI])]) > aux[PHI_MAX]:
            return BANK
        r = aux[RATE_MAX]
        if abs(x[int(aux[I_P])]) > r or abs(x[int(aux[I_Q])]) > r or abs(x[int(aux[I_R])]) > r:
            return RATE
        if x[int(aux[I_VC])] < aux[VC_MIN]:
            return AIRSPEED
    if mode & MEASURE:
        if sensor_kernels.measure(t_s, x, y, s_tab, s_off):
            return REFILL
    if mode & PILOT:
        pilot_kernels.step(t_s, y, u, p_state, p_par)
    if mode & STATS:  # airspeed relative to the steady air mass: the gusts are the pilot's to ride
        dn = x[int(aux[I_VN])] - aux[WN]
        de = x[int(aux[I_VE])] - aux[WE]
        dd = x[int(aux[I_VD])]
        v_air = math.sqrt(dn * dn + de * de + dd * dd)
        dv = abs(x[int(aux[I_VC])] * v_air / x[int(aux[I_VT])] - u[U_VC_REF])
        dh = abs(x[int(aux[I_H])] - u[U_H_REF])
        dphi = abs(x[int(aux[I_PHI])] - u[U_PHI_REF]) * DEG_PER_RAD
        if dh > aux[MAX_DH]:
            aux[MAX_DH] = dh
        if dv > aux[MAX_DV]:
            aux[MAX_DV] = dv
        if dphi > aux[MAX_DPHI]:
            aux[MAX_DPHI] = dphi
    return OK


def make_aux(truth_names: Sequence[str], plan: Sequence[tuple[int, int, float | None]], n_flat: int, *,
             alpha_min_rad: float, alpha_max_rad: float, phi_max_rad: float, rate_max_radps: float,
             vc_min_kts: float, wind_north_fps: float, wind_east_fps: float) -> NDArray[np.float64]:
    """The ``aux`` array of :func:`step`.

    Parameters
    ----------
    truth_names : sequence of str
        The truth signals, in order.
    plan : sequence of (int, int, float or None)
        Per truth signal its flat reads ``[first, end)`` and factor (:meth:`Aircraft.flat_reader`).
    n_flat : int
        Flat reads in all, the AGL altitude [ft] last.
    alpha_min_rad, alpha_max_rad, phi_max_rad, rate_max_radps, vc_min_kts : float
        The scenario's limits [rad, rad/s, kt].
    wind_north_fps, wind_east_fps : float
        The steady wind [ft/s].
    """
    idx = {nm: i for i, nm in enumerate(truth_names)}
    aux = np.zeros(TABLE + 3 * len(truth_names))
    aux[[A_LO, A_HI, PHI_MAX, RATE_MAX, VC_MIN, WN, WE]] = (alpha_min_rad, alpha_max_rad, phi_max_rad, rate_max_radps,
                                                             vc_min_kts, wind_north_fps, wind_east_fps)
    for slot, nm in ((I_ALPHA, "alpha_rad"), (I_PHI, "phi_rad"), (I_P, "p_radps"), (I_Q, "q_radps"), (I_R, "r_radps"),
                     (I_VC, "vc_kts"), (I_VN, "v_north_fps"), (I_VE, "v_east_fps"), (I_VD, "v_down_fps"),
                     (I_VT, "vt_fps"), (I_H, "h_ft")):
        aux[slot] = idx[nm]
    aux[N_TRUTH], aux[N_FLAT] = len(truth_names), n_flat
    if len(plan) != len(truth_names):
        raise ValueError(f"a plan of {len(plan)} signals for {len(truth_names)} truth signals")
    for i, (a, b, f) in enumerate(plan):
        aux[TABLE + 3 * i: TABLE + 3 * i + 3] = (a, b, math.nan if f is None else f)
    return aux


def divergence_reason(code: int, x: Sequence[float], truth_names: Sequence[str], limits: object) -> str:
    """The loop's message for a divergence code of :func:`step` (``x``: the truth, ``limits``:
    the scenario's ``model.limits``)."""
    idx = {nm: i for i, nm in enumerate(truth_names)}
    if code == NONFINITE:
        bad = [truth_names[i] for i in np.flatnonzero(~np.isfinite(np.array(x[: len(truth_names)])))[:3]]
        return f"non-finite state ({', '.join(bad)})"
    if code == GROUND:
        return "ground impact"
    if code == ALPHA:
        return (f"alpha {x[idx['alpha_rad']] * DEG_PER_RAD:.1f} deg outside "
                f"[{limits.alpha_min_deg}, {limits.alpha_max_deg}]")
    if code == BANK:
        return f"bank {x[idx['phi_rad']] * DEG_PER_RAD:.1f} deg beyond {limits.phi_max_deg}"
    if code == RATE:
        return f"body rate beyond {limits.rate_max_radps} rad/s"
    if code == AIRSPEED:
        return f"airspeed {x[idx['vc_kts']]:.1f} kt below {limits.vc_min_kts}"
    raise ValueError(f"not a divergence code: {code}")


# --- the cache of step: emptied when the kernels it calls change ------------------------------------
_DEPENDENCIES = (Path(sensor_kernels.__file__), Path(pilot_kernels.__file__))


def dependency_stamp(paths: Sequence[Path] = _DEPENDENCIES) -> str:
    """SHA-256 over the source files of the compiled functions :func:`step` calls."""
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        h.update(Path(p).read_bytes())
    return h.hexdigest()


def _fresh_cache(stamp_path: Path, stamp: str, flush: Callable[[], None]) -> bool:
    """Empty the cache (``flush``) when the stamp stored at ``stamp_path`` is not ``stamp``, then
    store it; True when flushed. Where the stamp cannot be stored (a read-only install), the cache
    is flushed every time: a compilation per process, never a stale kernel."""
    try:
        if stamp_path.read_text() == stamp:
            return False
    except OSError:
        pass
    flush()
    try:
        stamp_path.parent.mkdir(parents=True, exist_ok=True)
        stamp_path.write_text(stamp)
    except OSError:
        pass
    return True


def _check_cache() -> None:
    cache = getattr(step, "_cache", None)
    path = getattr(cache, "cache_path", None)
    if cache is None or path is None:  # numba without a file cache here (NUMBA_DISABLE_JIT, another layout)
        return
    _fresh_cache(Path(path) / "_core.step.deps", dependency_stamp(), cache.flush)


_check_cache()

"""Sidar's two examples (NASA TM-84240, 1982, sec. VI, fig. 6-9) under the readings the text leaves open.

Sidar's law (eq. 22/23, :mod:`fdi_sim.detectors.adaptive_observer`) is specified, but not how the
examples were run: continuous or discrete law and its step, the observer gain, the regressor, which
output drives an unmeasured row, the initial state. :class:`SidarReading` names each choice;
:func:`simulate_sidar` runs one reading for a batch of gain rows at once (vectorised, so gain grids
are cheap); :func:`sidar_bars` measures the numerical statements of sec. VI on every row. The study
and what reproduces are in docs/observers.md (Sidar section). Parameters are named (a, b) or
(a, b, c) with ``a = -A[0,0]``, ``b = B[-1]``, ``c = -A[1,0]``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.signal import place_poles

from fdi_sim.errors import DesignError

Array = NDArray[np.float64]

SIDAR_STEP_S = 0.05  # "after 8 sec. (160 steps)" (sec. VI a): Sidar's step


@dataclass(frozen=True)
class SidarReading:
    """One reading of what Sidar's sec. VI leaves open; the defaults are the literal text.

    Attributes
    ----------
    law : {"continuous", "sampled", "euler", "euler_observer"}
        ``"continuous"``: eq. 22, plant, observer and parameters integrated together (RK4), gains
        in [1/s]. The others apply eq. 23 once per ``step_s`` with per-step gains:
        ``"sampled"`` integrates plant and observer continuously in between with the matrices
        held; ``"euler"`` steps plant and observer by forward Euler; ``"euler_observer"`` steps
        only the observer by Euler on the samples of the exactly integrated plant (the two
        discretisations differ, so the true parameters are not an equilibrium of the law).
    regressor : {"x_hat", "x"}
        ``x_hat`` in eq. 22a as printed, or the true state (not measurable; a check).
    gain_design : {"initial", "true"}
        K places the stated poles for ``A(theta_hat(0))`` or for the true ``A(theta(0))``.
    outputs : {"own", "all"}
        Which outputs drive each parameter: ``"own"`` is ``M = g C^+`` (a from y1, c from y2,
        b from ``b_from``); ``"all"`` is every entry of M and N equal to the gain ("all unity").
    b_from : {"y2", "y1", "y1+y2"}
        Example 2 with ``outputs="own"``: the output error that drives b (x3 is not measured).
    full_matrices : bool
        Adapt every entry of ``A0`` and ``B0`` (M, N all gain) instead of only a, b, c.
    normalized : bool
        Divide the updates by ``1 + |x_hat|^2 + |u|^2`` (not in the paper).
    x_hat0 : tuple of float or None
        Observer initial state; None is the printed one.
    start_matched : bool
        Observer starts at the true parameters and state (the tracking runs' ramps start at 1 s).
    adapt_c : bool
        Example 2: adapt c (else held at its true value).
    step_s : float
        Step of the discrete laws [s].
    update : {"own_sample", "next_sample"}
        When a discrete law applies the eq. 23 update computed from the samples at ``t_k``:
        ``"own_sample"`` (eq. 23 read as ``A0(k) = A0(k-1) + M eps(k) xh(k)'``, used over
        ``[t_k, t_k+1]``) or ``"next_sample"`` (held until ``t_k+1``, one step late: the
        module's law before issue 12; it gives the old sampled row, 0.141 / 297 % on fig. 6).
    """

    law: Literal["continuous", "sampled", "euler", "euler_observer"] = "continuous"
    regressor: Literal["x_hat", "x"] = "x_hat"
    gain_design: Literal["initial", "true"] = "initial"
    outputs: Literal["own", "all"] = "own"
    b_from: Literal["y2", "y1", "y1+y2"] = "y2"
    full_matrices: bool = False
    normalized: bool = False
    x_hat0: tuple[float, ...] | None = None
    start_matched: bool = False
    adapt_c: bool = True
    step_s: float = SIDAR_STEP_S
    update: Literal["own_sample", "next_sample"] = "own_sample"


@dataclass(frozen=True)
class SidarBatch:
    """Sidar's example run for G gain rows of one reading.

    Attributes
    ----------
    example : int
    tracking : bool
    reading : SidarReading
    gains : NDArray
        (G, q) per-parameter gains in ``names`` order ([1/s] continuous, per step otherwise).
    t_s : NDArray
        (T,) record times [s].
    output_error_norm : NDArray
        (G, T) ``|eps(t)|`` (eq. 4); NaN after a run diverged (``|A0| > 1e4``).
    params_hat : NDArray
        (G, T, q) estimates.
    params_true : NDArray
        (T, q) plant parameters.
    names : tuple of str
    """

    example: int
    tracking: bool
    reading: SidarReading
    gains: Array
    t_s: Array
    output_error_norm: Array
    params_hat: Array
    params_true: Array
    names: tuple[str, ...]


def sidar_ramp(t_s: float, start: float, t_on_s: float, rate_per_s: float, t_off_s: float = 12.0) -> float:
    """Sidar's fig. 7 ramps: ``start`` until ``t_on``, then ``+rate`` per second until ``t_off``, then held."""
    return start + rate_per_s * (min(max(t_s, t_on_s), t_off_s) - t_on_s)


def _sidar_u(t_s: float) -> float:
    return float(np.sin(np.pi * t_s) + np.cos(t_s) / 3.0)  # u = sin(pi t) + cos(t)/3 (sec. VI a)


def _sidar_AB(example: int, p: NDArray) -> tuple[Array, Array]:
    """``A(theta)``, ``b(theta)`` for (..., q) parameters: ex. 1 ``[[-a, 1], [0, 0]]``, ex. 2 ``[[-a, 1, 0], [-c, 0, 1], [0, 0, 0]]``."""
    p = np.asarray(p, float)
    n = example + 1
    A = np.zeros(p.shape[:-1] + (n, n))
    A[..., 0, 0] = -p[..., 0]
    A[..., np.arange(n - 1), np.arange(1, n)] = 1.0
    if example == 2:
        A[..., 1, 0] = -p[..., 2]
    B = np.zeros(p.shape[:-1] + (n,))
    B[..., -1] = p[..., 1]
    return A, B


def _sidar_spec(example: int) -> dict:
    if example == 1:  # sec. VI (a)
        return dict(theta=np.array([1.0, 2.0]), theta_hat=np.array([1.5, 1.5]), poles=[-5 + 5j, -5 - 5j],
                    C=np.array([[1.0, 0.0]]), x=np.array([1.0, 0.0]), x_hat=np.array([0.8, 1.0]), names=("a", "b"))
    if example == 2:  # sec. VI (b)
        return dict(theta=np.array([1.0, 1.0, 3.0]), theta_hat=np.array([0.5, 0.5, 2.0]), poles=[-10.0, -8 + 8j, -8 - 8j],
                    C=np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), x=np.array([1.0, 0.0, 0.0]),
                    x_hat=np.array([0.5, 1.0, 1.0]), names=("a", "b", "c"))
    raise DesignError(f"Sidar has examples 1 and 2, not {example!r}")


def sidar_gain_matrices(example: int, gains: NDArray, reading: SidarReading = SidarReading()) -> tuple[Array, Array, NDArray[np.bool_], NDArray[np.bool_]]:
    """M, N (eq. 22) and the adapted entries for per-parameter gains ``(g_a, g_b[, g_c])``.

    Returns
    -------
    M, N : (n, m) arrays
    mask_A : (n, n) bool
    mask_B : (n,) bool
    """
    g = np.asarray(gains, float)
    n = example + 1
    m = example
    M, N = np.zeros((n, m)), np.zeros((n, m))
    if reading.full_matrices or reading.outputs == "all":
        M[:], N[:] = g[0], g[1]  # one gain for every entry (example 1: m, n); example 2 uses c's gain on row 2
        if example == 2:
            M[1, :] = g[2]
    else:
        M[0, 0] = g[0]  # a: row 1 of A, driven by y1
        if example == 1:
            N[1, 0] = g[1]
        else:
            M[1, 1] = g[2]  # c: row 2 of A, driven by y2
            N[2, :] = {"y2": (0.0, g[1]), "y1": (g[1], 0.0), "y1+y2": (g[1], g[1])}[reading.b_from]
    mask_A = np.ones((n, n), bool) if reading.full_matrices else np.zeros((n, n), bool)
    mask_B = np.ones(n, bool) if reading.full_matrices else np.zeros(n, bool)
    mask_A[0, 0] = mask_B[-1] = True
    if example == 2 and reading.adapt_c:
        mask_A[1, 0] = True
    return M, N, mask_A, mask_B


def _rk4(f: Callable[[float, tuple], tuple], t: float, z: tuple, h: float) -> tuple:
    """One classical Runge-Kutta step of ``dz/dt = f(t, z)`` for a tuple of arrays."""
    k1 = f(t, z)
    k2 = f(t + h / 2, tuple(a + h / 2 * b for a, b in zip(z, k1)))
    k3 = f(t + h / 2, tuple(a + h / 2 * b for a, b in zip(z, k2)))
    k4 = f(t + h, tuple(a + h * b for a, b in zip(z, k3)))
    return tuple(a + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4) for a, b1, b2, b3, b4 in zip(z, k1, k2, k3, k4))


def simulate_sidar(
    example: Literal[1, 2], gains: NDArray, tracking: bool = False, reading: SidarReading = SidarReading(),
    t_end_s: float = 12.0, h_s: float = 0.0025, record_dt_s: float = 0.01,
) -> SidarBatch:
    """Sidar's example 1 (fig. 6, 7) or 2 (fig. 8, 9) under one reading, for G gain rows at once.

    Example 1: ``dx1 = -a x1 + x2``, ``dx2 = b u``, ``y = x1``; a = 1, b = 2, estimates from 1.5,
    1.5; poles -5 +- 5j; ``u = sin(pi t) + cos(t)/3``; ``x(0) = (1, 0)``, ``x_hat(0) = (0.8, 1)``.
    Example 2: ``dx1 = -a x1 + x2``, ``dx2 = x3 - c x1``, ``dx3 = b u``, ``y = (x1, x2)``; a = 1,
    b = 1, c = 3 from 0.5, 0.5, 2; poles -10, -8 +- 8j; the same u (example 2 states none);
    ``x(0) = (1, 0, 0)``, ``x_hat(0) = (0.5, 1, 1)``. Tracking: a ramps +0.2/s over 1-12 s and b
    +0.2/s over 4-12 s (fig. 7; "as in the first example" for fig. 9).

    Parameters
    ----------
    example : {1, 2}
    gains : (G, q) or (q,) array
        Per-parameter gains (a, b[, c]): Sidar's m, n ([1/s] for the continuous law, per step for the others).
    tracking : bool
        The ramps of fig. 7 / 9.
    reading : SidarReading
    t_end_s : float
        Run length [s].
    h_s : float
        RK4 step [s] (continuous law; substep of the sampled law).
    record_dt_s : float
        Record interval [s] of the continuous law (the discrete laws record every step).
    """
    sp = _sidar_spec(example)
    g = np.atleast_2d(np.asarray(gains, float))
    G, q = g.shape
    if q != len(sp["names"]):
        raise DesignError(f"example {example} has {len(sp['names'])} gains {sp['names']}, got {q}")
    rd = reading
    C, n = sp["C"], example + 1
    th0 = sp["theta"]
    th_hat0 = th0 if rd.start_matched else sp["theta_hat"]
    xh_init = sp["x"] if rd.start_matched else np.asarray(sp["x_hat"] if rd.x_hat0 is None else rd.x_hat0, float)

    def theta(t: float) -> Array:
        if not tracking:
            return th0
        p = th0.copy()
        p[0], p[1] = sidar_ramp(t, th0[0], 1.0, 0.2), sidar_ramp(t, th0[1], 4.0, 0.2)
        return p

    K = place_poles(_sidar_AB(example, th_hat0 if rd.gain_design == "initial" else th0)[0].T, C.T, sp["poles"]).gain_matrix.T
    mats = [sidar_gain_matrices(example, gr, rd) for gr in g]
    M, N = np.stack([m[0] for m in mats]), np.stack([m[1] for m in mats])
    mask_A, mask_B = mats[0][2], mats[0][3]
    A0, B0 = _sidar_AB(example, np.broadcast_to(th_hat0, (G, q)))
    A0 = A0.copy()
    B0 = B0.copy()
    x = sp["x"].copy()
    xh = np.broadcast_to(xh_init, (G, n)).copy()

    def plant(t: float, xx: Array) -> Array:
        A, B = _sidar_AB(example, theta(t))
        return A @ xx + B * _sidar_u(t)

    def observer(t: float, xx: Array, xhh: Array, A0_: Array, B0_: Array) -> Array:
        eps = C @ xx - xhh @ C.T  # eq. 4, (G, m)
        return np.einsum("gij,gj->gi", A0_, xhh) + B0_ * _sidar_u(t) + eps @ K.T  # eq. 2 with A0, B0

    def adapt(t: float, xx: Array, xhh: Array) -> tuple[Array, Array]:
        """eq. 22/23 increments ``M eps r'``, ``N eps u'`` on the adapted entries."""
        eps, u = C @ xx - xhh @ C.T, _sidar_u(t)
        r = np.broadcast_to(xx, xhh.shape) if rd.regressor == "x" else xhh
        s = 1.0 / (1.0 + np.sum(r * r, axis=1) + u * u) if rd.normalized else np.ones(G)
        Me, Ne = np.einsum("gij,gj->gi", M, eps) * s[:, None], np.einsum("gij,gj->gi", N, eps) * s[:, None]
        return Me[:, :, None] * r[:, None, :] * mask_A, Ne * u * mask_B

    def full(t: float, z: tuple) -> tuple:  # eq. 22: plant, observer and parameters together
        return (plant(t, z[0]), observer(t, *z), *adapt(t, z[0], z[1]))

    ts, E, P = [], [], []
    law_steps = {"continuous": (h_s, 1), "sampled": (rd.step_s, max(1, round(rd.step_s / h_s))),
                 "euler": (rd.step_s, 1), "euler_observer": (rd.step_s, max(1, round(rd.step_s / h_s)))}
    if rd.law not in law_steps:
        raise DesignError(f"unknown law {rd.law!r}: one of {sorted(law_steps)}")
    if rd.update not in ("own_sample", "next_sample"):
        raise DesignError(f"unknown update {rd.update!r}: 'own_sample' or 'next_sample'")
    T, sub = law_steps[rd.law]
    every = max(1, round(record_dt_s / T)) if rd.law == "continuous" else 1
    for k in range(int(round(t_end_s / T)) + 1):
        t = k * T
        if k % every == 0:
            ts.append(t)
            E.append(np.linalg.norm(C @ x - xh @ C.T, axis=1))
            P.append(np.stack([-A0[:, 0, 0], B0[:, -1]] + ([-A0[:, 1, 0]] if example == 2 else []), axis=1))
        if t >= t_end_s - 1e-9:
            break
        if rd.law == "continuous":
            x, xh, A0, B0 = _rk4(full, t, (x, xh, A0, B0), T)
        else:
            dA, dB = adapt(t, x, xh)  # eq. 23 from the samples at t_k
            if rd.update == "own_sample":  # A0(k) = A0(k-1) + M eps(k) xh(k)', flown over [t_k, t_k+1]
                A0, B0 = A0 + dA, B0 + dB
            h = T / sub
            if rd.law == "sampled":  # plant and observer together, A0, B0 held over the step
                for j in range(sub):
                    x, xh = _rk4(lambda tt, z: (plant(tt, z[0]), observer(tt, z[0], z[1], A0, B0)), t + j * h, (x, xh), h)
            else:
                xh = xh + T * observer(t, x, xh, A0, B0)  # forward Euler on the samples y(t_k), u(t_k)
                if rd.law == "euler":
                    x = x + T * plant(t, x)
                else:  # euler_observer: the plant exact
                    for j in range(sub):
                        (x,) = _rk4(lambda tt, z: (plant(tt, z[0]),), t + j * h, (x,), h)
            if rd.update == "next_sample":  # held over the step, applied at t_k+1
                A0, B0 = A0 + dA, B0 + dB
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(A0).max(axis=(1, 2)) <= 1e4)  # diverged (or NaN): frozen at NaN
        A0[bad], B0[bad], xh[bad] = np.nan, np.nan, np.nan
    t_arr = np.array(ts)
    return SidarBatch(example, tracking, rd, g, t_arr, np.array(E).T, np.transpose(np.array(P), (1, 0, 2)),
                      np.array([theta(t) for t in t_arr]), sp["names"])


@dataclass(frozen=True)
class SidarBar:
    """One numerical statement of Sidar's sec. VI, measured on a batch.

    Attributes
    ----------
    figure : int
    text : str
        The statement, with the measure used.
    limit : float
        The paper's bound.
    measured : NDArray
        (G,) the measure per gain row (inf for a diverged run).
    """

    figure: int
    text: str
    limit: float
    measured: Array

    @property
    def met(self) -> NDArray[np.bool_]:
        """(G,) ``measured < limit``."""
        return self.measured < self.limit


def sidar_bars(run: SidarBatch) -> tuple[SidarBar, ...]:
    """The statements of sec. VI for the run's figure (6, 7, 8 or 9), measured on every gain row.

    Relative parameter error: fig. 6, 7 the largest ``|theta_i_hat - theta_i| / |theta_i|`` ("a0
    and b0 converged ... within 95 %"); fig. 8, 9 ``|theta_hat - theta| / |theta|`` ("the norm of
    the error vector"). Tracking windows start after fig. 6's / 8's settling time (3.5 s / 2.75 s)
    and end with the ramps (12 s).
    """
    t, E = run.t_s, run.output_error_norm
    d = run.params_hat - run.params_true[None]
    rel_max = np.max(np.abs(d) / np.abs(run.params_true[None]), axis=2)
    rel_norm = np.linalg.norm(d, axis=2) / np.linalg.norm(run.params_true, axis=1)[None]

    def worst(X: Array, t0: float, t1: float = np.inf) -> Array:
        sel = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        if not sel.any():
            raise DesignError(f"the run ends at {t[-1]:.3g} s, the statement needs {t0:.3g} s")
        out = np.max(X[:, sel], axis=1)
        return np.where(np.isfinite(out), out, np.inf)

    fig = {(1, False): 6, (1, True): 7, (2, False): 8, (2, True): 9}[(run.example, run.tracking)]
    if fig == 6:
        return (SidarBar(6, "|eps| for t >= 3.5 s", 4e-3, worst(E, 3.5)),
                SidarBar(6, "max_i |rel. error of a, b| for t >= 8 s", 0.05, worst(rel_max, 8.0)))
    if fig == 7:
        return (SidarBar(7, "|eps| while tracking (3.5-12 s)", 2.5e-2, worst(E, 3.5, 12.0)),
                SidarBar(7, "|eps| for t >= 13 s", 4e-3, worst(E, 13.0)),
                SidarBar(7, "max_i |rel. error| at 13 s", 0.10, worst(rel_max, 13.0, 13.0)),
                SidarBar(7, "max_i |rel. error| at the end (steady state)", 0.02, worst(rel_max, t[-1])))
    if fig == 8:
        return (SidarBar(8, "|eps| for t >= 2.75 s", 5e-2, worst(E, 2.75)),
                SidarBar(8, "|theta error| / |theta| for t >= 10 s", 0.10, worst(rel_norm, 10.0)))
    return (SidarBar(9, "|eps| while tracking (2.75-12 s)", 2e-2, worst(E, 2.75, 12.0)),
            SidarBar(9, "|eps| for t >= 13.4 s", 1e-2, worst(E, 13.4)),
            SidarBar(9, "|theta error| / |theta| for t >= 14.5 s", 0.10, worst(rel_norm, 14.5)))


def run_sidar_example(
    example: Literal[1, 2], tracking: bool = False, gains: NDArray | None = None, reading: SidarReading = SidarReading(),
    t_end_s: float | None = None,
) -> SidarBatch:
    """One run of :func:`simulate_sidar`: Sidar's stated gains by default (example 1: m = 10 for a,
    n = 5 for b; example 2: all unity), 12 s (20 s tracking) unless ``t_end_s`` is given."""
    g = np.asarray(([10.0, 5.0] if example == 1 else [1.0, 1.0, 1.0]) if gains is None else gains, float)
    return simulate_sidar(example, g, tracking, reading, t_end_s or (20.0 if tracking else 12.0))

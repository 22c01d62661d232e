"""LMI-optimal detection filters (Miller & Ribbens, US 6,643,569 B2, App. B, Theorems 5.2.2 and 5.3.2).

The LQ estimator ``L = P C' V^-1`` of ``dx/dt = A x + B u + G w``, ``y = C x + v`` is posed as an
LMI in ``P = P' > 0``, ``W = W' > 0`` and the detection-space eigenvalue(s) ``Lambda``
(seed ``002_d6038a6910cf5866.txt``):

* eq. 42 (the Riccati LMI, eq. 27):  ``[[A P + P A' + G W G', P C'], [C P, V]] >= 0``
* eq. 43 (poles no faster than -h):  ``[[A P + P A' + 2 h P, P C'], [C P, V/2]] > 0``
* eq. 44 (eigenvector alignment):    ``[[eps I, R'], [R, I]] > 0``, ``R = X_cl Lambda - (A - L C) X_cl``
* objective eq. 41: ``max x0' P x0`` (``trace P`` when no ``x0`` is given).

``method="least-squares"`` is Theorem 5.2.2. ``method="direct"`` is Theorem 5.3.2: its
parameterisation ``L = P C' = L_0 + X_cl L_j C_p + L_k C_p^perp`` with symmetric ``P`` (eq. 74-77,
89-94) is exactly the set of symmetric ``P`` with ``(A - P C' V^-1 C) X_cl = X_cl Lambda``, so it is
solved here as eq. 42-43 plus that linear equality (``eps = 0``); the patent states it for
``V = I``, which this form does not need.

Every solution is checked numerically before it is returned: solver status, ``P > 0``, closed-loop
poles inside ``-h <= Re s < 0``, alignment residual ``<= sqrt(eps)``, the sensitivity bound
``sigma_max(V^-1/2 S(jw) V^1/2) <= 1`` on a frequency grid (eq. 57) and the implied process noise
``Q~ = P C'V^-1 C P - A P - P A' >= 0`` that makes ``L`` an LQ gain (Theorem 5.3.1). A failed check
raises :class:`~fdi_sim.errors.DesignError`; a gain is never returned silently wrong.

The runtime :class:`LmiDetectionFilter` discretizes the continuous observer (zero-order hold on
``u`` and ``y``) at the detector rate and runs it as a
:class:`~fdi_sim.detectors.directional_observer.DirectionalObserver`.
"""
from __future__ import annotations

import hashlib
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from fdi_sim.detectors.beard_jones import angle_rad, check_observable, detection_space
from fdi_sim.detectors.beard_jones_filter import fault_directions_from_model
from fdi_sim.detectors.directional_observer import DirectionalObserver, DiscreteObserver
from fdi_sim.detectors.kalman import observer_residual_covariance
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

Array = NDArray[np.float64]

# ----------------------------------------------------------------------------- design


@dataclass(frozen=True)
class LmiFilterDesign:
    """Result of :func:`lmi_detection_gain`, with the checks made on it.

    Attributes
    ----------
    L : NDArray
        (n, m) gain ``P C' V^-1``.
    P, W : NDArray
        The LMI solution (``W`` is the solver's; ``Q_implied`` is the one that makes ``L`` exact).
    Lambda : NDArray
        (k, k) eigenvalue block on the detection space [1/s].
    A_cl : NDArray
        ``A - L C``.
    poles : NDArray
        Closed-loop eigenvalues [1/s].
    X_cl : NDArray
        (n, k) orthonormal desired detection space.
    method : str
        ``"least-squares"`` (Thm 5.2.2) or ``"direct"`` (Thm 5.3.2).
    epsilon : float
        Alignment bound of eq. 44 (0 for ``direct``).
    h_radps : float
        Pole bound h [1/s] of eq. 43.
    alignment_residual : float
        ``||X_cl Lambda - A_cl X_cl||_2`` in the scaled coordinates of the solve.
    alignment_constraint : float
        The norm eq. 44 bounds by ``sqrt(epsilon)``: the residual above (``literal``) or
        ``sqrt(R' P^-1 R)`` (information form).
    alignment_error_deg : float
        Largest principal angle between ``X_cl`` and the closed-loop invariant subspace it should be [deg].
    max_sensitivity : float
        ``max_w sigma_max(V^-1/2 S(jw) V^1/2)`` on ``omega_radps`` (eq. 57 says <= 1).
    omega_radps : NDArray
        The frequency grid [rad/s].
    riccati_residual : float
        ``||A P + P A' + G W G' - P C'V^-1 C P|| / ||G W G'||`` (0 when eq. 42 is tight).
    q_implied_min_eig : float
        Smallest eigenvalue of ``Q~ = P C'V^-1 C P - A P - P A'`` relative to ``||Q~||`` (>= 0 required).
    objective : float
        ``trace P`` or ``x0' P x0``.
    solver, status : str
        cvxpy solver name and status.
    solve_time_s : float
        Wall time of the solve [s].
    """

    L: Array
    P: Array
    W: Array
    Lambda: Array
    A_cl: Array
    poles: NDArray[np.complex128]
    X_cl: Array
    method: str
    epsilon: float
    h_radps: float
    alignment_residual: float
    alignment_constraint: float
    alignment_error_deg: float
    max_sensitivity: float
    omega_radps: Array
    riccati_residual: float
    q_implied_min_eig: float
    objective: float
    solver: str
    status: str
    solve_time_s: float


def sensitivity_max_sv(A: Array, C: Array, L: Array, V: Array, omega_radps: Array) -> Array:
    """``sigma_max(V^-1/2 S(jw) V^1/2)`` with ``S = (I + C (jwI - A)^-1 L)^-1 = I - C (jwI - A + LC)^-1 L``.

    Parameters
    ----------
    A, C, L : arrays
        Model and observer gain.
    V : (m, m) array
        Measurement-noise intensity (the weighting of eq. 56-57).
    omega_radps : (N,) array
        Frequencies [rad/s].
    """
    n, m = A.shape[0], C.shape[0]
    Acl = A - L @ C
    Vh = sla.sqrtm(V).real
    Vhi = np.linalg.inv(Vh)
    out = np.empty(len(omega_radps))
    for i, w in enumerate(omega_radps):
        S = np.eye(m) - C @ np.linalg.solve(1j * w * np.eye(n) - Acl, L)
        out[i] = np.linalg.svd(Vhi @ S @ Vh, compute_uv=False)[0]
    return out


def alignment_error_deg(A_cl: Array, X_cl: Array, Lam: Array) -> float:
    """Largest principal angle [deg] between ``X_cl`` and the closed-loop invariant subspace matching it.

    k = 1: the smallest angle between ``x_cl`` and a real eigenvector of ``A_cl`` (a complex pair
    cannot hold a fixed direction). k > 1: the span of the eigenvectors whose eigenvalues are
    closest to ``eig(Lambda)``.
    """
    ev, vec = np.linalg.eig(A_cl)
    k = X_cl.shape[1]
    if k == 1:
        real = [i for i in range(len(ev)) if abs(ev[i].imag) <= 1e-9 * max(1.0, abs(ev[i]))]
        if not real:
            return 90.0
        return float(np.degrees(min(angle_rad(X_cl[:, 0], vec[:, i].real) for i in real)))
    used: list[int] = []
    for lam in np.linalg.eigvals(Lam):
        order = np.argsort(np.abs(ev - lam))
        used.append(int(next(j for j in order if j not in used)))
    cols = np.column_stack([np.column_stack([vec[:, j].real, vec[:, j].imag]) for j in used])
    basis = sla.orth(cols)
    return float(np.degrees(np.max(sla.subspace_angles(X_cl, basis))))


Method = Literal["least-squares", "direct", "literal"]


def _scaling(C: Array, V: Array) -> tuple[Array, Array]:
    """State scaling ``T`` (diagonal) and output whitening ``V^-1/2`` used to condition the LMI.

    ``y~ = V^-1/2 y`` has unit noise; ``x = T x~`` gives the columns of ``V^-1/2 C T`` unit norm
    (states no sensor sees keep scale 1).
    """
    Vih = np.linalg.inv(sla.sqrtm(V).real)
    Cw = Vih @ C
    norms = np.linalg.norm(Cw, axis=0)
    t = np.where(norms > 1e-12 * max(norms.max(), 1e-300), 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    return np.diag(t), Vih


def _solve_y(A: Array, C: Array, x: Array, lam: float, h: float, eps: float, method: str, obj_w: Array,
             solver: str, margin: float) -> tuple[str, float, Array | None]:
    """One convex problem in ``Y = P^-1`` for a fixed detection eigenvalue ``lam`` (V = I, scaled).

    ``N = C'C - Y A - A'Y >= 0``      <=> implied ``Q~ = P N P >= 0`` (eq. 42 tight: an exact ARE)
    ``Y A + A'Y - 2 C'C + 2 h Y > 0`` <=> eq. 43 after the congruence with ``Y``
    ``R_Y = lam Y x - Y A x + C'C x``  = ``Y R``, ``R = (lam I - A + L C) x`` (eq. 29);
    eq. 44 becomes ``R' Y R <= eps``, i.e. ``[[eps, R_Y'], [R_Y, Y]] >= 0``
    Objective ``min trace(obj_w Y)`` (the largest ``P``, eq. 41, in information form).
    """
    import cvxpy as cp

    n = A.shape[0]
    Y = cp.Variable((n, n), symmetric=True)
    CtC = C.T @ C
    YA = Y @ A
    N = CtC - YA - YA.T
    pole = YA + YA.T - 2 * CtC + 2 * h * Y
    Ry = lam * (Y @ x) - YA @ x + CtC @ x
    cons = [Y >> margin * np.eye(n), 0.5 * (N + N.T) >> 0, 0.5 * (pole + pole.T) >> margin * np.eye(n)]
    if method == "direct":
        cons.append(Ry == 0)
    else:
        # R' Y R <= eps with R = P R_Y: [[eps, R_Y'], [R_Y, Y]] >= 0 (Schur), eq. 44 in the Y metric
        ali = cp.bmat([[eps * np.eye(1), cp.reshape(Ry, (1, n), order="F")], [cp.reshape(Ry, (n, 1), order="F"), Y]])
        cons.append(0.5 * (ali + ali.T) >> 0)
    prob = cp.Problem(cp.Minimize(cp.trace(obj_w @ Y)), cons)
    try:
        with warnings.catch_warnings():  # line-search points may be inaccurate; the chosen one is checked
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=solver)
    except cp.error.SolverError:
        return "solver_error", np.inf, None
    return prob.status, float(prob.value) if prob.value is not None else np.inf, Y.value


def _solve_literal(A: Array, C: Array, X: Array, G: Array, h: float, eps: float, obj_w: Array, solver: str,
                   margin: float) -> tuple[str, float, Array | None, Array | None, Array | None]:
    """Theorem 5.2.2 exactly as posed (eq. 41-44, V = I after scaling): variables P, W, Lambda."""
    import cvxpy as cp

    n, m, k = A.shape[0], C.shape[0], X.shape[1]
    P = cp.Variable((n, n), symmetric=True)
    W = cp.Variable((G.shape[1], G.shape[1]), symmetric=True)
    Lam = cp.Variable((k, k))
    AP = A @ P
    ric = cp.bmat([[AP + AP.T + G @ W @ G.T, P @ C.T], [C @ P, np.eye(m)]])  # eq. 42
    pole = cp.bmat([[AP + AP.T + 2 * h * P, P @ C.T], [C @ P, np.eye(m) / 2]])  # eq. 43
    Rm = X @ Lam - A @ X + P @ C.T @ C @ X  # (Lambda I - A + P C' V^-1 C) X_cl  (eq. 29)
    ali = cp.bmat([[eps * np.eye(k), Rm.T], [Rm, np.eye(n)]])  # eq. 44
    cons = [P >> margin * np.eye(n), W >> margin * np.eye(G.shape[1]), 0.5 * (ric + ric.T) >> 0,
            0.5 * (pole + pole.T) >> margin * np.eye(n + m), 0.5 * (ali + ali.T) >> 0]
    prob = cp.Problem(cp.Maximize(cp.trace(obj_w @ P)), cons)
    try:
        prob.solve(solver=solver)
    except cp.error.SolverError:
        return "solver_error", -np.inf, None, None, None
    return prob.status, float(prob.value) if prob.value is not None else -np.inf, P.value, W.value, Lam.value


def _solve_information_form(A: Array, C: Array, x: Array, G: Array, h: float, eps: float, method: str, obj_w: Array,
                            solver: str, margin: float, n_lambda: int) -> tuple[str, float, Array, Array, Array]:
    """Theorem 5.2.2 / 5.3.2 in ``Y = P^-1`` (scaled, V = I) with a line search over the detection eigenvalue.

    ``n_lambda`` grid points over ``(-h, 0)``, then 10 golden-section steps between the best point's
    neighbours; returns status, objective, ``P``, ``W`` (``G W G' = Q~``, the implied process noise)
    and ``Lambda`` of the best feasible ``lambda``.
    """
    best: tuple[float, float, Array | None, str] = (np.inf, np.nan, None, "infeasible")

    def f(lam: float) -> float:
        nonlocal best
        st, v, Yv = _solve_y(A, C, x, lam, h, eps, method, obj_w, solver, margin)
        ok = st in ("optimal", "optimal_inaccurate") and Yv is not None
        if ok and v < best[0]:
            best = (v, lam, Yv, st)
        return v if ok else np.inf

    grid = -h * np.geomspace(1e-3, 1.0 - 1e-3, n_lambda)
    vals = [f(lam) for lam in grid]
    i = int(np.argmin(vals))
    if np.isfinite(vals[i]):  # golden section on [grid[i+1], grid[i-1]] (the grid is decreasing)
        a, b = grid[min(i + 1, n_lambda - 1)], grid[max(i - 1, 0)]
        gr = (np.sqrt(5) - 1) / 2
        c, d = b - gr * (b - a), a + gr * (b - a)
        fc, fd = f(c), f(d)
        for _ in range(10):
            if fc < fd:
                b, d, fd = d, c, fc
                c = b - gr * (b - a)
                fc = f(c)
            else:
                a, c, fc = c, d, fd
                d = a + gr * (b - a)
                fd = f(d)
    val, lam_best, Yv, status = best
    if Yv is None:
        raise DesignError(
            f"LMI ({method}) is infeasible for every detection eigenvalue in (-{h}, 0) 1/s with epsilon = {eps}: "
            "no LQ detection filter with these bounds. Increase h (allow faster poles) or epsilon (looser alignment)."
        )
    Y = 0.5 * (Yv + Yv.T)
    if np.min(np.linalg.eigvalsh(Y)) <= 0:
        raise DesignError(f"LMI ({method}) returned a Y that is not positive definite; try solver='SCS'")
    P = np.linalg.inv(Y)
    Q = P @ (C.T @ C - Y @ A - A.T @ Y) @ P  # implied process noise Q~ = P N P
    W = np.linalg.lstsq(G, np.linalg.lstsq(G, Q, rcond=None)[0].T, rcond=None)[0].T  # G W G' = Q~
    return status, val, P, W, np.array([[lam_best]])


#: solved designs by their inputs (:func:`_gain_key`), the most recent :data:`MEMO_SIZE`: the SDP line
#: search costs 3-4 s and a study worker designs the same filter for every run of a design point (an
#: every-detector bench run spent more on it than on its flight, session 22); the solution is a
#: function of its inputs only, so a repeat returns the same design
_GAIN_MEMO: OrderedDict[str, LmiFilterDesign] = OrderedDict()
MEMO_SIZE = 32


def _gain_key(arrays: tuple[NDArray | None, ...], options: tuple[object, ...]) -> str:
    h = hashlib.sha256(repr(options).encode())
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.ascontiguousarray(a, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def lmi_detection_gain(
    A: NDArray,
    C: NDArray,
    X_cl: NDArray,
    G: NDArray,
    V: NDArray,
    h_radps: float,
    epsilon: float = 1e-7,
    method: Method = "least-squares",
    x0: NDArray | None = None,
    omega_radps: NDArray | None = None,
    solver: str = "CLARABEL",
    n_lambda: int = 12,
    margin: float = 1e-7,
) -> LmiFilterDesign:
    """Solve the LMI-optimal detection filter of App. B (Theorem 5.2.2 or 5.3.2) and check it.

    The problem is solved in scaled coordinates (``V^-1/2`` on the outputs, diagonal ``T`` on the
    states, :func:`_scaling`), so ``epsilon`` and the objective refer to the scaled system.

    ``method="literal"`` poses eq. 41-44 as printed, with ``P``, ``W`` and ``Lambda`` free. With
    ``W`` free, the maximal ``P`` is in general *not* a Riccati solution (eq. 42 is not tight), so
    the LQ robustness ``||S|| <= 1`` is lost and :func:`_check` rejects it (see docs/observers.md).
    ``"least-squares"`` and ``"direct"`` therefore use the information form ``Y = P^-1``, where the
    implied process noise ``Q~ = P C'V^-1 C P - A P - P A' >= 0`` (the condition for ``L`` to be an
    LQ gain, Theorem 5.3.1) is the *linear* constraint ``C'V^-1 C - Y A - A'Y >= 0`` and eq. 43
    becomes ``Y A + A'Y - 2 C'V^-1 C + 2 h Y > 0``. The alignment residual is bilinear in
    ``(Y, lambda)``, so the detection eigenvalue ``lambda`` is found by a line search over
    ``(-h, 0)`` (``n_lambda`` points, then golden-section refinement); only a one-dimensional
    detection space (k = 1) is supported there. ``G`` must then have full row rank (``W = Q~``).

    Parameters
    ----------
    A : (n, n) array
        Continuous-time state matrix [1/s].
    C : (m, n) array
    X_cl : (n, k) array
        Desired detection space (columns), e.g. ``detection_space(...).basis``.
    G : (n, q) array
        Process-noise input matrix.
    V : (m, m) array
        Measurement-noise intensity, symmetric positive definite.
    h_radps : float
        Pole bound h > 0 [1/s]: all poles in ``-h <= Re s < 0`` (eq. 35-37).
    epsilon : float
        Alignment bound of eq. 29-30 (not used by ``direct``).
    method : {"least-squares", "direct", "literal"}
        See above.
    x0 : (n,) array, optional
        Objective weight ``x0 x0'`` (eq. 41); default identity (``trace``).
    omega_radps : array, optional
        Frequency grid for the sensitivity check; default 400 points over 1e-3 .. 1e3 rad/s.
    solver : str
        cvxpy solver (``"CLARABEL"`` or ``"SCS"``).
    n_lambda : int
        Grid points of the lambda line search.
    margin : float
        Strictness margin of the ``> 0`` constraints (scaled problem).

    Raises
    ------
    DesignError
        Bad shapes or values, unobservable ``(A, C)``, infeasible or unsolved LMI, or a solution
        that fails any numerical check (the message gives the failing numbers).

    Notes
    -----
    A solved design is kept in memory (the last :data:`MEMO_SIZE`, keyed by every input's bits) and
    returned again, read-only, for the same inputs; a refusal is not kept.
    """
    key = _gain_key((A, C, X_cl, G, V, x0, omega_radps), (float(h_radps), float(epsilon), method, solver,
                                                          int(n_lambda), float(margin)))
    if key in _GAIN_MEMO:
        _GAIN_MEMO.move_to_end(key)
        return _GAIN_MEMO[key]
    design = _solve_gain(A, C, X_cl, G, V, h_radps, epsilon, method, x0, omega_radps, solver, n_lambda, margin)
    for v in vars(design).values():  # shared by every later caller: nobody may change it in place
        if isinstance(v, np.ndarray):
            v.flags.writeable = False
    _GAIN_MEMO[key] = design
    while len(_GAIN_MEMO) > MEMO_SIZE:
        _GAIN_MEMO.popitem(last=False)
    return design


def _solve_gain(A: NDArray, C: NDArray, X_cl: NDArray, G: NDArray, V: NDArray, h_radps: float, epsilon: float,
                method: Method, x0: NDArray | None, omega_radps: NDArray | None, solver: str, n_lambda: int,
                margin: float) -> LmiFilterDesign:
    """:func:`lmi_detection_gain` without its memo."""
    A, C = np.asarray(A, float), np.asarray(C, float)
    n, m = A.shape[0], C.shape[0]
    X = np.asarray(X_cl, float).reshape(n, -1)
    G, V = np.asarray(G, float).reshape(n, -1), np.asarray(V, float)
    if V.shape != (m, m) or not np.allclose(V, V.T) or np.min(np.linalg.eigvalsh(V)) <= 0:
        raise DesignError(f"V must be a symmetric positive definite ({m}x{m}) measurement-noise intensity")
    if h_radps <= 0:
        raise DesignError(f"pole bound h must be > 0 [1/s], got {h_radps}")
    if method not in ("least-squares", "direct", "literal"):
        raise DesignError(f"method must be 'least-squares', 'direct' or 'literal', got {method!r}")
    if method != "direct" and epsilon <= 0:
        raise DesignError(f"epsilon must be > 0 for the {method} method, got {epsilon}")
    check_observable(A, C)
    T, Vih = _scaling(C, V)
    Ti = np.linalg.inv(T)
    As, Cs, Gs = Ti @ A @ T, Vih @ C @ T, Ti @ G
    Xs = sla.orth(Ti @ X)
    k = Xs.shape[1]
    w0 = np.eye(n) if x0 is None else np.outer(Ti @ np.asarray(x0, float), Ti @ np.asarray(x0, float))
    t0 = time.perf_counter()
    if method == "literal":
        status, val, Ps, Ws, Lam = _solve_literal(As, Cs, Xs, Gs, h_radps, epsilon, w0, solver, margin)
        if status not in ("optimal", "optimal_inaccurate") or Ps is None:
            raise DesignError(f"LMI (literal Theorem 5.2.2) is {status}: no gain for h = {h_radps}, epsilon = {epsilon}. "
                              "Increase h or epsilon.")
        Ws = np.asarray(Ws)
    else:
        if k != 1:
            raise DesignError(f"the {method} method supports a one-dimensional detection space; this one has k = {k}. "
                              "Use method='literal' or a Beard-Jones filter.")
        if np.min(np.linalg.eigvalsh(Gs @ Gs.T)) <= 1e-12 * max(1.0, np.linalg.norm(Gs) ** 2):
            raise DesignError("G must have full row rank for the information-form LMI (W = implied Q~); use method='literal'")
        status, val, Ps, Ws, Lam = _solve_information_form(As, Cs, Xs[:, 0], Gs, h_radps, epsilon, method, w0, solver, margin,
                                                           n_lambda)
    solve_time = time.perf_counter() - t0
    Ps = 0.5 * (Ps + Ps.T)
    P = T @ Ps @ T.T
    Vi = np.linalg.inv(V)
    L = P @ C.T @ Vi
    Acl = A - L @ C
    poles = np.linalg.eigvals(Acl)
    omega = np.logspace(-3, 3, 400) if omega_radps is None else np.asarray(omega_radps, float)
    ssv = sensitivity_max_sv(A, C, L, V, omega)
    GWG = G @ Ws @ G.T
    ric_res = A @ P + P @ A.T + GWG - P @ C.T @ Vi @ C @ P
    Qt = P @ C.T @ Vi @ C @ P - A @ P - P @ A.T
    Qt = 0.5 * (Qt + Qt.T)
    qmin = float(np.min(np.linalg.eigvalsh(Qt)) / max(np.linalg.norm(Qt, 2), 1e-300))
    Xo = sla.orth(X)
    Lam = np.asarray(Lam, float)
    Rs = Xs @ Lam - (As - Ps @ Cs.T @ Cs) @ Xs  # alignment residual in the scaled coordinates of the solve
    res_s = float(np.linalg.norm(Rs, 2))
    res_c = res_s if method == "literal" else float(np.sqrt(np.max(np.linalg.eigvalsh(Rs.T @ np.linalg.inv(Ps) @ Rs))))
    ang = alignment_error_deg(Acl, Xo, Lam)
    design = LmiFilterDesign(
        L, P, Ws, Lam, Acl, poles[np.argsort(poles.real)], Xo, method,
        0.0 if method == "direct" else epsilon, h_radps, res_s, res_c, ang, float(np.max(ssv)), omega,
        float(np.linalg.norm(ric_res, 2) / max(np.linalg.norm(GWG, 2), 1e-300)), qmin, val, solver, status, solve_time,
    )
    _check(design, solver)
    return design


def _check(d: LmiFilterDesign, solver: str) -> None:
    """Numerical acceptance of an LMI solution; raise with the failing numbers."""
    tol = 1e-4
    problems = []
    if np.min(np.linalg.eigvalsh(d.P)) <= 0:
        problems.append(f"P not positive definite (min eig {np.min(np.linalg.eigvalsh(d.P)):.3g})")
    if np.max(d.poles.real) >= 0:
        problems.append(f"unstable closed loop (max Re {np.max(d.poles.real):.4g})")
    if np.min(d.poles.real) < -d.h_radps * (1 + 1e-3):
        problems.append(f"pole faster than -h = {-d.h_radps}: {np.min(d.poles.real):.4g}")
    bound = 1e-5 if d.method == "direct" else np.sqrt(d.epsilon) * 1.05
    if d.alignment_constraint > max(bound, 1e-6 * np.linalg.norm(d.A_cl, 2)):
        problems.append(f"alignment residual {d.alignment_constraint:.3g} > {bound:.3g}")
    if d.max_sensitivity > 1 + tol:
        problems.append(f"max sigma(S) = {d.max_sensitivity:.5f} > 1 (LQ robustness lost)")
    if d.q_implied_min_eig < -tol:
        problems.append(f"implied process noise not PSD (relative min eig {d.q_implied_min_eig:.3g})")
    if problems:
        raise DesignError(
            f"LMI solution ({d.method}, {solver} status {d.status}) rejected: " + "; ".join(problems)
            + ". Loosen h or epsilon, or try the other method or solver."
        )


def design_lmi_filter(
    model: LinearModel,
    fault: str,
    V: NDArray,
    h_radps: float,
    G: NDArray | None = None,
    epsilon: float = 1e-7,
    method: Method = "least-squares",
    solver: str = "CLARABEL",
) -> LmiFilterDesign:
    """LMI detection filter for one actuator fault of a continuous model.

    The desired eigenspace is the Beard-Jones detection space of ``B[:, fault]``
    (:func:`~fdi_sim.detectors.beard_jones.detection_space`). ``G`` defaults to the identity.

    Parameters
    ----------
    model : LinearModel
        Continuous-time model (a discrete one raises: design on the continuous linearization).
    fault : str
        Input name, e.g. ``"elevator_cmd_norm"``.
    V : (m, m) array
        Measurement-noise intensity.
    h_radps : float
        Pole bound [1/s].
    G, epsilon, method, solver
        As in :func:`lmi_detection_gain`.
    """
    if model.is_discrete:
        raise DesignError("the LMI detection filter is designed in continuous time: pass the continuous model (dt_s = 0)")
    names, F = fault_directions_from_model(model, [fault])
    A, C = np.asarray(model.A), np.asarray(model.C)
    ds = detection_space(A, C, F[:, 0], names[0])
    Gm = np.eye(model.n_states) if G is None else np.asarray(G, float)
    return lmi_detection_gain(A, C, ds.basis, Gm, V, h_radps, epsilon, method, solver=solver)


# ----------------------------------------------------------------------------- runtime


class LmiDetectionFilter(DirectionalObserver):
    """Runs an LMI-designed continuous observer at sample time ``dt_s`` (``reset`` / ``step``).

    ``xh(k+1) = Phi xh(k) + Gam_u u(k) + Gam_y y(k)`` is the zero-order-hold discretization of
    ``dxh/dt = (A - L C) xh + (B - L D) u + L y``; ``r(k) = y(k) - C xh(k) - D u(k)``. The statistic
    is ``r' S^-1 r`` (``S`` from the discrete noise ``Qd``, ``Rd``; ``Rd = I`` if not given) against the
    chi-square threshold at ``alpha``; isolation by the whitened angle between ``r`` and ``C X_cl``
    for the single fault (:class:`~fdi_sim.detectors.directional_observer.DirectionalObserver`).

    Parameters
    ----------
    model : LinearModel
        The continuous model the design used.
    design : LmiFilterDesign
    fault : str
        Hypothesis name.
    dt_s : float
        Detector sample time [s].
    alpha : float
        Per-sample false-alarm probability.
    Rd : (m, m) array, optional
        Discrete measurement-noise covariance for ``S``.
    Qd : (n, n) array, optional
        Discrete process-noise covariance for ``S``.
    max_angle_rad : float
        Largest residual angle [rad] accepted for isolation.
    """

    def __init__(self, model: LinearModel, design: LmiFilterDesign, fault: str, dt_s: float, alpha: float = 1e-3,
                 Rd: NDArray | None = None, Qd: NDArray | None = None, max_angle_rad: float = 0.35, id: str = "lmi-detection-v1") -> None:
        if dt_s <= 0:
            raise DesignError("dt_s must be > 0")
        A, B, C, D, L = model.A, model.B, model.C, model.D, design.L
        p = C.shape[0]
        observer = LinearModel(A=A - L @ C, B=np.hstack([B - L @ D, L]), C=C, D=np.zeros((p, B.shape[1] + p))).discretize(dt_s)
        Phi, Gam_u, Gam_y = observer.A, observer.B[:, : B.shape[1]], observer.B[:, B.shape[1]:]
        # discrete error e(k+1) = Phi e + w - Gam_y v, r = C e + v
        self.S = observer_residual_covariance(Phi, C, Gam_y, Qd, np.eye(p) if Rd is None else Rd)
        super().__init__(DiscreteObserver(Phi, Gam_u, Gam_y, C, D, model.u0, model.y0), self.S, C @ design.X_cl[:, :1],
                         (fault,), alpha, max_angle_rad, id)

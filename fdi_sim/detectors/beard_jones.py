"""Beard-Jones fault detection filters (Miller & Ribbens, US 6,643,569 B2, App. A, eq. 2.1-2.54).

A detection filter is a full-order observer ``xh' = A xh + B u + L (y - C xh - D u)`` whose gain
``L`` makes the output error ``r = y - yh`` keep the fixed direction ``C f_i`` whenever the fault
``f_i n_i(t)`` acts, during the transient and in steady state (Definition 2.1.1).

Design, for each hypothesized direction ``f_i`` (seed ``002_d6038a6910cf5866.txt``):

1. output separability: ``rank [C f_1 ... C f_r] = r`` (Lemma 2.1.2, eq. 2.10); a direction with
   ``C f_i = 0`` is replaced by ``A^mu f_i`` (eq. 2.15-2.16, 2.27);
2. detection space ``D_f = N(M)`` with ``M = [C'; C'K'; ...; C'K'^(n-1)]`` (eq. 2.34-2.37,
   Definition 2.1.3), completion space its orthogonal complement (Definition 2.1.4);
3. the detection generator ``g`` (Definition 2.1.2, eq. 2.11-2.20);
4. the detection gain: ``L_i`` assigns the poles on ``D_f`` (eq. 2.39-2.46 generalised to
   order k by eq. 2.24), then ``L_p`` places the remaining poles on ``(A_i, C_i)`` and
   ``L = L_i + L_p (I - Cf (Cf)^+)`` (eq. 2.50).

A fault that also reaches the outputs directly (``y = C x + d n``: every actuator of the paired
sampled models, and the accelerometers see a surface at once) has the output direction ``d`` and
detection order 0, ``L d = f`` (:func:`feedthrough_space`): the patent's rule that the output
direction is the first non-zero Markov parameter (``C A^mu f``, eq. 2.15-2.16, 2.27) one step
earlier, and eq. 2.24 with ``k = 0``.

Several output-separable faults share one filter when their detection spaces are independent
and no unassignable pole is unstable; otherwise
:func:`~fdi_sim.detectors.beard_jones_filter.plan_bank` splits them into a bank.

The algebra holds for continuous (``dx/dt``) and discrete (``x(k+1)``) models alike; poles are
given in the model's own domain. This module is the design mathematics (pure functions); the
runtime filter, the bank and the model-level design are in :mod:`fdi_sim.detectors.beard_jones_filter`.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Callable, Sequence

import control
import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray
from scipy.signal import place_poles

from fdi_sim.errors import DesignError

Array = NDArray[np.float64]


class PoleCountError(DesignError):
    """Wrong number of completion poles; ``n_placeable`` is how many this design can place."""

    def __init__(self, message: str, n_placeable: int) -> None:
        super().__init__(message)
        self.n_placeable = n_placeable


# ----------------------------------------------------------------------------- linear algebra


def _svd_tol(s: NDArray, rtol: float) -> float:
    """Rank tolerance for singular values ``s`` (descending): relative ``rtol`` with an absolute floor 1e-12.

    The floor is why scipy's ``null_space`` / ``orth`` (relative tolerance only) are not used: with one
    output, ``C' = (I - Cf (Cf)^+) C`` is rounding noise (~1e-17) and must count as zero, not full rank.
    """
    return max(rtol * s[0], 1e-12) if s.size else 0.0


def _rank(M: NDArray, rtol: float = 1e-9) -> int:
    """Numerical rank by SVD (tolerance :func:`_svd_tol`)."""
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > _svd_tol(s, rtol)))


def null_basis(M: NDArray, rtol: float = 1e-9) -> Array:
    """Orthonormal basis (columns) of the null space of ``M``, by SVD (tolerance :func:`_svd_tol`)."""
    if M.shape[0] == 0:
        return np.eye(M.shape[1])
    _, s, vt = np.linalg.svd(M)
    return vt[int(np.sum(s > _svd_tol(s, rtol))):].T.copy()


def range_basis(M: NDArray, rtol: float = 1e-9) -> Array:
    """Orthonormal basis (columns) of the range of ``M``, by SVD (tolerance :func:`_svd_tol`)."""
    if M.size == 0:
        return np.zeros((M.shape[0], 0))
    u, s, _ = np.linalg.svd(M, full_matrices=False)
    return u[:, : int(np.sum(s > _svd_tol(s, rtol)))].copy()


def angle_rad(a: Array, b: Array) -> float:
    """Angle between two vectors [rad], sign-insensitive (a direction, not an orientation)."""
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0.0 or nb == 0.0:
        return float("nan")
    ua, ub = np.asarray(a, float) / na, np.asarray(b, float) / nb
    c = float(np.dot(ua, ub))
    return float(np.arctan2(np.linalg.norm(ua - c * ub), abs(c)))  # accurate near 0, unlike arccos


def _is_stable(poles: NDArray, discrete: bool) -> bool:
    return bool(np.all(np.abs(poles) < 1.0)) if discrete else bool(np.all(np.real(poles) < 0.0))


#: relative tolerance of the scaled PBH test in :func:`check_observable`: about sqrt(eps), the
#: accuracy of an eigenvalue of a non-normal matrix (an eigenvalue moves by O(sqrt(eps)) when A
#: has a near-defective pair), so a smaller singular value cannot be told from zero; four orders
#: below the least observable mode of the default grids (DHC-6 prop_rpm, 1.0e-4 at 120 Hz ZOH,
#: 1.2e-3 continuous; F-16 h_ft 2.7e-2), so no mode a sensor really sees is refused.
OBSERVABILITY_RTOL = 1e-8


def observability_margins(A: NDArray, C: NDArray) -> tuple[NDArray[np.complex128], NDArray[np.float64], Array]:
    """Scaled Popov-Belevitch-Hautus margins of every mode of ``(A, C)``.

    A mode ``lambda`` of ``A`` is unobservable iff ``[lambda I - A; C]`` loses rank (PBH test). The
    test is made scale-free first: a diagonal similarity ``A~ = T^-1 A T`` balances ``A``
    (LAPACK ``gebal``, no permutation), ``C~ = C T`` has its rows normalized (a sensor's unit does
    not matter), and the smallest singular value is divided by ``max(||A~||, 1)``. The Krylov
    matrix ``[C; CA; ...; CA^(n-1)]`` is not used: its blocks grow like ``|lambda_max|^(n-1)``
    (a continuous F-16 at 50 rad/s: 1e15), so any relative rank test calls slow modes unobservable.

    Returns
    -------
    eigenvalues : (n,) complex array
        The modes of ``A`` [1/s or per step].
    margins : (n,) array
        Relative smallest singular value of the scaled PBH matrix per mode (0 = unobservable).
    directions : (n, n) complex array
        Columns: the unit state direction [state units] closest to unobservable for each mode.
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    n = A.shape[0]
    _, (t, _) = sla.matrix_balance(A, permute=False, separate=True)
    At = A * (t[None, :] / t[:, None])  # T^-1 A T with T = diag(t)
    Ct = C * t[None, :]
    Ct = _unit_rows(Ct)
    scale = max(float(np.linalg.norm(At, 2)), 1.0)
    lams = np.linalg.eigvals(At)
    margins = np.empty(n)
    dirs = np.empty((n, n), complex)
    for j, lam in enumerate(lams):
        _, s, vh = np.linalg.svd(np.vstack([lam * np.eye(n) - At, Ct]))
        margins[j] = s[-1] / scale
        v = t * vh[-1].conj()  # back to the model's state coordinates, x = T x~
        dirs[:, j] = v / np.linalg.norm(v)
    return lams, margins, dirs


def unobservable_subspace(A: NDArray, C: NDArray, rtol: float = OBSERVABILITY_RTOL) -> Array:
    """Orthonormal basis (columns) of the unobservable subspace of ``(A, C)``.

    The largest A-invariant subspace in ``N(C)``, by the orthogonal recursion ``V_0 = N(C)``,
    ``V_(j+1) = {x in V_j : A x in V_j}`` (the observability staircase) on the balanced, row-normalized
    system of :func:`observability_margins`: every step works on orthonormal bases, so unlike the
    null space of the Krylov matrix ``[C; CA; ...]`` nothing is raised to the power n - 1 (with
    the DHC-6 throttle at 120 Hz the Krylov singular values fall to 2.5e-10 of the largest for a
    direction the PBH test sees at 1e-3, which a 1e-9 rank test counts as a second detection dimension).
    A direction counts as zero below ``rtol`` times ``max(||A~||, 1)`` (or times 1 for the unit rows of ``C~``).
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    n = A.shape[0]
    _, (t, _) = sla.matrix_balance(A, permute=False, separate=True)
    At = A * (t[None, :] / t[:, None])  # T^-1 A T
    Ct = C * t[None, :]
    Ct = _unit_rows(Ct)
    scale = max(float(np.linalg.norm(At, 2)), 1.0)
    V = _null_abs(Ct, rtol) if Ct.size else np.eye(n)
    while V.shape[1]:
        # z with (I - V V') A V z = 0 keeps A V z inside span(V)
        Z = _null_abs((At @ V) - V @ (V.T @ At @ V), rtol * scale)
        if Z.shape[1] == V.shape[1]:
            break
        V = V @ Z
    if not V.shape[1]:
        return np.zeros((n, 0))
    return sla.orth(t[:, None] * V)  # back to the model's coordinates, x = T x~


def _unit_rows(C: Array) -> Array:
    """Rows of ``C`` normalized to unit length; rows of rounding noise are dropped.

    A row counts as zero below ``max(1e-12, 1e-12 * max row norm)``: the absolute floor of
    :func:`_svd_tol`, because ``C' = (I - Cf (Cf)^+) C`` with one output is rounding noise (~1e-16) that a
    normalization would otherwise blow up into a sensor.
    """
    rows = np.linalg.norm(C, axis=1)
    keep = rows > max(1e-12, 1e-12 * (rows.max() if rows.size else 0.0))
    return C[keep] / rows[keep, None]


def _null_abs(M: Array, tol: float) -> Array:
    """Orthonormal null-space basis of ``M`` with an absolute singular-value tolerance ``tol``."""
    _, s, vh = np.linalg.svd(M, full_matrices=True)
    r = int(np.sum(s > tol))
    return vh[r:].T.copy()


def check_observable(A: NDArray, C: NDArray, rtol: float = OBSERVABILITY_RTOL) -> None:
    """Raise :class:`DesignError` if ``(A, C)`` is not observable (Lemma 2.1.3, condition 1).

    The scaled PBH test of :func:`observability_margins`; a mode is unobservable when its margin
    is at most ``rtol`` (default :data:`OBSERVABILITY_RTOL`).
    """
    lams, margins, dirs = observability_margins(A, C)
    bad = np.flatnonzero(margins <= rtol)
    if bad.size:
        j = int(bad[np.argmin(margins[bad])])
        v = dirs[:, j]
        v = (v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))).real  # a real representative
        raise DesignError(
            f"(A, C) is not observable: {bad.size} of {A.shape[0]} modes fail the scaled PBH test (relative margin "
            f"<= {rtol:g}); mode {np.round(lams[j], 6)} has margin {margins[j]:.2e}, direction "
            f"{np.round(v, 4).tolist()}. Add a sensor that sees it, or remove that state from the model."
        )


# ----------------------------------------------------------------------------- separability


@dataclass(frozen=True)
class OutputSeparability:
    """Output separability of a set of fault directions (Lemma 2.1.2, eq. 2.10).

    Attributes
    ----------
    separable : bool
        ``rank [C A^mu_1 f_1, ..., C A^mu_r f_r] == r``.
    rank : int
        That rank.
    mu : tuple of int
        Per fault, the smallest ``j`` with ``C A^j f_i != 0`` (eq. 2.15-2.16); -1 if none below n.
    output_directions : NDArray
        (m, r) unit columns: the feedthrough ``d_i`` of a fault that has one, else ``C A^mu_i f_i``.
    dependent : tuple of tuple of int
        Fault indices whose output directions are linearly dependent on earlier ones.
    feedthrough : tuple of bool
        Per fault, True if it reaches the outputs directly (``y = C x + d_i n_i``, ``d_i != 0``): its
        output direction is ``d_i`` (relative degree 0, :func:`feedthrough_space`). Empty: none has.
    """

    separable: bool
    rank: int
    mu: tuple[int, ...]
    output_directions: Array
    dependent: tuple[tuple[int, ...], ...]
    feedthrough: tuple[bool, ...] = ()


def _first_visible_power(A: Array, C: Array, f: Array, rtol: float) -> tuple[int, Array]:
    """``(mu, A^mu f)`` with ``mu`` the smallest ``j < n`` such that ``C A^j f != 0`` (eq. 2.15-2.16), or ``(-1, f)``."""
    scale = max(np.linalg.norm(C, 2), 1e-300)
    fj = f
    for j in range(A.shape[0]):
        if np.linalg.norm(C @ fj) > rtol * scale * max(np.linalg.norm(fj), 1e-300):
            return j, fj
        fj = A @ fj
    return -1, f


def has_feedthrough(C: NDArray, f: NDArray, d: NDArray | None, rtol: float = 1e-9) -> bool:
    """True if the fault's feedthrough ``d`` [output units per unit fault] is not zero.

    The test of ``C A^j f != 0`` in :func:`output_separability` (eq. 2.15-2.16), one Markov
    parameter earlier: ``|d| > rtol |C| |f|``.
    """
    if d is None:
        return False
    d = np.asarray(d, float).reshape(-1)
    scale = max(float(np.linalg.norm(C, 2)) * float(np.linalg.norm(f)), 1e-300)
    return bool(np.linalg.norm(d) > rtol * scale)


def _feedthrough_columns(C: Array, F: Array, G: NDArray | None) -> Array | None:
    """``G`` as an (m, r) array (None if not given), checked against ``C`` and ``F``."""
    if G is None:
        return None
    G = np.asarray(G, float).reshape(C.shape[0], -1)
    if G.shape[1] != F.shape[1]:
        raise DesignError(f"feedthrough has {G.shape[1]} columns for {F.shape[1]} fault directions")
    return G


def output_separability(A: NDArray, C: NDArray, F: NDArray, rtol: float = 1e-9,
                        feedthrough: NDArray | None = None) -> OutputSeparability:
    """Check output separability of the columns of ``F`` (Lemma 2.1.2).

    Parameters
    ----------
    A : (n, n) array
    C : (m, n) array
    F : (n, r) array
        Fault directions as columns.
    rtol : float
        Relative rank tolerance.
    feedthrough : (m, r) array, optional
        Direct effect ``d_i`` of each fault on the outputs (``y = C x + d_i n_i``) [output units per
        unit fault]. A fault with ``d_i != 0`` (:func:`has_feedthrough`) has the output direction
        ``d_i``: the first non-zero Markov parameter of the fault, as ``C A^mu f`` is in eq. 2.27.
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    F = np.asarray(F, float).reshape(A.shape[0], -1)
    G = _feedthrough_columns(C, F, feedthrough)
    shifts = [_first_visible_power(A, C, F[:, i], rtol) for i in range(F.shape[1])]
    mus = tuple(mu for mu, _ in shifts)
    ft = tuple(G is not None and has_feedthrough(C, F[:, i], G[:, i], rtol) for i in range(F.shape[1]))
    D = np.zeros((C.shape[0], F.shape[1]))
    for i, (mu, fmu) in enumerate(shifts):
        if ft[i]:
            D[:, i] = G[:, i] / np.linalg.norm(G[:, i])  # type: ignore[index]
        elif mu >= 0:
            cf = C @ fmu
            D[:, i] = cf / np.linalg.norm(cf)
    dep: list[tuple[int, ...]] = []
    for i in range(D.shape[1]):
        if _rank(D[:, : i + 1], 1e-7) < _rank(D[:, :i], 1e-7) + 1:
            partners = tuple(j for j in range(i) if angle_rad(D[:, i], D[:, j]) < 1e-4) or tuple(range(i))
            dep.append((*partners, i))
    r = _rank(D, 1e-7)
    visible = all(f or mu >= 0 for f, mu in zip(ft, mus))
    return OutputSeparability(r == F.shape[1] and visible, r, mus, D, tuple(dep), ft if any(ft) else ())


# ----------------------------------------------------------------------------- detection space


@dataclass(frozen=True)
class DetectionSpace:
    """Detection space of one fault direction (Definitions 2.1.2-2.1.6).

    Attributes
    ----------
    f : NDArray
        (n,) the fault direction as given.
    basis : NDArray
        (n, k) orthonormal basis of ``D_f = N(M)``, eq. 2.36 and Definition 2.1.3.
    completion : NDArray
        (n, n-k) orthonormal basis of the completion space (row space of ``M``, Definition 2.1.4).
    order : int
        Detection order k (Definition 2.1.5).
    mu : int
        Smallest ``j`` with ``C A^j f != 0`` (eq. 2.15-2.16); for a fault with a feedthrough only
        informative (-1 if none below n), its output direction is the feedthrough.
    generator : NDArray
        (n,) maximal detection generator ``g``: ``C A^j g = 0`` for ``j < k-1`` (eq. 2.11),
        ``C A^(k-1) g != 0`` (eq. 2.12), ``f = sum alpha_j A^(j-1) g`` with ``alpha_(k-mu) = 1``
        (eq. 2.19-2.20).
    alpha : NDArray
        (k,) the coefficients ``alpha_1..alpha_k`` of eq. 2.14.
    output_direction : NDArray
        (m,) unit vector ``C A^mu f`` (eq. 2.27), or the feedthrough ``d / |d|``: every residual of
        this fault lies on it.
    feedthrough : NDArray or None
        (m,) the fault's direct effect ``d`` on the outputs [output units per unit fault] when it
        has one (:func:`feedthrough_space`): order 0, ``basis`` is (n, 0), ``generator`` is ``f``
        itself and ``alpha`` is empty. None for a fault in the state equation only.
    """

    f: Array
    basis: Array
    completion: Array
    order: int
    mu: int
    generator: Array
    alpha: Array
    output_direction: Array
    feedthrough: Array | None = None


def feedthrough_space(A: NDArray, C: NDArray, f: NDArray, d: NDArray, name: str = "f", rtol: float = 1e-9) -> DetectionSpace:
    """The detection space of a fault that also reaches the outputs directly: order 0.

    The patent's model has the fault in the state equation only (eq. 2.6-2.7). A sampled actuator
    fault also moves the outputs of its own sample (``y = C x + d n``, ``d = D b`` for the input
    column ``b`` of ``D``: the paired form of :mod:`fdi_sim.detectors.samples` has ``D = C B +
    D_c``, accelerometers see a surface at once). Then ``e(k+1) = (A - LC) e + (f - L d) n``,
    ``r = C e + d n``: ``r = d n`` at the onset whatever ``L``, so ``d`` is the only direction the
    residual can keep. It keeps it exactly when ``L d = f``: the state error is then not driven
    at all (``e = 0``) and ``r = d n(t)`` from the first sample on, for any ``n(t)``. This is the
    detection gain of eq. 2.24 with ``k = 0`` (``L (first non-zero Markov parameter) = g``,
    ``g = f``), the first non-zero Markov parameter being ``d`` instead of ``C A^mu f``
    (eq. 2.15-2.16, 2.27-2.28, one step earlier). No detection pole is assigned; the poles the
    completion cannot move are the invariant zeros of ``(A, f, C, d)``, checked stable by
    :func:`beard_jones_gain`. (A detection space of order 1 with output direction ``d`` would need
    a ``v`` with ``C v`` along ``d`` and ``f`` in ``span{v, A v}``; for the actuators of both aircraft
    at the reference points ``d`` is 0.03-26 % off ``range(C)`` and ``f`` 0.1-100 % off that span.)

    Parameters
    ----------
    A : (n, n) array
    C : (m, n) array
    f : (n,) array
        Fault direction in the state equation [state units per unit fault].
    d : (m,) array
        Its feedthrough [output units per unit fault], not zero (:func:`has_feedthrough`).
    name : str
        Used in error messages.
    rtol : float
        Relative tolerance of the zero test.

    Raises
    ------
    DesignError
        ``(A, C)`` unobservable, or ``d`` zero.
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    f, d = np.asarray(f, float).reshape(-1), np.asarray(d, float).reshape(-1)
    check_observable(A, C)
    if not has_feedthrough(C, f, d, rtol):
        raise DesignError(f"fault {name!r}: its feedthrough is zero; use detection_space")
    mu, _ = _first_visible_power(A, C, f, rtol)
    n = A.shape[0]
    return DetectionSpace(f, np.zeros((n, 0)), np.eye(n), 0, mu, f.copy(), np.zeros(0), d / np.linalg.norm(d), d.copy())


def detection_space(A: NDArray, C: NDArray, f: NDArray, name: str = "f", rtol: float = 1e-9) -> DetectionSpace:
    """Detection space, completion space and detection generator of ``f`` (App. A, eq. 2.11-2.37).

    ``C' = (I - Cf (Cf)^+) C`` (eq. 2.34), ``K' = A - A f (Cf)^+ C`` (eq. 2.37) and
    ``D_f = N([C'; C'K'; ...; C'K'^(n-1)])`` (eq. 2.36, Definition 2.1.3); with ``C f = 0`` the
    patent's rule applies: ``f`` is replaced by ``A^mu f`` in ``C f`` (eq. 2.27-2.28).

    Parameters
    ----------
    A : (n, n) array
    C : (m, n) array
    f : (n,) array
        Fault direction.
    name : str
        Used in error messages.
    rtol : float
        Relative rank tolerance.

    Raises
    ------
    DesignError
        ``(A, C)`` unobservable, or ``C A^j f = 0`` for all j (the fault never reaches the outputs).
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    f = np.asarray(f, float).reshape(-1)
    check_observable(A, C)
    mu, fmu = _first_visible_power(A, C, f, rtol)
    if mu < 0:
        raise DesignError(f"fault {name!r}: C A^j f = 0 for every j < n; the fault is invisible at the outputs.")
    cf = C @ fmu
    cf_pinv = cf[None, :] / (cf @ cf)  # (Cf)^+ = ((Cf)'Cf)^-1 (Cf)'   (Lemma 2.1.5)
    Cp = (np.eye(C.shape[0]) - cf[:, None] @ cf_pinv) @ C  # C' (eq. 2.34)
    Kp = A - (A @ fmu)[:, None] @ cf_pinv @ C  # K' (eq. 2.37)
    # D_f = N([C'; C'K'; ...; C'K'^(n-1)]) (eq. 2.36), the unobservable subspace of (K', C'),
    # computed by the orthogonal staircase rather than from the Krylov matrix itself
    D = unobservable_subspace(Kp, Cp)
    k = D.shape[1]
    if k == 0:
        raise DesignError(f"fault {name!r}: empty detection space (numerical rank of M is n); check the model scaling.")
    completion = null_basis(D.T)
    # detection generator: g in D_f with C A^j g = 0, j < k-1 (eq. 2.11)
    if k > 1:
        Z = null_basis(control.obsv(A, C)[: C.shape[0] * (k - 1)] @ D, 1e-7)
        if Z.shape[1] != 1:
            raise DesignError(
                f"fault {name!r}: detection space of order {k} has no unique generator ({Z.shape[1]} candidates); "
                "the fault is not a single-generator (Beard) direction."
            )
        g = D @ Z[:, 0]
    else:
        g = D[:, 0].copy()
    Kg = np.column_stack([np.linalg.matrix_power(A, j) @ g for j in range(k)])
    alpha, *_ = np.linalg.lstsq(Kg, f, rcond=None)  # f = sum alpha_j A^(j-1) g   (eq. 2.14)
    resid = np.linalg.norm(Kg @ alpha - f)
    if resid > 1e-6 * max(np.linalg.norm(f), 1e-300):
        raise DesignError(
            f"fault {name!r}: f is not in the span of its generator's Krylov vectors (residual {resid:.3g}); "
            "the detection space is ill-conditioned, rescale the states."
        )
    lead = alpha[k - mu - 1]  # alpha_(k-mu) in the patent's 1-based numbering (eq. 2.18)
    g, alpha = g * lead, alpha / lead
    return DetectionSpace(f, D, completion, k, mu, g, alpha, cf / np.linalg.norm(cf))


# ----------------------------------------------------------------------------- gain


@dataclass(frozen=True)
class BeardJonesDesign:
    """A Beard-Jones detection gain and everything it was checked against.

    Attributes
    ----------
    L : NDArray
        (n, m) detection gain.
    A_cl : NDArray
        ``A - L C``.
    poles : NDArray
        Eigenvalues of ``A - L C`` (model domain: s [1/s] or z [-]).
    names : tuple of str
        Fault hypothesis names, in column order of ``F``.
    F : NDArray
        (n, r) fault directions used in the design.
    spaces : tuple of DetectionSpace
        One per fault.
    output_directions : NDArray
        (m, r) unit output directions ``C A^mu f_i``.
    detection_poles : tuple of NDArray
        Poles assigned on each detection space.
    completion_poles : NDArray
        Poles assigned on the completion space.
    fixed_poles : NDArray
        Eigenvalues the gain cannot move (they are stable, or the design would have raised).
    L_detection : NDArray
        The part ``L_i`` of eq. 2.44 (generalised), before the completion gain.
    L_completion : NDArray
        The part ``L_p C_i`` of eq. 2.50, written as an (n, m) gain.
    discrete : bool
        True if the poles are z-plane poles.
    max_direction_error_rad : float
        Largest angle between ``C (A-LC)^j D_i`` and the output direction of fault i [rad]
        (0 for an exact design).
    """

    L: Array
    A_cl: Array
    poles: NDArray[np.complex128]
    names: tuple[str, ...]
    F: Array
    spaces: tuple[DetectionSpace, ...]
    output_directions: Array
    detection_poles: tuple[NDArray[np.complex128], ...]
    completion_poles: NDArray[np.complex128]
    fixed_poles: NDArray[np.complex128]
    L_detection: Array
    L_completion: Array
    discrete: bool
    max_direction_error_rad: float


def _sorted(p: NDArray) -> NDArray[np.complex128]:
    p = np.asarray(p, dtype=complex).reshape(-1)
    return p[np.lexsort((p.imag, p.real))]


def _remove_assigned(all_poles: NDArray, assigned: NDArray) -> NDArray[np.complex128]:
    """The poles of ``all_poles`` left after removing the closest match of each ``assigned`` pole."""
    rest = list(np.asarray(all_poles, complex))
    for p in np.asarray(assigned, complex):
        if not rest:
            break
        j = int(np.argmin([abs(q - p) for q in rest]))
        rest.pop(j)
    return np.array(rest, dtype=complex)


def _place(A: Array, B: Array, poles: NDArray, what: str) -> Array:
    """``K`` with ``eig(A - B K) = poles`` (scipy ``place_poles``), with a checked result."""
    poles = np.asarray(poles, dtype=complex)
    if A.shape[0] == 0:
        return np.zeros((B.shape[1], 0))
    try:
        with warnings.catch_warnings():  # YT's "convergence not reached": the result is checked below
            warnings.filterwarnings("ignore", "Convergence was not reached", UserWarning)
            res = place_poles(A, B, poles, method="YT", maxiter=200)
    except ValueError as exc:
        raise DesignError(f"cannot place the {what} poles {np.round(poles, 4).tolist()}: {exc}") from exc
    got = np.linalg.eigvals(A - B @ res.gain_matrix)
    err = np.max([np.min(np.abs(got - p)) for p in poles]) if poles.size else 0.0
    if err > 1e-6 * max(1.0, np.max(np.abs(poles))):
        raise DesignError(f"placing the {what} poles failed: wanted {np.round(poles, 4).tolist()}, got {np.round(got, 4).tolist()}")
    return res.gain_matrix


def _detection_part(A: Array, C: Array, sp: DetectionSpace, poles: NDArray, name: str) -> tuple[Array, Array]:
    """``(c, v)`` with ``L c = v`` assigning ``poles`` on the detection space ``sp`` (eq. 2.23-2.24, 2.39).

    With ``C D = c w'`` (rank one), the closed loop on ``D`` is ``Lambda = D'A D - kappa w'``; ``c`` is the
    unit output direction and ``v = (A D - D Lambda) w / |w|^2``. A fault with feedthrough ``d``
    (order 0, :func:`feedthrough_space`): ``c = d / |d|``, ``v = f / |d|`` (``L d = f``), no pole.
    """
    if poles.size != sp.order:
        raise DesignError(f"fault {name!r} has detection order {sp.order}; give exactly {sp.order} detection pole(s), got {poles.size}")
    if sp.feedthrough is not None:  # order 0: L d = f (feedthrough_space), i.e. L c = f / |d| with c = d / |d|
        dn = float(np.linalg.norm(sp.feedthrough))
        return sp.feedthrough / dn, sp.f / dn
    D = sp.basis
    u_, s_, vt_ = np.linalg.svd(C @ D, full_matrices=False)  # C D = c w' (rank one)
    c, w = u_[:, 0], s_[0] * vt_[0]
    # (I - D D') A D must be rank one along w': the detection space is (A, C)-invariant off w
    off = A @ D - D @ (D.T @ A @ D)
    if np.linalg.norm(off - np.outer(off @ w, w) / (w @ w)) > 1e-7 * max(1.0, np.linalg.norm(A)):
        raise DesignError(f"fault {name!r}: detection space is not invariant off the output direction; rescale the model")
    Lam0 = D.T @ A @ D
    if sp.order == 1:
        if abs(poles[0].imag) > 0:
            raise DesignError(f"fault {name!r}: a detection order of 1 needs a real pole, got {poles[0]}")
        Lam = np.array([[poles[0].real]])
    else:
        kappa = _place(Lam0.T, w[:, None], poles, f"detection ({name})").T
        Lam = Lam0 - kappa @ w[None, :]
    v = (A @ D - D @ Lam) @ w / (w @ w)  # L c = v   (eq. 2.39 with f -> D_f, eq. 2.24)
    return c, v


def beard_jones_gain(
    A: NDArray,
    C: NDArray,
    F: NDArray,
    detection_poles: Sequence[Sequence[complex] | complex],
    completion_poles: Sequence[complex] | Callable[[int], NDArray[np.complex128]],
    names: Sequence[str] | None = None,
    discrete: bool = False,
    allow_shift: bool = False,
    rtol: float = 1e-9,
    feedthrough: NDArray | None = None,
) -> BeardJonesDesign:
    """Detection gain for one or several output-separable faults (App. A, Lemmas 2.1.4-2.1.7).

    For each fault ``f_i`` with orthonormal detection-space basis ``D_i`` and rank-one output map
    ``C D_i = c_i w_i'`` the closed loop on ``D_i`` is ``Lambda_i = D_i'A D_i - kappa_i w_i'``
    with ``kappa_i`` placing ``detection_poles[i]`` (eq. 2.23-2.24); then
    ``L c_i = v_i = (A D_i - D_i Lambda_i) w_i / |w_i|^2`` (eq. 2.39 with ``f`` -> ``D_i``), so
    ``L_0 = V (CF)^+`` (eq. 2.44, 2.30), ``A_i = A - L_0 C`` (eq. 2.46), ``C_i = (I - CF (CF)^+) C``
    (eq. 2.45), and the completion gain places the observable part of ``(A_i, C_i)``;
    ``L = L_0 + L_p (I - CF (CF)^+)`` (eq. 2.50). The free part of ``L_p`` along the unobservable
    (detection) directions is set to zero (minimum norm); the patent's MATLAB ``place`` picked
    another member of the same family (eq. 2.51), with the same poles and detection space.

    A fault with a feedthrough ``d_i`` (``y = C x + d_i n_i``) has detection order 0
    (:func:`feedthrough_space`): ``c_i = d_i / |d_i|``, ``v_i = f_i / |d_i|`` (``L d_i = f_i``), no
    detection pole (give an empty list); its residual is ``d_i n_i(t)`` exactly. The poles the
    completion cannot move are then the detection poles and the invariant zeros of these faults.

    Parameters
    ----------
    A : (n, n) array
    C : (m, n) array
    F : (n, r) array
        Fault directions (columns).
    detection_poles : sequence
        Per fault, ``k_i`` poles (k_i = detection order; a scalar is accepted for k_i = 1).
    completion_poles : sequence, or callable ``count -> poles``
        The ``n - sum(k_i) - n_fixed`` remaining poles; a callable is given that count (the
        number of fixed poles is only known once the detection part is designed).
    names : sequence of str, optional
        Fault names (default ``f0, f1, ...``).
    discrete : bool
        Poles are z-plane poles (stability = inside the unit circle).
    allow_shift : bool
        Accept a fault with ``C f = 0`` by using ``C A^mu f`` as its output direction (eq. 2.27-2.28;
        the detection order is then at least ``mu + 1``). If False such a fault raises.
    rtol : float
        Relative rank tolerance.
    feedthrough : (m, r) array, optional
        Direct effect ``d_i`` of each fault on the outputs [output units per unit fault]; a zero
        column (:func:`has_feedthrough`) is a fault in the state equation only. Default: none.

    Raises
    ------
    DesignError
        Unobservable ``(A, C)``; faults not output separable (with the ``A^k f`` suggestion);
        wrong number of poles; detection spaces not independent; an unassignable pole unstable.
    """
    A, C = np.asarray(A, float), np.asarray(C, float)
    n, m = A.shape[0], C.shape[0]
    F = np.asarray(F, float).reshape(n, -1)
    r = F.shape[1]
    G = _feedthrough_columns(C, F, feedthrough)
    if r == 0:
        raise DesignError("no fault direction given: F needs at least one column")
    names = tuple(names) if names is not None else tuple(f"f{i}" for i in range(r))
    if len(names) != r:
        raise DesignError(f"{len(names)} names for {r} fault directions")
    if len(detection_poles) != r:
        raise DesignError(f"detection_poles has {len(detection_poles)} entries for {r} faults; give one list per fault")
    check_observable(A, C)
    sep = output_separability(A, C, F, rtol, G)
    ft = sep.feedthrough or (False,) * r
    for i, mu in enumerate(sep.mu):
        if ft[i]:
            continue  # seen at once through d_i, whatever C A^j f_i
        if mu < 0:
            raise DesignError(f"fault {names[i]!r}: C A^j f = 0 for every j < n; no sensor ever sees it. Add a sensor.")
        if mu > 0 and not allow_shift:
            raise DesignError(
                f"fault {names[i]!r} is not output separable: C f = 0 (Lemma 2.1.2); use A^{mu} f = "
                f"{np.round(np.linalg.matrix_power(A, mu) @ F[:, i], 4).tolist()} as its output-side direction "
                "(the patent's A^k f replacement, allow_shift=True), or add a sensor that sees it."
            )
    if not sep.separable:
        groups = ", ".join("{" + ", ".join(names[j] for j in grp) + "}" for grp in sep.dependent)
        raise DesignError(
            f"faults {groups} are not output separable: rank [C f_1 ... C f_r] = {sep.rank} < {r} (Lemma 2.1.2"
            f"{'; a feedthrough d_i stands for C f_i' if any(ft) else ''}). "
            "Design a bank of filters (plan_bank), or replace one direction by A^j f (j > 0) as the patent suggests."
        )
    spaces = tuple(feedthrough_space(A, C, F[:, i], G[:, i], names[i], rtol) if ft[i]  # type: ignore[index]
                   else detection_space(A, C, F[:, i], names[i], rtol) for i in range(r))
    Dall = np.hstack([s.basis for s in spaces])
    if _rank(Dall, 1e-7) < Dall.shape[1]:
        raise DesignError(
            f"the detection spaces of {', '.join(names)} intersect (rank {_rank(Dall, 1e-7)} < {Dall.shape[1]}); "
            "they cannot be assigned in one filter: use a bank of filters (plan_bank)."
        )
    det_poles = [np.atleast_1d(np.asarray(p, dtype=complex)) for p in detection_poles]
    cols_c, cols_v = zip(*(_detection_part(A, C, sp, p, name) for sp, p, name in zip(spaces, det_poles, names)))
    CF, V = np.column_stack(cols_c), np.column_stack(cols_v)
    CFp = np.linalg.pinv(CF)
    L0 = V @ CFp  # eq. 2.44 / 2.30 with E = 0
    Ai = A - L0 @ C  # eq. 2.46
    Proj = np.eye(m) - CF @ CFp
    Ci = Proj @ C  # eq. 2.45
    U = unobservable_subspace(Ai, Ci)  # unobservable subspace: every D_i, and the invariant zeros of the order-0 faults
    O = null_basis(U.T) if U.shape[1] else np.eye(n)
    n_obs = O.shape[1]
    # orthonormal basis of the remaining output directions the states reach: range(Ci), not
    # range(Proj). An exact relation among the model's outputs (DHC-6 at every default point:
    # theta_rad - alpha_rad = hdot_fps / V, C of rank 13 for 14 outputs) would otherwise make
    # C1 row-rank deficient and scipy's place_poles (which needs C1' of full column rank) fails;
    # such an output combination carries no state, so the gain along it is zero anyway.
    Vr = range_basis(Ci)
    comp = np.asarray(completion_poles(n_obs) if callable(completion_poles) else completion_poles, dtype=complex).reshape(-1)
    if comp.size != n_obs:
        raise PoleCountError(
            f"{comp.size} completion pole(s) given; this design can place exactly {n_obs} "
            f"(n = {n}, detection orders {[s.order for s in spaces]}, {U.shape[1] - sum(s.order for s in spaces)} fixed)",
            n_obs,
        )
    if n_obs:
        A11, C1 = O.T @ Ai @ O, Vr.T @ Ci @ O
        Lo = _place(A11.T, C1.T, comp, "completion").T  # eig(A11 - Lo C1) = completion poles
        Lc = O @ Lo @ Vr.T  # L_p (I - CF CF^+) of eq. 2.50, in (n, m) form
    else:
        Lc = np.zeros((n, m))
    L = L0 + Lc
    Acl = A - L @ C
    poles = np.linalg.eigvals(Acl)
    fixed = _remove_assigned(poles, np.concatenate([*det_poles, comp]))
    if fixed.size and not _is_stable(fixed, discrete):
        raise DesignError(
            f"faults {', '.join(names)} leave unassignable unstable pole(s) {np.round(fixed, 4).tolist()}; "
            "these directions are not mutually detectable in one filter: use a bank of filters (plan_bank)."
        )
    err = _direction_error(Acl, C, spaces, CF, L)
    if err > 1e-5:
        raise DesignError(f"design check failed: residual direction error {err:.3g} rad (expected 0); rescale the model")
    return BeardJonesDesign(
        L, Acl, _sorted(poles), names, F, spaces, CF, tuple(_sorted(p) for p in det_poles), _sorted(comp), _sorted(fixed),
        L0, Lc, discrete, err,
    )


def _direction_error(Acl: Array, C: Array, spaces: Sequence[DetectionSpace], CF: Array, L: Array) -> float:
    """Largest angle between ``C Acl^j x`` (x in D_i, j < n) and the fault's output direction [rad].

    For a fault with feedthrough ``d`` (order 0) the residual is ``d n + C e`` with ``e`` driven by
    ``x = f - L d`` (0 by design): the bound ``sum_(j<n) |C Acl^j x| / |d|`` on the angle ``C e``
    turns the residual of a unit step over the first n samples (discrete design; in continuous
    time the same sum of Markov parameters, as a size).
    """
    n = Acl.shape[0]
    worst = 0.0
    for i, sp in enumerate(spaces):
        if sp.feedthrough is not None:
            x, total = sp.f - L @ sp.feedthrough, 0.0
            for _ in range(n):
                total += float(np.linalg.norm(C @ x))
                x = Acl @ x
            worst = max(worst, float(np.arctan(total / np.linalg.norm(sp.feedthrough))))
            continue
        X = sp.basis
        for _ in range(n):
            Y = C @ X
            for col in Y.T:
                if np.linalg.norm(col) > 1e-9 * max(1.0, np.linalg.norm(C) * np.linalg.norm(X)):
                    worst = max(worst, angle_rad(col, CF[:, i]))
            X = Acl @ X
            X = X / max(np.linalg.norm(X), 1e-300)
    return worst

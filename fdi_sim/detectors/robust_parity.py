"""Optimally robust parity relations (Lou, Willsky & Verghese 1986; Chow, Lou, Verghese & Willsky 1984).

Given Q models of one system (neighbouring schedule points, icing levels, sampled parameter
uncertainty), choose p orthonormal relations ``P`` (``P'P = I``) that make the parity checks as
small as possible on average over the models:

    J = sum_q a_q ||P' R_q||_F^2                                  (Lou et al. eq. 22, 24, 32, 40)

where ``R_q`` holds the directions the window of observations takes under model q:

- the scaled observation matrix ``Z_q = O_q M_q`` with ``M_q M_q' = `` the state covariance
  (eq. 13-15, 29; Chow et al. eq. 4.1-4.5);
- with noise, also the Toeplitz matrix of the unit-covariance noise, ``[Z_q, H_q]`` (eq. 30-35);
- with known inputs, ``R_q = [[Z_q, H_q], [0, I]] N_q`` and relations act on ``[Y; U]`` (eq. 36-41).

One SVD of ``T = [sqrt(a_1) R_1, ..., sqrt(a_Q) R_Q] = U diag(sigma) V`` gives the answer: the
left singular vectors of the p smallest singular values (eq. 18-21), with ``J* = sum_{i<=p}
sigma_i^2`` (eq. 23, A.3). ``sigma_i^2`` ranks the relations by robustness and ``J*(p)`` is the
robustness curve of sec. 5.1 (Fig. 4) used to compare sensor sets.

Detection versus robustness (sec. 4.3): with failed models ``Zbar_q`` too, minimize
``sum ||P'Z_q||^2 - ||P'Zbar_q||^2`` by the eigenvectors of ``H S H'`` (eq. 48-55), i.e. the
S-singular value decomposition ``H = U Sigma V``, ``V S V' = S`` (eq. 56-61).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.parity import input_columns, input_toeplitz, observability_matrix, parity_basis
from fdi_sim.detectors.window_detector import WindowParityDetector, _psd_sqrt
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "DetectionRobustness",
    "RobustParity",
    "SSvd",
    "check_same_size",
    "design_block",
    "example_icing_models",
    "detection_robustness",
    "increasing_svd",
    "make_robust_parity_detector",
    "prior_weights",
    "robust_parity",
    "robustness_cost",
    "s_svd",
    "stationary_state_sqrt",
    "window_scale",
]

INPUT_MODES = ("known", "noise", "ignore")


def _sqrt_or_eye(M: NDArray | None, size: int, what: str) -> NDArray[np.float64]:
    if M is None:
        return np.eye(size)
    M = np.atleast_2d(np.asarray(M, float))
    if M.shape == (1, size) and size > 1 or M.shape == (size, 1) and size > 1:
        M = np.diag(M.ravel())
    if M.shape != (size, size):
        raise DesignError(f"{what} must be a ({size}, {size}) square root of a covariance, got {M.shape}")
    return M


def stationary_state_sqrt(
    model: LinearModel, input_sqrt: NDArray | None = None, disturbance_sqrt: NDArray | None = None,
    inputs: str = "known",
) -> NDArray[np.float64]:
    """A square root ``M`` of the stationary state covariance ``S = M M'`` (Lou et al. eq. 29).

    ``S = A S A' + B_u Su Su' B_u' + B_d Sd Sd' B_d'`` for white inputs with per-sample square-root
    covariances ``Su`` (control, unless ``inputs="ignore"``) and ``Sd`` (disturbance).

    Raises
    ------
    DesignError
        If A is not Schur stable (no stationary covariance: pass ``state_sqrt`` explicitly).
    """
    from scipy.linalg import solve_discrete_lyapunov

    rho = float(np.max(np.abs(np.linalg.eigvals(model.A))))
    if rho >= 1.0:
        raise DesignError(
            f"model has spectral radius {rho:.6f} >= 1, so no stationary state covariance exists; "
            "pass state_sqrt (e.g. the identity or a covariance from simulation) instead"
        )
    cu, cd = input_columns(model, "control"), input_columns(model, "disturbance")
    G = np.zeros((model.n_states, 0))
    if cu and inputs != "ignore":
        G = np.hstack([G, model.B[:, cu] @ _sqrt_or_eye(input_sqrt, len(cu), "input_sqrt")])
    if cd:
        G = np.hstack([G, model.B[:, cd] @ _sqrt_or_eye(disturbance_sqrt, len(cd), "disturbance_sqrt")])
    return _psd_sqrt(solve_discrete_lyapunov(model.A, G @ G.T))  # S = A S A' + G G'  (eq. 29)


def design_block(
    model: LinearModel,
    order_s: int,
    state_sqrt: NDArray | str | None = None,
    inputs: str = "known",
    input_sqrt: NDArray | None = None,
    disturbance_sqrt: NDArray | None = None,
    measurement_sqrt: NDArray | None = None,
) -> NDArray[np.float64]:
    """The matrix ``R_q`` of one model: the directions its observation window can take.

    ``E[X X'] = R_q R_q'`` for the window ``X = Y`` (or ``[Y; U]`` with known inputs) when the
    state at the window start has covariance ``M M'`` and all noises/inputs are white.

    Parameters
    ----------
    model : LinearModel
        Discrete model. Control columns are known inputs, disturbance columns unit noise.
    order_s : int
        Parity order s.
    state_sqrt : NDArray, "stationary" or None
        ``M_q`` of eq. 14/29; None is the identity (all state directions equally likely),
        "stationary" solves the Lyapunov equation (:func:`stationary_state_sqrt`).
    inputs : str
        "known": relations act on ``[Y; U]`` (eq. 36-41); "noise": control inputs are treated as
        white noise like disturbances (eq. 27-35); "ignore": control inputs are dropped (eq. 11-12).
    input_sqrt, disturbance_sqrt, measurement_sqrt : NDArray, optional
        Square roots of the per-sample covariances of the control inputs, the disturbances and
        the measurement noise (None: identity, identity, no measurement noise).
    """
    if inputs not in INPUT_MODES:
        raise DesignError(f"inputs must be one of {INPUT_MODES}, got {inputs!r}")
    if not model.is_discrete:
        raise DesignError("robust parity needs discrete models; call model.discretize(dt_s) first")
    s, L = order_s, order_s + 1
    A, C = model.A, model.C
    if isinstance(state_sqrt, str):
        if state_sqrt != "stationary":
            raise DesignError(f"state_sqrt must be an array, None or 'stationary', got {state_sqrt!r}")
        M = stationary_state_sqrt(model, input_sqrt, disturbance_sqrt, inputs)
    else:
        M = _sqrt_or_eye(state_sqrt, model.n_states, "state_sqrt")
    cols = [observability_matrix(A, C, s) @ M]  # Z_q = O_q M_q  (eq. 14-15)
    cu, cd = input_columns(model, "control"), input_columns(model, "disturbance")
    noise_cols = list(cd) + (cu if inputs == "noise" else [])
    if noise_cols:  # H_q of unit-covariance noise (eq. 30)
        Sn = np.eye(len(noise_cols))
        if cd:
            Sn[: len(cd), : len(cd)] = _sqrt_or_eye(disturbance_sqrt, len(cd), "disturbance_sqrt")
        if inputs == "noise" and cu:
            Sn[len(cd):, len(cd):] = _sqrt_or_eye(input_sqrt, len(cu), "input_sqrt")
        Hn = input_toeplitz(A, model.B[:, noise_cols] @ Sn, C, model.D[:, noise_cols] @ Sn, s)
        cols.append(Hn)
    if measurement_sqrt is not None:
        cols.append(np.kron(np.eye(L), _sqrt_or_eye(measurement_sqrt, model.n_outputs, "measurement_sqrt")))
    Rq = np.hstack(cols)
    if inputs == "known" and cu:
        Su = np.kron(np.eye(L), _sqrt_or_eye(input_sqrt, len(cu), "input_sqrt"))
        Hu = input_toeplitz(A, model.B[:, cu], C, model.D[:, cu], s)
        top = np.hstack([Rq, Hu @ Su])  # R_q = [[Z_q, H_q], [0, I]] N_q  (eq. 41)
        bottom = np.hstack([np.zeros((Su.shape[0], Rq.shape[1])), Su])
        Rq = np.vstack([top, bottom])
    return Rq


def check_same_size(models: Sequence[LinearModel], what: str = "models") -> None:
    """Raise DesignError unless ``models`` are discrete, of one size and sample time, with the same input kinds."""
    if len(models) == 0:
        raise DesignError(f"give at least one model in {what}")
    ref = models[0]
    for q, m in enumerate(models):
        sizes = (m.n_states, m.n_inputs, m.n_outputs)
        if sizes != (ref.n_states, ref.n_inputs, ref.n_outputs) or m.input_kinds != ref.input_kinds:
            raise DesignError(
                f"{what}[{q}] has (n, m, r) = {sizes} and input kinds {m.input_kinds}, but {what}[0] has "
                f"{(ref.n_states, ref.n_inputs, ref.n_outputs)} and {ref.input_kinds}: a robust design needs "
                "models of the same size with the same signals (linearize every point with one signal list)"
            )
        if abs(m.dt_s - ref.dt_s) > 1e-12 * max(ref.dt_s, 1.0) or not m.is_discrete:
            raise DesignError(f"{what}[{q}] has dt_s={m.dt_s}; all models must be discrete with dt_s={ref.dt_s}")


def prior_weights(weights: Sequence[float] | None, Q: int) -> NDArray[np.float64]:
    """The prior probabilities a_q of Q models (Lou et al. eq. 24): 1/Q each by default, else validated."""
    a = np.full(Q, 1.0 / Q) if weights is None else np.asarray(weights, float)
    if a.shape != (Q,) or np.any(a <= 0) or not np.all(np.isfinite(a)):
        raise DesignError(f"weights must be {Q} positive numbers (prior probabilities a_q of eq. 24), got {weights}")
    return a


# the names these had while private (kept for callers that import them)
_check_same_size = check_same_size
_weights = prior_weights


def window_scale(
    output_scale: NDArray | None, input_scale: NDArray | None, n_outputs: int, n_known: int, order_s: int
) -> NDArray[np.float64]:
    """(N,) scale of the stacked window ``[Y; U]``: each signal's scale repeated over the s + 1 samples.

    ``None`` is no scaling (ones); otherwise ``n_outputs`` and ``n_known`` positive numbers [signal units].
    """
    L = order_s + 1
    return np.concatenate([
        np.tile(_positive(output_scale, n_outputs, "output_scale"), L),
        np.tile(_positive(input_scale, n_known, "input_scale"), L) if n_known else np.zeros(0),
    ])


def increasing_svd(T: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """All left singular vectors of ``T`` and its singular values, in increasing order (Lou et al. eq. 18-19).

    Rows beyond the column count have sigma = 0 (zero padding, sec. 3), so ``sigma`` has one
    entry per row of ``T`` and the first columns of ``U`` are the most robust relations.
    """
    Uf, sv, _ = np.linalg.svd(T, full_matrices=True)
    N, k = T.shape[0], sv.size
    order = np.concatenate([np.arange(k, N), np.arange(k - 1, -1, -1)]).astype(int)
    return Uf[:, order], np.concatenate([np.zeros(N - k), sv[::-1]])


@dataclass(frozen=True, eq=False)
class RobustParity:
    """Robust parity relations from one SVD (Lou et al. 1986, eq. 18-23, 35, 41).

    Attributes
    ----------
    order_s : int
        Parity order s.
    U : NDArray
        All left singular vectors of ``T``, columns in order of increasing singular value.
    sigma : NDArray
        Singular values of ``T``, increasing, zero-padded to the row count N (eq. 19).
    T : NDArray
        The stacked matrix ``[sqrt(a_1) R_1, ..., sqrt(a_Q) R_Q]``, in scaled coordinates
        ``diag(scale)^-1 T`` when a window scaling is used.
    n_relations : int
        p, the number of relations kept.
    n_y : int
        Rows of ``T`` that belong to the stacked outputs Y (the rest to U).
    known_inputs : tuple of int
        Input columns in the U part (empty unless ``inputs="known"``).
    weights : NDArray
        The a_q used.
    scale : NDArray
        (N,) window scaling (1 = none): relations are orthonormal in ``diag(scale)^-1 X``.
    """

    order_s: int
    U: NDArray[np.float64]
    sigma: NDArray[np.float64]
    T: NDArray[np.float64]
    n_relations: int
    n_y: int
    known_inputs: tuple[int, ...]
    weights: NDArray[np.float64]
    scale: NDArray[np.float64]

    @property
    def P(self) -> NDArray[np.float64]:
        """The p most robust relations ``[u_1 ... u_p]`` (eq. 21) acting on the raw window, (N, p).

        Equal to ``diag(scale)^-1 [u_1 ... u_p]``; orthonormal when there is no scaling.
        """
        return self.U[:, : self.n_relations] / self.scale[:, None]

    @property
    def sigma_sq(self) -> NDArray[np.float64]:
        """Robustness measures sigma_i^2, increasing (sec. 3, end)."""
        return self.sigma**2

    @property
    def J_star(self) -> float:
        """Minimum of J for the p kept relations, ``sum_{i<=p} sigma_i^2`` (eq. 23)."""
        return float(np.sum(self.sigma_sq[: self.n_relations]))

    def curve(self) -> NDArray[np.float64]:
        """Robustness curve ``J*(p)`` for p = 0..N (sec. 5.1, Fig. 4); convex and non-decreasing."""
        return np.concatenate([[0.0], np.cumsum(self.sigma_sq)])

    def residual(self, Y: NDArray, U: NDArray | None = None) -> NDArray[np.float64]:
        """Parity checks ``r = P' [Y; U]`` (eq. 33, 36) of stacked deviation windows."""
        X = np.asarray(Y, float) if not self.known_inputs else np.hstack([np.asarray(Y, float), np.asarray(U, float)])
        return X @ self.P


def robustness_cost(P: NDArray, T: NDArray) -> float:
    """``J = ||P' T||_F^2 = tr(P' T T' P)`` for any relations P (Lou et al. eq. A.1-A.2)."""
    P = np.asarray(P, float)
    return float(np.sum((P.T @ np.asarray(T, float)) ** 2))


def robust_parity(
    models: Sequence[LinearModel],
    order_s: int,
    n_relations: int | None = None,
    weights: Sequence[float] | None = None,
    state_sqrt: NDArray | str | Sequence[NDArray] | None = None,
    inputs: str = "known",
    input_sqrt: NDArray | None = None,
    disturbance_sqrt: NDArray | None = None,
    measurement_sqrt: NDArray | None = None,
    output_scale: NDArray | None = None,
    input_scale: NDArray | None = None,
) -> RobustParity:
    """Optimally robust parity relations of order s for a finite set of models (one SVD).

    Parameters
    ----------
    models : sequence of LinearModel
        The Q models (same sizes and signal kinds).
    order_s : int
        Parity order s (window of s + 1 samples).
    n_relations : int, optional
        p; default the exact parity dimension of the first model (``(s+1) r - rank O``).
    weights : sequence of float, optional
        Prior probabilities a_q (eq. 24); default 1/Q each.
    state_sqrt : NDArray, "stationary", sequence of NDArray or None
        Scaling ``M_q`` (eq. 14, 29): one for all models, one per model, "stationary" or identity.
    inputs, input_sqrt, disturbance_sqrt, measurement_sqrt
        See :func:`design_block`.
    output_scale, input_scale : NDArray, optional
        Per-signal scales (r,) and (m_known,) [signal units], e.g. the sensor noise and input
        standard deviations. The SVD is then done on ``diag(scale)^-1 T`` so ``P'P = I`` holds in
        scaled units: the observation-side counterpart of the state scaling of Chow et al.
        sec. 4.1 (without it, relations mixing signals of different units are ranked by raw
        numbers).

    Raises
    ------
    DesignError
        Models of different sizes, bad weights or scalings, or p outside 1..N.
    """
    models = list(models)
    check_same_size(models)
    Q = len(models)
    a = prior_weights(weights, Q)
    if isinstance(state_sqrt, (list, tuple)):
        if len(state_sqrt) != Q:
            raise DesignError(f"state_sqrt has {len(state_sqrt)} entries for {Q} models")
        scal = list(state_sqrt)
    else:
        scal = [state_sqrt] * Q
    blocks = [np.sqrt(a[q]) * design_block(models[q], order_s, scal[q], inputs, input_sqrt,
                                           disturbance_sqrt, measurement_sqrt) for q in range(Q)]
    T = np.hstack(blocks)  # T = [sqrt(a_1) R_1 ... sqrt(a_Q) R_Q]  (eq. 16, 35)
    N = T.shape[0]
    cu = tuple(input_columns(models[0], "control")) if inputs == "known" else ()
    scale = window_scale(output_scale, input_scale, models[0].n_outputs, len(cu), order_s)
    T = T / scale[:, None]
    U_inc, sigma = increasing_svd(T)
    ny = (order_s + 1) * models[0].n_outputs
    if n_relations is None:
        n_relations = parity_basis(observability_matrix(models[0].A, models[0].C, order_s)).shape[1]
        if n_relations < 1:
            raise DesignError(f"order s={order_s} gives no exact parity relation for models[0]; pass n_relations or raise order_s")
    if not 1 <= int(n_relations) <= N:
        raise DesignError(f"n_relations must be between 1 and N={N}, got {n_relations}")
    return RobustParity(order_s=int(order_s), U=U_inc, sigma=sigma, T=T, n_relations=int(n_relations),
                        n_y=ny, known_inputs=cu, weights=a, scale=scale)


def _positive(v: NDArray | None, size: int, what: str) -> NDArray[np.float64]:
    if v is None:
        return np.ones(size)
    v = np.asarray(v, float).ravel()
    if v.shape != (size,) or np.any(v <= 0) or not np.all(np.isfinite(v)):
        raise DesignError(f"{what} must be {size} positive numbers, got {v}")
    return v


def make_robust_parity_detector(
    model: LinearModel,
    design: RobustParity,
    cov_r: NDArray | None = None,
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    detector_id: str = "parity-robust-v1",
) -> WindowParityDetector:
    """Run the p most robust relations as a detector on the nominal ``model``'s trim point.

    ``cov_r`` defaults to the design's own average residual covariance ``P' T T' P`` (the
    expected ``r r'`` over the model set, eq. 26), which is ``diag(sigma_1^2 .. sigma_p^2)``
    and gives a chi-square-like statistic.
    """
    P = design.P
    if cov_r is None:  # E[r r'] = U_p' T T' U_p = diag(sigma_1^2 .. sigma_p^2)  (eq. 19-23)
        cov_r = np.diag(design.sigma_sq[: design.n_relations])
    return WindowParityDetector(
        detector_id=detector_id, order_s=design.order_s, proj_y=P[: design.n_y].T, proj_u=P[design.n_y:].T,
        known_inputs=design.known_inputs, u0=model.u0, y0=model.y0, cov_r=cov_r, threshold=threshold,
        p_false_alarm=p_false_alarm,
    )


@dataclass(frozen=True, eq=False)
class DetectionRobustness:
    """Relations for robust detection of one failure mode (Lou et al. 1986, sec. 4.3).

    Attributes
    ----------
    P : NDArray
        (N, p) the eigenvectors of the p smallest eigenvalues of ``H S H'`` (eq. 54).
    U : NDArray
        All eigenvectors, increasing eigenvalue.
    lam : NDArray
        Eigenvalues of ``H S H' = sum Z_q Z_q' - sum Zbar_q Zbar_q'``, increasing (eq. 52-53).
    n_useful : int
        Number of negative eigenvalues: relations larger under failure than without (sec. 4.3).
    H : NDArray
        ``[Zbar_1 ... Zbar_Q, Z_1 ... Z_Q]`` (eq. 49).
    signs : NDArray
        Diagonal of ``S`` (eq. 50): -1 for failed-model columns, +1 for unfailed.
    n_y : int
        Rows that belong to Y.
    """

    P: NDArray[np.float64]
    U: NDArray[np.float64]
    lam: NDArray[np.float64]
    n_useful: int
    H: NDArray[np.float64]
    signs: NDArray[np.float64]
    n_y: int

    @property
    def J_star(self) -> float:
        """``sum_{i<=p} lambda_i`` (eq. 55)."""
        return float(np.sum(self.lam[: self.P.shape[1]]))


def detection_robustness(
    unfailed: Sequence[LinearModel],
    failed: Sequence[LinearModel],
    order_s: int,
    n_relations: int | None = None,
    weights: Sequence[float] | None = None,
    failed_weights: Sequence[float] | None = None,
    **block_kwargs,
) -> DetectionRobustness:
    """Trade robustness against detection of one failure mode (eq. 48-55).

    Minimizes ``J = sum_q a_q (||P'Z_q||^2 - ||P'Zbar_q||^2)`` over ``P'P = I``; ``Z_q`` and
    ``Zbar_q`` are :func:`design_block` of the unfailed and failed models (``block_kwargs`` are
    passed on, so noise and known inputs work as in sec. 4.1-4.2). ``weights`` and
    ``failed_weights`` default to 1/Q of each set. ``p`` defaults to the number of negative
    eigenvalues (the useful relations).

    Raises
    ------
    DesignError
        Different model sizes or no relation that grows under the failure.
    """
    unfailed, failed = list(unfailed), list(failed)
    check_same_size(unfailed + failed, "unfailed+failed models")
    a = prior_weights(weights, len(unfailed))
    b = prior_weights(failed_weights, len(failed))
    Zbar = [np.sqrt(b[q]) * design_block(m, order_s, **block_kwargs) for q, m in enumerate(failed)]
    Z = [np.sqrt(a[q]) * design_block(m, order_s, **block_kwargs) for q, m in enumerate(unfailed)]
    H = np.hstack(Zbar + Z)  # eq. 49
    signs = np.concatenate([-np.ones(sum(z.shape[1] for z in Zbar)), np.ones(sum(z.shape[1] for z in Z))])  # eq. 50
    M = (H * signs) @ H.T  # H S H'  (eq. 51)
    lam, U = np.linalg.eigh((M + M.T) / 2)  # increasing (eq. 52-53)
    tol = 1e-12 * max(float(np.abs(lam).max()), 1e-300)
    n_useful = int(np.sum(lam < -tol))
    if n_relations is None:
        if n_useful == 0:
            raise DesignError("no relation is larger under the failure than without it (H S H' has no negative "
                              "eigenvalue): this failure mode is not robustly detectable with these models and order")
        n_relations = n_useful
    if not 1 <= int(n_relations) <= U.shape[0]:
        raise DesignError(f"n_relations must be between 1 and {U.shape[0]}, got {n_relations}")
    ny = (order_s + 1) * unfailed[0].n_outputs
    return DetectionRobustness(P=U[:, : int(n_relations)], U=U, lam=lam, n_useful=n_useful, H=H, signs=signs, n_y=ny)


@dataclass(frozen=True, eq=False)
class SSvd:
    """S-singular value decomposition ``H = U Sigma V`` with ``V S V' = S_sign`` (eq. 56-61).

    Attributes
    ----------
    U : NDArray
        Orthogonal (N, N).
    sigma : NDArray
        (N,) positive, ``sigma_i^2 = |lambda_i|`` (eq. 56).
    V : NDArray
        (N, M) ``Sigma^-1 U' H`` (eq. 59).
    sign : NDArray
        (N,) sign of each lambda_i; ``V S V' = diag(sign)`` (eq. 60).
    """

    U: NDArray[np.float64]
    sigma: NDArray[np.float64]
    V: NDArray[np.float64]
    sign: NDArray[np.float64]


def s_svd(H: NDArray, signs: NDArray) -> SSvd:
    """S-SVD of ``H`` for ``S = diag(signs)`` (Lou et al. 1986, eq. 56-61; Chow et al. eq. 4.29-4.34).

    Raises
    ------
    DesignError
        If ``H S H'`` is singular (eq. 59 needs a non-singular Sigma).
    """
    H = np.atleast_2d(np.asarray(H, float))
    sg = np.asarray(signs, float).ravel()
    if sg.size != H.shape[1] or not np.all(np.isin(sg, (-1.0, 1.0))):
        raise DesignError(f"signs must be {H.shape[1]} entries of +1/-1")
    M = (H * sg) @ H.T
    lam, U = np.linalg.eigh((M + M.T) / 2)
    if np.min(np.abs(lam)) <= 1e-12 * np.max(np.abs(lam)):
        raise DesignError("H S H' is singular, so the S-SVD (eq. 59) does not exist; use fewer rows or more columns")
    sigma = np.sqrt(np.abs(lam))
    V = (U.T @ H) / sigma[:, None]  # V = Sigma^-1 U' H  (eq. 59)
    return SSvd(U=U, sigma=sigma, V=V, sign=np.sign(lam))


def example_icing_models(etas: Sequence[float] = (0.0, 0.05, 0.1), dt_s: float = 0.05) -> list[LinearModel]:
    """A synthetic longitudinal model set, clean and iced, for designs before the DHC-6 linearizer.

    Not the DHC-6: invented stability derivatives of a light twin near 70 m/s; icing scales them
    as ``(1 + eta k)`` in the manner of Bragg's icing factor (lift slope k = -0.8, pitch stiffness
    -1.0, pitch damping -0.5, elevator power -1.0, drag +3). States u, alpha, q, theta; inputs
    elevator and throttle (control) and a vertical gust (disturbance); outputs the four states
    and the normal acceleration az. Zero-order hold at ``dt_s``.
    """
    g_mps2, u_trim_mps = 9.81, 70.0
    out = []
    for eta in etas:
        Xu, Xa, Xth = -0.045 * (1 + 3.0 * eta), 6.0, 2.5
        Zu, Za, Zde = -0.28, -115.0 * (1 - 0.8 * eta), -6.0 * (1 - 1.0 * eta)
        Ma, Mq, Mde = -4.5 * (1 - 1.0 * eta), -2.2 * (1 - 0.5 * eta), -9.0 * (1 - 1.0 * eta)
        A = np.array([[Xu, Xa, 0, -g_mps2], [Zu / u_trim_mps, Za / u_trim_mps, 1, 0], [0, Ma, Mq, 0], [0, 0, 1, 0]])
        B = np.array([[0, Xth, 0], [Zde / u_trim_mps, 0, Za / u_trim_mps**2], [Mde, 0, Ma / u_trim_mps], [0, 0, 0]])
        C = np.vstack([np.eye(4), [Zu, Za, 0, 0]])
        D = np.zeros((5, 3))
        D[4] = [Zde, 0, Za / u_trim_mps]
        m = LinearModel(A=A, B=B, C=C, D=D, state_names=("u_mps", "alpha_rad", "q_radps", "theta_rad"),
                        input_names=("elevator_rad", "throttle_norm", "wgust_mps"),
                        output_names=("u_mps", "alpha_rad", "q_radps", "theta_rad", "az_mps2"),
                        input_kinds=("control", "control", "disturbance"), meta={"synthetic": True, "eta": eta})
        out.append(m.discretize(dt_s))
    return out

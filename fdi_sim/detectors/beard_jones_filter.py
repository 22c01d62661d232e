"""Beard-Jones detection filters on a model: discrete design, the running filter and the bank.

The gain mathematics (detection spaces, eq. 2.8-2.50 of Miller & Ribbens, US 6,643,569 B2, App. A,
seed ``002_d6038a6910cf5866.txt``) is in :mod:`fdi_sim.detectors.beard_jones`. Here
:func:`design_detection_filter` turns a :class:`~fdi_sim.linear.model.LinearModel` and fault names
into a discrete filter (a continuous model is discretized: poles ``z = exp(s dt)``, fault
directions ``f -> int_0^dt e^(A t) dt f``), :func:`plan_bank` groups faults that cannot share one
filter, and :class:`BeardJonesFilter` / :class:`BeardJonesBank` run them.

The design needs ``(A, C)`` observable (Lemma 2.1.3, Theorem 2.1.1). The models of
:func:`fdi_sim.training.models.model_for_scenario` (20 Hz, paired form ``(A, B, C A, C B + D)``) are
not: the accelerometer lag states ``n*_lag_g`` (``z_(k+1) = C_i x_k + D_i u_k``, nothing depends on
them) are invisible to ``C A`` and sit at ``z = 0`` (3 of 13 F-16 and 3 of 15 DHC-6 modes, every
default-grid point, PBH margin exactly 0; every other mode has a scaled margin of 1.9e-4 or more, the
DHC-6 engine and propeller modes, and 0.19 or more on the F-16).
:func:`observable_realization` removes them before the design (exactly: the same output error).
Every actuator of those models also moves the outputs of its own sample (``C B + D``), which
the patent's model (eq. 2.6-2.7) does not have: such a fault gets detection order 0
(:func:`~fdi_sim.detectors.beard_jones.feedthrough_space`), exact from the first sample.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.detectors.beard_jones import (
    BeardJonesDesign,
    beard_jones_gain,
    detection_space,
    has_feedthrough,
    null_basis,
    unobservable_subspace,
)
from fdi_sim.detectors.directional_observer import DirectionalObserver, DiscreteObserver
from fdi_sim.detectors.kalman import observer_residual_covariance
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

Array = NDArray[np.float64]
#: input names (actuator faults, direction ``B[:, j]``), or name -> direction in state coordinates
Faults = Sequence[str] | Mapping[str, Sequence[float]]


#: tolerance of "marginal" for an unobservable mode that :func:`observable_realization` removes:
#: ``|z| <= 1 + MARGINAL_TOL`` (discrete) or ``Re s <= MARGINAL_TOL`` [1/s] (continuous)
MARGINAL_TOL = 1e-9


@dataclass(frozen=True)
class ObservableRealization:
    """The observable part of a model (Kalman observability decomposition): what a filter is designed on.

    With ``T`` an orthonormal basis of the complement of the unobservable subspace ``U`` (the largest
    ``A``-invariant subspace in ``N(C)``), ``x = T x_o + U x_u`` gives ``x_o(k+1) = T'A T x_o + T'B u``,
    ``y = C T x_o + D u``: ``T'A U = 0`` (``U`` is invariant) and ``C U = 0``, so ``x_u`` never reaches
    ``x_o`` or ``y``.

    Attributes
    ----------
    model : LinearModel
        ``(T'A T, T'B, C T, D)`` with ``x0 = T' x0``; the model itself when it is observable.
    basis : NDArray
        (n, n_o) ``T`` [-]: ``x_o = T' x``.
    removed : NDArray
        (n, n - n_o) ``U``, orthonormal basis of the unobservable subspace [-].
    removed_poles : NDArray
        Eigenvalues of ``A`` on ``U`` (model domain: z [-] or s [1/s]).
    removed_states : tuple of str
        The states removed when ``U`` is spanned by state axes (the kept states keep their names and
        ``T`` is a column selection); empty otherwise (states ``obs0, obs1, ...``).
    """

    model: LinearModel
    basis: Array
    removed: Array
    removed_poles: NDArray[np.complex128]
    removed_states: tuple[str, ...]

    @property
    def n_removed(self) -> int:
        """Number of unobservable modes removed."""
        return self.removed.shape[1]


def observable_realization(model: LinearModel) -> ObservableRealization:
    """The observable part of ``model``, for a detection filter (removes unobservable modes that are stable or marginal).

    Sound for detection: an unobservable mode never shows in ``y`` (``C U = 0``) and does not drive
    the observable part (``T'A U = 0``), so a filter on ``(T'A T, T'B, C T, D)`` has the same output
    error ``r = y - y_hat`` as a full-order one, for every input and fault; a fault ``f`` acts through
    ``T' f`` only (its ``U`` part is invisible to any filter). A full-order observer could not
    move those modes anyway (they are eigenvalues of ``A - L C`` for every ``L``, Lemma 2.1.6) and
    the patent's design needs ``(A, C)`` observable (Lemma 2.1.3, Theorem 2.1.1). Removing also
    keeps modes at ``|z| = 1`` out of the filter. ``U`` is the orthogonal staircase of the balanced
    pair (:func:`~fdi_sim.detectors.beard_jones.unobservable_subspace`, the tolerance of the
    observability test). The paired 20 Hz models of both aircraft (``fdi_sim.detectors.samples``,
    ``C A`` for ``C``) have exactly three: the accelerometer lag states ``n*_lag_g`` at ``z = 0``
    (nothing depends on the last sample's lag, every default-grid point).

    Raises
    ------
    DesignError
        An unobservable mode is unstable (``|z| > 1`` or ``Re s > 0``): the linearization leaves its
        trim along a direction no sensor sees (the system is not detectable, eq. 2.1-2.3 assume it is).
    """
    A, C, n = model.A, model.C, model.n_states
    U = unobservable_subspace(A, C)
    if not U.shape[1]:
        return ObservableRealization(model, np.eye(n), np.zeros((n, 0)), np.zeros(0, complex), ())
    poles = np.linalg.eigvals(U.T @ A @ U)
    bad = np.abs(poles) > 1.0 + MARGINAL_TOL if model.is_discrete else poles.real > MARGINAL_TOL
    if bad.any():
        v = U @ np.linalg.eig(U.T @ A @ U)[1][:, int(np.argmax(np.abs(poles) if model.is_discrete else poles.real))]
        top = np.argsort(-np.abs(v))[:3]
        raise DesignError(
            f"(A, C) has {int(bad.sum())} unstable unobservable mode(s) {np.round(poles[bad], 6).tolist()} "
            f"({'|z|' if model.is_discrete else 'Re s'} = "
            f"{np.round(np.abs(poles[bad]) if model.is_discrete else poles[bad].real, 6).tolist()}), mostly in states "
            f"{[model.state_names[i] for i in top]}: no sensor sees them and no filter can follow them; add a sensor")
    w = np.sum(U * U, axis=1)  # diagonal of the projector U U'
    on_axis = np.abs(w - 1.0) < 1e-9
    if np.all(on_axis | (w < 1e-9)) and int(on_axis.sum()) == U.shape[1]:
        keep = np.flatnonzero(~on_axis)
        T, U = np.eye(n)[:, keep], np.eye(n)[:, on_axis]  # the exact axes: A[keep, removed] = 0, C[:, removed] = 0
        poles = np.linalg.eigvals(U.T @ A @ U)
        names = tuple(model.state_names[i] for i in keep)
        removed = tuple(model.state_names[i] for i in np.flatnonzero(on_axis))
    else:
        T = null_basis(U.T)
        names, removed = tuple(f"obs{i}" for i in range(T.shape[1])), ()
    # "lag_states" names states of the model: kept only while all of them are still states
    meta = {k: v for k, v in model.meta.items() if k != "lag_states" or set(v) <= set(names)}
    meta["observable_realization"] = {"from_states": n, "states": int(T.shape[1]), "removed_states": list(removed),
                                      "removed_poles": [[float(p.real), float(p.imag)] for p in poles]}
    reduced = LinearModel(
        A=T.T @ A @ T, B=T.T @ model.B, C=C @ T, D=model.D, dt_s=model.dt_s, state_names=names,
        input_names=model.input_names, output_names=model.output_names, input_kinds=model.input_kinds,
        x0=T.T @ model.x0, u0=model.u0, y0=model.y0, op=model.op, meta=meta,
    )
    return ObservableRealization(reduced, T, U, poles, removed)


@dataclass(frozen=True)
class DetectionFilterDesign:
    """A discrete detection filter ready to run, from :func:`design_detection_filter`.

    Attributes
    ----------
    model : LinearModel
        The discrete model the filter runs on: the observable part of the model it was designed
        from (:func:`observable_realization`; that model itself when it is observable).
    gain : BeardJonesDesign
        The gain design (z-plane poles), in the states of ``model``.
    S : NDArray
        (m, m) steady-state residual covariance for the given noise (identity if none given).
    realization : ObservableRealization or None
        How ``model`` was cut from the discrete model given (``basis``: ``x_o = T' x``).
    """

    model: LinearModel
    gain: BeardJonesDesign
    S: Array
    realization: ObservableRealization | None = None


def fault_directions_from_model(model: LinearModel, faults: Faults) -> tuple[tuple[str, ...], Array]:
    """Fault directions of a model: input names give ``B[:, j]`` (actuator faults), a mapping gives columns.

    Parameters
    ----------
    model : LinearModel
    faults : sequence of input names, or mapping name -> (n,) direction in the model's state coordinates

    Returns
    -------
    names : tuple of str
    F : (n, r) array
        The directions as columns.
    """
    n = model.n_states
    if isinstance(faults, Mapping):
        cols = [np.asarray(faults[k], float).reshape(n) for k in faults]
    else:
        unknown = [name for name in faults if name not in model.input_names]
        if unknown:
            raise DesignError(f"fault(s) {unknown} are not inputs of the model; inputs are {list(model.input_names)}")
        cols = [model.B[:, model.input_names.index(name)] for name in faults]
    return tuple(faults), (np.column_stack(cols) if cols else np.zeros((n, 0)))


def fault_feedthrough_from_model(model: LinearModel, faults: Faults) -> Array:
    """The direct effect of each fault on the outputs: ``D[:, j]`` of an actuator fault, 0 for a state direction.

    Returns
    -------
    (m, r) array
        [output units per unit fault].
    """
    if isinstance(faults, Mapping):
        return np.zeros((model.n_outputs, len(faults)))
    cols = [model.D[:, model.input_names.index(name)] for name in faults]
    return np.column_stack(cols) if cols else np.zeros((model.n_outputs, 0))


#: smallest whitened feedthrough ``|R^-1/2 d|`` [-] (per unit of the input) of a control input that
#: :func:`default_faults` keeps when it has a feedthrough at all. Below it a full-scale fault moves
#: the outputs of its own sample by less than one noise standard deviation, and its order-0 gain
#: ``L d = f`` (:func:`~fdi_sim.detectors.beard_jones.feedthrough_space`) is ``|f| / |d|`` large. On the
#: paired 20 Hz models of the 50 default-grid points (suite noise) the surfaces and the F-16 throttle
#: have 44 or more, the DHC-6 throttle 0.08-0.28 (it acts through the PT6A's n1 and propeller
#: states, which the sensors see with a PBH margin of 2.6e-4): its filter gain reaches 3e5-3e6, its
#: steady residual 0.005-0.05 noise sigma per unit throttle, and sharing a filter with it costs the
#: DHC-6 surfaces 2-12 times their SNR (aileron 298 -> 24 per unit at 5000 ft / 120 KCAS).
MIN_FEEDTHROUGH_SNR = 1.0


def default_faults(model: LinearModel, R: NDArray | None = None) -> list[str]:
    """The actuator faults a Beard-Jones filter is designed for by default.

    Every control input, except one whose feedthrough is not zero but below the noise:
    ``0 < |R^-1/2 D[:, j]| < MIN_FEEDTHROUGH_SNR`` (:data:`MIN_FEEDTHROUGH_SNR`; unweighted ``|D[:, j]|``
    without ``R``). An input without feedthrough is kept (order >= 1 design, eq. 2.11-2.50).

    Parameters
    ----------
    model : LinearModel
    R : (m, m) array, optional
        Measurement-noise covariance [output units squared].
    """
    W = np.linalg.inv(np.linalg.cholesky(np.asarray(R, float))) if R is not None else np.eye(model.n_outputs)
    out = []
    for j in model.control_columns():
        d = model.D[:, j]
        if has_feedthrough(model.C, model.B[:, j], d) and np.linalg.norm(W @ d) < MIN_FEEDTHROUGH_SNR:
            continue  # seen within its sample below the noise: left out (MIN_FEEDTHROUGH_SNR)
        out.append(model.input_names[j])
    return out


def spread_poles(base: complex, count: int, step: float = 0.15) -> NDArray[np.complex128]:
    """``count`` distinct real poles ``base * (1 + step j)``, j = 0..count-1 (place_poles needs distinct poles)."""
    return base * (1.0 + step * np.arange(count, dtype=complex))


def design_detection_filter(
    model: LinearModel,
    faults: Faults,
    detection_pole_radps: float = -4.0,
    completion_pole_radps: float = -6.0,
    dt_s: float | None = None,
    Q: NDArray | None = None,
    R: NDArray | None = None,
    allow_shift: bool = False,
) -> DetectionFilterDesign:
    """Design a discrete detection filter for ``faults`` on ``model`` (one filter, all faults).

    The filter is designed on, and runs, the observable part of the discrete model
    (:func:`observable_realization`). An actuator fault with a feedthrough ``d = D[:, j]`` gets
    detection order 0 (``L d = f``, residual ``d n`` exactly,
    :func:`~fdi_sim.detectors.beard_jones.feedthrough_space`); the others the detection space of
    App. A. Continuous poles ``s`` are mapped to ``z = exp(s dt)``; detection poles are spread
    (:func:`spread_poles`) over each detection order, completion poles over the rest.

    Parameters
    ----------
    model : LinearModel
        Continuous (needs ``dt_s``) or discrete.
    faults : sequence or mapping
        Input names (actuator faults, direction ``B[:, j]``, feedthrough ``D[:, j]``) or name ->
        continuous-time direction (no feedthrough).
    detection_pole_radps, completion_pole_radps : float
        Continuous-time pole locations [1/s], negative.
    dt_s : float, optional
        Sample time [s] for a continuous model.
    Q : (n, n) array, optional
        Discrete process-noise covariance per step (for the residual covariance ``S``), in the
        states of ``model`` (projected on the observable part here).
    R : (m, m) array, optional
        Measurement-noise covariance.
    allow_shift : bool
        Passed to :func:`~fdi_sim.detectors.beard_jones.beard_jones_gain` (faults with ``C f = 0``).
    """
    if detection_pole_radps >= 0 or completion_pole_radps >= 0:
        raise DesignError("detection_pole_radps and completion_pole_radps must be negative [1/s]")
    names, F = fault_directions_from_model(model, faults)
    if not names:
        raise DesignError("no fault to design a detection filter for: give at least one input name or direction")
    if not model.is_discrete:
        if dt_s is None or dt_s <= 0:
            raise DesignError("a continuous model needs dt_s > 0 to run as a discrete detection filter")
        # a constant fault f enters the ZOH model as int_0^dt e^(A t) dt f: the input matrix of (A, F) discretized
        F = LinearModel(A=model.A, B=F, C=model.C, D=np.zeros((model.n_outputs, F.shape[1]))).discretize(dt_s).B
        model = model.discretize(dt_s)
    G = fault_feedthrough_from_model(model, faults)  # y = C x + D u: a fault on u_j adds D[:, j] n at once
    real = observable_realization(model)
    T, model = real.basis, real.model
    F = T.T @ F  # x_o = T' x: only the observable part of a fault acts on what the filter sees
    if Q is not None:
        Q = T.T @ np.asarray(Q, float) @ T
    A, C, dt = model.A, model.C, model.dt_s
    orders = [0 if has_feedthrough(C, F[:, i], G[:, i]) else detection_space(A, C, F[:, i], names[i]).order
              for i in range(F.shape[1])]
    det = [np.exp(spread_poles(detection_pole_radps * (1 + 0.05 * i), k) * dt) for i, k in enumerate(orders)]
    gain = beard_jones_gain(
        A, C, F, det, lambda count: np.exp(spread_poles(completion_pole_radps, count) * dt), names,
        discrete=True, allow_shift=allow_shift, feedthrough=G,
    )
    return DetectionFilterDesign(model, gain, observer_residual_covariance(gain.A_cl, C, gain.L, Q, R), real)


def plan_bank(model: LinearModel, faults: Faults, **options: Any) -> list[DetectionFilterDesign]:
    """Group faults greedily into as few filters as the theory allows.

    A fault joins the first group with which one filter can still be designed (output separable,
    independent detection spaces, stable unassignable poles); otherwise it starts a new group.
    A fault that cannot be designed even alone raises its own :class:`DesignError`.

    Parameters
    ----------
    model : LinearModel
    faults : sequence or mapping
        As in :func:`design_detection_filter`.
    **options
        Keyword arguments of :func:`design_detection_filter` (poles, ``dt_s``, ``Q``, ``R``, ``allow_shift``).
    """
    names, _ = fault_directions_from_model(model, faults)
    if not names:
        raise DesignError("a bank needs at least one fault")
    design = partial(design_detection_filter, model, **options)
    subset = (lambda keys: {k: faults[k] for k in keys}) if isinstance(faults, Mapping) else list
    groups: list[list[str]] = []
    designs: list[DetectionFilterDesign] = []
    for name in names:
        for gi, grp in enumerate(groups):
            try:
                designs[gi] = design(subset([*grp, name]))
            except DesignError:
                continue
            grp.append(name)
            break
        else:
            designs.append(design(subset([name])))
            groups.append([name])
    return designs


class BeardJonesFilter(DirectionalObserver):
    """A running Beard-Jones detection filter (``reset(rng)`` / ``step(t_s, u, y)``).

    ``r(k) = y(k) - C xh(k) - D u(k)``, ``xh(k+1) = A xh(k) + B u(k) + L r(k)`` (eq. 2.3-2.4 in
    discrete form, deviations from trim), run as ``xh+ = (A - L C) xh + (B - L D) u + L y`` on the
    states of ``design.model`` (the observable part, :func:`observable_realization`). The
    statistic is ``r' S^-1 r`` against the chi-square threshold at ``alpha``; isolation is by the
    whitened angle between ``r`` and each output direction ``C f_i`` or ``D[:, j]``
    (:class:`DirectionalObserver`).

    Parameters
    ----------
    design : DetectionFilterDesign
    alpha : float
        Per-sample false-alarm probability of the chi-square threshold (Gaussian residual).
    max_angle_rad : float
        Largest residual angle [rad] accepted for isolation.
    id : str
        Registry id.
    """

    def __init__(self, design: DetectionFilterDesign, alpha: float = 1e-3, max_angle_rad: float = 0.35, id: str = "beard-jones-v1") -> None:
        md = design.model
        observer = DiscreteObserver.from_gain(md.A, md.B, md.C, md.D, design.gain.L, md.u0, md.y0)
        super().__init__(observer, design.S, design.gain.output_directions, design.gain.names, alpha, max_angle_rad, id)
        self.design = design


class BeardJonesBank:
    """A bank of Beard-Jones filters run side by side (faults that cannot share one filter).

    The statistic is ``max_j stat_j / threshold_j`` against 1; scores are each hypothesis's angle
    in its own filter; isolation comes from the filter with the largest normalized statistic.
    """

    def __init__(self, filters: Sequence[BeardJonesFilter], id: str = "beard-jones-bank-v1") -> None:
        if not filters:
            raise DesignError("a bank needs at least one filter")
        self.filters, self.id = list(filters), id
        self.hypotheses: tuple[str, ...] = tuple(h for f in self.filters for h in f.hypotheses)
        r_end = np.cumsum([f.n_outputs for f in self.filters])
        s_end = np.cumsum([len(f.hypotheses) for f in self.filters])
        # each filter's slice of the concatenated residual and scores
        self._slices = [(slice(re - f.n_outputs, re), slice(se - len(f.hypotheses), se))
                        for f, re, se in zip(self.filters, r_end, s_end)]
        self._ratios = np.empty(len(self.filters))

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Reset every filter."""
        for f in self.filters:
            f.reset(rng)

    def step(self, t_s: float, u: NDArray, y: NDArray) -> Residual:
        """Step every filter on the same sample."""
        r, scores = np.empty(self._slices[-1][0].stop), np.empty(len(self.hypotheses))
        for i, (f, (rs, ss)) in enumerate(zip(self.filters, self._slices)):
            self._ratios[i] = f.advance(u, y, r[rs], scores[ss]) / f.threshold
        j = int(np.argmax(self._ratios))
        ratio = float(self._ratios[j])
        alarm = ratio > 1.0
        iso = self.filters[j].isolate(scores[self._slices[j][1]]) if alarm else None
        res = Residual(t_s, r, ratio, 0, 1.0, alarm, iso, scores)
        # one diverged filter makes its ratio NaN/inf: the bank's step is invalid (checked over all ratios and r)
        return res if np.isfinite(self._ratios).all() else replace(finite_or_invalid(res), alarm=False, isolation=None,
                                                                    valid=False)

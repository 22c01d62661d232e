"""Beard-Jones detection filters on a model: discrete design, the running filter and the bank.

The gain mathematics (detection spaces, eq. 2.8-2.50 of Miller & Ribbens, US 6,643,569 B2, App. A,
seed ``002_d6038a6910cf5866.txt``) is in :mod:`fdi_sim.detectors.beard_jones`. Here
:func:`design_detection_filter` turns a :class:`~fdi_sim.linear.model.LinearModel` and fault names
into a discrete filter (a continuous model is discretized: poles ``z = exp(s dt)``, fault
directions ``f -> int_0^dt e^(A t) dt f``), :func:`plan_bank` groups faults that cannot share one
filter, and :class:`BeardJonesFilter` / :class:`BeardJonesBank` run them.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.base import Residual, finite_or_invalid
from fdi_sim.detectors.beard_jones import BeardJonesDesign, beard_jones_gain, detection_space
from fdi_sim.detectors.directional_observer import DirectionalObserver, DiscreteObserver
from fdi_sim.detectors.kalman import observer_residual_covariance
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

Array = NDArray[np.float64]
#: input names (actuator faults, direction ``B[:, j]``), or name -> direction in state coordinates
Faults = Sequence[str] | Mapping[str, Sequence[float]]


@dataclass(frozen=True)
class DetectionFilterDesign:
    """A discrete detection filter ready to run, from :func:`design_detection_filter`.

    Attributes
    ----------
    model : LinearModel
        The discrete model the filter runs on.
    gain : BeardJonesDesign
        The gain design (z-plane poles).
    S : NDArray
        (m, m) steady-state residual covariance for the given noise (identity if none given).
    """

    model: LinearModel
    gain: BeardJonesDesign
    S: Array


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

    Continuous poles ``s`` are mapped to ``z = exp(s dt)``; detection poles are spread
    (:func:`spread_poles`) over each detection order, completion poles over the rest.

    Parameters
    ----------
    model : LinearModel
        Continuous (needs ``dt_s``) or discrete.
    faults : sequence or mapping
        Input names (actuator faults, direction ``B[:, j]``) or name -> continuous-time direction.
    detection_pole_radps, completion_pole_radps : float
        Continuous-time pole locations [1/s], negative.
    dt_s : float, optional
        Sample time [s] for a continuous model.
    Q : (n, n) array, optional
        Discrete process-noise covariance per step (for the residual covariance ``S``).
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
    A, C, dt = model.A, model.C, model.dt_s
    orders = [detection_space(A, C, F[:, i], names[i]).order for i in range(F.shape[1])]
    det = [np.exp(spread_poles(detection_pole_radps * (1 + 0.05 * i), k) * dt) for i, k in enumerate(orders)]
    gain = beard_jones_gain(
        A, C, F, det, lambda count: np.exp(spread_poles(completion_pole_radps, count) * dt), names,
        discrete=True, allow_shift=allow_shift,
    )
    return DetectionFilterDesign(model, gain, observer_residual_covariance(gain.A_cl, C, gain.L, Q, R))


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
    discrete form, deviations from trim), run as ``xh+ = (A - L C) xh + (B - L D) u + L y``. The
    statistic is ``r' S^-1 r`` against the chi-square threshold at ``alpha``; isolation is by the
    whitened angle between ``r`` and each output direction ``C f_i`` (:class:`DirectionalObserver`).

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

"""Beard-Jones design on the observable part of a model, and faults that reach the outputs directly.

Two extensions of Miller & Ribbens (US 6,643,569 B2), App. A, that the aircraft models need:
unobservable modes are removed before the design (Kalman decomposition; the residual is the same
output error), and a fault with a feedthrough ``y = C x + d n`` gets detection order 0 (``L d = f``,
residual ``d n`` exactly; eq. 2.24 with k = 0).
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.detectors.beard_jones import (
    angle_rad,
    beard_jones_gain,
    feedthrough_space,
    output_separability,
)
from fdi_sim.detectors.beard_jones_filter import (
    BeardJonesFilter,
    design_detection_filter,
    observable_realization,
)
from fdi_sim.detectors.directional_observer import DiscreteObserver
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel


def _system(seed: int = 3, n: int = 5, m: int = 4, p: int = 2) -> tuple[np.ndarray, ...]:
    """A stable random discrete system with a feedthrough on every input."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.9 / np.abs(np.linalg.eigvals(A)).max()
    return A, rng.normal(size=(n, p)), rng.normal(size=(m, n)), rng.normal(size=(m, p))


def _residuals(A, B, C, D, L, j: int, n_of_k, steps: int = 80) -> np.ndarray:
    """Output error of the observer with gain L when input j carries the fault n(k) (plant and filter from 0)."""
    x, xh, out = np.zeros(A.shape[0]), np.zeros(A.shape[0]), []
    for k in range(steps):
        du = np.zeros(B.shape[1])
        du[j] = n_of_k(k)
        r = C @ x + D @ du - C @ xh  # the filter is given the commanded input 0
        out.append(r)
        x, xh = A @ x + B @ du, A @ xh + L @ r
    return np.array(out)


def test_order_0_residual_is_the_feedthrough_direction_at_every_sample() -> None:
    A, B, C, D = _system()
    d = beard_jones_gain(A, C, B, [[], []], np.linspace(0.3, 0.5, A.shape[0]), discrete=True, feedthrough=D)
    assert [s.order for s in d.spaces] == [0, 0] and all(s.feedthrough is not None for s in d.spaces)
    assert np.allclose(d.L @ D, B, atol=1e-10)  # L d_i = f_i: the state error is never driven
    assert np.abs(d.poles).max() < 1 and d.max_direction_error_rad < 1e-9
    for j in range(2):
        assert angle_rad(d.output_directions[:, j], D[:, j]) < 1e-12
        for n_of_k in (lambda k: 1.0, lambda k: np.sin(0.3 * k) + 0.2 * np.cos(1.7 * k)):
            R = _residuals(A, B, C, D, d.L, j, n_of_k)
            big = np.linalg.norm(R, axis=1) > 1e-9
            assert big.sum() > 70 and max(angle_rad(r, D[:, j]) for r in R[big]) < 1e-9
    # the classical order-1 design on the same faults, the feedthrough left out: the direction is lost
    old = beard_jones_gain(A, C, B, [[0.2], [0.25]], np.linspace(0.3, 0.5, A.shape[0] - 2), discrete=True)
    R = _residuals(A, B, C, D, old.L, 0, lambda k: 1.0)
    assert max(min(angle_rad(r, D[:, 0]), angle_rad(r, old.output_directions[:, 0])) for r in R[1:]) > 0.05


def test_feedthrough_sets_the_output_direction_and_separability() -> None:
    A, B, C, D = _system()
    sep = output_separability(A, C, B, feedthrough=D)
    assert sep.separable and sep.feedthrough == (True, True)
    assert angle_rad(sep.output_directions[:, 1], D[:, 1]) < 1e-12
    both = np.column_stack([D[:, 0], 2.0 * D[:, 0]])  # two faults seen along one direction at once
    assert not output_separability(A, C, B, feedthrough=both).separable
    with pytest.raises(DesignError, match="not output separable"):
        beard_jones_gain(A, C, B, [[], []], np.linspace(0.3, 0.5, A.shape[0]), discrete=True, feedthrough=both)
    with pytest.raises(DesignError, match="feedthrough is zero"):
        feedthrough_space(A, C, B[:, 0], np.zeros(C.shape[0]))


def _with_unobservable(pole: float) -> tuple[LinearModel, np.ndarray]:
    """The random system plus two states no output sees (one feeding the other), at ``pole``."""
    A, B, C, D = _system()
    n = A.shape[0]
    Af = np.zeros((n + 2, n + 2))
    Af[:n, :n], Af[n:, :n] = A, 0.3 * C[:2]  # the extra states follow the others, nothing follows them
    Af[n:, n:] = [[pole, 0.1], [0.0, 0.5 * pole]]
    Bf = np.vstack([B, np.ones((2, B.shape[1]))])
    Cf = np.hstack([C, np.zeros((C.shape[0], 2))])
    model = LinearModel(A=Af, B=Bf, C=Cf, D=D, dt_s=0.05, state_names=tuple(f"s{i}" for i in range(n)) + ("u1", "u2"),
                        input_names=("a_cmd_norm", "b_cmd_norm"))
    return model, Af


def test_observable_realization_gives_the_full_order_residual() -> None:
    model, _ = _with_unobservable(1.0)  # a marginal unobservable mode (an integrator no sensor sees)
    real = observable_realization(model)
    assert real.removed_states == ("u1", "u2") and real.model.state_names == tuple(f"s{i}" for i in range(5))
    assert np.allclose(np.sort(real.removed_poles.real), [0.5, 1.0])
    design = design_detection_filter(model, ["a_cmd_norm", "b_cmd_norm"])
    assert design.model.n_states == 5 and design.realization.removed_states == ("u1", "u2")
    filt = BeardJonesFilter(design)
    # the same gain lifted to the full state (zero on the removed states): residuals agree to rounding
    T = design.realization.basis
    full = DiscreteObserver.from_gain(model.A, model.B, model.C, model.D, T @ design.gain.L, model.u0, model.y0)
    rng = np.random.default_rng(5)
    x, r_full = np.zeros(7), np.empty(model.n_outputs)
    filt.reset()
    full.reset()
    for k in range(200):
        u = 0.1 * rng.normal(size=2)
        y = model.C @ x + model.D @ u + 0.01 * rng.normal(size=model.n_outputs)
        r = filt.step(k * 0.05, u, y).r
        full.residual(u, y, r_full)
        assert np.allclose(r, r_full, rtol=1e-9, atol=1e-12)
        x = model.A @ x + model.B @ u
    # the full-order filter keeps the removed modes (its |z| = 1 mode), the reduced one is strictly stable
    assert np.isclose(np.abs(np.linalg.eigvals(full._F[:, :7])).max(), 1.0)
    assert np.abs(np.linalg.eigvals(filt.observer._F[:, :5])).max() < 0.8


def test_unstable_unobservable_mode_is_refused_with_its_numbers() -> None:
    model, _ = _with_unobservable(1.2)
    with pytest.raises(DesignError, match=r"unstable unobservable mode.*1\.2.*\['u1'"):
        observable_realization(model)


def test_unobservable_subspace_off_the_state_axes_gets_new_state_names() -> None:
    model, _ = _with_unobservable(0.4)
    rng = np.random.default_rng(1)
    Q, _ = np.linalg.qr(rng.normal(size=(7, 7)))  # x = Q z: the unobservable directions mix every state
    mixed = LinearModel(A=Q.T @ model.A @ Q, B=Q.T @ model.B, C=model.C @ Q, D=model.D, dt_s=0.05)
    real = observable_realization(mixed)
    assert real.n_removed == 2 and real.removed_states == () and real.model.state_names[0] == "obs0"
    assert np.allclose(mixed.C @ real.removed, 0.0, atol=1e-10)
    same = observable_realization(model).model
    # the same input-output map: Markov parameters C A^k B agree
    for k in range(6):
        assert np.allclose(real.model.C @ np.linalg.matrix_power(real.model.A, k) @ real.model.B,
                           same.C @ np.linalg.matrix_power(same.A, k) @ same.B, atol=1e-9)

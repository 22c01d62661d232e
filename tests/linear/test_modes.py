"""Mode naming: synthetic models with known modes, unit invariance, python-control's damp as reference."""
from __future__ import annotations

import itertools

import control
import numpy as np
import pytest

from fdi_sim.errors import DesignError
from fdi_sim.linear.modes import identify_modes, match_eigenvalues, participation

STATES = ("vt_fps", "alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps", "phi_rad", "theta_rad", "psi_rad", "h_ft")


def _pair_block(sigma: float, wd: float) -> np.ndarray:
    return np.array([[sigma, wd], [-wd, sigma]])


def synthetic_aircraft(rng: np.random.Generator, overdamped_sp: bool = False) -> np.ndarray:
    """A with short period on (alpha, q), phugoid on (vt, theta), altitude on h, Dutch roll on
    (beta, r), roll on p, spiral on phi, heading on psi, then weakly coupled and rotated a little."""
    idx = {s: i for i, s in enumerate(STATES)}
    A = np.zeros((10, 10))

    def put(block: np.ndarray, names: tuple[str, ...]) -> None:
        ii = [idx[s] for s in names]
        A[np.ix_(ii, ii)] = block

    put(np.diag([-9.0, -1.7]) if overdamped_sp else _pair_block(-2.2, 2.6), ("alpha_rad", "q_radps"))
    put(_pair_block(-0.02, 0.18), ("vt_fps", "theta_rad"))
    put(np.array([[-0.001]]), ("h_ft",))
    put(_pair_block(-0.4, 4.4), ("beta_rad", "r_radps"))
    put(np.array([[-5.5]]), ("p_radps",))
    put(np.array([[-0.02]]), ("phi_rad",))
    put(np.array([[0.0]]), ("psi_rad",))
    # weak coupling keeps the structure recognizable but makes the eigenvectors non-trivial
    T = np.eye(10) + 0.05 * rng.normal(size=(10, 10))
    return T @ A @ np.linalg.inv(T)


@pytest.mark.parametrize("overdamped", [False, True])
def test_names_recovered_and_invariant_to_units(overdamped: bool) -> None:
    rng = np.random.default_rng(11)
    A = synthetic_aircraft(rng, overdamped)
    mt = identify_modes(A, STATES)
    names = sorted(m.name for m in mt.modes)
    sp = mt.get("short period")
    assert len(sp) == (2 if overdamped else 1)
    assert not overdamped or all(not m.is_pair for m in sp)
    for want in ("phugoid", "dutch roll", "roll", "spiral", "heading", "altitude"):
        assert len(mt.get(want)) == 1, (want, names)
    assert abs(mt.get("dutch roll")[0].eigenvalue - complex(-0.4, 4.4)) < 0.05
    assert abs(mt.get("roll")[0].eigenvalue + 5.5) < 0.1
    assert abs(mt.get("spiral")[0].eigenvalue + 0.02) < 0.005
    # a change of units (diagonal similarity) must not change any name
    S = np.diag(10.0 ** rng.uniform(-3, 3, size=10))
    mt2 = identify_modes(S @ A @ np.linalg.inv(S), STATES)
    for m in mt.modes:
        twin = [x for x in mt2.modes if abs(x.eigenvalue - m.eigenvalue) < 1e-6 * max(1, abs(m.eigenvalue))]
        assert twin and twin[0].name == m.name


def test_frequency_and_damping_match_python_control() -> None:
    A = synthetic_aircraft(np.random.default_rng(12))
    mt = identify_modes(A, STATES)
    wn, zeta, poles = control.damp(control.ss(A, np.zeros((10, 1)), np.zeros((1, 10)), 0), doprint=False)
    for m in mt.modes:
        if m.name == "heading":
            continue
        k = int(np.argmin(np.abs(poles - m.eigenvalue)))
        assert m.wn_radps == pytest.approx(wn[k], rel=1e-9)
        assert m.zeta == pytest.approx(zeta[k], rel=1e-9, abs=1e-12)
        if m.is_pair:
            assert m.period_s == pytest.approx(2 * np.pi / m.eigenvalue.imag)
        else:
            assert m.tau_s == pytest.approx(-1 / m.eigenvalue.real)
    np.testing.assert_allclose(np.sort_complex(mt.eigenvalues()), np.sort_complex(np.linalg.eigvals(A)), atol=1e-9)


def test_participation_does_not_depend_on_units_or_state_order() -> None:
    """The module's reason for participation factors over mode shapes: a change of units (diagonal
    similarity) leaves them unchanged, a reordering of the states permutes their rows."""
    rng = np.random.default_rng(13)
    A = synthetic_aircraft(rng)
    lam, P = participation(A)
    S = np.diag(10.0 ** rng.uniform(-3, 3, size=10))
    perm = rng.permutation(10)
    for A2, rows in ((S @ A @ np.linalg.inv(S), np.arange(10)), (A[np.ix_(perm, perm)], perm)):
        lam2, P2 = participation(A2)
        k = [int(np.argmin(np.abs(lam2 - z))) for z in lam]  # the same mode in the other coordinates
        np.testing.assert_allclose(P2[:, k], P[rows], atol=1e-8)
    np.testing.assert_allclose(P.sum(axis=0), 1.0)
    # a triangular A: each mode belongs to its own state alone
    _, Pt = participation(np.triu(rng.normal(size=(4, 4))) + np.diag([-1.0, -2.0, -3.0, -4.0]))
    np.testing.assert_allclose(Pt, np.eye(4), atol=1e-12)


def test_match_eigenvalues_is_the_optimal_pairing() -> None:
    rng = np.random.default_rng(14)
    a = rng.normal(size=6) + 1j * rng.normal(size=6)
    b = a[rng.permutation(6)] * (1 + 0.01 * rng.normal(size=6))
    j, rel = match_eigenvalues(a, b)
    best = min(itertools.permutations(range(6)), key=lambda p: np.sum(np.abs(a - b[list(p)])))
    assert list(j) == list(best)
    assert np.all(rel < 0.05)


def test_relative_errors_per_mode() -> None:
    """A pair scores the worse of its two roots against the reference; real roots score alone."""
    mt = identify_modes(synthetic_aircraft(np.random.default_rng(15)), STATES)
    lam = mt.eigenvalues()
    ref = lam * (1 + 0.01 * np.arange(lam.size))  # a distinct relative error per eigenvalue
    rel = mt.relative_errors(ref)
    k = 0
    for m, r in zip(mt.modes, rel):
        n = 2 if m.is_pair else 1
        expected = max(abs(lam[i] - ref[i]) / max(abs(ref[i]), 1e-3) for i in range(k, k + n))
        assert r == pytest.approx(expected, rel=1e-12, abs=1e-15), m.name
        k += n


def test_bad_input() -> None:
    with pytest.raises(DesignError, match="state names"):
        identify_modes(np.eye(3), STATES)
    J = np.array([[0.0, 1.0], [0.0, 0.0]])  # a Jordan block has no eigenvector basis
    with pytest.raises(DesignError, match="defective"):
        participation(J)

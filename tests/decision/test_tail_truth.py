"""The exact episode rates of the synthetic statistics, and the tail bound's coverage measured
against them at the extrapolation the default banks use (the smallest member target: the DHC-6's
six members, 3,000 x)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from fdi_sim.decision.tail import MAX_EXTRAPOLATION, confident_episode_threshold
from fdi_sim.decision.tail_truth import (
    TRANSFORMS,
    Ar1Statistic,
    ar1_flights,
    episode_rate_curve,
    simulate_episode_rate,
)
from fdi_sim.bank.members import default_member_far_per_h
from fdi_sim.errors import DesignError

#: the smallest per-member target of the default banks [1/h]: the default far_per_h over the largest bank
MEMBER_TARGET_PER_H = min(default_member_far_per_h().values())


def test_one_of_one_matches_the_bivariate_normal():
    """Without persistence an episode is ``|x[j-1]| <= u < |x[j]|``: a bivariate-normal rectangle."""
    stat = Ar1Statistic(k=1, n=1)
    curve = episode_rate_curve(stat, np.array([2.0, 3.0, 4.0]))
    rho = stat.rho
    mv = multivariate_normal(mean=[0.0, 0.0], cov=[[1.0, rho], [rho, 1.0]])
    for u, got in zip((2.0, 3.0, 4.0), curve.per_h):
        inside = norm.cdf(u) - norm.cdf(-u)
        box = mv.cdf([u, u]) - mv.cdf([-u, u]) - mv.cdf([u, -u]) + mv.cdf([-u, -u])
        assert got == pytest.approx((inside - box) * 20.0 * 3600.0, rel=2e-3)


def test_the_grid_is_fine_enough():
    stat = Ar1Statistic()
    u = np.array([2.0, 4.0, 5.0])
    assert episode_rate_curve(stat, u).per_h == pytest.approx(episode_rate_curve(stat, u, h=0.00125).per_h, rel=1e-3)


def test_three_of_five_matches_simulated_flights():
    """100 h of 1 h flights: the counts at three levels within 4 % of the exact rate (episodes
    cluster, so their spread is wider than Poisson's; measured 1-2 %)."""
    stat = Ar1Statistic()
    levels = np.array([1.5, 2.0, 2.5])
    exact = episode_rate_curve(stat, levels).per_h
    counted = simulate_episode_rate(stat, levels, 100.0, np.random.default_rng(11)) / 100.0
    assert counted == pytest.approx(exact, rel=0.04)


@pytest.mark.parametrize("transform", list(TRANSFORMS))
def test_every_transform_has_the_episodes_of_abs_x(transform):
    stat = Ar1Statistic(transform=transform)
    for u in (0.7, 2.5, 4.2):
        assert stat.level(float(stat.statistic(np.array([u]))[0])) == pytest.approx(u, abs=1e-9)


LIGHT_XFAIL = pytest.mark.xfail(strict=True, reason=(
    "the form the kinematic checks give (x^2, light-tailed) covers about 0.92 at 2,500 x, not the 95 % "
    "promised nor 36 of these 40: 33 of 40 here (at 3,000 x; 33 at 2,500 x too), 162 of 180 on seeds "
    "[77, 0..179] at 2,500 x, 188 of 200 there in "
    "docs/tail_coverage.md; probably the exponential in x^2 is a little too light at the fitted level (Rice's "
    "polynomial factor), a bias the bootstrap cannot see"))


@pytest.mark.parametrize("power, heavy", [(None, True), pytest.param(2.0, False, marks=LIGHT_XFAIL)],
                         ids=["form-chosen", "form-given-light"])
def test_the_bound_covers_a_gaussian_statistic_at_the_member_target(power, heavy):
    """The issue's bar: 24 x 300 s of a Gaussian AR(1) statistic (10 s correlation, 3-of-5), the
    default banks' smallest member target (0.1 / 6 per h, 3,000 x beyond the fitted level's 50 per
    h; the F-16's 0.02 is 2,500 x): the share of 40 trials whose
    bound's exact rate meets the target is at least 0.9, with the tail's form chosen from the data
    and given as the kinematic checks give it (the full table, 200 trials a row:
    docs/tail_coverage.md)."""
    stat = Ar1Statistic()
    curve = episode_rate_curve(stat, np.linspace(2.0, 7.0, 51))
    covered = 0
    for t in range(40):
        rng = np.random.default_rng([77, t])
        thr, _ = confident_episode_threshold(ar1_flights(stat, 24, 300.0, rng), MEMBER_TARGET_PER_H,
                                             [300.0 / 3600.0] * 24, rng, power=power, heavy=heavy)
        covered += curve.rate_per_h(thr) <= MEMBER_TARGET_PER_H
    print(f"form {power}, heavy {heavy}: {covered} of 40 covered")
    assert covered >= 36, covered


def test_a_target_beyond_the_measured_extrapolation_is_refused():
    stat = Ar1Statistic()
    rng = np.random.default_rng(3)
    fl = ar1_flights(stat, 24, 300.0, rng)
    with pytest.raises(DesignError, match=r"calibration flights"):
        confident_episode_threshold(fl, 50.0 / MAX_EXTRAPOLATION / 3.0, [300.0 / 3600.0] * 24, rng, n_boot=20)

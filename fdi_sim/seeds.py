"""The seed registry: every seed the project's studies, cards, figures and bars fly, with its role.

A method is judged on flights it was not tuned on. Four roles keep that honest:

- ``development``: looked at freely, tuned on (and every set that was once "held out" but then
  shaped a decision: it is development now, and says what it shaped);
- ``calibration``: thresholds and filters are fitted on it;
- ``validation``: a fresh seed that checks a calibration once it is made (never fitted on);
- ``hold-out``: looked at once to report a bar, never tuned on;
- ``benchmark``: a frozen benchmark suite (``fdi_sim/bench``): every method is reported on it, as
  often as the leaderboard is made, and none of fdi-sim's own is tuned on it (its ``train`` split
  is for learners outside fdi-sim).

Training flights (:func:`fdi_sim.training.flights.training_seeds`) are calibration flights of
the trained thresholds. A study's seed is its master seed: run ``i`` flies
``SeedSequence([seed, i])`` (:mod:`fdi_sim.study.spec`), so two studies with different master
seeds share no flight. ``tests/test_seeds.py`` checks that the sets are disjoint, that every
shipped study and every module-level seed constant draws from here, and that a hold-out set is
used by one consumer only.

Synthetic data (``docs/make_tail_coverage.py``'s AR(1) statistics) draws from its own set: its
numbers are not flights.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["REGISTRY", "SeedSet", "role_of", "seed_set", "seeds"]

ROLES = ("development", "calibration", "validation", "hold-out", "benchmark", "synthetic")


@dataclass(frozen=True)
class SeedSet:
    """A named set of seeds with one role.

    Attributes
    ----------
    name : str
    role : str
        One of :data:`ROLES`.
    seeds : tuple of int
    used_by : tuple of str
        The studies, modules or tests that fly it (a hold-out set: exactly one).
    history : str
        What it was used for, and what it shaped (why a set is development now).
    """

    name: str
    role: str
    seeds: tuple[int, ...]
    used_by: tuple[str, ...]
    history: str

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"seed set {self.name!r}: role {self.role!r} is not one of {', '.join(ROLES)}")


def _r(a: int, b: int) -> tuple[int, ...]:
    return tuple(range(a, b))


REGISTRY: tuple[SeedSet, ...] = (
    SeedSet("training", "calibration", _r(1_000_000, 1_001_000), ("fdi_sim.training.flights",),
            "the trained thresholds' fault-free training flights (seed 1e6 + i)"),
    SeedSet("kinematic-calibration", "calibration", _r(1, 9), ("docs/make_kinematic_card.py",),
            "the kinematic checks' noise levels and windows were set on these"),
    SeedSet("kinematic-card", "development", _r(11, 19), ("docs/make_kinematic_card.py",),
            "the kinematic card's held-out flights, reported many times while the checks changed"),
    SeedSet("bank-development-1", "development", _r(101, 109),
            ("fdi_sim.study.card", "fdi_sim.study.bank_false_alarms"),
            "the DHC-6 airspeed check's point-estimate threshold alarmed 3 times on them, which led to the "
            "bootstrap bound; the offline detector card reports on them (it called them held out)"),
    SeedSet("bank-development-2", "development", _r(201, 209),
            ("fdi_sim.study.scheduling", "fdi_sim.study.bank_false_alarms"),
            "the bank report until the alarm of seed 204 (DHC-6 approach) was traced to the per-sample tail "
            "fit, which led to the episode-rate thresholds; the gain-scheduling comparison"),
    SeedSet("bank-bar", "hold-out", _r(301, 309), ("tests/sim/test_bank_bars.py",),
            "the default bank's fault-free bar at the shipped operating points (no design decision saw it)"),
    SeedSet("parity-fresh", "validation", _r(9000, 9020), ("docs/make_parity_figures.py",),
            "fresh DHC-6 flights for the parity figures' threshold check"),
    SeedSet("false-alarm-studies", "validation", (14001, 14002),
            ("studies/f16_false_alarms", "studies/dhc6_false_alarms"),
            "the shipped fault-free studies that check the shipped thresholds files"),
    SeedSet("detection-studies", "validation", (14003, 14004),
            ("studies/f16_detection", "studies/dhc6_detection"),
            "the shipped detection studies (their delays were looked at while the bank was tuned)"),
    SeedSet("calibration-studies", "calibration", (14005, 14006),
            ("studies/dhc6_calibration", "studies/f16_calibration"),
            "the shipped thresholds files are fitted on their runs (14005's odd half also judged the tail "
            "method that replaced the one it rejected: it is not a validation set)"),
    SeedSet("calibration-validation", "validation", (14011, 14012),
            ("studies/f16_validation", "studies/dhc6_validation"),
            "fresh fault-free studies at the calibration studies' conditions: each checks its thresholds file once"),
    SeedSet("envelope-hold-out-1", "development", (15001, 15002),
            ("fdi_sim/bank/turbulence.py", "scenarios/studies/dhc6_envelope_hold_out.toml"),
            "the envelope hold-outs' first seeds, each flown once (2026-12-04): the F-16's with the schedule "
            "on the vertical accelerometer (24 alarms in 49.6 h, all in severe air: its severe runs then "
            "set the F-16's pitch-gyro schedule); the DHC-6's (2 alarms in 49.4 h; 3 severe-air runs "
            "departed, leaving 49.5 h of the bar's 50: the study was then asked for 52 h, on a new seed). "
            "Both are development now"),
    SeedSet("envelope-hold-out", "hold-out", (15003, 15004),
            ("studies/f16_envelope_hold_out", "studies/dhc6_envelope_hold_out"),
            "fault-free studies across each aircraft's envelope, no to severe turbulence (issue 24's bar); "
            "the F-16's second seed (its schedule changed after the first), the DHC-6's second (52 h asked "
            "for, so that departures in severe air leave 50; the bank is the one the first was flown with)"),
    SeedSet("engine-gauge-development", "development", _r(900, 906),
            ("fdi_sim/detectors/engine_gauges.py", "fdi_sim/bank/turbulence.py"),
            "six fault-free 300 s DHC-6 flights (light to severe air) the engine-gauge check's scales, its "
            "tail form and its turbulence exponent were judged on"),
    SeedSet("envelope-development", "development", (15101, 15102),
            ("studies/f16_envelope_development", "studies/dhc6_envelope_development",
             "fdi_sim/detectors/engine_gauges.py"),
            "the envelope hold-out studies' development twins: looked at freely while the bank's turbulence "
            "handling is made; the DHC-6's (with the engine-gauge check added, its 180 flights reflown with "
            "full logs) gave the torque limiter's window and allowance and Np's exclusion"),
    SeedSet("engine-gauge-hold-out", "hold-out", (15005,),
            ("tests/data/engine_gauges/dhc6_engine_gauges_hold_out.toml",),
            "the engine-gauge check's hold-out (issue 25): the envelope development study's sampling, written "
            "after the limiter's window and Np's exclusion were chosen on seed 15102, flown once"),
    SeedSet("engine-limiter-development", "development", _r(910, 914), ("tests/sim/test_engine_limiter.py",),
            "four fault-free 300 s DHC-6 flights at 130 KIAS, 3,500 ft in severe air (the lever near full "
            "travel): the engine-gauge check with and without the limiter's window, and a flameout in them"),
    SeedSet("atlas-hold-out-scenarios", "hold-out", (90417, 90418),
            ("tests/data/holdout/holdout_f16_roll_gyro_bias_7500ft.toml",
             "tests/data/holdout/holdout_dhc6_calm_6900ft.toml"),
            "new scenarios written for issue 24 (not shipped, never tuned on): a flight inside each atlas "
            "envelope takes off with no training flight (tests/training/test_atlas.py, docs/make_atlas_table.py)"),
    SeedSet("test-calibration", "calibration", (21,), ("tests/study/test_calibration.py",),
            "the small DHC-6 calibration study of the thresholds-file tests (mechanics, not a verdict)"),
    SeedSet("test-validation", "validation", (24,), ("tests/study/test_calibration.py",),
            "the small fresh study that validates that file in the same tests (mechanics, not a verdict)"),
    SeedSet("fdi-bench", "benchmark", (16001,), ("bench/fdi-bench-v1", "bench/fdi-bench-v2"),
            "the frozen benchmark suites fdi-bench-v1 and v2 (issue 27; their cases' seeds are SeedSequence([16001, g, "
            "s, r]); v2 holds v1's groups first, so v1's cases are v2's): "
            "reported on by every method, tuned on by none"),
    SeedSet("tail-coverage", "synthetic", (20261204,), ("docs/make_tail_coverage.py",),
            "synthetic AR(1) statistics of the tail method's coverage table"),
)


def seed_set(name: str) -> SeedSet:
    """The registered set called ``name``."""
    for s in REGISTRY:
        if s.name == name:
            return s
    raise KeyError(f"no seed set {name!r}; registered: {', '.join(s.name for s in REGISTRY)}")


def seeds(name: str) -> tuple[int, ...]:
    """The seeds of the registered set called ``name``."""
    return seed_set(name).seeds


def role_of(seed: int) -> SeedSet | None:
    """The registered set holding ``seed`` (None: unregistered)."""
    for s in REGISTRY:
        if int(seed) in s.seeds:
            return s
    return None

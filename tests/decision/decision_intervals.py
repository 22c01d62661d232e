"""95 % intervals shared by the decision-rule tests (exact binomial; CLT on run lengths)."""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from fdi_sim.decision.intervals import clopper_pearson


def binomial_ci(k: int, n: int) -> tuple[float, float]:
    """Clopper-Pearson 95 % interval of a proportion k / n (the project's own)."""
    return clopper_pearson(int(k), int(n))


def mean_ci(x: NDArray) -> tuple[float, float, float]:
    """Mean and its 95 % interval (CLT; run lengths are iid, near-geometric, so n >= 1000 is plenty)."""
    x = np.asarray(x, float)
    m, se = float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size))
    z = float(norm.ppf(0.975))
    return m, m - z * se, m + z * se


def first_alarms(alarm: NDArray) -> NDArray[np.int64]:
    """Run length [samples] to the first alarm of each column (1-based); raises if a column never alarms."""
    a = np.asarray(alarm, bool)
    assert a.any(axis=0).all(), "some runs never alarmed: make the traces longer"
    return a.argmax(axis=0) + 1


def run_lengths(rule, rng: np.random.Generator, n_runs: int, length: int, shift: float = 0.0,
                batch: int = 500) -> NDArray[np.int64]:
    """First-alarm times of ``rule.run`` on ``n_runs`` independent N(shift, 1) traces of ``length``."""
    out = []
    for start in range(0, n_runs, batch):
        m = min(batch, n_runs - start)
        out.append(first_alarms(rule.run(rng.standard_normal((length, m)) + shift).alarm))
    return np.concatenate(out)

"""Thresholds for false-alarm probabilities smaller than the training data can show.

A per-sample target ``p`` that a training set of ``N`` samples holds fewer than ten exceedances
of (``N p < 10``) has no empirical quantile worth the name. Peaks over threshold (Pickands 1975;
Coles 2001, sec. 4.3): above a high threshold ``u``, the excess ``x - u`` of a statistic with any
of the usual tails is close to a generalized Pareto distribution,

    P(X > u + z | X > u) = (1 + xi z / sigma)^(-1/xi),

so with ``q = P(X > u)`` the ``1 - p`` quantile is ``u + (sigma / xi) ((p / q)^(-xi) - 1)``
(``u - sigma log(p / q)`` for ``xi = 0``; Coles eq. 4.13). ``u`` is the empirical ``1 - q``
quantile with ``q`` chosen to leave about 1000 exceedances (at most 2 % of the samples), and
``xi``, ``sigma`` are the maximum-likelihood fit (``scipy.stats.genpareto``). The further ``p / q``
the larger the extrapolation error: the method string says how far it went.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import genpareto

from fdi_sim.errors import DesignError

__all__ = ["tail_threshold"]

#: exceedances an empirical quantile needs
MIN_EMPIRICAL = 10
#: exceedances the tail fit aims for, and the fewest it accepts
TAIL_EXCEEDANCES = 1000
MIN_TAIL = 50
#: the largest tail fraction fitted
Q_MAX = 0.02


def tail_threshold(x: NDArray[np.float64], p: float) -> tuple[float, str]:
    """The ``1 - p`` quantile of the samples ``x``, tail-extrapolated where they are too few.

    Parameters
    ----------
    x : NDArray
        Training samples of the statistic (finite).
    p : float
        Exceedance probability per sample, in (0, 1).

    Returns
    -------
    (threshold, method) : (float, str)
        ``method`` is ``"empirical (k exceedances of N)"`` or the tail fit's parameters.

    Raises
    ------
    DesignError
        ``p`` outside (0, 1), or fewer samples than a tail fit needs.
    """
    if not 0.0 < p < 1.0:
        raise DesignError(f"per-sample false-alarm probability {p} must be in (0, 1)")
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n * p >= MIN_EMPIRICAL:
        return float(np.quantile(x, 1.0 - p)), f"empirical ({n * p:.0f} exceedances expected of {n} samples)"
    q = min(Q_MAX, TAIL_EXCEEDANCES / max(n, 1))
    if n * q < MIN_TAIL:
        raise DesignError(f"{n} training samples are too few for a tail fit ({MIN_TAIL / Q_MAX:.0f} at least); fly more "
                          "or longer calibration flights")
    u = float(np.quantile(x, 1.0 - q))
    z = x[x > u] - u
    xi, _, sigma = genpareto.fit(z, floc=0.0)
    thr = u + float(genpareto.ppf(1.0 - p / q, xi, loc=0.0, scale=sigma))
    return thr, (f"GPD tail over the {1 - q:.4f} quantile ({z.size} exceedances of {n}), xi {xi:.3f}, sigma "
                 f"{sigma:.3g}, extrapolated {q / p:.3g} x beyond it")

"""Wald's sequential probability ratio test, repeated: H0 mean 0 against H1 mean ``nu`` (Gaussian).

Increments of the log-likelihood ratio ``s_k = (nu / sigma^2)(x_k - nu / 2)`` are summed,
``Lambda_k = Lambda_{k-1} + s_k``, and the test stops (Wald 1945, eq. 3.2-3.4 and Wald's thresholds
``A = (1 - beta) / alpha``, ``B = beta / (1 - alpha)``)

    accept H1 when Lambda_k >= a = log((1 - beta) / alpha),
    accept H0 when Lambda_k <= b = log(beta / (1 - alpha)),

then restarts from 0. The verdict (alarm) is the last decision taken, held until the next one.

Error probabilities. Wald's inequalities bound the actual ``alpha' <= alpha / (1 - beta)`` and
``alpha' + beta' <= alpha + beta``. Because ``Lambda`` overshoots the thresholds, the actual errors
are below the nominal ones. Siegmund's correction (Siegmund 1985, §3.1; ``rho = 0.583`` for
Gaussian increments of standard deviation ``delta = |nu| / sigma``) moves the thresholds out,
``a' = a + 0.583 delta``, ``b' = b - 0.583 delta``, and, since ``exp(Lambda)`` is a martingale under
H0 (``exp(-Lambda)`` under H1),

    alpha' ~ (1 - e^{b'}) / (e^{a'} - e^{b'}),     beta' ~ (1 - e^{-a'}) / (e^{-b'} - e^{-a'}),

with expected sample numbers (Wald's identity, ``E0 s = -delta^2/2``, ``E1 s = +delta^2/2``)

    E0 N ~ ((1 - alpha') b' + alpha' a') / (-delta^2 / 2),   E1 N ~ ((1 - beta') a' + beta' b') / (delta^2 / 2).

Measured (tests/decision/test_decision_sprt.py, docs/decision.md, delta = 1): the corrected
``alpha'``/``beta'`` fall inside the binomial 95 % intervals; the corrected sample numbers are
short by about 4 % at alpha = beta = 0.05 and 2 % at 0.01 (Wald's, uncorrected, by 10-20 %).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.base import Decision, DecisionTrace, check_positive, check_probability
from fdi_sim.errors import DesignError

__all__ = ["Sprt", "SprtOperatingCharacteristic", "sprt_operating_characteristic", "wald_thresholds"]

#: Siegmund's expected overshoot over the threshold, in units of the increments' std (Gaussian)
OVERSHOOT_RHO = 0.583


def wald_thresholds(alpha: float, beta: float) -> tuple[float, float]:
    """Wald's thresholds ``(a, b) = (log((1 - beta)/alpha), log(beta/(1 - alpha)))`` (Wald 1945)."""
    a_ = check_probability(alpha, "alpha")
    b_ = check_probability(beta, "beta")
    if a_ + b_ >= 1.0:
        raise DesignError(f"alpha + beta must be < 1, got {a_} + {b_}")
    return math.log((1.0 - b_) / a_), math.log(b_ / (1.0 - a_))


@dataclass(frozen=True)
class SprtOperatingCharacteristic:
    """Error probabilities and expected sample numbers of one SPRT (Siegmund-corrected, module doc).

    Attributes
    ----------
    alpha : float
        Probability of accepting H1 under H0 (a false alarm per test).
    beta : float
        Probability of accepting H0 under H1 (a missed detection per test).
    asn0_samples, asn1_samples : float
        Expected number of samples per test under H0 and H1 [samples].
    """

    alpha: float
    beta: float
    asn0_samples: float
    asn1_samples: float


def sprt_operating_characteristic(a: float, b: float, delta: float, overshoot: bool = True) -> SprtOperatingCharacteristic:
    """The SPRT's actual errors and sample numbers for thresholds ``a > 0 > b`` and ``delta = |nu|/sigma``.

    ``overshoot=False`` gives Wald's approximations (no overshoot); True applies Siegmund's
    ``0.583 delta`` correction.
    """
    d = check_positive(delta, "delta")
    c = OVERSHOOT_RHO * d if overshoot else 0.0
    ap, bp = a + c, b - c  # a' = a + rho delta, b' = b - rho delta
    alpha = -math.expm1(bp) / (math.exp(ap) - math.exp(bp))  # (1 - e^b') / (e^a' - e^b')
    beta = -math.expm1(-ap) / (math.exp(-bp) - math.exp(-ap))  # (1 - e^-a') / (e^-b' - e^-a')
    asn0 = ((1.0 - alpha) * bp + alpha * ap) / (-d * d / 2.0)
    asn1 = ((1.0 - beta) * ap + beta * bp) / (d * d / 2.0)
    return SprtOperatingCharacteristic(alpha, beta, asn0, asn1)


class Sprt:
    """Repeated SPRT of mean 0 against mean ``shift`` in Gaussian noise of std ``sigma``.

    Parameters
    ----------
    sigma : float
        Noise standard deviation of the input (same unit as the input).
    shift : float
        The mean under H1 (same unit).
    alpha, beta : float
        Nominal error probabilities per test, each in (0, 1) (Wald's thresholds).

    Notes
    -----
    ``statistic`` is ``Lambda_k`` before the restart (a value beyond ``a`` or ``b`` marks a decision
    at that sample); ``threshold`` is ``a``. The actual per-test errors and sample numbers are in
    :attr:`characteristic` (Siegmund-corrected). A non-finite input adds nothing and is invalid.
    ``run`` does Python work once per *decision* (every ~ASN samples), not per sample.
    """

    id = "sprt-v1"
    hypotheses: tuple[str, ...] = ()

    def __init__(self, sigma: float, shift: float, alpha: float = 1e-3, beta: float = 1e-2) -> None:
        self.sigma = check_positive(sigma, "sigma")
        self.shift = float(shift)
        if not (math.isfinite(self.shift) and self.shift != 0.0):
            raise DesignError(f"shift must be a finite non-zero mean change, got {shift}")
        self.alpha, self.beta = float(alpha), float(beta)
        self.a, self.b = wald_thresholds(alpha, beta)
        self.threshold = self.a
        self.delta = abs(self.shift) / self.sigma
        self.characteristic = sprt_operating_characteristic(self.a, self.b, self.delta)
        self._gain = self.shift / self.sigma ** 2
        self._offset = self.shift / 2.0
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """``Lambda = 0``, verdict H0."""
        self._L = 0.0
        self._verdict = False

    def step(self, t_s: float, x: float) -> Decision:
        """One sample at time ``t_s`` [s]."""
        v = float(x)
        ok = math.isfinite(v)
        if ok:
            self._L += (v - self._offset) * self._gain  # Lambda_k = Lambda_{k-1} + (nu/sigma^2)(x - nu/2)
        L = self._L
        if L >= self.a or L <= self.b:
            self._verdict = L >= self.a
            self._L = 0.0  # restart
        return Decision(t_s, L, self.threshold, ok and self._verdict, None, ok)

    def run(self, x: NDArray[np.float64]) -> DecisionTrace:
        """A whole trace from ``reset`` ((N,) or (N, m): columns are independent traces)."""
        v = np.asarray(x, float)
        ok = np.isfinite(v)
        s = np.where(ok, (v - self._offset) * self._gain, 0.0)
        if s.ndim == 1:
            stat, verdict = self._run_1d(s)
        else:
            flat = s.reshape(s.shape[0], -1)
            stat, verdict = np.empty_like(flat), np.empty(flat.shape, dtype=bool)
            for j in range(flat.shape[1]):
                stat[:, j], verdict[:, j] = self._run_1d(flat[:, j])
            stat, verdict = stat.reshape(s.shape), verdict.reshape(s.shape)
        return DecisionTrace(stat, verdict & ok, self.threshold, None, None if ok.all() else ok)

    def _run_1d(self, s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        N = s.size
        stat = np.empty(N)
        verdict = np.empty(N, dtype=bool)
        pos, state = 0, False
        look = max(16, int(4 * max(self.characteristic.asn0_samples, self.characteristic.asn1_samples)))
        while pos < N:
            end = min(N, pos + look)
            L = np.cumsum(s[pos:end])  # Lambda from the restart, same additions as step()
            hit = np.flatnonzero((L >= self.a) | (L <= self.b))
            if hit.size == 0:
                if end == N:  # no decision before the trace ends
                    stat[pos:] = L
                    verdict[pos:] = state
                    break
                look *= 2
                continue
            i = int(hit[0])
            stat[pos:pos + i + 1] = L[: i + 1]
            verdict[pos:pos + i] = state
            state = bool(L[i] >= self.a)
            verdict[pos + i] = state
            pos += i + 1
        return stat, verdict

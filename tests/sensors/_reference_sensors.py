"""The sensor suite as it was before the compiled kernel (commit d97be8c): the oracle of the kernel tests.

A verbatim copy of ``SensorSuite`` (pure Python floats, a noise block of ``BLOCK_STEPS`` rows
drawn at the step that needs it), renamed ``ReferenceSuite``. The compiled
:class:`fdi_sim.sensors.suite.SensorSuite` must give the same floats, bit for bit, from the same
generator. Do not "fix" this file: it is the definition of the numbers the logs hold.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.sensors.suite import Measurement, SensorSpec

BLOCK_STEPS = 120


class ReferenceSuite:
    """All sensors of one aircraft; ``reset(rng)`` then ``step(t_s, truth)`` each step.

    Parameters
    ----------
    specs : sequence of SensorSpec
    truth_names : sequence of str
        Order of the truth vector passed to :meth:`step`.
    dt_s : float
        Simulation step [s].
    """

    def __init__(self, specs: Sequence[SensorSpec], truth_names: Sequence[str], dt_s: float) -> None:
        self.specs = tuple(specs)
        self.names = tuple(s.name for s in specs)
        unknown = [n for n in self.names if n not in truth_names]
        if unknown:
            raise ValueError(f"sensors measure unknown signals {unknown}")
        self.dt_s = dt_s
        sim_hz = 1.0 / dt_s
        decim = []
        for s in specs:
            d = sim_hz / s.rate_hz
            if s.rate_hz <= 0 or abs(d - round(d)) > 1e-6 or round(d) < 1:
                raise ValueError(f"sensor {s.name}: rate {s.rate_hz} Hz does not divide the simulation rate {sim_hz:g} Hz")
            decim.append(int(round(d)))
        self._period = math.lcm(*decim)
        truth_idx = [list(truth_names).index(n) for n in self.names]
        # per phase k % period: the sensors that sample, as (sensor, truth index) without quantization
        # and (sensor, truth index, quantum) with it -- scalar Python per step is cheaper than half a
        # dozen numpy calls on a 14-element vector
        self._plan = [
            ([(i, truth_idx[i]) for i in range(len(specs)) if k % decim[i] == 0 and not specs[i].quantum],
             [(i, truth_idx[i], specs[i].quantum) for i in range(len(specs)) if k % decim[i] == 0 and specs[i].quantum])
            for k in range(self._period)
        ]
        self._noise_std = np.array([s.noise_std for s in specs])
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Draw the turn-on biases and restart the noise stream from ``rng``."""
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.bias = np.array([s.bias + s.bias_std * self._rng.standard_normal() for s in self.specs])
        self._y = [0.0] * len(self.specs)
        self._block_start = -(10**9)
        self._offset: list[list[float]] = []

    def _fill_block(self, k0: int) -> None:
        # bias + noise for the next block, drawn as one array (sampling instants only use their row)
        off = self.bias + self._noise_std * self._rng.standard_normal((BLOCK_STEPS, len(self.specs)))
        self._offset = off.tolist()
        self._block_start = k0

    def step(self, t_s: float, truth: NDArray[np.float64]) -> Measurement:
        """Measure the truth vector at time ``t_s`` [s]."""
        return Measurement(t_s, np.array(self.step_list(t_s, truth.tolist())))

    def step_list(self, t_s: float, truth: list[float]) -> list[float]:
        """:meth:`step` on Python floats (the simulation loop's fast path).

        Parameters
        ----------
        t_s : float
            Time [s].
        truth : list of float
            The truth vector in ``truth_names`` order.

        Returns
        -------
        list of float
            A new list in :attr:`names` order (the caller may change it).
        """
        k = int(round(t_s / self.dt_s))
        j = k - self._block_start
        if not 0 <= j < BLOCK_STEPS:
            self._fill_block(k)
            j = 0
        off = self._offset[j]
        y = self._y
        plain, quantized = self._plan[k % self._period]
        for i, ti in plain:  # sample, then hold until the next sample
            y[i] = truth[ti] + off[i]
        for i, ti, q in quantized:
            y[i] = round((truth[ti] + off[i]) / q) * q
        return y[:]

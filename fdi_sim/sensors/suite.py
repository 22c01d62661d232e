"""Sensor suite: truth -> measurement with bias, white noise, sample-and-hold and quantization.

Every sensor measures one truth signal and keeps its name (``q_radps`` measures ``q_radps``).
Model (``sampled-noisy-v1``), at each sample instant k of the sensor (rate ``rate_hz``, a divisor
of the simulation rate), held between samples::

    y_k = Q( x_k + b + v_k ),   b ~ N(bias, bias_std^2) drawn once per run,  v_k ~ N(0, noise_std^2)

with ``Q`` rounding to ``quantum`` (none if 0). Noise is drawn in blocks of one simulated second
from the suite's own ``numpy.random.Generator``, so a seed gives the same measurements bit for bit.
The per-step arithmetic is one compiled call (:mod:`fdi_sim.sensors._kernels`, numba).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

import fdi_sim.sensors._kernels as K  # the module, not its package (no import cycle through __init__)
from fdi_sim.data import aircraft_file  # aircraft/ in a checkout, packaged in a wheel

BLOCK_STEPS = 120  # noise rows drawn at a time, one simulated second at 120 Hz


@dataclass(frozen=True)
class SensorSpec:
    """One sensor (all values in the units of the measured signal's name).

    Attributes
    ----------
    name : str
        Measured signal, e.g. ``"q_radps"``.
    kind : str
        What the instrument is (``"rate gyro"``), for documentation and plots.
    noise_std : float
        White-noise standard deviation per sample.
    bias : float
        Mean of the turn-on bias.
    bias_std : float
        Standard deviation of the turn-on bias drawn per run.
    rate_hz : float
        Sample rate [Hz]; must divide the simulation rate.
    quantum : float
        Resolution (0 for none).
    """

    name: str
    kind: str
    noise_std: float
    bias: float = 0.0
    bias_std: float = 0.0
    rate_hz: float = 120.0
    quantum: float = 0.0


def suite_path(aircraft: str, suite: str = "default") -> Path:
    """``aircraft/<aircraft>/sensors.toml`` for ``suite = "default"``, else ``sensors_<suite>.toml``."""
    return aircraft_file(aircraft, "sensors.toml" if suite == "default" else f"sensors_{suite}.toml")


def suite_names(aircraft: str) -> list[str]:
    """The sensor suites shipped for ``aircraft``: ``default`` and every ``sensors_<suite>.toml``."""
    folder = suite_path(aircraft).parent
    return ["default"] + sorted(p.stem.removeprefix("sensors_") for p in folder.glob("sensors_*.toml"))


def load_suite(aircraft: str, suite: str = "default") -> tuple[SensorSpec, ...]:
    """Read the suite file :func:`suite_path` names.

    Raises
    ------
    FileNotFoundError
        No such suite (the scenario loader turns it into a message with :func:`suite_names`).
    """
    path = suite_path(aircraft, suite)
    if not path.exists():
        raise FileNotFoundError(path)
    data = tomllib.loads(path.read_text())
    return tuple(SensorSpec(name=name, **vals) for name, vals in data["sensor"].items())


def apply_overrides(specs: Sequence[SensorSpec], noise_scale: float = 1.0, biases: bool = True,
                    overrides: dict[str, dict[str, float]] | None = None) -> tuple[SensorSpec, ...]:
    """Scale all noise, drop biases, or replace single fields of named sensors."""
    out = []
    for s in specs:
        s = replace(s, noise_std=s.noise_std * noise_scale)
        if not biases:
            s = replace(s, bias=0.0, bias_std=0.0)
        if overrides and s.name in overrides:
            s = replace(s, **overrides[s.name])
        out.append(s)
    return tuple(out)


@dataclass(frozen=True, slots=True)
class Measurement:
    """The suite's output for one step: ``y`` in :attr:`SensorSuite.names` order."""

    t_s: float
    y: NDArray[np.float64]


class SensorSuite:
    """All sensors of one aircraft; ``reset(rng)`` then ``step(t_s, truth)`` each step.

    Parameters
    ----------
    specs : sequence of SensorSpec
    truth_names : sequence of str
        Order of the truth vector passed to :meth:`step`.
    dt_s : float
        Simulation step [s].

    Notes
    -----
    :meth:`measure_into` (arrays, the loop's fast path), :meth:`step_list` and :meth:`step` run the
    same compiled function on the same state and can be mixed. Noise: at the first step outside
    the current block, ``rng.standard_normal((BLOCK_STEPS, n_sensors))`` gives the rows of that
    step and the next ``BLOCK_STEPS - 1`` (every sensor draws every step, sampling or not), and
    nothing else draws from ``rng`` after :meth:`reset`'s biases.
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
        truth_idx = [list(truth_names).index(n) for n in self.names]
        # header (block start, wanted block, -, dt) and per sensor: truth index, decimation (samples
        # at steps k % decimation == 0), quantum (0: none), held output
        self._tab = np.zeros((1 + len(specs), 4))
        self._tab[0, K.DT_S] = dt_s
        self._tab[1:, K.TRUTH_INDEX] = truth_idx
        self._tab[1:, K.DECIMATION] = decim
        self._tab[1:, K.QUANTUM] = [s.quantum for s in specs]
        self._noise_std = np.array([s.noise_std for s in specs])
        self._off = np.zeros((BLOCK_STEPS, len(specs)))
        self._y_list = np.zeros(len(specs))  # step_list's output buffer (returned as a new list)
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Draw the turn-on biases and restart the noise stream from ``rng``."""
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.bias = np.array([s.bias + s.bias_std * self._rng.standard_normal() for s in self.specs])
        self._tab[1:, K.HELD] = 0.0
        self._tab[0, K.BLOCK_START] = -(10**9)  # no block yet: the first step draws one

    def _fill_block(self, k0: int) -> None:
        # bias + noise for steps k0 .. k0 + BLOCK_STEPS - 1, drawn as one array (sampling instants
        # only use their row): off = bias + std * z, in place (z std is std z bit for bit)
        off = self._off
        self._rng.standard_normal(out=off)
        np.multiply(off, self._noise_std, out=off)
        np.add(off, self.bias, out=off)
        self._tab[0, K.BLOCK_START] = k0

    def measure_into(self, t_s: float, x: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """Measure the truth at time ``t_s`` [s] into ``out``, no object created (the loop's fast path).

        Parameters
        ----------
        t_s : float
            Time [s].
        x : ndarray, float64, shape (n_truth,)
            The truth vector in ``truth_names`` order (read only).
        out : ndarray, float64, shape (n_sensors,)
            Receives the measurements in :attr:`names` order, the floats :meth:`step_list` returns
            (the caller may change them: the suite holds its own copy).
        """
        if K.measure(t_s, x, out, self._tab, self._off):  # True: step outside the noise block, nothing written
            self._fill_block(int(self._tab[0, K.K_WANTED]))
            K.measure(t_s, x, out, self._tab, self._off)

    def compiled(self) -> tuple[Callable[..., bool], NDArray[np.float64], NDArray[np.float64], Callable[[], None]]:
        """:meth:`measure_into` without its Python frame, for the loop: ``(measure, tab, off, refill)``
        with ``if measure(t_s, x, out, tab, off): refill(); measure(t_s, x, out, tab, off)`` the
        same call (the arrays are the suite's own, updated in place by :meth:`reset` and ``refill``)."""
        return K.measure, self._tab, self._off, self._refill

    def _refill(self) -> None:
        self._fill_block(int(self._tab[0, K.K_WANTED]))

    def step(self, t_s: float, truth: NDArray[np.float64]) -> Measurement:
        """Measure the truth vector at time ``t_s`` [s]."""
        y = np.empty(len(self.specs))
        self.measure_into(float(t_s), np.ascontiguousarray(truth, dtype=np.float64), y)
        return Measurement(t_s, y)

    def step_list(self, t_s: float, truth: list[float]) -> list[float]:
        """:meth:`measure_into` on Python floats.

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
        y = self._y_list
        self.measure_into(float(t_s), np.array(truth, dtype=np.float64), y)
        return y.tolist()

"""Decimation of time series for display that never hides a spike.

A 10-minute run at 120 Hz is 72,000 samples a signal; a browser draws a few thousand points a
trace comfortably. Outside the zoom windows (around fault and alarm onsets, where a reviewer
looks closely) the time axis is cut into equal buckets and each bucket keeps its first, minimum,
maximum and last sample, in time order (the M4 scheme of Jugel et al., VLDB 2014): the drawn
envelope and every extreme survive, a single-sample spike included. A bucket holding a NaN also
keeps its first NaN, so a gap in the signal stays a gap in the line. Inside the windows every
sample is kept.

One :class:`Decimator` serves every trace of a figure: the buckets depend on the figure's time
span only, so traces on the same time base keep the same first and last times in every bucket
(and two runs of the same scenario, compared on shared axes, keep the same ones too).
Everything is vectorised numpy (one pass per trace, no Python loop per sample).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

MAX_POINTS: int = 4000
"""Default cap on points a trace keeps outside the zoom windows."""
ZOOM_BEFORE_S: float = 2.0
ZOOM_AFTER_S: float = 5.0


@dataclass(frozen=True, eq=False)
class Decimated:
    """The samples a trace keeps.

    Attributes
    ----------
    t_s : NDArray
        Kept times [s], increasing.
    y : NDArray
        Kept values [unit of the input], NaN where the input was NaN.
    index : NDArray
        Indices of the kept samples in the input.
    """

    t_s: NDArray[np.float64]
    y: NDArray[np.float64]
    index: NDArray[np.intp]

    def __len__(self) -> int:
        return int(self.index.size)


@dataclass(frozen=True, eq=False)
class _Segments:
    starts: NDArray[np.intp]
    ends: NDArray[np.intp]
    seg: NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class _Grid:
    """A time base cut into buckets: the window mask, the outside samples, their segments
    (4 points a bucket; 5 for a trace with NaN, which keeps one NaN a bucket)."""

    inside: NDArray[np.bool_]
    out: NDArray[np.intp]
    plain: _Segments
    with_nan: _Segments


@dataclass(frozen=True)
class Decimator:
    """Decimation shared by the traces of one figure.

    Attributes
    ----------
    t0_s, t1_s : float
        Time span the buckets cover [s] (samples outside it fall into the end buckets).
    windows_s : tuple of (float, float)
        Closed intervals [s] kept at full resolution, sorted and disjoint (see :func:`zoom_windows`).
    max_points : int
        Cap on the points a trace keeps outside the windows (the windows add their samples); it
        holds whenever it is at least ``5 * (len(windows_s) + 1)`` (each window may split a bucket).
    """

    t0_s: float
    t1_s: float
    windows_s: tuple[tuple[float, float], ...] = ()
    max_points: int = MAX_POINTS
    _grids: dict[Any, tuple[NDArray[np.float64], _Grid]] = field(default_factory=dict, init=False, repr=False,
                                                                 compare=False)

    def __post_init__(self) -> None:
        if not self.max_points >= 8:
            raise ValueError(f"Decimator.max_points must be at least 8 (4 per bucket, 2 buckets); got {self.max_points}")
        if not np.isfinite(self.t0_s) or not np.isfinite(self.t1_s) or self.t1_s < self.t0_s:
            raise ValueError(f"Decimator needs a finite span t0_s <= t1_s [s]; got {self.t0_s} .. {self.t1_s}")

    def __call__(self, t_s: ArrayLike, y: ArrayLike) -> Decimated:
        """Decimate one trace: ``t_s`` [s] increasing, ``y`` the same length."""
        t = np.asarray(t_s, dtype=np.float64)
        v = np.asarray(y, dtype=np.float64)
        idx = self.keep(t, v)
        return Decimated(t[idx], v[idx], idx)

    def keep(self, t_s: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.intp]:
        """Indices of the samples to keep, increasing.

        Parameters
        ----------
        t_s : NDArray
            Sample times [s], non-decreasing, shape (n,).
        y : NDArray
            Values, shape (n,); NaN marks a gap.
        """
        n = t_s.shape[0]
        if y.shape != (n,):
            raise ValueError(f"decimate: t_s has {n} samples but y has shape {y.shape}; give one value per time")
        grid = self._grid(t_s)
        if grid.out.size <= self.max_points:
            return np.arange(n, dtype=np.intp)
        v = y[grid.out]
        nan = np.isnan(v)
        g = grid.with_nan if nan.any() else grid.plain
        lo = np.where(nan, np.inf, v)
        hi = np.where(nan, -np.inf, v)
        picks = [g.starts, g.ends,
                 _first_per_segment(g.seg, lo == np.minimum.reduceat(lo, g.starts)[g.seg]),
                 _first_per_segment(g.seg, hi == np.maximum.reduceat(hi, g.starts)[g.seg])]
        if nan.any():
            picks.append(_first_per_segment(g.seg, nan))
        mask = grid.inside.copy()
        mask[grid.out[np.concatenate(picks)]] = True
        return np.flatnonzero(mask)

    def _grid(self, t_s: NDArray[np.float64]) -> _Grid:
        """The buckets of a time base, computed once per time array (traces of one topic share it)."""
        key = (t_s.__array_interface__["data"][0], t_s.shape, t_s.strides)
        hit = self._grids.get(key)
        if hit is not None and hit[0].shape == t_s.shape and np.shares_memory(hit[0], t_s):
            return hit[1]  # the cached array is held, so its memory (read-only log data) is the same
        inside = self._inside(t_s)
        out = np.flatnonzero(~inside)
        grid = _Grid(inside, out, self._segments(t_s, out, 4), self._segments(t_s, out, 5))
        self._grids[key] = (t_s, grid)
        return grid

    def _segments(self, t_s: NDArray[np.float64], out: NDArray[np.intp], per_bucket: int) -> _Segments:
        """Runs of consecutive outside samples in one bucket, ``per_bucket`` points each at most."""
        # a window can split a bucket in two: reserve its extra points so the cap holds
        n_buckets = max(1, (self.max_points - per_bucket * len(self.windows_s)) // per_bucket)
        span_s = self.t1_s - self.t0_s
        scale = n_buckets / span_s if span_s > 0 else 0.0
        bucket = np.clip(((t_s[out] - self.t0_s) * scale).astype(np.int64), 0, n_buckets - 1)
        cut = np.flatnonzero((np.diff(bucket) != 0) | (np.diff(out) != 1)) + 1
        starts = np.concatenate(([0], cut))
        ends = np.concatenate((cut, [out.size])) - 1
        return _Segments(starts, ends, np.repeat(np.arange(starts.size), ends - starts + 1))

    def _inside(self, t_s: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Mask of the samples inside any window (the windows' edges counted in)."""
        mark = np.zeros(t_s.shape[0] + 1, dtype=np.int64)
        if self.windows_s:
            w = np.asarray(self.windows_s, dtype=np.float64)
            np.add.at(mark, np.searchsorted(t_s, w[:, 0], side="left"), 1)
            np.add.at(mark, np.searchsorted(t_s, w[:, 1], side="right"), -1)
        return np.cumsum(mark[:-1]) > 0


def _first_per_segment(seg: NDArray[np.int64], hit: NDArray[np.bool_]) -> NDArray[np.intp]:
    """Position of the first ``hit`` in each segment that has one (``seg`` non-decreasing)."""
    pos = np.flatnonzero(hit)
    s = seg[pos]
    return pos[np.concatenate(([True], s[1:] != s[:-1]))] if pos.size else pos


def zoom_windows(onsets_s: Iterable[float], *, before_s: float = ZOOM_BEFORE_S, after_s: float = ZOOM_AFTER_S,
                 budget_s: float | None = None) -> tuple[tuple[float, float], ...]:
    """Full-resolution windows ``[onset - before_s, onset + after_s]`` [s], merged where they overlap.

    Parameters
    ----------
    onsets_s : iterable of float
        Onset times [s] in order of priority (fault onsets first, then alarm onsets).
    before_s, after_s : float
        Window extent before and after each onset [s].
    budget_s : float, optional
        Stop adding onsets once the merged windows cover this much time [s] (a run whose alarms
        chatter would otherwise be kept whole).

    Returns
    -------
    tuple of (float, float)
        Sorted, disjoint windows [s].
    """
    chosen: list[tuple[float, float]] = []
    for t in onsets_s:
        if not np.isfinite(t):
            continue
        chosen.append((float(t) - before_s, float(t) + after_s))
        merged = _merge(chosen)
        if budget_s is not None and sum(b - a for a, b in merged) >= budget_s:
            return merged
    return _merge(chosen)


def _merge(windows: Sequence[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
    out: list[tuple[float, float]] = []
    for a, b in sorted(windows):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return tuple(out)

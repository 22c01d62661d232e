"""Time profiles of faults: when a fault acts and how strongly (its *level*, 0..1).

A profile is a set of on-windows ``[a, b)`` inside ``[t_start_s, t_end_s)`` and a ramp-in time.
Inside a window the level rises linearly from 0 to 1 over ``ramp_s`` and stays at 1; outside it
is 0. The fault is *active* whenever its level is above 0. Windows are

* one window ``[t_start_s, t_end_s)`` (``t_end_s`` omitted: until the end of the run);
* explicit (``intermittent.windows_s``), absolute times;
* random (``intermittent.duty_cycle`` and ``mean_dwell_s``): on and off periods alternate,
  starting *on* at ``t_start_s``, with exponentially distributed lengths of mean
  ``mean_dwell_s`` (on) and ``mean_dwell_s (1 - d) / d`` (off), so the long-run fraction of time
  on is the duty cycle ``d``. They are drawn once per run from the run's fault stream, so the
  same seed repeats the same windows exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator


class IntermittentParams(BaseModel):
    """Intermittency of a fault: explicit windows, or random on/off with a duty cycle."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    windows_s: tuple[tuple[float, float], ...] | None = Field(
        default=None, description="explicit on-windows [[start, end], ...] in absolute time [s]")
    duty_cycle: float | None = Field(default=None, gt=0.0, lt=1.0, description="long-run fraction of time on [-]")
    mean_dwell_s: float | None = Field(default=None, gt=0.0, le=3600.0, description="mean length of an on period [s]")

    @model_validator(mode="after")
    def _one_kind(self) -> "IntermittentParams":
        explicit = self.windows_s is not None
        random = self.duty_cycle is not None or self.mean_dwell_s is not None
        if explicit == random:
            raise ValueError("give either windows_s, or duty_cycle and mean_dwell_s")
        if random and (self.duty_cycle is None or self.mean_dwell_s is None):
            raise ValueError("random intermittency needs both duty_cycle and mean_dwell_s")
        if explicit:
            prev = -math.inf
            for a, b in self.windows_s:
                if not b > a:
                    raise ValueError(f"window [{a}, {b}] ends before it starts")
                if a < prev:
                    raise ValueError("windows_s must be sorted and must not overlap")
                prev = b
        return self


class ProfileParams(BaseModel):
    """The timing keys every fault has (mixed into each fault's parameter model)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    t_start_s: float = Field(ge=0.0, description="fault onset [s]")
    t_end_s: float | None = Field(default=None, gt=0.0, description="fault cleared [s]; omitted: until the end of the run")
    ramp_s: float = Field(default=0.0, ge=0.0, le=3600.0, description="ramp-in time of the level at each onset [s]")
    intermittent: IntermittentParams | None = None

    @model_validator(mode="after")
    def _timing(self) -> "ProfileParams":
        if self.t_end_s is not None and self.t_end_s <= self.t_start_s:
            raise ValueError(f"t_end_s ({self.t_end_s}) must be after t_start_s ({self.t_start_s})")
        w = self.intermittent.windows_s if self.intermittent else None
        if w:
            if w[0][0] < self.t_start_s:
                raise ValueError(f"the first window starts at {w[0][0]} s, before t_start_s ({self.t_start_s})")
            if self.t_end_s is not None and w[-1][1] > self.t_end_s:
                raise ValueError(f"the last window ends at {w[-1][1]} s, after t_end_s ({self.t_end_s})")
        return self


@dataclass(frozen=True)
class Profile:
    """The on-windows and ramp of one fault in one run.

    Attributes
    ----------
    windows : tuple of (float, float)
        On-windows ``[a, b)`` [s], sorted, disjoint.
    ramp_s : float
        Ramp-in time at each onset [s].
    """

    windows: tuple[tuple[float, float], ...]
    ramp_s: float = 0.0

    def level(self, t_s: float) -> float:
        """Level at ``t_s`` [s], 0..1 (slow path; the injector walks windows incrementally)."""
        for a, b in self.windows:
            if a <= t_s < b:
                return ramp_level(t_s - a, self.ramp_s)
        return 0.0


def ramp_level(t_on_s: float, ramp_s: float) -> float:
    """Level ``t_on_s`` [s] after an onset: rises linearly from 0 to 1 over ``ramp_s`` [s], then 1."""
    return min(1.0, t_on_s / ramp_s) if ramp_s > 0 else 1.0


def make_profile(p: ProfileParams, duration_s: float, rng: np.random.Generator) -> Profile:
    """Draw the windows of one fault for one run.

    Parameters
    ----------
    p : ProfileParams
    duration_s : float
        Length of the run [s]; windows are cut there.
    rng : numpy.random.Generator
        Used only by random intermittency.
    """
    t0 = p.t_start_s
    t1 = min(p.t_end_s if p.t_end_s is not None else math.inf, duration_s + 1.0)
    it = p.intermittent
    if it is None:
        windows = [(t0, t1)]
    elif it.windows_s is not None:
        windows = [(a, min(b, t1)) for a, b in it.windows_s if a < t1]
    else:
        mean_on = float(it.mean_dwell_s)
        mean_off = mean_on * (1.0 - it.duty_cycle) / it.duty_cycle
        windows, t = [], t0
        while t < t1:
            on = rng.exponential(mean_on)
            windows.append((t, min(t + on, t1)))
            t += on + rng.exponential(mean_off)
    return Profile(tuple((float(a), float(b)) for a, b in windows if b > a), float(p.ramp_s))

"""Maneuvers: the excitation and reference changes of a scenario.

Two families, both pure functions of time so that a whole block of steps is evaluated at once
(vectorized over ``t_s``); the pilot's compiled step evaluates the same edges and ramps for one
step at a time (:mod:`fdi_sim.pilot._kernels`):

* stick inputs (``doublet-v1``, ``3211-v1``, ``pulse-v1``) add a deflection to one command axis
  on top of the autopilot, the excitation FDI needs;
* reference changes (``altitude-v1``, ``airspeed-v1``, ``heading-v1``, ``turn-v1``) move the
  autopilot's references, ramped at a rate.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

AXES: tuple[str, ...] = ("elevator", "aileron", "rudder", "throttle")
Axis = Literal["elevator", "aileron", "rudder", "throttle"]


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    type: str
    t_start_s: float = Field(ge=0.0, description="start time [s]")


class PulseTrainParams(_Params):
    """A sequence of square pulses on one command axis."""

    axis: Axis
    amplitude_norm: float = Field(gt=-1.0, lt=1.0, description="pulse height, normalized command units [-]")
    pulse_s: float = Field(gt=0.0, le=60.0, description="unit pulse width [s]")


class AltitudeParams(_Params):
    h_ft: float = Field(ge=500.0, le=50000.0, description="new altitude reference [ft]")
    rate_fps: float = Field(default=20.0, gt=0.0, le=500.0, description="ramp rate of the reference [ft/s]")


class AirspeedParams(_Params):
    vc_kts: float = Field(gt=40.0, le=800.0, description="new calibrated airspeed reference [kt]")
    rate_ktps: float = Field(default=1.0, gt=0.0, le=20.0, description="ramp rate of the reference [kt/s]")


class HeadingParams(_Params):
    psi_deg: float = Field(ge=-360.0, le=360.0, description="new heading reference [deg true]")


class TurnParams(_Params):
    phi_deg: float = Field(ge=-60.0, le=60.0, description="bank angle held during the turn [deg]")
    duration_s: float = Field(gt=0.0, le=36000.0, description="time spent in the turn [s]")


@dataclass(frozen=True)
class PulseTrain:
    """Stick input: pulses of signs ``pattern`` and widths ``widths`` x ``pulse_s``.

    A doublet is (+1, -1) with widths (1, 1); the 3-2-1-1 is (+1, -1, +1, -1) with widths (3, 2, 1, 1).
    """

    axis: str
    t_start_s: float
    amplitude_norm: float
    pulse_s: float
    pattern: tuple[float, ...]
    widths: tuple[float, ...]

    @property
    def t_end_s(self) -> float:
        return self.t_start_s + self.pulse_s * sum(self.widths)

    def pulses(self) -> list[tuple[float, float, float]]:
        """The pulses as (start [s], end [s], deflection [normalized]), each holding on [start, end).

        The one place the pulse edges are computed: :meth:`stick` and the pilot's compiled step
        both read them, so both see the same floats.
        """
        out = []
        t0 = self.t_start_s
        for sign, w in zip(self.pattern, self.widths):
            t1 = t0 + w * self.pulse_s
            out.append((t0, t1, sign * self.amplitude_norm))
            t0 = t1
        return out

    def stick(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Deflection added to the axis at each time [normalized] (a later pulse wins an overlap)."""
        out = np.zeros_like(t_s)
        for t0, t1, value in self.pulses():
            out[(t_s >= t0) & (t_s < t1)] = value
        return out


@dataclass(frozen=True)
class RefRamp:
    """Reference change: ``channel`` ramps from its value at ``t_start_s`` to ``target`` at ``rate`` per s."""

    channel: str  # "h_ft" or "vc_kts"
    t_start_s: float
    target: float
    rate: float

    def value_at(self, t_s: float, start_value: float, before: float) -> float:
        """The reference at one time [channel units]: ``before`` until the start, then the ramp."""
        return float(self.apply(np.array([t_s]), np.array([before]), start_value)[0])

    def apply(self, t_s: NDArray[np.float64], ref: NDArray[np.float64], start_value: float) -> NDArray[np.float64]:
        dt = np.maximum(t_s - self.t_start_s, 0.0)
        step = self.target - start_value
        ramp = start_value + np.sign(step) * np.minimum(np.abs(step), self.rate * dt)
        return np.where(t_s >= self.t_start_s, ramp, ref)


@dataclass(frozen=True)
class HeadingChange:
    t_start_s: float
    psi_deg: float


@dataclass(frozen=True)
class Turn:
    t_start_s: float
    phi_deg: float
    duration_s: float


def doublet(p: PulseTrainParams) -> PulseTrain:
    return PulseTrain(p.axis, p.t_start_s, p.amplitude_norm, p.pulse_s, (1.0, -1.0), (1.0, 1.0))


def three_two_one_one(p: PulseTrainParams) -> PulseTrain:
    return PulseTrain(p.axis, p.t_start_s, p.amplitude_norm, p.pulse_s, (1.0, -1.0, 1.0, -1.0), (3.0, 2.0, 1.0, 1.0))


def pulse(p: PulseTrainParams) -> PulseTrain:
    return PulseTrain(p.axis, p.t_start_s, p.amplitude_norm, p.pulse_s, (1.0,), (1.0,))


def altitude(p: AltitudeParams) -> RefRamp:
    return RefRamp("h_ft", p.t_start_s, p.h_ft, p.rate_fps)


def airspeed(p: AirspeedParams) -> RefRamp:
    return RefRamp("vc_kts", p.t_start_s, p.vc_kts, p.rate_ktps)


def heading(p: HeadingParams) -> HeadingChange:
    return HeadingChange(p.t_start_s, p.psi_deg)


def turn(p: TurnParams) -> Turn:
    return Turn(p.t_start_s, p.phi_deg, p.duration_s)

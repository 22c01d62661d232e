"""Gain-scheduled ``kalman-gust-v1``: one design per schedule point, switched by the nearest point.

The aircraft's dynamics change with altitude and airspeed (dynamic pressure scales every
aerodynamic derivative), so a filter designed at one trim point mismatches the aircraft once it
climbs or accelerates away from it. A :class:`GustKalmanSchedule` holds a design (and its
calibration) at each of ``P`` schedule points; the streaming kernel
(:mod:`fdi_sim.detectors.gust_kalman_stream`) uses at each detector sample the design of the
point nearest the *measured* scheduling variables (low-passed, ``tau_s``), in units of the grid
spacing::

    d_i = || (s - s_i) / spacing ||_2,     s = (h_ft, vc_kts) measured, low-passed

and switches from the active point ``c`` to the nearest ``i`` only when ``d_c - d_i >
hysteresis`` (no chattering on a boundary in turbulence). Switching is bumpless: the filter's
state is a deviation from its design's trim, so the absolute estimate is carried across,
``dx_new = dx_old + x0_old - x0_new`` (plant, sensor-lag, gust and bias states alike: the
augmented trim of gust and bias states is zero; the heading's ``x0_old - x0_new`` is wrapped to
[-pi, pi), as JSBSim may read a trim heading of 0 as 2 pi: ``gust_kalman_stream``), and the
innovation window, the gain index and the alarm state continue.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.gust_kalman import Calibration, GustKalmanDesign
from fdi_sim.errors import DesignError

#: the measured outputs that schedule the designs
SCHEDULE_SIGNALS: tuple[str, ...] = ("h_ft", "vc_kts")
#: switch only when the new point is this much nearer, in grid spacings (hysteresis)
DEFAULT_HYSTERESIS = 0.1
#: time constant of the low pass on the measured scheduling signals [s]: moderate turbulence moves
#: the measured vc by about 5 kt rms about the steady-air speed, more than the DHC-6's 4 kt spacing
DEFAULT_TAU_S = 5.0


@dataclass(frozen=True, eq=False)
class GustKalmanSchedule:
    """kalman-gust-v1 designs at schedule points, with their calibrations.

    Attributes
    ----------
    points : NDArray
        (P, S) the scheduling values of each design's trim (``SCHEDULE_SIGNALS`` order:
        ``h_ft`` [ft], ``vc_kts`` [kt]).
    spacing : NDArray
        (S,) the unit of distance per scheduling variable (grid spacing) [ft, kt].
    designs : tuple of GustKalmanDesign
        One per point; identical state, input and output names and window.
    calibrations : tuple of Calibration
        One per point (``sigma_m`` and threshold of that point).
    labels : tuple of str
        What each point is (``"h 10000 ft, vc 300 kt"``).
    hysteresis : float
        Switching hysteresis [grid spacings].
    tau_s : float
        Time constant of the first-order low pass on the measured scheduling signals [s].
    notes : tuple of str
        How the designs and calibrations were made (for the log and the report).
    """

    points: NDArray[np.float64]
    spacing: NDArray[np.float64]
    designs: tuple[GustKalmanDesign, ...]
    calibrations: tuple[Calibration, ...]
    labels: tuple[str, ...] = ()
    hysteresis: float = DEFAULT_HYSTERESIS
    notes: tuple[str, ...] = field(default=())
    tau_s: float = DEFAULT_TAU_S

    def __post_init__(self) -> None:
        P = len(self.designs)
        pts = np.asarray(self.points, dtype=float)
        if P == 0:
            raise DesignError("a gain schedule needs at least one design")
        if pts.shape != (P, len(SCHEDULE_SIGNALS)):
            raise DesignError(f"points must be ({P}, {len(SCHEDULE_SIGNALS)}) ({', '.join(SCHEDULE_SIGNALS)}); got {pts.shape}")
        sp = np.asarray(self.spacing, dtype=float)
        if sp.shape != (len(SCHEDULE_SIGNALS),) or not np.all(sp > 0):
            raise DesignError(f"spacing must be {len(SCHEDULE_SIGNALS)} positive numbers; got {sp}")
        if len(self.calibrations) != P:
            raise DesignError(f"{P} designs but {len(self.calibrations)} calibrations")
        m0 = self.designs[0].model
        for i, d in enumerate(self.designs):
            m = d.model
            same = (tuple(m.state_names) == tuple(m0.state_names) and tuple(m.input_names) == tuple(m0.input_names)
                    and tuple(m.output_names) == tuple(m0.output_names) and d.window_n == self.designs[0].window_n
                    and d.control_columns == self.designs[0].control_columns
                    and d.hypotheses == self.designs[0].hypotheses)
            if not same:
                raise DesignError(f"design {i} ({self.label(i)}) differs in its states, inputs, outputs, window or "
                                  "hypotheses from design 0: the points of one schedule must share one structure")
            if self.calibrations[i].sigma_m.shape != (m.n_outputs, m.n_outputs):
                raise DesignError(f"calibration {i} ({self.label(i)}) is not for {m.n_outputs} outputs")
        missing = [s for s in SCHEDULE_SIGNALS if s not in m0.output_names]
        if missing:
            raise DesignError(f"the designs do not measure the scheduling signals {missing}")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "spacing", sp)

    @property
    def n_points(self) -> int:
        return len(self.designs)

    @property
    def thresholds(self) -> NDArray[np.float64]:
        """(P,) the calibrated threshold of each point."""
        return np.array([c.threshold for c in self.calibrations])

    def label(self, i: int) -> str:
        if i < len(self.labels):
            return self.labels[i]
        h, v = self.points[i]
        return f"h {h:.0f} ft, vc {v:.0f} kt"

    def nearest(self, s: Sequence[float]) -> int:
        """The point nearest the scheduling values ``s`` (no hysteresis)."""
        d = np.linalg.norm((np.asarray(s, dtype=float)[None, :] - self.points) / self.spacing[None, :], axis=1)
        return int(np.argmin(d))

    @classmethod
    def single(cls, design: GustKalmanDesign, calibration: Calibration, label: str = "") -> GustKalmanSchedule:
        """One design (no scheduling): the point is the design's own trim."""
        m = design.model
        y0 = np.asarray(m.y0, dtype=float)
        pt = np.array([[y0[list(m.output_names).index(s)] for s in SCHEDULE_SIGNALS]])
        # one point: the spacing scales no distance (a unit one, not some aircraft's grid)
        return cls(pt, np.ones(len(SCHEDULE_SIGNALS)), (design,), (calibration,), (label,) if label else (),
                   notes=("single design: not scheduled",))

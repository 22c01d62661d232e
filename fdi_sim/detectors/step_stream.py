"""The streaming contract over a per-sample detector (``step(t_s, u, y) -> Residual``): the fallback.

Every registered detector flies in a bank through :class:`~fdi_sim.detectors.stream.StreamingDetector`.
Where a detector's runtime has a compiled block kernel (:mod:`fdi_sim.detectors.seed_streams`:
the parity window, the directional observers and the steady Kalman filter; the gust filter; the
kinematic checks) the bank uses it. The rest (the adaptive observer, the time-varying Kalman
filter, the multiple-model bank, and a plugin that only offers ``step``) run through
:class:`StepStream`, which calls ``step`` once per sample in Python, at Python's cost. On valid
samples its numbers are those ``fdi-sim detect`` gives offline
(:func:`fdi_sim.offline.detect.run_detector` feeds the same absolute values); on invalid ones they
differ (offline feeds the NaN in, here the sample is skipped). It is the one member kind that fails
the contract's "no Python work per sample" check, and the checker says so.

Inputs as in :func:`fdi_sim.offline.detect.run_detector`: the model's inputs that the loop logs come
from ``u``; the others (the gust inputs) are held at trim; each output's deviation from trim is
wrapped where it is a heading (:func:`fdi_sim.detectors.samples.is_wrapped`). A sample with any
output not ``ok`` (a dropout, a non-finite value, a sensor excluded by reconfiguration) is not
given to the detector at all (most raise on a NaN): it is written invalid, and the detector's
state skips it.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.samples import is_wrapped
from fdi_sim.detectors.stream import BlockOutputs, command_columns, hash_arrays

__all__ = ["StepStream"]

_TWO_PI = 2.0 * math.pi


class StepStream:
    """A per-sample detector run block by block (module docstring).

    Parameters
    ----------
    det : object
        ``id``, ``hypotheses``, ``threshold``, ``reset(rng)``, ``step(t_s, u, y) -> Residual``
        (:class:`fdi_sim.detectors.base.Detector`), designed from ``model``.
    model : LinearModel
        Its design model (input and output names, trim ``u0``, ``y0``).
    command_names : sequence of str
        The commands the loop logs.
    params : mapping
        The design options (for :meth:`design_key`).
    id : str, optional
        The member id (default ``det.id``).
    """

    #: runs ``step`` in Python per sample (the contract checker reports it)
    compiled = False
    independent = False
    fault_directions = False
    estimate_names: tuple[str, ...] = ()

    def __init__(self, det: Any, model: Any, command_names: Sequence[str], params: Mapping[str, Any] | None = None,
                 id: str | None = None) -> None:
        self.det = det
        self.id = str(id or det.id)
        self.hypotheses: tuple[str, ...] = tuple(det.hypotheses)
        self.input_names, col = command_columns(model, command_names)
        self._u_cols = np.flatnonzero(col >= 0)  # the model's columns of the logged commands, in model order
        self.output_names: tuple[str, ...] = tuple(model.output_names)
        self._u0 = np.asarray(model.u0, dtype=float).copy()
        self._y0 = np.asarray(model.y0, dtype=float).copy()
        self._wrap = np.array([is_wrapped(nm) for nm in self.output_names], dtype=bool)
        self._key = hash_arrays(f"StepStream {self.id}", (model.A, model.B, model.C, model.D, model.u0, model.y0),
                                (sorted((str(k), repr(v)) for k, v in dict(params or {}).items()),
                                 tuple(model.input_names), tuple(model.output_names)))
        # the residual's width: one step at trim, then back to the designed state
        det.reset(np.random.default_rng(0))
        r = np.atleast_1d(np.asarray(det.step(0.0, self._u0.copy(), self._y0.copy()).r, dtype=float))
        self.residual_names: tuple[str, ...] = tuple(f"r{i}" for i in range(r.size))
        self._u = self._u0.copy()
        self.reset()

    @property
    def threshold(self) -> float:
        """The detector's threshold on its statistic [-]."""
        return float(self.det.threshold)

    def set_threshold(self, value: float) -> None:
        """Set the detector's threshold (its ``step`` isolates above it)."""
        self.det.threshold = float(value)

    def reset(self) -> None:
        """The detector's own reset (deterministic detectors ignore the generator)."""
        self.det.reset(np.random.default_rng(0))

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """One design point: a reset."""
        self.reset()

    def design_key(self) -> bytes:
        """sha256 of the detector's id, options and model (:func:`fdi_sim.detectors.stream.hash_arrays`)."""
        return self._key

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """``step`` per sample (Python); invalid samples skipped (module docstring)."""
        hyp = {h: i for i, h in enumerate(self.hypotheses)}
        thr = self.threshold
        out.threshold[:] = thr
        out.point[:] = 0
        for j in range(t_s.shape[0]):
            if not ok[j].all():
                out.statistic[j], out.valid[j], out.hypothesis[j] = math.nan, False, -1
                out.residual[j] = math.nan
                continue
            self._u[self._u_cols] = u[j]
            dy = y[j] - self._y0
            if self._wrap.any():  # a heading: the deviation on [-pi, pi), as the offline samples
                dy[self._wrap] = (dy[self._wrap] + math.pi) % _TWO_PI - math.pi
            res = self.det.step(float(t_s[j]), self._u, self._y0 + dy)
            stat = float(res.statistic)
            ok_j = bool(res.valid) and math.isfinite(stat)
            out.statistic[j] = stat
            out.valid[j] = ok_j
            out.hypothesis[j] = hyp.get(res.isolation, -1) if ok_j and stat > thr else -1
            r = np.atleast_1d(np.asarray(res.r, dtype=float))
            out.residual[j, : r.size] = r[: out.residual.shape[1]]

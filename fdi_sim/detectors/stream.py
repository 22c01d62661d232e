"""The one streaming contract every detector in a bank implements (built-in and plugin alike).

A bank runs its members block by block (:mod:`fdi_sim.bank.runtime`): every ``block_s`` it hands each
member the block's detector samples, by the time convention of :mod:`fdi_sim.detectors.samples`
(sample ``j`` pairs the command averaged over the interval ending at ``t_j`` with the measurement
read at ``t_j``), and the member writes, per sample, its statistic, the threshold it is tested
against, whether the sample is valid, the hypothesis it points at and its residual into arrays
the bank allocated once (:class:`BlockOutputs`). The bank alone decides (k-of-n persistence on
``valid and statistic > threshold``, :func:`fdi_sim.decision.persistence.k_of_n_step`), isolates (the
vote over ``hypothesis``), keeps the failure log and reconfigures; a member never sees another.

Contract (checked for every registered detector by :func:`fdi_sim.detectors.check.check_stream`):

- *block invariance*: cutting the same samples into blocks of any size gives the same bits;
- *reset*: :meth:`StreamingDetector.reset` restores the state the detector was designed in;
- *NaN in, invalid out*: a sample whose used measurement is not finite or not ``ok`` is either
  processed without it or reported ``valid = False``; a NaN statistic is never a valid "no alarm";
- *no Python work per sample*: the cost of a call does not grow with the block in Python objects
  (the per-sample work is compiled, or vectorised over the block);
- *thresholds in and out through* :attr:`StreamingDetector.threshold` and
  :meth:`StreamingDetector.set_threshold` (the bank's one calibration rule sets every member's).

Two optional attributes: ``tail_power`` (1.0 or 2.0), the form of the statistic, which the
threshold's tail fit then takes as given instead of choosing it from the training data (2: a
mean of Gaussian residuals, exponential in ``x^2``; 1: a quadratic form, exponential in ``x``),
and ``tail_heavy`` (default True: a heavier tail may replace the exponential where significant;
False: the statistic is known to be light-tailed) (:func:`fdi_sim.decision.tail.episode_threshold`).
A member without them gets the data's choice.

Values are absolute (the detector subtracts its own trim), in the order of the detector's
``input_names`` (the bank's logged commands) and ``output_names`` (the bank's logged
measurements). A detector that needs no command has ``input_names = ()`` and gets a (N, 0) array.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = ["BlockOutputs", "EstimatesActuators", "StreamingDetector", "command_columns", "hash_arrays",
           "stream_design_key"]


@dataclass(frozen=True, eq=False)
class BlockOutputs:
    """The arrays a member writes for one block of ``N`` samples (rows ``0 .. N-1``).

    Allocated once per member (:meth:`allocate`) at the bank's block size; a shorter block (the
    end of a replay) gets row views (:meth:`rows`).

    Attributes
    ----------
    statistic : NDArray
        (N,) the test statistic [-] (any scale; the threshold is on the same scale).
    threshold : NDArray
        (N,) the threshold the sample is tested against [-] (a scheduled detector may change it
        with the operating point; most write :attr:`StreamingDetector.threshold`).
    valid : NDArray of bool
        (N,) the statistic is a usable decision input (window full, filter settled, finite).
    hypothesis : NDArray of int64
        (N,) index into ``hypotheses`` of the fault the sample points at, -1 for none (a detector
        that cannot isolate writes -1). The bank counts it only while the member is in alarm.
    point : NDArray of int64
        (N,) the active design point of a scheduled detector (0 otherwise).
    residual : NDArray
        (N, len(residual_names)) the residual vector (detector units), logged as
        ``/fdi/<id>/residual``.
    estimate : NDArray
        (N, len(estimate_names)) the detector's estimate of each measurement it reconstructs (a
        filter's predicted output), logged as ``/fdi/<id>/estimate``; reconfiguration substitutes
        it for a failed sensor. (N, 0) for a detector without estimates.
    cosine : NDArray
        (N,) the cosine of the isolated hypothesis's direction (the angle-magnitude rule), NaN
        where the detector has no directions.
    """

    statistic: NDArray[np.float64]
    threshold: NDArray[np.float64]
    valid: NDArray[np.bool_]
    hypothesis: NDArray[np.int64]
    point: NDArray[np.int64]
    residual: NDArray[np.float64]
    estimate: NDArray[np.float64]
    cosine: NDArray[np.float64]

    @classmethod
    def allocate(cls, n_samples: int, n_residuals: int, n_estimates: int = 0) -> BlockOutputs:
        """Arrays for blocks of up to ``n_samples`` samples."""
        S = int(n_samples)
        return cls(np.zeros(S), np.zeros(S), np.zeros(S, dtype=np.bool_), np.full(S, -1, dtype=np.int64),
                   np.zeros(S, dtype=np.int64), np.zeros((S, int(n_residuals))), np.zeros((S, int(n_estimates))),
                   np.full(S, np.nan))

    @property
    def n_samples(self) -> int:
        """Rows allocated."""
        return int(self.statistic.shape[0])

    def rows(self, n: int) -> BlockOutputs:
        """Views of the first ``n`` rows (a short block)."""
        return BlockOutputs(self.statistic[:n], self.threshold[:n], self.valid[:n], self.hypothesis[:n],
                            self.point[:n], self.residual[:n], self.estimate[:n], self.cosine[:n])


@runtime_checkable
class StreamingDetector(Protocol):
    """The contract of a bank member (module docstring).

    Attributes
    ----------
    id : str
        Unique within a bank; the ``/fdi/<id>/...`` topics.
    hypotheses : tuple of str
        The faults it can isolate (``BlockOutputs.hypothesis`` indexes it), by signal name:
        a sensor (``q_radps``) or an actuator command (``elevator_cmd_norm``).
    input_names : tuple of str
        The commands it reads (columns of ``u``), a subset of the loop's logged commands.
    output_names : tuple of str
        The measurements it reads (columns of ``y``, ``ok`` and ``fresh``).
    residual_names : tuple of str
        Columns of ``BlockOutputs.residual``.
    estimate_names : tuple of str
        Columns of ``BlockOutputs.estimate`` (measurements it can stand in for; ``()`` if none).
        Reconfiguration relies on it: once a sensor is confirmed faulty the bank marks it not
        ``ok`` for the first member that estimates it, which must go on estimating it from the
        other outputs, and the pilot gets ``y - mean(y - estimate)`` (:mod:`fdi_sim.bank.runtime`).
    independent : bool
        Its isolation compares independent sensor groups (exact kinematics, no model), so one
        confirmation of its suffices to reconfigure a sensor. Declare it only if that is true.
    fault_directions : bool
        It writes ``cosine`` (the angle-magnitude rule may use it).
    """

    id: str
    hypotheses: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    residual_names: tuple[str, ...]
    estimate_names: tuple[str, ...]
    independent: bool
    fault_directions: bool

    @property
    def threshold(self) -> float:
        """The alarm threshold on the statistic [-]."""
        ...

    def set_threshold(self, value: float) -> None:
        """Set the threshold (every operating point alike); ``inf`` must be accepted (the bank
        records the raw statistic of its calibration flights with it)."""
        ...

    def reset(self) -> None:
        """Back to the state it was designed in (empty windows, filters at trim)."""
        ...

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """Reset at the flight's initial condition (a scheduled detector picks its point)."""
        ...

    def design_key(self) -> bytes:
        """Bytes that change whenever the numbers the detector computes would (calibration cache)."""
        ...

    def process_block(self, t_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                      ok: NDArray[np.bool_], fresh: NDArray[np.bool_], out: BlockOutputs) -> None:
        """Process ``N`` consecutive samples.

        Parameters
        ----------
        t_s : NDArray
            (N,) sample times [s].
        u : NDArray
            (N, len(input_names)) absolute commands, averaged over each sample's interval.
        y : NDArray
            (N, len(output_names)) absolute measurements at ``t_s`` (heading as measured).
        ok : NDArray of bool
            (N, len(output_names)) the measurement is usable (valid, finite, not excluded by
            reconfiguration).
        fresh : NDArray of bool
            (N, len(output_names)) the sensor produced a new value at this sample.
        out : BlockOutputs
            Rows ``0 .. N-1`` written.
        """
        ...


@runtime_checkable
class EstimatesActuators(Protocol):
    """An optional capability of a member: estimating an actuator's effectiveness from its own
    residuals once the bank has confirmed a fault on that actuator (reconfiguration rescales the
    command; :mod:`fdi_sim.bank.runtime`). ``kalman-gust-v1``'s stream has it.

    ``effectiveness_estimator(actuator)`` returns an object with ``update(u, residual, point,
    j_start)`` (the block's inputs, residuals and design points, and the index of the block's first
    sample, ``samples_seen`` before the block), ``usable() -> bool`` and ``estimate`` (effectiveness
    [-], its standard deviation [-], samples used).
    """

    @property
    def samples_seen(self) -> int:
        """Samples processed since the last reset."""
        ...

    def effectiveness_estimator(self, actuator: str) -> object:
        """An estimator of ``actuator``'s effectiveness from this member's residuals."""
        ...


def stream_design_key(stream: object) -> bytes:
    """``stream.design_key()``, checked to be bytes (a plugin's key goes into cache file names)."""
    key = stream.design_key()  # type: ignore[attr-defined]
    if not isinstance(key, (bytes, bytearray)):
        raise TypeError(f"{getattr(stream, 'id', stream)!r}.design_key() must return bytes, got {type(key).__name__}")
    return bytes(key)


# --- helpers for streams built on a linear model ------------------------------------------------
def command_columns(model: Any, command_names: Sequence[str]) -> tuple[tuple[str, ...], NDArray[np.int64]]:
    """The model inputs that are logged commands, and each model input's column among them.

    Parameters
    ----------
    model : LinearModel
        Gives ``input_names``.
    command_names : sequence of str
        The commands the loop logs.

    Returns
    -------
    input_names : tuple of str
        The model inputs found in ``command_names``, in model order (the stream's ``u`` columns).
    column : NDArray of int64
        (n_inputs,) for each model input its column in ``u``, -1 if it is held at trim.
    """
    cmds = tuple(command_names)
    names = tuple(nm for nm in model.input_names if nm in cmds)
    col = np.array([names.index(nm) if nm in names else -1 for nm in model.input_names], dtype=np.int64)
    return names, col


def hash_arrays(tag: str, arrays: Sequence[NDArray], settings: Any) -> bytes:
    """sha256 over a tag, the arrays' shapes and float64 bytes, and ``repr(settings)`` (a design key)."""
    h = hashlib.sha256(tag.encode())
    for a in arrays:
        a = np.ascontiguousarray(a, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    h.update(repr(settings).encode())
    return h.digest()


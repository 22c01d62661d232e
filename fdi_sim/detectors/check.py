"""The contract checker: what every bank member must do, checked on any stream (built in or plugin).

In the spirit of Gymnasium's ``check_env``: :func:`check_stream` runs a
:class:`~fdi_sim.detectors.stream.StreamingDetector` over a sequence of samples and returns the
contract's failures, each naming the check and the first sample where it failed (empty: it
passes). The checks (:mod:`fdi_sim.detectors.stream`):

``attributes``
    the protocol's attributes exist with the right types; ``set_threshold`` round-trips;
``blocks``
    blocks of 1 and of 37 samples give the same bits as one whole pass (every output array);
``reset``
    a second whole pass after ``reset`` gives the same bits as the first;
``nan``
    NaN measurements (``ok`` False: every output for 3 samples, then one output alone for 3) never
    give a valid sample with a non-finite statistic, and the detector gives valid samples again
    before the end of the sequence (its state was not poisoned);

Every pass also checks the outputs are usable by the bank (a hypothesis index in ``[-1, H)``, a
design point >= 0, a threshold that is not NaN), and a pass that raises fails its check.
``python-per-sample``
    the number of Python function calls of one ``process_block`` does not grow with the block
    (8 against 64 samples): the per-sample work is compiled or vectorised.

The suite runs it over every registered detector (``tests/sim/test_every_detector.py``); a
bank refuses a plugin whose correctness checks fail, naming the check and the sample
(:func:`fdi_sim.training.build.member_stream`).
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.stream import BlockOutputs, StreamingDetector

__all__ = ["BlockInputs", "ContractFailure", "check_stream", "contract_inputs", "run_blocks", "CHECKS"]

#: the checks, in the order they run
CHECKS = ("attributes", "blocks", "reset", "nan", "python-per-sample")
#: checks whose failure means wrong numbers (a plugin failing one is refused); the last is about cost
CORRECTNESS = CHECKS[:4]


@dataclass(frozen=True)
class ContractFailure:
    """One failed check: its name, what was wrong, and the first sample it was wrong at (if any)."""

    check: str
    detail: str
    sample: int | None = None

    def __str__(self) -> str:
        at = f" (sample {self.sample})" if self.sample is not None else ""
        return f"{self.check}: {self.detail}{at}"


@dataclass(frozen=True, eq=False)
class BlockInputs:
    """A sequence of samples for :meth:`StreamingDetector.process_block` (absolute values)."""

    t_s: NDArray[np.float64]
    u: NDArray[np.float64]
    y: NDArray[np.float64]
    ok: NDArray[np.bool_]
    fresh: NDArray[np.bool_]

    def rows(self, a: int, b: int) -> BlockInputs:
        return BlockInputs(self.t_s[a:b], self.u[a:b], self.y[a:b], self.ok[a:b], self.fresh[a:b])


def contract_inputs(stream: Any, model: Any = None, n_samples: int = 400, rate_hz: float = 20.0,
                    rng: np.random.Generator | None = None) -> BlockInputs:
    """Samples for the checks: trim values (``model.u0``, ``model.y0`` where the model has the
    signal, else 1) plus white noise of 1 % of each value's size (at least 1e-3), and a step of
    10 noise sizes on every output from the middle on, so a detector sees both quiet and faulty
    data. Deterministic for a given ``rng`` (default seed 0)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    N = int(n_samples)

    def base(names: tuple[str, ...], values: Any, model_names: Any) -> NDArray[np.float64]:
        idx = list(model_names) if model_names is not None else []
        return np.array([float(values[idx.index(nm)]) if nm in idx else 1.0 for nm in names])

    u0 = base(tuple(stream.input_names), getattr(model, "u0", None), getattr(model, "input_names", None))
    y0 = base(tuple(stream.output_names), getattr(model, "y0", None), getattr(model, "output_names", None))
    su, sy = np.maximum(1e-3, 0.01 * np.abs(u0)), np.maximum(1e-3, 0.01 * np.abs(y0))
    u = u0 + su * rng.standard_normal((N, u0.size))
    y = y0 + sy * rng.standard_normal((N, y0.size))
    y[N // 2:] += 10.0 * sy
    t = np.arange(1, N + 1) / float(rate_hz)
    return BlockInputs(t, np.ascontiguousarray(u), np.ascontiguousarray(y), np.ones(y.shape, dtype=np.bool_),
                       np.ones(y.shape, dtype=np.bool_))


def run_blocks(stream: Any, x: BlockInputs, block: int | None = None) -> BlockOutputs:
    """Reset, then process ``x`` in blocks of ``block`` samples (one call if None); the outputs of
    every sample, in arrays allocated once."""
    N = x.t_s.shape[0]
    out = BlockOutputs.allocate(N, len(stream.residual_names), len(stream.estimate_names))
    stream.reset()
    step = N if not block else int(block)
    for a in range(0, N, max(step, 1)):
        b = min(N, a + step)
        stream.process_block(x.t_s[a:b], x.u[a:b], x.y[a:b], x.ok[a:b], x.fresh[a:b], _rows(out, a, b))
    return out


def _rows(out: BlockOutputs, a: int, b: int) -> BlockOutputs:
    """Rows ``a .. b-1`` of a whole-flight output (views)."""
    return BlockOutputs(out.statistic[a:b], out.threshold[a:b], out.valid[a:b], out.hypothesis[a:b], out.point[a:b],
                        out.residual[a:b], out.estimate[a:b], out.cosine[a:b])


_FIELDS = ("statistic", "threshold", "valid", "hypothesis", "point", "residual", "estimate", "cosine")


def _first_difference(a: BlockOutputs, b: BlockOutputs) -> tuple[str, int] | None:
    for f in _FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        same = (x == y) | ((x != x) & (y != y)) if x.dtype.kind == "f" else (x == y)
        if same.ndim > 1:
            same = same.all(axis=1)
        if not same.all():
            return f, int(np.flatnonzero(~same)[0])
    return None


def _count_calls(stream: Any, x: BlockInputs) -> int:
    out = BlockOutputs.allocate(x.t_s.shape[0], len(stream.residual_names), len(stream.estimate_names))
    stream.reset()
    calls = [0]

    def prof(frame: Any, event: str, arg: Any) -> None:
        if event in ("call", "c_call"):
            calls[0] += 1

    old = sys.getprofile()
    sys.setprofile(prof)
    try:
        stream.process_block(x.t_s, x.u, x.y, x.ok, x.fresh, out)
    finally:
        sys.setprofile(old)
    return calls[0]


def check_stream(stream: Any, x: BlockInputs, *, checks: tuple[str, ...] = CHECKS) -> list[ContractFailure]:
    """Run the contract's checks (module docstring) on ``stream`` over the samples ``x``.

    Returns
    -------
    list of ContractFailure
        Empty when every check asked for passes. The stream is left reset.
    """
    fails: list[ContractFailure] = []
    if "attributes" in checks:
        fails += _attributes(stream)
        if fails:
            return fails  # the other checks need the attributes
    N = x.t_s.shape[0]

    def attempt(check: str, inputs: BlockInputs, block: int | None = None) -> BlockOutputs | None:
        """One pass; a pass that raises is that check's failure (a foreign kernel's error is the finding)."""
        try:
            out = run_blocks(stream, inputs, block)
        except Exception as exc:  # noqa: BLE001
            fails.append(ContractFailure(check, f"process_block raised {type(exc).__name__}: {exc}"))
            return None
        bad = _out_of_range(stream, out)
        if bad is not None:
            fails.append(ContractFailure(check, bad[0], bad[1]))
            return None
        return out

    whole = attempt("blocks", x)
    if whole is None:
        stream.reset()
        return fails
    if "blocks" in checks:
        for size in (1, 37):
            part = attempt("blocks", x, size)
            d = _first_difference(whole, part) if part is not None else None
            if d:
                fails.append(ContractFailure("blocks", f"blocks of {size} differ from one pass in {d[0]}", d[1]))
    if "reset" in checks:
        again = attempt("reset", x)
        d = _first_difference(whole, again) if again is not None else None
        if d:
            fails.append(ContractFailure("reset", f"a second pass after reset differs in {d[0]}", d[1]))
    if "nan" in checks:
        k = N // 8
        # every output lost for 3 samples, then one output lost alone for 3 (a single sensor's dropout)
        y, ok = x.y.copy(), x.ok.copy()
        y[k:k + 3] = np.nan
        ok[k:k + 3] = False
        if y.shape[1]:
            y[k + 10:k + 13, 0] = np.nan
            ok[k + 10:k + 13, 0] = False
        bad = attempt("nan", BlockInputs(x.t_s, x.u, y, ok, x.fresh))
        if bad is not None:
            wrong = bad.valid & ~np.isfinite(bad.statistic)
            if wrong.any():
                fails.append(ContractFailure("nan", "a valid sample with a non-finite statistic",
                                             int(np.flatnonzero(wrong)[0])))
            # a detector with a window of w samples is invalid for w after a loss: it must give valid
            # samples again before the end of the sequence (337 samples after the loss by default: the
            # kinematic attitude check warms up for 5 s and fills a 2 s window, 140 samples at 20 Hz)
            if whole.valid[-1] and not bad.valid[k + 13:].any():
                fails.append(ContractFailure("nan", f"no valid sample in the {N - k - 13} samples after the NaN "
                                             "measurements (the state was poisoned)", k + 13))
    stream.reset()
    if "python-per-sample" in checks and N >= 64:
        c8, c64 = _count_calls(stream, x.rows(0, 8)), _count_calls(stream, x.rows(0, 64))
        if c64 > c8:
            fails.append(ContractFailure("python-per-sample", f"{(c64 - c8) / 56:.1f} Python calls per sample "
                                         f"({c8} for a block of 8, {c64} for 64): the per-sample work is not compiled"))
        stream.reset()
    return fails


def _out_of_range(stream: Any, out: BlockOutputs) -> tuple[str, int] | None:
    """The first output the bank could not use: a hypothesis index outside [-1, H), a negative
    design point, a threshold that is NaN (the bank indexes its votes by the hypothesis: an index
    past the end would write outside them)."""
    H = len(stream.hypotheses)
    for name, bad in (("hypothesis", (out.hypothesis < -1) | (out.hypothesis >= max(H, 0))),
                      ("point", out.point < 0), ("threshold", np.isnan(out.threshold))):
        if name == "hypothesis" and H == 0:
            bad = out.hypothesis != -1
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            return f"{name} {getattr(out, name)[j].item()!r} is outside what the bank accepts (hypotheses: {H})", j
    return None


def _attributes(stream: Any) -> list[ContractFailure]:
    out = []
    if not isinstance(stream, StreamingDetector):
        missing = [a for a in ("id", "hypotheses", "input_names", "output_names", "residual_names", "estimate_names",
                               "independent", "fault_directions", "threshold", "set_threshold", "reset", "start_at",
                               "design_key", "process_block") if not hasattr(stream, a)]
        return [ContractFailure("attributes", f"not a StreamingDetector: missing {', '.join(missing)}")]
    for a in ("hypotheses", "input_names", "output_names", "residual_names", "estimate_names"):
        v = getattr(stream, a)
        if not isinstance(v, tuple) or not all(isinstance(s, str) for s in v):
            out.append(ContractFailure("attributes", f"{a} must be a tuple of str, got {v!r}"))
    if not isinstance(stream.id, str) or not stream.id:
        out.append(ContractFailure("attributes", f"id must be a non-empty str, got {stream.id!r}"))
    try:
        thr = float(stream.threshold)
        stream.set_threshold(thr * 2.0 + 1.0)
        if float(stream.threshold) != thr * 2.0 + 1.0:
            out.append(ContractFailure("attributes", "set_threshold(x) did not make threshold == x"))
        stream.set_threshold(math.inf)  # the bank's calibration replays with the threshold at inf
        if float(stream.threshold) != math.inf:
            out.append(ContractFailure("attributes", "set_threshold(inf) did not make threshold == inf"))
        stream.set_threshold(thr)
        if not math.isfinite(thr):
            out.append(ContractFailure("attributes", f"threshold {thr} is not finite"))
    except Exception as exc:  # noqa: BLE001
        out.append(ContractFailure("attributes", f"threshold/set_threshold failed: {type(exc).__name__}: {exc}"))
    try:
        key = stream.design_key()
        if not isinstance(key, (bytes, bytearray)):
            out.append(ContractFailure("attributes", f"design_key() must return bytes, got {type(key).__name__}"))
    except Exception as exc:  # noqa: BLE001
        out.append(ContractFailure("attributes", f"design_key() failed: {type(exc).__name__}: {exc}"))
    return out

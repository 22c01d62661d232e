"""The contract checker says no: each broken toy stream fails exactly the check it breaks."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.detectors.check import CHECKS, check_stream, contract_inputs
from fdi_sim.detectors.stream import BlockOutputs, StreamingDetector


class Toy:
    """A correct stream: an exponential average of the first output's deviation, vectorised over
    the block except for the carried state (a closed-form recursion, no per-sample Python)."""

    id = "toy-v1"
    hypotheses = ("y0",)
    input_names: tuple[str, ...] = ()
    output_names = ("y0", "y1")
    residual_names = ("e",)
    estimate_names: tuple[str, ...] = ()
    independent = False
    fault_directions = False

    def __init__(self) -> None:
        self._thr = 3.0
        self.reset()

    @property
    def threshold(self) -> float:
        return self._thr

    def set_threshold(self, value: float) -> None:
        self._thr = float(value)

    def reset(self) -> None:
        self._last = np.zeros(1)

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        self.reset()

    def design_key(self) -> bytes:
        return b"toy"

    def _stat(self, y: np.ndarray, ok: np.ndarray) -> np.ndarray:
        e = np.where(ok[:, 0], y[:, 0] - 1.0, 0.0) * 100.0
        return np.abs(e) + 0.0 * self._last[0]

    def process_block(self, t_s, u, y, ok, fresh, out: BlockOutputs) -> None:
        s = self._stat(y, ok)
        out.statistic[:] = s
        out.valid[:] = ok[:, 0]
        out.statistic[~ok[:, 0]] = np.nan
        out.threshold[:] = self._thr
        out.hypothesis[:] = np.where(out.valid & (s > self._thr), 0, -1)
        out.residual[:, 0] = s
        out.point[:] = 0


class BlockDependent(Toy):
    def _stat(self, y, ok):
        e = np.where(ok[:, 0], y[:, 0], 0.0)
        return np.abs(e - e.mean()) * 100.0  # depends on which samples share the block


class NoReset(Toy):
    def reset(self) -> None:
        if not hasattr(self, "_n"):
            self._n = 0
            self._last = np.zeros(1)

    def _stat(self, y, ok):
        self._n += 1
        return super()._stat(y, ok) + self._n  # the number of calls since construction leaks in


class NanValid(Toy):
    def process_block(self, t_s, u, y, ok, fresh, out):
        super().process_block(t_s, u, y, ok, fresh, out)
        out.valid[:] = True  # a NaN measurement reported as a valid sample


class PerSample(Toy):
    def _stat(self, y, ok):
        return np.array([abs(float(y[j, 0]) - 1.0) * 100.0 if ok[j, 0] else 0.0 for j in range(y.shape[0])])


class NotAStream:
    id = "nothing-v1"


def _x(stream):
    return contract_inputs(stream, None, n_samples=160)


def test_a_correct_stream_passes_every_check():
    assert isinstance(Toy(), StreamingDetector)
    assert check_stream(Toy(), _x(Toy())) == []


@pytest.mark.parametrize("cls, check", [(BlockDependent, "blocks"), (NoReset, "reset"), (NanValid, "nan"),
                                        (PerSample, "python-per-sample")])
def test_each_broken_stream_fails_its_check(cls, check):
    fails = check_stream(cls(), _x(cls()))
    assert check in {f.check for f in fails}, fails
    assert all(f.check in CHECKS for f in fails)
    if check != "python-per-sample":  # a wrong number is located
        assert any(f.sample is not None for f in fails if f.check == check)
    assert str(fails[0]).startswith(fails[0].check + ": ")


def test_not_a_stream_names_what_is_missing():
    fails = check_stream(NotAStream(), _x(Toy()))
    assert [f.check for f in fails] == ["attributes"] and "process_block" in fails[0].detail


class BadIndex(Toy):
    def process_block(self, t_s, u, y, ok, fresh, out):
        super().process_block(t_s, u, y, ok, fresh, out)
        out.hypothesis[:] = 7  # past its one hypothesis: the bank's votes would be written out of bounds


class RaisesOnNan(Toy):
    def process_block(self, t_s, u, y, ok, fresh, out):
        if not ok.all():
            raise ValueError("NaN in y")
        super().process_block(t_s, u, y, ok, fresh, out)


def test_outputs_the_bank_cannot_use_and_exceptions_are_failures_not_crashes():
    fails = check_stream(BadIndex(), _x(BadIndex()))
    assert any(f.check == "blocks" and "hypothesis 7" in f.detail and f.sample == 0 for f in fails), fails
    fails = check_stream(RaisesOnNan(), _x(RaisesOnNan()))
    assert [f.check for f in fails] == ["nan"] and "ValueError: NaN in y" in fails[0].detail

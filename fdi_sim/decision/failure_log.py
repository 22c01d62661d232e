"""The failure log of Miller & Ribbens' FIG. 4: events from per-hypothesis binary signatures over time.

The patent's decision logic gives one binary failure signal ``F`` per hypothesized failure, false
without the failure and true while it is present; the failure log stores "the time of occurrence,
duration and nature of the failure" (US 6,643,569 B2, description of FIG. 4). Here an *event* is a
maximal run of samples where ``F`` is true (runs separated by fewer than ``merge_gap_s`` seconds
of false are one event); its nature is ``"persistent"`` when it is the hypothesis' only event and
``"intermittent"`` when the hypothesis recurs (two or more events in the log), so an intermittent
fault gives several events, each marked intermittent.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

__all__ = ["FailureEvent", "FailureLogger", "failure_log"]

PERSISTENT = "persistent"
INTERMITTENT = "intermittent"


@dataclass(frozen=True)
class FailureEvent:
    """One entry of the failure log.

    Attributes
    ----------
    hypothesis : str
        The hypothesized failure whose signature was on.
    onset_t_s : float
        Time of the first sample with the signature on [s].
    end_t_s : float
        Time of the first sample with it off again [s]; the last sample's time if it never went off.
    duration_s : float
        ``end_t_s - onset_t_s`` [s].
    nature : str
        ``"persistent"`` or ``"intermittent"`` (the hypothesis has more than one event).
    ongoing : bool
        True when the signature was still on at the last sample.
    """

    hypothesis: str
    onset_t_s: float
    end_t_s: float
    duration_s: float
    nature: str
    ongoing: bool = False


def failure_log(t_s: NDArray[np.float64], signature: NDArray[np.bool_], hypotheses: Sequence[str],
                merge_gap_s: float = 0.0) -> list[FailureEvent]:
    """Events of a whole trace, sorted by onset.

    Parameters
    ----------
    t_s : NDArray
        (N,) sample times [s], increasing.
    signature : NDArray
        (N, n_h) binary failure signal per hypothesis (or (N,) for one).
    hypotheses : sequence of str
        Names of the columns.
    merge_gap_s : float
        Off-gaps shorter than this [s] do not split an event (debouncing); 0 keeps every gap.
    """
    t = np.asarray(t_s, float)
    F = np.asarray(signature, bool)
    F = F[:, None] if F.ndim == 1 else F
    if F.shape != (t.size, len(hypotheses)):
        raise DesignError(f"signature shape {F.shape} must be (len(t_s)={t.size}, len(hypotheses)={len(hypotheses)})")
    events: list[tuple[float, float, bool, str, str]] = []
    for j, name in enumerate(hypotheses):
        edges = np.diff(np.concatenate([[0], F[:, j].astype(np.int8), [0]]))
        on = np.flatnonzero(edges == 1)  # first sample on
        off = np.flatnonzero(edges == -1)  # first sample off (N if still on)
        if on.size and merge_gap_s > 0.0:
            inner_off, next_on = off[:-1], on[1:]
            keep = t[next_on] - t[inner_off] >= merge_gap_s  # gap from first-off to next-on
            on = np.concatenate([on[:1], next_on[keep]])
            off = np.concatenate([inner_off[keep], off[-1:]])
        nature = INTERMITTENT if on.size > 1 else PERSISTENT
        for a, b in zip(on, off):
            ongoing = b >= t.size
            end = t[-1] if ongoing else t[b]
            events.append((float(t[a]), float(end), bool(ongoing), name, nature))
    events.sort(key=lambda e: (e[0], hypotheses.index(e[3])))
    return [FailureEvent(h, a, b, b - a, n, o) for a, b, o, h, n in events]


class FailureLogger:
    """The failure log built sample by sample (the same events as :func:`failure_log`, no merging).

    Parameters
    ----------
    hypotheses : sequence of str
        Names of the binary signals, in the order ``step`` receives them.
    """

    def __init__(self, hypotheses: Sequence[str]) -> None:
        self.hypotheses = tuple(hypotheses)
        self._on = np.zeros(len(self.hypotheses), dtype=bool)
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Empty the log."""
        self._on[:] = False
        self._onset = [0.0] * len(self.hypotheses)
        self._closed: list[tuple[float, float, int]] = []
        self._count = [0] * len(self.hypotheses)
        self._t_last = float("nan")

    def step(self, t_s: float, signature: NDArray[np.bool_]) -> tuple[FailureEvent, ...]:
        """One sample of the signals at ``t_s`` [s]; returns the events that ended at this sample
        (their nature as known so far: a first event reads persistent until the fault recurs)."""
        F = np.asarray(signature, bool)
        ended: list[FailureEvent] = []
        for j in np.flatnonzero(F != self._on):
            if F[j]:
                self._onset[j] = float(t_s)
                self._count[j] += 1
            else:
                self._closed.append((self._onset[j], float(t_s), int(j)))
                a = self._onset[j]
                ended.append(FailureEvent(self.hypotheses[j], a, float(t_s), float(t_s) - a,
                                          INTERMITTENT if self._count[j] > 1 else PERSISTENT))
        self._on[:] = F
        self._t_last = float(t_s)
        return tuple(ended)

    def events(self) -> list[FailureEvent]:
        """Every event so far, sorted by onset, with its final nature; open events end at the last sample."""
        rows = [(a, b, j, False) for a, b, j in self._closed]
        rows += [(self._onset[j], self._t_last, int(j), True) for j in np.flatnonzero(self._on)]
        rows.sort(key=lambda r: (r[0], r[2]))
        return [FailureEvent(self.hypotheses[j], a, b, b - a,
                             INTERMITTENT if self._count[j] > 1 else PERSISTENT, o) for a, b, j, o in rows]

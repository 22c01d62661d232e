"""The bank's compiled per-block kernels: command averages, a member's columns, the one decision.

Each is a sequential loop over the block's samples, so a flight cut into blocks of any size gives
the same bits (the loop and a replay of its log agree).
"""
from __future__ import annotations

import math

import numba

from fdi_sim.decision.persistence import k_of_n_step


@numba.njit(cache=True, nogil=True)
def average_commands(rows, n, out):  # pragma: no cover - compiled
    """``out[j] = (1/n) sum_{i<n} rows[j n + i]``, summed in row order (the time convention's
    average; sequential so that the loop and a replay of the log give the same bits)."""
    J, m = out.shape
    for j in range(J):
        for c in range(m):
            acc = 0.0
            for i in range(n):
                acc += rows[j * n + i, c]
            out[j, c] = acc / n


@numba.njit(cache=True, nogil=True)
def gather_columns(meas, valid, cols, excluded, every, row0, n, y, ok, fresh):  # pragma: no cover - compiled
    """A member's columns of the block: values, usability (valid, finite, not excluded) and
    freshness (the sensor sampled at this row: ``row % every == 0``)."""
    S = y.shape[0]
    for j in range(S):
        row = row0 + (j + 1) * n
        for c in range(cols.shape[0]):
            v = meas[j, cols[c]]
            y[j, c] = v
            ok[j, c] = valid[j, cols[c]] and math.isfinite(v) and not excluded[c]
            fresh[j, c] = row % every[c] == 0


@numba.njit(cache=True, nogil=True)
def take_columns(src, cols, out):  # pragma: no cover - compiled
    """``out[j, c] = src[j, cols[c]]`` (a member's inputs from the command averages)."""
    for j in range(out.shape[0]):
        for c in range(cols.shape[0]):
            out[j, c] = src[j, cols[c]]


@numba.njit(cache=True, nogil=True)
def statistic_rows(stat, thr, exceed, alarm, valid, iso, point, out):  # pragma: no cover - compiled
    """The rows of ``/fdi/<id>/statistic`` (:data:`STAT_FIELDS` after ``t_s``)."""
    for j in range(stat.shape[0]):
        out[j, 0] = stat[j]
        out[j, 1] = thr[j]
        out[j, 2] = 1.0 if exceed[j] else 0.0
        out[j, 3] = 1.0 if alarm[j] else 0.0
        out[j, 4] = 1.0 if valid[j] else 0.0
        out[j, 5] = iso[j]
        out[j, 6] = point[j]


@numba.njit(cache=True, nogil=True)
def decide(stat, thr, valid, hyp, k, need_direction, ring, st, votes, exceed, alarm, iso, lead):  # pragma: no cover
    """k-of-n persistence and the isolation vote, carried across blocks.

    ``ring`` (n,) last exceedances; ``st`` = [ring position, count, alarm on, leader, leader votes,
    an alarm in this call];
    ``votes`` (H,) votes of the current alarm; ``lead`` gets the leader's votes at each sample. With ``need_direction`` (the two-step rule) a sample
    exceeds only if its residual is also within the angle bound of some fault direction
    (``hyp >= 0``: the detector's cosine test passed)."""
    st[5] = 0
    for j in range(stat.shape[0]):
        e = valid[j] and stat[j] > thr[j] and (hyp[j] >= 0 or not need_direction)
        exceed[j] = e
        on = k_of_n_step(e, k, ring, st)  # the one k-of-n kernel (st[0], st[1]: ring position, count)
        if on:
            h = hyp[j]
            if e and h >= 0:
                votes[h] += 1
                if votes[h] > st[4]:
                    st[4] = votes[h]
                    st[3] = h
        else:
            if st[2]:
                for h in range(votes.shape[0]):
                    votes[h] = 0
                st[3] = -1
                st[4] = 0
        st[2] = 1 if on else 0
        if on:
            st[5] = 1
        alarm[j] = on
        iso[j] = st[3] if on else -1
        lead[j] = st[4] if on else 0


"""The loop's compiled chunk core (issue 26): many steps in one compiled call, JSBSim included.

:func:`run_chunk` flies steps ``k0 ..`` of a fault-free flight (the loop's fast path) with no
Python per step: per step it reads the JSBSim properties of the truth through their
``SGPropertyNode*`` (:mod:`fdi_sim.aircraft.native`), runs the per-step core
(:func:`fdi_sim.sim._core.step`: truth, divergence checks, sensors, pilot, statistics), stores
the bank's detector sample, writes the commands to JSBSim's nodes, keeps the log's rows in
preallocated buffers and calls ``FGFDMExec::Run()`` through the exception shim. It returns to
Python, which flies the rest, at

- ``BLOCK``: a step that ends a bank block, after its sample is stored (the bank's block runs in
  Python, may reconfigure; the chunk then resumes the same step with ``phase = 1``);
- ``REFILL``: the sensors need a new noise block (nothing of the step done; the step is re-run);
- a divergence code of :mod:`fdi_sim.sim._core` (the step's truth is in ``x``);
- ``STOPPED`` (JSBSim's ``Run()`` returned false) or ``EXCEPTION`` (it threw; the message is in
  the shim's buffer), both after the step's rows are kept;
- ``END`` after the last step, or ``k_end`` (the caller's limit: the writer's flush window, the
  chunk length that keeps a stop request within about a millisecond).

The order of operations is the Python loop's (``fdi_sim.sim.run._loop``), so the numbers are the
same bits: the same core, the same JSBSim calls in the same order, the same commands. ``state``
(int64) carries ``[k, phase, mode, rows, next_sample]`` in and out.
"""
from __future__ import annotations

from pathlib import Path

import numba
import numpy as np

from fdi_sim.sim import _core

#: return codes beyond _core's (OK 0, REFILL 1, divergences 2..7)
LIMIT, BLOCK, END, STOPPED, EXCEPTION = 10, 11, 12, 13, 14
#: ``state`` slots
S_K, S_PHASE, S_MODE, S_ROWS, S_NEXT = range(5)


@numba.njit(cache=True)
def run_chunk(state, k_end, n_steps, dt_s, run_shim, run_addr, fdm, msg_addr, msg_n, get, set_, read_nodes, n_truth,
              cmd_nodes, surf_nodes, x, y, yp, u_arr, cmd_rows, use_bank, n_fdi, K, S, meas_rows, corrected, corr,
              has_scale, scale, s_tab, s_off, p_state, p_par, aux, per_step, log_state, b_t, b_truth, b_meas, b_cmd,
              b_op, b_surf, flaps_deg, i_h, i_vc, i_mach, i_alpha):  # pragma: no cover (compiled)
    """Fly steps from ``state[S_K]`` (module docstring); returns the code it stopped with."""
    k = state[S_K]
    phase = state[S_PHASE]
    mode = state[S_MODE]
    r = state[S_ROWS]
    next_sample = state[S_NEXT]
    n_flat = read_nodes.shape[0]
    code = LIMIT
    while k < k_end:
        t_s = k * dt_s
        u_row = cmd_rows[k % K] if use_bank else u_arr
        if phase == 0:
            for j in range(n_flat):
                x[n_truth + j] = get(read_nodes[j])
            mode = _core.ALL if (k != next_sample and not corrected) else (_core.TRUTH | _core.MEASURE)
            c = _core.step(mode, t_s, x, y, u_row, s_tab, s_off, p_state, p_par, aux)
            if c != _core.OK:  # REFILL (nothing measured) or a divergence: Python takes it from here
                code = c
                break
            if k == next_sample:
                jb = (k // n_fdi - 1) % S
                for i in range(y.shape[0]):
                    meas_rows[jb, i] = y[i]
                next_sample += n_fdi
                if k % K == 0:  # the bank's block: in Python, then this step again from phase 1
                    phase = 1
                    code = BLOCK
                    break
        phase = 0
        if mode != _core.ALL:  # the pilot after the bank's sample, on its (corrected) input
            if corrected:
                for i in range(y.shape[0]):
                    yp[i] = y[i] - corr[i]
                _core.step(_core.PILOT | _core.STATS, t_s, x, yp, u_row, s_tab, s_off, p_state, p_par, aux)
            else:
                _core.step(_core.PILOT | _core.STATS, t_s, x, y, u_row, s_tab, s_off, p_state, p_par, aux)
        if has_scale:  # an actuator's lost effectiveness made up (the log keeps the pilot's command)
            set_(cmd_nodes[0], u_row[0] * scale[0])
            set_(cmd_nodes[1], u_row[1] * scale[1])
            set_(cmd_nodes[2], u_row[2] * scale[2])
            th = u_row[3] * scale[3]
        else:
            set_(cmd_nodes[0], u_row[0])
            set_(cmd_nodes[1], u_row[1])
            set_(cmd_nodes[2], u_row[2])
            th = u_row[3]
        for i in range(3, cmd_nodes.shape[0]):
            set_(cmd_nodes[i], th)
        if per_step:
            b_t[r] = t_s
            if log_state:
                for i in range(n_truth):
                    b_truth[r, i] = x[i]
                b_op[r, 0] = x[i_h]
                b_op[r, 1] = x[i_vc]
                b_op[r, 2] = x[i_mach]
                b_op[r, 3] = x[i_alpha]
                b_op[r, 4] = flaps_deg
                b_op[r, 5] = 0.0  # icing eta: a faulty flight (icing) never takes this path
            for i in range(y.shape[0]):
                b_meas[r, i] = y[i]
            for i in range(u_row.shape[0]):
                b_cmd[r, i] = u_row[i]
        if k == n_steps:
            r += 1
            k += 1
            code = END
            break
        rc = run_shim(run_addr, fdm, msg_addr, msg_n)
        if log_state and rc == 1:
            for i in range(surf_nodes.shape[0]):
                b_surf[r, i] = get(surf_nodes[i])
        r += 1
        k += 1
        if rc != 1:
            code = STOPPED if rc == 0 else EXCEPTION
            break
    state[S_K] = k
    state[S_PHASE] = phase
    state[S_MODE] = mode
    state[S_ROWS] = r
    state[S_NEXT] = next_sample
    return code


# --- the cache of run_chunk: emptied when the kernels it calls change (as _core's) -------------------
_DEPENDENCIES = (*_core._DEPENDENCIES, Path(_core.__file__))


def _check_cache() -> None:
    cache = getattr(run_chunk, "_cache", None)
    path = getattr(cache, "cache_path", None)
    if cache is None or path is None:
        return
    _core._fresh_cache(Path(path) / "_chunk.run_chunk.deps", _core.dependency_stamp(_DEPENDENCIES), cache.flush)


_check_cache()


def prime(nat, s_tab, s_off, p_state, p_par) -> None:
    """Load (or compile) :func:`run_chunk` for the argument types the loop passes, with a call that
    flies no step (``k_end = 0``): numba's first call costs 0.3-0.6 s, which belongs to the set-up,
    not to the flight (a stop in that time would end a flight with no step)."""
    f1, f2, u1 = np.zeros(1), np.zeros((1, 1)), np.zeros(1, dtype=np.uintp)
    state = np.zeros(5, dtype=np.int64)
    run_chunk(state, 0, 0, 1.0, nat.run_shim, nat.run, nat.fdm, nat.message.ctypes.data, len(nat.message), nat.get,
              nat.set, u1, 0, u1, u1, f1, f1, f1, f1, f2, False, 1, 1, 1, f2, False, f1, False, f1, s_tab, s_off,
              p_state, p_par, f1, False, False, f1, f2, f2, f2, f2, f2, 0.0, 0, 0, 0, 0)


def buffers(n_rows: int, n_truth: int, n_meas: int, n_cmd: int, n_surf_flat: int) -> tuple[np.ndarray, ...]:
    """The log-row buffers of a chunk of ``n_rows`` steps: t, truth, measurements, commands,
    operating point (6), surfaces (their flat reads)."""
    return (np.zeros(n_rows), np.zeros((n_rows, n_truth)), np.zeros((n_rows, n_meas)), np.zeros((n_rows, n_cmd)),
            np.zeros((n_rows, 6)), np.zeros((n_rows, n_surf_flat)))

"""The sensor suite's per-step arithmetic, compiled: sample, add bias + noise, quantize, hold.

:class:`fdi_sim.sensors.suite.SensorSuite` keeps everything the step reads and writes, except
the noise, in one float64 array ``tab`` of shape (1 + n_sensors, 4): row 0 the header
(``BLOCK_START``, ``K_WANTED``, ``DT_S``), row ``1 + i`` sensor ``i`` (truth index, decimation,
quantum, held output); one array instead of four saves numba's per-argument dispatch (about
50 ns of the call's 350 ns). The noise block ``off`` (bias + noise, ``BLOCK_STEPS`` rows) is drawn
by the suite in Python from its generator, exactly as before the kernel, because the draws must
stay numpy's. :func:`measure` returns ``True`` without writing anything when step ``k`` is
outside the block; the suite then draws the block starting at ``k`` (``tab[0, K_WANTED]``) and
calls again.

Bit identity with the Python implementation of commit d97be8c (``tests/sensors/_reference_sensors.py``):
``x + off`` is one IEEE addition in both; Python's ``round(v / q) * q`` (ties to even, an int
times ``q``) is ``np.rint(v / q)`` (ties to even) with a negative zero made positive (the int 0
has no sign) times ``q``.
"""
from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

#: ``tab`` header (row 0): the step the noise block starts at, the step that asked for a new
#: block, the simulation step [s]
BLOCK_START, K_WANTED, DT_S = 0, 1, 3
#: ``tab`` sensor rows (1 + i): columns
TRUTH_INDEX, DECIMATION, QUANTUM, HELD = 0, 1, 2, 3


@numba.njit(cache=True)
def measure(t_s: float, x: NDArray[np.float64], out: NDArray[np.float64], tab: NDArray[np.float64],
            off: NDArray[np.float64]) -> bool:  # pragma: no cover (compiled)
    """Measure the truth ``x`` at time ``t_s`` [s] into ``out``; ``True``: a new noise block is needed.

    Parameters
    ----------
    t_s : float
        Time [s].
    x : ndarray, float64
        Truth vector.
    out : ndarray, float64, shape (n_sensors,)
        Receives the held outputs after this step's samples.
    tab : ndarray, float64, shape (1 + n_sensors, 4)
        Header and sensor rows (module constants).
    off : ndarray, float64, shape (BLOCK_STEPS, n_sensors)
        Bias + noise of the block's steps.

    Returns
    -------
    bool
        ``True`` when step ``k`` lies outside the block (nothing written; ``tab[0, K_WANTED] = k``).
    """
    k = int(np.rint(t_s / tab[0, DT_S]))  # round(t_s / dt_s): ties to even, as Python's round
    j = k - int(tab[0, BLOCK_START])
    if j < 0 or j >= off.shape[0]:
        tab[0, K_WANTED] = k
        return True
    for i in range(off.shape[1]):
        row = tab[1 + i]
        if k % int(row[DECIMATION]) == 0:  # a sample instant of sensor i, else hold
            v = x[int(row[TRUTH_INDEX])] + off[j, i]
            q = row[QUANTUM]
            if q != 0.0:
                v = (np.rint(v / q) + 0.0) * q  # + 0.0: round() gives the int 0, never -0
            row[HELD] = v
        out[i] = row[HELD]
    return False

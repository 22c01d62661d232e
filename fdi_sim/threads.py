"""One BLAS thread for the numbers a design is made of, whatever the machine's thread count.

OpenBLAS splits a matrix product or factorization among its threads and sums the pieces in
another order for each thread count, so the same linearization or Riccati solution differs in
its last bits between a process with one BLAS thread and one with two (measured: the DHC-6
default bank's linear model ``A`` and ``C``, the filter's gains and ``Sigma_m^-1``, hence its
design hash and calibration key, all differed between a study's Dask workers, which run with
``OPENBLAS_NUM_THREADS=1``, and ``fdi-sim`` in a shell on a 2-core machine). Every design entry
point (:func:`fdi_sim.linear.linearize.linearize_grid`, :func:`fdi_sim.detectors.gust_kalman.design_gust_kalman`
and ``calibrate``, :func:`fdi_sim.training.build.build_bank`, :func:`fdi_sim.detectors.spec.build_detector`)
and the ``fdi-sim`` command itself run with one BLAS
thread, so a run flown alone designs exactly what it designed inside a study. The matrices are
tens of rows: a second thread bought nothing there.
"""
from __future__ import annotations

import functools
from typing import Any, Callable, TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar("F", bound=Callable[..., Any])


def one_blas_thread() -> threadpool_limits:
    """Context manager: BLAS limited to one thread inside, restored after (``threadpoolctl``)."""
    return threadpool_limits(limits=1, user_api="blas")


def single_blas_thread(fn: F) -> F:
    """Decorator: ``fn`` runs under :func:`one_blas_thread`."""

    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapped  # type: ignore[return-value]

"""One BLAS thread for code that solves many small dense problems.

OpenBLAS runs even a 3 x 3 triangular solve with many right-hand sides (a plane's basis
at its points) or a 150 x 150 eigenproblem on all its threads (as many as the machine has
cores), and its idle threads spin while they wait for the next call. Code that makes tens
of thousands of such calls (the SAR segmentation: a likelihood, a Forward Search, refits
and tests per surface unit) then spends about half of its CPU seconds handing calls over
and spinning, the more so on a machine whose cores are busy with other work.
:func:`single_blas_thread` runs a function with BLAS limited to one thread and restores
the previous limit on return (the Numba kernels' own threads are not affected). The
per-call and whole-command figures are in ``benchmarks/results_sar_speed.json``.
"""

from __future__ import annotations

import functools


def single_blas_thread(func):
    """Decorator: run `func` with the BLAS libraries (OpenBLAS, MKL, BLIS) on one thread.

    Results do not depend on the number of BLAS threads beyond the rounding of the
    reductions a threaded BLAS splits; the limit is process-wide while `func` runs.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper

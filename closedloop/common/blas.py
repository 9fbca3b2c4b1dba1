"""One BLAS thread per process: the project's matrices are small.

A stiffness query makes dozens of LAPACK calls on matrices of a few dozen rows; a
multi-threaded OpenBLAS spends more on waking its threads than on the work (a 27 x 15
least-squares solve: 9 us on one thread, 85 us to milliseconds on two on a loaded 2-core
machine), and sweep workers, one process per core, each with a thread per core,
oversubscribe the machine. The command lines and the sweep worker processes call
:func:`single_threaded_blas`; a Python user can call it too (it applies to the whole
process, numpy's and scipy's BLAS alike).
"""

from __future__ import annotations


def single_threaded_blas() -> None:
    """Limit every BLAS/OpenMP library loaded in this process to one thread."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)

"""The LAPACK routines of the library, SciPy's compiled wrappers without ``scipy.linalg``.

The queries call LAPACK directly on small matrices (SVD ``dgesdd``/``dgesvd``, QR
``dgeqrf`` and with column pivoting ``dgeqp3``, ``dorgqr``, triangular ``dlantr``,
``dtrtri``, ``dtrtrs`` and rank-revealing least squares ``dgelsy``), which numpy does not
expose. ``scipy.linalg.lapack`` re-exports them from the extension module
``scipy.linalg._flapack``, but importing it first runs the package ``scipy.linalg``, which
loads all of SciPy's linear algebra and, through it, numpy's f2py, testing and masked
arrays: a few hundred milliseconds, most of a command line's start-up beyond Pinocchio
and numpy. The extension module itself loads in a few milliseconds, so it is loaded from
its file in SciPy's folder; where that is not possible (SciPy already imported, another
layout of SciPy, a failed load) the routines come from ``scipy.linalg.lapack``. Either
way they are the same compiled functions with the same signatures, each behind a check
that raises ``numpy.linalg.LinAlgError`` for a zero-size array, which LAPACK would refuse
with a message printed on the process's output. :func:`min_norm_solve` is the
minimum-norm least-squares solve of the assembly's Gauss-Newton steps.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np

#: The routines the library calls (``tests/common/test_lapack.py`` checks them against SciPy's).
ROUTINES = ("dgesdd", "dgesvd", "dgeqrf", "dgeqp3", "dorgqr", "dlantr", "dtrtri", "dtrtrs",
            "dgelsy")  # fmt: skip


def _from_file() -> ModuleType | None:
    """``scipy.linalg._flapack`` loaded from its file, without its packages' code."""
    spec = importlib.util.find_spec("scipy")  # a top-level package: found, not imported
    for folder in (spec.submodule_search_locations or []) if spec is not None else []:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = Path(folder, "linalg", "_flapack" + suffix)
            if not path.is_file():
                continue
            try:
                found = importlib.util.spec_from_file_location("scipy.linalg._flapack", path)
                module = importlib.util.module_from_spec(found)
                found.loader.exec_module(module)
            except ImportError:
                return None
            return module if all(hasattr(module, name) for name in ROUTINES) else None
    return None


def _load() -> ModuleType:
    if "scipy.linalg" not in sys.modules:
        module = _from_file()
        if module is not None:
            return module
    from scipy.linalg import lapack

    return lapack


_lapack = _load()


def _refusing_empty(name: str):
    """LAPACK routine ``name`` that raises instead of being handed a zero-size array.

    LAPACK refuses a leading dimension of 0 (an empty matrix): it prints
    ``** On entry to ... had an illegal value`` on the process's output and returns a
    negative ``info``. The callers treat empty matrices themselves (an empty least-squares
    problem, no rows to factor); one that does not gets this error instead of the print.
    """
    routine = getattr(_lapack, name)

    def call(*args, **kwargs):
        for a in args:
            if type(a) is np.ndarray and a.size == 0:
                raise np.linalg.LinAlgError(
                    f"{name} called with an empty array of shape {a.shape} (LAPACK refuses it)"
                )
        return routine(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = routine.__doc__
    return call


#: The compiled routines themselves, for a caller that has checked its arrays' sizes
#: (:func:`closedloop.common.conditioning.svd`): the check costs a tenth of a 6 x 6 SVD.
unchecked = _lapack

dgesdd = _refusing_empty("dgesdd")
dgesvd = _refusing_empty("dgesvd")
dgeqrf = _refusing_empty("dgeqrf")
dgeqp3 = _refusing_empty("dgeqp3")
dorgqr = _refusing_empty("dorgqr")
dlantr = _refusing_empty("dlantr")
dtrtri = _refusing_empty("dtrtri")
dtrtrs = _refusing_empty("dtrtrs")
dgelsy = _refusing_empty("dgelsy")


def min_norm_solve(A: np.ndarray, b: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """Minimum-norm least-squares solution x (n,) of A x = b, A (m, n), b (m,).

    LAPACK ``dgelsy``: QR with column pivoting, the effective rank being the largest
    leading block of R whose estimated condition number stays below 1 / ``rcond``, then a
    complete orthogonal decomposition. Same answer as ``numpy.linalg.lstsq`` (an SVD) up
    to rounding when the rank decision agrees, and several times faster on small matrices.
    No row (no closure) or no column: x = 0, without LAPACK (which refuses empty arrays).
    """
    m, n = A.shape
    if m == 0 or n == 0:
        return np.zeros(n)
    if m >= n:
        rhs = b  # dgelsy works on a copy
    else:
        rhs = np.zeros(n)
        rhs[:m] = b
    a = np.array(A, dtype=float, order="F")  # overwritten by dgelsy
    _, x, _, _, info = dgelsy(
        a, rhs, np.zeros(n, dtype=np.int32), rcond, overwrite_a=1,
        lwork=max(min(m, n) + 3 * n + 1, 2 * min(m, n) + 1),
    )  # fmt: skip
    if info != 0:
        raise np.linalg.LinAlgError(f"dgelsy failed (info={info})")
    return x[:n]

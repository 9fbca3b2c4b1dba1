"""closedloop.common.lapack: SciPy's compiled LAPACK wrappers loaded without ``scipy.linalg``, the
same routines as ``scipy.linalg.lapack``, and the fall-back to it."""

import importlib.machinery
import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg.lapack

from closedloop.common import lapack


def test_the_routines_are_scipys_with_the_same_signatures_and_results():
    rng = np.random.default_rng(3)
    A, b = rng.standard_normal((7, 5)), rng.standard_normal(7)
    fresh = lapack._from_file()  # the file load, although scipy.linalg is imported here
    assert fresh is not None
    for module in (lapack, fresh):
        for name in lapack.ROUTINES:
            assert getattr(module, name).__doc__ == getattr(scipy.linalg.lapack, name).__doc__
        # the same compiled code: equal to the last bit
        for got, expected in zip(module.dgesdd(A), scipy.linalg.lapack.dgesdd(A), strict=True):
            np.testing.assert_array_equal(got, expected)
        got, expected = (  # the pivots jpvt are overwritten: a new array each call
            f(A.copy(order="F"), b.copy(), np.zeros(5, dtype=np.int32), 1e-12, 64)
            for f in (module.dgelsy, scipy.linalg.lapack.dgelsy)
        )
        np.testing.assert_array_equal(got[1], expected[1])


def fresh_interpreter(statement: str) -> list[str]:
    """What ``statement`` and then importing closedloop.common.lapack print: the name of the
    module the routines come from, and whether scipy.linalg is imported."""
    code = (f"import sys; {statement}; from closedloop.common import lapack; "
            "print(lapack._lapack.__name__, 'scipy.linalg' in sys.modules)")  # fmt: skip
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120).stdout.split()  # fmt: skip


def test_a_fresh_interpreter_loads_the_extension_alone():
    assert fresh_interpreter("pass") == ["scipy.linalg._flapack", "False"]


def test_without_the_file_scipy_linalg_is_imported():
    hide = (
        "import importlib.util as u; find = u.find_spec; "
        "u.find_spec = lambda name, *a: None if name == 'scipy' else find(name, *a)"
    )
    assert fresh_interpreter(hide) == ["scipy.linalg.lapack", "True"]


def test_scipy_linalg_already_imported_is_used_as_it_is(monkeypatch):
    monkeypatch.setattr(lapack, "_from_file", lambda: 1 / 0)  # must not be called
    assert lapack._load() is scipy.linalg.lapack


def test_a_broken_or_missing_file_is_not_loaded(tmp_path, monkeypatch):
    (tmp_path / "linalg").mkdir()
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    (tmp_path / "linalg" / f"_flapack{suffix}").write_bytes(b"not a shared library")
    fake = importlib.machinery.ModuleSpec("scipy", None, is_package=True)
    fake.submodule_search_locations = [str(tmp_path)]
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: fake)
    assert lapack._from_file() is None  # the ImportError of the load: the fall-back
    (tmp_path / "linalg" / f"_flapack{suffix}").unlink()
    assert lapack._from_file() is None  # no such file


def test_single_threaded_blas_reaches_the_blas_of_these_routines():
    """The extension's OpenBLAS, loaded with it, is among those limited to one thread."""
    code = (
        "import json; from closedloop.common import lapack; from closedloop.common.blas import "
        "single_threaded_blas; single_threaded_blas(); from threadpoolctl import "
        "threadpool_info; print(json.dumps(threadpool_info()))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)  # fmt: skip
    blas = [i for i in json.loads(done.stdout) if i["user_api"] == "blas"]
    assert any("scipy" in i["filepath"] for i in blas)
    assert all(i["num_threads"] == 1 for i in blas)


#: A call of each routine with a zero-size matrix (LAPACK's own check refuses them all,
#: printing "** On entry to ... had an illegal value" on the process's output).
EMPTY_CALLS = {
    "dgesdd": lambda: lapack.dgesdd(np.zeros((0, 3))),
    "dgesvd": lambda: lapack.dgesvd(np.zeros((3, 0))),
    "dgeqrf": lambda: lapack.dgeqrf(np.zeros((0, 3))),
    "dgeqp3": lambda: lapack.dgeqp3(np.zeros((0, 0))),
    "dorgqr": lambda: lapack.dorgqr(np.zeros((0, 0)), np.zeros(0)),
    "dlantr": lambda: lapack.dlantr(b"1", np.zeros((0, 0))),
    "dtrtri": lambda: lapack.dtrtri(np.zeros((0, 0))),
    "dtrtrs": lambda: lapack.dtrtrs(np.zeros((0, 0)), np.zeros((0, 2))),
    "dgelsy": lambda: lapack.dgelsy(np.zeros((0, 3), order="F"), np.zeros(3),
                                    np.zeros(3, dtype=np.int32), 1e-12, lwork=16),
}  # fmt: skip


def test_every_routine_is_listed_with_an_empty_call():
    assert sorted(EMPTY_CALLS) == sorted(lapack.ROUTINES)


@pytest.mark.parametrize("name", sorted(EMPTY_CALLS))
def test_an_empty_matrix_never_reaches_lapack(capfd, name):
    """An empty matrix is refused before LAPACK, which would print its complaint on the
    process's output (a four-bar without loops showed ``** On entry to DGELSY parameter
    number 5 had an illegal value`` before a failure)."""
    with pytest.raises(np.linalg.LinAlgError, match=rf"^{name} called with an empty array"):
        EMPTY_CALLS[name]()
    assert capfd.readouterr() == ("", "")

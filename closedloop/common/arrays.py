"""Small array helpers shared by the packages: read-only copies and input checks."""

from __future__ import annotations

import math
import re
import sys

import numpy as np

from closedloop.exceptions import InvalidInputError


def readonly(a) -> np.ndarray:
    """Read-only float copy of ``a``."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only in place (for an array the caller has just created)."""
    a.setflags(False)  # write=False: positional, half the cost of the keyword (a third
    # of setting a.flags.writeable)
    return a


class ReadOnlyArrays:
    """Base of the result classes whose arrays are read-only: an unpickled copy keeps
    them read-only (numpy unpickles writable arrays), arrays in dict fields included.

    A field declared :class:`OnFirstRead` may be held as the function that computes it
    (in the dict ``_on_first_read`` of the instance, field name -> (function, arguments...)),
    which is called on its first read; a pickled (or copied) result carries the computed
    values.
    """

    def __getstate__(self) -> dict:
        state = self.__dict__
        if "_on_first_read" in state:  # each field computed, as a reader would see it
            state = {k: v for k, v in state.items() if k != "_on_first_read"}
            for name in self.__dict__["_on_first_read"]:
                state[name] = getattr(self, name)
        return state

    def __setstate__(self, state: dict) -> None:
        for value in state.values():
            for a in value.values() if isinstance(value, dict) else (value,):
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False
        self.__dict__.update(state)


class OnFirstRead:
    """A field of a (frozen) :class:`ReadOnlyArrays` dataclass that an instance may compute
    on its first read (set on the class after the dataclass is made:
    ``Result.K = OnFirstRead("K")``).

    An instance made with the field's value holds it as any field; one made without it
    holds, in its dict ``_on_first_read``, a tuple (function, arguments...) whose call
    returns the value (read-only, the same bits at every call: the computation it saved).
    The first read calls it and keeps the value; every later read, in any thread, returns
    that same array. Two threads reading it first at once may both call the function: the
    first value kept is the one both return.
    """

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        fields = instance.__dict__
        try:
            compute, *args = fields["_on_first_read"][self.name]
        except KeyError:
            raise AttributeError(self.name) from None
        return fields.setdefault(self.name, compute(*args))


#: A number as text: ASCII digits with an optional sign, decimal point and exponent
#: (``-1e5``, ``.5``, ``2.``), or ``inf``, ``infinity``, ``nan`` in any case.
DECIMAL = re.compile(r"[-+]?((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|infinity|nan)", re.ASCII | re.I)


def decimal(text: str) -> float:
    """The number written in ``text`` (:data:`DECIMAL`), which must be all of it.

    Python's ``float`` also reads digits grouped by ``_`` (``0_3`` is 3.0), the digits of
    other scripts (Arabic-Indic, full-width) and surrounding white space, and reads a
    number beyond the double range (``1e999``) as infinity; a typo or a pasted character
    must not pass for a number, nor an overflow for ``inf`` (a locked joint), so these are
    refused.

    Raises:
        ValueError: ``text`` is not such a number (as ``float`` raises), or is beyond the
            double range without saying ``inf`` (:func:`overflowing`).
    """
    if not DECIMAL.fullmatch(text):
        raise ValueError(f"{text!r} is not a decimal number")
    if overflowing(text):
        raise ValueError(
            f"{text!r} is beyond the floating point range (about 1.8e308); expected a "
            "finite number, or inf"
        )
    return float(text)


def overflowing(text: str) -> bool:
    """True when ``text``, a number written as a string, is beyond the double range (it
    reads as infinity without saying ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        return False
    return math.isinf(value) and "inf" not in text.lower()


def real_number(value) -> float:
    """``value`` as a float: a real number (Python's or numpy's int or float, a 0-d
    array of them; not a bool: ``True`` is not 1) or a string in ASCII decimal notation
    (:func:`decimal`; YAML 1.1 reads ``1e5`` as a string), spaces around it ignored.

    Raises:
        ValueError: a string that is not such a number, or an overflowing one.
        TypeError: a bool (Python's or numpy's) or another object.
    """
    if isinstance(value, str):
        return decimal(value.strip())
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, bool | np.bool_) or not isinstance(
        value, int | float | np.integer | np.floating
    ):
        raise TypeError(f"{value!r} is a {type(value).__name__}, not a number")
    try:
        return float(value)
    except OverflowError:  # an int beyond the float range
        digits = str(value)
        raise ValueError(
            f"{digits[:20]}{'...' if len(digits) > 20 else ''} is beyond the floating point "
            "range (about 1.8e308)"
        ) from None


def decimals(text: str) -> np.ndarray:
    """(n,) the numbers written in ``text``, separated by white space, each
    :func:`decimal` (as a file's ``"0 0.1 -2e-3"``).

    Raises:
        ValueError: a word of ``text`` is not such a number.
    """
    return np.array([decimal(word) for word in text.split()], dtype=float)


def real_array(value, name: str) -> np.ndarray:
    """``value`` as a float array, refusing what is not real numbers.

    Args:
        value: a number or a (nested) sequence or array of numbers (ints, floats).
        name: the argument, named by the error message.

    Raises:
        InvalidInputError: booleans (``True`` is not 1 rad), also among numbers in a
            sequence (``[1.0, True]``, which numpy would cast to ``[1.0, 1.0]``), strings,
            complex numbers (their imaginary part would be dropped), ``None`` or other
            objects, ragged sequences, a masked array with masked entries (numpy would hand
            over the values hidden under the mask).
    """
    if "numpy.ma" in sys.modules and np.ma.is_masked(value):  # (no masked array without it)
        raise InvalidInputError(
            f"{name} has masked entries at {np.flatnonzero(np.ma.getmaskarray(value)).tolist()}"
            " (flat indices); expected every value given (fill or drop them first)"
        )
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        a = None
    if a is None:
        kind = f"ragged {type(value).__name__}"
    elif a.dtype.kind not in "iuf":
        kind = {"b": "bool", "c": "complex"}.get(a.dtype.kind, type(value).__name__)
    elif not isinstance(value, np.ndarray) and any(
        isinstance(x, bool | np.bool_) for x in np.asarray(value, dtype=object).flat
    ):  # a bool among numbers in a sequence, which numpy casts to a number
        kind = "bool"
    else:
        return a.astype(float)
    text = " ".join(repr(value).split())
    text = text if len(text) <= 80 else text[:77] + "..."
    raise InvalidInputError(f"{name} must be real numbers, got {text} ({kind})")


def _shown(value) -> str:
    return repr(value.item() if isinstance(value, np.generic) else value)


def check_positive(name: str, value, unit: str, *, allow_inf: bool = False) -> None:
    """Refuse a solver option that is not a real number > 0 (finite unless ``allow_inf``;
    NaN and bools refused) with an InvalidInputError naming it, its unit and the value."""
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    if ok:
        try:
            x = float(value)
        except OverflowError:  # an int beyond the float range
            x = math.inf
    if not (ok and x > 0 and (allow_inf or math.isfinite(x))):
        kind = "> 0 (inf allowed)" if allow_inf else "finite and > 0"
        raise InvalidInputError(f"{name} must be a number {kind} [{unit}], got {_shown(value)}")


def check_count(name: str, value, least: int) -> None:
    """Refuse an option that is not an integer >= ``least`` (InvalidInputError)."""
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if not (ok and value >= least):
        raise InvalidInputError(f"{name} must be an integer >= {least}, got {_shown(value)}")


def check_wrench(w, name: str = "wrench") -> np.ndarray:
    """(6,) validated wrench (fx, fy, fz [N], nx, ny, nz [N m]); raises InvalidInputError
    naming the argument ``name``."""
    w = real_array(w, name).reshape(-1)
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise InvalidInputError(
            f"{name} must be 6 finite values (fx fy fz [N], nx ny nz [N m]), got {w.tolist()}"
        )
    return w


def symmetrized(K: np.ndarray, rtol: float, what: str, expected: str) -> np.ndarray:
    """(K + K^T) / 2 of a square matrix K whose asymmetry max|K - K^T| is at most ``rtol``
    times max|K|, else an InvalidInputError: "``what`` is not symmetric (...); expected
    ``expected``"."""
    scale, skew = np.max(np.abs(K)), np.max(np.abs(K - K.T))
    if skew > rtol * scale:
        raise InvalidInputError(
            f"{what} is not symmetric (max |K - K^T| = {skew:.3g}, max |K| = {scale:.3g}); "
            f"expected {expected}"
        )
    return 0.5 * (K + K.T)


def upper_triangular_inverses(R: np.ndarray) -> np.ndarray:
    """(n, p, p) inverses of the upper triangular matrices R (n, p, p) (the entries below
    the diagonal are not read).

    Back substitution a row at a time for the whole stack, X[i, i] = 1 / R[i, i] and
    X[i, j] = -R[i, i+1:] X[i+1:, j] / R[i, i] (j > i): about half the time of
    ``numpy.linalg.inv``'s LU of each matrix on CaHyMan's 16 x 16 blocks, to rounding the
    same (both are backward stable). A zero on a diagonal gives inf or NaN, never an
    error: callers test the diagonal.
    """
    p = R.shape[1]
    X = np.zeros(R.shape)
    d = 1.0 / np.diagonal(R, axis1=1, axis2=2)  # (n, p)
    for i in range(p - 1, -1, -1):
        X[:, i, i] = d[:, i]
        if i + 1 < p:
            X[:, i, i + 1 :] = (R[:, None, i, i + 1 :] @ X[:, i + 1 :, i + 1 :])[:, 0]
            X[:, i, i + 1 :] *= -d[:, i, None]
    return X

"""Assembly: solve the passive coordinates so that every loop closure holds."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import lapack
from .arrays import ReadOnlyArrays, check_count, check_positive, frozen, real_array
from .exceptions import AssemblyError, InvalidInputError
from .kinematics import jacobian_rows, residual_rows
from .model import ClosedLoopModel

#: Default closure tolerance: infinity norm of the residual with its rows in metres divided
#: by the model's characteristic length L (radians as they are), unit-free like
#: :data:`closedloop.configuration.CLOSURE_TOL`: 1e-12 L for a point closure, whatever the
#: size of the mechanism (an absolute 1e-12 m is 3e-3 of the size of a nanometre one).
ASSEMBLY_TOL = 1e-12


@dataclass(frozen=True)
class Assembly(ReadOnlyArrays):
    """An assembled configuration.

    Attributes:
        q: (nq,) configuration (read-only) satisfying every closure.
        residual: infinity norm of the closure residual [m, rad] (unscaled).
        iterations: Gauss-Newton iterations used.
        closure: when asked for (``jacobian=True``), the closure residuals (m,) [m; m, rad]
            and their Jacobian (m, nv) at q (:func:`closedloop.kinematics.closure_residual`
            and :func:`closedloop.kinematics.closure_jacobian`), read-only, computed from
            the kinematics of the last iteration: a stacked query of many assembled
            configurations takes them instead of evaluating the constraints again;
            otherwise None.
    """

    q: np.ndarray
    residual: float
    iterations: int
    closure: tuple[np.ndarray, np.ndarray] | None = None


def free_coordinates(clm: ClosedLoopModel) -> np.ndarray:
    """Tangent indices solved by assembly: the passive ones (zero stiffness)."""
    return np.flatnonzero(clm.stiffness == 0.0)


def min_norm_solve(A: np.ndarray, b: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """Minimum-norm least-squares solution x (n,) of A x = b, A (m, n), b (m,).

    LAPACK ``dgelsy``: QR with column pivoting, the effective rank being the largest
    leading block of R whose estimated condition number stays below 1 / ``rcond``, then a
    complete orthogonal decomposition. Same answer as ``numpy.linalg.lstsq`` (an SVD) up
    to rounding when the rank decision agrees, and several times faster on small matrices.
    """
    m, n = A.shape
    if m >= n:
        rhs = b  # dgelsy works on a copy
    else:
        rhs = np.zeros(n)
        rhs[:m] = b
    a = np.array(A, dtype=float, order="F")  # overwritten by dgelsy
    _, x, _, _, info = lapack.dgelsy(
        a, rhs, np.zeros(n, dtype=np.int32), rcond, overwrite_a=1,
        lwork=max(min(m, n) + 3 * n + 1, 2 * min(m, n) + 1),
    )  # fmt: skip
    if info != 0:
        raise np.linalg.LinAlgError(f"dgelsy failed (info={info})")
    return x[:n]


def _row_tolerances(clm: ClosedLoopModel, tol: float) -> tuple[np.ndarray | float, float, float]:
    """(tolerance of each residual row [m, rad] (one number when every row is in
    metres), its smallest and its largest value) of the scaled tolerance ``tol``."""
    L = clm.length
    if clm.memo("metre_rows", clm.linear_rows.all):
        return tol * L, tol * L, tol * L
    rows = np.where(clm.linear_rows, tol * L, tol)
    return rows, float(rows.min(initial=tol)), float(rows.max(initial=tol))


def _residual(clm: ClosedLoopModel, data, datas, q: np.ndarray, tols) -> tuple:
    """Closure residual r (m,) at q, its squared 2-norm and whether each row is within
    its tolerance (``tols``: :func:`_row_tolerances`); leaves the joint placements and
    Jacobians of q in ``data`` (what the constraints and their Jacobians read; the frame
    placements are not updated)."""
    pin.computeJointJacobians(clm.model, data, q)
    r = residual_rows(clm, data, datas)
    size2 = float(r.dot(r))
    rows, low, high = tols
    # |r|_inf <= |r|_2 <= sqrt(m) |r|_inf: the rows one by one only when these leave it open
    if size2 <= low * low:
        return r, size2, True
    if size2 > r.size * high * high or size2 != size2:  # NaN: not closed
        return r, size2, False
    return r, size2, bool((abs(r) <= rows).all())


def assemble(
    clm: ClosedLoopModel,
    actuated: np.ndarray | None = None,
    q0: np.ndarray | None = None,
    *,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 50,
    jacobian: bool = False,
) -> Assembly:
    """Close every loop by moving the passive coordinates only.

    Actuated coordinates are set to ``actuated``; spring and locked coordinates keep the
    values they have in ``q0`` (their rest values). The passive coordinates are found by
    :func:`close_loops`.

    Args:
        clm: the model.
        actuated: (n_act,) values of the actuated coordinates [rad or m], in the order of
            ``clm.actuated``; ``None`` keeps those of ``q0``.
        q0: (nq,) start configuration, which picks the assembly branch (default: neutral).
        tol: closure tolerance, > 0: infinity norm of the residual with its rows in metres
            divided by the model's length L (radians as they are; :data:`ASSEMBLY_TOL`).
        max_iter: iteration limit (an integer >= 0; 0 only checks the start).
        jacobian: also return the closure residuals and Jacobian at the solution
            (:attr:`Assembly.closure`).

    Raises:
        AssemblyError: the closures cannot be satisfied from this start (unreachable
            input); the message gives the residual reached.
        InvalidInputError: bad ``actuated``, ``q0``, ``tol`` or ``max_iter``.
    """
    check_positive("tol", tol, "metres / L, rad")
    check_count("max_iter", max_iter, 0)
    q = clm.check_configuration(pin.neutral(clm.model) if q0 is None else q0)
    if actuated is not None:
        clm.set_actuated(q, check_actuated(clm, actuated))
    return close_loops(clm, q, tol=tol, max_iter=max_iter, jacobian=jacobian)


def check_actuated(clm: ClosedLoopModel, actuated) -> np.ndarray:
    """Validated actuated values (n_act,) [rad, m] of ``clm``'s actuated joints.

    Raises:
        InvalidInputError: not real numbers, a wrong count, or not finite.
    """
    if not (type(actuated) is np.ndarray and actuated.dtype == np.float64):
        actuated = real_array(actuated, "actuated")
    actuated = actuated.reshape(-1)
    if actuated.shape != (len(clm.actuated),):
        raise InvalidInputError(
            f"{actuated.size} actuated values given; expected {len(clm.actuated)} "
            f"for joints {list(clm.actuated)}"
        )
    if not np.isfinite(actuated).all():
        raise InvalidInputError(f"actuated values must be finite, got {actuated.tolist()}")
    return actuated


def close_loops(
    clm: ClosedLoopModel,
    q: np.ndarray,
    *,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 50,
    jacobian: bool = False,
) -> Assembly:
    """The loop of :func:`assemble` from a start that its caller has validated.

    Gauss-Newton on the stacked closure residual, moving the passive coordinates only,
    each step a minimum-norm least-squares solve (:func:`min_norm_solve`, rank revealing:
    redundant closure rows are harmless), with backtracking when a step does not reduce
    the residual.

    Args:
        clm: the model.
        q: (nq,) start: a float array of the model's size, finite, quaternions normalised
            (:meth:`ClosedLoopModel.check_configuration`), the actuated values written; the
            caller hands it over (it may be modified, and is made read-only when returned).
        tol, max_iter: as :func:`assemble`.
        jacobian: also return the closure residuals and Jacobian at the solution
            (:attr:`Assembly.closure`).

    Raises:
        AssemblyError: as :func:`assemble`.
    """
    model = clm.model
    free = clm.memo("free_coordinates", lambda: free_coordinates(clm))
    data, datas = clm.workspace()
    tols = _row_tolerances(clm, tol)
    r, size2, closed = _residual(clm, data, datas, q, tols)
    if not closed and not free.size:
        raise AssemblyError(
            f"cannot close the loops of {clm.name!r}: no passive coordinate to move (every "
            "joint is actuated, sprung or locked); give the loops passive joints",
            _inf_norm(r),
        )
    it = 0
    while not closed and it < max_iter and size2 == size2:
        it += 1
        # the kinematics and constraint datas of q are those of its residual evaluation
        step = np.zeros(model.nv)
        step[free] = -min_norm_solve(jacobian_rows(clm, data, datas, calc=False)[:, free], r)
        for _ in range(30):
            q_try = pin.integrate(model, q, step)
            r_try, size2_try, closed_try = _residual(clm, data, datas, q_try, tols)
            if size2_try < size2 or closed_try:
                break
            step *= 0.5
        else:
            break
        q, r, size2, closed = q_try, r_try, size2_try, closed_try
    err = _inf_norm(r)
    if not closed:
        k, names = clm.stiffness, clm.model.names  # held: a joint with a spring or locked
        held = [names[j] for j in range(1, len(names)) if names[j] not in clm.actuated
                and np.any(k[clm.joint_v_slice(names[j])] != 0.0)]  # fmt: skip
        raise AssemblyError(
            f"cannot close the loops of {clm.name!r} with actuated "
            f"{dict(zip(clm.actuated, clm.actuated_values(q).tolist(), strict=True))}"
            + (f" (the joints with springs or locked, {held}, keep their start values: "
               "a loop that needs them to move cannot close)" if held else ""),
            err,
        )  # fmt: skip
    q.flags.writeable = False
    closure = None
    if jacobian:  # the datas are those of q's residual evaluation, the last one
        closure = (frozen(r), frozen(jacobian_rows(clm, data, datas, calc=False)))
    result = object.__new__(Assembly)  # every field checked here: without the frozen __init__
    result.__dict__.update(q=q, residual=err, iterations=it, closure=closure)
    return result


def _inf_norm(r: np.ndarray) -> float:
    """Infinity norm of r (m,) (0 for no row; NaN propagates)."""
    return float(abs(r).max()) if r.size else 0.0

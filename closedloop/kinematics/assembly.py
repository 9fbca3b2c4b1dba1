"""Assembly: solve the passive coordinates so that every loop closure holds."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common import lapack
from closedloop.common.arrays import ReadOnlyArrays, check_count, check_positive, frozen, real_array
from closedloop.common.conditioning import rule_rank, svd
from closedloop.common.lapack import min_norm_solve
from closedloop.exceptions import AssemblyError, InvalidInputError, SingularConfigurationError
from closedloop.kinematics.configuration import CLOSURE_TOL
from closedloop.kinematics.constraints import flipped_closures, jacobian_rows, residual_rows
from closedloop.model.closed_loop import ClosedLoopModel

#: Default closure tolerance: infinity norm of the residual with its rows in metres divided
#: by the model's characteristic length L (radians as they are), unit-free like
#: :data:`closedloop.kinematics.configuration.CLOSURE_TOL`: 1e-12 L for a point closure, whatever
#: the size of the mechanism (an absolute 1e-12 m is 3e-3 of the size of a nanometre one).
ASSEMBLY_TOL = 1e-12
#: Step of a sweep: the largest change of an actuated value per step of
#: :func:`closedloop.kinematics.driving.assemble_connected` [rad, and lengths in units of the
# model's  characteristic length L]; :func:`close_loops` follows the branch of a start's origin to
#: first order up to twice as far (a step of INPUT_STEP whatever its rounding).
INPUT_STEP = 0.05
#: A closed configuration whose scaled passive Jacobian has a singular value below
#: POLISH_FACTOR sqrt(tol) times its largest is iterated past the tolerance: at a distance t
#: from a singular configuration that value is about c t (c ~ 1, the curvature of the
#: closures) and the residual c t^2 / 2, so the tolerance alone admits poses up to
#: sqrt(2 tol) from the singular one, where the rank rule would not see the rank drop.
POLISH_FACTOR = 100.0
#: Most Gauss-Newton iterations past the tolerance (towards a singular solution they gain
#: about a factor 2 each: from 1e-6 to the rounding, 1e-8, in about 10).
POLISH_ITER = 40
#: Step [rad, or lengths per L] of the central second difference along a passive
#: direction that the closure rows do not see to first order (the check that a closed
#: configuration is not a singular one, :func:`close_loops`).
CURVATURE_STEP = 1e-4
#: Scaled curvature of the closures along such a direction, outside the range of the
#: passive Jacobian, relative to its largest singular value, above which the direction is
#: not a motion: a singular configuration. An idle motion (a rod turning about its axis)
#: gives the rounding over CURVATURE_STEP^2 and fourth-order terms, about 1e-8; the
#: collinear four-bar about 1.
CURVATURE_RTOL = 1e-6


@dataclass(frozen=True)
class Assembly(ReadOnlyArrays):
    """An assembled configuration.

    Attributes:
        q: (nq,) configuration (read-only) satisfying every closure.
        residual: infinity norm of the closure residual [m, rad] (unscaled).
        iterations: Gauss-Newton iterations of the last solve (of a driven assembly, its
            last step).
        closure: when asked for (``jacobian=True``), the closure residuals (m,) [m; m, rad]
            and their Jacobian (m, nv) at q
            (:func:`closedloop.kinematics.constraints.closure_residual` and
            :func:`closedloop.kinematics.constraints.closure_jacobian`), read-only, computed from
            the kinematics of the last iteration: a stacked query of many assembled configurations
            takes them instead of evaluating the constraints again; otherwise None.
    """

    q: np.ndarray
    residual: float
    iterations: int
    closure: tuple[np.ndarray, np.ndarray] | None = None


def free_coordinates(clm: ClosedLoopModel) -> np.ndarray:
    """Tangent indices solved by assembly: the passive ones (zero stiffness)."""
    return np.flatnonzero(clm.stiffness == 0.0)


def coordinate_scale(clm: ClosedLoopModel) -> np.ndarray:
    """(nv,) the unit of each tangent coordinate in :data:`INPUT_STEP`: L [m] for a
    length, 1 for an angle (once per model)."""
    return clm.memo("coordinate_scale", lambda: np.where(clm.linear_coordinates, clm.length, 1.0))


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
    return (r, *within(r, tols))


def within(r: np.ndarray, tols) -> tuple[float, bool]:
    """(squared 2-norm of the residual r (m,), whether each row is within its tolerance)
    (``tols``: (tolerance of each row or one for all, the smallest, the largest))."""
    size2 = float(r.dot(r))
    rows, low, high = tols
    # |r|_inf <= |r|_2 <= sqrt(m) |r|_inf: the rows one by one only when these leave it open
    if size2 <= low * low:
        return size2, True
    if size2 > r.size * high * high or size2 != size2:  # NaN: not closed
        return size2, False
    return size2, bool((abs(r) <= rows).all())


def assemble(
    clm: ClosedLoopModel,
    actuated: np.ndarray | None = None,
    q0: np.ndarray | None = None,
    *,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 50,
    jacobian: bool = False,
) -> Assembly:
    """Close every loop by moving the passive coordinates only, on the assembly mode
    continuous from a start.

    The start is ``q0``, by default the model's reference configuration
    (:meth:`ClosedLoopModel.reference_configuration`), as for the command line, the maps
    and the identification. The actuated values are driven from the start's to
    ``actuated`` in steps of at most :data:`INPUT_STEP`, each closed from the last
    (:func:`drive`), not reached in one solve, which may land on another mode (the bundled
    four-bar at crank 1.0 rad solved at once from neutral: rocker -3.17 rad, the lower
    mode; driven from its start on the upper mode: 0.52 rad). Where a step cannot be
    closed (the start's mode ends on the way, at a singular configuration), the one solve
    from the start is taken. :func:`closedloop.assembly_modes` lists the modes found.
    Spring and locked coordinates keep their start values (their rest values); so do
    passive coordinates that no closure row moves (a serial chain has its actuated values
    set, and nothing else; a query at a frame they move reports a mechanism).

    Args:
        clm: the model.
        actuated: (n_act,) values of the actuated coordinates [rad or m], in the order of
            ``clm.actuated``; ``None`` keeps those of the start.
        q0: (nq,) start configuration, which picks the assembly mode (default: the
            reference configuration); a sweep passes the last configuration assembled.
        tol: closure tolerance, > 0: infinity norm of the residual with its rows in metres
            divided by the model's length L (radians as they are; :data:`ASSEMBLY_TOL`).
        max_iter: iteration limit of a solve (an integer >= 0; 0 only checks the start,
            its actuated values written).
        jacobian: also return the closure residuals and Jacobian at the solution
            (:attr:`Assembly.closure`).

    Raises:
        AssemblyError: the closures cannot be satisfied from this start (unreachable
            input; joints with springs whose start values do not let the loops close), or
            close only with the z axes of a revolute or cylindrical closure opposite; the
            message gives the residual reached.
        SingularConfigurationError: the closures are met at a singular configuration of
            the assembly, where its branches meet: the passive coordinates are not
            determined there (:func:`close_loops`).
        InvalidInputError: bad ``actuated``, ``q0``, ``tol`` or ``max_iter``.
    """
    check_positive("tol", tol, "metres / L, rad")
    check_count("max_iter", max_iter, 0)
    q = clm.check_configuration(clm.reference_configuration() if q0 is None else q0)
    target = None if actuated is None else check_actuated(clm, actuated)
    return drive(clm, q, target, tol=tol, max_iter=max_iter, jacobian=jacobian)


#: Most steps of :func:`drive` (a longer way takes longer steps).
MAX_INPUT_STEPS = 1000


def input_scale(clm: ClosedLoopModel) -> np.ndarray:
    """(n_act,) the unit of each actuated value in :data:`INPUT_STEP` (the largest change
    of an actuated value per step of :func:`drive`): L [m] for a length, 1 for an angle
    (once per model)."""
    return clm.memo("input_scale", lambda: coordinate_scale(clm)[clm.actuated_v_indices])


def drive(
    clm: ClosedLoopModel,
    q: np.ndarray,
    target: np.ndarray | None,
    *,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 50,
    jacobian: bool = False,
    check=None,
) -> Assembly:
    """The continuation of :func:`assemble` from a start q (nq,) that its caller has
    validated (not modified) to the checked actuated values ``target`` (n_act,) [rad, m]
    (None: q's own), in at most :data:`MAX_INPUT_STEPS` steps, each closed from the last
    by :func:`close_at`; where one fails, the one solve from q. ``check(q)`` (the
    joints' limits: :func:`closedloop.kinematics.driving.assemble_connected`) is called on
    each step's start, its actuated values written, and raises InvalidInputError to
    refuse it: on the way, the one solve from q is then taken; at the target, it is raised.
    """
    start = clm.actuated_values(q)
    target = start if target is None else target
    with np.errstate(over="ignore"):  # inputs near the float range: one step, refused there
        steps = float(np.max(np.abs(target - start) / input_scale(clm), initial=0)) / INPUT_STEP
    n = min(MAX_INPUT_STEPS, math.ceil(steps)) if math.isfinite(steps) and max_iter else 1
    path = q
    try:
        for k in range(1, n):
            path = close_at(clm, path, start + k / n * (target - start), tol=tol,
                            max_iter=max_iter, check=check).q  # fmt: skip
    except (AssemblyError, InvalidInputError, SingularConfigurationError):
        path = q
    return close_at(clm, path, target, tol=tol, max_iter=max_iter, jacobian=jacobian, check=check)


def close_at(
    clm: ClosedLoopModel,
    origin: np.ndarray,
    actuated: np.ndarray,
    *,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 50,
    jacobian: bool = False,
    check=None,
) -> Assembly:
    """One solve (:func:`close_loops`) from ``origin`` (nq,), validated (not modified),
    with its actuated values set to ``actuated`` (n_act,) [rad, m], checked: from a closed
    origin a step of at most 2 :data:`INPUT_STEP` follows its branch to first order.
    ``check`` as for :func:`drive`."""
    q = origin.copy()
    clm.set_actuated(q, actuated)
    if check is not None:
        check(q)
    return close_loops(clm, q, tol=tol, max_iter=max_iter, jacobian=jacobian, origin=origin)


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
    origin: np.ndarray | None = None,
) -> Assembly:
    """The loop of :func:`assemble` from a start that its caller has validated.

    Gauss-Newton on the stacked closure residual, moving the passive coordinates only,
    each step a minimum-norm least-squares solve (:func:`min_norm_solve`, rank revealing:
    redundant closure rows are harmless), with backtracking when a step does not reduce
    the residual.

    Near a singular configuration the first step from a start whose inputs have just
    moved is large (the residual holds the second-order terms of the input step) and
    may land on another branch (the parallelogram four-bar 0.1 rad from its change point,
    the crank moved 0.05 rad towards it). With an ``origin`` at most 2 :data:`INPUT_STEP`
    away, the first step is instead the first-order continuation of the origin's branch
    (an origin where branches meet picks none). A closed configuration is then checked
    not to be a singular one (at
    the change point the tolerance admitted poses up to 2.6e-6 rad from it, each with its
    own compliance; it is a SingularConfigurationError instead).

    Args:
        clm: the model.
        q: (nq,) start: a float array of the model's size, finite, quaternions normalised
            (:meth:`ClosedLoopModel.check_configuration`), the actuated values written; the
            caller hands it over (it may be modified, and is made read-only when returned).
        tol, max_iter: as :func:`assemble`.
        jacobian: also return the closure residuals and Jacobian at the solution
            (:attr:`Assembly.closure`).
        origin: (nq,) the configuration q was made from by writing the actuated (and
            held) values, validated as q, or None; used when it closes the loops to
            :data:`closedloop.kinematics.configuration.CLOSURE_TOL`, q is at most
            2 :data:`INPUT_STEP` from it and the continuation closes the loops better than
            q (the first iteration then), else ignored.

    Raises:
        AssemblyError, SingularConfigurationError: as :func:`assemble`.
    """
    free = clm.memo("free_coordinates", lambda: free_coordinates(clm))
    data, datas = clm.workspace()
    tols = _row_tolerances(clm, tol)
    guess = None
    if origin is not None and max_iter > 0 and free.size:
        guess = _continued(clm, origin, q, free)
    r, size2, closed = _residual(clm, data, datas, q, tols)
    if not closed and not free.size:
        raise AssemblyError(
            f"cannot close the loops of {clm.name!r}: no passive coordinate to move (every "
            "joint is actuated, sprung or locked); give the loops passive joints",
            _inf_norm(r),
        )
    it = 0
    if guess is not None and not closed:
        r_g, size2_g, closed_g = _residual(clm, data, datas, guess, tols)
        if size2_g < size2 or closed_g:
            it, q, r, size2, closed = 1, guess, r_g, size2_g, closed_g
        else:  # the kinematics of q back in the workspace, for its Jacobian
            r, size2, closed = _residual(clm, data, datas, q, tols)
    while not closed and it < max_iter and size2 == size2:
        it += 1
        found = descend(clm, q, r, size2, free, tols)
        if found is None:
            break
        q, r, size2, closed = found
    J = None  # the closure Jacobian at q, once computed
    if closed and free.size and r.size:
        polish = POLISH_ITER if max_iter else 0  # max_iter 0: the start as it is
        q, r, it, J = _check_regular(clm, q, r, it, free, tols, tol, polish)
    err = _inf_norm(r)
    if not closed:
        k, names = clm.stiffness, clm.model.names  # held: a joint with a spring or locked
        held = [names[j] for j in range(1, len(names)) if names[j] not in clm.actuated
                and np.any(k[clm.joint_v_slice(names[j])] != 0.0)]  # fmt: skip
        raise AssemblyError(
            f"cannot close the loops of {clm.name!r} with actuated "
            f"{dict(zip(clm.actuated, clm.actuated_values(q).tolist(), strict=True))}"
            + (f" (the joints with springs or locked, {held}, keep their start values: "
               "a loop that needs them to move cannot close; give them start values that "
               "close it: q0, on the command line --near JOINT=VALUE or --start Q)"
               if held else ""),
            err,
        )  # fmt: skip
    if flipped := flipped_closures(clm, datas):
        raise AssemblyError(
            f"the loops of {clm.name!r} close with the z axes of closures {flipped} pointing "
            "opposite ways, which is not the joint they stand for; start from a configuration "
            "nearer the drawing (q0) or check the frames' z axes",
            err,
        )
    q.flags.writeable = False
    closure = None
    if jacobian:  # the datas are those of q's residual evaluation, the last one
        closure = (
            frozen(r),
            frozen(jacobian_rows(clm, data, datas, calc=False) if J is None else J),
        )
    result = object.__new__(Assembly)  # every field checked here: without the frozen __init__
    result.__dict__.update(q=q, residual=err, iterations=it, closure=closure)
    return result


def descend(clm: ClosedLoopModel, q, r, size2, free, tols, *, strict: bool = False, rows=None):
    """One Gauss-Newton step from q (residual r, its squared norm size2) on the passive
    coordinates ``free``, halved until the residual decreases or the loops close (with
    ``strict``, past the tolerance: until its square halves at least, less being the
    rounding's play): (q, r, size2, closed) of the new point, or None when 30 halvings do
    not do it. The workspace holds the kinematics of q on entry, of the last point tried
    on exit.

    ``rows``: the equations solved, by default the closures (tolerances ``tols``); or a
    pair of functions, ``residual(q) -> (r, size2, closed)`` that leaves q's kinematics in
    the workspace and ``jacobian() -> (m, nv)`` of r at the q last evaluated (the inverse
    kinematics: :mod:`closedloop.kinematics.inverse`); ``free`` then the coordinates it
    moves."""
    data, datas = clm.workspace()
    residual, jacobian = rows or (
        lambda x: _residual(clm, data, datas, x, tols),
        lambda: jacobian_rows(clm, data, datas, calc=False),
    )
    step = np.zeros(clm.model.nv)
    step[free] = -min_norm_solve(jacobian()[:, free], r)
    for _ in range(30):
        q_try = pin.integrate(clm.model, q, step)
        r_try, size2_try, closed_try = residual(q_try)
        if (size2_try <= 0.5 * size2) if strict else (size2_try < size2 or closed_try):
            return q_try, r_try, size2_try, closed_try
        step *= 0.5
    return None


def scaled_passive_jacobian(clm: ClosedLoopModel, J: np.ndarray, free: np.ndarray):
    """(m, p) columns ``free`` (the passive coordinates) of the closure Jacobian J (m, nv),
    unit-free: rows in metres divided by L, columns of lengths multiplied by L."""
    rows = np.where(clm.linear_rows, 1.0 / clm.length, 1.0)
    return J[:, free] * rows[:, None] * coordinate_scale(clm)[free]


def _singular_values(A: np.ndarray) -> np.ndarray:
    """Singular values (min(m, n),) of a non-empty A (m, n), descending (NaN if LAPACK
    fails, which no rank test passes)."""
    _, s, _, info = lapack.dgesdd(A, compute_uv=0)
    return s if info == 0 else np.full(min(A.shape), np.nan)


def _check_regular(clm: ClosedLoopModel, q, r, it: int, free, tols, tol: float, polish: int):
    """(q, r, iterations, closure Jacobian (m, nv) at q) of a closed configuration q
    (residual r, kinematics in the workspace), made sure not to be a singular one of the
    assembly.

    Where the scaled passive Jacobian A (:func:`scaled_passive_jacobian`) is nearly
    rank deficient, the tolerance admits poses up to about sqrt(2 tol) from a singular
    solution, each a different answer: q is then iterated further (at most ``polish``
    iterations, :data:`POLISH_FACTOR`) while the residual decreases, towards the solution
    itself. Then the rank rule (:func:`closedloop.common.conditioning.rule_rank`) splits off the
    directions Z of the passive coordinates that A does not see. Each is either a motion
    that the closures allow (a rod turning about its own axis: their curvature along it
    stays in the range of A, where the other passive coordinates take it up) or the sign
    of a singular configuration, where assembly branches meet (the parallelogram four-bar
    with its bars collinear): there the closures curve along it out of the range of A (a
    central second difference, :data:`CURVATURE_STEP`, :data:`CURVATURE_RTOL`), the
    passive coordinates are not determined by the actuated ones, and neighbouring poses
    within the tolerance answer differently.

    Raises:
        SingularConfigurationError: a singular configuration; the message names the
            actuated values.
    """
    data, datas = clm.workspace()
    J = jacobian_rows(clm, data, datas, calc=False)
    s = _singular_values(scaled_passive_jacobian(clm, J, free))
    if not s[-1] > POLISH_FACTOR * np.sqrt(tol) * s[0]:
        size2 = float(r.dot(r))
        for _ in range(polish):
            found = descend(clm, q, r, size2, free, tols, strict=True)
            if found is None:
                break
            q, r, size2, _ = found
            it += 1
        _residual(clm, data, datas, q, tols)  # q's kinematics back in the workspace
        J = jacobian_rows(clm, data, datas, calc=False)
        s = _singular_values(scaled_passive_jacobian(clm, J, free))
    rank = rule_rank(s)
    if rank == len(free) or rank == len(r):  # nothing unseen, or every row in the range
        return q, r, it, J
    U, s, Vt = svd(scaled_passive_jacobian(clm, J, free))
    rank = rule_rank(s)
    rows = np.where(clm.linear_rows, 1.0 / clm.length, 1.0)
    scale = coordinate_scale(clm)[free]
    h, U0, worst = CURVATURE_STEP, U[:, rank:], 0.0
    for z in Vt[rank:]:
        step = np.zeros(clm.model.nv)
        step[free] = h * z * scale
        ahead = _residual(clm, data, datas, pin.integrate(clm.model, q, step), tols)[0]
        back = _residual(clm, data, datas, pin.integrate(clm.model, q, -step), tols)[0]
        bend = (ahead + back - 2.0 * r) * rows / (h * h)
        worst = max(worst, float(np.linalg.norm(U0.T @ bend)))
    _residual(clm, data, datas, q, tols)
    if worst > CURVATURE_RTOL * s[0]:
        values = dict(zip(clm.actuated, clm.actuated_values(q).tolist(), strict=True))
        raise SingularConfigurationError(
            f"cannot assemble {clm.name!r} with actuated {values}: a singular configuration "
            f"(the closures lose rank {min(len(free), len(r)) - rank} on the passive joints, "
            f"scaled singular value {s[rank]:.1e} of {s[0]:.1e}; assembly branches meet "
            "there and the passive joints are not determined); give actuated values away "
            "from it"
        )
    return q, r, it, J


def _continued(clm: ClosedLoopModel, origin: np.ndarray, q: np.ndarray, free: np.ndarray):
    """(nq,) q with its passive coordinates (tangent indices ``free``) moved by the
    Gauss-Newton step at ``origin`` of the closures linearised in the move of the other
    coordinates from origin to q: the first-order continuation of origin's branch (exact
    on a branch along which the coordinates vary linearly). None where the other
    coordinates do not move or move by more than 2 :data:`INPUT_STEP`, or origin does not
    close the loops to :data:`closedloop.kinematics.configuration.CLOSURE_TOL` (it has no branch to
    follow); then or else, leaves origin's kinematics in the workspace."""
    model = clm.model
    move = pin.difference(model, origin, q)
    move[free] = 0.0
    if not 0.0 < float(np.max(np.abs(move) / coordinate_scale(clm))) <= 2 * INPUT_STEP:
        return None
    data, datas = clm.workspace()
    r0, _, closed = _residual(clm, data, datas, origin, _row_tolerances(clm, CLOSURE_TOL))
    if not closed:
        return None
    J0 = jacobian_rows(clm, data, datas, calc=False)
    step = np.zeros(model.nv)
    step[free] = -min_norm_solve(J0[:, free], r0 + J0 @ move)
    return pin.integrate(model, q, step)


def _inf_norm(r: np.ndarray) -> float:
    """Infinity norm of r (m,) (0 for no row; NaN propagates)."""
    return float(abs(r).max()) if r.size else 0.0

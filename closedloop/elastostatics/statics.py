"""Nonlinear static equilibrium under a finite dead-load wrench at a frame.

The wrench w = (f [N], n [N m]) acts at the origin of a frame, with both the force and the
moment fixed in world axes while the frame moves (a dead load). The springs of the model
store 1/2 dq^T K_q dq (1/2 sum_i k_i dq_i^2 without spring blocks) with
dq = ``pin.difference(model, q_rest, q)`` on the spring coordinates (a beam's virtual
joint stores the energy of a beam-column, :mod:`closedloop.model.elastic`); their rest
configuration q_rest is the assembled configuration at which the load is applied.
Locked coordinates (k = inf, including actuated joints without a spring) keep their
values of q_rest; passive ones (k = 0) follow the closures.

A moment fixed in world axes is not conservative under finite rotations, so the solver
works on the equilibrium equations (virtual work) rather than on an energy:

    F(q, lambda) = g(q) - J(q)^T w + J_c(q)^T lambda = 0,   c(q) = 0,

with g = Jd^T K_q dq the spring forces (Jd = d dq/dq, 1 for 1-dof joints), J (6, nv) the
frame Jacobian (world-aligned axes, at the frame origin), c (m,) the closure residuals of
:func:`closedloop.elastostatics.tangent.closure_gap` (world gap p2 - p1 of each point closure, log6
of each weld: the iterates do not depend on the order in which a pair is written), J_c their
Jacobian and lambda (m,) the multipliers. Each Newton step splits the free coordinates by
an SVD of J_c, unit-free (lengths in units of the mechanism's size L in its rows and
coordinates, :class:`closedloop.elastostatics.equations.SolverUnits`), into its row space (a
minimum-norm Gauss-Newton step that restores the closures; redundant closure rows only lower the
rank) and its null space N (a Newton step on N^T F with the tangent stiffness of
:func:`closedloop.elastostatics.tangent.tangent_stiffness`). The multipliers are the least-squares
ones, lambda = -(J_c^T)^+ g_F with g_F = g - J^T w: the part of the closure forces that
redundant rows leave statically indeterminate is set to zero (minimum norm, rows in
metres counted in units of L). The load is followed from zero (continuation) on the
branch that starts at q_rest: each increment starts from the tangent prediction
dq = N K_t^-1 N^T J^T dw, is sized so that this prediction stays small and its corrector
a fraction of it, and is halved when Newton fails. An increment is refused, and halved,
when Newton's answer is not the continuation of the branch: it lies far from the
prediction, or the prediction back from it misses the last equilibrium, or the tangent
stiffness turned singular in between (the sign of its determinant). The signed smallest
singular value of the spring-scaled tangent stiffness, watched at each equilibrium and
extrapolated, makes the increments approach a singularity by halves; there the solver
steps across (a bifurcation) or stops at a limit load (a fold) bracketed to
:data:`FOLD_RTOL` of its load. An answer is an equilibrium of the branch from rest, or
an :class:`~closedloop.EquilibriumError` that says which: a limit load, or a failure of the
iterations.

Joint limits (``model.lowerPositionLimit`` / ``upperPositionLimit`` of revolute and prismatic
joints) are not part of the equations: an equilibrium outside them is flagged
(:attr:`~closedloop.elastostatics.equilibrium.Equilibrium.limits_violated`,
:class:`JointLimitWarning`) or refused (``enforce_limits=True``, :class:`JointLimitError`).

For a pure force the equilibrium is a stationary point of
:func:`~closedloop.elastostatics.equilibrium.potential_energy` on the closure manifold, an
independent check.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import check_count, check_positive, check_wrench, readonly
from closedloop.elastostatics.continuation import (
    JUMP_FLOOR,
    LONG,
    allowed_corrector,
    branch_rate,
    failure,
    fold_distance,
    jump,
)
from closedloop.elastostatics.equations import EquilibriumEquations
from closedloop.elastostatics.equilibrium import Equilibrium, frame_displacement
from closedloop.elastostatics.newton import WANDERED, distance, newton
from closedloop.elastostatics.springs import check_spread, spring_factor
from closedloop.exceptions import (
    AssemblyError,
    InvalidInputError,
    JointLimitError,
    JointLimitWarning,
)
from closedloop.kinematics.assembly import close_loops
from closedloop.kinematics.configuration import Configuration, accepts_configuration
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import GravityLoad, Load, Payload

#: Closure tolerance of the equilibrium (infinity norm) [rad, and lengths in units of the
#: characteristic length L: 1e-12 L for point rows].
CLOSURE_TOL = 1e-12


#: Default largest Newton step and largest predicted motion per load increment (infinity
#: norm) [rad, and lengths in units of L].
MAX_STEP, MAX_INCREMENT = 0.5, 0.1
#: Most load increments of one solve: at the default MAX_INCREMENT a motion of 100 rad or
#: 100 L, seconds of work; a load that needs more deflects far beyond the mechanism.
MAX_LOAD_STEPS = 1000


#: Width of the bracket in which a limit load (fold) is located, relative to its load.
#: Along the branch the signed smallest singular value tau of the spring-scaled tangent
#: stiffness (:meth:`closedloop.elastostatics.equations.EquilibriumEquations.stability`) falls like
# the  square root of the load still to go; tau^2 extrapolated from the last equilibria gives
#: the distance to the singularity, which the increments approach by halves. Within
#: FOLD_RTOL / 4 of the load of the last equilibrium, t, an increment of FOLD_RTOL t steps
#: across (a bifurcation, where the branch goes on) or finds no equilibrium on the branch:
#: the fold then lies in [t, (1 + FOLD_RTOL) t] (``EquilibriumError.fold_bracket``).
FOLD_RTOL = 1e-6


#: Fraction of the extrapolated distance to a singularity that one increment may cover:
#: at a fold, where the branch goes like the square root of the remaining load, the
#: corrector of such an increment is at most 0.17 of its predictor.
FOLD_APPROACH = 0.5


#: Newton's iterations for an increment stop when they leave WANDER times the largest corrector
#: allowed (:func:`~closedloop.elastostatics.continuation.allowed_corrector`): bound for another
#: branch, or nowhere.
WANDER = 4.0
#: Ratio of corrector to predictor that the next increment aims at (the increments follow
#: the curvature of the branch, within JUMP_RATIO).
CORRECTOR_AIM = 0.25


def _check_options(tol, max_iter, max_halvings, max_step, max_increment) -> None:
    """Raise InvalidInputError for a solver argument outside its range (NaN included)."""
    for name, value, unit, allow_inf in (
        ("tol", tol, "m, rad", False),
        ("max_step", max_step, "rad or m", True),
        ("max_increment", max_increment, "rad or m", True),
    ):
        if value is not None:  # None: the default, relative to the size of the mechanism
            check_positive(name, value, unit, allow_inf=allow_inf)
    check_count("max_iter", max_iter, 1)
    check_count("max_halvings", max_halvings, 0)


@accepts_configuration
def solve_equilibrium(
    clm: ClosedLoopModel,
    q_rest: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    *,
    tol: float | None = None,
    max_iter: int = 30,
    max_halvings: int = 12,
    max_step: float | None = None,
    max_increment: float | None = None,
    enforce_limits: bool = False,
    gravity=None,
    payloads: Sequence[Payload] = (),
) -> Equilibrium:
    """Static equilibrium of the mechanism under a dead-load wrench at ``frame``.

    Converged when the closure residual is below ``tol`` and the unbalanced generalised
    force on the admissible motions is below ``FORCE_RTOL`` times the largest spring or
    load generalised force, or (when rounding in the spring forces prevents that) after a
    Newton step below ``STEP_TOL * max(1, norm(q, inf))``; Newton converging quadratically, q is
    then exact to rounding. The tests are unit-free: lengths count in units of the
    mechanism's characteristic length L (``clm.length``), forces on translations as N L,
    so that a mechanism scaled from micrometres to kilometres converges alike.

    Args:
        clm: model with closures and springs (or a :class:`Configuration`, then no q_rest:
            its q is the rest configuration).
        q_rest: (nq,) assembled configuration, rest configuration of the springs; it must
            close the loops to :data:`closedloop.kinematics.configuration.CLOSURE_TOL`. Its passive
            coordinates are first re-solved to the closure tolerance of the equilibrium
            (:func:`closedloop.kinematics.assembly.close_loops`; the result's ``q_rest``), else the
            re-closing would count as displacement.
        frame: name of the loaded frame.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin,
            fixed in world axes while the frame moves.
        tol: closure tolerance (infinity norm) [m, rad], finite and > 0; default
            :data:`CLOSURE_TOL` rad and CLOSURE_TOL L for the rows in metres.
        max_iter: Newton iterations per load increment (>= 1).
        max_halvings: how many times in all a failed or refused load increment may be
            halved (>= 0).
        max_step: largest Newton step (infinity norm) [rad or m], > 0; default 0.5 rad
            and 0.5 L (:data:`MAX_STEP`).
        max_increment: largest predicted joint motion per load increment (infinity
            norm) [rad or m], > 0; larger deflections are followed in several increments;
            default 0.1 rad and 0.1 L (:data:`MAX_INCREMENT`).
        enforce_limits: refuse the load as soon as an equilibrium along the way leaves
            the joint limits (:class:`JointLimitError`) instead of flagging the result.
        gravity: (3,) acceleration [m/s^2], world axes, that weighs the model's link
            inertias (and ``payloads``) together with the wrench; None: no weight.
        payloads: point masses at frames (:class:`closedloop.model.gravity.Payload`), with
            ``gravity``.

    Warns:
        JointLimitWarning: the equilibrium lies outside joint limits (also listed in
            :attr:`~closedloop.elastostatics.equilibrium.Equilibrium.limits_violated`).

    Raises:
        InvalidInputError: a wrench that is not 6 finite values, or so large that the
            equations overflow (near 1e308 N), a solver argument out of range, a bad
            q_rest; :class:`OpenLoopError` for a q_rest that does not close the loops.
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame (no equilibrium).
        SingularConfigurationError: a mechanism with closures whose springs are further
            apart than :data:`closedloop.elastostatics.springs.SPREAD_RESOLVED` (1e20, scaled), the
            message naming the stiffest and the softest
            (:func:`closedloop.elastostatics.springs.check_spread`); so is one with a
            passive joint (k = 0), whose spring-free motions
            :func:`closedloop.elastostatics.springs.spring_factor` checks. Without either, any
            spread.
        EquilibriumError: no equilibrium of the branch from rest found. Its ``limit_load``
            is True at a limit load (a fold: the tangent stiffness turns singular and the
            branch ends), located in ``fold_bracket`` = (``load_fraction``, upper) of
            relative width :data:`FOLD_RTOL` (the failed increment, wider, when
            ``max_halvings`` ran out first); False when Newton failed to converge (or
            only converged on another branch) with the tangent stiffness regular:
            ``stability_margin`` holds the margin at the last equilibrium. Its advice
            names what the failure calls for
            (:data:`closedloop.elastostatics.continuation.ADVICE`): more ``max_iter`` when
            Newton was still converging, a smaller ``max_increment`` or more
            ``max_halvings`` when it went off, a larger ``max_step`` when its steps were
            cut, none when it stalls at the rounding of the equations; followed, it may
            reach further, never another branch.
            :class:`JointLimitError` (a subclass) with ``enforce_limits``.
    """
    _check_options(tol, max_iter, max_halvings, max_step, max_increment)
    if payloads and gravity is None:
        raise InvalidInputError(
            "payloads weigh nothing without gravity: give gravity=(gx, gy, gz) [m/s^2]"
        )
    weight = None if gravity is None else GravityLoad(clm, gravity, payloads)
    w = Load(check_wrench(wrench), weight)
    # the one closure tolerance; the limits: flagged or enforced on the equilibrium below
    rest = Configuration(clm, q_rest, check_limits=False).require_closed()
    q_rest = _closed_rest(clm, rest)
    _check_spread(clm)
    if clm.closures or np.any(clm.stiffness == 0.0):  # else every free motion has a spring
        spring_factor(rest, rest.frame_jacobian(frame), frame)  # MechanismError before any work
    eqs = EquilibriumEquations(clm, q_rest, frame)
    units = eqs.units
    weighed = "" if weight is None else f" and the weight under gravity {weight.gravity.tolist()}"
    where = f"for wrench {w.wrench.tolist()}{weighed} at frame {frame!r} of {clm.name!r}"
    row_tol = units.rows * CLOSURE_TOL if tol is None else np.full(units.rows.size, tol)
    step_limit = units.limit(max_step, MAX_STEP)
    increment_limit = units.limit(max_increment, MAX_INCREMENT)
    q, t, dt, iterations, steps, halvings = q_rest.copy(), 0.0, 1.0, 0, 0, 0
    how = ""  # how the last increment refused failed (newton's kinds), for the advice
    st = eqs.evaluate(q, 0.0 * w)
    if enforce_limits:
        _enforce_limits(clm, q, st, 0.0, where)
    rate = branch_rate(eqs, q, 0.0, w, st)
    # (load fraction, tau) of the last three equilibria (tau of
    # EquilibriumEquations.stability: 1 at rest)
    history = [(0.0, 1.0)]
    while t < 1.0:
        fold = fold_distance(history)
        probe = fold <= 0.25 * FOLD_RTOL * t  # a singularity within reach: across, or stop
        speed = float(np.max(np.abs(rate) / increment_limit, initial=0.0))
        if not np.isfinite(speed):  # the rate is that of the full load
            raise InvalidInputError(
                f"the load {where} overflows the equilibrium equations (their generalised "
                "forces and stiffness leave the double range); expected a far smaller load"
            )
        if probe:
            ds = min(FOLD_RTOL * t, 1.0 - t)
        else:
            ds = min(dt, 1.0 - t, FOLD_APPROACH * fold)
            if speed * ds > 1.0:
                ds = 1.0 / speed
        s_try = 1.0 if t + ds >= 1.0 - 1e-12 else t + ds
        if not s_try > t:
            detail = f"no progress, the load increment {ds:.3g} vanishes at {t:.6g} of the load"
            raise failure(eqs, q, t, s_try, w, where, detail, iterations, st, history, how)
        if steps >= MAX_LOAD_STEPS:  # a deflection of thousands of increments: hours
            detail = (
                f"{steps} load increments reached only {t:.3g} of the load (each moving the "
                f"joints by at most max_increment, now {ds:.3g} of the load): a deflection "
                "far beyond the mechanism's size"
            )
            raise failure(eqs, q, t, s_try, w, where, detail, iterations, st, history, LONG)
        guess = pin.integrate(clm.model, q, (s_try - t) * rate) if np.any(rate) else q
        allowed = allowed_corrector(eqs, q, guess)
        q_new, st_try, it, how = newton(
            eqs,
            guess,
            s_try * w,
            row_tol=row_tol,
            max_iter=max_iter,
            step_limit=step_limit,
            radius=WANDER * allowed,
        )
        iterations += it
        why = "Newton failed"
        if q_new is not None:
            tau_new = eqs.stability(q_new, s_try * w)[1]
            rate_new = branch_rate(eqs, q_new, s_try, w, st_try)  # also the kinematics of q_new
            back = pin.integrate(clm.model, q_new, (t - s_try) * rate_new)
            # unloaded, M = I; a spring-free motion that any load destabilises (a link
            # upright on a passive joint) flips the sign of det M at once, at t = 0
            across = probe or t == 0.0
            points = (q, guess, q_new, back)
            why = jump(eqs, points, (history[-1][1], tau_new), allowed, across)
            how = WANDERED if why else how
        if why:
            if probe or halvings >= max_halvings:
                detail = (
                    f"{why} at {s_try:.9g} of the load, {iterations} iterations in all "
                    f"({steps} increments, {halvings} halvings)"
                )
                raise failure(eqs, q, t, s_try, w, where, detail, iterations, st_try, history, how)
            halvings += 1
            dt = 0.5 * ds
            continue
        if enforce_limits:
            _enforce_limits(clm, q_new, st_try, t, where)
        # the corrector grows like the square of the increment: the next one aims at
        # CORRECTOR_AIM of its predictor (at most doubled, at least halved)
        ratio = distance(eqs, guess, q_new) / max(distance(eqs, q, guess), JUMP_FLOOR)
        dt = ds * min(2.0, max(0.5, CORRECTOR_AIM / max(ratio, 1e-300)))
        q, st, rate, t, steps = q_new, st_try, rate_new, s_try, steps + 1
        history = [*history[-2:], (t, tau_new)]
    bad = joints_outside_limits(clm, q)
    if bad:
        warnings.warn(
            f"the equilibrium {where} is outside the joint limits: {describe_limits(bad)}",
            JointLimitWarning,
            stacklevel=3,  # the caller of the accepts_configuration wrapper
        )
    disp = frame_displacement(clm, q, q_rest, frame)  # leaves the kinematics of q in clm.data
    return Equilibrium(
        q=readonly(q),
        q_rest=readonly(q_rest),
        frame=frame,
        wrench=readonly(w.wrench),
        translation=readonly(disp[:3]),
        rotation=readonly(disp[3:]),
        joint_deflection=readonly(pin.difference(clm.model, q_rest, q)),
        multipliers=readonly(st["lam"]),
        closure_residual=st["closure"],
        force_residual=st["force"],
        iterations=iterations,
        load_steps=max(steps, 1),
        limits_violated=tuple(bad),
        gravity=weight,
    )


def _closed_rest(clm: ClosedLoopModel, rest: Configuration) -> np.ndarray:
    """(nq,) the rest configuration, its passive coordinates re-solved to 1e-12 of L
    (:func:`closedloop.kinematics.assembly.close_loops`): one closed only to the configurations'
    CLOSURE_TOL (1e-6 of L) moved by up to that much under any load, zero included. As
    given where the passive coordinates cannot close it tighter."""
    try:
        return np.array(close_loops(clm, np.array(rest.q)).q)
    except AssemblyError:
        return np.array(rest.q)


def _enforce_limits(clm, q, st: dict, t_within: float, where: str) -> None:
    """Raise JointLimitError when q is outside the joint limits (``enforce_limits``)."""
    bad = joints_outside_limits(clm, q)
    if bad:
        raise JointLimitError(
            f"the load drives joints beyond their limits {where}: {describe_limits(bad)}",
            st["closure"],
            st["force"],
            t_within,
            bad,
        )


def _check_spread(clm: ClosedLoopModel) -> None:
    """Refuse a mechanism with closures whose springs span more than
    :data:`closedloop.elastostatics.springs.SPREAD_RESOLVED` (scaled at ``clm.length``), naming the
    stiffest and the softest spring (with spring blocks: the stiffness of the stiffest and
    the softest direction of the spring factor, on the joint it moves most).

    The admissible motions of the closures (the null space of J_c, an SVD) mix the
    coordinates: a soft motion's part on a stiff coordinate is known to eps of the soft
    motion only, so the stiff springs' deflections and forces (and the multipliers) lose
    their digits as the spread grows (the four-bar, crank 1 N m/rad and axial springs
    spread / L^2, loads of 1e-6 N: up to 1e-3 of their deflection at 1e20, 0.2 at 1e22,
    1 to 4 at 1e24, while the loaded frame's motion keeps 1e-7). Without closures the
    basis is the identity on the free coordinates and each spring is solved for through
    its own square root
    (:meth:`closedloop.elastostatics.equations.EquilibriumEquations.step`), at any spread.
    """
    if clm.closures:
        check_spread(clm, clm.length, "the statics of a mechanism with closures")

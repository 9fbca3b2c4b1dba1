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
coordinates, :class:`closedloop.elastostatics.tangent.SolverUnits`), into its row space (a
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
an :class:`EquilibriumError` that says which: a limit load, or a failure of the
iterations.

Joint limits (``model.lowerPositionLimit`` / ``upperPositionLimit`` of revolute and
prismatic joints) are not part of the equations: an equilibrium outside them is flagged
(:attr:`Equilibrium.limits_violated`, :class:`JointLimitWarning`) or refused
(``enforce_limits=True``, :class:`JointLimitError`).

For a pure force the equilibrium is a stationary point of :func:`potential_energy` on the
closure manifold, an independent check.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import (
    ReadOnlyArrays,
    check_count,
    check_positive,
    check_wrench,
    readonly,
    real_array,
)
from closedloop.elastostatics.springs import check_spread, spring_factor
from closedloop.elastostatics.tangent import EquilibriumEquations
from closedloop.exceptions import (
    AssemblyError,
    EquilibriumError,
    InvalidInputError,
    JointLimitError,
    JointLimitWarning,
)
from closedloop.kinematics.assembly import close_loops
from closedloop.kinematics.configuration import Configuration, accepts_configuration
from closedloop.kinematics.constraints import update_kinematics
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.elastic import deflection, spring_law
from closedloop.model.gravity import GravityLoad, Load, Payload

#: Closure tolerance of the equilibrium (infinity norm) [rad, and lengths in units of the
#: characteristic length L: 1e-12 L for point rows].
CLOSURE_TOL = 1e-12
#: Relative tolerance on the unbalanced generalised force (see :func:`solve_equilibrium`).
FORCE_RTOL = 1e-11
#: Newton step [rad, and lengths in units of L], relative to max(1, |q|) (q in the same
#: units), after which q counts as converged.
STEP_TOL = 1e-12
#: Default largest Newton step and largest predicted motion per load increment (infinity
#: norm) [rad, and lengths in units of L].
MAX_STEP, MAX_INCREMENT = 0.5, 0.1
#: Most load increments of one solve: at the default MAX_INCREMENT a motion of 100 rad or
#: 100 L, seconds of work; a load that needs more deflects far beyond the mechanism.
MAX_LOAD_STEPS = 1000


#: Width of the bracket in which a limit load (fold) is located, relative to its load.
#: Along the branch the signed smallest singular value tau of the spring-scaled tangent
#: stiffness (:meth:`closedloop.elastostatics.tangent.EquilibriumEquations.stability`) falls like
# the  square root of the load still to go; tau^2 extrapolated from the last equilibria gives
#: the distance to the singularity, which the increments approach by halves. Within
#: FOLD_RTOL / 4 of the load of the last equilibrium, t, an increment of FOLD_RTOL t steps
#: across (a bifurcation, where the branch goes on) or finds no equilibrium on the branch:
#: the fold then lies in [t, (1 + FOLD_RTOL) t] (``EquilibriumError.fold_bracket``).
FOLD_RTOL = 1e-6
#: Error of tau (absolute: M is 1 unloaded; the weld curvature by central differences
#: carries 1e-10 of it): a fall of tau^2 below TAU_NOISE (2 |tau| + TAU_NOISE) is rounding,
#: not a trend to extrapolate.
TAU_NOISE = 1e-9
#: Fraction of the extrapolated distance to a singularity that one increment may cover:
#: at a fold, where the branch goes like the square root of the remaining load, the
#: corrector of such an increment is at most 0.17 of its predictor.
FOLD_APPROACH = 0.5
#: An increment is refused as a jump to another branch when Newton's answer lies further
#: than JUMP_RATIO times the predicted motion from the prediction (the corrector of a step
#: on a smooth branch is second order), or when the prediction back from the answer, along
#: its own tangent, misses the last equilibrium by as much (the unstable twin of a fold
#: has its tangent reversed). Infinity norms, lengths in units of L.
JUMP_RATIO = 0.5
#: Corrector below which an increment is not refused, whatever its predictor: JUMP_FLOOR
#: [rad, and lengths in units of L] (a load with no first-order motion along the branch)
#: plus JUMP_RTOL times the deflection from rest, the resolution of the equilibria under
#: huge loads (1e16 N on the UR5's 1e4 N m/rad springs: correctors of 5e-8 rad at
#: predictors of 1e-10 rad, at deflections of 1.5 rad). A jump to another branch moves
#: the joints by a part of the deflection itself (8 times it in CaHyMan near a leg
#: singularity).
JUMP_FLOOR, JUMP_RTOL = 1e-9, 1e-6
#: Newton's iterations for an increment stop when they leave WANDER times the largest
#: corrector allowed (:func:`_allowed`): bound for another branch, or nowhere.
WANDER = 4.0
#: Ratio of corrector to predictor that the next increment aims at (the increments follow
#: the curvature of the branch, within JUMP_RATIO).
CORRECTOR_AIM = 0.25


@dataclass(frozen=True)
class Equilibrium(ReadOnlyArrays):
    """A static equilibrium under a dead-load wrench (arrays read-only).

    Attributes:
        q: (nq,) equilibrium configuration.
        q_rest: (nq,) rest configuration of the springs (unloaded, assembled).
        frame: name of the loaded frame.
        wrench: (6,) applied wrench (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the
            frame origin.
        translation: (3,) displacement of the frame origin from its unloaded position [m],
            world axes.
        rotation: (3,) rotation vector of the frame from its unloaded orientation [rad],
            world axes: R = exp(rotation) R_rest.
        joint_deflection: (nv,) difference(q_rest, q) [rad or m].
        multipliers: (m,) closure multipliers lambda, one per row of
            :func:`closedloop.elastostatics.tangent.closure_gap`; for a point closure, the force [N]
            that side 2 exerts on side 1 at the anchor, in world axes; for a weld, the wrench
            [N, N m] conjugate to its log6 residual rows. Minimum-norm when closure rows
            are redundant (no self-stress).
        closure_residual: infinity norm of the closure residual at q [m, rad].
        force_residual: infinity norm of the unbalanced generalised force
            (g - J^T w + J_c^T lambda on the free coordinates) [N m, N].
        iterations: Newton iterations, all load increments together.
        load_steps: load increments used (1 when the full load converged at once).
        limits_violated: names of the joints outside their position limits at q (see
            :func:`closedloop.kinematics.limits.joints_outside_limits`); empty when every limit
            holds.
        gravity: the weight of the links and payloads that acts with the wrench
            (:class:`closedloop.model.gravity.GravityLoad`), or None.
    """

    q: np.ndarray
    q_rest: np.ndarray
    frame: str
    wrench: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray
    joint_deflection: np.ndarray
    multipliers: np.ndarray
    closure_residual: float
    force_residual: float
    iterations: int
    load_steps: int
    limits_violated: tuple[str, ...] = ()
    gravity: GravityLoad | None = None

    @property
    def displacement(self) -> np.ndarray:
        """(6,) (translation [m], rotation vector [rad]) of the frame, world axes."""
        return np.concatenate([self.translation, self.rotation])

    @property
    def load(self) -> Load:
        """The full load: the wrench and the weight."""
        return Load(self.wrench, self.gravity)


def frame_displacement(
    clm: ClosedLoopModel, q: np.ndarray, q_ref: np.ndarray, frame: str
) -> np.ndarray:
    """(6,) displacement of ``frame`` from its pose at q_ref to its pose at q, world axes.

    Translation p(q) - p(q_ref) [m] of the frame origin, then the rotation vector
    log3(R(q) R(q_ref)^T) [rad]; to first order the frame twist J dq.
    """
    fid = clm.frame_id(frame)
    update_kinematics(clm, q_ref)
    ref = clm.data.oMf[fid].copy()
    update_kinematics(clm, q)
    cur = clm.data.oMf[fid]
    return np.concatenate(
        [cur.translation - ref.translation, pin.log3(cur.rotation @ ref.rotation.T)]
    )


def potential_energy(
    clm: ClosedLoopModel,
    q: np.ndarray,
    q_rest: np.ndarray,
    frame: str,
    force: np.ndarray,
    gravity: GravityLoad | None = None,
) -> float:
    """Potential energy [J] of the springs, a dead-load force at a frame origin, the weight.

    ``1/2 dq^T K_q dq - f . (p(q) - p(q_rest)) + V_g(q) - V_g(q_rest)`` over the spring
    coordinates (0 < k < inf; K_q = ``clm.spring_matrix``, diag(k) or with blocks),
    dq = difference(q_rest, q); a beam's energy is that of :mod:`closedloop.model.elastic`
    (its tip displacement and rotation, with the shortening of the bent beam). A
    world-fixed moment has no potential.

    Args:
        force: (3,) force [N], world axes, at the origin of ``frame``.
        gravity: the weight (:class:`closedloop.model.gravity.GravityLoad`), or None.
    """
    f = real_array(force, "force").reshape(-1)
    if f.shape != (3,) or not np.isfinite(f).all():
        raise InvalidInputError(f"force must be 3 finite values (fx fy fz) [N], got {f.tolist()}")
    springs = spring_law(clm, deflection(clm, q_rest, q))[1]
    dp = frame_displacement(clm, q, q_rest, frame)[:3]
    weight = 0.0 if gravity is None else gravity.potential(q) - gravity.potential(q_rest)
    return float(springs - f @ dp + weight)


def _newton(eqs: EquilibriumEquations, q, w, *, row_tol, max_iter: int, step_limit, radius):
    """Newton iterations at a fixed wrench; returns (q or None, state, iterations).

    Args:
        row_tol: (m,) closure tolerance of each row [m, rad]; step_limit: (nv,) largest
            step of each coordinate [rad, m]; radius: the iterations stop (None) when they
            leave this distance from the start (:func:`_distance`): bound for another
            branch.
    """
    units, start = eqs.units, q
    st = eqs.evaluate(q, w)
    for it in range(max_iter + 1):
        if _closed(st, row_tol) and _balanced(st, eqs.free_scales):
            return q, st, it
        if it == max_iter:
            break
        v, dropped = eqs.step(q, w, st)
        ratio = np.max(np.abs(v) / step_limit, initial=0.0)
        if not np.isfinite(ratio):
            break
        capped = ratio > 1.0  # a cut step says nothing of the distance to the solution
        if capped:
            v /= ratio
        q = pin.integrate(eqs.clm.model, q, v)
        if _distance(eqs, start, q) > radius:
            break
        st = eqs.evaluate(q, w)
        if not (np.isfinite(st["closure"]) and np.isfinite(st["force"])):
            break
        size = np.max(np.abs(v) / units.coords, initial=0.0)
        if (
            not capped
            and _closed(st, row_tol)
            and size <= STEP_TOL * max(1.0, np.max(np.abs(q) / units.q))
            and not dropped  # a step that resolved every direction: q is at rounding
        ):  # level (Newton converges quadratically); else the force test decides
            return q, st, it + 1
    return None, st, max_iter


def _closed(st: dict, row_tol: np.ndarray) -> bool:
    """Every closure row within its tolerance."""
    return bool(np.all(np.abs(st["c"]) <= row_tol))


def _balanced(st: dict, coords: np.ndarray) -> bool:
    """The unbalanced generalised force below FORCE_RTOL times the largest spring or load
    one, each a force times the scale of its coordinate (N m, N L)."""
    scale = max(
        np.max(np.abs(st["spring"]) * coords, initial=0.0),
        np.max(np.abs(st["load"]) * coords, initial=0.0),
    )
    return bool(np.max(np.abs(st["unbalanced"]) * coords, initial=0.0) <= FORCE_RTOL * scale)


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
            :attr:`Equilibrium.limits_violated`).

    Raises:
        InvalidInputError: a wrench that is not 6 finite values, or so large that the
            equations overflow (near 1e308 N), a solver argument out of range, a bad
            q_rest; :class:`OpenLoopError` for a q_rest that does not close the loops.
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame (no equilibrium).
        SingularConfigurationError: a mechanism with closures whose springs are further
            apart than :data:`closedloop.elastostatics.springs.SPREAD_RESOLVED` (1e20, scaled), the
            message naming the stiffest and the softest (:func:`_check_spread`); so is one
            with a passive joint (k = 0), whose spring-free motions
            :func:`closedloop.elastostatics.springs.spring_factor` checks. Without either, any
            spread.
        EquilibriumError: no equilibrium of the branch from rest found. Its ``limit_load``
            is True at a limit load (a fold: the tangent stiffness turns singular and the
            branch ends), located in ``fold_bracket`` = (``load_fraction``, upper) of
            relative width :data:`FOLD_RTOL` (the failed increment, wider, when
            ``max_halvings`` ran out first); False when Newton failed to converge (or
            only converged on another branch) with the tangent stiffness regular:
            ``stability_margin`` holds the margin at the last equilibrium. A smaller
            ``max_increment`` or more ``max_iter`` / ``max_halvings`` then may reach
            further, never another branch. :class:`JointLimitError` (a subclass) with
            ``enforce_limits``.
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
    st = eqs.evaluate(q, 0.0 * w)
    if enforce_limits:
        _enforce_limits(clm, q, st, 0.0, where)
    rate = _rate(eqs, q, 0.0, w, st)
    # (load fraction, tau) of the last three equilibria (tau of
    # EquilibriumEquations.stability: 1 at rest)
    history = [(0.0, 1.0)]
    while t < 1.0:
        fold = _fold_distance(history)
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
            raise _failure(eqs, q, t, s_try, w, where, detail, iterations, st, history)
        if steps >= MAX_LOAD_STEPS:  # a deflection of thousands of increments: hours
            detail = (
                f"{steps} load increments reached only {t:.3g} of the load (each moving the "
                f"joints by at most max_increment, now {ds:.3g} of the load): a deflection "
                "far beyond the mechanism's size; give a smaller load or a larger max_increment"
            )
            raise _failure(eqs, q, t, s_try, w, where, detail, iterations, st, history)
        guess = pin.integrate(clm.model, q, (s_try - t) * rate) if np.any(rate) else q
        allowed = _allowed(eqs, q, guess)
        q_new, st_try, it = _newton(
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
            rate_new = _rate(eqs, q_new, s_try, w, st_try)  # also the kinematics of q_new
            back = pin.integrate(clm.model, q_new, (t - s_try) * rate_new)
            # unloaded, M = I; a spring-free motion that any load destabilises (a link
            # upright on a passive joint) flips the sign of det M at once, at t = 0
            across = probe or t == 0.0
            points = (q, guess, q_new, back)
            why = _jump(eqs, points, (history[-1][1], tau_new), allowed, across)
        if why:
            if probe or halvings >= max_halvings:
                detail = (
                    f"{why} at {s_try:.9g} of the load, {iterations} iterations in all "
                    f"({steps} increments, {halvings} halvings)"
                )
                raise _failure(eqs, q, t, s_try, w, where, detail, iterations, st_try, history)
            halvings += 1
            dt = 0.5 * ds
            continue
        if enforce_limits:
            _enforce_limits(clm, q_new, st_try, t, where)
        # the corrector grows like the square of the increment: the next one aims at
        # CORRECTOR_AIM of its predictor (at most doubled, at least halved)
        ratio = _distance(eqs, guess, q_new) / max(_distance(eqs, q, guess), JUMP_FLOOR)
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
    its own square root (:meth:`closedloop.elastostatics.tangent.EquilibriumEquations.step`), at any
    spread.
    """
    if clm.closures:
        check_spread(clm, clm.length, "the statics of a mechanism with closures")


def _advice(eqs: EquilibriumEquations, q) -> str:
    """What to try after a failed continuation: a smaller step, unless the part of the
    load reached already turns a joint coordinate by a radian or more (a load far beyond
    the springs, which no step size helps)."""
    clm = eqs.clm
    turn = np.where(clm.linear_coordinates, 0.0, np.abs(pin.difference(clm.model, eqs.q_rest, q)))
    i = int(np.argmax(turn)) if turn.size else 0
    if turn.size and turn[i] >= 1.0:
        return (
            f"the part of the load reached already turns joint {clm.coordinate_joint(i)!r} by "
            f"{turn[i]:.3g} rad from rest: the load is far beyond what the springs hold; "
            "expected a smaller load"
        )
    return "try a smaller max_increment or a larger max_iter"


def _rate(eqs: EquilibriumEquations, q, t: float, w, st: dict) -> np.ndarray:
    """(nv,) dq/ds at the equilibrium q under t w (state ``st``) as the load grows by s w
    [rad or m per unit of load fraction]; zero without load."""
    return eqs.step(q, t * w, st, load=w)[0] if w.any() else np.zeros(eqs.clm.model.nv)


def _fold_distance(history) -> float:
    """Load fraction still to go to where tau (:meth:`EquilibriumEquations.stability`)
    vanishes: a Newton step on tau^2, its slope at the last equilibrium that of the parabola
    through the last three (t, tau) pairs of ``history`` (the chord through two if only
    two); inf when |tau| does not fall (beyond its rounding, TAU_NOISE) or has changed
    sign."""
    if len(history) < 2:
        return np.inf
    t, tau = np.array(history[-3:]).T
    if np.any(tau[:-1] * tau[-1] <= 0.0):
        return np.inf
    y = tau * tau
    if y[-2] - y[-1] <= TAU_NOISE * (2.0 * abs(tau[-2]) + TAU_NOISE):  # rounding, or rising
        return np.inf
    slope = (y[-1] - y[-2]) / (t[-1] - t[-2])
    if t.size == 3:  # add the curvature term of the parabola, at t[-1]
        slope += (t[-1] - t[-2]) * (slope - (y[1] - y[0]) / (t[1] - t[0])) / (t[2] - t[0])
    return y[-1] / -slope if slope < 0.0 else np.inf


def _distance(eqs: EquilibriumEquations, a: np.ndarray, b: np.ndarray) -> float:
    """Infinity norm of difference(a, b) [rad, and lengths in units of L]."""
    d = pin.difference(eqs.clm.model, a, b) / eqs.units.coords
    return float(np.max(np.abs(d), initial=0.0))


def _allowed(eqs: EquilibriumEquations, q: np.ndarray, guess: np.ndarray) -> float:
    """Largest corrector of an increment from the equilibrium q predicted at ``guess``
    (both (nq,)) [rad, and lengths in units of L]: JUMP_RATIO of the predictor, plus the
    resolution of the equilibria (JUMP_FLOOR, JUMP_RTOL)."""
    rounding = JUMP_FLOOR + JUMP_RTOL * _distance(eqs, eqs.q_rest, guess)
    return JUMP_RATIO * _distance(eqs, q, guess) + rounding


def _jump(eqs: EquilibriumEquations, points, taus, allowed: float, across: bool) -> str:
    """Why an increment that converged is refused ('' when it is not).

    Args:
        points: (q, guess, q_new, back): the last equilibrium, the prediction Newton
            started from, its answer, and the prediction from q_new back to the last load
            fraction along its own tangent, (nq,) each.
        allowed: the largest corrector (:func:`_allowed`).
        taus: tau at q and at q_new; across: whether the increment may step across a
            singularity (one extrapolated within it): a sign change of det M is allowed
            only then.
    """
    q, guess, q_new, back = points
    if _distance(eqs, guess, q_new) > allowed or _distance(eqs, back, q) > allowed:
        return "Newton converged away from the predicted equilibrium (on another branch)"
    if taus[0] * taus[1] <= 0.0 and not across:
        return "the tangent stiffness turned singular within the increment"
    return ""


def _failure(eqs: EquilibriumEquations, q, t, s_fail, w, where, detail, iterations, state, history):
    """EquilibriumError after a failed continuation, limit load or not (its ``limit_load``).

    (q, t): the last equilibrium and its load fraction; ``s_fail`` the load fraction that
    failed; ``state``: the :meth:`evaluate` state whose residuals the error reports;
    ``history``: (t, tau) of the last three equilibria. A limit load when tau extrapolates
    to zero within the failed increment: the fold is bracketed by [t, s_fail].
    """
    margin, tau = eqs.stability(q, t * w)
    fold = _fold_distance(history)
    limit = fold <= s_fail - t
    if limit:
        reason = (
            f"no static equilibrium found {where} beyond {t:.9g} of the load: a limit load "
            f"(fold) between {t:.9g} and {s_fail:.9g} of the load ends the branch that starts "
            f"at q_rest (the spring-scaled tangent stiffness turns singular there: its "
            f"smallest singular value {abs(tau):.3g}, extrapolated to 0 at {t + fold:.9g}; "
            f"stability margin {margin:.3g}); {detail}"
        )
    else:
        near = "" if not np.isfinite(fold) else f", extrapolated to 0 at {t + fold:.6g}"
        reason = (
            f"the solver failed to converge {where}: {detail}; not a limit load (the "
            f"spring-scaled tangent stiffness is regular at {t:.6g} of the load: smallest "
            f"singular value {abs(tau):.3g}{near}, stability margin {margin:.3g}): "
            f"{_advice(eqs, q)}"
        )
    return EquilibriumError(
        reason,
        state["closure"],
        state["force"],
        t,
        limit_load=limit,
        stability_margin=margin,
        iterations=iterations,
        fold_bracket=(float(t), float(s_fail)) if limit else None,
    )

"""Deflection compensation: the actuated values whose loaded equilibrium puts a frame
exactly on its target, and the loaded equilibria of a path, each warm-started from the last.

The actuators are springs at rest at the commanded values u (an actuated joint without a
spring is rigid: it sits at u); every other spring keeps its rest value. The equilibrium
under a load (a dead-load wrench at the frame and the weight,
:mod:`closedloop.elastostatics.statics`) at commands u is the equilibrium whose rest
configuration is the unloaded one with its actuated values set to u.

**Exact compensation.** The compensated equilibrium q and its commands u solve

    c(q) = 0,   N_h^T F_h(q) = 0,   task(q) = 0,   u = q_A + f_A(q) / k_A,

where F_h is the generalised force of the *held* model (:func:`held_model`: the actuated
joints locked at their values in q) on its free coordinates, with the multipliers lambda
of the closures, N_h its admissible motions, ``task`` the frame's rows
(:class:`closedloop.kinematics.frame_task.FrameTask`) and f_A = (J_c^T lambda - J^T w +
G)_A the generalised force that the actuators' springs k_A hold (u = q_A for a rigid
actuator). The unknowns are the actuated coordinates and the free ones together: Newton
with the held model's tangent stiffness (:func:`closedloop.elastostatics.tangent.tangent_stiffness`,
which carries the geometric stiffness of the load, the loop curvature and the weight's),
its matrix kept for the next iterates while they converge (chord steps,
:data:`CHORD_RATE`), whose answer is exact to the statics' tolerance, not only to first
order. A serial arm with springs on its actuators only has nothing to settle: q is the
unloaded pose and u = q - K^-1 (J^T w - G(q)), the closed form.

**Warm starts along a path** (:func:`extrapolated`): the last points' deflections from
their rest configurations, extrapolated to this point's. From the last point alone the
start is off by the change of the deflection between the points (first order in the
step); from the last two, by its curvature along the path (second order): CaHyMan's
compensation on a line of 1 mm steps then converges in one Newton step (two evaluations
of the equations and one tangent), where a start carried from the last point takes two,
and chord steps on the last point's Newton matrix three or four, each an evaluation of
the equations, which together cost more than the one new tangent.

**Loaded equilibria along a path** (:func:`loaded_equilibrium`): Newton from the warm
start, kept when it stays near its start and crosses no singularity; the load continuation
from rest (:func:`closedloop.elastostatics.statics.solve_equilibrium`) at the first point,
and wherever that Newton fails or is not kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.elastostatics.continuation import JUMP_FLOOR, JUMP_RATIO
from closedloop.elastostatics.equations import EquilibriumEquations, solver_units
from closedloop.elastostatics.newton import STEP_TOL, balanced, closed, distance, newton
from closedloop.elastostatics.springs import spring_factor
from closedloop.elastostatics.statics import CLOSURE_TOL, MAX_STEP, solve_equilibrium
from closedloop.elastostatics.tangent import tangent_stiffness
from closedloop.exceptions import EquilibriumError, JointLimitError
from closedloop.kinematics.assembly import min_norm_solve
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import frame_jacobian
from closedloop.kinematics.frame_task import FrameTask
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import Load

#: Tolerance of the compensated frame's task rows: metres per characteristic length L,
#: radians (the inverse kinematics' own, :data:`closedloop.kinematics.inverse.IK_TOL`).
TASK_TOL = 1e-12
#: Newton iterations of a compensation, and of a warm-started loaded equilibrium.
MAX_ITER = 20
#: A compensation's Newton matrix is kept for the next iterate (a chord step: no new
#: tangent stiffness) while the residual falls by this factor a step at least; from a warm
#: start it falls like the square of the first step's, far below it.
CHORD_RATE = 0.1
#: Most a warm start extrapolates (:func:`extrapolated`): the step to this point at most
#: this many times the last one along it (a path whose steps grow faster is carried).
EXTRAPOLATION_LIMIT = 4.0
#: A warm-started equilibrium is kept when Newton ends within WARM_RATIO of the guess's
#: deflection from its start (plus the resolution of the equilibria, JUMP_FLOOR): the
#: statics' bound on an increment's corrector (JUMP_RATIO), against a jump to another
#: branch; a load that changes much from point to point goes to the continuation.
WARM_RATIO = JUMP_RATIO


def held_model(clm: ClosedLoopModel) -> ClosedLoopModel:
    """The model with its actuated joints locked (their springs left out), every other
    spring as it is (once per model)."""

    def build():
        springs = {k: v for k, v in clm.springs.items() if k not in clm.actuated}
        return clm.with_springs(springs, (*clm.locked, *clm.actuated))

    return clm.memo("held_model", build)


def rest_at(clm: ClosedLoopModel, q_rest: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """(nq,) the rest configuration q_rest (nq,) with its actuated values set to
    ``commands`` (n_act,) [rad, m] (it need not close the loops: only the springs read it)."""
    q = np.array(q_rest, dtype=float)
    clm.set_actuated(q, commands)
    return q


def extrapolated(clm: ClosedLoopModel, q_rest: np.ndarray, last: list) -> np.ndarray:
    """(nq,) a warm start [rad, m] at the rest configuration q_rest (nq,) from the last
    points' (rest, answer) pairs ``last`` (one or two, the older first; each (nq,)):
    q_rest + d, with d the last point's deflection difference(rest, answer) plus, given
    two, its change from the point before times s, the step dr from the last rest to
    q_rest along the last step dr_last (s = <dr, dr_last> / <dr_last, dr_last> on the
    tangent space, lengths in units of L, clamped to [0, :data:`EXTRAPOLATION_LIMIT`]):
    linear extrapolation along the path.
    """
    model = clm.model
    rest, answer = last[-1]
    d = pin.difference(model, rest, answer)
    if len(last) > 1:
        before, answer_before = last[-2]
        coords = solver_units(clm).coords
        step = pin.difference(model, rest, q_rest) / coords
        back = pin.difference(model, before, rest) / coords
        size = float(back @ back)
        s = min(max(float(step @ back) / size, 0.0), EXTRAPOLATION_LIMIT) if size else 0.0
        d += s * (d - pin.difference(model, before, answer_before))
    return pin.integrate(model, q_rest, d)


def linear_deflection(clm: ClosedLoopModel, q: np.ndarray, frame: str, load: Load) -> np.ndarray:
    """(nv,) joint deflection of the linear model at the unloaded configuration q (nq,):
    dq = P P^T (J^T w - G(q)) with the spring factor P of
    :func:`closedloop.elastostatics.springs.spring_factor` (K_r^+ on the admissible motions),
    the wrench and the weight as generalised forces [rad, m]; J dq is C w for a wrench
    alone (C the compliance at the frame).

    Raises:
        MechanismError: a spring-free motion moves the frame.
    """
    state = Configuration(clm, q, check_limits=False)
    J = state.frame_jacobian(frame)
    P = spring_factor(state, J, frame).P
    tau = J.T @ load.wrench - load.forces(state.q, clm.model.nv)
    return P @ (P.T @ tau)


def loaded_equilibrium(
    clm: ClosedLoopModel,
    frame: str,
    q_rest: np.ndarray,
    load: Load,
    guess: np.ndarray | None = None,
    *,
    sign: float | None = None,
    enforce_limits: bool = True,
    stability: bool = True,
) -> tuple[np.ndarray, float | None]:
    """(q, tau): the equilibrium q (nq,) under ``load`` whose rest configuration is q_rest
    (nq,), assembled, unloaded, on the branch from rest, and tau, the signed smallest
    singular value of its spring-scaled tangent stiffness
    (:meth:`EquilibriumEquations.stability`: 1 unloaded, its sign changes only where the
    branch meets a singularity).

    Newton from ``guess`` (nq,) (the last points' equilibria extrapolated along the path,
    :func:`extrapolated`), kept when it converges within :data:`WARM_RATIO` of the
    guess's deflection from its start and its tau has the sign ``sign`` (the last
    point's): no singularity crossed, no jump to another branch. Else, or without a
    guess, the load continuation from rest
    (:func:`closedloop.elastostatics.statics.solve_equilibrium`) decides. ``stability``
    False: tau is not computed (None) and the warm answer is kept on the distance test
    alone (a guess that is itself an equilibrium of the branch under this load, nearby).

    Raises:
        EquilibriumError: no equilibrium on the branch from rest (a limit load on the way,
            or the iterations fail); :class:`JointLimitError` with ``enforce_limits`` when
            the equilibrium leaves the joints' limits.
        MechanismError, SingularConfigurationError: as
            :func:`closedloop.elastostatics.statics.solve_equilibrium`.
    """
    eqs = EquilibriumEquations(clm, q_rest, frame)
    if guess is not None:
        q, st, _, _ = newton(
            eqs,
            guess,
            load,
            row_tol=eqs.units.rows * CLOSURE_TOL,
            max_iter=MAX_ITER,
            step_limit=eqs.units.limit(None, MAX_STEP),
            radius=WARM_RATIO * distance(eqs, q_rest, guess) + JUMP_FLOOR,
        )
        tau = None if q is None or not stability else eqs.stability(q, load)[1]
        if q is not None and (tau is None or sign is None or tau * sign > 0.0):
            bad = joints_outside_limits(clm, q)
            if bad and enforce_limits:
                raise JointLimitError(
                    f"the load drives joints of {clm.name!r} beyond their limits: "
                    f"{describe_limits(bad)}",
                    st["closure"],
                    st["force"],
                    1.0,
                    bad,
                )
            return q, tau
    gravity = load.gravity
    eq = solve_equilibrium(
        clm,
        q_rest,
        frame,
        load.wrench,
        gravity=None if gravity is None else gravity.gravity,
        payloads=() if gravity is None else gravity.payloads,
        enforce_limits=enforce_limits,
    )
    q = np.array(eq.q)
    return q, eqs.stability(q, load)[1] if stability else None


def branch_sign(clm: ClosedLoopModel, frame: str, q_rest, q, load: Load) -> float:
    """tau (:func:`loaded_equilibrium`) of the equilibrium q (nq,) whose springs rest at
    q_rest (nq,) under ``load``."""
    return EquilibriumEquations(clm, q_rest, frame).stability(q, load)[1]


@dataclass(frozen=True)
class Compensation:
    """An exactly compensated equilibrium.

    Attributes:
        q: (nq,) the equilibrium under the load at ``commands``, whose frame meets the task.
        commands: (n_act,) the actuated values [rad, m], in the model's actuated order.
        task_residual: infinity norm of the task's rows at q [m, rad].
        closure_residual: infinity norm of the closure residual at q [m, rad].
        force_residual: infinity norm of the unbalanced generalised force at q on the
            free coordinates but the actuated ones [N m, N] (the actuators' springs hold
            theirs at ``commands`` by construction).
        iterations: Newton iterations.
        matrices: Newton matrices formed (the iterations between them chord steps).
    """

    q: np.ndarray
    commands: np.ndarray
    task_residual: float
    closure_residual: float
    force_residual: float
    iterations: int
    matrices: int


def compensate(
    clm: ClosedLoopModel,
    frame: str,
    task: FrameTask,
    q_rest: np.ndarray,
    load: Load,
    guess: np.ndarray,
) -> Compensation:
    """The commands whose equilibrium under ``load`` meets ``task`` (module docstring).

    Args:
        clm: the model.
        frame: the loaded frame, which meets the task.
        task: the rows to meet (its target: the pose the frame is to hold under the load).
        q_rest: (nq,) the unloaded configuration: the rest values of every spring but the
            actuators'.
        load: the wrench at the frame and the weight.
        guess: (nq,) start of Newton (the uncompensated equilibrium, or the last points'
            compensated ones extrapolated along the path, :func:`extrapolated`).

    Raises:
        EquilibriumError: Newton does not converge in :data:`MAX_ITER` iterations (the
            actuators do not control the task's rows there, or the load is beyond a limit
            load); the message gives the residuals reached.
    """
    held = held_model(clm)
    eqs = EquilibriumEquations(held, q_rest, frame)
    units, free, A = eqs.units, eqs.free, clm.actuated_v_indices
    unknown = np.concatenate([free, A])
    cols = units.coords[unknown]
    task_scale = np.where(task.linear, clm.length, 1.0)
    row_tol = units.rows * CLOSURE_TOL
    q, fid = np.array(guess, dtype=float), clm.frame_id(frame)
    # the Newton matrix (with its basis), the last iterate's residual, the matrices formed
    system, last, matrices = None, math.inf, 0
    for it in range(MAX_ITER + 1):
        st = eqs.evaluate(q, load)  # the kinematics of q in held.data
        M = held.data.oMf[fid]
        t = task.residual(M) / task_scale
        done = closed(st, row_tol) and float(np.max(np.abs(t), initial=0.0)) <= TASK_TOL
        if done and balanced(st, eqs.free_scales):
            break
        if it == MAX_ITER:
            raise EquilibriumError(
                f"the deflection of frame {frame!r} of {clm.name!r} under the load cannot be "
                f"compensated: Newton on the actuated values did not converge in {MAX_ITER} "
                f"iterations (task rows left {np.max(np.abs(t)):.3g}, scaled); the actuators "
                "may not control the task's rows there",
                st["closure"],
                st["force"],
                1.0,
            )
        rhs = None if system is None else _rhs(eqs, st, system, t)
        if rhs is None or not float(np.max(np.abs(rhs))) <= CHORD_RATE * last:
            # the first iterate, or a chord that stalls: a fresh tangent
            system = _matrix(held, eqs, q, load, st, task, M, unknown, cols, task_scale)
            rhs, matrices = _rhs(eqs, st, system, t), matrices + 1
        last = float(np.max(np.abs(rhs)))
        step = np.zeros(clm.model.nv)
        step[unknown] = cols * min_norm_solve(system[0], -rhs)
        ratio = float(np.max(np.abs(step[unknown]) / (MAX_STEP * cols), initial=0.0))
        if ratio > 1.0:
            step /= ratio
        q = pin.integrate(clm.model, q, step)
        size = float(np.max(np.abs(step[unknown]) / cols, initial=0.0))
        if done and ratio <= 1.0 and size <= STEP_TOL * max(1.0, np.max(np.abs(q) / units.q)):
            st = eqs.evaluate(q, load)  # converged to rounding: the force test cannot tell
            t = task.residual(held.data.oMf[fid]) / task_scale
            break
    J = frame_jacobian(held, q, frame, "world", update=False)
    f_A = (st["Jc"].T @ st["lam"] - eqs.generalised_load(q, load, J))[A]
    k_A = clm.stiffness[A]
    commands = clm.actuated_values(q) + np.where(np.isinf(k_A), 0.0, f_A / k_A)
    return Compensation(
        q=q,
        commands=commands,
        task_residual=float(np.max(np.abs(t * task_scale), initial=0.0)),
        closure_residual=st["closure"],
        force_residual=st["force"],
        iterations=it,
        matrices=matrices,
    )


def _matrix(held, eqs, q, load, st, task, M, unknown, cols, task_scale) -> tuple:
    """(matrix, B, scale) of a Newton step of :func:`compensate` at q on the ``unknown``
    coordinates (the held model's free ones, then the actuated ones), scaled by ``cols``:
    the closures' rows, the equilibrium's on the held model's admissible motions B (on the
    scale of its stiffest spring, :meth:`EquilibriumEquations.motions`) with the held
    model's tangent stiffness, and the task's, stacked; solved by minimum-norm least squares
    (where the actuators leave freedom)."""
    free, units = eqs.free, eqs.units
    J = frame_jacobian(held, q, eqs.frame, "world", update=False)
    H = tangent_stiffness(
        held, q, eqs.q_rest, eqs.frame, load.wrench, st["lam"], gravity=load, update=False
    )
    B, scale = eqs.motions(st)
    rows = [
        st["Jc"][:, unknown] * cols / units.rows[:, None],
        B.T @ (eqs.free_scales[:, None] * H[np.ix_(free, unknown)] * cols) / scale,
        task.jacobian(M, J)[:, unknown] * cols / task_scale[:, None],
    ]
    return np.vstack(rows), B, scale


def _rhs(eqs, st: dict, system: tuple, task_rows: np.ndarray) -> np.ndarray:
    """The residuals that a step of ``system`` (:func:`_matrix`) cancels: the closures,
    the unbalanced force on the motions B of the system (zero at equilibrium whatever the
    basis, so that a matrix of an earlier iterate still applies: a chord step) and the
    task's rows (scaled, ``task_rows``)."""
    _, B, scale = system
    unbalanced = B.T @ (eqs.free_scales * st["unbalanced"]) / scale
    return np.concatenate([st["c"] / eqs.units.rows, unbalanced, task_rows])

"""Nonlinear static equilibrium under a finite dead-load wrench at a frame.

The wrench w = (f [N], n [N m]) acts at the origin of a frame, with both the force and the
moment fixed in world axes while the frame moves (a dead load). The springs of the model
store 1/2 sum_i k_i dq_i^2 with dq = ``pin.difference(model, q_rest, q)`` on the spring
coordinates; their rest configuration q_rest is the assembled configuration at which the
load is applied. Locked coordinates (k = inf, including actuated joints without a spring)
keep their values of q_rest; passive ones (k = 0) follow the closures.

A moment fixed in world axes is not conservative under finite rotations, so the solver
works on the equilibrium equations (virtual work) rather than on an energy:

    F(q, lambda) = g(q) - J(q)^T w + J_c(q)^T lambda = 0,   c(q) = 0,

with g = Jd^T K_q dq the spring forces (Jd = d dq/dq, 1 for 1-dof joints), J (6, nv) the
frame Jacobian (world-aligned axes, at the frame origin), c (m,) the stacked closure
residuals, J_c their Jacobian and lambda (m,) the multipliers. Each Newton step splits the
free coordinates by an SVD of J_c into its row space (a minimum-norm Gauss-Newton step
that restores the closures; redundant closure rows only lower the rank) and its null
space N (a Newton step on N^T F with the tangent stiffness of
:func:`closedloop.preload.tangent_stiffness`). The multipliers are the least-squares
ones, lambda = -(J_c^T)^+ g_F with g_F = g - J^T w: the part of the closure forces that
redundant rows leave statically indeterminate is set to zero (minimum norm). The load is
followed from zero (continuation): each increment starts from the tangent prediction
dq = N K_t^-1 N^T J^T dw, is sized so that this prediction stays small, and is halved
when Newton fails, so that the solution stays on the branch that starts at q_rest
(past a limit load, where K_t turns singular, no equilibrium is found on it).

For a pure force the equilibrium is a stationary point of :func:`potential_energy` on the
closure manifold, an independent check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .arrays import check_wrench, readonly
from .compliance import spring_subspace
from .exceptions import EquilibriumError, InvalidInputError
from .kinematics import (
    RANK_RTOL,
    closure_jacobian,
    closure_residual,
    frame_jacobian,
    update_kinematics,
)
from .model import ClosedLoopModel
from .preload import tangent_stiffness

#: Closure tolerance of the equilibrium (infinity norm) [m for points; m, rad for welds].
CLOSURE_TOL = 1e-12
#: Relative tolerance on the unbalanced generalised force (see :func:`solve_equilibrium`).
FORCE_RTOL = 1e-11
#: Newton step [rad or m], relative to max(1, |q|), after which q counts as converged.
STEP_TOL = 1e-12
#: Largest closure residual accepted in the rest configuration [m, rad].
REST_TOL = 1e-8


@dataclass(frozen=True)
class Equilibrium:
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
        multipliers: (m,) closure multipliers lambda, one per closure row; for a point
            closure, the force [N] that side 2 exerts on side 1 at the anchor, in the axes
            of the side-1 anchor frame; for a weld, the wrench [N, N m] conjugate to its
            log6 residual rows. Minimum-norm when closure rows are redundant (no self-stress).
        closure_residual: infinity norm of the closure residual at q [m, rad].
        force_residual: infinity norm of the unbalanced generalised force
            (g - J^T w + J_c^T lambda on the free coordinates) [N m, N].
        iterations: Newton iterations, all load increments together.
        load_steps: load increments used (1 when the full load converged at once).
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

    @property
    def displacement(self) -> np.ndarray:
        """(6,) (translation [m], rotation vector [rad]) of the frame, world axes."""
        return np.concatenate([self.translation, self.rotation])


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
    clm: ClosedLoopModel, q: np.ndarray, q_rest: np.ndarray, frame: str, force: np.ndarray
) -> float:
    """Potential energy [J] of the springs and of a dead-load force at a frame origin.

    ``1/2 sum k_i dq_i^2 - f . (p(q) - p(q_rest))`` over the spring coordinates
    (0 < k < inf), dq = difference(q_rest, q). A world-fixed moment has no potential.

    Args:
        force: (3,) force [N], world axes, at the origin of ``frame``.
    """
    f = np.asarray(force, dtype=float).reshape(-1)
    if f.shape != (3,):
        raise InvalidInputError(f"force must be 3 values (fx fy fz), got {f.size}")
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    dq = pin.difference(clm.model, q_rest, q)
    dp = frame_displacement(clm, q, q_rest, frame)[:3]
    return float(0.5 * np.sum(k * dq * dq) - f @ dp)


class _Statics:
    """Equilibrium equations of one model, frame, wrench and rest configuration."""

    def __init__(self, clm: ClosedLoopModel, q_rest: np.ndarray, frame: str):
        self.clm, self.q_rest, self.frame = clm, q_rest, frame
        self.k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
        self.free = np.flatnonzero(np.isfinite(clm.stiffness))

    def evaluate(self, q: np.ndarray, w: np.ndarray) -> dict:
        """Residuals, multipliers and the SVD of the closure Jacobian at q under w."""
        clm, free = self.clm, self.free
        update_kinematics(clm, q)
        c = closure_residual(clm, q, update=False)
        A = closure_jacobian(clm, q, update=False)[:, free]
        J = frame_jacobian(clm, q, self.frame, "world", update=False)
        dq = pin.difference(clm.model, self.q_rest, q)
        Jd = pin.dDifference(clm.model, self.q_rest, q, pin.ARG1)
        g = Jd.T @ (self.k * dq)
        load = J.T @ w
        F = (g - load)[free]
        if A.size:
            U, s, Vt = np.linalg.svd(A, full_matrices=True)
            r = int(np.sum(s > RANK_RTOL * s[0])) if s[0] > 0 else 0
        else:
            U, s, Vt, r = np.zeros((A.shape[0], 0)), np.zeros(0), np.eye(free.size), 0
        Ur, sr, R, N = U[:, :r], s[:r], Vt[:r].T, Vt[r:].T
        lam = -Ur @ ((R.T @ F) / sr)
        unbalanced = F - R @ (R.T @ F)  # F + A^T lam: its component along N
        scale = max(np.max(np.abs(g[free]), initial=0.0), np.max(np.abs(load[free]), initial=0.0))
        return {
            "c": c,
            "closure": float(np.max(np.abs(c), initial=0.0)),
            "F": F,
            "force": float(np.max(np.abs(unbalanced), initial=0.0)),
            "force_tol": FORCE_RTOL * scale,
            "lam": lam,
            "Ur": Ur,
            "sr": sr,
            "R": R,
            "N": N,
        }

    def step(self, q, w, st: dict, load: np.ndarray | None = None) -> np.ndarray:
        """(nv,) tangent step at q (state ``st`` of :meth:`evaluate` under w).

        Without ``load``: the Newton step, a minimum-norm Gauss-Newton correction of the
        closures plus the Newton step of N^T F on the admissible motions. With ``load``
        (6,): the rate dq/ds of the equilibrium when the wrench grows by s ``load``.
        """
        free = self.free
        H = tangent_stiffness(self.clm, q, self.q_rest, self.frame, w, st["lam"], update=False)
        H = H[np.ix_(free, free)]
        R, N = st["R"], st["N"]
        if load is None:
            dx = -R @ ((st["Ur"].T @ st["c"]) / st["sr"])  # restores the closures
            rhs = -N.T @ (st["F"] + H @ dx)
        else:
            J = frame_jacobian(self.clm, q, self.frame, "world", update=False)
            dx, rhs = np.zeros(free.size), N.T @ (J.T @ load)[free]
        dx += N @ np.linalg.lstsq(N.T @ H @ N, rhs, rcond=1e-12)[0]
        v = np.zeros(self.clm.model.nv)
        v[free] = dx
        return v

    def newton(self, q, w, *, tol: float, max_iter: int, max_step: float):
        """Newton iterations at a fixed wrench; returns (q or None, state, iterations)."""
        st = self.evaluate(q, w)
        for it in range(max_iter + 1):
            if st["closure"] <= tol and st["force"] <= st["force_tol"]:
                return q, st, it
            if it == max_iter:
                break
            v = self.step(q, w, st)
            size = np.max(np.abs(v), initial=0.0)
            if not np.isfinite(size):
                break
            if size > max_step:
                v *= max_step / size
            q = pin.integrate(self.clm.model, q, v)
            st = self.evaluate(q, w)
            if not (np.isfinite(st["closure"]) and np.isfinite(st["force"])):
                break
            if st["closure"] <= tol and size <= STEP_TOL * max(1.0, np.max(np.abs(q))):
                return q, st, it + 1  # Newton converges quadratically: q is at rounding level
        return None, st, max_iter


def solve_equilibrium(
    clm: ClosedLoopModel,
    q_rest: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    *,
    tol: float = CLOSURE_TOL,
    max_iter: int = 30,
    max_halvings: int = 12,
    max_step: float = 0.5,
    max_increment: float = 0.1,
) -> Equilibrium:
    """Static equilibrium of the mechanism under a dead-load wrench at ``frame``.

    Converged when the closure residual is below ``tol`` and the unbalanced generalised
    force on the admissible motions is below ``FORCE_RTOL`` times the largest spring or
    load generalised force, or (when rounding in the spring forces prevents that) after a
    Newton step below ``STEP_TOL`` max(1, |q|_inf); Newton converging quadratically, q is
    then exact to rounding.

    Args:
        clm: model with closures and springs.
        q_rest: (nq,) assembled configuration, rest configuration of the springs.
        frame: name of the loaded frame.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin,
            fixed in world axes while the frame moves.
        tol: closure tolerance (infinity norm) [m, rad].
        max_iter: Newton iterations per load increment.
        max_halvings: how many times a failed load increment may be halved.
        max_step: largest Newton step (infinity norm) [rad or m].
        max_increment: largest predicted joint motion per load increment (infinity
            norm) [rad or m]; larger deflections are followed in several increments.

    Raises:
        InvalidInputError: a wrench that is not 6 finite values, a bad q_rest, or a q_rest
            that violates the closures.
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame (no equilibrium).
        EquilibriumError: Newton failed even with the smallest load increment; the error
            carries the residuals reached.
    """
    w = check_wrench(wrench)
    q_rest = clm.check_configuration(q_rest)
    clm.frame_id(frame)  # unknown frame: NameNotFoundError before any work
    r0 = float(np.max(np.abs(closure_residual(clm, q_rest)), initial=0.0))
    if r0 > REST_TOL:
        raise InvalidInputError(
            f"q_rest violates the closures by {r0:.3e} (> {REST_TOL:g}); assemble it first "
            "(closedloop.assembly.assemble)"
        )
    spring_subspace(clm, q_rest, frame_jacobian(clm, q_rest, frame, update=False), frame)
    statics = _Statics(clm, q_rest, frame)
    q, t, dt, iterations, steps, halvings = q_rest.copy(), 0.0, 1.0, 0, 0, 0
    while t < 1.0:
        st = statics.evaluate(q, t * w)  # also the kinematics of q, after a failed attempt
        rate = statics.step(q, t * w, st, load=w) if np.any(w) else np.zeros(clm.model.nv)
        ds = min(dt, 1.0 - t)
        speed = float(np.max(np.abs(rate), initial=0.0))
        if speed * ds > max_increment:
            ds = max_increment / speed
        s_try = 1.0 if t + ds >= 1.0 - 1e-12 else t + ds
        guess = pin.integrate(clm.model, q, (s_try - t) * rate) if np.any(rate) else q
        q_new, st_try, it = statics.newton(
            guess, s_try * w, tol=tol, max_iter=max_iter, max_step=max_step
        )
        iterations += it
        if q_new is None:
            halvings += 1
            if halvings > max_halvings:
                raise EquilibriumError(
                    f"no static equilibrium found for wrench {w.tolist()} at frame {frame!r} "
                    f"of {clm.name!r} (a limit load, where the tangent stiffness turns "
                    "singular, ends the branch that starts at q_rest)",
                    st_try["closure"],
                    st_try["force"],
                    t,
                )
            dt = 0.5 * ds
            continue
        q, st, t, steps, dt = q_new, st_try, s_try, steps + 1, 2.0 * ds
    disp = frame_displacement(clm, q, q_rest, frame)  # leaves the kinematics of q in clm.data
    return Equilibrium(
        q=readonly(q),
        q_rest=readonly(q_rest),
        frame=frame,
        wrench=readonly(w),
        translation=readonly(disp[:3]),
        rotation=readonly(disp[3:]),
        joint_deflection=readonly(pin.difference(clm.model, q_rest, q)),
        multipliers=readonly(st["lam"]),
        closure_residual=st["closure"],
        force_residual=st["force"],
        iterations=iterations,
        load_steps=max(steps, 1),
    )

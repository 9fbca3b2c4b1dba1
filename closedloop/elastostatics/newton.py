"""Newton iterations at a fixed load, the inner loop of the nonlinear statics
(:func:`closedloop.elastostatics.statics.solve_equilibrium`), and their convergence tests.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.elastostatics.equations import EquilibriumEquations

#: Relative tolerance on the unbalanced generalised force
#: (see :func:`~closedloop.solve_equilibrium`).
FORCE_RTOL = 1e-11
#: Newton step [rad, and lengths in units of L], relative to max(1, ``|q|``) (q in the same
#: units), after which q counts as converged.
STEP_TOL = 1e-12

#: How the iterations of :func:`newton` failed, for the advice of the error
#: (:func:`closedloop.elastostatics.continuation.advice`): out of iterations while their
#: steps still shrank; stalled at the rounding of the equations (:data:`STALL_STEP`); their
#: steps still cut to ``max_step`` at the end; gone off (beyond the radius, overflowing).
CONVERGING, STALLED, CAPPED, WANDERED = "converging", "stalled", "capped", "wandered"
#: The iterations have stalled when their last STALL_ITERS steps are no smaller than half
#: the smallest before them and that one is below STALL_STEP [rad, and lengths in units
#: of L]: Newton, converging quadratically, would have gone from such a step to the
#: rounding in one or two; its steps then wander at the rounding of the equations (a
#: coupled 6x6 spring of 1e9 beside 20 N m/rad evaluated as a product left steps of 1e-10
#: rad that no iteration count or load increment got below).
STALL_ITERS, STALL_STEP = 3, 1e-8


def newton(eqs: EquilibriumEquations, q, w, *, row_tol, max_iter: int, step_limit, radius):
    """Newton iterations at a fixed wrench; returns (q or None, state, iterations, how),
    ``how`` '' on success, else how they failed (:data:`CONVERGING`, :data:`STALLED`,
    :data:`CAPPED`, :data:`WANDERED`).

    Args:
        row_tol: (m,) closure tolerance of each row [m, rad]; step_limit: (nv,) largest
            step of each coordinate [rad, m]; radius: the iterations stop (None) when they
            leave this distance from the start (:func:`distance`): bound for another
            branch.
    """
    units, start = eqs.units, q
    st = eqs.evaluate(q, w)
    sizes, capped = [], False  # the steps [rad, L]
    for it in range(max_iter + 1):
        if closed(st, row_tol) and balanced(st, eqs.free_scales):
            return q, st, it, ""
        if it == max_iter:
            break
        v, dropped = eqs.step(q, w, st)
        ratio = np.max(np.abs(v) / step_limit, initial=0.0)
        if not np.isfinite(ratio):
            return None, st, max_iter, WANDERED
        capped = ratio > 1.0  # a cut step says nothing of the distance to the solution
        if capped:
            v /= ratio
        q = pin.integrate(eqs.clm.model, q, v)
        if distance(eqs, start, q) > radius:
            return None, st, max_iter, WANDERED
        st = eqs.evaluate(q, w)
        if not (np.isfinite(st["closure"]) and np.isfinite(st["force"])):
            return None, st, max_iter, WANDERED
        sizes.append(np.max(np.abs(v) / units.coords, initial=0.0))
        if (
            not capped
            and closed(st, row_tol)
            and sizes[-1] <= STEP_TOL * max(1.0, np.max(np.abs(q) / units.q))
            and not dropped  # a step that resolved every direction: q is at rounding
        ):  # level (Newton converges quadratically); else the force test decides
            return q, st, it + 1, ""
    return None, st, max_iter, CAPPED if capped else _how_ended(sizes)


def _how_ended(sizes: list) -> str:
    """STALLED when the steps (their sizes [rad, L], in order) stopped shrinking at the
    rounding (:data:`STALL_ITERS`), else CONVERGING (also when too few to tell)."""
    before, last = sizes[:-STALL_ITERS], sizes[-STALL_ITERS:]
    if before and min(before) <= STALL_STEP and min(last) >= 0.5 * min(before):
        return STALLED
    return CONVERGING


def closed(st: dict, row_tol: np.ndarray) -> bool:
    """Every closure row within its tolerance."""
    return bool(np.all(np.abs(st["c"]) <= row_tol))


def balanced(st: dict, coords: np.ndarray) -> bool:
    """The unbalanced generalised force below FORCE_RTOL times the largest spring or load
    one, each a force times the scale of its coordinate (N m, N L)."""
    scale = max(
        np.max(np.abs(st["spring"]) * coords, initial=0.0),
        np.max(np.abs(st["load"]) * coords, initial=0.0),
    )
    return bool(np.max(np.abs(st["unbalanced"]) * coords, initial=0.0) <= FORCE_RTOL * scale)


def distance(eqs: EquilibriumEquations, a: np.ndarray, b: np.ndarray) -> float:
    """Infinity norm of difference(a, b) [rad, and lengths in units of L]."""
    d = pin.difference(eqs.clm.model, a, b) / eqs.units.coords
    return float(np.max(np.abs(d), initial=0.0))

"""Newton iterations at a fixed load, the inner loop of the nonlinear statics
(:func:`closedloop.elastostatics.statics.solve_equilibrium`), and their convergence tests.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.elastostatics.equations import EquilibriumEquations

#: Relative tolerance on the unbalanced generalised force (see :func:`solve_equilibrium`).
FORCE_RTOL = 1e-11
#: Newton step [rad, and lengths in units of L], relative to max(1, |q|) (q in the same
#: units), after which q counts as converged.
STEP_TOL = 1e-12


def newton(eqs: EquilibriumEquations, q, w, *, row_tol, max_iter: int, step_limit, radius):
    """Newton iterations at a fixed wrench; returns (q or None, state, iterations).

    Args:
        row_tol: (m,) closure tolerance of each row [m, rad]; step_limit: (nv,) largest
            step of each coordinate [rad, m]; radius: the iterations stop (None) when they
            leave this distance from the start (:func:`distance`): bound for another
            branch.
    """
    units, start = eqs.units, q
    st = eqs.evaluate(q, w)
    for it in range(max_iter + 1):
        if closed(st, row_tol) and balanced(st, eqs.free_scales):
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
        if distance(eqs, start, q) > radius:
            break
        st = eqs.evaluate(q, w)
        if not (np.isfinite(st["closure"]) and np.isfinite(st["force"])):
            break
        size = np.max(np.abs(v) / units.coords, initial=0.0)
        if (
            not capped
            and closed(st, row_tol)
            and size <= STEP_TOL * max(1.0, np.max(np.abs(q) / units.q))
            and not dropped  # a step that resolved every direction: q is at rounding
        ):  # level (Newton converges quadratically); else the force test decides
            return q, st, it + 1
    return None, st, max_iter


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

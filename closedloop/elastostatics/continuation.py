"""The load increments of the nonlinear statics along the branch from rest
(:func:`closedloop.elastostatics.statics.solve_equilibrium`): the tangent rate of the branch,
the refusal of a jump to another branch, the distance to a fold, and the error when the
continuation fails (a limit load or not).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.elastostatics.equations import EquilibriumEquations
from closedloop.elastostatics.newton import CAPPED, CONVERGING, STALLED, WANDERED, distance
from closedloop.exceptions import EquilibriumError

#: Error of tau (absolute: M is 1 unloaded; the weld curvature by central differences
#: carries 1e-10 of it): a fall of tau^2 below TAU_NOISE (2 ``|tau|`` + TAU_NOISE) is rounding,
#: not a trend to extrapolate.
TAU_NOISE = 1e-9


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


#: The continuation stopped after :data:`closedloop.elastostatics.statics.MAX_LOAD_STEPS`
#: increments (a kind of failure beside those of :func:`~closedloop.elastostatics.newton.newton`).
LONG = "long"
#: What helps after each kind of failure: followed, the continuation reaches further on
#: the same branch (the jump tests refuse any other) or fails again.
ADVICE = {
    CONVERGING: "try a larger max_iter (Newton was still converging when its iterations ran "
    "out) or a smaller max_increment",
    CAPPED: "try a larger max_step (Newton's steps were still cut to it when its iterations "
    "ran out)",
    WANDERED: "try a smaller max_increment or a larger max_halvings (Newton went off from "
    "the prediction of the smallest increment allowed, or converged away from it)",
    STALLED: "Newton stalls at the rounding of the equations (its steps no longer shrink), "
    "which neither more iterations nor smaller increments get below",
    LONG: "give a smaller load or a larger max_increment",
}


def advice(eqs: EquilibriumEquations, q, how: str) -> str:
    """What to try after a failed continuation that ended as ``how`` says (a key of
    :data:`ADVICE`; '' gives that of a :data:`WANDERED` failure), unless the part of the
    load reached already turns a joint coordinate by a radian or more (a load far beyond
    the springs, which no option helps)."""
    clm = eqs.clm
    turn = np.where(clm.linear_coordinates, 0.0, np.abs(pin.difference(clm.model, eqs.q_rest, q)))
    i = int(np.argmax(turn)) if turn.size else 0
    if turn.size and turn[i] >= 1.0:
        return (
            f"the part of the load reached already turns joint {clm.coordinate_joint(i)!r} by "
            f"{turn[i]:.3g} rad from rest: the load is far beyond what the springs hold; "
            "expected a smaller load"
        )
    return ADVICE[how or WANDERED]


def branch_rate(eqs: EquilibriumEquations, q, t: float, w, st: dict) -> np.ndarray:
    """(nv,) dq/ds at the equilibrium q under t w (state ``st``) as the load grows by s w
    [rad or m per unit of load fraction]; zero without load."""
    return eqs.step(q, t * w, st, load=w)[0] if w.any() else np.zeros(eqs.clm.model.nv)


def fold_distance(history) -> float:
    """Load fraction still to go to where tau (:meth:`EquilibriumEquations.stability`)
    vanishes: a Newton step on tau^2, its slope at the last equilibrium that of the parabola
    through the last three (t, tau) pairs of ``history`` (the chord through two if only
    two); inf when ``|tau|`` does not fall (beyond its rounding, TAU_NOISE) or has changed
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


def allowed_corrector(eqs: EquilibriumEquations, q: np.ndarray, guess: np.ndarray) -> float:
    """Largest corrector of an increment from the equilibrium q predicted at ``guess``
    (both (nq,)) [rad, and lengths in units of L]: JUMP_RATIO of the predictor, plus the
    resolution of the equilibria (JUMP_FLOOR, JUMP_RTOL)."""
    rounding = JUMP_FLOOR + JUMP_RTOL * distance(eqs, eqs.q_rest, guess)
    return JUMP_RATIO * distance(eqs, q, guess) + rounding


def jump(eqs: EquilibriumEquations, points, taus, allowed: float, across: bool) -> str:
    """Why an increment that converged is refused ('' when it is not).

    Args:
        points: (q, guess, q_new, back): the last equilibrium, the prediction Newton
            started from, its answer, and the prediction from q_new back to the last load
            fraction along its own tangent, (nq,) each.
        allowed: the largest corrector (:func:`allowed_corrector`).
        taus: tau at q and at q_new; across: whether the increment may step across a
            singularity (one extrapolated within it): a sign change of det M is allowed
            only then.
    """
    q, guess, q_new, back = points
    if distance(eqs, guess, q_new) > allowed or distance(eqs, back, q) > allowed:
        return "Newton converged away from the predicted equilibrium (on another branch)"
    if taus[0] * taus[1] <= 0.0 and not across:
        return "the tangent stiffness turned singular within the increment"
    return ""


def failure(
    eqs: EquilibriumEquations, q, t, s_fail, w, where, detail, iterations, state, history, how
):
    """EquilibriumError after a failed continuation, limit load or not (its ``limit_load``).

    (q, t): the last equilibrium and its load fraction; ``s_fail`` the load fraction that
    failed; ``state``: the
    :meth:`~closedloop.elastostatics.equations.EquilibriumEquations.evaluate` state whose
    residuals the error reports; ``history``: (t, tau) of the last three equilibria;
    ``how``: how the last failed increment failed (:func:`advice`). A limit load when tau
    extrapolates to zero within the failed increment: the fold is bracketed by
    [t, s_fail].
    """
    margin, tau = eqs.stability(q, t * w)
    fold = fold_distance(history)
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
            f"{advice(eqs, q, how)}"
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

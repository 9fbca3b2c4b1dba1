"""The nonlinear statics never leave the branch that starts at rest (issue #32).

Past a limit load (a fold) the branch from rest ends: the solver raises an
EquilibriumError with ``limit_load`` and a bracket of the fold's load, where it used to
jump to an equilibrium of another branch and return it (CaHyMan near a leg singularity:
M moved 8 times its deflection at the fold, silently) or to call the fold a failure of
Newton, whose advice led to that jump. Independent checks: the equilibrium equations
written here from Pinocchio's kinematics alone (spring forces, the frame Jacobian's
virtual work, the world gaps of the ball closures with their point Jacobians) and solved
by Newton with finite-difference derivatives, along the load from rest; and the solver's
own answers along ten times finer increments, which cannot share a jump of the default
increments.
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

import closedloop as cl
from closedloop.elastostatics.statics import FOLD_RTOL, solve_equilibrium
from closedloop.io.loader import load_urdf
from closedloop.kinematics.assembly import close_at

#: The issue's pose and load direction: CaHyMan at alpha = (2, 60, 75) deg, alpha4 = 45
#: deg, s4 = 0, the wrench s * U at M (about its softest direction there).
ISSUE_ALPHA_DEG, ISSUE_ALPHA4_DEG = (2.0, 60.0, 75.0), 45.0
U = np.array([0.0217, 0.138, -0.1868, -0.4642, 0.7863, 0.3345])
#: The fold of the branch from rest along U, as the issue measured it (s ~ 0.337).
ISSUE_FOLD = 0.337
#: Agreement of two converged equilibria (joint deflections, relative to the largest):
#: each balances its forces to 1e-11 of the largest (FORCE_RTOL; here to 1e-12 by the
#: independent Newton), and the tangent stiffness, at least 0.3 of the springs' on the
#: tested branches (margin 0.55 at s = 0.30), amplifies that by about 3: 1e-8 leaves a
#: factor 100 for the coupling of stiff and soft joints (springs 876 to 2.6e6), while a
#: jump to another branch moves the joints by their whole deflection.
RTOL_SAME = 1e-8


# ---------------------------------------------------------------- independent equations
def _point_jacobian(model, data, joint: int, point: np.ndarray) -> np.ndarray:
    """(3, nv) Jacobian of a point fixed on ``joint``, world axes: v_p = v_o + w x (p - o)
    from Pinocchio's LOCAL_WORLD_ALIGNED joint Jacobian (velocity of the joint origin o)."""
    J = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
    r = point - data.oMi[joint].translation
    skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return J[:3] - skew @ J[3:]


def _residual(clm, q_rest, frame, wrench, v, lam):
    """Equilibrium equations at q = integrate(q_rest, v): (forces on the free coordinates
    [N m, N], closure gaps [m]) and the gap Jacobian (m, nv)."""
    model, data = clm.model, model_data(clm)
    q = pin.integrate(model, q_rest, v)
    pin.forwardKinematics(model, data, q)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = pin.getFrameJacobian(model, data, model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED)
    gaps, rows = [], []
    for closure in clm.closures:
        c = closure.constraint
        p1 = data.oMi[c.joint1_id].act(c.joint1_placement.translation)
        p2 = data.oMi[c.joint2_id].act(c.joint2_placement.translation)
        gaps.append(p2 - p1)
        rows.append(
            _point_jacobian(model, data, c.joint2_id, p2)
            - _point_jacobian(model, data, c.joint1_id, p1)
        )
    A = np.vstack(rows)
    k = np.where(np.isfinite(clm.stiffness), clm.stiffness, 0.0)
    force = k * pin.difference(model, q_rest, q) - J.T @ wrench + A.T @ lam
    free = np.isfinite(clm.stiffness)
    return force[free], np.concatenate(gaps), A


def model_data(clm):
    """A Data of the model's own, apart from the solver's."""
    return clm.memo("independent_data", lambda: clm.model.createData())


def independent_equilibrium(clm, q_rest, frame, wrench, v, *, iterations=12):
    """Newton on the equations of :func:`_residual` from the deflection v (nv,), the
    derivatives with respect to v by central differences; returns (v, lam, reduced
    tangent stiffness on the motions that keep the loops closed)."""
    free = np.flatnonzero(np.isfinite(clm.stiffness))
    scale = np.max(clm.stiffness[free])  # forces and multipliers on the scale of 1
    v, lam = np.array(v, dtype=float), np.zeros(clm.n_constraints)
    for _ in range(iterations + 1):
        f, gap, A = _residual(clm, q_rest, frame, wrench, v, lam)
        D = np.zeros((f.size + gap.size, free.size))  # d(forces / scale, gaps) / dv
        for j, i in enumerate(free):
            h = np.zeros_like(v)
            h[i] = 1e-7
            fp, gp, _ = _residual(clm, q_rest, frame, wrench, v + h, lam)
            fm, gm, _ = _residual(clm, q_rest, frame, wrench, v - h, lam)
            D[:, j] = np.concatenate([(fp - fm) / scale, gp - gm]) / 2e-7
        # unknowns: dv on the free coordinates, d lam / scale
        K = np.hstack([D, np.vstack([A[:, free].T, np.zeros((gap.size, gap.size))])])
        step = np.linalg.lstsq(K, -np.concatenate([f / scale, gap]), rcond=1e-13)[0]
        v[free] += step[: free.size]
        lam += step[free.size :] * scale
        if np.max(np.abs(step[: free.size])) < 1e-14:
            break
    null = np.linalg.svd(A[:, free])[2][np.linalg.matrix_rank(A[:, free]) :].T
    return v, lam, null.T @ D[: f.size] @ null * scale


def smallest_singular(K: np.ndarray) -> float:
    return float(np.linalg.svd(K, compute_uv=False)[-1])


def independent_path(clm, q_rest, frame, wrench, steps: int):
    """The deflection (nv,) under ``wrench``, followed from rest in ``steps`` equal load
    increments (each Newton solve from the previous equilibrium)."""
    v = np.zeros(clm.model.nv)
    for i in range(1, steps + 1):
        v, _, _ = independent_equilibrium(clm, q_rest, frame, i / steps * wrench, v)
    return v


def assert_same_deflection(actual, expected):
    np.testing.assert_allclose(actual, expected, rtol=0, atol=RTOL_SAME * np.max(np.abs(expected)))


# ---------------------------------------------------------------- the issue's cases
@pytest.fixture(scope="module")
def issue_pose(cahyman):
    q = np.array(cahyman.assemble(np.deg2rad(ISSUE_ALPHA_DEG), np.deg2rad(ISSUE_ALPHA4_DEG), 0.0))
    return cahyman.clm, q


def test_below_the_fold_the_answer_is_the_branch_from_rest(issue_pose):
    """s = 0.30: on the branch from rest, as an independent path from rest finds it."""
    clm, q = issue_pose
    eq = solve_equilibrium(clm, q, "M", 0.30 * U)
    expected = independent_path(clm, eq.q_rest, "M", 0.30 * U, steps=10)
    assert_same_deflection(eq.joint_deflection, expected)
    assert 1e-3 < np.linalg.norm(eq.translation) < 2e-3  # the issue's 1.3 mm


@pytest.fixture(scope="module")
def issue_folds(issue_pose):
    """The errors past the fold, for each load factor s of the issue (and beyond)."""
    clm, q = issue_pose
    errors = {}
    for s in (0.35, 0.40, 0.45, 0.50, 1.35):
        with pytest.raises(cl.EquilibriumError) as err:
            solve_equilibrium(clm, q, "M", s * U)
        errors[s] = err.value
    return errors


def test_past_the_fold_a_limit_load_is_raised_with_its_bracket(issue_folds):
    """s = 0.35 'converged' on another branch (M 10.3 mm away), s = 0.40 failed as no
    limit load: now each is a limit load, bracketed to FOLD_RTOL, all at one fold."""
    lows, highs = [], []
    for s, err in issue_folds.items():
        assert err.limit_load, (s, str(err))
        lo, hi = err.fold_bracket
        assert lo == err.load_fraction
        assert 0.0 < hi - lo <= FOLD_RTOL * lo + 1e-15  # the rounding of lo + FOLD_RTOL lo
        assert "a limit load (fold) between" in str(err)
        lows.append(s * lo)
        highs.append(s * hi)
    assert max(lows) <= min(highs)  # one fold, in every bracket
    assert abs(max(lows) - ISSUE_FOLD) < 1e-3


def test_the_fold_is_where_the_independent_stiffness_turns_singular(issue_pose, issue_folds):
    """At the bracket's lower end the solver's equilibrium is one of the independent
    equations, and their tangent stiffness on the closed-loop motions has lost all but
    1e-2 of what it has at rest: a singular point. There the solver's unbalanced force
    (its tolerance) moves the equilibrium by up to that force over the smallest
    stiffness (1e-6 of the deflection, not 1e-8): a factor 10 above it is allowed."""
    clm, q = issue_pose
    err = issue_folds[0.35]
    load = 0.35 * err.load_fraction * U
    eq = solve_equilibrium(clm, q, "M", load)
    v, _, K_fold = independent_equilibrium(clm, eq.q_rest, "M", load, eq.joint_deflection)
    bound = 10.0 * eq.force_residual / smallest_singular(K_fold)
    np.testing.assert_allclose(eq.joint_deflection, v, rtol=0, atol=bound)
    assert bound < 1e-4 * np.max(np.abs(v))
    _, _, K_rest = independent_equilibrium(clm, eq.q_rest, "M", 0.0 * U, np.zeros(clm.model.nv))
    assert smallest_singular(K_fold) < 1e-2 * smallest_singular(K_rest)


def test_a_margin_that_collapses_within_one_increment_is_a_limit_load(cahyman):
    """The issue's second case: "not a limit load (stability margin 0.129 > 0.1)", whose
    advice (max_iter=400) gave a silent jump. The issue's pose was given to 0.1 deg and
    without alpha4 and s4; alpha4 = 0, s4 = 0 reproduces the report with the previous
    solver (margin 0.130 at 0.590 of the load, 'not a limit load'). Now both runs stop at
    the same limit load."""
    q = np.array(cahyman.assemble(np.deg2rad([2.1, -12.0, -2.3]), 0.0, 0.0))
    w = np.array([1.0, 2.0, -3.0, 0.1, 0.0, 0.2])
    brackets = []
    for options in ({}, {"max_iter": 400}):
        with pytest.raises(cl.EquilibriumError, match="a limit load") as err:
            solve_equilibrium(cahyman.clm, q, "M", w, **options)
        assert err.value.limit_load
        brackets.append(err.value.fold_bracket)
    (lo1, hi1), (lo2, hi2) = brackets
    assert max(lo1, lo2) <= min(hi1, hi2)
    assert 0.55 < lo1 < 0.65


def test_cahyman_view_past_the_fold_is_a_one_line_error(capsys, tmp_path):
    """``cahyman view --nonlinear`` at s = 0.35 drew the other branch's equilibrium and
    exited 0."""
    from cahyman_pin.cli import main

    force = [f"{x:.6g}" for x in 0.35 * U[:3]]
    torque = [f"{x:.6g}" for x in 0.35 * U[3:]]
    status = main(
        ["view", "--alpha", *(f"{a:g}" for a in ISSUE_ALPHA_DEG), "--alpha4", "45",
         "--s4", "0", "--force", *force, "--torque", *torque, "--nonlinear",
         "--html", str(tmp_path / "v.html")]
    )  # fmt: skip
    out, err = capsys.readouterr()
    assert status == 3 and out == ""
    assert err.count("\n") == 1 and err.startswith("cahyman: error: no static equilibrium")
    assert "a limit load (fold) between" in err
    assert not (tmp_path / "v.html").exists()


# ---------------------------------------------------------------- property
def unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x)


def solve_or_error(clm, q, frame, wrench, **options):
    """The equilibrium, or the EquilibriumError, of a solve (joint-limit warnings off:
    the poses are drawn near singularities, where joints travel far)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cl.JointLimitWarning)
        try:
            return solve_equilibrium(clm, q, frame, wrench, **options)
        except cl.EquilibriumError as err:
            return err


def check_branch(clm, q, frame, wrench, finest: float) -> bool:
    """Every answer is that of a continuation along increments ten times finer (or
    more: ``max_increment`` = ``finest`` [rad or m]; the default is 0.1 rad and 0.1 L),
    or a limit load that the finer one brackets alike; below a fold found, at 0.9 of it,
    the answer is the finer one's. Returns whether a fold was found."""
    finer = {"max_increment": finest}
    coarse = solve_or_error(clm, q, frame, wrench)
    fine = solve_or_error(clm, q, frame, wrench, **finer)
    if isinstance(coarse, cl.Equilibrium):
        assert isinstance(fine, cl.Equilibrium), str(fine)
        assert_same_deflection(coarse.joint_deflection, fine.joint_deflection)
        return False
    assert coarse.limit_load, str(coarse)
    assert isinstance(fine, cl.EquilibriumError) and fine.limit_load, str(fine)
    (lo, hi), (lo_f, hi_f) = coarse.fold_bracket, fine.fold_bracket
    assert max(lo, lo_f) <= min(hi, hi_f), (coarse.fold_bracket, fine.fold_bracket)
    below = 0.9 * lo * np.asarray(wrench)
    eq = solve_or_error(clm, q, frame, below)
    eq_fine = solve_or_error(clm, q, frame, below, **finer)
    assert isinstance(eq, cl.Equilibrium) and isinstance(eq_fine, cl.Equilibrium)
    assert_same_deflection(eq.joint_deflection, eq_fine.joint_deflection)
    return True


def test_fourbar_answers_are_the_branch_from_rest_or_a_bracketed_fold():
    """Random crank angles (a full turn: the bundled four-bar is a crank-rocker,
    0.1 + 0.3 < 0.3 + 0.15, without a change point; its folds come from the loads) and
    random in-plane forces of 2000 N at P, past the folds of some directions (about
    1000 N at crank 0.3, 1600 N at 0.22 and 1.88). Finer increments: 0.01 rad, ten times
    finer in the angles, which carry the motion (the axial springs of 1e5 and 2e5 N/m
    move by millimetres; 0.01 m is 3.4 times finer than their 0.1 L)."""
    clm = load_urdf(REPO / "urdf" / "fourbar.urdf", REPO / "urdf" / "fourbar.yaml")
    rng = np.random.default_rng(3201)
    folds = 0
    for _ in range(4):
        crank = np.array([rng.uniform(0.0, 2.0 * np.pi)])  # one solve from neutral: either
        q = np.array(close_at(clm, pin.neutral(clm.model), crank).q)  # mode, folds on both
        direction = unit(np.array([rng.normal(), 0.0, rng.normal()]))
        wrench = np.r_[2000.0 * direction, 0.0, 0.0, 0.0]
        folds += check_branch(clm, q, "P", wrench, finest=0.01)
    assert folds >= 2  # the property is tested at folds, not only on smooth branches


def test_cahyman_answers_near_a_leg_singularity_are_the_branch_from_rest_or_a_fold(cahyman):
    """Poses near the issue's (alpha_1 of 1.5 to 3 deg: leg 1 near its singularity),
    random wrenches at M of the issue's size, 1.5 times the issue's fold load. Finer
    increments: 0.01 L, 10 times finer for the passive telescopes, 28 times for the
    angles."""
    rng = np.random.default_rng(3202)
    folds = 0
    for _ in range(2):
        alpha = np.deg2rad([rng.uniform(1.5, 3.0), rng.uniform(50, 70), rng.uniform(65, 85)])
        q = np.array(cahyman.assemble(alpha, np.deg2rad(rng.uniform(30, 60)), 0.0))
        wrench = np.r_[0.23 * unit(rng.normal(size=3)), 0.97 * unit(rng.normal(size=3))]
        folds += check_branch(cahyman.clm, q, "M", 0.5 * wrench, finest=0.01 * cahyman.clm.length)
    assert folds >= 1


def test_the_advice_of_a_newton_failure_leads_to_the_same_branch(fourbar):
    """Two Newton iterations an increment are too few for 300 N on the four-bar (below
    its fold, about 990 N along this direction): not a limit load, and the advice (more
    iterations, smaller increments) gives the answer of the finer continuation."""
    clm, q0 = fourbar
    w = np.array([300.0, 0, -300.0, 0, 0, 0])
    with pytest.raises(
        cl.EquilibriumError, match=r"try a larger max_iter .* or a smaller max_increment"
    ) as err:
        solve_equilibrium(clm, q0, "P", w, max_iter=2, max_halvings=2)
    assert not err.value.limit_load and err.value.fold_bracket is None
    fine = solve_or_error(clm, q0, "P", w, max_increment=0.01)
    for options in ({"max_iter": 30}, {"max_increment": 0.02}):
        eq = solve_or_error(clm, q0, "P", w, **{"max_iter": 2, "max_halvings": 2, **options})
        assert isinstance(eq, cl.Equilibrium), str(eq)
        assert_same_deflection(eq.joint_deflection, fine.joint_deflection)


def test_the_advice_when_newton_goes_off_leads_to_the_same_branch(fourbar):
    """900 N in one increment (max_increment inf) and no halving: Newton goes off from
    the linear prediction; the advice (a smaller max_increment, or a halving) gives the
    answer of the finer continuation, below the fold at about 990 N."""
    clm, q0 = fourbar
    w = np.array([900.0, 0, -900.0, 0, 0, 0])
    failing = {"max_halvings": 0, "max_increment": np.inf}
    err = solve_or_error(clm, q0, "P", w, **failing)
    assert isinstance(err, cl.EquilibriumError) and not err.limit_load
    assert "try a smaller max_increment or a larger max_halvings" in str(err)
    fine = solve_or_error(clm, q0, "P", w, max_increment=0.01)
    for options in ({"max_increment": 0.5}, {"max_halvings": 1}):
        eq = solve_or_error(clm, q0, "P", w, **{**failing, **options})
        assert isinstance(eq, cl.Equilibrium), str(eq)
        assert_same_deflection(eq.joint_deflection, fine.joint_deflection)

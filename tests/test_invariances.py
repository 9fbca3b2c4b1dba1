"""Invariance and property checks of the compliance that need no reference implementation.

Each test changes the question without changing its answer (or changes it in a known
way) and compares the library with itself, on the test mechanisms of
:mod:`mechanisms` (four-bar, CaHyMan, UR5, Stewart, 3-RRR, five-bar, Delta, a serial robot
with spring blocks) and at their edges (near-singular poses, springs from 1e-150 to
1e150, lengths from 1e-150 to 1e150 m):

* spring scaling: every spring times s divides C and G by s (both paths, the batch);
* unit scaling: every length times s, prismatic springs / s^2, gives D C D
  (D = diag(s, s, s, 1, 1, 1)), L times s, the same rank and condition number; with every
  spring also times s (a true change of the length unit) det K is unchanged;
* rigid motion of the world (at a given characteristic length): world-axes C turns as
  R6 C R6^T, local-axes C and det K do not change;
* order: closures permuted, their two frames swapped, springs listed in another order;
* batch: each row of ``compliances`` is the single query's, errors included;
* symmetry and definiteness: C symmetric PSD, C = J G, K C = I, energy shares sum to 1;
* threads: queries from 8 threads on shared models are bit-identical to serial ones.

Tolerances. Matrices are compared in the unit-free coordinates of the rank rule
(C_s = D_L C D_L, D_L = diag(1/L, 1/L, 1/L, 1, 1, 1)), relative to their largest entry.
A change that only reorders or rescales floating point operations moves C by a few
eps (the springs, the lengths) times the sensitivity of the problem: the square-root
factor gives every quantity to about eps sqrt(cond(K_s)) relative
(:mod:`closedloop.common.conditioning`), so the bound is ``tol(cond)`` = 64 eps max(1, sqrt(cond)).
K C - I carries eps cond(K_s) (K and C are inverses: their product sees the whole spread).
G, solved for in joint space, also carries the spread of the springs (``tol_joint``); det K
the rounding of its six eigenvalues; a batch row's condition number up to COND_GRAM that of
the eigenvalues of the formed C_s, eps cond (``tol_batch_cond``). Each bound holds with a
margin on OpenBLAS's Haswell, SandyBridge and Nehalem kernels (OPENBLAS_CORETYPE), one
thread or two.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pinocchio as pin
import pytest
from helpers import spherical_fourbar, welded_fourbar
from mechanisms import (
    PATH_CASES,
    fourbar_case,
    serial_with_block,
    stewart_near_singular,
    ur5_case,
)

import closedloop as cl
from closedloop.common.conditioning import twist_scaling
from closedloop.elastostatics.batch import COND_GRAM, QUERY_ERRORS, answered
from closedloop.elastostatics.compliance import energy_shares
from closedloop.elastostatics.partition import model_scaling
from closedloop.model.closed_loop import ClosedLoopModel, Closure

EPS = np.finfo(float).eps
PATHS = ("auto", "null-space")


def tol(cond: float) -> float:
    """Relative tolerance of a quantity recomputed with other rounding (module docstring)."""
    return 64.0 * EPS * max(1.0, math.sqrt(cond))


def tol_joint(clm: ClosedLoopModel, cond: float, length: float) -> float:
    """Relative tolerance of G (joint deflections per wrench) recomputed with other
    rounding: G is solved for in joint space, whose square-root factor spans the springs'
    square roots (scaled at ``length``: their spread, partition.model_scaling) as well as
    K_s: :func:`tol` of the larger (the four-bar, crank 50 N m/rad beside axial springs of
    1e5 N/m, spread 21 against sqrt(cond) 7.6, measured 49 eps sqrt(cond) on its
    null-space path with the world moved: 18 eps of this)."""
    return tol(max(cond, model_scaling(clm, length).spread ** 2))


#: det K is the product of six eigenvalues, each known to tol(cond): DET_TERMS tol(cond).
DET_TERMS = 6


#: A batch row's condition number up to COND_GRAM is the ratio of the eigenvalues of the
#: formed C_s (:func:`closedloop.elastostatics.batch._ranks`): each eigenvalue to about
#: eps |C_s|, the smallest relative eps cond, not eps sqrt(cond) (measured: 2.6 eps cond
#: at most between two batches, 1.5 against the single query, on 1900 random UR5 poses
#: with OpenBLAS's Haswell, SandyBridge and Katmai kernels): GRAM_ULPS eps cond.
GRAM_ULPS = 16.0


def tol_batch_cond(cond: float) -> float:
    """Relative tolerance of a batch row's condition number against another computation
    of it: :func:`tol`, or GRAM_ULPS eps cond where the row may have it from the formed
    C_s (up to twice COND_GRAM: the other side may have decided on the other side of it)."""
    if cond <= 2.0 * COND_GRAM:
        return max(tol(cond), GRAM_ULPS * EPS * cond)
    return tol(cond)


# ---------------------------------------------------------------------------- cases
def _block_case():
    m, q, _ = serial_with_block()
    return m, q, "tool"


def _near_singular_stewart():
    mb = stewart_near_singular(1e-4)  # Fichter's singularity 1e-4 rad away: cond 1.4e10
    return mb.clm, mb.q, mb.frame


def _near_singular_ur5():
    m, q, f = ur5_case()
    return m, np.r_[q[:2], 1e-3, q[3:]], f  # elbow 1e-3 rad from stretched: cond 1.2e8


BUILDERS = {name: build for name, (build, _) in PATH_CASES.items()}
BUILDERS |= {
    "block": _block_case,
    "stewart_1e-4": _near_singular_stewart,
    "ur5_1e-3": _near_singular_ur5,
}
_CACHE: dict = {}


def case(name):
    """(model, q, frame) of a test mechanism, built once per session."""
    if name not in _CACHE:
        _CACHE[name] = BUILDERS[name]()
    return _CACHE[name]


# ---------------------------------------------------------------------------- helpers
def scaled_error(actual, desired, length) -> float:
    """max |A_s - B_s| / max |B_s| of two compliances (6, 6) in unit-free coordinates."""
    d = twist_scaling(length)
    dd = np.outer(d, d)
    return float(np.abs((actual - desired) * dd).max() / np.abs(desired * dd).max())


def relative_error(actual, desired) -> float:
    return float(np.abs(actual - desired).max() / np.abs(desired).max())


def projector(basis) -> np.ndarray:
    """Orthogonal projector on the span of the orthonormal columns of ``basis``."""
    return basis @ basis.T


def times_springs(clm: ClosedLoopModel, s: float) -> ClosedLoopModel:
    """The model with every spring (numbers and blocks) multiplied by s."""
    return clm.with_springs({n: np.asarray(v) * s for n, v in clm.springs.items()}, clm.locked)


def _scaled_placement(M: pin.SE3, s: float) -> pin.SE3:
    return pin.SE3(M.rotation, M.translation * s)


def rebuilt(clm: ClosedLoopModel, model: pin.Model, closures, springs=None) -> ClosedLoopModel:
    return ClosedLoopModel(
        model,
        closures,
        clm.actuated,
        clm.springs if springs is None else springs,
        clm.locked,
        name=clm.name,
    )


def length_scaled(clm: ClosedLoopModel, q, s: float):
    """Every length times s (joint, frame and closure placements, prismatic and free-flyer
    translation coordinates, prismatic position limits); the springs of the linear
    coordinates divided by s^2 (blocks: S^-1 K S^-1), so that the energy of a motion is
    that of the unscaled one and C = D C_1 D, D = diag(s, s, s, 1, 1, 1). Returns (model, q)."""
    m = pin.Model(clm.model)
    for j in range(1, m.njoints):
        m.jointPlacements[j] = _scaled_placement(m.jointPlacements[j], s)
    for f in m.frames:
        f.placement = _scaled_placement(f.placement, s)
    closures = []
    for c in clm.closures:
        k = c.constraint
        a, b = _scaled_placement(k.joint1_placement, s), _scaled_placement(k.joint2_placement, s)
        closures.append(Closure(type(k)(m, k.joint1_id, a, k.joint2_id, b), c.name))
    springs = {}
    for name, value in clm.springs.items():
        f = np.where(clm.linear_coordinates[clm.joint_v_slice(name)], 1.0 / s, 1.0)
        value = np.asarray(value, dtype=float)
        springs[name] = value * (np.outer(f, f) if value.ndim == 2 else f**2)
        if value.ndim == 0:
            springs[name] = float(value * f[0] ** 2)
    q = np.array(q, dtype=float)
    for jm in m.joints[1:]:
        kind = jm.shortname()
        if kind.startswith("JointModelP"):  # prismatic, and its position limits
            q[jm.idx_q : jm.idx_q + jm.nq] *= s
            for limit in (m.lowerPositionLimit, m.upperPositionLimit):
                with np.errstate(over="ignore"):  # unbounded (1.8e308) stays unbounded: inf
                    limit[jm.idx_q : jm.idx_q + jm.nq] *= s
        elif kind == "JointModelFreeFlyer":
            q[jm.idx_q : jm.idx_q + 3] *= s
        else:  # a rotation joint
            assert not clm.linear_coordinates[jm.idx_v : jm.idx_v + jm.nv].any(), kind
    return rebuilt(clm, m, closures, springs), q


def world_moved(clm: ClosedLoopModel, M: pin.SE3) -> ClosedLoopModel:
    """The model built with its world moved by M: the placements of the root joints, of
    the frames on the universe and of the closure anchors on the universe premultiplied
    by M. The same q stays assembled (a free flyer at the root moves with its placement)."""
    m = pin.Model(clm.model)
    for j in range(1, m.njoints):
        if m.parents[j] == 0:
            m.jointPlacements[j] = M * m.jointPlacements[j]
    for f in m.frames:
        if f.parentJoint == 0 and f.name != "universe":
            f.placement = M * f.placement
    closures = []
    for c in clm.closures:
        k = c.constraint
        a = M * k.joint1_placement if k.joint1_id == 0 else k.joint1_placement
        b = M * k.joint2_placement if k.joint2_id == 0 else k.joint2_placement
        closures.append(Closure(type(k)(m, k.joint1_id, a, k.joint2_id, b), c.name))
    return rebuilt(clm, m, closures)


def reordered(clm: ClosedLoopModel, order, swap, spring_order) -> ClosedLoopModel:
    """The closures in ``order``, those of ``swap`` (indices before reordering) written
    frame 2 first, the springs listed in ``spring_order``."""
    closures = []
    for i, c in enumerate(clm.closures):
        k = c.constraint
        if i in swap:
            k = type(k)(clm.model, k.joint2_id, k.joint2_placement, k.joint1_id, k.joint1_placement)
        closures.append(Closure(k, c.name))
    springs = clm.springs
    names = [list(springs)[i] for i in spring_order]
    return rebuilt(clm, clm.model, [closures[i] for i in order], {n: springs[n] for n in names})


def assert_same_answer(r, ref, clm, scale=1.0) -> None:
    """r is ref (C, G divided by ``scale``) of the model ``clm`` (or one of the same
    springs) to rounding (:func:`tol`, :func:`tol_joint`): C, G, rank, rigid directions,
    condition number, path."""
    rtol = tol(ref.condition_number)
    assert r.rank == ref.rank
    assert r.path == ref.path
    assert scaled_error(r.C * scale, ref.C, ref.length) <= rtol
    assert relative_error(r.G * scale, ref.G) <= tol_joint(clm, ref.condition_number, ref.length)
    np.testing.assert_allclose(r.condition_number, ref.condition_number, rtol=rtol)
    np.testing.assert_allclose(
        projector(r.rigid_directions), projector(ref.rigid_directions), atol=rtol
    )


# ---------------------------------------------------------------------------- 1. springs
SPRING_SCALES = (1e-150, 1e-30, 1e-8, 3.7, 1e8, 1e30, 1e150)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BUILDERS)
def test_springs_times_s_divide_the_compliance_by_s(name, path):
    m, q, f = case(name)
    ref = cl.compliance(m, q, f, path=path)
    for s in SPRING_SCALES:
        r = cl.compliance(times_springs(m, s), q, f, path=path)
        assert_same_answer(r, ref, m, scale=s)


def test_springs_times_s_on_the_rank_deficient_side_of_a_singular_pose():
    """The UR5 stretched (elbow 1e-6 rad, 0): rank 5 whatever the springs' scale, the same
    rigid direction (the rank rule reads the kinematics, not the springs)."""
    m, q, f = ur5_case()
    for elbow in (1e-6, 0.0):
        qe = np.r_[q[:2], elbow, q[3:]]
        for path in PATHS:
            ref = cl.compliance(m, qe, f, path=path)
            assert ref.rank == 5
            for s in (1e-150, 1e150):
                r = cl.compliance(times_springs(m, s), qe, f, path=path)
                assert_same_answer(r, ref, m, scale=s)


def test_the_two_paths_agree_under_spring_scaling():
    """path="auto" and path="null-space" give the same C at every spring scale (springs
    within a factor 1e3 of each other: the general path's SVD of the spring factor then
    loses nothing that shows)."""
    for name in BUILDERS:
        m, q, f = case(name)
        for s in (1e-150, 1.0, 1e150):
            ms = times_springs(m, s)
            a, b = (cl.compliance(ms, q, f, path=p) for p in PATHS)
            rtol = tol(a.condition_number)
            assert a.rank == b.rank, name
            assert scaled_error(b.C, a.C, a.length) <= rtol, name
            assert relative_error(b.G, a.G) <= tol_joint(ms, a.condition_number, a.length), name
            np.testing.assert_allclose(b.condition_number, a.condition_number, rtol=rtol)


def test_springs_times_s_in_the_batch():
    """compliances(): rows from a generic UR5 pose to its singular one and Stewart rows
    towards Fichter's singularity, springs times 1e-150 and 1e150."""
    m, q, f = ur5_case()
    Q = np.array([np.r_[q[:2], e, q[3:]] for e in (1.4, 1e-2, 1e-4, 3e-6, 1e-6, 0.0)])
    st = stewart_near_singular(0.1)
    Qs = np.array([stewart_near_singular(d).q for d in (0.1, 1e-3, 1e-5, 1e-6)])
    for model, configurations, frame in ((m, Q, f), (st.clm, Qs, st.frame)):
        ref = cl.compliances(model, configurations, frame)
        for s in (1e-150, 1e150):
            b = cl.compliances(times_springs(model, s), configurations, frame)
            np.testing.assert_array_equal(b.rank, ref.rank)
            for i in range(len(configurations)):
                rtol = tol(ref.condition_number[i])
                assert scaled_error(b.C[i] * s, ref.C[i], ref.length) <= rtol
                rtol_G = tol_joint(model, ref.condition_number[i], ref.length)
                assert relative_error(b.G[i] * s, ref.G[i]) <= rtol_G
                np.testing.assert_allclose(
                    b.condition_number[i],
                    ref.condition_number[i],
                    rtol=tol_batch_cond(ref.condition_number[i]),
                )


# ---------------------------------------------------------------------------- 2. units
#: 1e-120, not 1e-150: near a singular pose K ~ k cond / L^2 would overflow (a typed error)
LENGTH_SCALES = (1e-120, 1e-9, 1e-3, 1e3, 1e9, 1e150)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BUILDERS)
def test_lengths_times_s_scale_the_compliance_by_the_unit(name, path):
    """Lengths times s, prismatic springs / s^2: C = D C_1 D, D = diag(s, s, s, 1, 1, 1);
    G scales its linear coordinates' rows by s and its force columns by s; L = s L_1; the
    rank, rigid directions (in unit-free coordinates) and condition number are the same."""
    m, q, f = case(name)
    ref = cl.compliance(m, q, f, path=path)
    rtol = tol(ref.condition_number)
    for s in LENGTH_SCALES:
        m2, q2 = length_scaled(m, q, s)
        r = cl.compliance(m2, q2, f, path=path)
        D = np.r_[np.full(3, s), np.ones(3)]
        rows = np.where(m.linear_coordinates, s, 1.0)
        assert r.rank == ref.rank and r.path == ref.path
        np.testing.assert_allclose(r.length, s * ref.length, rtol=4 * EPS)
        assert scaled_error(r.C / np.outer(D, D), ref.C, ref.length) <= rtol
        rtol_G = tol_joint(m, ref.condition_number, ref.length)
        assert relative_error(r.G / np.outer(rows, D), ref.G) <= rtol_G
        np.testing.assert_allclose(r.condition_number, ref.condition_number, rtol=rtol)
        # null(C) = D^-1 null(C_1): D maps the rigid directions back. Each is an SI unit
        # vector, its entries to eps absolute: D amplifies that by max(s, 1/s) relative
        atol = rtol * max(s, 1.0 / s)
        if r.rank < 6 and atol < 1e-3:
            back = np.linalg.qr(r.rigid_directions * D[:, None])[0]
            np.testing.assert_allclose(
                projector(back), projector(ref.rigid_directions), rtol=0, atol=atol
            )
        np.testing.assert_allclose(r.point, s * ref.point, rtol=rtol, atol=rtol * s)


@pytest.mark.parametrize("name", ["cahyman", "ur5", "stewart", "delta", "block", "stewart_1e-4"])
def test_a_change_of_length_unit_keeps_det_K(name):
    """Metres to millimetres (s = 1e3) and others: lengths times s, every spring per the
    unit (prismatic N/m / s, revolute N m/rad * s). det K [N^6/rad^3] has no length in its
    unit: it is unchanged, and C = D C_1 D / s."""
    m, q, f = case(name)
    ref = cl.compliance(m, q, f)
    det = cl.StiffnessIndices.from_result(ref).determinant
    rtol = tol(ref.condition_number)
    for s in (1e-3, 1e3, 1e9):
        m2, q2 = length_scaled(m, q, s)
        r = cl.compliance(times_springs(m2, s), q2, f)
        D = np.r_[np.full(3, s), np.ones(3)]
        assert scaled_error(r.C * s / np.outer(D, D), ref.C, ref.length) <= rtol
        np.testing.assert_allclose(
            cl.StiffnessIndices.from_result(r).determinant, det, rtol=DET_TERMS * rtol
        )


def test_the_batch_under_a_change_of_length_unit():
    m, q, f = ur5_case()
    Q = np.array([np.r_[q[:2], e, q[3:]] for e in (1.4, 1e-2, 1e-4, 3e-6, 0.0)])
    ref = cl.compliances(m, Q, f)
    for s in (1e-3, 1e3):
        m2, _ = length_scaled(m, q, s)
        b = cl.compliances(m2, Q, f)  # revolute joints only: q is unchanged
        D = np.r_[np.full(3, s), np.ones(3)]
        np.testing.assert_array_equal(b.rank, ref.rank)
        np.testing.assert_allclose(b.length, s * ref.length, rtol=4 * EPS)
        for i in range(len(Q)):
            rtol = tol(ref.condition_number[i])
            assert scaled_error(b.C[i] / np.outer(D, D), ref.C[i], ref.length) <= rtol
            np.testing.assert_allclose(
                b.condition_number[i],
                ref.condition_number[i],
                rtol=tol_batch_cond(ref.condition_number[i]),
            )


# ---------------------------------------------------------------------------- 3. world
WORLD_MOTIONS = {
    "turned": pin.SE3(pin.exp3(np.array([0.4, -0.7, 0.3])), np.zeros(3)),
    "shifted": pin.SE3(np.eye(3), np.array([0.3, -2.0, 5.0])),
    "both": pin.SE3(pin.exp3(np.array([-1.1, 0.2, 2.5])), np.array([0.1, 0.2, -0.3])),
}
#: Rounding of the characteristic length of a mechanism moved by at most 5 m: its points
#: carry eps |p| of rounding against L ~ 1 m (measured 1e-15).
RTOL_MOVED_LENGTH = 1e-13


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BUILDERS)
def test_a_rigid_motion_of_the_world_turns_the_world_axes_compliance(name, path):
    """The mechanism built with its world moved by M = (R, p), 2 km away included: its
    characteristic length does not change; C in world axes becomes R6 C R6^T
    (R6 = diag(R, R)), G turns its wrench columns, the rigid directions turn with R6; C in
    local axes, the point relative to the frame, the rank, the condition number and det K
    do not change."""
    m, q, f = case(name)
    ref = {axes: cl.compliance(m, q, f, axes, path=path) for axes in ("world", "local")}
    L = ref["world"].length
    rtol = tol(ref["world"].condition_number)
    for M in WORLD_MOTIONS.values():
        m2 = world_moved(m, M)
        R6 = np.kron(np.eye(2), M.rotation)
        np.testing.assert_allclose(m2.length, L, rtol=RTOL_MOVED_LENGTH)
        r = cl.compliance(m2, q, f, path=path)
        local = cl.compliance(m2, q, f, "local", path=path)
        w = ref["world"]
        assert r.rank == w.rank and local.rank == w.rank
        assert scaled_error(r.C, R6 @ w.C @ R6.T, L) <= rtol
        assert relative_error(r.G, w.G @ R6.T) <= tol_joint(m, w.condition_number, L)
        assert scaled_error(local.C, ref["local"].C, L) <= rtol
        np.testing.assert_allclose(r.point, M.act(w.point), atol=rtol * L)
        np.testing.assert_allclose(r.condition_number, w.condition_number, rtol=rtol)
        np.testing.assert_allclose(
            projector(r.rigid_directions), projector(R6 @ w.rigid_directions), atol=rtol
        )
        if w.rank == 6:
            det = cl.StiffnessIndices.from_result(w).determinant
            np.testing.assert_allclose(
                cl.StiffnessIndices.from_result(r).determinant, det, rtol=DET_TERMS * rtol
            )
            np.testing.assert_allclose(
                cl.StiffnessIndices.from_result(local).determinant, det, rtol=DET_TERMS * rtol
            )


@pytest.mark.parametrize("distance", [1e3, 1e5])
@pytest.mark.parametrize("name", BUILDERS)
def test_far_from_the_world_origin_the_rules_do_not_change(name, distance):
    """The mechanism moved 2.3 distance away from the world origin: its characteristic
    length, and with it the rank, the condition number and the ill-conditioned flag, do
    not change (L once spanned the world origin: the UR5 1 km away had cond 7.7e7 instead
    of 70). Its points carry eps |p| of rounding, a relative error eps |p| / L in J,
    amplified by cond(B) = sqrt(cond) in the condition number."""
    m, q, f = case(name)
    ref = cl.compliance(m, q, f)
    M = pin.SE3(pin.exp3(np.array([0.2, 0.9, -0.4])), distance * np.array([1.0, -2.0, 0.5]))
    m2 = world_moved(m, M)
    rounding = 64 * EPS * np.linalg.norm(M.translation) / ref.length
    np.testing.assert_allclose(m2.length, ref.length, rtol=rounding)
    r = cl.compliance(m2, q, f)
    assert r.rank == ref.rank and r.ill_conditioned == ref.ill_conditioned
    np.testing.assert_allclose(
        r.condition_number, ref.condition_number, rtol=rounding * np.sqrt(ref.condition_number)
    )


def test_world_and_local_axes_are_one_rotation_apart():
    """C_world = R6 C_local R6^T with R the frame's world orientation, in every case."""
    for name in BUILDERS:
        m, q, f = case(name)
        w, loc = (cl.compliance(m, q, f, axes) for axes in ("world", "local"))
        R = cl.Configuration(m, q).frame_placement(f).rotation
        R6 = np.kron(np.eye(2), R)
        assert scaled_error(R6 @ loc.C @ R6.T, w.C, w.length) <= tol(w.condition_number), name


# ---------------------------------------------------------------------------- 4. order
ORDER_CASES = dict.fromkeys(BUILDERS) | {"welded_fourbar": None, "spherical_fourbar": None}


def order_case(name):
    if name == "welded_fourbar":  # a 6d closure
        m, q, _ = fourbar_case()
        return welded_fourbar(m, q), q, "P"
    if name == "spherical_fourbar":  # a redundant 3d closure
        m, q = spherical_fourbar()
        return m, q, "tool"
    return case(name)


@pytest.mark.parametrize("name", ORDER_CASES)
def test_the_order_of_closures_frames_and_springs_does_not_matter(name):
    m, q, f = order_case(name)
    n, n_springs = len(m.closures), len(m.springs)
    rng = np.random.default_rng(7)
    variants = [(np.arange(n)[::-1], set(range(n)), np.arange(n_springs)[::-1])]
    variants += [
        (rng.permutation(n), set(np.flatnonzero(rng.random(n) < 0.5)), rng.permutation(n_springs))
        for _ in range(2)
    ]
    for path in PATHS:
        ref = cl.compliance(m, q, f, path=path)
        for order, swap, spring_order in variants:
            r = cl.compliance(reordered(m, order, swap, spring_order), q, f, path=path)
            assert_same_answer(r, ref, m)
            assert (r.mobility, r.internal_mobilities) == (ref.mobility, ref.internal_mobilities)


# ---------------------------------------------------------------------------- 5. batch
def _ur5_rows():
    """UR5 rows from a generic pose to the stretched one, across its rank threshold
    (elbow ~1.08e-6 rad) and at it: (model, Q, frame)."""
    m, q, f = ur5_case()
    elbows = (1.4, 1e-1, 1e-3, 1e-4, 1e-5, 2e-6, 1.0823e-6, 1.0824e-6, 1e-6, 1e-8, 0.0)
    return m, np.array([np.r_[q[:2], e, q[3:]] for e in elbows]), f


def _stewart_rows():
    """Stewart rows towards Fichter's singularity, the last ones just on the mechanism
    side of the rank rule's limit (delta ~5.51e-7 rad)."""
    st = stewart_near_singular(0.1)
    deltas = (0.3, 0.1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 5.6e-7)
    return st.clm, np.array([stewart_near_singular(d).q for d in deltas]), st.frame


def _cahyman_rows():
    m, q, f = case("cahyman")
    from cahyman_pin.model import cahyman_model

    model = cahyman_model()
    Q = [
        model.assemble(np.deg2rad(a), np.deg2rad(45.0), 0.01)
        for a in ([45, 60, 75], [80, 85, 90], [50, 50, 50])
    ]
    return m, np.array([q, *Q]), f


@pytest.mark.parametrize("rows", [_ur5_rows, _stewart_rows, _cahyman_rows])
@pytest.mark.parametrize("axes", ["world", "local"])
def test_each_row_of_the_batch_is_the_single_query(rows, axes):
    """C, G, rank and condition number of every row equal the single query's: to rounding
    on the stacked rows, bit for bit on the rows the batch leaves to the single query
    (near a singular pose)."""
    m, Q, f = rows()
    b = cl.compliances(m, Q, f, axes)
    assert b.C.shape == (len(Q), 6, 6) and b.length == m.length
    for i, q in enumerate(Q):
        r = cl.compliance(m, q, f, axes)
        assert b.rank[i] == r.rank
        if not b.stacked[i]:
            np.testing.assert_array_equal(b.C[i], r.C)
            np.testing.assert_array_equal(b.G[i], r.G)
            assert b.condition_number[i] == r.condition_number
            continue
        rtol = tol(r.condition_number)
        assert scaled_error(b.C[i], r.C, r.length) <= rtol
        assert relative_error(b.G[i], r.G) <= tol_joint(m, r.condition_number, r.length)
        np.testing.assert_allclose(
            b.condition_number[i], r.condition_number, rtol=tol_batch_cond(r.condition_number)
        )
    if rows is not _cahyman_rows:  # near a singular pose: some rows left to the single query
        assert not b.stacked.all()


def _failing_rows():
    """Stewart rows: good ones, a singular pose (MechanismError), a configuration that
    does not close the loops (OpenLoopError), a good one after them."""
    m, Q, f = _stewart_rows()
    singular = stewart_near_singular(3e-7).q
    open_q = Q[1].copy()
    open_q[0] += 1e-3  # the platform moved, the legs not
    return m, np.array([Q[0], Q[2], singular, Q[3], open_q, Q[4]]), f


def test_a_failing_row_is_the_single_query_error_naming_the_row():
    m, Q, f = _failing_rows()
    with pytest.raises(cl.MechanismError) as batch_error:
        cl.compliances(m, Q, f)
    with pytest.raises(cl.MechanismError) as single_error:
        cl.compliance(m, Q[2], f)
    assert str(batch_error.value) == str(single_error.value)
    assert batch_error.value.__notes__ == ["at configuration 2 of Q"]


def test_every_row_answered_or_its_own_error():
    """The per-configuration record of the maps (closedloop.elastostatics.batch.answered): each row
    is the single query's answer, or its error (same type and message), the others kept."""
    m, Q, f = _failing_rows()
    C, G, rank, cond, _, errors, L = answered(m, Q, f, "world", None, QUERY_ERRORS)
    assert L == m.length
    assert sorted(errors) == [2, 4]
    for i, q in enumerate(Q):
        try:
            r = cl.compliance(m, q, f)
        except QUERY_ERRORS as e:
            assert type(errors[i]) is type(e) and str(errors[i]) == str(e)
            assert np.isnan(C[i]).all() and rank[i] == -1 and np.isnan(cond[i])
            continue
        rtol = tol(r.condition_number)
        assert rank[i] == r.rank
        assert scaled_error(C[i], r.C, r.length) <= rtol
        assert relative_error(G[i], r.G) <= tol_joint(m, r.condition_number, r.length)
        np.testing.assert_allclose(
            cond[i], r.condition_number, rtol=tol_batch_cond(r.condition_number)
        )


# ---------------------------------------------------------------------------- 6. properties
@pytest.mark.parametrize("s", [1e-150, 1.0, 1e150])
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BUILDERS)
def test_compliance_is_symmetric_psd_and_the_inverse_of_K(name, path, s):
    """C symmetric PSD with rank(C) eigenvalues resolved above the rule's threshold;
    C = J G (J the frame Jacobian, same axes); K C = I to eps cond(K_s) where the rank is
    6; the energy shares are >= 0 and sum to 1."""
    m, q, f = case(name)
    ms = times_springs(m, s)
    for axes in ("world", "local"):
        r = cl.compliance(ms, q, f, axes, path=path)
        rtol = tol(r.condition_number)
        d = twist_scaling(r.length)
        dd = np.outer(d, d)
        C_s = r.C * dd
        top = np.abs(C_s).max()
        assert np.abs(C_s - C_s.T).max() <= 4 * EPS * top
        mu = np.linalg.eigvalsh(C_s)
        assert mu[0] >= -64 * EPS * mu[-1]
        # eigenvalues of the formed C_s hold to eps |C_s|: those of rank are above it
        assert np.count_nonzero(mu > 1e3 * EPS * mu[-1]) <= r.rank
        J = cl.Configuration(ms, q).frame_jacobian(f, axes)
        assert scaled_error(J @ r.G, r.C, r.length) <= rtol
        if r.rank == 6:
            K_s = r.K / dd
            assert np.abs(K_s @ C_s - np.eye(6)).max() <= 64 * EPS * r.condition_number
            np.testing.assert_allclose(K_s, K_s.T, rtol=0, atol=4 * EPS * np.abs(K_s).max())
        else:
            assert r.rigid_directions.shape == (6, 6 - r.rank)
            np.testing.assert_allclose(
                r.rigid_directions.T @ r.rigid_directions, np.eye(6 - r.rank), atol=16 * EPS
            )
            # null(C) = D_L null(C_s): C_s (D_L^-1 R) ~ 0
            rigid_s = np.linalg.qr(r.rigid_directions / d[:, None])[0]
            assert np.abs(C_s @ rigid_s).max() <= rtol * top
    rng = np.random.default_rng(3)
    for _ in range(3):
        shares = energy_shares(ms, r, rng.normal(size=6))
        assert shares and min(shares.values()) >= -rtol
        assert abs(sum(shares.values()) - 1.0) <= rtol


# ---------------------------------------------------------------------------- 7. threads
THREAD_CASES = ("fourbar", "cahyman", "ur5", "stewart", "delta", "block", "stewart_1e-4")


def _queries(name):
    """Every answer of a case as bytes: both paths and axes, K, the batch of its rows."""
    m, q, f = case(name)
    out = []
    for path in PATHS:
        for axes in ("world", "local"):
            r = cl.compliance(cl.Configuration(m, q), f, axes, path=path)
            K = r.K.tobytes() if r.rank == 6 else None
            out.append((r.C.tobytes(), r.G.tobytes(), r.rank, r.condition_number, K))
    Q = np.array([q, q, q])
    if name == "ur5":
        Q = _ur5_rows()[1]
    b = cl.compliances(m, Q, f)
    out.append(tuple(a.tobytes() for a in (b.C, b.G, b.rank, b.condition_number, b.stacked)))
    return out


def test_threads_on_shared_models_give_the_serial_answers_bit_for_bit():
    serial = {name: _queries(name) for name in THREAD_CASES}
    jobs = [name for _ in range(3) for name in THREAD_CASES]
    results, failures = [None] * len(jobs), []
    barrier = threading.Barrier(8)

    def work(k):
        try:
            barrier.wait()
            for i in range(k, len(jobs), 8):
                results[i] = _queries(jobs[i])
        except Exception as e:  # reported below
            failures.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures
    for name, got in zip(jobs, results, strict=True):
        assert got == serial[name], name

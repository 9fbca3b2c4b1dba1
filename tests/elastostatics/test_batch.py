"""closedloop.compliances (the stacked fast path) against the single query, point by point.

The reference is :func:`closedloop.compliance`, computed here for every configuration:
the stacked path must give its C, G and rank, answer only where the single query takes a
fast path with a full-rank C, and leave everything else (singular poses, rank deficient
robots, the null-space path, open loops, overflows) to it, errors included.
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from mechanisms import PATH_CASES, fourbar_chain, serial_with_block

import closedloop as cl
from closedloop.elastostatics.batch import stacked_compliances
from closedloop.exceptions import (
    ClosedLoopError,
    InvalidInputError,
    NameNotFoundError,
    OpenLoopError,
    SingularConfigurationError,
)
from closedloop.model.closed_loop import ClosedLoopModel

#: Stacked vs single query: the same formulas, with LAPACK calls that differ in their
#: order of operations (measured: 1e-16 relative on every case here); cond(J_p) ~ 1e2
#: multiplies rounding in the passive motion.
RTOL_STACKED = 1e-12
#: Condition numbers of the stacked and single paths: eigenvalues of the formed C_s
#: against squared singular values of its factor, which differ by ~1e-16 cond (cond up to
#: COND_GRAM = 1e4 on that path), or the singular values of one factor in two LAPACK
#: calls, or of two factors (the null-space path against the stacked one) at a pose near
#: the rank threshold (cond up to 1e10).
RTOL_COND = 1e-6
#: Projectors onto the rigid directions of two paths: the left singular vectors of two
#: factors of one matrix, at a gap of 1e7 between the kept and the rigid values.
RTOL_DIRECTIONS = 1e-8


def _assert_as_single(clm, Q, frame, axes="world", length=None):
    """compliances() equals compliance() at every configuration; returns the batch."""
    batch = cl.compliances(clm, Q, frame, axes, length=length)
    for i, q in enumerate(Q):
        single = cl.compliance(clm, q, frame, axes, length=length)
        assert batch.rank[i] == single.rank
        # the condition number: the same factor's singular values, or the eigenvalues of
        # C_s up to COND_GRAM (cond <= 1e4: rounding ~1e-16 cond)
        assert batch.condition_number[i] == pytest.approx(single.condition_number, rel=RTOL_COND)
        assert_close_in_norm(batch.C[i], single.C, RTOL_STACKED)
        assert_close_in_norm(batch.G[i], single.G, RTOL_STACKED)
        assert not batch.stacked[i] or single.path != "null-space"  # stacked: a fast path
    assert batch.length == (clm.length if length is None else length)
    for a in (batch.C, batch.G, batch.rank, batch.stacked):
        assert not a.flags.writeable
    return batch


def _ur5_poses(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-2.5, 2.5, (n, 6))


@pytest.mark.parametrize("case", sorted(PATH_CASES))
def test_every_path_case_equals_its_single_queries(case):
    build, path = PATH_CASES[case]
    clm, q, frame = build()
    Q = _ur5_poses(5) if case == "ur5" else np.array([q, q])
    batch = _assert_as_single(clm, Q, frame)
    assert batch.stacked.all() == (path != "null-space")  # planar ones too (rank < 6)


@pytest.mark.parametrize("axes", ["world", "local"])
def test_cahyman_poses_in_both_axes_and_a_length(cahyman, axes):
    poses = [(a, b) for a in (45.0, 60.0, 75.0) for b in (50.0, 70.0)]
    Q = np.array([cahyman.assemble(np.deg2rad([a, b, 60.0]), np.deg2rad(30.0), 0.01)
                  for a, b in poses])  # fmt: skip
    batch = _assert_as_single(cahyman.clm, Q, "M", axes, length=0.4)
    assert batch.stacked.all()


def test_serial_robot_with_spring_blocks_and_a_locked_joint():
    clm, q, _ = serial_with_block()
    frame = clm.model.frames[-1].name
    Q = np.array([q, q + 0.05 * np.sin(np.arange(q.size))])
    Q[1] = pin.normalize(clm.model, Q[1])
    _assert_as_single(clm, Q, frame)


def test_singular_poses_are_rank_deficient_as_in_the_single_query(ur5):
    clm, _ = ur5
    # elbow stretched (q3 = 0) and wrist aligned (q5 = 0), between regular poses
    Q = np.vstack([_ur5_poses(2), [0.3, -1.2, 0.0, -0.6, 1.1, 0.2],
                   [0.3, -1.2, 1.4, -0.6, 0.0, 0.2], _ur5_poses(2, seed=2)])  # fmt: skip
    batch = _assert_as_single(clm, Q, "tool0")
    assert batch.rank.tolist() == [6, 6, 5, 5, 6, 6] and batch.stacked.all()


def test_poses_at_the_rank_threshold_go_through_the_single_query(ur5):
    """Approaching the elbow singularity, the smallest singular value crosses the rank
    rule's threshold: poses near it are left to the single query, which decides; every
    pose, on either side, equals its single query."""
    clm, q = ur5
    Q = np.repeat(q[None], 120, axis=0)
    Q[:, 2] = np.logspace(-10, -4, len(Q))
    batch = _assert_as_single(clm, Q, "tool0")
    assert {5, 6} <= set(batch.rank.tolist())
    assert 0 < np.count_nonzero(~batch.stacked) < len(Q)


@pytest.mark.parametrize("start", [-10.0, -7.0])
def test_the_eigenvalue_shortcut_decides_as_the_singular_values(ur5, monkeypatch, start):
    """The full-rank shortcut on the eigenvalues of the formed C_s (GRAM_MARGIN) gives
    the ranks, and leaves the same poses to the single query, as the singular values of
    the factors alone; across the elbow singularity, where the shortcut stops deciding
    before the rank rule does (q3 from 1e-10 or 1e-7 to 1e-4 rad), and at random poses."""
    clm, q = ur5
    Q = np.repeat(q[None], 80, axis=0)
    Q[:, 2] = np.logspace(start, -4, len(Q))
    Q = np.vstack([Q, _ur5_poses(20)])
    batch = cl.compliances(clm, Q, "tool0")
    monkeypatch.setattr(cl.elastostatics.batch, "GRAM_MARGIN", np.inf)  # never decides: SVDs only
    by_svd = cl.compliances(clm, Q, "tool0")
    np.testing.assert_array_equal(batch.rank, by_svd.rank)
    np.testing.assert_array_equal(batch.stacked, by_svd.stacked)
    assert_close_in_norm(batch.C, by_svd.C, RTOL_STACKED)
    assert np.count_nonzero(batch.stacked & (batch.rank == 6)) > 20


def test_a_four_bar_chain_through_its_change_point():
    """Loop 1 of the chain passes its collinear change point (t = 0): there the passive
    part J_p is singular, and the stacked path leaves the pose to the single query (its
    answer or its error)."""
    angles = [(0.8, t, -0.6) for t in (0.5, 0.1, 1e-3, 0.0, -0.2)]
    clm = fourbar_chain(angles[0])[0]
    Q = np.array([fourbar_chain(a)[1] for a in angles])
    assert stacked_compliances(clm, Q, "tip", "world", clm.length)[2][3] == -1
    _assert_as_single(clm, Q[[0, 1, 2, 4]], "tip")
    try:
        single = cl.compliance(clm, Q[3], "tip")
    except ClosedLoopError as e:
        with pytest.raises(type(e)):
            cl.compliances(clm, Q[3:4], "tip")
    else:
        assert_close_in_norm(cl.compliances(clm, Q[3:4], "tip").C[0], single.C, RTOL_STACKED)


def test_many_passive_coordinates_take_the_single_query():
    """From 48 passive coordinates the single query solves loop by loop: not stacked."""
    clm, q, frame = fourbar_chain([0.8, -0.8] * 13)
    batch = _assert_as_single(clm, np.array([q]), frame)
    assert not batch.stacked.any()


def test_an_open_configuration_is_the_single_query_error_naming_it(fourbar):
    clm, q = fourbar
    Q = np.array([q, q])
    Q[1, 2] += 0.1  # a passive joint moved: the loop opens
    with pytest.raises(OpenLoopError) as info:
        cl.compliances(clm, Q, "P")
    assert "at configuration 1 of Q" in info.value.__notes__


@pytest.mark.parametrize("k", [1e-300, 1e300])
def test_extreme_springs_agree_with_the_single_query(ur5_urdf, k):
    """Springs near the floating point limits: the stacked path answers or leaves it, and
    either way the result (or the overflow error) is the single query's."""
    clm = cl.load_model(ur5_urdf, joint_stiffness=k)
    Q = _ur5_poses(3)
    try:
        expected = [cl.compliance(clm, q, "tool0") for q in Q]
    except SingularConfigurationError:
        with pytest.raises(SingularConfigurationError):
            cl.compliances(clm, Q, "tool0")
        return
    batch = cl.compliances(clm, Q, "tool0")
    for i, single in enumerate(expected):
        assert_close_in_norm(batch.C[i], single.C, RTOL_STACKED)


def test_near_singular_pose_with_huge_springs_overflows_in_both(ur5_urdf):
    """Springs of 1e300 (one of 1e290) with the elbow nearly straight: K overflows. The
    stacked path decided rank 6 from the kinematic factor without the overflow test, and
    answered (a map showed det K = -inf) where the single query raises."""
    names = [f"{j}_joint" for j in ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1",
                                     "wrist_2", "wrist_3")]  # fmt: skip
    clm = cl.load_model(ur5_urdf, springs=dict(zip(names, [1e300] * 5 + [1e290], strict=True)))
    q = np.array([0.3, -1.2, 1e-4, -0.6, 1.1, 0.2])
    with pytest.raises(SingularConfigurationError, match="overflows"):
        cl.compliance(clm, q, "tool0")
    with pytest.raises(SingularConfigurationError, match="overflows"):
        cl.compliances(clm, q[None], "tool0")


def test_springs_spanning_more_than_the_float_range_are_answered_as_the_single_query(ur5_urdf):
    """Springs of 1e200 and 1e-130 (a spread of 1e330): the single query answers on the
    null-space path (the wrist joints do not move the forearm); the stacked path raised
    Python's OverflowError squaring the spread, which stopped a whole map."""
    names = [f"{j}_joint" for j in ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1",
                                     "wrist_2", "wrist_3")]  # fmt: skip
    clm = cl.load_model(ur5_urdf, springs=dict(zip(names, [1e200] * 3 + [1e-130] * 3, strict=True)))
    q = _ur5_poses(2)
    batch = _assert_as_single(clm, q, "forearm_link")
    assert list(batch.rank) == [3, 3]


def _parallelogram_with_arm() -> ClosedLoopModel:
    """A parallelogram four-bar (crank sprung) carrying a sprung planar 2R arm on its
    rocker; at arm1 = 0 the rocker pivot, the arm's base and its elbow are aligned, and
    the tip loses a direction (rank 2 of the planar twists below arm1 ~ 2.06e-6 rad)."""
    model = pin.Model()

    def joint(parent, name, x):
        place = pin.SE3(np.eye(3), np.array([x, 0.0, 0.0]))
        return model.addJoint(parent, pin.JointModelRZ(), place, name)

    crank = joint(0, "crank", 0.0)
    coupler = joint(crank, "coupler", 0.3)
    rocker = joint(0, "rocker", 0.5)
    closure = pin.PointAnchorConstraintModel(
        model, coupler, pin.SE3(np.eye(3), np.array([0.5, 0, 0])),
        rocker, pin.SE3(np.eye(3), np.array([0.3, 0, 0])),
    )  # fmt: skip
    arm2 = joint(joint(rocker, "arm1", 0.3), "arm2", 0.3)
    model.addFrame(pin.Frame("tip", arm2, pin.SE3(np.eye(3), np.array([0.25, 0, 0])),
                             pin.FrameType.OP_FRAME))  # fmt: skip
    springs = {"crank": 1e3, "arm1": 50.0, "arm2": 80.0}
    return ClosedLoopModel(model, [closure], ["crank", "arm1", "arm2"], springs, name="arm")


def test_the_rank_threshold_does_not_depend_on_the_path():
    """Across the rank threshold of the arm on a parallelogram (arm1 = 2.0596e-6 rad at
    the model's length, 1.35 m), the partitioned path, the null-space path and the stacked
    path decide the same rank (and condition number) at every pose. When the fast paths
    read the rank on J T, T = [I; X] not orthonormal, they put the threshold about 1 %
    further out: between the two, rank 2 against rank 3 (cond 2e14)."""
    clm = _parallelogram_with_arm()
    arm1 = np.linspace(2.02e-6, 2.10e-6, 17)
    Q = np.array([[0.9, -0.9, 0.9, a, 0.7] for a in arm1])  # the parallelogram closes exactly
    batch = _assert_as_single(clm, Q, "tip")
    assert set(batch.rank) == {2, 3}
    for q in Q:
        fast = cl.compliance(clm, q, "tip")
        general = cl.compliance(clm, q, "tip", path="null-space")
        assert fast.path == "partitioned"
        assert fast.rank == general.rank
        assert fast.condition_number == pytest.approx(general.condition_number, rel=RTOL_COND)
        # the same rigid directions: equal projectors onto them
        R_f, R_g = fast.rigid_directions, general.rigid_directions
        np.testing.assert_allclose(R_f @ R_f.T, R_g @ R_g.T, atol=RTOL_DIRECTIONS)


def test_tiny_springs_whose_entries_are_finite_are_answered_by_both(ur5_urdf):
    """Springs of 5e-308: every entry of C and G is finite (up to 5e307) but their sum
    overflows, which the single query took for an overflow; both answer alike now."""
    clm = cl.load_model(ur5_urdf, joint_stiffness=5e-308)
    q = _ur5_poses(5, seed=0)[3]
    single = cl.compliance(clm, q, "tool0")
    assert np.isfinite(single.C).all() and np.abs(single.C).max() > 1e307
    _assert_as_single(clm, q[None], "tool0")


@pytest.mark.parametrize(
    ("Q", "message"),
    [
        (np.zeros((2, 5)), r"shape \(2, 5\); expected \(n, nq=6\)"),
        (np.zeros(6), r"shape \(6,\)"),
        ([[0.0] * 5 + [np.nan]] * 2, "configuration 0 of Q has non-finite values"),
        ([["a"] * 6], "Q must be real numbers"),
        (np.zeros((1, 6)) + 1j, "complex"),
    ],
)
def test_bad_configurations_are_named(ur5, Q, message):
    with pytest.raises(InvalidInputError, match=message):
        cl.compliances(ur5[0], Q, "tool0")


def test_bad_frame_axes_and_length(ur5):
    clm, q = ur5
    with pytest.raises(NameNotFoundError, match="nope"):
        cl.compliances(clm, [q], "nope")
    with pytest.raises(InvalidInputError, match="axes 'body'"):
        cl.compliances(clm, [q], "tool0", "body")
    with pytest.raises(InvalidInputError, match="characteristic length"):
        cl.compliances(clm, [q], "tool0", length=-1.0)


@pytest.mark.parametrize(
    ("frame", "axes", "length", "error"),
    [("nope", "world", None, NameNotFoundError), (3, "world", None, InvalidInputError),
     ("tool0", "body", None, InvalidInputError), ("tool0", "world", -1.0, InvalidInputError)],
)  # fmt: skip
def test_errors_of_the_frame_axes_and_length_name_no_configuration(ur5, frame, axes, length,
                                                                   error):  # fmt: skip
    """They concern every configuration alike: no "at configuration 0 of Q" note (there
    was one, the single query of configuration 0 raising them again)."""
    clm, q = ur5
    with pytest.raises(error) as e:
        cl.compliances(clm, [q, q], frame, axes, length=length)
    assert not getattr(e.value, "__notes__", None), e.value.__notes__


#: Condition numbers up to 1e10, stacked path and single query: both the squared ratio of
#: the extreme singular values of one factor (formed in two orders), each with relative
#: error ~eps sqrt(cond) = 2e-11 at cond 1e10 (measured: below 2e-15); 50 times that. The
#: eigenvalues of the formed C_s err by ~eps cond (2.6e-7 measured at cond 1.7e9).
RTOL_COND_FACTOR = 1e-9


def test_ill_conditioned_poses_have_the_single_query_condition_number(ur5):
    """Near the elbow singularity (q3 from 1e-2 to 1e-4 rad: cond 1e6 to 1e10, all on the
    stacked path) the condition number is the single query's to rounding."""
    clm, q = ur5
    Q = np.repeat(q[None], 9, axis=0)
    Q[:, 2] = np.logspace(-2, -4, len(Q))
    batch = cl.compliances(clm, Q, "tool0")
    assert batch.stacked.all() and (batch.rank == 6).all()
    assert batch.condition_number.max() > 1e9
    for i, q_i in enumerate(Q):
        single = cl.compliance(clm, q_i, "tool0")
        assert batch.condition_number[i] == pytest.approx(single.condition_number,
                                                          rel=RTOL_COND_FACTOR)  # fmt: skip


def test_no_configuration_gives_empty_arrays(ur5):
    batch = cl.compliances(ur5[0], np.zeros((0, 6)), "tool0")
    assert batch.C.shape == (0, 6, 6) and batch.G.shape == (0, 6, 6) and batch.rank.size == 0
    with pytest.raises(NameNotFoundError, match="nope"):  # still checked without a query
        cl.compliances(ur5[0], np.zeros((0, 6)), "nope")


def test_threads_sharing_one_model_get_their_own_answers(ur5):
    """Each call takes a workspace of the model's pool: calls from several threads at
    once give what each gives alone."""
    clm, _ = ur5
    stacks = [_ur5_poses(40, seed=s) for s in range(6)]
    alone = [cl.compliances(clm, Q, "tool0").C for Q in stacks]
    results: dict[int, np.ndarray] = {}

    def run(k: int) -> None:
        for _ in range(5):
            results[k] = cl.compliances(clm, stacks[k], "tool0").C

    threads = [threading.Thread(target=run, args=(k,)) for k in range(len(stacks))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k, C in enumerate(alone):
        np.testing.assert_array_equal(results[k], C)


def test_a_long_stack_is_computed_in_parts(ur5, monkeypatch):
    """Q longer than closedloop.elastostatics.batch.STACK is computed STACK configurations at a time
    (bounded memory), with the answers of one stack."""
    import closedloop.elastostatics.batch

    clm, _ = ur5
    Q = _ur5_poses(25, seed=4)
    whole = cl.compliances(clm, Q, "tool0")
    monkeypatch.setattr(closedloop.elastostatics.batch, "STACK", 7)
    parts = cl.compliances(clm, Q, "tool0")
    np.testing.assert_array_equal(parts.rank, whole.rank)
    assert_close_in_norm(parts.C, whole.C, RTOL_STACKED)
    assert_close_in_norm(parts.G, whole.G, RTOL_STACKED)


@pytest.mark.parametrize("p", [1, 2, 7, 16])
def test_stacked_triangular_inverses_solve_each_triangle(p):
    """upper_triangular_inverses against LAPACK's triangular solve of R X = I, matrix by
    matrix; the entries below the diagonal are not read."""
    import scipy.linalg

    from closedloop.common.arrays import upper_triangular_inverses

    rng = np.random.default_rng(p)
    R = rng.normal(size=(5, p, p)) + 4.0 * np.eye(p)  # junk below the diagonal
    X = upper_triangular_inverses(R)
    for R_k, X_k in zip(R, X, strict=True):
        expected = scipy.linalg.solve_triangular(np.triu(R_k), np.eye(p))
        # both backward stable: rounding times cond(R) (~10 here)
        np.testing.assert_allclose(X_k, expected, rtol=0, atol=1e-13 * abs(expected).max())
    R[2, p - 1, p - 1] = 0.0  # a zero pivot: not finite, no error
    with np.errstate(divide="ignore", invalid="ignore"):
        assert not np.isfinite(upper_triangular_inverses(R)[2]).all()

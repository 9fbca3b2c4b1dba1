"""The prepared query, closedloop.ComplianceQuery: its results are the plain query's to the
last bit (one plan of the frame, the same operations: np.testing.assert_array_equal is the
right comparison here, not a tolerance), on every path and kind of model, from several
threads at once; its errors are the plain query's; a q is checked once."""

from __future__ import annotations

import re
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest
from helpers import Calls
from mechanisms import PATH_CASES, cahyman_case, serial_with_block, ur5_case

import closedloop as cl
from closedloop.elastostatics.query import query_plan
from closedloop.kinematics.configuration import Configuration
from closedloop.model.closed_loop import ClosedLoopModel

#: Every field of a ComplianceResult.
FIELDS = ("C", "frame", "axes", "point", "q", "rank", "rigid_directions", "closure_residual",
          "mobility", "internal_mobilities", "G", "length", "condition_number",
          "stiffness_matrix", "path", "note")  # fmt: skip
#: The UR5's links as aluminium tubes (as scripts/bench_closedloop.py): link -> beam end.
UR5_BEAMS = {"upper_arm_link": "elbow_joint", "forearm_link": "wrist_1_joint"}
TUBE = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}


def assert_same_result(a, b) -> None:
    """Every field of two results equal, bit for bit (arrays with their shapes)."""
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=name, strict=True)
        else:
            assert x == y, name


def assert_read_only(result) -> None:
    for name in ("C", "G", "point", "q", "rigid_directions"):
        assert not getattr(result, name).flags.writeable, name
    if result.stiffness_matrix is not None:
        assert not result.stiffness_matrix.flags.writeable


# --------------------------------------------------------- the plain query's results
@pytest.mark.parametrize("path", ["auto", "null-space"])
@pytest.mark.parametrize("name", sorted(PATH_CASES))
def test_the_prepared_query_is_the_plain_query_on_every_path(name, path):
    """Serial (UR5), partitioned (four-bar, CaHyMan, Stewart, 3-RRR, five-bar) and
    null-space (the Delta, every model with path='null-space'), in both axes."""
    build, taken = PATH_CASES[name]
    clm, q, frame = build()
    for axes in ("world", "local"):
        query = cl.ComplianceQuery(clm, frame, axes, path=path)
        result = query(q)
        assert result.path == (taken if path == "auto" else "null-space")
        assert_same_result(result, cl.compliance(clm, q, frame, axes, path=path))
        assert_same_result(query(q), result)  # and again: nothing kept between calls
        assert_read_only(result)


def test_the_prepared_query_at_a_length_and_without_limits(fourbar):
    clm, q = fourbar
    query = cl.ComplianceQuery(clm, "P", length=2.5, check_limits=False)
    assert (query.model, query.frame, query.axes, query.path) == (clm, "P", "world", "auto")
    assert (query.length, query.check_limits) == (2.5, False)
    assert_same_result(query(q), cl.compliance(clm, q, "P", length=2.5, check_limits=False))
    with pytest.raises(AttributeError):  # what was resolved stays so
        query.length = 1.0


def test_typed_and_elastic_closures_give_the_plain_query(fourbars, pins):
    """Revolute, cylindrical, universal and prismatic closures, two point closures, a
    weld, and the sprung pin of a '6d' and a 'revolute' elastic closure."""
    cases = [(clm, [q]) for clm, q in fourbars.values()] + list(pins.values())
    for clm, Q in cases:
        query = cl.ComplianceQuery(clm, "P")
        for q in Q:
            assert_same_result(query(q), cl.compliance(clm, q, "P"))


def test_beams_and_spring_blocks_give_the_plain_query():
    ur5, q_arm, _ = ur5_case()
    beams = ur5.with_beams({link: {**TUBE, "end": end} for link, end in UR5_BEAMS.items()})
    q_beams = pin.neutral(beams.model)  # the beams' virtual joints at rest, the arm at q_arm
    for j, value in zip(range(1, ur5.model.njoints), q_arm, strict=True):
        q_beams[beams.model.joints[beams.model.getJointId(ur5.model.names[j])].idx_q] = value
    blocks, q_block, _ = serial_with_block()
    for clm, q, frame in ((beams, q_beams, "tool0"), (blocks, q_block, "tool")):
        result = cl.ComplianceQuery(clm, frame)(q)
        assert_same_result(result, cl.compliance(clm, q, frame))
        assert_same_result(
            cl.ComplianceQuery(clm, frame, path="null-space")(q),
            cl.compliance(clm, q, frame, path="null-space"),
        )


def test_a_configuration_gives_the_query_of_its_q():
    clm, q, frame = cahyman_case()
    state = Configuration(clm, q)
    assert_same_result(cl.ComplianceQuery(clm, frame)(q), cl.compliance(state, frame))


def test_the_partitioned_query_in_turn_at_poses_gives_the_plain_query_at_each():
    """The prepared partitioned query computes in a pooled workspace that the last call,
    at another pose, left behind (joint, frame and closure data): each result is the plain
    query's (a Configuration of its own) at its pose, in both axes."""
    from cahyman_pin.model import cahyman_model

    machine = cahyman_model()
    rng = np.random.default_rng(7)
    Q = [machine.assemble(np.deg2rad(rng.uniform(45, 75, 3)), rng.uniform(0.2, 1.2),
                          rng.uniform(0.0, 0.04)) for _ in range(4)]  # fmt: skip
    for axes in ("world", "local"):
        query = cl.ComplianceQuery(machine.clm, "M", axes)
        for q in Q + Q[::-1]:
            result = query(q)
            assert result.path == "partitioned"
            assert_same_result(result, cl.compliance(machine.clm, q, "M", axes))


def test_threads_sharing_one_query_and_one_model_give_the_serial_results():
    """8 threads, one query of one model each (their Pinocchio workspaces their own)."""
    poses = []
    for build in (cahyman_case, ur5_case):
        clm, q, frame = build()
        rng = np.random.default_rng(1)
        if clm.closures:  # CaHyMan: assembled poses around q
            from cahyman_pin.model import cahyman_model

            machine = cahyman_model()
            Q = [machine.assemble(np.deg2rad(rng.uniform(50, 70, 3)), 0.7, 0.01) for _ in range(6)]
        else:
            Q = [q + rng.uniform(-0.3, 0.3, q.size) for _ in range(6)]
        poses.append((cl.ComplianceQuery(clm, frame), Q))
    for query, Q in poses:
        serial = [query(q) for q in Q]
        with ThreadPoolExecutor(max_workers=8) as pool:
            for _ in range(4):
                threaded = list(pool.map(query, Q * 8))
                for i, result in enumerate(threaded):
                    assert_same_result(result, serial[i % len(Q)])


def test_with_and_without_numpy_warnings_the_serial_arithmetic_is_the_same():
    """A serial robot whose numbers cannot overflow is queried with numpy's error state as it
    is, others under np.errstate: the same operations either way."""
    clm, q, frame = ur5_case()
    plan = query_plan(clm, frame)
    assert plan._bounded  # the UR5 with 1e4 N m/rad springs: nothing near the float range
    state = Configuration(clm, q).require_closed()
    J = pin.getFrameJacobian(clm.model, state.data, plan._fid, plan._reference)
    assert_same_result(plan._guarded(state, J), plan.at(state))


@pytest.mark.parametrize("k", [1e-310, 1e308])
def test_overflowing_springs_are_the_typed_error_without_a_warning(ur5_urdf, k):
    clm = cl.load_model(ur5_urdf, joint_stiffness=k, geometry=False)
    query = cl.ComplianceQuery(clm, "tool0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(cl.SingularConfigurationError, match=re.escape(f"{k:.3g}")):
            query(np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3]))


# ------------------------------------------------------------------------ errors
def test_what_does_not_change_is_refused_when_the_query_is_made(fourbar):
    clm, _ = fourbar
    with pytest.raises(cl.NameNotFoundError, match="'Q'"):
        cl.ComplianceQuery(clm, "Q")
    for kwargs, expected in (
        ({"frame": 3}, "frame name must be a str"),
        ({"frame": "P", "axes": "body"}, "axes 'body'"),
        ({"frame": "P", "axes": ["world"]}, "axes"),
        ({"frame": "P", "path": "fast"}, "path 'fast'"),
        ({"frame": "P", "length": -1.0}, "characteristic length"),
    ):
        with pytest.raises(cl.InvalidInputError, match=re.escape(expected)):
            cl.ComplianceQuery(clm, **kwargs)
    with pytest.raises(cl.InvalidInputError, match="expected a ClosedLoopModel"):
        cl.ComplianceQuery(clm.model, "P")


def test_a_model_without_moving_joint_is_refused_when_the_query_is_made():
    model = pin.Model()
    model.addFrame(pin.Frame("tip", 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    with pytest.raises(cl.InvalidInputError, match=r"no moving joint \(nv = 0\)"):
        cl.ComplianceQuery(ClosedLoopModel(model, name="rigid"), "tip")


def _error(call, *args, **kwargs):
    try:
        call(*args, **kwargs)
    except cl.ClosedLoopError as e:
        return type(e), str(e)
    raise AssertionError("no error")


def test_bad_configurations_are_the_plain_query_errors(fourbar, ur5):
    """A q of the wrong size, NaN, strings, a stack of them, joints outside their limits,
    open loops: the error (type and message) of the plain query, at each call."""
    clm, q = fourbar
    arm, q_arm = ur5
    query, arm_query = cl.ComplianceQuery(clm, "P"), cl.ComplianceQuery(arm, "tool0")
    bad = [
        (query, clm, q[:-1], "P"),
        (query, clm, np.r_[q[:-1], np.nan], "P"),
        (query, clm, ["a"] * q.size, "P"),
        (query, clm, np.array([q, q]), "P"),
        (query, clm, [0.3, 0.0, 0.0, 0.0, 0.0], "P"),  # does not close the loop
        (arm_query, arm, np.r_[q_arm[:2], 20.0, q_arm[3:]], "tool0"),  # degrees?
    ]
    for prepared, model, value, frame in bad:
        error = _error(prepared, value)
        assert error == _error(cl.compliance, model, value, frame)
        assert error[0] is not cl.ClosedLoopError
    outside = np.r_[q_arm[:2], 20.0, q_arm[3:]]
    assert _error(arm_query, outside)[0] is cl.OutsideLimitsError
    unchecked = cl.ComplianceQuery(arm, "tool0", check_limits=False)
    assert_same_result(unchecked(outside), cl.compliance(arm, outside, "tool0", check_limits=False))


# ------------------------------------------------------------------ checked once
def test_a_query_checks_q_and_its_limits_once(monkeypatch, ur5):
    import closedloop.kinematics.configuration as configuration

    clm, q = ur5
    query = cl.ComplianceQuery(clm, "tool0")
    checks = Calls(monkeypatch, ClosedLoopModel, "check_configuration")
    limits = Calls(monkeypatch, configuration, "require_within_limits")
    query(q)
    cl.compliance(clm, q, "tool0")
    assert (checks.n, limits.n) == (2, 2)  # once a query


def test_the_cahyman_query_checks_its_assembled_q_and_its_limits_once(monkeypatch):
    """cahyman_pin.api.stiffness: q from the assembly is checked by the Configuration of
    the query, and its limits (in CaHyMan's words) once (each was done twice)."""
    import cahyman_pin.model as cahyman
    import closedloop.kinematics.configuration as configuration
    from cahyman_pin.api import stiffness

    checks = Calls(monkeypatch, ClosedLoopModel, "check_configuration")
    limits = [Calls(monkeypatch, m, "joints_outside_limits") for m in (cahyman, configuration)]
    result = stiffness(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01)
    assert result.is_full_rank
    assert (checks.n, sum(c.n for c in limits)) == (1, 1)

"""The query entry points at their edges: compliance(), compliances() and Configuration
at poses near singular ones, with extreme springs and lengths, at coordinates too large
for the kinematics to resolve the loops, from several threads at once, and the model's
memo under a sweep of lengths."""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from mechanisms import fourbar_case, stewart_near_singular

import closedloop as cl
from closedloop.elastostatics.batch import QUERY_ERRORS
from closedloop.kinematics.configuration import CLOSURE_TOL
from closedloop.model.beams import map_configuration
from closedloop.model.closed_loop import MEMO_SIZE, ClosedLoopModel

#: Stacked vs single query: the same formulas in LAPACK calls of another order of
#: operations (as tests/elastostatics/test_batch.py).
RTOL_STACKED = 1e-12
#: Crank angles [rad] of the bundled four-bar that assemble.
CRANKS = np.linspace(0.05, 1.2, 12)


def _single_or_error(clm, q, frame, length):
    try:
        return cl.compliance(clm, q, frame, length=length)
    except QUERY_ERRORS as e:
        return e


def _assert_batch_is_single(clm, Q, frame, length=None):
    """compliances() gives each pose's compliance() C, G and rank, or its error type (on
    the pose alone, and at the first such pose of the whole stack)."""
    singles = [_single_or_error(clm, q, frame, length) for q in Q]
    for q, single in zip(Q, singles, strict=True):
        if isinstance(single, Exception):
            with pytest.raises(type(single)):
                cl.compliances(clm, q[None], frame, length=length)
            continue
        batch = cl.compliances(clm, q[None], frame, length=length)
        assert batch.rank[0] == single.rank
        assert_close_in_norm(batch.C[0], single.C, RTOL_STACKED)
        assert_close_in_norm(batch.G[0], single.G, RTOL_STACKED)
    errors = [s for s in singles if isinstance(s, Exception)]
    if errors:
        with pytest.raises(type(errors[0])):
            cl.compliances(clm, Q, frame, length=length)
    return singles


# ------------------------------------------------ batch against single, at the edges
@pytest.mark.parametrize("springs", [1e-12, 1e12])
@pytest.mark.parametrize("length", [1e-3, 1e3])
def test_stewart_stepping_onto_its_singularity_is_answered_as_the_single_query(springs, length):
    """Fichter's singularity approached to 1e-4, 1e-8, 1e-12 rad and reached, with leg
    springs scaled by 1e-12 or 1e12 and the unit-free rules at 1 mm or 1 km."""
    clm = stewart_near_singular(0.1).clm
    clm = clm.with_springs({k: v * springs for k, v in clm.springs.items()})
    Q = np.array([stewart_near_singular(d).q for d in (0.1, 1e-4, 1e-8, 1e-12, 0.0)])
    singles = _assert_batch_is_single(clm, Q, "platform", length)
    assert isinstance(singles[0], cl.ComplianceResult)
    assert isinstance(singles[-1], cl.MechanismError)  # at the singularity: no equilibrium


# ------------------------------------------- coordinates the kinematics cannot resolve
def test_sliders_far_beyond_the_mechanism_close_no_loop():
    """The four-bar with both axial sliders at s = 1e17 m and the three angles equal
    (crank 0.3 rad): both closure anchors move by s along one direction, so the residual
    is that at s = 0, a loop open by 0.65 L. Placed 1e17 m from the origin, the anchors
    are known to ~16 m: the residual rounded to exactly 0, the loop counted as closed
    and both queries answered (rank 1, C of 1e32 m/N). The sliders' limits (+-0.01 m)
    would refuse these q first: not checked here."""
    clm, q_ok, frame = fourbar_case()
    at = lambda s: np.array([0.3, s, 0.3, 0.3, s])  # noqa: E731
    assert cl.Configuration(clm, at(0.0)).closure_error > 0.1  # the loop is open
    far = cl.Configuration(clm, at(1e17), check_limits=False)
    assert not far.is_closed
    with pytest.raises(cl.OpenLoopError, match=r"joints up to 2e\+17 m from the world origin"):
        far.require_closed()
    with pytest.raises(cl.OpenLoopError, match="closure residual is known to"):
        cl.compliance(clm, at(1e17), frame, check_limits=False)
    with pytest.raises(cl.OpenLoopError) as info:
        cl.compliances(clm, np.array([q_ok, at(1e17)]), frame, check_limits=False)
    with pytest.raises(cl.OutsideLimitsError, match="crank_axial = 1e"):
        cl.compliance(clm, at(1e17), frame)
    assert "at configuration 1 of Q" in info.value.__notes__


def _carriage_parallelogram() -> ClosedLoopModel:
    """A parallelogram four-bar (crank 0.3 m, sprung 1e3 N m/rad; coupler 0.2 m; rocker
    0.3 m, pivots 0.2 m apart) on a locked carriage sliding along x: at q = (s, t, -t, t)
    the loop closes for every carriage position s [m]; the frame ``tip`` is the rocker's
    tip."""
    m = pin.Model()
    at = lambda x: pin.SE3(np.eye(3), np.array([x, 0.0, 0.0]))  # noqa: E731
    carriage = m.addJoint(0, pin.JointModelPX(), at(0.0), "carriage")
    crank = m.addJoint(carriage, pin.JointModelRZ(), at(0.0), "crank")
    coupler = m.addJoint(crank, pin.JointModelRZ(), at(0.3), "coupler")
    rocker = m.addJoint(carriage, pin.JointModelRZ(), at(0.2), "rocker")
    m.addFrame(pin.Frame("tip", rocker, at(0.3), pin.FrameType.OP_FRAME))
    closure = pin.PointAnchorConstraintModel(m, coupler, at(0.2), rocker, at(0.3))
    return ClosedLoopModel(m, [closure], ["crank"], {"crank": 1e3}, ["carriage"])


def test_a_carriage_too_far_to_resolve_the_loop_is_refused_by_both_queries():
    """The carriage moves the whole loop: the residual at s is that at s = 0. At
    s = 1e14 m the kinematics no longer resolve it (an open pose's residual is lost
    there): the single query refused such a pose, the stacked path answered it. At
    s = 1e6 m both give the compliance at s = 0."""
    clm = _carriage_parallelogram()
    pose = lambda s, rocker=0.8: np.array([s, 0.8, -0.8, rocker])  # noqa: E731
    gap = cl.Configuration(clm, pose(0.0, 0.801)).residual  # the loop opened by 1e-3 rad
    lost = cl.Configuration(clm, pose(1e14, 0.801)).residual
    assert np.max(abs(lost - gap)) > CLOSURE_TOL * clm.length
    with pytest.raises(cl.OpenLoopError, match="closure residual is known to"):
        cl.compliance(clm, pose(1e14), "tip")
    with pytest.raises(cl.OpenLoopError, match="closure residual is known to"):
        cl.compliances(clm, pose(1e14)[None], "tip")
    ref = cl.compliance(clm, pose(0.0), "tip")
    # lever arms of 0.3 m with positions known to eps 1e6 m = 2e-10 m
    rtol = 1e-8
    assert_close_in_norm(cl.compliance(clm, pose(1e6), "tip").C, ref.C, rtol)
    assert_close_in_norm(cl.compliances(clm, pose(1e6)[None], "tip").C[0], ref.C, rtol)


# --------------------------------------------------------------------------- threads
def test_threads_sharing_models_and_configurations_give_the_serial_results():
    """Eight threads switching every microsecond: queries of one model, of shared
    configurations whose Jacobians are first computed there, stacked queries, and models
    built (with_beams) while the others query, all give the serial answers bit for bit."""
    clm, _, frame = fourbar_case()
    Q = np.array([cl.assemble(clm, actuated=[a]).q for a in CRANKS])
    beam = {"rocker_link": {"E": 7e10, "G": 2.6e10, "end": "rocker_axial",
                            "section": {"shape": "tube", "d": 0.02, "t": 0.002}}}  # fmt: skip
    flex = clm.with_beams(beam)
    Q_flex = np.array([map_configuration(clm.model, flex.model, q) for q in Q])
    serial = {
        "single": [cl.compliance(clm, q, frame).C for q in Q],
        "stacked": [cl.compliances(clm, q[None], frame).C[0] for q in Q],
        "beams": [cl.compliance(flex, q, frame).C for q in Q_flex],
    }
    states = [cl.Configuration(clm, q) for q in Q]  # shared by the threads
    kinds = {
        "single": lambda i: cl.compliance(clm, Q[i], frame).C,
        "state": lambda i: cl.compliance(states[i], frame).C,
        "own state": lambda i: cl.compliance(cl.Configuration(clm, Q[i]), frame).C,
        "stacked": lambda i: cl.compliances(clm, Q[i : i + 1], frame).C[0],
        "beams": lambda i: cl.compliance(clm.with_beams(beam), Q_flex[i], frame).C,
    }
    jobs = [(kind, i % len(Q)) for i in range(120) for kind in kinds]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        with ThreadPoolExecutor(8) as pool:
            results = list(pool.map(lambda job: kinds[job[0]](job[1]), jobs))
    finally:
        sys.setswitchinterval(interval)
    for (kind, i), C in zip(jobs, results, strict=True):
        expected = serial.get(kind, serial["single"])[i]
        np.testing.assert_array_equal(C, expected, err_msg=f"{kind} at pose {i}")


# ------------------------------------------------------------------------------ memo
def test_a_sweep_of_lengths_keeps_a_bounded_memo():
    """Each length L of the unit-free rules has its scaling (tens of kB on CaHyMan): a
    sweep of lengths kept them all. Past MEMO_SIZE entries they are dropped, and a length
    asked again is computed again, to the same answer."""
    base, q, frame = fourbar_case()
    clm = base.with_springs(base.springs)  # a memo of its own
    first = cl.compliance(clm, q, frame, length=0.5)
    for k in range(3 * MEMO_SIZE):
        cl.compliances(clm, q[None], frame, length=0.5 + 1e-3 * (k + 1))
    assert len(clm._memo) <= MEMO_SIZE + 1
    again = cl.compliance(clm, q, frame, length=0.5)
    np.testing.assert_array_equal(again.C, first.C)
    assert again.rank == first.rank and again.condition_number == first.condition_number

"""The pieces of the fast compliance paths against independent computations.

The path equality on every test mechanism is in test_compliance_paths.py; here: the
passive motion X against numpy's SVD least squares, the serial path of a chain with
locked, prismatic and block-spring joints against C = J K^-1 J^T written out, the exact
symmetry of C and K, and the validation of q and the closure residual norm.
"""

from __future__ import annotations

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from mechanisms import PATH_CASES as CASES
from mechanisms import serial_with_block

import closedloop as cl
from closedloop.elastostatics.partition import partition, scaling
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import closure_residual

#: X = -J_p^+ J_s by QR (the library) and by SVD (numpy.linalg.lstsq) on a passive part
#: of condition ~1e2: they agree to rounding times the condition.
RTOL_LSTSQ = 1e-12
#: Fast paths (serial, partitioned, by blocks) against the null-space path.
RTOL_PATHS = 1e-12
#: C = J K^-1 J^T by an explicit inverse of the 6x6 block vs the scaled factor: rounding
#: times cond(K_q) ~ 1e4 here.
RTOL_CLOSED_FORM = 1e-10


def test_passive_motion_is_the_least_squares_solution():
    from cahyman_pin.model import cahyman_model

    m = cahyman_model()
    q = m.assemble(np.deg2rad([50.0, 65.0, 70.0]), np.deg2rad(30.0), 0.02)
    state = Configuration(m.clm, q)
    sc = scaling(state)
    path, X = partition(state, sc)
    assert path == "partitioned"
    Jc = np.where(m.clm.linear_rows[:, None], state.closure_jacobian() / state.length,
                  state.closure_jacobian())  # fmt: skip
    s_q = np.where(m.clm.linear_coordinates, state.length, 1.0)
    J_p = Jc[:, sc.passive] * s_q[sc.passive]
    J_s = Jc[:, sc.sprung] * s_q[sc.sprung]
    reference = np.linalg.lstsq(J_p, -J_s, rcond=None)[0]
    np.testing.assert_allclose(X, reference, rtol=0, atol=RTOL_LSTSQ * np.abs(reference).max())
    # the closures hold along every spring motion
    np.testing.assert_allclose(J_s + J_p @ X, 0.0, atol=RTOL_LSTSQ * np.abs(J_s).max())


def _chain_with_locked_prismatic_and_block():
    """RZ (spring), PX (spring, N/m), RY (locked), spherical (3x3 block), tool frame."""
    model = pin.Model()
    j0 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "base")
    j1 = model.addJoint(j0, pin.JointModelPX(), pin.SE3(np.eye(3), np.array([0.3, 0, 0])), "slide")
    j2 = model.addJoint(j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0, 0, 0.2])), "lock")
    place = pin.SE3(pin.exp3(np.array([0.1, 0.2, -0.3])), np.array([0.25, 0.05, 0.0]))
    j3 = model.addJoint(j2, pin.JointModelSpherical(), place, "wrist")
    model.addFrame(pin.Frame("tool", j3, pin.SE3(np.eye(3), np.array([0.1, 0.0, 0.05])),
                             pin.OP_FRAME))  # fmt: skip
    block = np.array([[300.0, 40.0, -20.0], [40.0, 250.0, 10.0], [-20.0, 10.0, 200.0]])
    springs = {"base": 2e3, "slide": 5e5, "wrist": block}
    clm = cl.ClosedLoopModel(model, springs=springs, locked=["lock"], name="mixed")
    q = pin.neutral(model)
    q[:3] = [0.4, 0.05, -0.3]
    q[3:] = pin.Quaternion(pin.exp3(np.array([0.2, -0.1, 0.3]))).coeffs()
    return clm, q


@pytest.mark.parametrize("axes", ["world", "local"])
def test_serial_path_with_locked_prismatic_and_block_springs(axes):
    clm, q = _chain_with_locked_prismatic_and_block()
    res = cl.compliance(clm, q, "tool", axes)
    assert res.path == "serial"
    data = clm.model.createData()
    pin.computeJointJacobians(clm.model, data, q)
    pin.updateFramePlacements(clm.model, data)
    ref = pin.LOCAL_WORLD_ALIGNED if axes == "world" else pin.LOCAL
    J = pin.getFrameJacobian(clm.model, data, clm.model.getFrameId("tool"), ref)
    kept = [0, 1, 3, 4, 5]  # every coordinate but the locked one
    K = np.zeros((5, 5))
    K[0, 0], K[1, 1] = 2e3, 5e5
    K[2:, 2:] = clm.spring_blocks["wrist"]
    G_ref = np.zeros((6, 6))
    G_ref[kept] = np.linalg.solve(K, J[:, kept].T)
    C_ref = J @ G_ref
    scale = np.abs(C_ref).max()
    np.testing.assert_allclose(res.C, C_ref, rtol=0, atol=RTOL_CLOSED_FORM * scale)
    np.testing.assert_allclose(res.G, G_ref, rtol=0, atol=RTOL_CLOSED_FORM * np.abs(G_ref).max())
    general = cl.compliance(clm, q, "tool", axes, path="null-space")
    np.testing.assert_allclose(res.C, general.C, rtol=0, atol=RTOL_PATHS * scale)
    assert res.rank == general.rank == 5  # the locked rotation is rigid
    np.testing.assert_allclose(res.rigid_directions, general.rigid_directions, atol=1e-10)


@pytest.mark.parametrize("name", sorted(CASES))
def test_compliance_and_stiffness_are_exactly_symmetric(name):
    clm, q, frame = CASES[name][0]()
    for path in ("auto", "null-space"):
        res = cl.compliance(clm, q, frame, path=path)
        np.testing.assert_array_equal(res.C, res.C.T)
        if res.is_full_rank:
            np.testing.assert_array_equal(res.K, res.K.T)


def test_block_serial_chain_is_exactly_symmetric():
    clm, q, _ = serial_with_block()
    res = cl.compliance(clm, q, "tool")
    assert res.path == "serial"
    np.testing.assert_array_equal(res.C, res.C.T)
    np.testing.assert_array_equal(res.K, res.K.T)


def test_configuration_copies_q_and_refuses_bad_values():
    m = mech.fivebar((0.02, 0.35))
    q = np.array(m.q, dtype=float)
    state = Configuration(m.clm, q)
    q[0] += 1.0  # the configuration kept its own copy
    assert state.q[0] == m.q[0]
    np.testing.assert_allclose(state.residual_norm, np.abs(state.residual).max(), rtol=0)
    for bad, match in ((np.r_[m.q[:-1], np.nan], "non-finite"), (m.q[:-1], "expected nq"),
                       (np.array(m.q, dtype=np.float32)[:-1], "expected nq"),
                       (np.array(m.q).astype(complex), "real numbers")):  # fmt: skip
        with pytest.raises(cl.InvalidInputError, match=match):
            Configuration(m.clm, bad)
    for bad in (np.inf, -np.inf):  # an infinite entry next to finite ones of either sign
        for other in (1e308, -1e308):
            with pytest.raises(cl.InvalidInputError, match="non-finite"):
                m.clm.check_configuration(np.r_[bad, np.full(m.q.size - 1, other)])
    # finite entries whose sum overflows are finite values, accepted as they are
    huge = np.full(m.q.size, 1e308)
    np.testing.assert_array_equal(m.clm.check_configuration(huge), huge)


def test_closure_error_of_metre_rows_is_the_scaled_residual_norm():
    # point closures only (metres): closure_error = max |r| / L, the scaling of every row
    m = mech.fivebar((0.02, 0.35))
    state = Configuration(m.clm, m.q, length=0.7)
    assert m.clm.linear_rows.all() and state.residual.size
    expected = np.max(np.abs(state.residual) / 0.7)
    np.testing.assert_allclose(state.closure_error, expected, rtol=1e-15)


@pytest.mark.parametrize("name", sorted(n for n, (_, path) in CASES.items() if path != "serial"))
def test_loop_by_loop_solve_equals_the_dense_one(name, monkeypatch):
    """The block path (for many passive joints) forced on every test mechanism with loops."""
    import closedloop.elastostatics.partition as partition

    build, expected_path = CASES[name]
    dense = cl.compliance(*build())
    monkeypatch.setattr(partition, "BLOCK_PASSIVE", 1)
    clm, q, frame = build()
    clm = clm.with_springs(clm.springs, clm.locked)  # a new model, scaled with the blocks
    assert partition.scaling(Configuration(clm, q)).loop_blocks is not None
    blocks = cl.compliance(clm, q, frame)
    assert blocks.path == dense.path == expected_path
    general = cl.compliance(clm, q, frame, path="null-space")
    for res in (dense, general):
        scale = np.abs(res.C).max()
        np.testing.assert_allclose(blocks.C, res.C, rtol=0, atol=RTOL_PATHS * scale)
        np.testing.assert_allclose(blocks.G, res.G, rtol=0, atol=RTOL_PATHS * np.abs(res.G).max())


def _fourbar_chain(n: int):
    """n planar parallelogram four-bars in series, each standing on the previous rocker
    (as in scripts/bench_closedloop.py), springs on the cranks."""
    model, closures, q, base = pin.Model(), [], [], 0
    for i in range(n):
        t = 0.8 if i % 2 == 0 else -0.8
        place = [pin.SE3(np.eye(3), np.array([x, 0.0, 0.0])) for x in (0.0, 0.3, 0.2)]
        crank = model.addJoint(base, pin.JointModelRZ(), place[0], f"crank{i}")
        coupler = model.addJoint(crank, pin.JointModelRZ(), place[1], f"coupler{i}")
        rocker = model.addJoint(base, pin.JointModelRZ(), place[2], f"rocker{i}")
        closures.append(pin.PointAnchorConstraintModel(model, coupler, place[2], rocker, place[1]))
        q += [t, -t, t]
        base = rocker
    model.addFrame(pin.Frame("tip", base, pin.SE3(np.eye(3), np.array([0.3, 0, 0])), pin.OP_FRAME))
    cranks = [f"crank{i}" for i in range(n)]
    springs = {c: 1e3 * (1.0 + 0.1 * i) for i, c in enumerate(cranks)}
    return cl.ClosedLoopModel(model, closures, cranks, springs, name=f"4bar{n}"), np.array(q)


def test_closure_jacobian_vanishes_on_common_ancestors():
    """The premise of the block path, by central differences of the residual at a
    configuration that does not close: moving a common ancestor of a closure's two joints
    leaves its residual unchanged."""
    clm, q = _fourbar_chain(4)
    q = q + 0.05 * np.sin(np.arange(q.size) + 1.0)  # open loops
    h = 1e-6
    for i, c in enumerate(clm.closures):
        j1, j2 = c.constraint.joint1_id, c.constraint.joint2_id
        common = set(clm.model.supports[j1]) & set(clm.model.supports[j2]) - {0}
        for j in common:
            e = np.zeros(clm.model.nv)
            e[clm.model.joints[j].idx_v] = h
            rows = slice(3 * i, 3 * i + 3)
            plus = closure_residual(clm, pin.integrate(clm.model, q, e))[rows]
            minus = closure_residual(clm, pin.integrate(clm.model, q, -e))[rows]
            np.testing.assert_allclose((plus - minus) / (2 * h), 0.0, atol=1e-9)
        assert common or i == 0


def test_chain_of_loops_by_blocks_equals_the_null_space_path():
    clm, q = _fourbar_chain(30)  # 60 passive coordinates: the block path
    from closedloop.elastostatics.partition import BLOCK_PASSIVE, scaling

    state = Configuration(clm, q)
    assert int(np.sum(clm.stiffness == 0)) >= BLOCK_PASSIVE
    ((rows, passive, springs, *_),) = scaling(state).loop_blocks  # one shape: each loop
    # a loop's block: its closure rows, its coupler and rocker, and its own crank only
    assert rows.shape == (30, 3) and passive.shape == (30, 2) and springs.shape == (30, 1)
    fast = cl.compliance(state, "tip")
    general = cl.compliance(state, "tip", path="null-space")
    assert fast.path == "partitioned"
    scale = np.abs(general.C).max()
    np.testing.assert_allclose(fast.C, general.C, rtol=0, atol=RTOL_PATHS * scale)
    np.testing.assert_allclose(fast.G, general.G, rtol=0, atol=RTOL_PATHS * np.abs(general.G).max())
    assert fast.rank == general.rank == 3  # planar


def test_the_spring_factor_basis_is_orthonormal_where_the_fast_path_applies():
    """spring_factor (what a preloaded compliance's rank rule reads) returns N orthonormal
    in the scaled coordinates, as documented, also where the partitioned path applies:
    it returned the fast path's N = [I; X], whose singular values (1 to 9.2 at this pose)
    moved that rule's threshold."""
    from cahyman_pin.model import cahyman_model
    from closedloop.elastostatics.springs import spring_factor

    m = cahyman_model()
    q = m.assemble(np.deg2rad([50.0, 65.0, 70.0]), np.deg2rad(30.0), 0.02)
    state = Configuration(m.clm, q)
    assert cl.compliance(state, "M").path == "partitioned"
    f = spring_factor(state, state.frame_jacobian("M"), "M")
    N_s = f.N / np.where(m.clm.linear_coordinates, state.length, 1.0)[:, None]
    np.testing.assert_allclose(N_s.T @ N_s, np.eye(N_s.shape[1]), atol=RTOL_PATHS)

"""Typed loop closures (revolute, prismatic, cylindrical, universal), each against an
independent description: its rows' Jacobian against finite differences, a four-bar cut at
a revolute closure against the same four-bar written with two point closures and with
the cut joint kept in the tree (the loop welded elsewhere)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm, tangent_differences
from spatial_fourbar import DESCRIPTIONS, INF, SHARED, fourbar_as, shared_values, urdf_text

import closedloop as cl
from closedloop.io.loader import load_model
from closedloop.kinematics.constraints import closure_jacobian, closure_residual
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import CLOSURE_TYPES, Closure

#: Central differences with step 1e-6: truncation ~1e-12, rounding ~1e-10 of the rows.
RTOL_DIFFERENCES = 1e-7
#: Two descriptions of one mechanism, each solved to rounding (assembly to 1e-12 L, the
#: compliance by factorisations of condition ~1e6 at most).
RTOL_SAME = 1e-8

TYPED = ("revolute", "prismatic", "cylindrical", "universal")
ROWS = {"revolute": 5, "prismatic": 5, "cylindrical": 4, "universal": 4}


def _sample(kind: str, seed: int) -> tuple[ClosedLoopModel, np.ndarray]:
    """Pinocchio's 6R sample manipulator with a ``kind`` closure between random frames on
    joints 2 and 6, at a random configuration (not closed: the rows away from zero)."""
    rng = np.random.default_rng(seed)
    model = pin.buildSampleModelManipulator()
    M1 = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.2)
    M2 = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.2)
    c = Closure(CLOSURE_TYPES[kind](model, 2, M1, 6, M2), f"{kind} cut", kind)
    clm = ClosedLoopModel(model, [c], [])
    return clm, rng.uniform(-2.0, 2.0, model.nq)


@pytest.mark.parametrize("kind", TYPED)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_rows_jacobian_is_their_derivative(kind, seed):
    clm, q = _sample(kind, seed)
    J = closure_jacobian(clm, q)
    assert J.shape == (ROWS[kind], clm.model.nv) and clm.n_constraints == ROWS[kind]
    expected = tangent_differences(clm.model, lambda x: closure_residual(clm, x).copy(), q)
    assert_close_in_norm(J, expected, RTOL_DIFFERENCES)


@pytest.mark.parametrize("kind", TYPED)
def test_each_type_vanishes_on_what_it_constrains_and_only_there(kind):
    """Rows of B placed against A by hand: zero exactly on the allowed relative motions."""
    from closedloop.kinematics.constraints import typed_residual

    along_z, turn_z = (
        pin.SE3(np.eye(3), np.array([0, 0, 0.3])),
        pin.SE3(pin.exp3(np.array([0, 0, 0.7])), np.zeros(3)),
    )
    tilt = pin.SE3(pin.exp3(np.array([0.7, 0, 0])), np.zeros(3))  # z_B turned off z_A
    side = pin.SE3(np.eye(3), np.array([0.3, 0, 0]))
    allowed = {
        "revolute": [turn_z],
        "prismatic": [along_z],
        "cylindrical": [turn_z, along_z, turn_z * along_z],
        "universal": [pin.SE3(pin.exp3(np.array([math.pi / 2, 0, 0])), np.zeros(3))],
    }[kind]
    refused = {
        "revolute": [along_z, tilt, side],
        "prismatic": [turn_z, tilt, side],
        "cylindrical": [tilt, side],
        "universal": [pin.SE3.Identity(), side],
    }[kind]
    for M in allowed:
        np.testing.assert_allclose(typed_residual(kind, M), 0.0, atol=1e-15)
    for M in refused:
        assert np.max(np.abs(typed_residual(kind, M))) > 0.1


# --------------------------------------------------------- a four-bar cut at its pin C
def test_a_revolute_closure_assembles_as_the_other_descriptions(fourbars):
    clm, q = fourbars["revolute closure"]
    assert [c.kind for c in clm.closures] == ["revolute"] and clm.n_constraints == 5
    for d in ("two point closures", "pin in the tree, rocker welded"):
        np.testing.assert_allclose(shared_values(clm, q), shared_values(*fourbars[d]), atol=1e-10)


@pytest.mark.parametrize("other", ["two point closures", "pin in the tree, rocker welded"])
def test_a_revolute_closure_has_the_compliance_of_the_other_descriptions(fourbars, other):
    clm, q = fourbars["revolute closure"]
    C = cl.compliance(clm, q, "P").C
    assert np.linalg.matrix_rank(C, tol=1e-9 * np.abs(C).max()) >= 2  # not a trivial answer
    expected = cl.compliance(*fourbars[other], "P").C
    assert_close_in_norm(C, expected, RTOL_SAME, scale=[1, 1, 1, 0.1, 0.1, 0.1])
    Q = np.array([q, cl.assemble(clm, [0.2], q).q])
    Q_other = np.array([fourbars[other][1], cl.assemble(fourbars[other][0], [0.2]).q])
    batch, batch_other = (
        cl.compliances(clm, Q, "P").C,
        cl.compliances(fourbars[other][0], Q_other, "P").C,
    )
    assert_close_in_norm(batch[0], C, RTOL_SAME, scale=[1, 1, 1, 0.1, 0.1, 0.1])
    assert_close_in_norm(batch[1], batch_other[1], RTOL_SAME, scale=[1, 1, 1, 0.1, 0.1, 0.1])


@pytest.mark.parametrize("gravity", [None, (0.0, 0.0, -9.81)])
def test_a_revolute_closure_has_the_statics_of_the_pin_in_the_tree(fourbars, gravity):
    """Nonlinear equilibrium under a load with moments (and the links' weight), and the
    preloaded compliance there (the closure rows' curvature, weighted by their forces)."""
    from closedloop.elastostatics.statics import frame_displacement

    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    moved, preloaded = {}, {}
    for d in ("revolute closure", "pin in the tree, rocker welded"):
        clm, q = fourbars[d]
        eq = cl.solve_equilibrium(clm, q, "P", wrench, gravity=gravity)
        moved[d] = frame_displacement(clm, eq.q, q, "P")
        preloaded[d] = cl.preloaded_compliance(clm, eq).C
    assert np.abs(moved["revolute closure"][:3]).min() > 5e-6  # in and out of the plane
    assert_close_in_norm(moved["revolute closure"], moved["pin in the tree, rocker welded"],
                         RTOL_SAME)  # fmt: skip
    C, C_tree = preloaded["revolute closure"], preloaded["pin in the tree, rocker welded"]
    unloaded = cl.compliance(*fourbars["revolute closure"], "P").C
    assert np.abs(C - unloaded).max() > 1e-4 * np.abs(unloaded).max()  # the preload counts
    # the curvature of either closure by central differences: ~1e-10 relative (tangent.py)
    assert_close_in_norm(C, C_tree, 1e-6, scale=[1, 1, 1, 0.1, 0.1, 0.1])


def test_a_revolute_closure_closed_with_its_z_axes_opposite_is_refused(tmp_path):
    """Its rows vanish with z_B = -z_A too: the assembly tells that branch apart."""
    clm = fourbar_as(tmp_path, "revolute closure", flip=True)
    with pytest.raises(cl.AssemblyError, match=r"z axes of closures \['cA<->cB'\] pointing"):
        cl.assemble(clm, [0.4])


@pytest.mark.parametrize(
    ("closure", "tree"),
    [("universal closure", "universal in the tree, rocker welded"),
     ("cylindrical closure", "cylindrical in the tree, rocker welded")],
)  # fmt: skip
def test_a_universal_or_cylindrical_closure_equals_its_joint_in_the_tree(fourbars, closure, tree):
    """The pin C of the spatial four-bar replaced by a universal or a cylindrical joint,
    written as a closure or kept in the tree as two joints (the loop welded in the
    rocker): the same assembly, compliance (single and batch) and nonlinear statics."""
    from closedloop.elastostatics.statics import frame_displacement

    (clm, q), (twin, q_twin) = fourbars[closure], fourbars[tree]
    assert clm.n_constraints == 4
    np.testing.assert_allclose(shared_values(clm, q), shared_values(twin, q_twin), atol=1e-10)
    scale = [1, 1, 1, 0.1, 0.1, 0.1]
    C = cl.compliance(clm, q, "P").C
    assert np.linalg.matrix_rank(C, tol=1e-9 * np.abs(C).max()) >= 3
    assert_close_in_norm(C, cl.compliance(twin, q_twin, "P").C, RTOL_SAME, scale=scale)
    batch = cl.compliances(clm, np.array([q, cl.assemble(clm, [0.2], q).q]), "P").C
    batch_twin = cl.compliances(twin, np.array([q_twin, cl.assemble(twin, [0.2], q_twin).q]), "P")
    assert_close_in_norm(batch[1], batch_twin.C[1], RTOL_SAME, scale=scale)
    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    moved = []
    for m, x in ((clm, q), (twin, q_twin)):
        eq = cl.solve_equilibrium(m, x, "P", wrench, gravity=(0.0, 0.0, -9.81))
        moved.append((frame_displacement(m, eq.q, x, "P"), cl.preloaded_compliance(m, eq).C))
    assert np.abs(moved[0][0][:3]).min() > 5e-6
    assert_close_in_norm(moved[0][0], moved[1][0], RTOL_SAME)
    assert_close_in_norm(moved[0][1], moved[1][1], 1e-6, scale=scale)


def test_a_revolute_closure_is_driven_as_the_pin_in_the_tree(fourbars):
    """assemble_connected: the crank driven from the drawing in steps, on one branch."""
    from closedloop.kinematics.driving import assemble_connected

    (clm, _), (twin, _) = fourbars["revolute closure"], fourbars["pin in the tree, rocker welded"]
    q = assemble_connected(clm, np.array([1.2])).q
    expected = shared_values(twin, assemble_connected(twin, [1.2]).q)
    np.testing.assert_allclose(shared_values(clm, q), expected, atol=1e-10)
    assert shared_values(clm, q)[0] == pytest.approx(1.2)


def test_a_closure_of_an_unknown_type_or_the_wrong_carrier_is_refused(tmp_path):
    from closedloop.exceptions import InvalidInputError, ModelFileError

    model = pin.buildSampleModelManipulator()
    point = pin.PointAnchorConstraintModel(model, 2, pin.SE3.Identity(), 6, pin.SE3.Identity())
    frame = pin.FrameAnchorConstraintModel(model, 2, pin.SE3.Identity(), 6, pin.SE3.Identity())
    with pytest.raises(InvalidInputError, match=r"type 'revolute' holds a PointAnchorConstraint"):
        Closure(point, "c", "revolute")
    with pytest.raises(InvalidInputError, match=r"type 'hinge'; expected one of \['3d', '6d', "):
        Closure(frame, "c", "hinge")
    assert (Closure(point, "c").kind, Closure(frame, "c").kind) == ("3d", "6d")
    urdf = tmp_path / "r.urdf"
    urdf.write_text(urdf_text(SHARED + DESCRIPTIONS["revolute closure"][0]))
    closures = tmp_path / "c.yaml"
    closures.write_text("closed_loop: [[cA, cB]]\ntype: ['hinge']\nname_mot: [crank]\n")
    with pytest.raises(ModelFileError, match=r"type 'hinge'; expected one of \['3d', '6d', 're"):
        load_model(urdf, closures, geometry=False)


# ------------------------------------------------------------- springs at a loop cut
@pytest.mark.parametrize(
    ("closure", "tree", "springs", "tree_springs"),
    [("revolute closure", "pin in the tree, rocker welded", [INF] * 5 + [7.0], {"pin_C": 7.0}),
     ("cylindrical closure", "cylindrical in the tree, rocker welded",
      [INF, INF, 900.0, INF, INF, 7.0], {"c1": 7.0, "c2": 900.0})],
)  # fmt: skip
def test_a_spring_at_a_cut_equals_the_sprung_joint_in_the_tree(
    tmp_path, closure, tree, springs, tree_springs
):
    """closure_springs: a torsion (and axial) spring at the cut C, against the same springs
    on the joints kept in the tree; at the drawing, where every spring is at rest (a
    sprung joint at C holds the crank where it is drawn)."""
    from closedloop.elastostatics.statics import frame_displacement

    clm = fourbar_as(tmp_path, closure, closure_springs={0: springs})
    cut = [n for n in clm.model.names if n.startswith("cA<->cB_")]
    assert cut == (["cA<->cB_rz"] if closure.startswith("rev") else ["cA<->cB_pz", "cA<->cB_rz"])
    assert [c.kind for c in clm.closures] == ["6d"]
    twin = fourbar_as(tmp_path, tree, springs=tree_springs)
    q, q_twin = pin.neutral(clm.model), pin.neutral(twin.model)
    C = cl.compliance(clm, q, "P").C
    assert_close_in_norm(C, cl.compliance(twin, q_twin, "P").C, RTOL_SAME,
                         scale=[1, 1, 1, 0.1, 0.1, 0.1])  # fmt: skip
    # the spring counts: without it the rotation at the cut is free
    free = cl.compliance(fourbar_as(tmp_path, closure), q[: clm.model.nq - len(cut)], "P").C
    assert abs(free[0, 0] - C[0, 0]) > 0.01 * C[0, 0]  # along x at P: 6% for the rotation
    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    moved = [frame_displacement(m, cl.solve_equilibrium(m, x, "P", wrench).q, x, "P")
             for m, x in ((clm, q), (twin, q_twin))]  # fmt: skip
    assert_close_in_norm(moved[0], moved[1], RTOL_SAME)


@pytest.mark.parametrize(
    ("kind", "springs", "error", "message"),
    [("revolute", "{1: [.inf, .inf, .inf, .inf, .inf, 5.0]}", "ModelFileError",
      r"closure_springs index 1; expected the 0-based index of a closed_loop pair, 0..0"),
     ("revolute", "[5.0]", "ModelFileError",
      r"closure_springs must be a mapping closed_loop pair index \(0..0\) -> 6 stiff"),
     ("revolute", "{0: [1.0, 2.0]}", "InvalidInputError",
      r"closure 'cA<->cB' of type 'revolute' given the spring \[1.0, 2.0\]; expected 6 "),
     ("revolute", "{0: [.inf, .inf, .inf, .inf, .inf, .inf]}", "InvalidInputError",
      r"\.inf on \['rz'\], which the type leaves free"),
     ("6d", "{0: [1.0, 1.0, 1.0, 1.0, 1.0, -1.0]}", "InvalidInputError",
      r"expected values >= 0"),
     ("6d", "{0: " + str([[1.0 if i == j else (0.5 if (i, j) == (0, 1) else 0.0)
                           for j in range(6)] for i in range(6)]) + "}",
      "InvalidInputError", r"not symmetric .*expected a symmetric positive semi-definite"),
     ("6d", "{0: " + str([[1.0 if i == j else (2.0 if {i, j} == {0, 1} else 0.0)
                           for j in range(6)] for i in range(6)]) + "}",
      "InvalidInputError", r"not positive semi-definite \(eigenvalues \[-1.0"),
     ("universal", "{0: [.inf, .inf, .inf, .inf, 0.0, 0.0]}", "InvalidInputError",
      r"type 'universal' given the spring .*\.inf on \['rx'\], which the type leaves free")],
)  # fmt: skip
def test_bad_closure_springs_are_refused_naming_file_closure_and_value(
    tmp_path, kind, springs, error, message
):
    import closedloop.exceptions as exceptions

    urdf = tmp_path / "r.urdf"
    urdf.write_text(urdf_text(SHARED + DESCRIPTIONS["revolute closure"][0]))
    closures = tmp_path / "c.yaml"
    closures.write_text(f"closed_loop: [[cA, cB]]\ntype: [{kind}]\nclosure_springs: {springs}\n")
    where = rf"^closure file '{closures}'"
    with pytest.raises(getattr(exceptions, error), match=where + ".*" + message):
        load_model(urdf, closures, geometry=False)


def test_bad_keyword_closure_springs_are_refused(tmp_path):
    from closedloop.exceptions import InvalidInputError

    urdf = tmp_path / "r.urdf"
    urdf.write_text(urdf_text(SHARED + DESCRIPTIONS["revolute closure"][0]))
    closures = tmp_path / "c.yaml"
    closures.write_text("closed_loop: [[cA, cB]]\ntype: [revolute]\n")
    with pytest.raises(InvalidInputError, match=r"closure_springs index 3; expected"):
        load_model(urdf, closures, geometry=False, closure_springs={3: [INF] * 6})
    with pytest.raises(InvalidInputError, match=r"given the spring \[1.0\]; expected 6 numbers"):
        load_model(urdf, closures, geometry=False, closure_springs={0: [1.0]})


# ------------------------------------------------------------------ elastic closures
SCALE = [1, 1, 1, 0.1, 0.1, 0.1]  # P's twist: rotations weighed by 0.1 m


def test_the_issue_pin_is_one_rotation_joint_at_the_cut_on_either_type(pins):
    for d in ("weld at C", "revolute closure"):
        clm = pins[d][0]
        assert [n for n in clm.model.names if n.startswith("cA<->cB")] == ["cA<->cB_rz"]
        assert clm.springs["cA<->cB_rz"] == 20.0 and [c.kind for c in clm.closures] == ["6d"]


@pytest.mark.parametrize("description", ["weld at C", "revolute closure"])
def test_the_issue_pin_has_the_compliance_of_the_sprung_pin_in_the_tree(pins, description):
    clm, Q = pins[description]
    tree, Q_tree = pins["tree"]
    for q, q_tree in zip(Q, Q_tree, strict=True):
        expected = cl.compliance(tree, q_tree, "P").C
        assert_close_in_norm(cl.compliance(clm, q, "P").C, expected, RTOL_SAME, scale=SCALE)
    batch, expected = cl.compliances(clm, Q, "P").C, cl.compliances(tree, Q_tree, "P").C
    for i in range(len(Q)):
        assert_close_in_norm(batch[i], expected[i], RTOL_SAME, scale=SCALE)
    # the spring counts: the unsprung revolute closure is softer
    free = cl.compliance(*fourbars_free(pins), "P").C
    assert abs(free[0, 0] - expected[0][0, 0]) > 0.01 * expected[0][0, 0]


def fourbars_free(pins):
    """The revolute closure without spring at the first configuration of ``pins``."""
    clm, Q = pins["revolute closure"]
    bare = ClosedLoopModel(clm.model, clm.closures, clm.actuated,
                           {**clm.springs, "cA<->cB_rz": 0.0}, clm.locked)  # fmt: skip
    return bare, Q[0]


@pytest.mark.parametrize("description", ["weld at C", "revolute closure"])
def test_the_issue_pin_has_the_equilibrium_of_the_sprung_pin_in_the_tree(pins, description):
    """Nonlinear statics under a small load (the spring energy on the chain's coordinate,
    exact for one rotation): the same displacement of P."""
    from closedloop.elastostatics.statics import frame_displacement

    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    moved = [frame_displacement(m, cl.solve_equilibrium(m, Q[0], "P", wrench).q, Q[0], "P")
             for m, Q in (pins[description], pins["tree"])]  # fmt: skip
    assert np.max(np.abs(moved[1][:3])) > 1e-5  # the load moves P
    assert_close_in_norm(moved[0], moved[1], RTOL_SAME)


def test_the_energy_shares_and_identification_name_the_closure_spring(pins):
    from closedloop.analysis.identification import identify
    from closedloop.analysis.measurements import Measurement
    from closedloop.elastostatics.unloaded import energy_shares

    clm, Q = pins["weld at C"]
    tree, Q_tree = pins["tree"]
    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    shares = energy_shares(clm, cl.compliance(clm, Q[0], "P"), wrench)
    expected = energy_shares(tree, cl.compliance(tree, Q_tree[0], "P"), wrench)
    assert shares["cA<->cB_rz"] > 0.01
    np.testing.assert_allclose(shares["cA<->cB_rz"], expected["pin_C"], rtol=RTOL_SAME)
    # deflections of the tree's pin at 20 N m/rad; fitted from 5 at the cut
    rng = np.random.default_rng(3)
    measurements = []
    for q, q_tree in zip(Q, Q_tree, strict=True):
        for w in rng.normal(size=(3, 6)):
            twist = cl.compliance(tree, q_tree, "P").C @ w
            measurements.append(Measurement.of(q=q, wrench=w, twist=twist, sd=np.full(6, 1e-6)))
    fitted = identify(clm, measurements, "P", ["cA<->cB_rz"], start={"cA<->cB_rz": 5.0})
    np.testing.assert_allclose(fitted.estimates["cA<->cB_rz"], 20.0, rtol=1e-6)


def _bushing(seed: int = 4) -> np.ndarray:
    """A 6x6 symmetric positive definite stiffness [N/m, N, N m/rad] in A's axes, coupled."""
    rng = np.random.default_rng(seed)
    d = np.sqrt([4e4, 6e4, 5e4, 40.0, 60.0, 30.0])
    B = rng.normal(size=(6, 6)) * 0.3
    return d[:, None] * (np.eye(6) + B @ B.T / 6) * d[None, :]


def test_a_6x6_bushing_equals_a_free_flyer_in_the_tree_with_that_block(tmp_path):
    K = _bushing()
    clm = fourbar_as(tmp_path, "weld at C", closure_springs={0: K.tolist()})
    assert "cA<->cB_bushing" in clm.spring_blocks
    tree = fourbar_as(tmp_path, "bushing in the tree, rocker welded",
                      springs_keyword={"bushing": K})  # fmt: skip
    q, q_tree = pin.neutral(clm.model), pin.neutral(tree.model)
    C = cl.compliance(clm, q, "P").C
    assert_close_in_norm(C, cl.compliance(tree, q_tree, "P").C, RTOL_SAME, scale=SCALE)
    batch = cl.compliances(clm, np.array([q, q]), "P").C
    assert_close_in_norm(batch[1], C, RTOL_SAME, scale=SCALE)
    wrench = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])
    from closedloop.elastostatics.statics import frame_displacement

    moved = [frame_displacement(m, cl.solve_equilibrium(m, x, "P", wrench).q, x, "P")
             for m, x in ((clm, q), (tree, q_tree))]  # fmt: skip
    assert_close_in_norm(moved[0], moved[1], RTOL_SAME)


def test_a_nearly_diagonal_bushing_is_the_chain_of_its_diagonal(tmp_path):
    """The bushing's axes against the chain's (checked against the pin above): a 6x6 with a
    coupling of 1e-9 of its diagonal, and its 6 diagonal values."""
    d = np.array([4e4, 6e4, 5e4, 40.0, 60.0, 30.0])
    K = np.diag(d) + 1e-9 * np.sqrt(np.outer(d, d)) * (1 - np.eye(6))
    bushing = fourbar_as(tmp_path, "weld at C", closure_springs={0: K.tolist()})
    chain = fourbar_as(tmp_path, "revolute closure", closure_springs={0: d.tolist()})
    assert [n for n in chain.model.names if n.startswith("cA<->cB")] == [
        f"cA<->cB_{s}" for s in ("px", "py", "rx", "ry", "pz", "rz")
    ]
    C = cl.compliance(bushing, pin.neutral(bushing.model), "P").C
    expected = cl.compliance(chain, pin.neutral(chain.model), "P").C
    assert_close_in_norm(C, expected, 1e-7, scale=SCALE)  # the coupling's 1e-9, times 6


def test_a_spring_on_a_free_and_a_constrained_direction_equals_slides_in_the_tree(tmp_path):
    """A prismatic closure (free along A's z) with a spring along z and a bushing along x."""
    clm = fourbar_as(tmp_path, "prismatic closure",
                     closure_springs={0: [3e4, INF, 500.0, INF, INF, INF]})  # fmt: skip
    assert [n for n in clm.model.names if n.startswith("cA<->cB")] == ["cA<->cB_px", "cA<->cB_pz"]
    tree = fourbar_as(tmp_path, "slides in the tree, rocker welded",
                      springs={"s_x": 3e4, "s_z": 500.0})  # fmt: skip
    q, q_tree = pin.neutral(clm.model), pin.neutral(tree.model)
    C = cl.compliance(clm, q, "P").C
    assert_close_in_norm(C, cl.compliance(tree, q_tree, "P").C, RTOL_SAME, scale=SCALE)
    free = fourbar_as(tmp_path, "prismatic closure")  # the slide along z unsprung, x rigid
    assert cl.compliance(free, pin.neutral(free.model), "P").C[1, 1] > 1.01 * C[1, 1]

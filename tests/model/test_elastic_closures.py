"""Elastic closures measure B's motion in A's axes at A's origin at any rest of the pair.

Each case is checked against a closed form written here: a body held to the ground by
nothing but one elastic closure (a passive free flyer in the tree) has, at a frame of
the body that coincides with A, the compliance K^-1 of the closure's spring, whatever
the pair's relative placement at rest (a revolute pair turned, a prismatic one slid, a
ball turned 90 degrees about y, where a chain of three rotations would lock); and a
two-link arm tied to the ground by an elastic ball has the compliance of its two joint
springs plus the ball's springs, by hand.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import closedloop as cl
from closedloop.elastostatics.compliance import energy_shares
from closedloop.exceptions import InvalidInputError, MechanismError
from closedloop.io.loader import load_model
from closedloop.kinematics.constraints import closure_residual

#: Both sides are solved to rounding: the compliance of a 6x6 spring of condition ~1e4
#: (N/m against N m/rad, the model's length 1 m), 1e4 * 1e-16, with a wide margin.
RTOL_EXACT = 1e-9

INF = float("inf")
#: A's placement in the world: a generic orientation and position.
A_WORLD = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.5, 0.8), np.array([0.2, -0.1, 0.4]))
#: A diagonal spring with every direction elastic [N/m, N m/rad].
DIAGONAL = np.array([2e4, 3e4, 5e4, 40.0, 70.0, 20.0])

#: B's placement relative to A at rest, per type: where the type holds, away from the
#: placement where A and B coincide in every direction the type leaves free.
AT_REST = {
    "6d": pin.SE3.Identity(),
    "revolute": pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.7), np.zeros(3)),
    "prismatic": pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])),
    "cylindrical": pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, -1.1), np.array([0.0, 0.0, 0.3])),
    "3d": pin.SE3(pin.rpy.rpyToMatrix(0.4, np.pi / 2, -0.3), np.zeros(3)),
    # B's z turned 0.6 rad about A's z from A's x, B turned -0.4 rad about it
    "universal": pin.SE3(
        pin.rpy.rpyToMatrix(0.0, 0.0, 0.6)
        @ pin.rpy.rpyToMatrix(-0.4, 0.0, 0.0)
        @ pin.rpy.rpyToMatrix(0.0, np.pi / 2, 0.0),
        np.zeros(3),
    ),
}
#: The frame of the spring's directions relative to A: A's own, but for the universal pair
#: its frame U (x along B's z, y along z_A x z_B, z along A's z).
SPRING_FRAME = {"universal": pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.6), np.zeros(3))}


def _origin(M: pin.SE3) -> str:
    xyz = " ".join(repr(float(x)) for x in M.translation)
    rpy = " ".join(repr(float(x)) for x in pin.rpy.matrixToRpy(M.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _held_body(tmp_path, kind: str, spring, second=None, pair2=("A2", "B2")) -> tuple:
    """A body on a passive free flyer, held to the ground by one elastic closure of type
    ``kind`` between A (on the ground) and B (the body's origin) at :data:`AT_REST`; the
    body's frame ``at_A`` coincides with A (U for a universal pair: :data:`SPRING_FRAME`)
    at rest; ``second``: the spring of a second closure of the same type between the same
    places (frames ``pair2``: A2 and B2, or A and body themselves).
    Returns (model, q at rest)."""
    B_world = A_WORLD * AT_REST[kind]
    inertial = ('<inertial><mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')  # fmt: skip
    urdf = f"""<robot name="held">
<link name="ground"/><link name="body">{inertial}</link><link name="A"/><link name="at_A"/>
<link name="A2"/><link name="B2"/>
<joint name="A2_joint" type="fixed"><parent link="ground"/><child link="A2"/>
{_origin(A_WORLD)}</joint>
<joint name="B2_joint" type="fixed"><parent link="body"/><child link="B2"/></joint>
<joint name="float" type="floating"><parent link="ground"/><child link="body"/>
{_origin(B_world)}</joint>
<joint name="A_joint" type="fixed"><parent link="ground"/><child link="A"/>
{_origin(A_WORLD)}</joint>
<joint name="at_A_joint" type="fixed"><parent link="body"/><child link="at_A"/>
{_origin(AT_REST[kind].inverse() * SPRING_FRAME.get(kind, pin.SE3.Identity()))}</joint>
</robot>"""
    (tmp_path / "held.urdf").write_text(urdf)
    listed = lambda x: x.tolist() if isinstance(x, np.ndarray) else x  # noqa: E731
    pairs, springs = [["A", "body"]], {0: listed(spring)}
    if second is not None:
        pairs, springs[1] = [*pairs, list(pair2)], listed(second)
    types = ", ".join([f"'{kind}'"] * len(pairs))
    (tmp_path / "held.yaml").write_text(f"closed_loop: {pairs}\ntype: [{types}]\nname_mot: []\n")
    clm = load_model(
        tmp_path / "held.urdf", tmp_path / "held.yaml", geometry=False, closure_springs=springs
    )
    return clm, clm.reference_configuration()


def _bushing() -> np.ndarray:
    """A coupled 6x6 symmetric positive definite stiffness [N/m, N, N m/rad]."""
    rng = np.random.default_rng(7)
    d = np.sqrt(DIAGONAL)
    B = rng.normal(size=(6, 6)) * 0.3
    return d[:, None] * (np.eye(6) + B @ B.T / 6) * d[None, :]


@pytest.mark.parametrize(
    ("kind", "form"),
    [(kind, "6 values") for kind in AT_REST]
    + [(kind, "6x6") for kind in AT_REST if kind != "universal"],
)
def test_the_spring_is_in_a_axes_at_a_origin_whatever_the_rest(tmp_path, kind, form):
    K = np.diag(DIAGONAL) if form == "6 values" else _bushing()
    clm, q = _held_body(tmp_path, kind, DIAGONAL if form == "6 values" else K)
    np.testing.assert_allclose(closure_residual(clm, q), 0.0, atol=1e-12)  # closed at rest
    C = cl.compliance(clm, q, "at_A", axes="local").C  # A's axes (U's)
    expected = np.linalg.inv(K)
    unit = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))  # entries per their units
    np.testing.assert_allclose(C / unit, expected / unit, rtol=0.0, atol=RTOL_EXACT)


def _singular(free: int, seed: int = 5) -> np.ndarray:
    """A coupled 6x6 positive semi-definite stiffness of rank 6 - ``free`` [N/m, N,
    N m/rad], its free directions general twists (screws, not along A's axes)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    d = np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])  # unit-balanced at 0.1 m
    lam = np.r_[[40.0, 70.0, 20.0, 55.0, 30.0, 60.0][: 6 - free], np.zeros(free)]
    return (Q * lam) @ Q.T / np.outer(d, d)


@pytest.mark.parametrize("kind", [k for k in AT_REST if k != "universal"])
@pytest.mark.parametrize("free", [1, 2])
def test_a_singular_bushing_in_parallel_with_a_diagonal_spring(tmp_path, kind, free):
    """A positive semi-definite 6x6 (free along 1 or 2 general twists) and a diagonal
    spring, two closures between the same places: the body has the compliance
    (K + diag)^-1 in A's axes at A's origin; the bushing alone leaves it a mechanism."""
    K = _singular(free)
    assert np.linalg.matrix_rank(K, tol=1e-9 * np.abs(K).max()) == 6 - free
    clm, q = _held_body(tmp_path, kind, K, second=DIAGONAL)
    assert len([n for n in clm.model.names if "_free" in n]) == free  # one screw each
    np.testing.assert_allclose(closure_residual(clm, q), 0.0, atol=1e-12)
    C = cl.compliance(clm, q, "at_A", axes="local").C
    expected = np.linalg.inv(K + np.diag(DIAGONAL))
    unit = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    np.testing.assert_allclose(C / unit, expected / unit, rtol=0.0, atol=RTOL_EXACT)
    alone, q = _held_body(tmp_path, kind, K)
    with pytest.raises(MechanismError):
        cl.compliance(alone, q, "at_A")


def test_a_bushing_too_soft_to_tell_from_free_is_refused(tmp_path):
    """1e11 in five directions against 20 along a general twist (2e-10 of the stiffest,
    unit-balanced) was read as free: the soft spring dropped without a word. It is refused,
    naming the share; the same matrix with 0 there is a free direction, and 20 against 1e7
    a spring that the compliance resolves."""
    Q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(6, 6)))
    for soft, stiff, outcome in ((20.0, 1e11, "refused"), (0.0, 1e11, "free"),
                                 (20.0, 1e7, "spring")):  # fmt: skip
        K = (Q * np.r_[[stiff] * 5, soft]) @ Q.T
        if outcome == "refused":
            with pytest.raises(InvalidInputError, match=r"cannot tell a spring from a free"):
                _held_body(tmp_path, "6d", K)
            continue
        clm, q = _held_body(tmp_path, "6d", K, second=np.full(6, 1e3))
        assert len([n for n in clm.model.names if "_free" in n]) == (outcome == "free")
        C = cl.compliance(clm, q, "at_A", axes="local").C
        expected = np.linalg.inv(K + 1e3 * np.eye(6))
        unit = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
        # both sides solved to rounding of a stiffness of condition up to 1e8 (1e11 / 1e3):
        # eps * cond, with a margin of 100
        tol = 100 * np.finfo(float).eps * np.linalg.cond(K + 1e3 * np.eye(6))
        np.testing.assert_allclose(C / unit, expected / unit, rtol=0.0, atol=tol)


def _parallel_check(clm, q, springs) -> None:
    """The body held by ``springs`` (each (6,) diagonal or (6, 6)) in parallel: compliance
    (sum K)^-1 at at_A in A's axes, and a load's work split between the closures as each
    spring's energy d^T K_i d / d^T (sum K) d, d the deflection (K_i in A's axes, at rest)."""
    Ks = [np.diag(K) if np.ndim(K) == 1 else np.asarray(K) for K in springs]
    result = cl.compliance(clm, q, "at_A", axes="local")
    expected = np.linalg.inv(sum(Ks))
    unit = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    np.testing.assert_allclose(result.C / unit, expected / unit, rtol=0.0, atol=RTOL_EXACT)
    w = np.array([2.0, -3.0, 4.0, 0.02, -0.03, 0.01])  # A's axes, at A
    d = expected @ w
    shares = energy_shares(clm, result, w)
    names = [c.name for c in clm.closures]
    assert len(set(names)) == len(names)  # one closure, one name
    by_closure = [sum(v for n, v in shares.items() if n.startswith(f"{c}_")) for c in names]
    np.testing.assert_allclose(
        by_closure, [d @ K @ d / (w @ d) for K in Ks], rtol=0.0, atol=RTOL_EXACT
    )


@pytest.mark.parametrize(("kind", "second"), [("6d", "bushing"), ("3d", "diagonal"),
                                              ("revolute", "diagonal")])  # fmt: skip
def test_two_elastic_closures_on_one_pair_act_in_parallel(tmp_path, kind, second):
    """Two entries of a closure file on the same frames A and body, each with a spring:
    two bushings in parallel, the compliance (K1 + K2)^-1 (the second's joints were named
    as the first's and left passive: the compliance was K1^-1, each share listed once)."""
    K2 = _bushing() if second == "bushing" else 2.0 * DIAGONAL
    clm, q = _held_body(tmp_path, kind, DIAGONAL, second=K2, pair2=("A", "body"))
    names = list(clm.model.names)
    assert len(set(names)) == len(names)
    _parallel_check(clm, q, [DIAGONAL, K2])


def test_closure_springs_given_to_two_closures_of_one_pair_act_in_parallel(tmp_path):
    """``with_closure_springs`` on a model with two rigid closures on the same frames, at
    once or one call a closure: (K1 + K2)^-1."""
    rigid, _ = _held_body(tmp_path, "6d", [INF] * 6, second=[INF] * 6, pair2=("A", "body"))
    K2 = _bushing()
    at_once = rigid.with_closure_springs({0: DIAGONAL, 1: K2})
    _parallel_check(at_once, at_once.reference_configuration(), [DIAGONAL, K2])
    one_by_one = rigid.with_closure_springs({0: DIAGONAL}).with_closure_springs({1: K2})
    _parallel_check(one_by_one, one_by_one.reference_configuration(), [DIAGONAL, K2])


def test_a_closure_made_elastic_twice_is_refused_naming_it(tmp_path):
    """A second ``with_closure_springs`` on a closure made elastic by the first (its cut
    closed by the joints of its spring) would add a second chain in series, not in
    parallel: refused, naming the closure (it built a chain of the same joint names,
    springless)."""
    clm, _ = _held_body(tmp_path, "6d", DIAGONAL)
    for spring in (DIAGONAL, _bushing()):
        with pytest.raises(InvalidInputError, match=r"closure 'A<->body' is elastic already"):
            clm.with_closure_springs({0: spring})


def test_a_cut_joint_named_as_a_joint_of_the_robot_is_refused(tmp_path):
    """Joint names stay unique: a robot joint named as a joint the cut would add."""
    clm, _ = _held_body(tmp_path, "6d", [INF] * 6)
    renamed = pin.Model(clm.model)
    renamed.names[1] = "A<->body_rz"  # the free flyer
    plain = cl.ClosedLoopModel(renamed, clm.closures)
    with pytest.raises(InvalidInputError, match=r"'A<->body_rz'.*already"):
        plain.with_closure_springs({0: DIAGONAL})


def test_a_ball_rotation_spring_is_one_ball_joint_and_a_free_one_none(tmp_path):
    clm, _ = _held_body(tmp_path, "3d", DIAGONAL)
    assert [n for n in clm.model.names if n.startswith("A<->body")] == [
        "A<->body_ball", "A<->body_px", "A<->body_py", "A<->body_pz"
    ]  # fmt: skip
    np.testing.assert_array_equal(clm.springs["A<->body_ball"], DIAGONAL[3:])


ARM = """<robot name="arm">
<link name="ground"/><link name="l1">{inertial}</link><link name="l2">{inertial}</link>
<link name="tip"/><link name="B"/>
<joint name="j1" type="revolute"><parent link="ground"/><child link="l1"/>
<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
<origin xyz="0.5 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
</joint>
<joint name="tip_joint" type="fixed"><parent link="l2"/><child link="tip"/>
<origin xyz="0.5 0 0"/></joint>
<joint name="B_joint" type="fixed"><parent link="ground"/><child link="B"/>
<origin xyz="1 0 0" rpy="{rpy}"/></joint>
</robot>"""


@pytest.mark.parametrize("rpy", ["0 0 0", "0 1.2 0", "0 1.5707963267948966 0", "0.3 -0.7 2.0"])
@pytest.mark.parametrize("rotations", [(0.0, 0.0, 0.0), (30.0, 70.0, 20.0)])
def test_an_arm_tied_by_an_elastic_ball_whatever_the_ground_frame(tmp_path, rpy, rotations):
    """Two revolute joints (z at the origin, 100 N m/rad; y at x = 0.5 m, 50 N m/rad)
    whose tip (x = 1 m, world axes at q = 0) is tied to the ground frame B by an elastic
    ball: translation springs in the tip's axes and rotations free or sprung. Closed form
    at q = 0: K = diag(100, 50) + Jp^T Kt Jp + Jw^T Kr Jw on (q1, q2), C = J K^-1 J^T,
    with Jp, Jw the tip's point and rotation Jacobians. B's orientation cannot matter."""
    inertial = ('<inertial><mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')  # fmt: skip
    (tmp_path / "arm.urdf").write_text(ARM.format(inertial=inertial, rpy=rpy))
    kt = np.array([1e4, 2e4, 3e4])
    (tmp_path / "arm.yaml").write_text(
        "closed_loop: [[tip, B]]\ntype: ['3d']\nname_mot: [j1]\n"
        "springs: {j1: 100.0, j2: 50.0}\n"
        f"closure_springs: {{0: {[*kt.tolist(), *rotations]}}}\n"
    )
    clm = load_model(tmp_path / "arm.urdf", tmp_path / "arm.yaml", geometry=False)
    q = cl.assemble(clm, [0.0], clm.reference_configuration()).q
    Jp = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, -0.5]])
    Jw = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    K = np.diag([100.0, 50.0]) + Jp.T @ np.diag(kt) @ Jp + Jw.T @ np.diag(rotations) @ Jw
    J = np.vstack([Jp, Jw])
    expected = J @ np.linalg.solve(K, J.T)
    C = cl.compliance(clm, q, "tip").C
    np.testing.assert_allclose(C, expected, rtol=RTOL_EXACT, atol=RTOL_EXACT * expected.max())


def test_rotations_partly_free_and_partly_sprung_are_refused(tmp_path):
    with pytest.raises(InvalidInputError, match=r"partly free \(0\) and partly sprung"):
        _held_body(tmp_path, "3d", [1e4, 1e4, 1e4, 0.0, 0.0, 20.0])


@pytest.mark.parametrize(
    ("spring", "match"),
    [(_bushing(), r"6x6 spring .*expected 6 values \(in the pair's frame U"),
     ([1e4, 1e4, 1e4, 5.0, 0.0, 5.0], r"0 \(free\) on ry, .*cross axis")],
)  # fmt: skip
def test_a_universal_pair_refuses_a_coupled_spring_and_a_free_cross_rotation(
    tmp_path, spring, match
):
    with pytest.raises(InvalidInputError, match=match):
        _held_body(tmp_path, "universal", spring)


@pytest.mark.parametrize(("kind", "spring"), [("3d", "diagonal"), ("revolute", "singular")])
def test_a_small_load_moves_the_body_by_the_compliance(tmp_path, kind, spring):
    """The nonlinear equilibrium under a small wrench at at_A (the ball's rotations, a
    singular bushing's screws solved with the rest) against the linear compliance: they
    differ at second order, the difference falls 10 times with the load."""
    from closedloop.elastostatics.equilibrium import frame_displacement

    if spring == "diagonal":
        clm, q = _held_body(tmp_path, kind, DIAGONAL)
    else:
        clm, q = _held_body(tmp_path, kind, _singular(2), second=DIAGONAL)
    C = cl.compliance(clm, q, "at_A").C
    gaps = []
    for scale in (0.01, 0.001):  # deflections ~1e-6 m, rotations ~1e-5 rad and less
        wrench = scale * np.array([2.0, -3.0, 4.0, 0.02, -0.03, 0.01])  # world axes, at_A
        eq = cl.solve_equilibrium(clm, q, "at_A", wrench)
        moved = frame_displacement(clm, eq.q, q, "at_A")
        gaps.append(np.abs(moved - C @ wrench).max() / np.abs(C @ wrench).max())
    assert gaps[0] < 2e-4 and gaps[1] < 0.15 * gaps[0]


@pytest.mark.parametrize("bad", [[1e4] * 3 + [True] + [1e4] * 2, ["0_3"] * 6, [1e4] * 5])
def test_a_spring_that_is_not_six_numbers_is_refused(tmp_path, bad):
    with pytest.raises(InvalidInputError, match=r"expected 6 numbers"):
        _held_body(tmp_path, "6d", bad)

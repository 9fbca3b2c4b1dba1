"""Assembly of the four-bar: closure reached, unreachable inputs, invalid inputs."""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

from closedloop.exceptions import AssemblyError, InvalidInputError
from closedloop.io.loader import load_urdf
from closedloop.kinematics.assembly import ASSEMBLY_TOL, assemble

# Link lengths of urdf/fourbar.urdf [m]: crank AB, coupler BC, rocker DC, ground AD.
L_CRANK, L_COUPLER, L_ROCKER, GROUND = 0.1, 0.3, 0.15, 0.3
CRANK_AXIAL = 1  # index of crank_axial in q


@functools.cache
def fourbar(closures="urdf/fourbar.yaml"):
    """The four-bar with a closure file given relative to the repository."""
    return load_urdf(REPO / "urdf/fourbar.urdf", REPO / closures)


def world_gap(clm, q):
    """Distance [m] between the two closure frames, from Pinocchio's forward kinematics."""
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    a, b = (
        data.oMf[clm.model.getFrameId(f)].translation for f in ("closedloop1_A", "closedloop1_B")
    )
    return np.linalg.norm(a - b)


def test_residual_after_assembly_at_random_crank_angles():
    # Grashof: crank + coupler = 0.4 <= ground + rocker = 0.45 and the crank is the shortest
    # link, so the crank turns fully and every crank angle assembles.
    clm = fourbar()
    rng = np.random.default_rng(11)
    for theta in rng.uniform(-np.pi, np.pi, 12):
        asm = assemble(clm, [theta])
        assert asm.residual <= ASSEMBLY_TOL
        # the point residual is a 3-vector: its 2-norm is at most sqrt(3) times the max norm
        assert world_gap(clm, asm.q) <= np.sqrt(3) * ASSEMBLY_TOL
        assert asm.q[0] == theta
        np.testing.assert_array_equal(asm.q[[1, 4]], 0.0)  # springs keep their rest values
        assert not asm.q.flags.writeable


def test_start_configuration_keeps_its_branch():
    clm = fourbar()
    first = assemble(clm, [0.4])
    again = assemble(clm, [0.45], q0=first.q)  # small input step from an assembled pose
    # continuity: the passive angles move by a small amount, not to the other branch
    assert np.max(np.abs(again.q - first.q)) < 0.2


def test_unreachable_crank_angle():
    # With crank_axial = 0.1 m at rest the crank is 0.2 m long. At theta = -pi/2 it points
    # along -x, B = (-0.2, 0): |BD| = 0.5 m > BC + DC = 0.45 m, so C cannot exist and no
    # configuration comes closer than 0.05 m; the residual is that gap in the coupler
    # frame, in the x-z plane, so its max norm is at least 0.05 / sqrt(2).
    q0 = np.zeros(5)
    q0[CRANK_AXIAL] = 0.1
    with pytest.raises(
        AssemblyError, match=r"'crank': -1\.57.*closure residual reached: \d\.\d{3}e-0\d"
    ) as err:
        assemble(fourbar(), [-np.pi / 2], q0=q0)
    assert err.value.residual >= 0.05 / np.sqrt(2)


def test_unreachable_weld():
    # Welding the coupler frame to the rocker frame at C asks phi (coupler) = psi (rocker).
    # At theta = 0, B = (0, 0.1): B + 0.3 (cos phi, -sin phi) = D + 0.15 (sin phi, cos phi)
    # is linear in (c, s) = (cos phi, sin phi): 0.3 c - 0.15 s = 0.3, 0.15 c + 0.3 s = 0.1,
    # so c = 0.105 / 0.1125, s = -0.015 / 0.1125 and c^2 + s^2 = 0.889 != 1: no solution.
    c, s = np.linalg.solve([[0.3, -0.15], [0.15, 0.3]], [0.3, 0.1])
    assert abs(c**2 + s**2 - 1) > 0.1
    with pytest.raises(AssemblyError, match=r"closure residual reached") as err:
        assemble(fourbar("tests/data/fourbar_weld.yaml"), [0.0])
    assert err.value.residual > 1e3 * ASSEMBLY_TOL


@pytest.mark.parametrize(
    ("actuated", "q0", "match"),
    [
        ([0.1, 0.2], None, r"2 actuated values given; expected 1 for joints \['crank'\]"),
        ([], None, r"0 actuated values given; expected 1"),
        ([np.nan], None, r"actuated values must be finite, got \[nan\]"),
        ([np.inf], None, r"actuated values must be finite, got \[inf\]"),
        ([0.1], np.zeros(4), r"q has 4 values; expected nq=5"),
        ([0.1], [0, np.nan, 0, 0, 0], r"q contains non-finite values"),
    ],
)
def test_invalid_inputs(actuated, q0, match):
    with pytest.raises(InvalidInputError, match=match):
        assemble(fourbar(), actuated, q0=q0)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"tol": 0.0}, r"tol must be a number finite and > 0 \[metres / L, rad\], got 0\.0"),
        ({"tol": -1e-12}, r"got -1e-12"),
        ({"tol": np.inf}, r"got inf"),
        ({"tol": np.nan}, r"got nan"),
        ({"tol": "1e-9"}, r"got '1e-9'"),
        ({"tol": True}, r"got True"),
        ({"max_iter": -1}, r"max_iter must be an integer >= 0, got -1"),
        ({"max_iter": 2.5}, r"got 2\.5"),
    ],
)
def test_invalid_tolerance_and_iteration_limit(options, match):
    with pytest.raises(InvalidInputError, match=match):
        assemble(fourbar(), [0.3], **options)


def test_numpy_scalars_are_valid_options():
    """The options take numpy scalars as the statics' do (one check for both)."""
    a = assemble(fourbar(), [0.3], tol=np.float32(1e-10), max_iter=np.int64(50))
    b = assemble(fourbar(), [0.3], tol=1e-10, max_iter=50)
    np.testing.assert_array_equal(a.q, b.q)


def test_closure_at_the_solution_is_that_of_a_fresh_evaluation():
    """Assembly.closure (jacobian=True) against the residuals and Jacobian evaluated anew
    from the returned q; absent unless asked for."""
    from closedloop.kinematics.constraints import closure_jacobian, closure_residual

    clm = fourbar()
    a = assemble(clm, [0.7], jacobian=True)
    assert a.iterations > 0
    r, Jc = a.closure
    np.testing.assert_array_equal(r, closure_residual(clm, a.q))
    np.testing.assert_array_equal(Jc, closure_jacobian(clm, a.q))
    assert not r.flags.writeable and not Jc.flags.writeable
    assert assemble(clm, [0.7]).closure is None
    again = assemble(clm, [0.7], q0=a.q, jacobian=True)  # no iteration: the start's own
    assert again.iterations == 0
    np.testing.assert_array_equal(again.closure[1], Jc)


def test_cahyman_inputs_are_checked_alike_in_every_form():
    # the float-array form has a shortcut in check_inputs: it must refuse and accept what the
    # general form does, and return copies
    from cahyman_pin.model import check_inputs
    from cahyman_pin.params import DEFAULT_PARAMS as P

    good = np.deg2rad([45.0, 60.0, 75.0])
    alpha, a4, s4 = check_inputs(good, 0.5, 0.01, P)
    assert alpha is not good and (alpha == good).all() and (a4, s4) == (0.5, 0.01)
    assert check_inputs(list(good), np.float64(0.5), 0.01, P)[2] == 0.01
    huge = np.full(3, 1e308)  # finite, beyond the joints' limits in every form
    for form in (huge, list(huge)):
        with pytest.raises(InvalidInputError, match=r"alpha = \(1e\+308, 1e\+308, 1e\+308\) rad"):
            check_inputs(form, 0.5, 0.01, P)
    for bad in (np.nan, np.inf, -np.inf):
        for k in range(3):
            wrong = good.copy()
            wrong[k] = bad
            for form in (wrong, list(wrong)):
                with pytest.raises(InvalidInputError, match="alpha"):
                    check_inputs(form, 0.5, 0.01, P)
        with pytest.raises(InvalidInputError, match="alpha_4"):
            check_inputs(good, bad, 0.01, P)
        with pytest.raises(InvalidInputError, match="s_4"):
            check_inputs(good, 0.5, bad, P)
    for s4 in (-1e-9, P.s4_max * (1 + 1e-12)):
        with pytest.raises(InvalidInputError, match="s_4"):
            check_inputs(good, 0.5, s4, P)
    with pytest.raises(InvalidInputError, match="alpha"):
        check_inputs(good[:2], 0.5, 0.01, P)


def test_cahyman_warm_start_puts_virtual_springs_back_to_rest():
    # a warm start with deflected virtual springs assembles to the closed-form start's q
    # (springs at rest); the caller's start is not modified; a non-finite start is refused
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.urdf_builder import VIRTUAL_JOINTS

    model = cahyman_model()
    pose = (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01)
    reference = model.assemble(*pose)
    virtual = [model.clm.model.joints[model.clm.joint_id(n)].idx_q for n in VIRTUAL_JOINTS]
    q0 = model.assemble(np.deg2rad([46.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01).copy()
    q0[virtual] = 0.01
    kept = q0.copy()
    q = model.assemble(*pose, q0=q0)
    np.testing.assert_array_equal(q0, kept)
    np.testing.assert_array_equal(q[virtual], 0.0)
    # the same configuration from another start of the same branch: rounding of the
    # Gauss-Newton iterates (closure tolerance 1e-12 m on links of 0.1 m)
    np.testing.assert_allclose(q, reference, rtol=0, atol=1e-9)
    q0[virtual[0]] = np.nan
    with pytest.raises(InvalidInputError, match="non-finite"):
        model.assemble(*pose, q0=q0)


@pytest.mark.parametrize(("m", "n"), [(5, 3), (3, 5), (4, 4)])
def test_min_norm_solve_is_lstsq_and_leaves_its_inputs(m, n):
    """dgelsy's minimum-norm solution against numpy's SVD lstsq (rounding of two
    backward-stable solvers on well-conditioned matrices); A and b are not modified."""
    from closedloop.common.lapack import min_norm_solve

    rng = np.random.default_rng(m * 10 + n)
    A, b = rng.normal(size=(m, n)), rng.normal(size=m)
    A0, b0 = A.copy(), b.copy()
    x = min_norm_solve(A, b)
    np.testing.assert_allclose(x, np.linalg.lstsq(A, b, rcond=None)[0], rtol=0, atol=1e-13)
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(b, b0)


def test_no_iteration_only_checks_the_start():
    """max_iter = 0: an assembled start is returned as it is, any other one refused."""
    clm = fourbar()
    a = assemble(clm, [0.7])
    again = assemble(clm, [0.7], q0=a.q, max_iter=0)
    assert again.iterations == 0 and again.residual <= ASSEMBLY_TOL
    np.testing.assert_array_equal(again.q, a.q)
    with pytest.raises(AssemblyError, match="closure residual reached"):
        assemble(clm, [0.8], q0=a.q, max_iter=0)


def test_threads_sharing_a_model_get_the_closures_of_their_own_assemblies():
    """The closure residuals and Jacobian an assembly hands over are values of its own
    q (each thread works on a Data of its own): threads give the serial ones bit for bit."""
    from concurrent.futures import ThreadPoolExecutor

    clm = fourbar()
    cranks = np.linspace(-3.0, 3.0, 24)
    serial = [assemble(clm, [c], jacobian=True) for c in cranks]
    with ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda c: assemble(clm, [c], jacobian=True), cranks))
    for a, b in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.closure[0], b.closure[0])
        np.testing.assert_array_equal(a.closure[1], b.closure[1])


@pytest.mark.parametrize("crank", [1.0, 1.2, 1.9, 2.6, -1.5])
def test_actuated_values_are_assembled_on_the_mode_of_the_start(crank, capsys):
    """assemble_connected drives the input from the start's value to the target: the
    four-bar from crank 0 ends where a fine continuation (steps of 0.01 rad, each solve
    from the last) ends. One solve from crank 0 lands on the other mode at crank 1.0, 1.2,
    1.9 and 2.6 (P 0.13-0.16 m lower), and the command line's --actuated took it; so did
    cl.assemble, which now drives from the model's start as the command line does."""
    import json

    from closedloop.cli.app import main
    from closedloop.kinematics.driving import assemble_connected, assemble_within_limits

    clm = fourbar()
    q = pin.neutral(clm.model)
    for value in np.linspace(0.0, crank, 1 + round(abs(crank) / 0.01)):
        q = assemble(clm, [value], q).q
    got = assemble_connected(clm, [crank], pin.neutral(clm.model)).q
    np.testing.assert_allclose(got, q, rtol=0, atol=1e-9)  # both closed to 1e-12 L
    assert main(["stiffness", "fourbar", "--frame", "P", "--actuated", repr(crank), "--json"]) == 1
    np.testing.assert_allclose(json.loads(capsys.readouterr().out)["q"], q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(assemble(clm, [crank]).q, q, rtol=0, atol=1e-9)
    if crank in (1.0, 1.2, 1.9, 2.6):  # what one solve gives: another mode
        direct = assemble_within_limits(clm, [crank], pin.neutral(clm.model)).q
        assert np.max(np.abs(pin.difference(clm.model, direct, q))) > 0.1


def test_a_loop_held_by_a_spring_names_the_held_joints():
    """A spring on a passive joint holds it at its start value: the loop cannot close at
    most inputs, and the message says which joints were held (it named only the inputs)."""
    clm = fourbar().with_springs({**fourbar().springs, "coupler": 1.0})
    held = r"\(the joints with springs or locked, \[.*'coupler'.*\], keep their start values"
    with pytest.raises(AssemblyError, match=r"with actuated \{'crank': 0\.3\} " + held):
        assemble(clm, [0.3])
    free = fourbar().with_springs({**fourbar().springs, "coupler": 0.0, "rocker": 1.0})
    with pytest.raises(AssemblyError, match=r"locked, \[[^]]*'rocker'[^]]*\]") as err:
        assemble(free, [0.3])
    assert "coupler" not in str(err.value)  # a spring of 0: free, it moved

"""The state object, the public face, threads, open loops and degenerate models."""

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

import closedloop as cl

CRANK_ANGLES = np.linspace(0.05, 1.2, 200)  # rad, reachable four-bar inputs
N_THREADS = 4


@pytest.fixture
def fourbar(fourbar_urdf, fourbar_yaml):
    return cl.load_model(fourbar_urdf, fourbar_yaml)


def test_public_face_exports_the_workflow():
    for name in cl.__all__:
        assert getattr(cl, name) is not None, name
    assert cl.compliance is cl.compliance  # the function, not the module of that name
    assert callable(cl.compliance) and callable(cl.solve_equilibrium)
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        _ = cl.nonsense


def test_configuration_owns_its_data_and_freezes_q(fourbar):
    q = cl.assemble(fourbar, actuated=[0.3]).q
    a, b = cl.Configuration(fourbar, q), cl.Configuration(fourbar, q)
    assert a.data is not b.data and a.data is not fourbar.data
    with pytest.raises(ValueError, match="read-only"):
        a.q[0] = 1.0
    assert a.is_closed and a.closure_error < 1e-12
    assert a.closure_jacobian() is a.closure_jacobian()  # computed once
    np.testing.assert_array_equal(
        a.frame_jacobian("P"), cl.kinematics.constraints.frame_jacobian(fourbar, q, "P")
    )
    # the state and (model, q) give the same result
    np.testing.assert_array_equal(cl.compliance(a, "P").C, cl.compliance(fourbar, q, "P").C)


def test_open_loop_is_refused(fourbar):
    # the four-bar at crank 0.3 with every passive joint at 0: the loop is 0.13 m open
    with pytest.raises(cl.OpenLoopError, match=r"does not close the loops of 'fourbar'.*1e-06"):
        cl.compliance(fourbar, [0.3, 0, 0, 0, 0], "P")
    state = cl.Configuration(fourbar, [0.3, 0, 0, 0, 0])
    assert not state.is_closed
    assert np.max(np.abs(state.residual)) > 0.1  # metres
    with pytest.raises(cl.InvalidInputError, match="belong to the Configuration"):
        cl.compliance(state, [0.3, 0, 0, 0, 0], "P")


def test_model_without_moving_joint_is_a_typed_error(tmp_path):
    # pin.getFrameJacobian crashes the interpreter on nv = 0: run in a child process so
    # that a crash fails this test instead of killing the session.
    urdf = tmp_path / "rigid.urdf"
    urdf.write_text(
        '<robot name="rigid"><link name="base"/><link name="tip"/>'
        '<joint name="weld" type="fixed"><parent link="base"/><child link="tip"/>'
        '<origin xyz="0 0 1"/></joint></robot>'
    )
    code = (
        "import closedloop as cl, numpy as np\n"
        f"m = cl.load_model({str(urdf)!r})\n"
        "try:\n"
        "    cl.compliance(m, np.zeros(0), 'tip')\n"
        "except cl.InvalidInputError as e:\n"
        "    print('typed:', e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "typed: model 'rigid' has no moving joint (nv = 0)" in out.stdout


def _fourbar_point(clm, angle):
    q = cl.assemble(clm, actuated=[angle]).q
    res = cl.compliance(clm, q, "P")
    return q, res.C


def test_threads_sharing_a_model_give_the_serial_results(fourbar):
    serial = [_fourbar_point(fourbar, a) for a in CRANK_ANGLES]
    with ThreadPoolExecutor(N_THREADS) as pool:
        threaded = list(pool.map(lambda a: _fourbar_point(fourbar, a), CRANK_ANGLES))
    for (q_s, C_s), (q_t, C_t) in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(q_t, q_s)
        np.testing.assert_array_equal(C_t, C_s)


def test_cahyman_api_from_threads_gives_the_serial_results():
    from cahyman_pin.api import stiffness

    rng = np.random.default_rng(7)
    poses = [(np.deg2rad(rng.uniform(40, 80, 3)), rng.uniform(0, 1), 0.01) for _ in range(24)]

    def run(p):
        r = stiffness(*p)
        return r.C, r.pose.M, r.pose.R, r.pose.H_k

    serial = [run(p) for p in poses]
    with ThreadPoolExecutor(N_THREADS) as pool:
        threaded = list(pool.map(run, poses))
    for a, b in zip(serial, threaded, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


def test_cahyman_pose_from_a_configuration_is_the_closed_form_pose():
    # the pose read from a configuration's own kinematics (what the generic backend does)
    # equals the pose computed afresh and the closed-form geometry's (no Pinocchio); the
    # assembly closes the loops to 1e-12 m, the pose agrees to that order
    from cahyman_pin.model import cahyman_model, closed_form_pose

    model = cahyman_model()
    inputs = (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01)
    q = model.assemble(*inputs)
    state = cl.Configuration(model.clm, q)
    got, fresh, exact = (
        model.pose_from(state.q, state.data),
        model.pose(q),
        closed_form_pose(*inputs),
    )
    for name in ("H", "R", "s", "H_k", "Q", "M", "R_M", "phi", "theta", "psi"):
        np.testing.assert_array_equal(getattr(got, name), getattr(fresh, name))
        np.testing.assert_allclose(getattr(got, name), getattr(exact, name), rtol=0, atol=1e-10)
    assert not got.M.flags.writeable and not got.H_k.flags.writeable


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_huge_and_tiny_springs_give_finite_results_or_typed_errors(fourbar, scale):
    springs = {name: value * scale for name, value in {"crank": 50.0, "crank_axial": 1e5}.items()}
    clm = fourbar.with_springs({**springs, "rocker_axial": 2e5 * scale})
    q = cl.assemble(clm, actuated=[0.3]).q
    try:
        res = cl.compliance(clm, q, "P")
    except cl.SingularConfigurationError as e:
        assert scale < 1 and "overflows" in str(e)
        return
    assert np.all(np.isfinite(res.C)) and np.all(np.isfinite(res.G))
    base = cl.compliance(fourbar, q, "P")
    assert_close_in_norm(res.C * scale, base.C, 1e-12)
    if scale < 1:  # compliance ~1e297: a 1e20 N load moves the frame past 1e308 m
        with pytest.raises(cl.InvalidInputError, match="overflows the floating point range"):
            res.deflection([1e20, 0, 0, 0, 0, 0])
        with pytest.raises(cl.InvalidInputError, match="overflows the floating point range"):
            res.joint_deflection([1e20, 0, 0, 0, 0, 0])


def test_json_is_always_valid(tmp_path, ur5_urdf):
    # a rank-deficient and an ill-conditioned UR5: JSON without NaN or Infinity tokens
    def strict(text):
        return json.loads(text, parse_constant=lambda c: pytest.fail(f"token {c}"))

    for elbow in ("0", "1e-5"):
        out = subprocess.run(
            [sys.executable, "-m", "closedloop", "stiffness", str(ur5_urdf), "--frame", "tool0",
             "--q", "0.3", "-1", elbow, "-0.5", "1.2", "0.3", "--joint-stiffness", "1e4", "--json"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        doc = strict(out.stdout)
        assert out.returncode == (1 if elbow == "0" else 0)
        assert doc["ill_conditioned"] is (elbow != "0")
        assert isinstance(doc["condition_number"], float)


def test_frame_jacobian_matches_pinocchio(fourbar):
    q = cl.assemble(fourbar, actuated=[0.4]).q
    state = cl.Configuration(fourbar, q)
    data = fourbar.model.createData()
    J = pin.computeFrameJacobian(
        fourbar.model, data, q, fourbar.model.getFrameId("P"), pin.LOCAL_WORLD_ALIGNED
    )
    np.testing.assert_array_equal(state.frame_jacobian("P"), J)


def test_functions_written_for_model_and_q_take_the_state(fourbar):
    from closedloop.viewer.scene import deflection_scene

    q = cl.assemble(fourbar, actuated=[0.3]).q
    state = cl.Configuration(fourbar, q)
    w = [5.0, -2.0, 0.0, 0.0, 0.0, 0.1]
    a, b = deflection_scene(state, "P", w), deflection_scene(fourbar, q, "P", w)
    np.testing.assert_array_equal(a.q_deflected, b.q_deflected)

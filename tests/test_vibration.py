"""Natural frequencies and mode shapes (closedloop.vibration) against analytic cases,
Pinocchio's mass matrix used directly, and a four-bar's eigenproblem built by hand."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from helpers import REPO, pendulum
from mechanisms import ur5_case

import closedloop as cl
from closedloop.model import ClosedLoopModel

#: Relative agreement of two double-precision eigensolvers on well-conditioned problems
#: (mass ranges below 1e3, stiffness ranges below 1e6): 1e-16 times their condition, with
#: margin.
RTOL = 1e-9
G = 9.80665


def hinge_pendulum(k: float, m: float, length: float, up: bool = False) -> ClosedLoopModel:
    """A point mass m [kg] at distance L below (or above) a hinge about y with a torsion
    spring k [N m/rad], on a locked support (nv = 2)."""
    model = pin.Model()
    support = model.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "support")
    j = model.addJoint(support, pin.JointModelRY(), pin.SE3.Identity(), "hinge")
    c = np.array([0.0, 0.0, length if up else -length])
    model.appendBodyToJoint(j, pin.Inertia(m, c, np.zeros((3, 3))), pin.SE3.Identity())
    model.addFrame(pin.Frame("bob", j, pin.SE3(np.eye(3), c), pin.OP_FRAME))
    return ClosedLoopModel(model, springs={"hinge": k}, locked=["support"], name="pendulum")


def slider_chain(k1: float, m1: float, k2: float, m2: float) -> ClosedLoopModel:
    """Two sliders along x in series: the first (spring k1 [N/m], 0: free) carries m1
    [kg], the second (spring k2, relative to the first) m2; frame 'end' on the second."""
    model = pin.Model()
    a = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "first")
    b = model.addJoint(a, pin.JointModelPX(), pin.SE3.Identity(), "second")
    for j, m in ((a, m1), (b, m2)):
        if m:
            model.appendBodyToJoint(j, pin.Inertia(m, np.zeros(3), np.zeros((3, 3))), pin.SE3())
    model.addFrame(pin.Frame("end", b, pin.SE3.Identity(), pin.OP_FRAME))
    return ClosedLoopModel(model, springs={"first": k1, "second": k2}, name="chain")


def hz(omega2) -> np.ndarray:
    return np.sqrt(np.asarray(omega2)) / (2.0 * math.pi)


# ------------------------------------------------------------------------------ analytic
def test_pendulum_on_a_torsion_spring():
    k, m, L = 40.0, 2.0, 0.5
    res = cl.modes(hinge_pendulum(k, m, L), np.zeros(2), frame="bob")
    np.testing.assert_allclose(res.frequencies, hz([k / (m * L**2)]), rtol=RTOL)
    # the bob moves along x by L per radian: its effective mass along x is m
    np.testing.assert_allclose(res.effective_masses[0], [m], rtol=RTOL)
    assert res.n_rigid == 0 and res.mobility == 1


@pytest.mark.parametrize("up", [False, True])
def test_pendulum_with_gravity_stiffness(up):
    """Hanging, the weight adds m g L to the spring; upright it takes it away."""
    k, m, L = 40.0, 2.0, 0.5
    res = cl.modes(hinge_pendulum(k, m, L, up), np.zeros(2), gravity=cl.STANDARD_GRAVITY)
    sign = -1.0 if up else 1.0
    np.testing.assert_allclose(res.frequencies, hz([(k + sign * m * G * L) / (m * L**2)]),
                               rtol=1e-8)  # fmt: skip


def test_upright_pendulum_beyond_its_spring_is_refused():
    """k < m g L upright: the weight overturns the spring (no vibration about it)."""
    with pytest.raises(cl.ModesError, match="unstable"):
        cl.modes(hinge_pendulum(5.0, 2.0, 0.5, up=True), np.zeros(2), gravity=cl.STANDARD_GRAVITY)


def test_two_mass_chain():
    k1, m1, k2, m2 = 3e3, 2.0, 1e3, 0.5
    res = cl.modes(slider_chain(k1, m1, k2, m2), np.zeros(2), frame="end")
    a, b = (k1 + k2) / m1 + k2 / m2, k1 * k2 / (m1 * m2)  # det(K - w^2 M) = 0
    root = math.sqrt(a * a - 4 * b)
    np.testing.assert_allclose(res.frequencies, hz([(a - root) / 2, (a + root) / 2]), rtol=RTOL)


def test_free_slider_gives_a_rigid_body_mode():
    """No spring on the first slider: a rigid-body mode at exactly 0, then the two masses
    against each other, w^2 = k2 (m1 + m2) / (m1 m2)."""
    k2, m1, m2 = 1e3, 2.0, 0.5
    res = cl.modes(slider_chain(0.0, m1, k2, m2), np.zeros(2))
    assert res.frequencies[0] == 0.0 and res.n_rigid == 1
    np.testing.assert_allclose(res.frequencies[1], hz(k2 * (m1 + m2) / (m1 * m2)), rtol=RTOL)
    np.testing.assert_allclose(res.lowest_elastic_frequency, res.frequencies[1])


def test_massless_body_between_two_springs_is_condensed():
    """A massless slider between springs k1 and k2 that carry m: one mode, w^2 = k1 k2 /
    ((k1 + k2) m), the two springs in series."""
    k1, k2, m = 2e3, 6e3, 1.5
    res = cl.modes(slider_chain(k1, 0.0, k2, m), np.zeros(2), frame="end")
    assert res.n_massless == 1 and res.n_modes == 1
    np.testing.assert_allclose(res.frequencies, hz([k1 * k2 / ((k1 + k2) * m)]), rtol=RTOL)
    # the massless slider follows statically: the end moves (k1 + k2) / k2 times the first
    first, second = res.shapes[:, 0]
    np.testing.assert_allclose(second / first, k1 / k2, rtol=RTOL)


# ------------------------------------------------------------------- serial and closed
def test_ur5_against_pinocchio_mass_matrix():
    clm, q, frame = ur5_case()
    M = pin.crba(clm.model, clm.model.createData(), q)
    M = np.triu(M) + np.triu(M, 1).T
    omega2 = np.sort(np.linalg.eigvals(np.linalg.solve(M, np.diag(np.full(6, 1e4)))).real)
    res = cl.modes(clm, q, frame=frame)
    np.testing.assert_allclose(res.frequencies, hz(omega2), rtol=RTOL)
    # mass-normalised shapes; their frame twists sum to the compliance (modal expansion)
    np.testing.assert_allclose(res.shapes.T @ M @ res.shapes, np.eye(6), atol=1e-10)
    C = cl.compliance(clm, q, frame).C
    np.testing.assert_allclose((res.twists / res.eigenvalues) @ res.twists.T, C,
                               atol=1e-9 * np.abs(C).max())  # fmt: skip
    three = cl.modes(clm, q, n=3)
    np.testing.assert_allclose(three.frequencies, res.frequencies[:3], rtol=1e-12)


def test_fourbar_against_hand_built_tangent_space():
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    q = cl.assemble(clm, actuated=[0.3]).q
    pm = clm.model
    data = pm.createData()
    M = pin.crba(pm, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    K = np.zeros((pm.nv, pm.nv))  # the springs of fourbar.yaml, by hand
    for name, k in {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}.items():
        i = pm.joints[pm.getJointId(name)].idx_v
        K[i, i] = k
    N = scipy.linalg.null_space(cl.Configuration(clm, q).closure_jacobian())
    omega2 = scipy.linalg.eigh(N.T @ K @ N, N.T @ M @ N, eigvals_only=True)
    res = cl.modes(clm, q, frame="P")
    np.testing.assert_allclose(res.frequencies, hz(omega2), rtol=RTOL)
    C = cl.compliance(clm, q, "P").C
    np.testing.assert_allclose((res.twists / res.eigenvalues) @ res.twists.T, C,
                               atol=1e-9 * np.abs(C).max())  # fmt: skip


def test_batch_matches_single_queries():
    clm, q, _ = ur5_case()
    Q = np.array([q, q + 0.1, q - 0.2])
    F = cl.batch_modes(clm, Q, n=4)
    assert F.shape == (3, 4)
    for f, qi in zip(F, Q, strict=True):
        np.testing.assert_array_equal(f, cl.modes(clm, qi, n=4).frequencies)


# ------------------------------------------------------------------------------ bad input
def test_massless_model_is_refused():
    with pytest.raises(cl.ModesError, match="no mass"):
        cl.modes(pendulum(), np.zeros(2))


def test_rigid_model_is_refused():
    clm = hinge_pendulum(40.0, 2.0, 0.5).with_springs({"hinge": math.inf}, ["support"])
    with pytest.raises(cl.ModesError, match="rigid model"):
        cl.modes(clm, np.zeros(2))


@pytest.mark.parametrize("n", [0, 3, 1.5, True])
def test_bad_number_of_modes(n):
    with pytest.raises(cl.InvalidInputError, match="n = "):
        cl.modes(slider_chain(1.0, 1.0, 1.0, 1.0), np.zeros(2), n=n)


def test_open_loop_is_refused():
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    with pytest.raises(cl.OpenLoopError):
        cl.modes(clm, pin.neutral(clm.model) + 0.3)

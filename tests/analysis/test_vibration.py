"""Natural frequencies and mode shapes (closedloop.analysis.vibration) against analytic cases,
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
from closedloop.model.closed_loop import ClosedLoopModel

#: Relative agreement of two double-precision eigensolvers on well-conditioned problems
#: (mass ranges below 1e3, stiffness ranges below 1e6): 1e-16 times their condition, with
#: margin.
RTOL = 1e-9
G = 9.80665
#: One mechanism's frequencies from two eigen-solves (coordinates in other orders, or a
#: degenerate pair): the smallest eigenvalues of the mass matrix are known to eps of its
#: largest, each frequency to about eps times the mass condition
#: (ModesResult.mass_condition; measured up to 0.25 of it on thin steel rods of mass
#: condition 2e4 to 1.5e6, OpenBLAS's Haswell, SandyBridge and Nehalem kernels).
MASS_ULPS = 4.0


def assert_same_frequencies(a, b) -> None:
    """The frequencies of two ModesResult of one mechanism agree to their rounding."""
    rtol = MASS_ULPS * np.finfo(float).eps * max(a.mass_condition, b.mass_condition)
    np.testing.assert_allclose(a.frequencies, b.frequencies, rtol=rtol)


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


def test_payload_adds_its_mass():
    k, m, L, extra = 40.0, 2.0, 0.5, 1.5
    payload = cl.Payload(extra, "bob")
    res = cl.modes(hinge_pendulum(k, m, L), np.zeros(2), payloads=[payload])
    np.testing.assert_allclose(res.frequencies, hz([k / ((m + extra) * L**2)]), rtol=RTOL)


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
    q = pin.neutral(clm.model)
    q[clm.model.joints[clm.model.getJointId("crank")].idx_q] += 0.3  # the crank alone turned
    with pytest.raises(cl.OpenLoopError):
        cl.modes(clm, q)


# ------------------------------------------------------------------------- beams' own mass
E_STEEL, G_STEEL, RHO_STEEL, D_ROD, L_ROD = 2.1e11, 8.1e10, 7850.0, 0.01, 0.5
#: Roots beta_n L of 1 + cos(x) cosh(x) = 0: the clamped-free beam's bending modes.
CANTILEVER_ROOTS = (1.87510407, 4.69409113, 7.85475744)


def rod(tmp_path, n: int, density=RHO_STEEL, **keys) -> ClosedLoopModel:
    """A steel rod (circle, D_ROD) of length L_ROD along x, clamped by a locked hinge
    about z at the origin, as n beam links of L_ROD / n in a row (fixed joints between),
    frame 'tip' at its end; the links have no inertia of their own."""
    h = L_ROD / n
    links = "".join(f'<link name="seg{i}"/>' for i in range(n))
    joints = [
        '<joint name="root" type="revolute"><parent link="base"/><child link="seg0"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
    ]
    joints += [
        f'<joint name="j{i}" type="fixed"><parent link="seg{i - 1}"/><child link="seg{i}"/>'
        f'<origin xyz="{h} 0 0"/></joint>'
        for i in range(1, n)
    ]
    joints.append(
        f'<joint name="j{n}" type="fixed"><parent link="seg{n - 1}"/><child link="tip"/>'
        f'<origin xyz="{h} 0 0"/></joint>'
    )
    path = tmp_path / f"rod{n}.urdf"
    path.write_text(f'<robot name="rod"><link name="base"/>{links}<link name="tip"/>'
                    f'{"".join(joints)}</robot>')  # fmt: skip
    section = {"shape": "circle", "d": D_ROD}
    spec = {"E": E_STEEL, "G": G_STEEL, "section": section, **keys}
    if density is not None:
        spec["density"] = density
    beams = {f"seg{i}": {"end": f"j{i + 1}", **spec} for i in range(n)}
    return cl.load_model(path, springs={"root": math.inf}, beams=beams)


def at_rest(clm: ClosedLoopModel) -> tuple[ClosedLoopModel, np.ndarray]:
    """(model, its neutral configuration): the beams undeflected."""
    return clm, pin.neutral(clm.model)


def cantilever_hz(mode: int) -> float:
    """The Euler-Bernoulli cantilever's bending frequency [Hz] (closed form)."""
    area, inertia = math.pi * D_ROD**2 / 4, math.pi * D_ROD**4 / 64
    beta = CANTILEVER_ROOTS[mode]
    return beta**2 * math.sqrt(E_STEEL * inertia / (RHO_STEEL * area * L_ROD**4)) / (2 * math.pi)


def test_one_element_cantilever_within_half_a_percent(tmp_path):
    """The consistent mass: 3.533 / 3.516 - 1 = 0.48 % high with one element (a lumped
    half at the tip would be 30 % off). The round section bends alike in both planes."""
    res = cl.modes(*at_rest(rod(tmp_path, 1)))
    f = res.frequencies
    np.testing.assert_allclose(
        f[1], f[0], rtol=MASS_ULPS * np.finfo(float).eps * res.mass_condition
    )
    error = f[0] / cantilever_hz(0) - 1.0
    assert 0.0047 < error < 0.0048, error


def test_cantilever_converges_as_h4(tmp_path):
    """Split into n elements (``elements: n``), the first bending frequency approaches the
    closed form from above at the cubic element's rate h^4 (ratio of errors 2^4 = 16 per
    halving, once in the asymptotic range). At n = 8 the next two bending frequencies err
    as the first one at their shorter wavelength, (beta_m / beta_1)^4 times its error
    (within 20 %)."""
    errors = []
    for n in (2, 4, 8):
        clm = rod(tmp_path, 1, elements=n)
        f = cl.modes(clm, pin.neutral(clm.model), n=6).frequencies  # three bending pairs
        errors.append(f[0] / cantilever_hz(0) - 1.0)
    rates = np.log2(np.array(errors[:-1]) / errors[1:])
    np.testing.assert_allclose(rates, 4.0, atol=0.15)
    error = f[::2] / [cantilever_hz(m) for m in range(3)] - 1.0
    bound = errors[-1] * (np.array(CANTILEVER_ROOTS) / CANTILEVER_ROOTS[0]) ** 4
    assert np.all(error > 0.0) and np.all(error < 1.2 * bound), (error, bound)


@pytest.mark.parametrize("n", [2, 4])
def test_elements_key_is_the_chain_of_beam_links(tmp_path, n):
    """``elements: n`` on one link: the same n-element model as n beam links in a row
    (frequencies to rounding, eigenvalues of other coordinate orders), and the same tip
    compliance as one element (exact for end loads: Euler-Bernoulli's cubics)."""
    split, chain, one = rod(tmp_path, 1, elements=n), rod(tmp_path, n), rod(tmp_path, 1)
    assert split.model.nv == chain.model.nv == 1 + 6 * n
    assert_same_frequencies(cl.modes(*at_rest(split)), cl.modes(*at_rest(chain)))
    C = cl.compliance(*at_rest(one), "tip").C
    np.testing.assert_allclose(cl.compliance(*at_rest(split), "tip").C, C, rtol=1e-9,
                               atol=1e-12 * np.abs(C).max())  # fmt: skip


@pytest.mark.parametrize("elements", [0, 1.5, True, "2", 65])
def test_bad_elements(tmp_path, elements):
    with pytest.raises(cl.BeamError, match="elements"):
        rod(tmp_path, 1, elements=elements)


@pytest.mark.parametrize("n", [1, 3])
def test_beam_mass_holds_the_rigid_rod(tmp_path, n):
    """Turning the whole rod about the root hinge: the inertia of a slender rod about its
    end, rho A L^3 / 3, exactly (the cubics hold rigid motions)."""
    from closedloop.analysis.vibration import mass_matrix

    clm = rod(tmp_path, n)
    M = mass_matrix(cl.Configuration(clm, pin.neutral(clm.model)))
    root = clm.joint_v_slice("root").start
    area = math.pi * D_ROD**2 / 4
    np.testing.assert_allclose(M[root, root], RHO_STEEL * area * L_ROD**3 / 3, rtol=1e-12)


def test_model_wide_density(tmp_path):
    with_key = cl.modes(*at_rest(rod(tmp_path, 2))).frequencies
    by_default = cl.modes(*at_rest(rod(tmp_path, 2, None)), density=RHO_STEEL).frequencies
    np.testing.assert_array_equal(by_default, with_key)
    with pytest.raises(cl.ModesError, match="no mass"):  # no density, no inertia
        cl.modes(*at_rest(rod(tmp_path, 2, None)))


@pytest.mark.parametrize("density", [0.0, -7850.0, math.inf, "steel"])
def test_bad_density(tmp_path, density):
    with pytest.raises(cl.BeamError, match="density"):
        rod(tmp_path, 1, density)
    with pytest.raises(cl.InvalidInputError, match="density"):
        cl.modes(*at_rest(rod(tmp_path, 1, None)), density=density)


def test_density_without_a_section_is_refused(tmp_path):
    rod(tmp_path, 1)  # writes rod1.urdf
    beam = {"end": "j1", "stiffness_6x6": np.eye(6).tolist(), "density": 1.0}
    with pytest.raises(cl.BeamError, match="density needs a section"):
        cl.load_model(tmp_path / "rod1.urdf", beams={"seg0": beam})
    beam = {"end": "j1", "stiffness_6x6": np.eye(6).tolist(), "elements": 2}
    with pytest.raises(cl.BeamError, match="elements needs E, G and a section"):
        cl.load_model(tmp_path / "rod1.urdf", beams={"seg0": beam})
    with pytest.raises(cl.InvalidInputError, match="no beam with a section"):
        cl.modes(hinge_pendulum(40.0, 2.0, 0.5), np.zeros(2), density=RHO_STEEL)


# ------------------------------------------------------------------------------------ maps
def test_map_index_is_the_lowest_frequency_at_each_point():
    from closedloop.analysis.maps import stiffness_map

    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    cranks = [0.2, 0.3, 0.5]
    smap = stiffness_map(clm, "P", sweeps={"crank": cranks}, modes=True)
    expected = [cl.modes(clm, cl.assemble(clm, actuated=[c]).q).frequencies[0] for c in cranks]
    # the map assembles each point from the last one, Gauss-Newton converging
    # quadratically: the same pose to rounding (1e-14 measured)
    np.testing.assert_allclose(smap.indices["lowest_frequency"], expected, rtol=1e-9)
    assert "lowest_frequency" not in stiffness_map(clm, "P", sweeps={"crank": cranks}).indices


def test_map_of_frequencies_refuses_a_massless_model():
    from closedloop.analysis.maps import stiffness_map

    with pytest.raises(cl.ModesError, match="no mass"):
        stiffness_map(pendulum(), "tip", sweeps={"hinge": [0.0, 0.1]}, modes=True)


@pytest.mark.parametrize("n", [2, 3])
def test_beams_chained_on_one_link_are_the_chain_of_beam_links(tmp_path, n):
    """n beams chained on one link (``start:`` each the previous beam's end, a frame of
    the link at k L / n) carry their own mass as the n beam links in a row do: the same
    frequencies (to rounding, other coordinate orders) and the same tip compliance."""
    h = L_ROD / n
    points = "".join(
        f'<link name="p{k}"/><joint name="j{k}" type="fixed"><parent link="seg0"/>'
        f'<child link="p{k}"/><origin xyz="{k * h} 0 0"/></joint>'
        for k in range(1, n + 1)
    )
    path = tmp_path / f"one_link{n}.urdf"
    path.write_text(
        '<robot name="rod"><link name="base"/><link name="seg0"/>'
        '<joint name="root" type="revolute"><parent link="base"/><child link="seg0"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        f"{points}</robot>"
    )
    spec = {"E": E_STEEL, "G": G_STEEL, "section": {"shape": "circle", "d": D_ROD},
            "density": RHO_STEEL}  # fmt: skip
    beams = [{"end": "j1", **spec}]
    beams += [{"start": f"j{k - 1}", "end": f"j{k}", **spec} for k in range(2, n + 1)]
    one = cl.load_model(path, springs={"root": math.inf}, beams={"seg0": beams})
    links = rod(tmp_path, n)
    assert one.model.nv == links.model.nv == 1 + 6 * n
    assert_same_frequencies(cl.modes(*at_rest(one)), cl.modes(*at_rest(links)))
    C = cl.compliance(*at_rest(links), "tip").C
    np.testing.assert_allclose(cl.compliance(*at_rest(one), f"p{n}").C, C, rtol=1e-9,
                               atol=1e-12 * np.abs(C).max())  # fmt: skip

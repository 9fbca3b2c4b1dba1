"""The springs' elastic energy (closedloop.model.elastic) against independent references.

References: the slope integral of the cubic that matches a beam tip's displacement and
slope, by Gauss quadrature; central differences of the energy and of the forces along
``pin.integrate``; the linear spring law where no beam is deflected.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from helpers import UR5_BEAM_ENDS
from helpers import tangent_differences as differences
from test_beams import STEEL, cantilever

from closedloop.elastostatics.tangent import spring_hessian
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.model.beams import map_configuration
from closedloop.model.elastic import (
    beam_joints,
    deflection,
    deflection_jacobian,
    shortening_form,
    spring_law,
)

# Quadrature of a polynomial of degree 4 with 5 Gauss points: exact to rounding.
RTOL_QUADRATURE = 1e-12
# Central differences with step H: truncation ~H^2 times the third derivative (relative
# ~1e-8 on these deflections), rounding ~1e-16 |U| / H.
H = 1e-5
RTOL_DIFFERENCES = 1e-6

TUBE = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}


def _slope_integral(t, r, a, L):
    """1/2 the integral over the beam of |w'|^2, w the transverse cubic with w(0) = w'(0)
    = 0, w(L) = t across a, w'(L) = r x a (5-point Gauss-Legendre)."""
    P = np.eye(3) - np.outer(a, a)
    v, slope = P @ t, np.cross(r, a)
    # w(x) = c2 x^2 + c3 x^3 from the end conditions
    c3 = (slope * L - 2.0 * v) / L**3
    c2 = (v - c3 * L**3) / L**2
    x, wts = np.polynomial.legendre.leggauss(5)
    x, wts = 0.5 * L * (x + 1.0), 0.5 * L * wts
    d = 2.0 * c2[None, :] * x[:, None] + 3.0 * c3[None, :] * x[:, None] ** 2
    return 0.5 * float(wts @ np.sum(d * d, axis=1))


def test_the_shortening_form_is_the_slope_integral_of_the_cubic():
    rng = np.random.default_rng(3)
    for _ in range(5):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        L = rng.uniform(0.1, 2.0)
        t, r = rng.normal(size=3) * 1e-3, rng.normal(size=3) * 1e-2
        x = np.r_[t, r]
        expected = _slope_integral(t, r, a, L)
        np.testing.assert_allclose(0.5 * x @ shortening_form(a, L) @ x, expected,
                                   rtol=RTOL_QUADRATURE)  # fmt: skip


def _flexible_ur5():
    ur5 = load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf",
                    joint_stiffness=1e4, geometry=False)  # fmt: skip
    flex = ur5.with_beams({link: {**TUBE, "end": end} for link, end in UR5_BEAM_ENDS.items()})
    q_rest = map_configuration(ur5.model, flex.model, [0.3, -1.0, 1.5, -0.5, 1.2, 0.3])
    # every beam deflected (a few mm, a few 0.01 rad), the arm moved too
    rng = np.random.default_rng(7)
    v = rng.normal(size=flex.model.nv)
    v *= np.where(flex.linear_coordinates, 3e-3, 3e-2)
    return flex, q_rest, pin.integrate(flex.model, q_rest, v)


def _energy(clm, q_rest, q):
    return spring_law(clm, deflection(clm, q_rest, q))[1]


def _forces(clm, q_rest, q):
    """(nv,) generalised spring forces J_e^T f_e."""
    return deflection_jacobian(clm, q_rest, q).T @ spring_law(clm, deflection(clm, q_rest, q))[0]


def test_the_spring_forces_are_the_gradient_of_the_energy():
    clm, q_rest, q = _flexible_ur5()
    assert len(beam_joints(clm)) == 6
    expected = differences(clm.model, lambda x: np.atleast_1d(_energy(clm, q_rest, x)), q, H)[0]
    got = _forces(clm, q_rest, q)
    np.testing.assert_allclose(got, expected, rtol=RTOL_DIFFERENCES,
                               atol=RTOL_DIFFERENCES * np.abs(expected).max())  # fmt: skip


def test_the_spring_stiffness_is_the_derivative_of_the_forces():
    clm, q_rest, q = _flexible_ur5()
    expected = differences(clm.model, lambda x: _forces(clm, q_rest, x), q, H)
    got = spring_hessian(clm, q, q_rest)
    np.testing.assert_allclose(got, expected, rtol=RTOL_DIFFERENCES,
                               atol=RTOL_DIFFERENCES * np.abs(expected).max())  # fmt: skip


def test_a_bent_beam_shortens_and_its_axial_force_bends_it(tmp_path):
    """A tip displaced across the beam only (no axial coordinate) stretches the beam by
    the shortening s: energy 1/2 e^T K_b e + an axial force N = k_a s along a; and the
    law is the linear one K_b dq to first order."""
    clm, q0 = cantilever(tmp_path, {"shape": "circle", "d": 0.01}, length=0.5)
    (b,) = beam_joints(clm)
    a = b.axis[:3]  # the beam's axis in the tip's rest axes
    np.testing.assert_allclose(np.linalg.norm(a), 1.0, rtol=1e-15)
    across = np.cross(a, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    dq = np.zeros(6)
    dq[:3] = 1e-3 * across
    e = np.r_[dq[:3], 0.0, 0.0, 0.0]
    q = pin.integrate(clm.model, q0, dq)
    np.testing.assert_allclose(deflection(clm, q0, q), e, rtol=1e-12, atol=1e-18)
    s = 0.5 * e @ b.shortening @ e
    np.testing.assert_allclose(s, 0.6 * 1e-3**2 / 0.5, rtol=1e-12)  # 36 |t|^2 / (60 L)
    stretched = e + s * b.axis
    f, energy = spring_law(clm, e)
    np.testing.assert_allclose(energy, 0.5 * stretched @ b.stiffness @ stretched, rtol=1e-12)
    EA_per_L = STEEL["E"] * math.pi * 0.01**2 / 4 / 0.5
    np.testing.assert_allclose(a @ f[:3], EA_per_L * s, rtol=1e-9)  # the axial force
    # small deflection: the linear law, up to the axial force of the shortening, relative
    # (k_a / k_bending) |x| / L ~ 1e4 |x| / L on this slender rod: 3e-9 at |x| = 1e-13
    tiny = 1e-13 * np.r_[across, across]
    np.testing.assert_allclose(spring_law(clm, tiny)[0], b.stiffness @ tiny, rtol=1e-7)

"""The springs' elastic energy as a function of q: deflections, forces and stiffness.

A spring acts on the deflection dq = ``pin.difference(model, q_rest, q)`` of its joint
(log6 of the relative placement for a free flyer) with the energy 1/2 dq^T K_q dq, except
the 6-dof virtual joint of a beam (:mod:`closedloop.model.beams`). Its deflection is the one of
beam theory, in the beam's clamped (rest) axes at the tip: the tip's displacement t [m]
(the translation of the relative placement M_rest^-1 M, not log6's, which differs from it
at second order) and its rotation vector r = log3(R) [rad], with the shortening s of the
bent beam added to the axial elongation (Euler-Bernoulli, von Karman)::

    e = (t + s a, r),   energy 1/2 e^T K_b e,
    s = 1/2 (t, r)^T H_s (t, r) = (36 |t_p|^2 + 6 L t . (a x r) + 4 L^2 |r_p|^2) / (60 L),

with a the beam's axis (unit, rest axes), L its length, t_p and r_p the parts across the
beam: s is 1/2 the integral of the squared slope of the cubic that matches the tip's
displacement and slope r x a (the one-element beam of the direct stiffness method). So
the beam's axial force N = a6^T K_b e (a6 = (a, 0)) couples with its bending: the beam
stiffness on (t, r) is T^T K_b T + N H_s, T = I + a6 (H_s (t, r))^T, and N H_s is the
geometric (P-delta) stiffness of the beam element: compression (N < 0) softens the
bending, tension stiffens it. At zero deflection e = dq = 0 to first order and the
stiffness is K_b: the unloaded compliance does not depend on this.

Forces and stiffness are those of the generalised coordinates (the tangent of q): with
J_e = de/dq (``pin.dDifference`` for the ordinary joints; diag(R, Jlog3(R)) for a beam),
the generalised spring force is J_e^T f_e and its derivative J_e^T K_e J_e plus the
curvature of e weighted by f_e (:func:`closedloop.elastostatics.tangent.spring_hessian`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from closedloop.model.beam_joints import inserted_beams
from closedloop.model.closed_loop import ClosedLoopModel


class BeamJoint(NamedTuple):
    """The virtual joint of one beam: its velocity and configuration indices, axis and
    shortening form."""

    v: slice  # the joint's 6 tangent coordinates
    q: slice  # its 7 configuration values (translation, quaternion)
    axis: np.ndarray  # (6,) a6 = (a, 0): the beam's axis in the rest axes of the tip
    shortening: np.ndarray  # (6, 6) H_s [1/m, 1, m]: s = 1/2 (t, r)^T H_s (t, r)
    stiffness: np.ndarray  # (6, 6) K_b, the spring of the joint [N/m, N/rad, N m/rad]


def shortening_form(axis: np.ndarray, length: float) -> np.ndarray:
    """(6, 6) H_s of a beam of unit ``axis`` (3,) and ``length`` L [m] (module docstring)."""
    a = np.asarray(axis, dtype=float)
    across = np.eye(3) - np.outer(a, a)
    skew = pin.skew(a)  # skew @ r = a x r
    L = float(length)
    return np.block([[36.0 * across, 3.0 * L * skew], [3.0 * L * skew.T, 4.0 * L**2 * across]]) / (
        30.0 * L
    )


def beam_joints(clm: ClosedLoopModel) -> tuple[BeamJoint, ...]:
    """The beams' virtual joints of ``clm`` (:func:`closedloop.model.beam_joints.inserted_beams`)
    that carry a spring (computed once per model)."""
    return clm.memo("beam_joints", lambda: _beam_joints(clm))


def _beam_joints(clm: ClosedLoopModel) -> tuple[BeamJoint, ...]:
    model = clm.model
    if not any("_beam" in f.name for f in model.frames):
        return ()
    out = []
    for beam in inserted_beams(model):
        jm = model.joints[beam.joint]
        v = slice(jm.idx_v, jm.idx_v + jm.nv)
        K = clm.spring_matrix[v, v]
        tip = beam.rest.translation
        length = float(np.linalg.norm(tip))
        if not np.any(K) or length == 0.0:
            continue
        a = beam.rest.rotation.T @ tip / length
        axis = np.r_[a, 0.0, 0.0, 0.0]
        q = slice(jm.idx_q, jm.idx_q + jm.nq)
        out.append(BeamJoint(v, q, axis, shortening_form(a, length), np.array(K)))
    return tuple(out)


def _relative(q_rest: np.ndarray, q: np.ndarray, b: BeamJoint) -> pin.SE3:
    """The placement of the tip relative to its rest, M_rest^-1 M."""
    return pin.XYZQUATToSE3(q_rest[b.q]).actInv(pin.XYZQUATToSE3(q[b.q]))


def deflection(clm: ClosedLoopModel, q_rest: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(nv,) the springs' deflection coordinates at q: dq = difference(q_rest, q) [rad, m],
    and (t, r) for each beam (module docstring; the shortening is added by the law)."""
    e = pin.difference(clm.model, q_rest, q)
    for b in beam_joints(clm):
        M = _relative(q_rest, q, b)
        e[b.v] = np.r_[M.translation, pin.log3(M.rotation)]
    return e


def deflection_jacobian(clm: ClosedLoopModel, q_rest: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(nv, nv) J_e = d :func:`deflection` / dq (tangent of q)."""
    J = pin.dDifference(clm.model, q_rest, q, pin.ARG1)
    for b in beam_joints(clm):
        R = _relative(q_rest, q, b).rotation
        J[b.v, b.v] = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), pin.Jlog3(R)]])
    return J


def spring_law(clm: ClosedLoopModel, e: np.ndarray) -> tuple[np.ndarray, float]:
    """The springs' forces f_e (nv,) = dU/de [N, N m] at the deflection e (nv,) of
    :func:`deflection`, and their energy U [J] (0 on passive and locked coordinates)."""
    f = clm.spring_forces(e)
    energy = 0.5 * float(e @ f)
    for b in beam_joints(clm):
        x = e[b.v]
        grad, stretched, elastic = _stretched(b, x)
        f[b.v] = elastic + float(b.axis @ elastic) * grad
        energy += 0.5 * float(stretched @ elastic) - 0.5 * float(x @ (b.stiffness @ x))
    return f, energy


def spring_stiffness(clm: ClosedLoopModel, e: np.ndarray) -> np.ndarray:
    """(nv, nv) K_e = d f_e / de of :func:`spring_law` [N/m, N m/rad]: the spring matrix,
    and on each beam T^T K_b T + N H_s (module docstring)."""
    K = np.array(clm.spring_matrix)
    for b in beam_joints(clm):
        grad, _, elastic = _stretched(b, e[b.v])
        T = np.eye(6) + np.outer(b.axis, grad)
        K[b.v, b.v] = T.T @ b.stiffness @ T + float(b.axis @ elastic) * b.shortening
    return K


def _stretched(b: BeamJoint, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At a beam's (t, r) x (6,): the gradient H_s x of its shortening, its deflection
    e = x + s a6 with the shortening in the elongation, and the spring's force K_b e."""
    grad = b.shortening @ x
    stretched = x + 0.5 * float(x @ grad) * b.axis
    return grad, stretched, b.stiffness @ stretched

"""Peer test mechanisms built programmatically, with hand-derived (pure numpy) references.

Every builder returns a :class:`Mechanism`: the model, an exactly assembled configuration
q (closed-form inverse kinematics), the loaded frame, the world positions the frames must
have at q and the geometry of the analytic reference, computed by hand (trigonometry,
scipy rotations), never by Pinocchio, so that no reference shares code with the engine.

Units: lengths [m], angles [rad], prismatic springs [N/m], revolute springs [N m/rad].
Twists (dx, dy, dz [m], rx, ry, rz [rad]) and wrenches (fx, fy, fz [N], nx, ny, nz [N m])
are at the loaded frame origin, world axes, the order of ``closedloop.compliance``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from helpers import REPO
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import closure_between_frames

EZ = np.array([0.0, 0.0, 1.0])
#: Inertia of every body (0.1 kg, 1e-4 kg m^2): only needs to be nonzero.
BODY_INERTIA = pin.Inertia(0.1, np.zeros(3), 1e-4 * np.eye(3))
CLOSURE_ORDERS = ("as_written", "swapped")


@dataclass(frozen=True)
class Mechanism:
    """A built mechanism at an assembled configuration.

    Attributes:
        clm: the model (tree, closures, actuated joints, springs).
        q: (nq,) configuration satisfying every closure (read-only).
        frame: name of the loaded frame.
        positions: frame name -> (3,) world position [m] it must have at q (by hand).
        geometry: name -> array, the inputs of the mechanism's reference (see builders).
    """

    clm: ClosedLoopModel
    q: np.ndarray
    frame: str
    positions: dict
    geometry: dict


# ---------------------------------------------------------------- common builders
def _joint(model, parent, jmodel, name, xyz=(0.0, 0.0, 0.0), rotation=None) -> int:
    """Add joint ``name`` at placement (rotation, xyz) in its parent, with a body."""
    placement = pin.SE3(np.eye(3) if rotation is None else rotation, np.asarray(xyz, float))
    jid = model.addJoint(parent, jmodel, placement, name)
    model.appendBodyToJoint(jid, BODY_INERTIA, pin.SE3.Identity())
    return jid


def _frame(model, name, joint, xyz=(0.0, 0.0, 0.0)) -> None:
    placement = pin.SE3(np.eye(3), np.asarray(xyz, float))
    model.addFrame(pin.Frame(name, joint, placement, pin.FrameType.OP_FRAME))


def _finish(model, pairs, kind, q, frame, positions, geometry, closure_order="as_written", **kw):
    """Close the frame ``pairs`` (each (a, b), or (b, a) when swapped) and wrap it all."""
    if closure_order not in CLOSURE_ORDERS:
        raise ValueError(f"closure_order {closure_order!r}; expected one of {CLOSURE_ORDERS}")
    if closure_order == "swapped":
        pairs = [(b, a) for a, b in pairs]
    closures = [closure_between_frames(model, a, b, kind) for a, b in pairs]
    q = np.array(q, dtype=float)
    q.flags.writeable = False
    geometry = {key: np.asarray(v, dtype=float) for key, v in geometry.items()}
    return Mechanism(ClosedLoopModel(model, closures, **kw), q, frame, positions, geometry)


def _platform(model) -> int:
    """Free-flyer joint ``platform`` on the ground, with a frame ``platform`` at its origin."""
    ff = _joint(model, 0, pin.JointModelFreeFlyer(), "platform")
    _frame(model, "platform", ff)
    return ff


def z_to(v) -> tuple[float, float]:
    """Angles (a, b) with Rx(a) Ry(b) e_z = v / |v| (a universal joint pointing along v)."""
    u = np.asarray(v, float) / np.linalg.norm(v)
    return float(np.arctan2(-u[1], u[2])), float(np.arcsin(u[0]))


def rot_z_to(v) -> np.ndarray:
    """(3, 3) rotation Rx(a) Ry(b) that takes e_z to v / |v| (see :func:`z_to`)."""
    return Rotation.from_euler("XY", z_to(v)).as_matrix()


def quaternion(R) -> np.ndarray:
    """(4,) (x, y, z, w) unit quaternion of R, the layout of Pinocchio configurations."""
    return Rotation.from_matrix(R).as_quat()


def ring(radius, angles_deg, z=0.0) -> np.ndarray:
    """(n, 3) points at ``radius`` [m] and polar ``angles_deg`` [deg], height z [m]."""
    a = np.deg2rad(angles_deg)
    return np.column_stack([radius * np.cos(a), radius * np.sin(a), np.full(a.shape, z)])


# ---------------------------------------------------------------- Stewart 6-UPS
def hexagon(radius, half_angle_deg) -> np.ndarray:
    """(6, 3) semiregular hexagon: points at 120 k -/+ half_angle [deg], k = 0, 1, 2."""
    return ring(radius, np.repeat(120.0 * np.arange(3), 2) + np.tile([-1, 1], 3) * half_angle_deg)


#: Base (radius 1 m, pairs 30 deg apart) and platform (0.5 m, pairs 90 deg apart): each base
#: point joins the nearest platform point of the neighbouring pair (Fichter's 6-6 layout).
STEWART_ANCHORS = STEWART_BASE, STEWART_PLATFORM = hexagon(1.0, 15.0), hexagon(0.5, 45.0)
STEWART_K = np.array([1.0, 1.4, 1.8, 2.2, 2.6, 3.0]) * 1e5  # leg springs [N/m]


def perturbed_anchors(seed=0, amplitude=0.04) -> tuple[np.ndarray, np.ndarray]:
    """(base, platform) anchors moved by uniform noise of ``amplitude`` [m] (no symmetry)."""
    rng = np.random.default_rng(seed)
    noise = rng.uniform(-amplitude, amplitude, size=(2, 6, 3))
    return STEWART_BASE + noise[0], STEWART_PLATFORM + noise[1]


def stewart(position=(0.0, 0.0, 1.0), psi=0.0, tilt=(0.0, 0.0), anchors=STEWART_ANCHORS,
            k=STEWART_K, base_joint="universal") -> Mechanism:  # fmt: skip
    """Gough-Stewart 6-UPS: leg i from base anchor b_i to platform anchor a_i.

    Leg i: a base joint at b_i (``"universal"``: RX then RY; ``"spherical"``: a ball, whose
    spin about the leg is an internal mobility), then the prismatic leg ``leg{i}`` along
    its z axis (actuated, spring k_i [N/m], q = leg length [m]); its end ``leg{i}_end`` is
    closed by a 3d point closure to ``platform_anchor{i}`` on the free-flyer ``platform``.

    Args:
        position: (3,) platform origin [m]; psi: turn about the vertical [rad], applied
            first; tilt: (2,) horizontal rotation vector applied after it [rad].
        anchors: (base, platform), (6, 3) each [m], in the world and platform frames.
        k: (6,) leg stiffness [N/m].

    Geometry: ``u`` (6, 3) unit leg directions, ``r`` (6, 3) platform anchors relative to
    the platform origin (world axes) [m], ``k``, ``b``, ``a``, ``p``, ``R``, ``lengths``.
    """
    base, platform = (np.asarray(x, float) for x in anchors)
    tilt = Rotation.from_rotvec([tilt[0], tilt[1], 0.0])
    p, R = np.asarray(position, float), (tilt * Rotation.from_euler("z", psi)).as_matrix()
    r = platform @ R.T
    legs = p + r - base
    lengths = np.linalg.norm(legs, axis=1)
    model = pin.Model()
    ff = _platform(model)
    q, pairs, positions = [np.r_[p, quaternion(R)]], [], {"platform": p}
    for i, (b, leg) in enumerate(zip(base, legs, strict=True)):
        if base_joint == "universal":
            j = _joint(model, 0, pin.JointModelRX(), f"leg{i}_ux", b)
            j = _joint(model, j, pin.JointModelRY(), f"leg{i}_uy")
            q.append(z_to(leg))
        elif base_joint == "spherical":
            j = _joint(model, 0, pin.JointModelSpherical(), f"leg{i}_ball", b)
            q.append(quaternion(rot_z_to(leg)))
        else:
            raise ValueError(f"base_joint {base_joint!r}")
        j = _joint(model, j, pin.JointModelPZ(), f"leg{i}")
        q.append([lengths[i]])
        _frame(model, f"leg{i}_end", j)
        _frame(model, f"platform_anchor{i}", ff, platform[i])
        pairs.append((f"leg{i}_end", f"platform_anchor{i}"))
        positions |= {f"leg{i}_end": p + r[i], f"platform_anchor{i}": p + r[i]}
    names = [f"leg{i}" for i in range(6)]
    geometry = dict(u=legs / lengths[:, None], r=r, k=k, b=base, a=platform, p=p, R=R)
    geometry["lengths"] = lengths
    return _finish(
        model, pairs, "3d", np.concatenate(q), "platform", positions, geometry,
        actuated=names, springs=dict(zip(names, k, strict=True)), name="stewart",
    )  # fmt: skip


def stewart_near_singular(delta, height=1.0) -> Mechanism:
    """Semiregular Stewart, centred, turned by psi = 90 deg - delta [rad] (Fichter's
    singularity at delta = 0, at any height [m]: a platform twist leaves all legs still)."""
    return stewart(position=(0.0, 0.0, height), psi=np.pi / 2 - delta)


def stewart_inverse_jacobian(u, r) -> np.ndarray:
    """(6, 6) leg rates per platform twist: row i = [u_i, r_i x u_i], dl_i = u_i . (v + w x r_i)."""
    return np.hstack([u, np.cross(r, u)])


def stewart_stiffness(g) -> np.ndarray:
    """(6, 6) K = J^T diag(k) J [N/m, N, N m/rad] at the platform origin, world axes."""
    J = stewart_inverse_jacobian(g["u"], g["r"])
    return J.T @ (g["k"][:, None] * J)


# ---------------------------------------------------------------- planar RR legs
def two_r_ik(A, C, l1, l2, elbow=1) -> tuple[float, float]:
    """Angles (theta, beta) [rad] of a planar RR leg from A to C (links l1, l2 [m]).

    theta: absolute angle of the first link; beta: elbow angle (relative); elbow = +/-1.
    """
    d = np.asarray(C, float)[:2] - np.asarray(A, float)[:2]
    c = (d @ d - l1**2 - l2**2) / (2 * l1 * l2)
    if abs(c) >= 1:
        raise ValueError(f"point {C} out of reach of the leg at {A}")
    beta = elbow * np.arccos(c)
    theta = np.arctan2(d[1], d[0]) - np.arctan2(l2 * np.sin(beta), l1 + l2 * np.cos(beta))
    return float(theta), float(beta)


def _rr_legs(model, base, lengths, targets, elbows):
    """Planar RR legs ``leg{i}`` (revolute z axes) from base[i] to targets[i] (world)."""
    q, positions, B = [], {}, []
    for i, (A, (l1, l2), C, e) in enumerate(zip(base, lengths, targets, elbows, strict=True)):
        j = _joint(model, 0, pin.JointModelRZ(), f"leg{i}_base", A)
        j = _joint(model, j, pin.JointModelRZ(), f"leg{i}_elbow", (l1, 0.0, 0.0))
        _frame(model, f"leg{i}_end", j, (l2, 0.0, 0.0))
        theta, beta = two_r_ik(A, C, l1, l2, e)
        q.append([theta, beta])
        B.append(np.asarray(A, float) + l1 * np.array([np.cos(theta), np.sin(theta), 0.0]))
        positions |= {f"leg{i}_end": np.asarray(C, float), f"leg{i}_elbow": B[-1]}  # joint frame
    return q, positions, np.array(B)


def cross2(a, b) -> np.ndarray:
    """z component of the cross product of planar vectors a, b (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def rr_leg_rows(A, B, C) -> np.ndarray:
    """(n, 2) d theta_i / d C_i of planar RR legs A -> B -> C (C moves, the elbow follows).

    Dotting dC = dtheta z x (C - A) + dbeta z x (C - B) with d = C - B removes dbeta:
    dtheta = d . dC / ((B - A) x d)_z.
    """
    d, e = (C - B)[:, :2], (B - A)[:, :2]
    return d / cross2(e, d)[:, None]


RRR_BASE = ring(0.5, [90.0, 210.0, 330.0]) + np.array([[0.02, 0, 0], [0, -0.03, 0], [0, 0, 0]])
RRR_ANCHORS = ring(0.12, [60.0, 175.0, 300.0])  # platform frame [m]
RRR_LENGTHS = ((0.30, 0.32), (0.28, 0.30), (0.31, 0.29))  # (proximal, distal) [m]
RRR_K = np.array([120.0, 200.0, 160.0])  # base springs [N m/rad]


def rrr3(pose=(0.0, 0.0, 0.0), base=RRR_BASE, anchors=RRR_ANCHORS, lengths=RRR_LENGTHS,
         k=RRR_K, elbows=(1, 1, 1)) -> Mechanism:  # fmt: skip
    """3-RRR planar parallel robot in the plane z = 0, all revolute axes along z.

    Leg i: actuated base revolute ``leg{i}_base`` at base[i] (spring k_i [N m/rad]),
    passive elbow ``leg{i}_elbow``, distal end ``leg{i}_end`` closed by a 3d point closure
    to ``platform_anchor{i}`` (anchors[i] in the frame of the free-flyer ``platform``).

    Args:
        pose: (x [m], y [m], phi [rad]) of the platform.
        elbows: (3,) elbow branch +/-1 of each leg.

    Geometry: ``A`` base pivots, ``B`` elbows, ``C`` platform anchors (3, 3) [m] world;
    ``P`` (3,) platform origin [m]; ``k`` (3,) springs.
    """
    x, y, phi = pose
    R, P = Rotation.from_euler("z", phi).as_matrix(), np.array([x, y, 0.0])
    C = P + np.asarray(anchors, float) @ R.T
    model = pin.Model()
    ff = _platform(model)
    q, positions, B = _rr_legs(model, base, lengths, C, elbows)
    for i, c in enumerate(anchors):
        _frame(model, f"platform_anchor{i}", ff, c)
    positions |= {"platform": P}
    names = [f"leg{i}_base" for i in range(3)]
    return _finish(
        model, [(f"leg{i}_end", f"platform_anchor{i}") for i in range(3)], "3d",
        np.concatenate([np.r_[P, quaternion(R)], *q]), "platform", positions,
        dict(A=base, B=B, C=C, P=P, k=k),
        actuated=names, springs=dict(zip(names, k, strict=True)), name="3-RRR",
    )  # fmt: skip


def rrr3_planar_stiffness(g) -> np.ndarray:
    """(3, 3) stiffness (fx, fy, mz) per (dx, dy, rz) of the 3-RRR platform, J^T diag(k) J.

    With r_i = C_i - P, dC_i = (dx, dy) + rz z x r_i, so d . dC_i = d . dP + rz (r_i x d)_z.
    """
    rows = rr_leg_rows(g["A"], g["B"], g["C"])
    r = (g["C"] - g["P"])[:, :2]
    J = np.column_stack([rows, cross2(r, rows)])
    return J.T @ (g["k"][:, None] * J)


FIVEBAR_BASE = np.array([[-0.15, 0.0, 0.0], [0.15, 0.0, 0.0]])
FIVEBAR_LENGTHS = ((0.25, 0.30), (0.22, 0.32))  # (proximal, distal) [m]
FIVEBAR_K = np.array([80.0, 120.0])  # base springs [N m/rad]


def fivebar(
    point=(0.03, 0.35), base=FIVEBAR_BASE, lengths=FIVEBAR_LENGTHS, k=FIVEBAR_K, elbows=(-1, 1)
) -> Mechanism:
    """Planar 5-bar in the plane z = 0: two RR legs meeting at the end effector E.

    Actuated base revolutes ``leg0_base``, ``leg1_base`` (springs k [N m/rad]); passive
    elbows; the end ``ee`` of distal link 0 is closed by a 3d point closure to the end
    ``leg1_end`` of distal link 1. The loaded frame ``ee`` turns with distal link 0.

    Args:
        point: (x, y) of E [m]; elbows: (2,) branches +/-1 (default: elbows outward).

    Geometry: ``A`` pivots, ``B`` elbows (2, 3) [m], ``E`` (3,) [m], ``k`` (2,).
    """
    E = np.array([point[0], point[1], 0.0])
    model = pin.Model()
    q, positions, B = _rr_legs(model, base, lengths, [E, E], elbows)
    _frame(model, "ee", model.getJointId("leg0_elbow"), (lengths[0][1], 0.0, 0.0))
    names = ["leg0_base", "leg1_base"]
    return _finish(
        model, [("ee", "leg1_end")], "3d", np.concatenate(q), "ee", positions | {"ee": E},
        dict(A=base, B=B, E=E, k=k),
        actuated=names, springs=dict(zip(names, k, strict=True)), name="5-bar",
    )  # fmt: skip


def fivebar_planar_compliance(g) -> np.ndarray:
    """(3, 3) compliance (dx, dy, rz) per (fx, fy, mz) at E, rz that of distal link 0.

    Translation: the inverse of J_inv^T diag(k) J_inv (J_inv = :func:`rr_leg_rows`).
    Rotation: dE = dtheta_0 z x (B_0 - A_0) + rz z x d_0 (d_0 = E - B_0), so
    rz = (z x d_0) . (dE - dtheta_0 z x (B_0 - A_0)) / |d_0|^2 = g . dE, and
    C = [I; g^T] C_xy [I, g].
    """
    E2 = np.tile(g["E"], (2, 1))
    J_inv = rr_leg_rows(g["A"], g["B"], E2)
    C_xy = np.linalg.inv(J_inv.T @ (g["k"][:, None] * J_inv))
    zx = lambda v: np.array([-v[1], v[0]])  # noqa: E731  z x v in the plane
    d0, e0 = (g["E"] - g["B"][0])[:2], (g["B"][0] - g["A"][0])[:2]
    grad = (zx(d0) - (zx(d0) @ zx(e0)) * J_inv[0]) / (d0 @ d0)
    T = np.vstack([np.eye(2), grad])
    return T @ C_xy @ T.T


# ---------------------------------------------------------------- Delta (Clavel)
DELTA_K_ARM = np.array([300.0, 400.0, 500.0])  # arm springs [N m/rad]


def delta(position=(0.0, 0.0, -0.5), k_arm=DELTA_K_ARM, k_rod=None, closure_order="as_written",
          r_base=0.2, r_platform=0.05, arm=0.25, rod=0.6, width=0.04) -> Mechanism:  # fmt: skip
    """Delta robot: three arms, each carrying a parallelogram of two ball-ball rods.

    Arm i (i = 0, 1, 2, at polar angle 120 i deg): actuated revolute ``arm{i}`` at
    A_i = r_base u_i, axis a_i = z x u_i, spring k_arm[i] [N m/rad]; elbow midpoint
    E_i = A_i + arm (cos theta u_i - sin theta z). Rod j = 2 i + s (s = 0, 1): a ball joint
    ``rod{j}_ball`` at E_i -/+ width a_i, then (if ``k_rod`` [N/m] is given) an axial
    prismatic ``rod{j}_axial`` with spring k_rod; its end ``rod{j}_end``, ``rod`` [m] along
    the rod, closed by a 3d point closure to ``platform_anchor{j}`` at
    r_platform u_i -/+ width a_i on the free-flyer ``platform`` (identity orientation, at
    ``position`` [m]). Each rod spins freely about its axis: 6 internal mobilities.

    Args:
        position: (3,) platform origin [m]; k_arm: (3,) [N m/rad]; k_rod: [N/m] or None
            (rigid rods); closure_order: pairs written (rod end, platform) or swapped;
        r_base, r_platform, arm, rod: radii and link lengths [m]; width: half the spacing
            of the two rods of a parallelogram [m].

    Geometry: ``A``, ``E`` (3, 3) [m]; ``a`` (3, 3) arm axes; ``s`` (6, 3) unit rod
    directions (elbow to platform); ``r`` (6, 3) platform anchors relative to the platform
    origin [m]; ``arm_of`` (6,) arm of each rod; ``k_arm`` (3,); ``k_rod`` (6,) (inf if rigid).
    """
    p = np.asarray(position, float)
    model = pin.Model()
    ff = _platform(model)
    q, pairs, positions = [np.r_[p, 0.0, 0.0, 0.0, 1.0]], [], {"platform": p}
    A, E, a, s, r = [], [], [], [], []
    for i in range(3):
        gamma = np.deg2rad(120.0 * i)
        u = np.array([np.cos(gamma), np.sin(gamma), 0.0])
        R_arm = Rotation.from_euler("z", gamma).as_matrix()
        A_i, a_i = r_base * u, np.cross(EZ, u)
        D = p + r_platform * u - A_i  # elbow midpoint to platform midpoint: length rod
        M = (D @ D + arm**2 - rod**2) / (2 * arm)  # cos(theta) D.u - sin(theta) D.z = M
        theta = -np.arccos(M / np.hypot(D @ u, D[2])) - np.arctan2(D[2], D @ u)  # knee out
        E_i = A_i + arm * (np.cos(theta) * u - np.sin(theta) * EZ)
        R_upper = R_arm @ Rotation.from_euler("y", theta).as_matrix()
        j_arm = _joint(model, 0, pin.JointModelRY(), f"arm{i}", A_i, R_arm)
        q.append([theta])
        A.append(A_i), E.append(E_i), a.append(a_i)
        positions[f"arm{i}"] = A_i  # joint frame
        for side, sign in enumerate((-1.0, 1.0)):
            jr = 2 * i + side
            anchor = r_platform * u + sign * width * a_i
            tail = E_i + sign * width * a_i
            s.append((p + anchor - tail) / rod)
            r.append(anchor)
            ball = (arm, sign * width, 0.0)  # in the arm frame
            j = _joint(model, j_arm, pin.JointModelSpherical(), f"rod{jr}_ball", ball)
            q.append(quaternion(R_upper.T @ rot_z_to(s[-1])))
            if k_rod is not None:
                j = _joint(model, j, pin.JointModelPZ(), f"rod{jr}_axial")
                q.append([0.0])
            _frame(model, f"rod{jr}_end", j, (0.0, 0.0, rod))
            _frame(model, f"platform_anchor{jr}", ff, anchor)  # platform axes = world
            pairs.append((f"rod{jr}_end", f"platform_anchor{jr}"))
            positions |= {f"rod{jr}_end": p + anchor, f"platform_anchor{jr}": p + anchor}
    names = [f"arm{i}" for i in range(3)]
    springs = dict(zip(names, k_arm, strict=True))
    if k_rod is not None:
        springs |= {f"rod{j}_axial": k_rod for j in range(6)}
    geometry = dict(A=A, E=E, a=a, s=s, r=r, arm_of=np.repeat(np.arange(3), 2), k_arm=k_arm)
    geometry["k_rod"] = np.full(6, np.inf if k_rod is None else k_rod)
    return _finish(
        model, pairs, "3d", np.concatenate(q), "platform", positions, geometry, closure_order,
        actuated=names, springs=springs, name="delta",
    )  # fmt: skip


def delta_translational_compliance(g) -> np.ndarray:
    """(3, 3) compliance (dx, dy, dz) per (fx, fy, fz) of the rigid-rod Delta [m/N].

    The platform only translates, so each parallelogram keeps |P + c_i - E_i| = rod with
    both rods parallel to s_i; d/dt: s_i . (dP - dtheta_i v_i) = 0, hence the inverse
    Jacobian row s_i / (s_i . v_i) and C = J diag(1 / k_arm) J^T with J = J_inv^-1.
    """
    s, v = g["s"][::2], np.cross(g["a"], g["E"] - g["A"])  # elbow velocity per arm rate
    J = np.linalg.inv(s / np.sum(s * v, axis=1)[:, None])
    return (J / g["k_arm"]) @ J.T


def delta_sprung_compliance(g) -> np.ndarray:
    """(6, 6) compliance of the Delta with axial rod springs, by static condensation.

    Rod j of arm i stretches by dl_j = s_j . (dp + w x r_j - dtheta_i v_i), with the elbow
    velocity v_i = a_i x (E_i - A_i) per unit arm rate [m/rad], i.e.
    dl = A t - B dtheta with A = [s_j, r_j x s_j] (6, 6), B_ji = s_j . v_i (6, 3). The
    energy 1/2 dl^T K_r dl + 1/2 dtheta^T K_a dtheta, minimised over the arm angles that
    the load does not touch, leaves K = A^T K_r A - A^T K_r B (B^T K_r B + K_a)^-1 B^T K_r A.
    """
    s, A = g["s"], stewart_inverse_jacobian(g["s"], g["r"])
    B = np.zeros((6, 3))
    idx = g["arm_of"].astype(int)
    B[np.arange(6), idx] = np.sum(s * np.cross(g["a"], g["E"] - g["A"])[idx], axis=1)
    Kr, Ka = np.diag(g["k_rod"]), np.diag(g["k_arm"])
    KrA, KrB = Kr @ A, Kr @ B
    K = A.T @ KrA - KrA.T @ B @ np.linalg.solve(B.T @ KrB + Ka, KrB.T @ A)
    return np.linalg.inv(K)


# ------------------------------------------------------------------ path cases
def spd_block(rng: np.random.Generator, n: int, linear: float, angular: float) -> np.ndarray:
    """A (n, n) SPD block with strong coupling: scaled D (A A^T + n I) D, D the units."""
    A = rng.normal(size=(n, n))
    d = np.r_[np.full(min(n, 3), np.sqrt(linear)), np.full(max(n - 3, 0), np.sqrt(angular))]
    if n < 6:
        d = np.full(n, np.sqrt(angular))
    return d[:, None] * (A @ A.T + n * np.eye(n)) * d[None, :]


def serial_with_block(
    seed: int = 3, wrist: str = "universal"
) -> tuple[ClosedLoopModel, np.ndarray, dict]:
    """A revolute base, a 6-dof free-flyer-like flexible joint, a 2-dof universal wrist
    (or, with ``wrist="spherical"``, a 3-dof ball).

    Springs: base 2e3 N m/rad, the free flyer a coupled 6x6 (linear ~1e6 N/m, angular
    ~1e4 N m/rad), the wrist a coupled 2x2 or 3x3 (~300 N m/rad). Frame ``tool`` on the
    wrist. Returns the model, a configuration off the neutral one and the springs.

    Pinocchio's kinematic Hessians (the geometric stiffness of a preload) assume a
    constant joint motion subspace, which the universal joint does not have: the library
    takes its second derivatives by central differences (closedloop.common.derivatives).
    """
    rng = np.random.default_rng(seed)
    m = pin.Model()
    m.name = "serial_block"
    base = m.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "base")
    place = pin.SE3(pin.exp3(np.array([0.2, -0.1, 0.3])), np.array([0.4, 0.05, 0.1]))
    flex = m.addJoint(base, pin.JointModelFreeFlyer(), place, "flex")
    joint = (
        pin.JointModelUniversal(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        if wrist == "universal"
        else pin.JointModelSpherical()
    )
    wrist_id = m.addJoint(flex, joint, pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.0])), "wrist")
    for j in (base, flex, wrist_id):
        m.appendBodyToJoint(j, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
    tool = pin.SE3(pin.exp3(np.array([0.0, 0.4, 0.1])), np.array([0.1, 0.02, 0.15]))
    m.addFrame(pin.Frame("tool", wrist_id, tool, pin.OP_FRAME))
    springs = {
        "base": 2e3,
        "flex": spd_block(rng, 6, 1e6, 1e4),
        "wrist": spd_block(rng, joint.nv, 0.0, 150.0),
    }
    q = pin.integrate(m, pin.neutral(m), rng.normal(scale=0.3, size=m.nv))
    return ClosedLoopModel(m, springs=springs, name="serial_block"), q, springs


def fourbar_case():
    """The bundled four-bar at crank 0.3 rad: (model, q, "P")."""
    m = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    return m, cl.assemble(m, actuated=[0.3]).q, "P"


def cahyman_case():
    """CaHyMan at Table 3's cranks, alpha_4 = 45 deg, s_4 = 10 mm: (model, q, "M")."""
    from cahyman_pin.model import cahyman_model

    m = cahyman_model()
    return m.clm, m.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01), "M"


def ur5_case():
    """The UR5 with 1e4 N m/rad joint springs at a generic pose: (model, q, "tool0")."""
    m = load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=1e4)
    return m, np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2]), "tool0"


def built_case(build):
    """(model, q, frame) of a :class:`Mechanism` builder."""
    m = build()
    return m.clm, m.q, m.frame


#: Test mechanisms of the compliance paths: name -> (builder returning (model, q, frame),
#: the path the automatic choice takes).
PATH_CASES = {
    "fourbar": (fourbar_case, "partitioned"),
    "cahyman": (cahyman_case, "partitioned"),
    "ur5": (ur5_case, "serial"),
    "stewart": (lambda: built_case(lambda: stewart(position=(0.05, -0.02, 1.1),
                                                        psi=0.2, tilt=(0.1, -0.05))),
                "partitioned"),
    "rrr3": (lambda: built_case(lambda: rrr3((0.02, -0.01, 0.1))), "partitioned"),
    "fivebar": (lambda: built_case(lambda: fivebar((0.02, 0.35))), "partitioned"),
    # the rods spin about their axes: the passive joints are not determined
    "delta": (lambda: built_case(lambda: delta(k_rod=2e5)), "null-space"),
}  # fmt: skip


# ------------------------------------------------------------------ edge cases
def fourbar_chain(angles, k=1e3) -> tuple[ClosedLoopModel, np.ndarray, str]:
    """Planar parallelogram four-bars in series, each standing on the previous rocker
    (the chain of scripts/bench_closedloop.py, one crank angle per loop).

    Loop i: crank ``crank{i}`` (0.3 m, actuated, spring k (1 + i / 10) [N m/rad]) and
    rocker ``rocker{i}`` (0.3 m, passive) pivot 0.2 m apart on the previous rocker (the
    world for loop 0); the passive coupler ``coupler{i}`` (0.2 m) on the crank tip is closed
    to the rocker tip by a 3d point closure. At crank angle t_i (coupler -t_i, rocker t_i,
    relative) loop i closes exactly; at t_i = 0 its bars are collinear (a change point:
    the coupler and the rocker turn without moving the closure point to first order).

    Returns (model, q (3 n,), frame ``tip`` at the last rocker's tip).
    """
    model, closures, q, base = pin.Model(), [], [], 0
    place = [pin.SE3(np.eye(3), np.array([x, 0.0, 0.0])) for x in (0.0, 0.3, 0.2)]
    for i, t in enumerate(angles):
        crank = _joint(model, base, pin.JointModelRZ(), f"crank{i}")
        coupler = _joint(model, crank, pin.JointModelRZ(), f"coupler{i}", (0.3, 0.0, 0.0))
        rocker = _joint(model, base, pin.JointModelRZ(), f"rocker{i}", (0.2, 0.0, 0.0))
        closures.append(pin.PointAnchorConstraintModel(model, coupler, place[2], rocker, place[1]))
        q += [t, -t, t]
        base = rocker
    _frame(model, "tip", base, (0.3, 0.0, 0.0))
    cranks = [f"crank{i}" for i in range(len(angles))]
    springs = {c: k * (1.0 + 0.1 * i) for i, c in enumerate(cranks)}
    clm = ClosedLoopModel(model, closures, cranks, springs, name=f"4bar{len(angles)}")
    return clm, np.array(q, dtype=float), "tip"


def scaled_fourbar(s: float, springs=None) -> tuple[ClosedLoopModel, np.ndarray, str]:
    """The bundled four-bar with every length multiplied by ``s`` (joint and frame
    placements, closure anchors, prismatic coordinates), at crank 0.3 rad.

    Springs (default: the file's, crank 50 N m/rad, axial 1e5 and 2e5 N/m): revolute ones
    as given, prismatic ones divided by s^2, so that the energy of a motion is that of the
    unscaled one and C = D C_1 D, D = diag(s, s, s, 1, 1, 1) (m/N by s^2, rad/N by s,
    rad/(N m) unchanged). Returns (model, q, "P").
    """
    unit, q1, _ = fourbar_case()
    m = pin.Model(unit.model)
    for j in range(m.njoints):
        P = m.jointPlacements[j]
        m.jointPlacements[j] = pin.SE3(P.rotation, P.translation * s)
    for f in m.frames:
        f.placement = pin.SE3(f.placement.rotation, f.placement.translation * s)
    closure = closure_between_frames(m, "closedloop1_A", "closedloop1_B", "3d")
    spec = dict(unit.springs if springs is None else springs)
    linear = {n for n in spec if unit.linear_coordinates[unit.joint_v_slice(n)].all()}
    spec = {n: v / s**2 if n in linear else v for n, v in spec.items()}
    clm = ClosedLoopModel(m, [closure], ["crank"], spec, name="fourbar")
    q = np.array(q1, dtype=float)
    q[clm.linear_coordinates] *= s
    return clm, q, "P"


# ------------------------------------------------------------------ MJCF four-bar
#: The MJCF four-bar's points in the world at qpos0 [m], in the xz plane: the crank's hinge
#: at the origin, the coupler's at B, the rocker's at D, the loop's closing point C, the
#: output site P on the coupler.
MJCF_FOURBAR_POINTS = {"B": (0.0, 0.0, 0.12), "C": (0.3, 0.0, 0.18), "D": (0.34, 0.0, 0.0),
                       "P": (0.25, 0.0, 0.22)}  # fmt: skip


def xyz_text(v) -> str:
    """The text of an MJCF vector attribute: the numbers of ``v``, shortest round trip."""
    return " ".join(map(repr, map(float, v)))


def mjcf_fourbar(equality: str, k: float = 400.0, rocker_tip: bool = True,
                 points=MJCF_FOURBAR_POINTS) -> str:  # fmt: skip
    """The MJCF text of a planar four-bar closed by ``equality`` (the content of its
    ``<equality>``, e.g. a ``<connect>``).

    Bodies ``crank`` (hinge ``crank`` at the origin, ``stiffness`` k [N m/rad]), ``coupler``
    (hinge at B) and ``rocker`` (hinge at D), hinges about y; the jointless body
    ``coupler_tip`` at C carries the site ``P``, and the jointless body ``rocker_tip`` (left
    out when not ``rocker_tip``) is at C on the rocker; all inside a jointless ``ground``.
    ``points``: {"B", "C", "D", "P": (3,) world position at qpos0 [m]}; every body is
    world-aligned.
    """
    B, C, D, P = (np.asarray(points[n], float) for n in "BCDP")
    tip = f'\n        <body name="rocker_tip" pos="{xyz_text(C - D)}"/>' if rocker_tip else ""
    return f"""<mujoco model="fourbar">
  <compiler angle="radian"/>
  <worldbody>
    <body name="ground">
      <body name="crank">
        <joint name="crank" type="hinge" axis="0 1 0" stiffness="{k!r}"/>
        <body name="coupler" pos="{xyz_text(B)}">
          <joint name="coupler" type="hinge" axis="0 1 0"/>
          <body name="coupler_tip" pos="{xyz_text(C - B)}">
            <site name="P" pos="{xyz_text(P - C)}"/>
          </body>
        </body>
      </body>
      <body name="rocker" pos="{xyz_text(D)}">
        <joint name="rocker" type="hinge" axis="0 1 0"/>{tip}
      </body>
    </body>
  </worldbody>
  <equality>{equality}</equality>
</mujoco>"""

"""MuJoCo (the ``mujoco-core`` package) as an independent reader of MJCF files.

A plain module, not a test module. MuJoCo compiles the original file with its own parser
and kinematics; the library reads it through Pinocchio and its corrections. The helpers
here only translate between the two: joint coordinates by joint name (MuJoCo's
quaternions are w x y z, Pinocchio's x y z w; hinge and slide values are the same
numbers, both being MuJoCo's ``qpos``), bodies, sites and equalities by name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from closedloop.model.closed_loop import ClosedLoopModel


def mujoco():
    """The ``mujoco`` module, or the calling test skipped, saying how to install it."""
    return pytest.importorskip(
        "mujoco", reason="MuJoCo is not installed (pip install '.[test]', mujoco-core)"
    )


def compiled(path: Path):
    """(MjModel, MjData) of the file as MuJoCo compiles it."""
    mj = mujoco()
    m = mj.MjModel.from_xml_path(str(path))
    return m, mj.MjData(m)


def coordinates(m, clm: ClosedLoopModel) -> list[tuple[int, int]]:
    """(first configuration index, first velocity index) in the library of each of MuJoCo's
    joints: the joints in the same order (depth first), each where the library's joint of
    its name starts, or next (the later joints of a body, which Pinocchio merges into a
    composite joint named after the first)."""
    model, out, i, v = clm.model, [], 0, 0
    for j in range(m.njnt):
        if model.existJointName(m.joint(j).name):
            joint = model.joints[model.getJointId(m.joint(j).name)]
            i, v = joint.idx_q, joint.idx_v
        out.append((i, v))
        i += (m.jnt_qposadr[j + 1] if j + 1 < m.njnt else m.nq) - m.jnt_qposadr[j]
        v += (m.jnt_dofadr[j + 1] if j + 1 < m.njnt else m.nv) - m.jnt_dofadr[j]
    return out


def to_q(m, clm: ClosedLoopModel, qpos: np.ndarray) -> np.ndarray:
    """The library's configuration (nq,) of MuJoCo's ``qpos`` (m.nq,) (:func:`coordinates`)."""
    q = pin.neutral(clm.model)
    for j, (i, _) in enumerate(coordinates(m, clm)):
        a = m.jnt_qposadr[j]
        nq = (m.jnt_qposadr[j + 1] if j + 1 < m.njnt else m.nq) - a
        values = qpos[a : a + nq]
        if nq == 7:  # free: position, then quaternion
            values = np.r_[values[:3], values[4:], values[3]]
        elif nq == 4:  # ball
            values = np.r_[values[1:], values[0]]
        q[i : i + nq] = values
    return q


def one_dof(m, j: int) -> bool:
    """Whether MuJoCo's joint ``j`` is a hinge or a slide."""
    kinds = mujoco().mjtJoint
    return int(m.jnt_type[j]) in (int(kinds.mjJNT_HINGE), int(kinds.mjJNT_SLIDE))


def random_qpos(m, rng: np.random.Generator, turn: float = 1.0, slide: float = 0.02):
    """``m.qpos0`` moved at random: hinges by up to ``turn`` [rad], slides by up to
    ``slide`` [m], free positions by up to ``slide`` [m], quaternions to random ones."""
    kinds = mujoco().mjtJoint
    qpos = m.qpos0.copy()
    for j in range(m.njnt):
        a, kind = m.jnt_qposadr[j], int(m.jnt_type[j])
        if kind == int(kinds.mjJNT_HINGE):
            qpos[a] += rng.uniform(-turn, turn)
        elif kind == int(kinds.mjJNT_SLIDE):
            qpos[a] += rng.uniform(-slide, slide)
        else:
            if kind == int(kinds.mjJNT_FREE):
                qpos[a : a + 3] += rng.uniform(-slide, slide, 3)
                a += 3
            quat = rng.normal(size=4)
            qpos[a : a + 4] = quat / np.linalg.norm(quat)
    return qpos


def placements(m, d, clm: ClosedLoopModel, qpos: np.ndarray) -> dict[str, tuple]:
    """{"body NAME" / "site NAME": (MuJoCo's, the library's)} world placements
    ((4, 4) homogeneous matrices [m]) of every named body but the world, and every site,
    at ``qpos``."""
    mj = mujoco()
    d.qpos[:] = qpos
    mj.mj_kinematics(m, d)
    model, data = clm.model, clm.model.createData()
    pin.framesForwardKinematics(model, data, to_q(m, clm, qpos))

    def library(name: str, kind) -> np.ndarray:
        assert model.existFrame(name, kind), f"the library has no frame {name!r}"
        return data.oMf[model.getFrameId(name, kind)].homogeneous

    out = {}
    for b in range(1, m.nbody):
        M = homogeneous(d.xmat[b], d.xpos[b])
        out[f"body {m.body(b).name}"] = (M, library(m.body(b).name, pin.FrameType.BODY))
    for s in range(m.nsite):
        M = homogeneous(d.site_xmat[s], d.site_xpos[s])
        out[f"site {m.site(s).name}"] = (M, library(m.site(s).name, pin.FrameType.OP_FRAME))
    return out


def homogeneous(xmat: np.ndarray, xpos: np.ndarray) -> np.ndarray:
    """(4, 4) of a MuJoCo rotation (9,) row-major and position (3,) [m]."""
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = np.reshape(xmat, (3, 3)), xpos
    return M


def equality_ends(m, d, e: int) -> tuple[np.ndarray, np.ndarray]:
    """World placements (4, 4) [m] of the two ends of MuJoCo's equality ``e`` after
    ``mj_kinematics``, as ``eq_data`` defines them (MuJoCo's XML reference,
    ``equality/connect`` and ``equality/weld``; the point constraint is their positions'
    difference, the weld's rotation the difference of their orientations):

    * connect: body1's point ``eq_data[0:3]`` (the ``anchor``) and body2's point
      ``eq_data[3:6]`` (where the anchor is at ``qpos0``); orientations are body1's and
      body2's, unconstrained;
    * weld: body1's frame moved by ``eq_data[3:10]`` (``relpose``: position, quaternion
      w x y z; the pose at ``qpos0`` when the file's quaternion is zero) and body2's frame
      moved to ``eq_data[0:3]`` (the ``anchor``).
    """
    mj = mujoco()
    b1, b2, data = m.eq_obj1id[e], m.eq_obj2id[e], m.eq_data[e]
    X1, X2 = (homogeneous(d.xmat[b], d.xpos[b]) for b in (b1, b2))
    if m.eq_type[e] == mj.mjtEq.mjEQ_CONNECT:
        return X1 @ offset(np.eye(3), data[0:3]), X2 @ offset(np.eye(3), data[3:6])
    R = np.empty(9)
    mj.mju_quat2Mat(R, data[6:10] / np.linalg.norm(data[6:10]))
    return X1 @ offset(R.reshape(3, 3), data[3:6]), X2 @ offset(np.eye(3), data[0:3])


def offset(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, p
    return M


def closure_name(m, e: int) -> str:
    """The library's name of MuJoCo's equality ``e``: its own, else ``<tag><i>``, the i-th
    of its kind in the file."""
    if m.eq(e).name:
        return m.eq(e).name
    tag = "connect" if m.eq_type[e] == mujoco().mjtEq.mjEQ_CONNECT else "weld"
    return f"{tag}{int(np.sum(m.eq_type[:e] == m.eq_type[e]))}"


def library_ends(clm: ClosedLoopModel, name: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World placements (4, 4) [m] of the two anchors of the library's closure ``name`` at
    q (the library's configuration)."""
    (closure,) = [c for c in clm.closures if c.name == name]
    c = closure.constraint
    data = clm.model.createData()
    pin.forwardKinematics(clm.model, data, q)
    M1 = data.oMi[c.joint1_id] * c.joint1_placement
    M2 = data.oMi[c.joint2_id] * c.joint2_placement
    return M1.homogeneous, M2.homogeneous


#: A serial arm with a spring on every joint (no loop), for statics and vibration: hinges
#: (one with ``ref`` and ``springref`` away from 0), a slide and a ball joint, world
#: gravity off, ``armature`` 0 (MuJoCo then adds nothing to the mass matrix). Inertias off
#: their bodies' origins, rotated or full; the body ``tool`` has its centre of mass at
#: its origin, where MuJoCo's ``xfrc_applied`` acts.
SPRUNG_ARM = """<mujoco model="sprung_arm">
  <compiler angle="radian"/>
  <option gravity="0 0 0"/>
  <default><joint armature="0" damping="0"/></default>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="yaw" axis="0 0 1" stiffness="30"/>
      <inertial pos="0.02 0.01 0.1" mass="1.5" diaginertia="0.02 0.03 0.01"/>
      <body name="upper" pos="0 0 0.2" euler="0 0.4 0">
        <joint name="pitch" axis="0 1 0" ref="0.4" springref="0.4" stiffness="50"/>
        <inertial pos="0.15 0 0.01" quat="0.9 0.1 0.3 0" mass="1.2"
                  diaginertia="0.002 0.012 0.011"/>
        <body name="fore" pos="0.3 0 0">
          <joint name="reach" type="slide" axis="1 0 0" stiffness="2e4"/>
          <inertial pos="0.1 0.005 0" mass="0.8" fullinertia="0.001 0.004 0.0045 1e-4 -2e-4 5e-5"/>
          <body name="wrist" pos="0.2 0 0" axisangle="0 0 1 0.3">
            <joint name="roll" axis="1 0 0" stiffness="20"/>
            <inertial pos="0.02 0 0" mass="0.3" diaginertia="3e-4 2e-4 2e-4"/>
            <body name="hand" pos="0.05 0 0">
              <joint name="ball" type="ball" stiffness="15"/>
              <inertial pos="0.04 0.01 0" mass="0.25" diaginertia="2e-4 3e-4 2.5e-4"/>
              <body name="tool" pos="0.1 0.02 -0.03">
                <inertial pos="0 0 0" quat="0.8 0 0.6 0" mass="0.4"
                          diaginertia="4e-4 3e-4 2e-4"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def joint_inertias(m, clm: ClosedLoopModel) -> dict[int, pin.Inertia]:
    """{library joint id: MuJoCo's inertia of the bodies it carries} (mass [kg], centre of
    mass [m] and rotational inertia about it [kg m^2], in the joint's frame): each of
    MuJoCo's bodies (``body_mass``, ``body_ipos``, ``body_iquat``, ``body_inertia``, in the
    body's frame) moved into the frame of the library's joint that carries the body of its
    name (its BODY frame's ``parentJoint`` and ``placement``), summed per joint, as
    Pinocchio sums a fixed body into its joint. The world's joint (0) is left out."""
    mj, model, out = mujoco(), clm.model, {}
    for b in range(1, m.nbody):
        frame = model.frames[model.getFrameId(m.body(b).name, pin.FrameType.BODY)]
        if frame.parentJoint == 0:
            continue
        R = np.empty(9)
        mj.mju_quat2Mat(R, m.body_iquat[b])
        R = R.reshape(3, 3)
        own = pin.Inertia(m.body_mass[b], m.body_ipos[b], R @ np.diag(m.body_inertia[b]) @ R.T)
        moved = frame.placement.act(own)
        out[frame.parentJoint] = out.get(frame.parentJoint, pin.Inertia.Zero()) + moved
    return out

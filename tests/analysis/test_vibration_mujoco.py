"""Natural frequencies of a sprung serial MJCF arm against MuJoCo's mass matrix.

MuJoCo compiles :data:`mujoco_peer.SPRUNG_ARM` (inertias off their bodies' origins,
rotated, full; ``armature`` 0) and :data:`GEOM_CHAIN` (inertias from geoms) and gives
their joint-space mass matrix at a configuration (``mj_fullM`` after ``mj_forward``); the
joint springs give the stiffness, diagonal in MuJoCo's velocity coordinates (a ball
joint's three, in its body's axes, each with the joint's ``stiffness``: the
linearisation of MuJoCo's ball spring about its rest). The
generalised eigenproblem K y = omega^2 M y, solved by scipy, gives the frequencies that
``cl.modes`` must give (the modes about the configuration, unloaded: no geometric
stiffness).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from mujoco_peer import SPRUNG_ARM, compiled, mujoco, random_qpos, to_q

import closedloop as cl
from closedloop.io.loader import load_model

#: The same mass and stiffness matrices built by two codes (Pinocchio's composite rigid
#: body algorithm, MuJoCo's), entries from 1e-4 to 2e4, solved by two dense eigensolvers:
#: frequencies agree to rounding times the condition of the pencil (measured: 1.4e-13).
FREQUENCY_RTOL = 1e-9


#: A sprung chain without ``<inertial>``: MuJoCo and the library take each body's mass
#: and inertia from its geoms (a box, a capsule given by ``fromto``, a sphere with a
#: ``mass``, a rotated cylinder with a ``density``, an ellipsoid in a ``<frame>``; density
#: 1000 kg/m^3).
GEOM_CHAIN = """<mujoco model="geom_chain">
  <compiler angle="radian"/>
  <worldbody>
    <body name="a" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1" stiffness="10"/>
      <geom type="box" size="0.05 0.02 0.01" pos="0.05 0 0"/>
      <body name="b" pos="0.1 0 0">
        <joint name="j2" axis="0 1 0" stiffness="20"/>
        <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.01"/>
        <body name="c" pos="0.2 0 0">
          <joint name="j3" axis="1 0 0" stiffness="5"/>
          <geom type="sphere" size="0.03" pos="0.02 0.01 0" mass="0.3"/>
          <geom type="cylinder" size="0.01 0.04" pos="0 0 0.05" euler="0.3 0 0" density="2000"/>
          <frame pos="0.05 0 0" euler="0 0.2 0.4">
            <geom type="ellipsoid" size="0.01 0.02 0.03" pos="0.01 0 0"/></frame>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
MODELS = {"arm": SPRUNG_ARM, "geom_chain": GEOM_CHAIN}


@pytest.fixture(scope="module", params=list(MODELS))
def arm(tmp_path_factory, request):
    """(MjModel, MjData, the library's model) of each of :data:`MODELS`."""
    path = tmp_path_factory.mktemp("arm") / f"{request.param}.xml"
    path.write_text(MODELS[request.param])
    return (*compiled(path), load_model(path, geometry=False))


def mujoco_frequencies(m, d) -> np.ndarray:
    """Natural frequencies [Hz] (nv,), ascending, of MuJoCo's mass matrix and joint
    springs at ``d.qpos``."""
    mj = mujoco()
    mj.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mj.mj_fullM(m, d, M)
    K = np.diag(m.jnt_stiffness[m.dof_jntid])
    omega2 = scipy.linalg.eigh(K, M, eigvals_only=True)
    return np.sqrt(omega2) / (2 * np.pi)


def test_the_arm_has_no_armature(arm):
    m, _, _ = arm
    np.testing.assert_array_equal(m.dof_armature, 0.0)


@pytest.mark.parametrize("seed", [None, 1, 2], ids=["qpos0", "random1", "random2"])
def test_frequencies_are_mujocos(arm, seed):
    """At qpos0 and at random configurations (the springs' stiffness about them, no
    load: the unloaded modes of the arm posed there)."""
    m, d, clm = arm
    rng = None if seed is None else np.random.default_rng(seed)
    d.qpos[:] = m.qpos0 if rng is None else random_qpos(m, rng)
    expected = mujoco_frequencies(m, d)
    result = cl.modes(clm, to_q(m, clm, d.qpos))
    assert expected.shape == (m.nv,) and expected[0] > 0  # every motion sprung and massive
    np.testing.assert_allclose(result.frequencies, expected, rtol=FREQUENCY_RTOL)

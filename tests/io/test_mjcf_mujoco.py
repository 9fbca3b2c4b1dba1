"""MJCF files as MuJoCo reads them: the library's kinematics against MuJoCo's.

MuJoCo (``mujoco-core``) compiles each file with its own parser; its ``mj_kinematics``
places the bodies and sites, its ``eq_data`` the two ends of each ``<connect>`` and
``<weld>`` (read as :func:`mujoco_peer.equality_ends`, checked against MuJoCo's own
constraint residual below), its ``jnt_stiffness``, ``qpos_spring`` and ``jnt_range`` are the
springs and limits. The library reads the same file through Pinocchio and the corrections
of :mod:`closedloop.io.mjcf`. Compared at ``qpos0`` and at random configurations (closed
or not: the tree's kinematics does not care), on the bundled MJCF models and on small files
that each exercise one correction.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO
from mujoco_peer import (
    closure_name,
    compiled,
    coordinates,
    equality_ends,
    joint_inertias,
    library_ends,
    mujoco,
    one_dof,
    placements,
    random_qpos,
    to_q,
)
from scipy.spatial.transform import Rotation

from closedloop.io.loader import load_model

#: Placements of bodies a few joints deep, with lengths and rotation entries of order 1,
#: composed in double precision by two codes from the same decimal inputs: they differ by
#: a few ulps (measured: 9e-16 at most). The misplacements the library corrects were off
#: by 1e-2 m or more; a hinge read about a wrong point or axis, by the angle times a length.
PLACEMENT_TOL = 1e-12
#: Masses and inertias of boxes, spheres, capsules, cylinders and ellipsoids computed by
#: two codes from the same decimal sizes and densities, then moved and summed: they differ
#: by rounding (measured: masses 3e-16 relative; inertias 9e-15 relative to their largest
#: entry; centres of mass 3e-17 m, within :data:`PLACEMENT_TOL`). The geoms Pinocchio
#: dropped (in a <frame>) took 65 % of a body's mass away.
MASS_RTOL = 1e-12
#: Random configurations compared besides qpos0, per file.
N_RANDOM = 3

BUNDLED = ("fourbar", "fivebar5", "rrr3", "delta", "stewart")
INERTIAL = '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
#: Small files, each exercising corrections of Pinocchio's reading (docs/guide/mjcf_sdf.md).
FILES = {
    # rotated free-jointed bodies among several root bodies; a ball joint; worldbody sites
    "free": f"""<mujoco model="free"><compiler angle="radian"/><worldbody>
      <site name="w" pos="0.1 0.2 0.3" euler="0.1 0 0"/>
      <body name="arm" pos="0.1 0 0.05" euler="0.1 0.2 0.3"><joint name="a" axis="0 1 0"/>
        {INERTIAL}<body name="arm_tip" pos="0.3 0 0"><site name="tip" pos="0.01 0 0"/></body>
      </body>
      <body name="plat" pos="0.35 0.02 0.07" quat="0.9 0.1 -0.3 0.2"><freejoint name="pf"/>
        {INERTIAL}<site name="ps" pos="0.05 0.01 0" euler="0.3 0 0"/>
        <body name="child" pos="0 0.1 0" axisangle="1 1 0 0.4"><joint name="c" type="ball"/>
          {INERTIAL}<site name="cs" pos="0 0 0.1"/></body>
      </body></worldbody>
      <equality><connect name="k" body1="arm_tip" body2="plat" anchor="0 0 0"/>
        <weld name="w" body1="child" body2="arm" anchor="0.1 0 0.02"/></equality></mujoco>""",
    # connect and weld (relpose given or not; to the world, named or not) on bodies
    # without joints
    "jointless": f"""<mujoco model="jointless"><compiler angle="radian"/><worldbody>
      <body name="ground" pos="0 0 0.1">
        <body name="crank"><joint name="crank" axis="0 1 0" stiffness="400"/>{INERTIAL}
          <body name="coupler" pos="0 0 0.12" euler="0 0.3 0">
            <joint name="coupler" axis="0 1 0"/>{INERTIAL}
            <body name="coupler_tip" pos="0.3 0 0.06" euler="0.2 0 0.1">
              <site name="P" pos="0 0 0.05"/></body></body></body>
        <body name="rocker" pos="0.34 0 0"><joint name="rocker" axis="0 1 0"/>{INERTIAL}
          <body name="rocker_tip" pos="-0.04 0 0.18" quat="0.8 0 0.6 0"/></body>
      </body></worldbody>
      <equality>
        <connect name="C" body1="coupler_tip" body2="rocker_tip" anchor="0.01 0.02 0.03"/>
        <weld name="W" body1="rocker_tip" body2="coupler_tip" anchor="0.1 0 0"/>
        <weld name="R" body1="coupler_tip" body2="rocker_tip" anchor="0.1 0 0.02"
              relpose="0.1 0 0 0.9 0.1 0.2 0.1"/>
        <connect name="G" body1="rocker_tip" anchor="0 0.01 0"/>
        <connect name="GC" body1="coupler" body2="world" anchor="0.02 0 0.03"/>
        <weld name="GW" body1="world" body2="coupler_tip" relpose="0.2 0 0.1 1 0 0 0"/>
        <connect name="off" body1="crank" body2="rocker" anchor="0 0 0" active="false"/>
      </equality></mujoco>""",
    # <default> classes: joint axis, pos, ref, stiffness, range; site pos and orientation
    "classes": f"""<mujoco model="classes"><compiler angle="radian"/>
      <default><joint axis="0 1 0" stiffness="10"/><site pos="0.01 0 0"/>
        <default class="a"><joint axis="1 0 0" pos="0 0 0.05" ref="0.3" springref="0.3"
            stiffness="20" range="-1 1"/><site euler="0 0 1.2" pos="0 0.02 0"/></default>
        <default class="b"><joint type="slide" axis="0 0 1" ref="0.01" springref="0.01"
            stiffness="3e4"/></default></default>
      <worldbody><body name="b1" pos="0 0 0.1"><joint name="j1"/>{INERTIAL}<site name="s1"/>
        <body name="b2" pos="0.2 0 0" childclass="a"><joint name="j2"/>{INERTIAL}
          <site name="s2"/><site name="s3" class="main" quat="0 1 0 0"/>
          <body name="b3" pos="0.1 0 0"><joint name="j3" class="b"/>{INERTIAL}
            <site name="s4" axisangle="0 0 1 0.5"/></body></body></body>
      </worldbody></mujoco>""",
    # axisangle axes that are not unit vectors (bodies, sites, hinge axes), in degrees
    "axisangle": f"""<mujoco model="axisangle"><compiler angle="degree"/><worldbody>
      <body name="b1" pos="0 0 0.1" axisangle="0 0 2 30"><joint name="j1" axis="0 2 0"/>
        {INERTIAL}<site name="s1" axisangle="3 0 0 20" pos="0.1 0 0"/>
        <body name="b2" pos="0.2 0 0" axisangle="1 1 1 45">
          <joint name="j2" axis="1 0 1" ref="10"/>{INERTIAL}<site name="s2" pos="0 0 0.1"/>
        </body></body></worldbody></mujoco>""",
    # euler angles in another (intrinsic) sequence, in degrees; xyaxes and zaxis
    "orientations": f"""<mujoco model="orientations">
      <compiler angle="degree" eulerseq="zyx"/><worldbody>
      <body name="b1" pos="0 0.1 0" euler="30 -20 10"><joint name="j1" axis="1 0 0"/>
        {INERTIAL}<site name="s1" pos="0.1 0 0" euler="5 60 -15"/>
        <body name="b2" pos="0 0 0.1" xyaxes="0 1 0 -1 0 1"><joint name="j2" axis="0 0 1"/>
          {INERTIAL}<site name="s2" pos="0.12 0 0" zaxis="1 1 0"/>
          <body name="b3" pos="0.2 0 0" zaxis="0 1 1"><joint name="j3" axis="1 0 0"/>
            {INERTIAL}<site name="s3" pos="0 0 0.1" xyaxes="1 0 0 0 0 1"/></body></body></body>
      </worldbody></mujoco>""",
    # ranges: hinge ranges in degrees and shifted by ref, a slide's in metres, limited="false"
    "ranges": f"""<mujoco model="ranges"><compiler angle="degree" autolimits="true"/><worldbody>
      <body name="b1"><joint name="h" axis="0 0 1" ref="20" range="-30 60"/>{INERTIAL}
        <body name="b2" pos="0.1 0 0">
          <joint name="s" type="slide" axis="1 0 0" ref="0.005" range="-0.01 0.02"/>{INERTIAL}
          <body name="b3" pos="0.1 0 0">
            <joint name="u" axis="0 1 0" range="-10 10" limited="false"/>{INERTIAL}
            <body name="b4" pos="0.1 0 0"><joint name="v" axis="0 1 0" limited="true"
                range="-5 5"/>{INERTIAL}</body></body></body></body>
      </worldbody></mujoco>""",
    # several joints in one body (a composite joint in Pinocchio), away from its origin
    "composite": f"""<mujoco model="composite"><compiler angle="radian"/><worldbody>
      <body name="a" pos="0 0 0.1" euler="0.1 0.2 0"><joint name="h1" pos="0.02 0 0"/>
        <joint name="h2" axis="0 1 0" pos="0 0 0.03" ref="0.2"/>
        <joint name="s" type="slide" axis="1 1 0"/>{INERTIAL}<site name="sa" pos="0.1 0 0"/>
        <body name="b" pos="0.2 0 0"><joint name="b1" axis="1 0 0"/>{INERTIAL}
          <site name="sb" pos="0 0.1 0"/></body></body>
      </worldbody></mujoco>""",
    # a lone root body without joint, rotated, with sites; a hinge away from its body origin
    "lone_root": f"""<mujoco model="lone_root"><compiler angle="radian"/><worldbody>
      <site name="w1" pos="0.1 0.2 0.3" euler="0.1 0 0"/>
      <body name="base" pos="0.1 0 0.2" quat="0.9 0 0 0.3"><site name="bs" pos="0 0.05 0"/>
        <body name="l1" pos="0.1 0 0">
          <joint name="j1" axis="0 0 1" stiffness="5" pos="0.02 0 0"/>{INERTIAL}
          <site name="t1" pos="0.2 0 0"/>
          <body name="l2" pos="0.2 0 0"><joint name="j2" axis="0 1 0" stiffness="7"/>
            {INERTIAL}</body></body></body>
      </worldbody></mujoco>""",
    # geoms in a rotated <frame> of a body without <inertial> (Pinocchio dropped them)
    "frame_geoms": """<mujoco model="frame_geoms"><compiler angle="radian"/><worldbody>
      <body name="a" pos="0 0 0.1"><joint name="j1" axis="0 1 0"/>
        <geom type="box" size="0.05 0.02 0.01" pos="0.05 0 0"/>
        <frame pos="0.1 0.02 0" euler="0 0 0.5"><geom type="sphere" size="0.03" pos="0.02 0 0"/>
          <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/></frame>
      </body></worldbody></mujoco>""",
    # <frame> elements (rotated, nested; euler, xyaxes, zaxis, a childclass) holding geoms
    # (fromto and placed, in a body without <inertial>), sites, a joint, a body; a frame in
    # the worldbody holding a site and a root body
    "frames": """<mujoco model="frames"><compiler angle="degree" eulerseq="zyx"/>
      <default><default class="f"><geom type="box" size="0.02 0.01 0.01" pos="0.01 0 0"/>
        <site pos="0 0.01 0"/></default></default><worldbody>
      <frame pos="0.05 0 0" euler="10 0 0"><site name="w" pos="0 0 0.1"/>
        <body name="r" pos="0 0.2 0"><joint name="jr" axis="1 0 0"/>
          <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/></body></frame>
      <body name="a" pos="0 0 0.1"><joint name="j1" axis="0 1 0"/>
        <geom type="box" size="0.05 0.02 0.01" pos="0.05 0 0"/>
        <frame pos="0.1 0.02 0" euler="30 10 -20">
          <geom type="sphere" size="0.03" pos="0.02 0 0" density="2000"/>
          <geom type="capsule" fromto="0 0 0 0.1 0 0.02" size="0.01"/>
          <site name="s1" pos="0.05 0 0" axisangle="1 0 0 30"/>
          <frame pos="0 0.05 0" xyaxes="0 1 0 -1 0 0.5" childclass="f">
            <geom/><geom type="cylinder" size="0.01 0.03" zaxis="1 1 0" mass="0.2"/>
            <site name="s2"/></frame></frame>
        <frame pos="0.3 0 0" zaxis="0 1 1">
          <body name="b" pos="0.02 0 0" euler="0 20 0">
            <geom type="ellipsoid" size="0.01 0.02 0.03" pos="0.03 0 0"/>
            <frame quat="0.9 0.1 0 0.3"><joint name="j2" pos="0.01 0 0" axis="1 0 0"/></frame>
            <site name="s3" pos="0.05 0 0"/></body></frame>
      </body></worldbody></mujoco>""",
    # bodies without <inertial> (masses from geoms: <default> classes, mass or density,
    # fromto capsules and cylinders, a zero density) and with one too; the compiler's
    # inertiafromgeom MuJoCo's default (auto: the <inertial> wins), true (the geoms win)
    # and false (the <inertial> only)
    **{
        f"geom_masses_{setting}": f"""<mujoco model="geom_masses">
      <compiler angle="radian" inertiafromgeom="{setting}"/>
      <default><geom type="box" size="0.02 0.02 0.02" density="500"/>
        <default class="heavy"><geom type="sphere" size="0.03" mass="2" pos="0.1 0 0"/>
        </default></default><worldbody>
      <body name="a" pos="0 0 0.1"><joint name="j1" axis="0 1 0"/>
        <inertial pos="0.1 0 0" mass="0.5" diaginertia="1e-3 2e-3 2.5e-3"/>
        <geom pos="0.05 0 0"/><geom class="heavy"/>
        <body name="b" pos="0.2 0 0" childclass="heavy"><joint name="j2" axis="0 1 0"/>
          {INERTIAL if setting == "false" else ""}<geom/>
          <geom type="cylinder" size="0.01 0.05" euler="0.3 0 0" pos="0 0 0.05"/>
          <body name="c" pos="0.2 0 0"><joint name="j3" axis="1 0 0"/>
            {INERTIAL if setting == "false" else ""}
            <geom type="capsule" fromto="0 0 0 0.2 0.05 0" size="0.01" class="main"/>
            <geom type="cylinder" fromto="0 0 0 0 0 0.1" size="0.02" mass="0.3" class="main"/>
            <geom type="box" size="0.01 0.01 0.01" density="0" class="main"/>
          </body></body>
      </body></worldbody></mujoco>"""
        for setting in ("auto", "true", "false")
    },
}


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """{name: path} of the bundled MJCF models and the small files."""
    folder = tmp_path_factory.mktemp("mjcf")
    paths = {name: REPO / "urdf" / f"{name}.xml" for name in BUNDLED}
    for name, text in FILES.items():
        paths[name] = folder / f"{name}.xml"
        paths[name].write_text(text)
    return paths


def both(path: Path):
    """(MjModel, MjData, the library's model) of one file."""
    m, d = compiled(path)
    return m, d, load_model(path, geometry=False)


def configurations(m, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [m.qpos0.copy()] + [random_qpos(m, rng) for _ in range(N_RANDOM)]


@pytest.mark.parametrize("name", BUNDLED + tuple(FILES))
def test_bodies_and_sites_are_where_mujoco_puts_them(files, name):
    m, d, clm = both(files[name])
    for k, qpos in enumerate(configurations(m, seed=k_seed(name))):
        for what, (mj, lib) in placements(m, d, clm, qpos).items():
            np.testing.assert_allclose(
                lib, mj, rtol=0, atol=PLACEMENT_TOL, err_msg=f"{name}: {what}, configuration {k}"
            )


@pytest.mark.parametrize("name", BUNDLED + tuple(FILES))
def test_masses_and_inertias_are_mujocos(files, name):
    """Each moving joint carries MuJoCo's mass, centre of mass and rotational inertia of
    its bodies (:func:`mujoco_peer.joint_inertias`): given by ``<inertial>``, or by the
    geoms (those in a ``<frame>`` too), as the compiler's ``inertiafromgeom`` says."""
    m, _, clm = both(files[name])
    expected = joint_inertias(m, clm)
    assert sorted(expected) == list(range(1, clm.model.njoints)), name
    for j, Y in expected.items():
        lib, what = clm.model.inertias[j], f"{name}: joint {clm.model.names[j]}"
        np.testing.assert_allclose(lib.mass, Y.mass, rtol=MASS_RTOL, err_msg=what)
        np.testing.assert_allclose(lib.lever, Y.lever, rtol=0, atol=PLACEMENT_TOL, err_msg=what)
        scale = np.abs(Y.inertia).max()
        np.testing.assert_allclose(
            lib.inertia, Y.inertia, rtol=0, atol=MASS_RTOL * scale, err_msg=what
        )


@pytest.mark.parametrize("name", [*BUNDLED, "frame_geoms", "frames", "geom_masses_auto"])
def test_visual_geoms_are_where_mujoco_puts_them(files, name):
    """The library's visual geoms are MuJoCo's geoms (those in a ``<frame>`` too), in
    MuJoCo's order, where MuJoCo puts them (``geom_xpos``) and turned as MuJoCo
    turns them (``geom_xmat``), up to the shape's symmetries (Pinocchio turns a ``fromto``
    capsule or cylinder end for end): R diag(e^2) R^T agree, e the half-extents along the
    geom's axes, at qpos0 and elsewhere."""
    m, d = compiled(files[name])
    clm = load_model(files[name])
    assert len(clm.visual_model.geometryObjects) == m.ngeom, name
    data, geom_data = clm.model.createData(), pin.GeometryData(clm.visual_model)
    for k, qpos in enumerate(configurations(m, seed=k_seed(name))):
        d.qpos[:] = qpos
        mujoco().mj_kinematics(m, d)
        q = to_q(m, clm, qpos)
        pin.updateGeometryPlacements(clm.model, data, clm.visual_model, geom_data, q)
        for g in range(m.ngeom):
            lib, what = geom_data.oMg[g], f"{name}: geom {g}, configuration {k}"
            R, extents = d.geom_xmat[g].reshape(3, 3), np.diag(half_extents(m, g) ** 2)
            np.testing.assert_allclose(
                lib.translation, d.geom_xpos[g], rtol=0, atol=PLACEMENT_TOL, err_msg=what
            )
            np.testing.assert_allclose(
                lib.rotation @ extents @ lib.rotation.T,
                R @ extents @ R.T,
                rtol=0,
                atol=PLACEMENT_TOL,
                err_msg=what,
            )


def half_extents(m, g: int) -> np.ndarray:
    """Half-extents (3,) [m] of MuJoCo's geom ``g`` along its axes (``geom_size``: a
    sphere's radius; a capsule's or cylinder's radius and half-length along z)."""
    kinds, size = mujoco().mjtGeom, m.geom_size[g]
    kind = int(m.geom_type[g])
    if kind == int(kinds.mjGEOM_SPHERE):
        return np.full(3, size[0])
    if kind in (int(kinds.mjGEOM_CAPSULE), int(kinds.mjGEOM_CYLINDER)):
        return np.array([size[0], size[0], size[1]])
    return size.copy()  # box, ellipsoid


@pytest.mark.parametrize("name", [*BUNDLED, "free", "jointless"])
def test_closure_anchors_are_mujocos(files, name):
    """Each active equality's two ends (a connect's points, a weld's frames) in the world
    equal the library's closure anchors: at qpos0, where they coincide, and elsewhere."""
    m, d, clm = both(files[name])
    active = [e for e in range(m.neq) if m.eq_active0[e]]
    assert sorted(closure_name(m, e) for e in active) == sorted(c.name for c in clm.closures)
    for k, qpos in enumerate(configurations(m, seed=k_seed(name))):
        d.qpos[:] = qpos
        mujoco().mj_kinematics(m, d)
        q = to_q(m, clm, qpos)
        for e in active:
            ends, lib = equality_ends(m, d, e), library_ends(clm, closure_name(m, e), q)
            point = m.eq_type[e] == mujoco().mjtEq.mjEQ_CONNECT
            for i, (E, L) in enumerate(zip(ends, lib, strict=True)):
                np.testing.assert_allclose(
                    L[:3, 3] if point else L,
                    E[:3, 3] if point else E,
                    rtol=0,
                    atol=PLACEMENT_TOL,
                    err_msg=f"{name}: end {i + 1} of {closure_name(m, e)}, configuration {k}",
                )


def test_equality_ends_are_mujocos_constraint(files):
    """The reading of ``eq_data`` in :func:`mujoco_peer.equality_ends` is MuJoCo's: the
    ends' position difference is MuJoCo's residual ``efc_pos`` of the equality, and for a
    weld its rotation rows are the vector part of the quaternion of R1^T R2 (up to the
    quaternion's sign; ``torquescale`` 1)."""
    mj = mujoco()
    m, d = compiled(files["jointless"])
    d.qpos[:] = random_qpos(m, np.random.default_rng(3))
    mj.mj_forward(m, d)
    row = 0
    for e in (e for e in range(m.neq) if m.eq_active0[e]):
        (E1, E2), n = equality_ends(m, d, e), 3 if m.eq_type[e] == mj.mjtEq.mjEQ_CONNECT else 6
        residual = d.efc_pos[row : row + n]
        row += n
        np.testing.assert_allclose(residual[:3], E1[:3, 3] - E2[:3, 3], atol=PLACEMENT_TOL)
        if n == 6:
            half = Rotation.from_matrix(E1[:3, :3].T @ E2[:3, :3]).as_quat()[:3]  # x y z
            sign = np.sign(residual[3:] @ half)
            np.testing.assert_allclose(residual[3:], sign * half, atol=PLACEMENT_TOL)
    assert row == d.ne


@pytest.mark.parametrize("name", BUNDLED + tuple(FILES))
def test_springs_are_mujocos_at_rest_at_qpos0(files, name):
    """The springs the library reads are MuJoCo's ``jnt_stiffness`` (one per joint here),
    and MuJoCo's hinge and slide springs are at rest at ``qpos0`` (``qpos_spring``), where
    the library takes them at rest."""
    m, _, clm = both(files[name])
    mujocos = {m.joint(j).name: float(m.jnt_stiffness[j]) for j in range(m.njnt)}
    assert dict(clm.springs) == {n: k for n, k in mujocos.items() if k > 0}
    for j, (_, v) in enumerate(coordinates(m, clm)):
        nv = (m.jnt_dofadr[j + 1] if j + 1 < m.njnt else m.nv) - m.jnt_dofadr[j]
        np.testing.assert_array_equal(clm.stiffness[v : v + nv], m.jnt_stiffness[j])
        if m.jnt_stiffness[j] and one_dof(m, j):
            a = m.jnt_qposadr[j]
            assert m.qpos_spring[a] == m.qpos0[a], f"{name}: spring of {m.joint(j).name}"


@pytest.mark.parametrize("name", BUNDLED + tuple(FILES))
def test_limits_are_mujocos(files, name):
    """A limited hinge or slide has MuJoCo's ``jnt_range`` (radians, metres); an unlimited
    one none."""
    m, _, clm = both(files[name])
    for j, (i, _) in enumerate(coordinates(m, clm)):
        if not one_dof(m, j):
            continue
        lib = clm.model.lowerPositionLimit[i], clm.model.upperPositionLimit[i]
        expected = m.jnt_range[j] if m.jnt_limited[j] else (-np.inf, np.inf)
        np.testing.assert_allclose(lib, expected, rtol=1e-15, err_msg=f"{m.joint(j).name}")


def k_seed(name: str) -> int:
    """A fixed seed per file (the random configurations differ between files)."""
    return sum(map(ord, name))

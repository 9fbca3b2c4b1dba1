"""Shared test helpers: the scaled comparison, the balance check, small test mechanisms.

A plain module, not a test module (pytest puts ``tests/`` on ``sys.path``): test modules
import from here and from :mod:`mechanisms`, never from one another. Fixtures that
several modules use are in ``conftest.py``.
"""

from __future__ import annotations

import base64
import ctypes
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
import umsgpack

from closedloop.kinematics.assembly import assemble, close_at
from closedloop.kinematics.constraints import closure_jacobian, closure_residual, frame_jacobian
from closedloop.model.closed_loop import ClosedLoopModel, Closure

REPO = Path(__file__).resolve().parent.parent
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: Headless Chromium with software WebGL and no background traffic (closed network).
FLAGS = (
    "--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--disable-gpu", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--window-size=800,600", "--remote-debugging-port=0", "--remote-allow-origins=*",
)  # fmt: skip


def browser() -> str:
    """The path of a Chromium on PATH; without one, the calling test is skipped, saying so."""
    for name in BROWSERS:
        if path := shutil.which(name):
            return path
    pytest.skip(
        f"real-browser tests skipped: no Chromium on PATH (looked for {', '.join(BROWSERS)}); "
        "install the Debian package 'chromium' to run them"
    )


async def devtools_page(proc: subprocess.Popen, profile: Path, deadline: float):
    """The DevTools websocket of the one page of a Chromium started by ``proc`` with
    ``--user-data-dir=profile`` and a DevTools port of its choosing (:data:`FLAGS`), once it
    has written that port; ``deadline``: a ``time.monotonic()`` instant."""
    import asyncio
    import json
    import time
    import urllib.request

    from tornado.websocket import websocket_connect

    port_file = profile / "DevToolsActivePort"
    while not (port_file.is_file() and port_file.read_text().strip()):
        assert proc.poll() is None, f"Chromium exited with code {proc.returncode}"
        assert time.monotonic() < deadline, "Chromium did not open its DevTools port"
        await asyncio.sleep(0.05)
    port = int(port_file.read_text().split()[0])
    direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    with direct.open(f"http://127.0.0.1:{port}/json/list", timeout=10) as f:
        (page,) = [t for t in json.load(f) if t["type"] == "page"]
    return await websocket_connect(page["webSocketDebuggerUrl"], max_message_size=1 << 28)


def devtools_caller(ws, on_event):
    """``call(method, **params)``, an async DevTools command over the websocket ``ws``:
    it returns the command's reply and hands every other message (events) to
    ``on_event(message)`` as they come."""
    import json

    ids = iter(range(1, 1 << 30))

    async def call(method: str, **params) -> dict:
        n = next(ids)
        await ws.write_message(json.dumps({"id": n, "method": method, "params": params}))
        while True:
            message = json.loads(await ws.read_message())
            if message.get("id") == n:
                return message
            on_event(message)

    return call


#: The per-point indices of a map (closedloop.analysis.batch_indices.batch_indices names) as a
#: single query's StiffnessIndices gives them.
INDEX_GETTERS = {
    "det_K": lambda s: s.determinant,
    "condition_number": lambda s: s.scaled_condition_number,
    "condition_number_si": lambda s: s.condition_number,
    "min_translational": lambda s: s.min_translational_stiffness.value,
    "max_translational": lambda s: s.max_translational_stiffness.value,
    "min_rotational": lambda s: s.min_rotational_stiffness.value,
    "max_rotational": lambda s: s.max_rotational_stiffness.value,
}

UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: The documented UR5 example configuration [rad].
UR5_Q = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])

#: The UR5's links as beams: link -> the joint its beam ends at.
UR5_BEAM_ENDS = {
    "shoulder_link": "shoulder_lift_joint",
    "upper_arm_link": "elbow_joint",
    "forearm_link": "wrist_1_joint",
    "wrist_1_link": "wrist_2_joint",
    "wrist_2_link": "wrist_3_joint",
    "wrist_3_link": "ee_fixed_joint",
}

#: CaHyMan's leg frames, written from the model document (not from cahyman_pin.geometry):
#: delta_k = 0, 120, 240 deg, radial u_k (x towards leg 1) and tangential t_k = z x u_k,
#: one leg per row; ball k sits at r_p u_k in the plate frame, leg base O_k at r_e u_k.
SQ3 = np.sqrt(3.0)
LEG_U = np.array([[1.0, 0.0, 0.0], [-0.5, SQ3 / 2, 0.0], [-0.5, -SQ3 / 2, 0.0]])
LEG_T = np.array([[0.0, 1.0, 0.0], [-SQ3 / 2, -0.5, 0.0], [SQ3 / 2, -0.5, 0.0]])


def opensees():
    """openseespy's module, its bundled BLAS, LAPACK and Fortran runtime loaded first (the
    wheel's extension finds them only so); the calling test skipped, saying how to install
    it, without openseespy."""
    spec = importlib.util.find_spec("openseespylinux")
    if spec is None:
        pytest.skip("openseespy is not installed (pip install '.[test]')")
    lib = Path(spec.origin).parent / "lib"
    for name in ("libquadmath.so.0", "libgfortran.so.4", "libgomp.so.1", "libblas.so.3",
                 "liblapack.so.3"):  # fmt: skip
        ctypes.CDLL(str(lib / name), mode=ctypes.RTLD_GLOBAL)
    import openseespy.opensees as ops

    return ops


def rot_y(angle: float) -> np.ndarray:
    """(3, 3) rotation about y by ``angle`` [rad], written out."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


# Unbalanced virtual work on the admissible motions, relative to the applied generalised
# load max|J^T w|: the solver stops at 1e-11 of its largest generalised force (spring or
# load, here at most 1.3 max|J^T w|): measured 1e-16 to 1.3e-11. The iterate one Newton
# step before the solver's last leaves 1.7e-10 (30 N on the four-bar) to 1e-2: a solver
# stopping one step early fails every test that checks the balance.
RTOL_BALANCE = 1e-10
# Closure residual of an equilibrium [m, rad]: the solver's tolerance CLOSURE_TOL.
ATOL_CLOSURE = 1e-12


# ---------------------------------------------------------------------------- assertions
class Calls:
    """Counts the calls of a function patched into a module (pytest's monkeypatch)."""

    def __init__(self, monkeypatch, owner, name):
        self.n, original = 0, getattr(owner, name)

        def counted(*args, **kwargs):
            self.n += 1
            return original(*args, **kwargs)

        monkeypatch.setattr(owner, name, counted)


def assert_close_in_norm(actual, desired, rtol, scale=None) -> None:
    """Entries agree to rtol of themselves, with an absolute floor rtol * max|desired|.

    The one scaled comparison of the tests: near-zero (or exactly zero) entries of a
    matrix or vector are compared to rtol times its largest entry. With ``scale`` (n,),
    square matrices are compared as S A S, S = diag(scale): entries of mixed units (a
    compliance's rotation rows times a length [m], say) then weigh alike.
    """
    actual, desired = np.asarray(actual, dtype=float), np.asarray(desired, dtype=float)
    if scale is not None:
        s = np.outer(scale, scale)
        actual, desired = actual * s, desired * s
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=rtol * np.abs(desired).max())


def assert_balanced(clm: ClosedLoopModel, eq) -> None:
    """The equilibrium closes the loops and balances the virtual work, relative to the load.

    Independent of the solver's equations: N spans the tangent motions that keep
    Pinocchio's anchor closures (``closure_jacobian``) and the locked joints (scipy's null
    space); on them the spring forces g = Jd^T K dq balance the generalised load J^T w to
    :data:`RTOL_BALANCE` times max |J^T w|.
    """
    m, q, q0 = clm.model, eq.q, eq.q_rest
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    g = pin.dDifference(m, q0, q, pin.ARG1).T @ (k * pin.difference(m, q0, q))
    load = frame_jacobian(clm, q, eq.frame).T @ eq.wrench
    locked = np.eye(m.nv)[np.isinf(clm.stiffness)]
    N = scipy.linalg.null_space(np.vstack([closure_jacobian(clm, q), locked]))
    assert np.abs(closure_residual(clm, q)).max(initial=0.0) <= ATOL_CLOSURE
    unbalanced = np.abs(N.T @ (g - load)).max()
    assert unbalanced <= RTOL_BALANCE * np.abs(load).max(), (unbalanced, np.abs(load).max())


# ---------------------------------------------------------------------------- kinematics
def frame_placement(clm: ClosedLoopModel, q, frame: str) -> pin.SE3:
    """World placement of ``frame`` at q (a copy), from Pinocchio's forward kinematics."""
    d = clm.model.createData()
    pin.framesForwardKinematics(clm.model, d, q)
    return d.oMf[clm.frame_id(frame)].copy()


def rigid_link_poses(model: pin.Model, q, dq, a: float, step: float = 1e-6) -> np.ndarray:
    """(njoints, 4, 4) joint placements with each joint body moved rigidly by exp6(a xi_j),
    xi_j its world-frame twist under dq from central differences of the forward kinematics
    (log6 of the body's motion along q + t dq, t = +-step / max|dq|): the viewer's drawing
    (:mod:`closedloop.viewer.motion`) along a route of its own. Truncation ~ step^2 and
    rounding ~ 1e-16 / step, relative to the twist."""
    data = model.createData()
    dq = np.asarray(dq, dtype=float)
    t = step / max(float(np.max(np.abs(dq))), 1e-300)

    def placements(eps):
        pin.forwardKinematics(model, data, pin.integrate(model, q, eps * dq))
        return [m.copy() for m in data.oMi]

    nominal, plus, minus = placements(0.0), placements(t), placements(-t)
    out = []
    for M0, Mp, Mm in zip(nominal, plus, minus, strict=True):
        xi = (pin.log6(Mp * M0.inverse()).vector - pin.log6(Mm * M0.inverse()).vector) / (2 * t)
        out.append((pin.exp6(a * xi) * M0).homogeneous)
    return np.array(out)


# ---------------------------------------------------------------------------- mechanisms
def _z_to(a: np.ndarray) -> np.ndarray:
    """Rotation matrix taking the z axis to the unit vector a."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, a)
    return pin.exp3(v / np.linalg.norm(v) * np.arctan2(np.linalg.norm(v), z @ a))


def spherical_fourbar(springs=(300.0, 200.0, 800.0)) -> tuple[ClosedLoopModel, np.ndarray]:
    """Spherical four-bar: four revolute axes through the origin, closed by a 3D point.

    Every point of the mechanism stays on its sphere about the origin, so the point
    closure has 3 rows of rank 2 (a redundant spatial closure). Assembled by construction
    at q = 0, then solved at crank = 0.4 rad in one step. Returns the model (springs on the
    crank, the coupler and the rocker [N m/rad]) and the assembled configuration.
    """
    a2, a3, a4 = (np.array(v) / np.linalg.norm(v) for v in ([0.6, 0, 0.8], [5, 6, 6], [-2, 7, 7]))
    m = pin.Model()  # crank axis: z
    m.name = "spherical_fourbar"
    crank = m.addJoint(0, pin.JointModelRZ(), pin.SE3(np.eye(3), np.zeros(3)), "crank")
    coupler = m.addJoint(crank, pin.JointModelRZ(), pin.SE3(_z_to(a2), np.zeros(3)), "coupler")
    rocker = m.addJoint(0, pin.JointModelRZ(), pin.SE3(_z_to(a4), np.zeros(3)), "rocker")
    for j, R, name in ((coupler, _z_to(a2), "C_coupler"), (rocker, _z_to(a4), "C_rocker")):
        m.addFrame(pin.Frame(name, j, pin.SE3(np.eye(3), R.T @ (0.2 * a3)), pin.OP_FRAME))
        m.appendBodyToJoint(j, pin.Inertia.FromSphere(0.1, 0.01), pin.SE3.Identity())
    tool = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.5])), np.array([0.09, 0.06, 0.1]))
    m.addFrame(pin.Frame("tool", coupler, tool, pin.OP_FRAME))
    fa, fb = m.frames[m.getFrameId("C_coupler")], m.frames[m.getFrameId("C_rocker")]
    closure = pin.PointAnchorConstraintModel(
        m, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    clm = ClosedLoopModel(m, [Closure(closure, "C")], actuated=["crank"], springs={"crank": 1.0})
    q0 = one_solve(clm, [0.4], np.zeros(3))  # the configuration the invariance tests were
    # set on (driven in steps, it differs by rounding: test_invariances' 64 eps is that tight)
    k = dict(zip(("crank", "coupler", "rocker"), springs, strict=True))
    return clm.with_springs(k), q0


def welded_fourbar(fourbar_clm, q0) -> ClosedLoopModel:
    """The four-bar with its point closure replaced by a weld (6 rows of rank 3).

    The weld placement on the rocker side is that of the coupler-side frame at q0, so q0
    stays assembled; the coupler is then rigidly fixed to the rocker (a triangle).
    """
    m, d = fourbar_clm.model, fourbar_clm.model.createData()
    pin.framesForwardKinematics(m, d, q0)
    fa = m.frames[m.getFrameId("closedloop1_A")]
    fb = m.frames[m.getFrameId("closedloop1_B")]
    placement_b = d.oMi[fb.parentJoint].inverse() * d.oMf[m.getFrameId("closedloop1_A")]
    weld = pin.FrameAnchorConstraintModel(
        m, fa.parentJoint, fa.placement, fb.parentJoint, placement_b
    )
    springs = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    return ClosedLoopModel(m, [Closure(weld, "weld")], ["crank"], springs, name="welded")


def pendulum(k: float = 40.0, length: float = 0.5) -> ClosedLoopModel:
    """A hinge about y with a spring k [N m/rad] and a frame 'tip' at (0, 0, L) on it.

    The hinge sits on a locked prismatic joint (a support along z), which also keeps
    nv = 2 (with nv = 1 Pinocchio returns Jacobians as 1-D arrays).
    """
    m = pin.Model()
    support = m.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "support")
    j = m.addJoint(support, pin.JointModelRY(), pin.SE3.Identity(), "hinge")
    m.addFrame(pin.Frame("tip", j, pin.SE3(np.eye(3), np.array([0, 0, length])), pin.OP_FRAME))
    return ClosedLoopModel(
        m, actuated=["hinge"], springs={"hinge": k}, locked=["support"], name="pendulum"
    )


# ---------------------------------------------------------------------------- command lines
def one_error_line(err: str, prog: str = "closedloop") -> str:
    """The single line of ``err`` (a command's stderr), checked to be an error line without
    a traceback or a warning."""
    assert "Traceback" not in err and "Warning" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error: "), err
    return lines[0]


def closed_pipe_run(module: str, *argv) -> subprocess.CompletedProcess:
    """``python -m MODULE ARGV`` with stdout a pipe whose reader has already gone (``| head``
    that stopped before the first line); stderr captured as text."""
    read, write = os.pipe()
    os.close(read)
    try:
        return subprocess.run(
            [sys.executable, "-m", module, *map(str, argv)],
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(REPO)},
            timeout=120,
            check=False,
        )
    finally:
        os.close(write)


def map_argv(prog: str, n: int) -> list[str]:
    """``python -m`` arguments of an n x n map: ``closedloop map`` of the delta robot over
    two arms (the third at 0), ``cahyman map`` over alpha_1 and alpha_2."""
    if prog == "closedloop":
        return ["-m", "closedloop", "map", str(REPO / "urdf/delta.urdf"), "--closures",
                str(REPO / "urdf/delta.yaml"), "--frame", "platform", "--sweep",
                f"arm0=-0.3:0.3:{n}", "--sweep", f"arm1=-0.3:0.3:{n}", "--fixed",
                "arm2=0"]  # fmt: skip
    return ["-m", "cahyman_pin", "map", "--alpha1", f"30:90:{n}", "--alpha2", f"30:90:{n}"]


def default_sigint() -> None:
    """In a child process before it runs: SIGINT as a terminal's (a background shell may
    have ignored it)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def one_solve(clm: ClosedLoopModel, actuated, q0=None) -> np.ndarray:
    """(nq,) the loops closed in one solve from q0 (default: neutral) with the actuated
    values written, without driving them there: what ``cl.assemble`` did before it drove
    from the reference configuration (#45); far from q0 it may land on another mode (the
    bundled four-bar from neutral at crank 1.0 rad: its rocker at -3.17 rad)."""
    start = pin.neutral(clm.model) if q0 is None else np.asarray(q0, dtype=float)
    return np.array(close_at(clm, start, np.asarray(actuated, dtype=float)).q)


def driven(clm: ClosedLoopModel, inputs, step: float = 0.01) -> list[np.ndarray]:
    """Configurations (nq,) of a one-input mechanism driven from its reference
    configuration (the start of every assembly: ``ClosedLoopModel.reference_configuration``)
    through the input values ``inputs`` [rad, m] in order, by steps of at most ``step``,
    each assembled from the last: the assembly mode a robot driven there is on."""
    q, out = clm.reference_configuration(), []
    value = float(clm.actuated_values(q)[0])
    for target in inputs:
        for v in np.linspace(value, target, 2 + int(abs(target - value) / step)):
            q = assemble(clm, [v], q).q
        out.append(q)
        value = target
    return out


def tangent_differences(model, fun, q, h=1e-6):
    """(n, nv) central differences of fun (n,) along pin.integrate(q, h e_b): the tests'
    own, independent of the library's closedloop.common.derivatives."""
    cols = []
    for b in range(model.nv):
        e = np.zeros(model.nv)
        e[b] = h
        cols.append((fun(pin.integrate(model, q, e)) - fun(pin.integrate(model, q, -e))) / (2 * h))
    return np.array(cols).T


# ---------------------------------------------------------------------------- viewer pages
#: A meshcat command in a static page: a base64 msgpack blob.
BLOB = re.compile(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)")


def commands(html: str) -> list[dict]:
    """The meshcat commands embedded in a static page, in order."""
    return [umsgpack.unpackb(base64.b64decode(b)) for b in BLOB.findall(html)]


def robots_object(cmds: list[dict]) -> dict:
    """The three.js JSON of both robots (the one set_object at /meshcat/robots)."""
    (c,) = [c for c in cmds if c["type"] == "set_object" and c["path"] == "/meshcat/robots"]
    return c["object"]


def robot_groups(obj: dict, root: str) -> dict[str, dict]:
    """Group name -> group of one robot ('nominal' or 'deflected')."""
    (robot,) = [g for g in obj["object"]["children"] if g["name"] == root]
    return {g["name"]: g for g in robot["children"]}


def json_matrix(o: dict) -> np.ndarray:
    """(4, 4) matrix of a three.js object (column-major in its JSON)."""
    return np.array(o["matrix"], dtype=float).reshape(4, 4).T

"""Reading SDFormat robot files (the subset robot files use) into a model with closures.

Used when Pinocchio has no SDFormat support (``pin.WITH_SDFORMAT`` False, as in the PyPI
wheel). Read: one ``<model>`` of ``<link>``, ``<frame>`` and ``<joint>`` (revolute,
continuous, prismatic, ball, universal, fixed; ``<include>`` and nested models refused);
``<pose>`` (x y z roll pitch yaw, R = Rz Ry Rx; ``rotation_format="quat_xyzw"``,
``degrees="true"``) relative to ``relative_to`` (SDF >= 1.7) or ``frame`` (1.5/1.6), by
default a link's to the model, a joint's to its child link, a frame's to ``attached_to``;
``<axis><xyz>`` in the joint frame, or the model frame (``use_parent_model_frame``, SDF
<= 1.6; by default in SDF <= 1.4), or ``expressed_in`` a frame; ``<limit>`` (|value| >= 1e16: none);
``<dynamics><spring_stiffness>`` and ``<spring_reference>``; ``<inertial>``; ``<visual>``
mesh / box / cylinder / sphere, ``model://NAME/...`` found under the file's ancestors,
``$GZ_SIM_RESOURCE_PATH``, ``$SDF_PATH``, ``$GAZEBO_MODEL_PATH`` or example-robot-data.

A ``<frame>`` becomes a frame of the model (a loaded frame), fixed to the link it is
attached to: its ``attached_to`` link, the child link of its ``attached_to`` joint, the link
of its ``attached_to`` frame, or by default the canonical link (``canonical_link``, else the
first link).

Tree and loops: a link's tree joint is the first joint in file order naming it as child
(as in Pinocchio's parser); every later one closes a loop where the file draws it (the
joint frame is fixed to the child link; q = 0 is the drawing):

* ball: one point closure (3 rows) at the joint origin, every rotation free;
* revolute / continuous: two point closures, at the joint origin and a distance ``L``
  along the axis (``L``: the diameter of the link origins,
  :func:`closedloop.conditioning.characteristic_length`): 6 rows of rank 5, only the
  rotation about the axis free, rows in metres / ``L`` scaled like radians;
* fixed: a weld. A prismatic or universal joint, or one with a spring, cannot close one.

The root link (no joint names it as child) is fixed to the world at its pose, or carried
by a free flyer ``root_joint`` (``free_base``); a joint with parent ``world`` fixes its child.

Springs: ``spring_stiffness`` > 0 [N m/rad, N/m]. The model's springs are at rest at the
configuration analysed, so the rest configuration ``model.referenceConfigurations[REST]``
puts each spring joint at its ``spring_reference`` (others at the drawing, 0); assembly
from it keeps the springs at rest (:func:`closedloop.io.reference_configuration`).
"""

from __future__ import annotations

import math
import os
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .closures import Closure
from .conditioning import characteristic_length
from .data import robot_data_dir
from .exceptions import ModelFileError

#: Joint types read.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "ball", "universal", "fixed")
#: Name of the rest configuration (springs at their spring_reference) in the model.
REST = "spring_rest"
#: SDF writes "no limit" as +-1e16.
NO_LIMIT = 1e16
MODEL = "__model__"


@dataclass(frozen=True)
class SdfRobot:
    """What :func:`read_sdf` returns.

    Attributes:
        model: the kinematic tree; frames named after the links (BODY) and joints.
        closures: loop closures of the loop-closing joints (module docstring).
        springs: joint name -> stiffness [N m/rad or N/m] (one value, or one per coordinate).
        rest: (nq,) rest configuration (also ``model.referenceConfigurations[REST]``).
        visual: visual geometry, or None when not asked for.
        closing_joints: names of the joints that close loops, in file order.
    """

    model: pin.Model
    closures: list[Closure]
    springs: dict[str, float | list[float]]
    rest: np.ndarray
    visual: pin.GeometryModel | None
    closing_joints: tuple[str, ...]


class _Reader:
    def __init__(self, path: Path):
        self.path, self.where = path, f"SDF file {str(path)!r}"
        try:
            root = ET.parse(path).getroot()
        except (ET.ParseError, OSError) as e:
            raise ModelFileError(f"{self.where} is not valid XML: {e}") from None
        if root.tag != "sdf":
            self.fail(f"root element is <{root.tag}>; expected <sdf>")
        version = root.get("version") or "1.6"
        try:
            self.version = tuple(int(v) for v in version.split(".")[:2])
        except ValueError:
            self.fail(f"version {version!r}; expected numbers such as '1.6'")
        models = root.findall("model")
        if len(models) != 1 or root.find(".//include") is not None:
            self.fail(
                f"{len(models)} <model> element(s) or an <include>; expected one <model> "
                "with its links and joints written out"
            )
        self.elem = m = models[0]
        if m.find("model") is not None:
            self.fail("nested <model> elements are not supported; flatten the model")
        self.links = self.named(m, "link")
        self.joints = self.named(m, "joint")
        self.frames = self.named(m, "frame")
        canonical = m.get("canonical_link")
        if canonical is not None and canonical not in self.links:
            self.fail(f"canonical_link {canonical!r} is not a link; expected one of "
                      f"{list(self.links)}")  # fmt: skip
        self.poses: dict[str, pin.SE3] = {MODEL: pin.SE3.Identity()}

    def fail(self, message: str):
        raise ModelFileError(f"{self.where}: {message}")

    def named(self, parent: ET.Element, tag: str) -> dict[str, ET.Element]:
        out: dict[str, ET.Element] = {}
        for e in parent.findall(tag):
            name = e.get("name")
            if not name:
                self.fail(f"a <{tag}> has no name attribute")
            if (
                name in out
                or (tag != "link" and name in self.links)
                or (tag == "frame" and name in self.joints)
            ):
                self.fail(f"name {name!r} is used twice; expected unique names")
            out[name] = e
        return out

    def floats(self, elem: ET.Element | None, what: str, n: tuple[int, ...]) -> np.ndarray:
        text = (elem.text or "") if elem is not None else ""
        try:
            v = np.array([float(t) for t in text.split()])
        except ValueError:
            self.fail(f"{what} is {text.strip()!r}; expected {' or '.join(map(str, n))} numbers")
        if v.size not in n or not np.all(np.isfinite(v)):
            self.fail(
                f"{what} has {v.size} value(s) {text.strip()!r}; expected "
                f"{' or '.join(map(str, n))} finite numbers"
            )
        return v

    def number(self, elem: ET.Element, tag: str, default: float, what: str) -> float:
        child = elem.find(tag)
        return default if child is None else float(self.floats(child, f"{what} <{tag}>", (1,))[0])

    def local_pose(self, elem: ET.Element, what: str) -> tuple[pin.SE3, str | None]:
        """(pose, name of the frame it is relative to or None for the default)."""
        p = elem.find("pose")
        if p is None:
            return pin.SE3.Identity(), None
        ref = p.get("relative_to") or p.get("frame") or None
        if not (p.text or "").strip():  # <pose relative_to="b"/>: the identity (SDF 1.7)
            return pin.SE3.Identity(), ref
        quat = p.get("rotation_format") == "quat_xyzw"
        v = self.floats(p, f"pose of {what}", (7,) if quat else (6,))
        if quat:
            big = np.abs(v[3:]).max()
            if big == 0.0:
                self.fail(f"pose of {what} has the quaternion 0 0 0 0; expected a rotation")
            xyzw = v[3:] / big  # scaled first: its squared norm may underflow or overflow
            x, y, z, w = xyzw / np.linalg.norm(xyzw)
            R = pin.Quaternion(w, x, y, z).matrix()
        else:
            degrees = "degrees" in p.attrib and self.boolean(p.get("degrees"), "degrees")
            R = pin.rpy.rpyToMatrix(*(np.deg2rad(v[3:]) if degrees else v[3:]))
        return pin.SE3(R, v[:3]), ref

    def pose(self, name: str, chain: tuple[str, ...] = ()) -> pin.SE3:
        """Placement [m] of the link, joint or frame ``name`` in the model frame, at q = 0."""
        if name in self.poses:
            return self.poses[name]
        if name in chain:
            self.fail(f"poses relative to each other in a cycle: {' -> '.join((*chain, name))}")
        if name in self.links:
            local, ref = self.local_pose(self.links[name], f"link {name!r}")
            ref = ref or MODEL
        elif name in self.joints:
            local, ref = self.local_pose(self.joints[name], f"joint {name!r}")
            ref = ref or self.text(self.joints[name], "child", f"joint {name!r}")
        elif name in self.frames:
            local, ref = self.local_pose(self.frames[name], f"frame {name!r}")
            ref = ref or self.frames[name].get("attached_to") or MODEL
        else:
            self.fail(f"pose relative to unknown frame {name!r}; expected a link, joint or frame")
        self.poses[name] = pose = self.pose(ref, (*chain, name)) * local
        return pose

    def frame_link(self, name: str, chain: tuple[str, ...] = ()) -> str:
        """The link a ``<frame>`` is fixed to: its ``attached_to`` link, the child link of
        its ``attached_to`` joint, that of its ``attached_to`` frame, or by default the
        model frame's, the canonical link (``canonical_link``, else the first link)."""
        if name in chain:
            self.fail(f"frames attached to each other in a cycle: {' -> '.join((*chain, name))}")
        target = self.frames[name].get("attached_to") or MODEL
        if target == MODEL:
            return self.elem.get("canonical_link") or next(iter(self.links))
        if target in self.links:
            return target
        if target in self.joints:
            return self.text(self.joints[target], "child", f"joint {target!r}")
        if target in self.frames:
            return self.frame_link(target, (*chain, name))
        self.fail(
            f"frame {name!r} is attached to unknown {target!r}; expected a link, joint or frame"
        )

    def boolean(self, text: str | None, what: str) -> bool:
        """An SDF boolean: true/false or 1/0, any case (as libsdformat reads it)."""
        value = (text or "").strip().lower()
        if value not in ("true", "1", "false", "0"):
            self.fail(f"{what} is {text!r}; expected true or false (or 1 or 0)")
        return value in ("true", "1")

    def text(self, elem: ET.Element, tag: str, what: str) -> str:
        child = elem.find(tag)
        if child is None or not (child.text or "").strip():
            self.fail(f"{what} has no <{tag}>")
        return child.text.strip()

    def axis(self, name: str, tag: str = "axis") -> tuple[np.ndarray, ET.Element]:
        """(unit axis (3,) in the joint frame, the <axis> element)."""
        elem = self.joints[name].find(tag)
        what = f"<{tag}> of joint {name!r}"
        if elem is None:
            self.fail(f"joint {name!r} has no <{tag}>; expected <{tag}><xyz>x y z</xyz>")
        if elem.find("mimic") is not None:  # SDF 1.11
            self.fail(f"{what} has a <mimic>, which is not read (the joint would move freely); "
                      "expected no <mimic>")  # fmt: skip
        xyz = elem.find("xyz")
        a = self.floats(xyz, f"{what} <xyz>", (3,))
        if np.linalg.norm(a) == 0.0:
            self.fail(f"{what} is the zero vector; expected a direction")
        flag = elem.find("use_parent_model_frame")  # SDF <= 1.4: always the model frame
        use_model = self.version < (1, 5) if flag is None else self.boolean(flag.text, flag.tag)
        frame = xyz.get("expressed_in") or (MODEL if use_model and self.version < (1, 7) else "")
        if frame:
            R = self.pose(name).rotation.T @ self.pose(frame).rotation
            a = R @ a
        return a / np.linalg.norm(a), elem

    def limits(self, elem: ET.Element, what: str) -> tuple[float, float]:
        lim = elem.find("limit")
        if lim is None:
            return -math.inf, math.inf
        lo = self.number(lim, "lower", -NO_LIMIT, what)
        hi = self.number(lim, "upper", NO_LIMIT, what)
        lo, hi = (-math.inf if lo <= -NO_LIMIT else lo), (math.inf if hi >= NO_LIMIT else hi)
        if lo > hi:
            self.fail(f"{what} has lower limit {lo} > upper limit {hi}")
        return lo, hi

    def spring(self, elem: ET.Element, what: str) -> tuple[float, float]:
        """(stiffness >= 0, rest position) of an <axis>."""
        dyn = elem.find("dynamics")
        if dyn is None:
            return 0.0, 0.0
        k = self.number(dyn, "spring_stiffness", 0.0, what)
        if k < 0:
            self.fail(f"{what} has spring_stiffness {k}; expected a number >= 0 [N m/rad, N/m]")
        return k, self.number(dyn, "spring_reference", 0.0, what)

    def inertia(self, link: str) -> pin.Inertia:
        elem = self.links[link].find("inertial")
        if elem is None:
            return pin.Inertia(1.0, np.zeros(3), np.eye(3))  # SDF defaults
        what = f"inertial of link {link!r}"
        local, ref = self.local_pose(elem, what)
        if ref:
            local = self.pose(link).inverse() * self.pose(ref) * local
        i = elem.find("inertia")
        get = (lambda t, d: d) if i is None else (lambda t, d: self.number(i, t, d, what))
        upper = np.triu([[get(f"i{a}{b}", float(a == b)) for b in "xyz"] for a in "xyz"])
        inertia = upper + np.triu(upper, 1).T
        R, mass = local.rotation, self.number(elem, "mass", 1.0, what)
        try:
            return pin.Inertia(mass, local.translation, R @ inertia @ R.T)
        except (RuntimeError, ValueError) as e:  # not positive
            self.fail(f"{what} is not a valid inertia ({e}); expected a positive inertia matrix")


def _joint_model(r: _Reader, name: str, kind: str):
    """(Pinocchio joint model, spring stiffness per coordinate, rest per q, limits)."""
    if kind == "ball":
        return pin.JointModelSpherical(), None, None, None
    if kind == "universal":
        (a1, e1), (a2, e2) = r.axis(name), r.axis(name, "axis2")
        if abs(a1 @ a2) > 1e-9:
            r.fail(f"universal joint {name!r} has axes {a1} and {a2}; expected orthogonal axes")
        springs = [r.spring(e, f"joint {name!r}") for e in (e1, e2)]
        limits = [r.limits(e, f"joint {name!r}") for e in (e1, e2)]
        return pin.JointModelUniversal(a1, a2), *zip(*springs, strict=True), limits
    a, elem = r.axis(name)
    k, ref = r.spring(elem, f"joint {name!r}")
    limit = r.limits(elem, f"joint {name!r}") if kind != "continuous" else (-math.inf, math.inf)
    prismatic = kind == "prismatic"
    joint = (pin.JointModelPrismaticUnaligned if prismatic else pin.JointModelRevoluteUnaligned)(a)
    return joint, (k,), (ref,), [limit]


def read_sdf(path: str | Path, *, free_base: bool = False, geometry: bool = True) -> SdfRobot:
    """Read an SDF robot file (module docstring) into a Pinocchio tree with closures.

    Args:
        path: the ``.sdf`` file.
        free_base: carry the root link by a free-flyer joint ``root_joint`` instead of
            fixing it to the world.
        geometry: also build the visual geometry (mesh files must be found).

    Raises:
        ModelFileError: invalid XML, unknown joint type, missing parent or child, a pose
            or axis with the wrong number of values, an axis with a ``<mimic>``, a loop that
            cannot be closed, a mesh not found; one line naming the element and what was
            expected.
    """
    r = _Reader(Path(path))
    tree: dict[str, str] = {}  # child link -> its tree joint
    closing: list[str] = []
    for name, e in r.joints.items():
        kind, what = e.get("type"), f"joint {name!r}"
        if kind not in JOINT_TYPES:
            r.fail(f"{what} has type {kind!r}; expected one of {', '.join(JOINT_TYPES)}")
        parent, child = r.text(e, "parent", what), r.text(e, "child", what)
        for role, link in (("parent", parent), ("child", child)):
            if link not in r.links and not (role == "parent" and link == "world"):
                r.fail(f"{what} has {role} {link!r}; expected one of the links {list(r.links)}")
        if parent == child:
            r.fail(f"{what} joins link {child!r} to itself; expected two different links")
        if child in tree:
            closing.append(name)
        else:
            tree[child] = name
    roots = [link for link in r.links if link not in tree]
    children: dict[str, list[str]] = {}  # link -> its tree joints, file order
    for j in tree.values():
        children.setdefault(r.text(r.joints[j], "parent", j), []).append(j)
    grounded = children.get("world", [])
    if len(roots) != (0 if grounded else 1):
        found = f"links {roots} have no parent joint" if roots else "every link has a parent"
        r.fail(f"{found}; expected exactly one root link (none with a joint to 'world')")
    for name in (*r.links, *r.joints):  # Pinocchio's names of the world and the free base
        if name == "universe" or (name == "root_joint" and free_base):
            role = "world" if name == "universe" else "free base joint"
            r.fail(f"name {name!r} is taken by Pinocchio's {role}; expected another name")
    model = pin.Model()
    model.name = r.elem.get("name") or r.path.stem
    world_of_model = r.local_pose(r.elem, "model")[0]
    # placement of each Pinocchio joint in the model frame at q = 0 (the universe first)
    W = [world_of_model.inverse()]
    body: dict[str, tuple[int, pin.SE3]] = {}  # link -> (joint id, placement in that joint)
    springs: dict[str, float | list[float]] = {}
    rest_values: dict[int, float] = {}  # q index -> spring reference
    bounds: dict[int, tuple[float, float]] = {}  # q index -> (lower, upper) limits

    def attach(link: str, jid: int, frame: int) -> None:
        placement = W[jid].inverse() * r.pose(link)
        body[link] = (jid, placement)
        model.appendBodyToJoint(jid, r.inertia(link), placement)
        model.addFrame(pin.Frame(link, jid, frame, placement, pin.FrameType.BODY))
        for j in children.get(link, ()):
            add_joint(j, link)

    def add_joint(name: str, parent: str) -> None:
        kind = r.joints[name].get("type")
        pj, _ = body[parent] if parent in body else (0, None)
        parent_frame = model.getFrameId(parent) if parent in body else 0
        X = r.pose(name)
        child = r.text(r.joints[name], "child", name)
        if kind == "fixed":
            model.addFrame(
                pin.Frame(name, pj, parent_frame, W[pj].inverse() * X, pin.FrameType.FIXED_JOINT)
            )
            return attach(child, pj, model.getFrameId(name))
        joint, k, ref, limits = _joint_model(r, name, kind)
        jid = model.addJoint(pj, joint, (W[pj].inverse() * X), name)
        W.append(X)
        jm = model.joints[jid]
        for i, limit in enumerate(limits or ()):
            bounds[jm.idx_q + i] = limit
        if k is not None and any(v > 0 for v in k):
            springs[name] = k[0] if len(k) == 1 else list(k)
            rest_values.update({jm.idx_q + i: v for i, v in enumerate(ref)})
        attach(child, jid, model.addJointFrame(jid, parent_frame))

    if grounded and free_base:
        r.fail(f"joints {grounded} fix the model to the world; expected no free base")
    for j in grounded:
        add_joint(j, "world")
    if free_base:
        X = world_of_model * r.pose(roots[0])
        jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root_joint")
        W.append(r.pose(roots[0]))
        attach(roots[0], jid, model.addJointFrame(jid, 0))
        free_q = pin.SE3ToXYZQUAT(X)
    elif not grounded:
        attach(roots[0], 0, 0)
    lost = [link for link in r.links if link not in body]
    if lost:
        r.fail(f"links {lost} are not connected to the root (their parent joints form a cycle)")
    for name in r.frames:  # loaded frames, like a URDF's fixed joints
        link = r.frame_link(name)
        if model.existFrame(name):  # "universe", "root_joint"
            r.fail(f"frame {name!r} has the name of a frame of the model; expected another")
        jid = body[link][0]
        placement = W[jid].inverse() * r.pose(name)
        model.addFrame(
            pin.Frame(name, jid, model.getFrameId(link), placement, pin.FrameType.OP_FRAME)
        )
    closures = _closures(r, model, body, closing, W)
    rest = pin.neutral(model)
    for i, v in rest_values.items():
        rest[i] = v
    if free_base:
        rest[:7] = free_q
    model.referenceConfigurations[REST] = rest
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for i, (lo, hi) in bounds.items():
        lower[i], upper[i] = lo, hi
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    visual = _visuals(r, model, body) if geometry else None
    return SdfRobot(model, closures, springs, rest, visual, tuple(closing))


def _closures(r: _Reader, model, body, closing, W) -> list[Closure]:
    L = characteristic_length([r.pose(link).translation for link in r.links])
    out = []
    for name in closing:
        e, what = r.joints[name], f"loop-closing joint {name!r}"
        kind, X = e.get("type"), r.pose(name)
        if kind in ("prismatic", "universal"):
            r.fail(
                f"{what} is {kind}: such a loop cannot be closed by point or weld closures; "
                "expected ball, revolute or fixed (or list it first so it is a tree joint)"
            )
        if kind in ("revolute", "continuous") and r.spring(r.axis(name)[1], what)[0] > 0:
            r.fail(f"{what} has a spring, which needs a coordinate; list it first (tree joint)")
        parent, child = r.text(e, "parent", what), r.text(e, "child", what)
        if parent == "world":
            r.fail(f"{what} has parent 'world'; expected a link of the model")
        (j1, _), (j2, _) = body[parent], body[child]
        M1, M2 = W[j1].inverse() * X, W[j2].inverse() * X
        if kind == "fixed":
            c = pin.FrameAnchorConstraintModel(model, j1, M1, j2, M2)
            out.append(Closure(c, name))
            continue
        offsets = [np.zeros(3)] + ([L * r.axis(name)[0]] if kind != "ball" else [])
        for i, d in enumerate(offsets):
            P = pin.SE3(np.eye(3), d)
            c = pin.PointAnchorConstraintModel(model, j1, M1 * P, j2, M2 * P)
            out.append(Closure(c, name if len(offsets) == 1 else f"{name}[{i}]"))
    return out


def model_dirs(path: Path) -> list[Path]:
    """Folders searched for ``model://NAME/...`` (module docstring), in order."""
    dirs = list(path.resolve().parents)
    for var in ("GZ_SIM_RESOURCE_PATH", "SDF_PATH", "GAZEBO_MODEL_PATH"):
        dirs += [Path(p) for p in os.environ.get(var, "").split(os.pathsep) if p]
    try:
        share = [robot_data_dir().parent.parent]  # share/ holds example-robot-data/robots
    except ModelFileError:  # example-robot-data not installed: not searched
        share = []
    return dirs + share


def _mesh_file(r: _Reader, uri: str, what: str) -> str:
    if uri.startswith("file://"):
        candidates = [Path(uri[7:])]
    elif uri.startswith("model://"):
        candidates = [d / uri[8:] for d in model_dirs(r.path)]
    else:
        candidates = [r.path.parent / uri]
    for c in candidates:
        if c.is_file():
            return str(c)
    return r.fail(f"{what}: mesh {uri!r} not found (looked in {len(candidates)} folders)")


def _visuals(r: _Reader, model: pin.Model, body) -> pin.GeometryModel:
    import coal  # only when geometry is asked for

    gm = pin.GeometryModel()
    for link, (jid, M) in body.items():
        for i, v in enumerate(r.links[link].findall("visual")):
            what = f"visual {i} of link {link!r}"
            local, ref = r.local_pose(v, what)
            X = M * local if not ref else M * r.pose(link).inverse() * r.pose(ref) * local
            shape, scale, mesh = v.find("geometry/*"), np.ones(3), ""
            if shape is None:
                r.fail(f"{what} has no <geometry>")
            size = {t: r.number(shape, t, 1.0, what) for t in ("radius", "length")}
            if shape.tag == "mesh":
                mesh = _mesh_file(r, r.text(shape, "uri", what), what)
                if shape.find("scale") is not None:
                    scale = r.floats(shape.find("scale"), f"{what} scale", (3,))
                try:
                    geom = coal.MeshLoader().load(mesh, scale)
                except ValueError as e:  # a file that is not a mesh, a zero scale
                    r.fail(f"{what}: mesh {mesh!r} cannot be loaded ({' '.join(str(e).split())})")
            elif shape.tag == "box":
                geom = coal.Box(*r.floats(shape.find("size"), f"{what} size", (3,)))
            elif shape.tag == "cylinder":
                geom = coal.Cylinder(size["radius"], size["length"])
            elif shape.tag == "sphere":
                geom = coal.Sphere(size["radius"])
            else:
                continue  # planes, heightmaps...: nothing a robot's links show
            colour = v.find("material/ambient")
            rgba = r.floats(colour, f"{what} ambient", (4,)) if colour is not None else None
            fid = model.getFrameId(link)
            obj = pin.GeometryObject(f"{link}_{i}", jid, fid, X, geom, mesh, scale)
            if rgba is not None:
                obj.meshColor, obj.overrideMaterial = rgba, True
            gm.addGeometryObject(obj)
    return gm


def load_sdf(path: str | Path, *, free_base: bool = False, geometry: bool = True) -> SdfRobot:
    """:func:`read_sdf`, or Pinocchio's own SDF parser when it has one (``pin.WITH_SDFORMAT``).

    Pinocchio's parser gives the tree, its point closures and the geometry; the springs
    and their rest configuration, which it does not read, are read from the XML here.
    """
    if not getattr(pin, "WITH_SDFORMAT", False):
        try:
            return read_sdf(path, free_base=free_base, geometry=geometry)
        except RecursionError:  # the reader follows the tree and the poses recursively
            raise ModelFileError(
                f"SDF file {str(path)!r}: its links (or its poses relative_to one another) are "
                "nested too deep for the reader (Python's recursion limit, "
                f"{sys.getrecursionlimit()}); expected a shallower tree"
            ) from None
    r = _Reader(Path(path))
    root = pin.JointModelFreeFlyer() if free_base else None
    types = [pin.GeometryType.VISUAL] if geometry else None
    dirs = [str(d) for d in model_dirs(r.path)]
    model, points, *geometries = pin.buildModelsAndConstraintsFromSdf(
        str(path), package_dirs=dirs, root_joint=root, geometry_types=types
    )
    springs, rest = {}, pin.neutral(model)
    for name, e in r.joints.items():
        if e.get("type") in ("revolute", "prismatic") and model.existJointName(name):
            k, ref = r.spring(r.axis(name)[1], f"joint {name!r}")
            if k > 0:
                springs[name] = k
                rest[model.joints[model.getJointId(name)].idx_q] = ref
    model.referenceConfigurations[REST] = rest
    closures = [Closure(c, f"closure{i}") for i, c in enumerate(points)]
    closing = tuple(n for n in r.joints if not (model.existJointName(n) or model.existFrame(n)))
    visual = geometries[-1] if geometry and geometries else None
    return SdfRobot(model, closures, springs, rest, visual, closing)

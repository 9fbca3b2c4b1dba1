"""Reading SDFormat robot files (the subset robot files use) into a model with closures.

Used when Pinocchio has no SDFormat support (``pin.WITH_SDFORMAT`` False, as in the PyPI
wheel). Read: one ``<model>`` of ``<link>``, ``<frame>`` and ``<joint>`` (revolute,
continuous, prismatic, ball, universal, fixed; ``<include>`` and nested models refused);
``<pose>`` (x y z roll pitch yaw, R = Rz Ry Rx; ``rotation_format="quat_xyzw"``,
``degrees="true"``) relative to ``relative_to`` (SDF >= 1.7) or ``frame`` (1.5/1.6), by
default a link's to the model, a joint's to its child link, a frame's to ``attached_to``;
``<axis><xyz>`` in the joint frame, or the model frame (``use_parent_model_frame``, SDF
<= 1.6; by default in SDF <= 1.4), or ``expressed_in`` a frame; ``<limit>``
(``|value|`` >= 1e16: none);
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

* ball: a ``3d`` closure (3 rows) at the joint origin, every rotation free;
* revolute / continuous: a ``revolute`` closure (5 rows) at the joint origin, its z axes
  along the joint axis;
* prismatic: a ``prismatic`` closure (5 rows), its z axes along the joint axis;
* universal: a ``universal`` closure (4 rows) at the joint origin, the parent's z along
  ``axis``, the child's along ``axis2``;
* fixed: a weld (``6d``).

(:mod:`closedloop.model.closures`.) A revolute, continuous, prismatic or universal
loop-closing joint with a spring becomes an elastic closure, its free directions sprung
(:mod:`closedloop.model.elastic_closures`: the joint ``<name>_rz`` or ``<name>_pz``; a
universal's ``<name>_rz`` about ``axis`` and ``<name>_rx`` about ``axis2``), at rest at
its ``spring_reference`` from the drawing.

The root link (no joint names it as child) is fixed to the world at its pose, or carried
by a free flyer ``root_joint`` (``free_base``); a joint with parent ``world`` fixes its child.

Springs: ``spring_stiffness`` > 0 [N m/rad, N/m]. The model's springs are at rest at the
configuration analysed, so the rest configuration ``model.referenceConfigurations[REST]``
puts each spring joint at its ``spring_reference`` (others at the drawing, 0); assembly
from it keeps the springs at rest
(:meth:`closedloop.model.closed_loop.ClosedLoopModel.reference_configuration`).
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.exceptions import ModelFileError
from closedloop.io.data import robot_data_dir
from closedloop.io.sdf_reader import SdfReader
from closedloop.model.closures import CLOSURE_TYPES, Closure
from closedloop.model.elastic_closures import DIRECTIONS, FREE_DIRECTIONS, with_elastic_closures
from closedloop.model.reference import REST

#: Joint types read.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "ball", "universal", "fixed")


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


def _joint_model(r: SdfReader, name: str, kind: str):
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
    r = SdfReader(Path(path))
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
    closures, cut_springs = _closures(r, model, body, closing, W)
    elastic = {}  # a loop joint with springs: its free directions sprung or free
    for i, (c, sprung) in enumerate(zip(closures, cut_springs.values(), strict=True)):
        if sprung:
            elastic[i] = [0.0 if d in FREE_DIRECTIONS[c.kind] else math.inf for d in range(6)]
            for suffix, (k, _) in sprung.items():
                elastic[i][DIRECTIONS.index(suffix)] = k
    rest = pin.neutral(model)
    for i, v in rest_values.items():
        rest[i] = v
    if free_base:
        rest[:7] = free_q
    model.referenceConfigurations[REST] = rest
    model, closures, cut = with_elastic_closures(model, closures, elastic)
    rest = model.referenceConfigurations[REST].copy()
    for name, k in cut.items():  # a spring at a loop cut, at rest at its spring_reference
        springs[name] = k
        joint, suffix = name.rsplit("_", 1)
        rest[model.joints[model.getJointId(name)].idx_q] += cut_springs[joint][suffix][1]
    model.referenceConfigurations[REST] = rest
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for i, (lo, hi) in bounds.items():
        lower[i], upper[i] = lo, hi
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    visual = _visuals(r, model, body) if geometry else None
    return SdfRobot(model, closures, springs, rest, visual, tuple(closing))


def _z_along(axis: np.ndarray) -> pin.SE3:
    """A rotation (no translation) that takes z to the unit vector ``axis``."""
    q = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis / np.linalg.norm(axis))
    return pin.SE3(q.matrix(), np.zeros(3))


#: The closure type of each loop-closing joint type (module docstring).
LOOP_TYPES = {"ball": "3d", "fixed": "6d", "revolute": "revolute", "continuous": "revolute",
              "prismatic": "prismatic", "universal": "universal"}  # fmt: skip


def _closures(r: SdfReader, model, body, closing, W) -> tuple[list[Closure], dict]:
    """(the closures of the loop-closing joints, {joint: {direction: (spring stiffness,
    spring reference)} of its axes with a spring} in their order)."""
    out, springs = [], {}
    for name in closing:
        e, what = r.joints[name], f"loop-closing joint {name!r}"
        kind, X = e.get("type"), r.pose(name)
        axes = {"ball": (), "fixed": (), "universal": ("axis", "axis2")}.get(kind, ("axis",))
        found = [r.axis(name, a) for a in axes]
        if len(found) == 2 and abs(found[0][0] @ found[1][0]) > 1e-9:
            r.fail(f"{what} has axes {found[0][0]} and {found[1][0]}; expected orthogonal axes")
        # the directions of the closure's springs: along or about A's z axis, a universal
        # pair's second axis about B's z (closedloop.model.elastic_closures)
        suffixes = ("pz",) if kind == "prismatic" else ("rz", "rx")
        sprung = zip(suffixes, (r.spring(elem, what) for _, elem in found), strict=False)
        springs[name] = {suffix: (k, ref) for suffix, (k, ref) in sprung if k > 0}
        parent, child = r.text(e, "parent", what), r.text(e, "child", what)
        if parent == "world":
            r.fail(f"{what} has parent 'world'; expected a link of the model")
        (j1, _), (j2, _) = body[parent], body[child]
        M1, M2 = W[j1].inverse() * X, W[j2].inverse() * X
        if found:  # z of either frame along its axis (the child's along axis2)
            M1, M2 = M1 * _z_along(found[0][0]), M2 * _z_along(found[-1][0])
        kind = LOOP_TYPES[kind]
        c = CLOSURE_TYPES[kind](model, j1, M1, j2, M2)
        out.append(Closure(c, name, kind))
    return out, springs


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


def _mesh_file(r: SdfReader, uri: str, what: str) -> str:
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


def _visuals(r: SdfReader, model: pin.Model, body) -> pin.GeometryModel:
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
    r = SdfReader(Path(path))
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

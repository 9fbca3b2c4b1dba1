"""Flexible links as 6-dof virtual springs from beam theory (the Virtual Joint Method).

A flexible link is a rigid body with a 6-dof virtual spring at its end (Pashkevich,
Klimchik and Chablat's Virtual Joint Method). A *beam* on a link is straight, from the
origin of the link's frame (its start, clamped) to the origin of its ``end`` joint (the
tip): its length is that distance. The tip carries the ``end`` joint and everything beyond
it; the link's other child joints stay rigid with the start. :func:`apply_beams` puts a
6-dof virtual joint (a Pinocchio free flyer named ``<link>_beam``) between the link and
its ``end``, placed at the end joint's origin with the end joint's axes, and gives it the
beam's tip stiffness as an SPD block spring (:mod:`closedloop.model`). Its coordinates
dq = (v, w) are the twist of the tip (translation [m], small rotation [rad]) in the end
joint's axes, so the block is the tip stiffness in that frame, wrench (f [N], n [N m]).

Tip stiffness of a clamped straight beam (length L, beam axes: x along the beam, y and
z the section's principal axes), from its tip compliance C_b (wrench at the tip, beam
axes): axial L/(E A), torsion L/(G J); bending in the x-y plane (deflection along y,
Euler-Bernoulli, second moment Iz) C[v, f_y] = L^3/(3 E Iz), C[v, n_z] = C[th_z, f_y] =
L^2/(2 E Iz), C[th_z, n_z] = L/(E Iz); in the x-z plane the same with Iy and the sign of
the v-theta coupling reversed (a force along +z turns the tip about -y). Timoshenko adds
the shear compliance L/(kappa G A) to the deflection under the transverse force, with
Cowper's shear coefficients (nu = E/(2G) - 1): circle 6(1+nu)/(7+6nu); tube
6(1+nu)(1+m^2)^2/((7+6nu)(1+m^2)^2 + (20+12nu)m^2), m = d_inner/d; rectangle
10(1+nu)/(12+11nu); an explicit section gives ``kappa_y``, ``kappa_z``.

Sections: ``circle`` (d), ``tube`` (d outer diameter, t wall), Iy = Iz = I, J = 2 I;
``rectangle`` (b along the section's y axis, h along z): Iy = b h^3/12, Iz = h b^3/12,
J from Roark's approximation a c^3 (1/3 - 0.21 (c/a) (1 - c^4/(12 a^4))), a >= c the
sides (within 0.5% of the exact series); or explicit {A, Iy, Iz, J} [m^2, m^4]. The
section's y axis is ``y_axis`` (a vector in the link frame) made orthogonal to the beam;
default: the link frame axis most orthogonal to the beam, made orthogonal to it.

``section: geometry`` (URDF files only, :func:`urdf_shapes`) takes the section from the
link's ``<collision>`` elements, or its ``<visual>`` ones when it has none: they must hold
exactly one cylinder or box (other shapes, such as meshes, are ignored), whose axis must
lie along the beam within ``ALIGN_TOLERANCE``. A cylinder gives a circle of its diameter;
a box the rectangle of its two sides across the beam: the box axis along the beam is i
(x, y, z = 0, 1, 2), the section's y axis is box axis i + 1 (mod 3), b its size, and h
the size along box axis i + 2 (mod 3). The shape's length and position are not used (the
beam runs from the link's origin to its end joint).

Inertia: the link's own inertia stays at the beam's start (on the link's parent joint);
bodies beyond a ``fixed`` end (merged by Pinocchio's URDF parser into the link's joint)
move with the tip. Frames keep their indices (the virtual joint's frame is appended);
joints from the virtual joint on get new indices; frames, geometry objects and closure
anchors beyond the tip follow it.

Elements and mass: ``elements: N`` (default 1) splits the beam into N equal elements, a
6-dof virtual joint at each node, ``<link>_beam_1`` .. ``<link>_beam_{N-1}``, then
``<link>_beam`` at the tip, all in the end joint's axes, each with the clamped stiffness of
length L / N (:func:`inserted_beams` lists the elements, each from its start node).
``density`` [kg/m^3] gives the beam a mass of its own (:class:`BeamMass`, the consistent
mass of :mod:`closedloop.vibration`), with a section only.

Preload: the beam's energy is that of beam theory on the tip's displacement and rotation
in its rest axes, with the shortening of the bent beam in its axial elongation
(:mod:`closedloop.elastic`): an axial force softens (compression) or stiffens (tension) its
bending as the one-element beam-column does (0.2 % from the closed form at P = EI / L^2;
buckling of a clamped rod at 2.486 EI / L^2, Euler's pi^2 / 4 = 2.467). At zero deflection
it is the block above: the unloaded compliance does not depend on it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .exceptions import BeamError, InvalidInputError

THEORIES = ("euler-bernoulli", "timoshenko")
SHAPES = {"circle": ("d",), "tube": ("d", "t"), "rectangle": ("b", "h")}
EXPLICIT = ("A", "Iy", "Iz", "J")
BEAM_KEYS = (
    "end", "E", "G", "section", "theory", "stiffness_6x6", "compliance_6x6", "density",
    "elements",
)  # fmt: skip
#: ``section: geometry``: the section from the link's URDF cylinder or box.
GEOMETRY = "geometry"
#: Largest angle [rad] between the axis of that shape and the beam (0.057 deg): far above
#: the rounding of angles written with 4 decimals in URDF files (1.5708 for pi/2 is off by
#: 3.7e-6 rad), far below a deliberate tilt; the section is used with the beam's axes.
ALIGN_TOLERANCE = 1e-3


def _positive(beam: str, what: str, value) -> float:
    try:
        # "2.1e11" from a YAML 1.1 file is a number; a bool is not
        x = math.nan if isinstance(value, bool | np.bool_) else float(value)
    except (TypeError, ValueError):
        raise BeamError(beam, f"{what} is {value!r}; expected a number > 0") from None
    if not (math.isfinite(x) and x > 0):
        raise BeamError(beam, f"{what} is {value!r}; expected a finite number > 0")
    return x


@dataclass(frozen=True)
class Section:
    """Cross-section properties: area A [m^2], second moments Iy, Iz and torsion constant J
    [m^4] about the section's principal axes y, z; Timoshenko shear coefficients (None:
    from the shape, Cowper); ``y_axis`` (3,) in the link frame or None (module docstring);
    ``m``: inner/outer diameter ratio of a tube."""

    A: float
    Iy: float
    Iz: float
    J: float
    shape: str = "explicit"
    kappa_y: float | None = None
    kappa_z: float | None = None
    y_axis: tuple[float, float, float] | None = None
    m: float = 0.0

    def kappa(self, nu: float) -> tuple[float, float]:
        """(kappa_y, kappa_z) shear coefficients (dimensionless) at Poisson ratio nu."""
        if self.shape == "rectangle":
            k = 10 * (1 + nu) / (12 + 11 * nu)
        elif self.shape in ("circle", "tube"):
            m2 = self.m**2
            k = 6 * (1 + nu) * (1 + m2) ** 2 / ((7 + 6 * nu) * (1 + m2) ** 2 + (20 + 12 * nu) * m2)
        else:
            k = None
        return (self.kappa_y or k, self.kappa_z or k)


@dataclass(frozen=True)
class BeamMass:
    """What a beam's own mass needs besides its length: the section's area A [m^2] and
    polar second moment Ip = Iy + Iz [m^4], and the density [kg/m^3] of its ``density:``
    key (None: the model-wide default of :func:`closedloop.vibration.modes`)."""

    A: float
    Ip: float
    density: float | None


def section_from_spec(beam: str, spec) -> Section:
    """A :class:`Section` from its mapping (``{shape: circle, d: ..}``, ``{A: .., Iy: ..}``)."""
    if isinstance(spec, Section):
        return spec
    if not isinstance(spec, Mapping):
        raise BeamError(beam, f"section is {spec!r}; expected a mapping (shape and sizes)")
    spec = dict(spec)
    y_axis = spec.pop("y_axis", None)
    if y_axis is not None:
        try:
            # a list, tuple or array of numbers; not a string, a mapping or a scalar
            seq = isinstance(y_axis, list | tuple | np.ndarray) and np.ndim(y_axis) == 1
            y = np.asarray([float(v) for v in y_axis]) if seq else None
        except (TypeError, ValueError):
            y = None
        if y is None or y.shape != (3,) or not np.all(np.isfinite(y)) or not np.any(y):
            raise BeamError(beam, f"section y_axis is {y_axis!r}; expected 3 numbers, not all 0")
        y_axis = tuple(y.tolist())
    kap = {k: _positive(beam, f"section {k}", spec.pop(k)) for k in ("kappa_y", "kappa_z")
           if k in spec}  # fmt: skip
    shape = spec.pop("shape", None)
    if shape is not None and not isinstance(shape, str):
        raise BeamError(beam, f"section shape is {shape!r}; expected one of {list(SHAPES)}")
    if shape is None:
        if set(spec) != set(EXPLICIT):
            raise BeamError(beam, f"section keys {sorted(spec)}; expected shape: "
                            f"{'|'.join(SHAPES)} with its sizes, or {list(EXPLICIT)}")  # fmt: skip
        v = {k: _positive(beam, f"section {k}", spec[k]) for k in EXPLICIT}
        return Section(v["A"], v["Iy"], v["Iz"], v["J"], "explicit", y_axis=y_axis, **kap)
    if shape not in SHAPES or set(spec) != set(SHAPES[shape]):
        expected = ", ".join(f"{s} ({', '.join(k)})" for s, k in SHAPES.items())
        raise BeamError(beam, f"section {shape!r} with {sorted(spec)}; expected one of {expected}")
    v = {k: _positive(beam, f"section {k}", spec[k]) for k in SHAPES[shape]}
    if shape in ("circle", "tube"):
        r = v["d"] / 2
        ri = 0.0 if shape == "circle" else r - v["t"]
        if ri < 0:
            raise BeamError(beam, f"tube wall t = {v['t']} m is thicker than its radius {r} m")
        A, Ir = math.pi * (r**2 - ri**2), math.pi * (r**4 - ri**4) / 4
        return Section(A, Ir, Ir, 2 * Ir, shape, y_axis=y_axis, m=ri / r, **kap)
    b, h = v["b"], v["h"]
    a, c = max(b, h), min(b, h)
    J = a * c**3 * (1 / 3 - 0.21 * (c / a) * (1 - c**4 / (12 * a**4)))
    return Section(b * h, b * h**3 / 12, h * b**3 / 12, J, shape, y_axis=y_axis, **kap)


@dataclass(frozen=True)
class Shape:
    """One ``<collision>`` or ``<visual>`` element of a URDF link, as written: ``kind`` the
    tag of its geometry (cylinder, box, mesh, sphere...), ``sizes`` that tag's attributes
    (radius, length [m] / size "x y z" [m] / filename...), ``rpy`` its origin's roll, pitch,
    yaw [rad] in the link frame."""

    source: str  # "collision" or "visual"
    kind: str
    sizes: dict[str, str]
    rpy: str = "0 0 0"


def urdf_shapes(path) -> dict[str, list[Shape]]:
    """Link name -> its collision elements (its visual ones when it has none) of the URDF
    file ``path``, for ``section: geometry``."""
    out = {}
    for link in ET.parse(path).getroot().iter("link"):
        for source in ("collision", "visual"):
            shapes = []
            for element in link.findall(source):
                geometry = element.find("geometry")
                origin = element.find("origin")
                rpy = "0 0 0" if origin is None else origin.get("rpy", "0 0 0")
                for g in [] if geometry is None else list(geometry)[:1]:
                    shapes.append(Shape(source, g.tag, dict(g.attrib), rpy))
            if shapes:
                out[link.get("name")] = shapes
                break
    return out


def _numbers(beam: str, what: str, text: str, n: int) -> np.ndarray:
    try:
        x = np.array([float(v) for v in str(text).split()])
    except ValueError:
        x = np.zeros(0)
    if x.shape != (n,) or not np.all(np.isfinite(x)):
        raise BeamError(beam, f"section geometry: {what} is {text!r}; expected {n} numbers")
    return x


def geometry_section(beam: str, shapes: list[Shape] | None, axis: np.ndarray) -> dict:
    """The section mapping (``{shape: circle, d}`` or ``{shape: rectangle, b, h, y_axis}``)
    of ``section: geometry`` (module docstring) for a beam along ``axis`` (3,) in the link
    frame, from the link's ``shapes`` (:func:`urdf_shapes`; None: not read from a URDF).

    Raises:
        BeamError: no URDF, no cylinder or box, several of them, a shape across the beam.
    """
    if shapes is None:
        raise BeamError(
            beam,
            "section geometry is read from the link's URDF cylinder or box: "
            "give the beam to load_model with the URDF file, or give a section",
        )
    if not shapes:
        raise BeamError(
            beam,
            "section geometry: the link has no collision or visual geometry "
            "in the URDF; expected a cylinder or box",
        )
    found = [s for s in shapes if s.kind in ("cylinder", "box")]
    source = shapes[0].source
    if len(found) != 1:
        kinds = [s.kind for s in shapes]
        raise BeamError(
            beam,
            f"section geometry: the link's {source} geometry is {kinds}; "
            "expected exactly one cylinder or box",
        )
    shape = found[0]
    R = pin.rpy.rpyToMatrix(*_numbers(beam, f"{source} origin rpy", shape.rpy, 3))
    x = axis / np.linalg.norm(axis)
    i = 2 if shape.kind == "cylinder" else int(np.argmax(np.abs(R.T @ x)))
    angle = math.asin(min(1.0, float(np.linalg.norm(np.cross(R[:, i], x)))))
    if angle > ALIGN_TOLERANCE:
        raise BeamError(
            beam,
            f"section geometry: the {source} {shape.kind}'s axis "
            f"{np.round(R[:, i], 6).tolist()} (link frame) is at "
            f"{math.degrees(angle):.3g} deg from the beam {np.round(x, 6).tolist()}; "
            f"expected along it (within {ALIGN_TOLERANCE} rad)",
        )
    if shape.kind == "cylinder":
        radius = _numbers(beam, f"{source} cylinder radius", shape.sizes.get("radius"), 1)
        return {"shape": "circle", "d": float(2 * radius[0])}
    size = _numbers(beam, f"{source} box size", shape.sizes.get("size"), 3).tolist()
    j, k = (i + 1) % 3, (i + 2) % 3
    return {"shape": "rectangle", "b": size[j], "h": size[k], "y_axis": R[:, j].tolist()}


def clamped_compliance(L: float, E: float, G: float, s: Section, theory: str) -> np.ndarray:
    """(6, 6) tip compliance of a clamped straight beam [m/N, rad/N, rad/(N m)], beam axes
    (x along the beam), twist (v, w) of the tip per wrench (f, n) at the tip."""
    C = np.zeros((6, 6))
    C[0, 0], C[3, 3] = L / (E * s.A), L / (G * s.J)
    ky, kz = s.kappa(E / (2 * G) - 1) if theory == "timoshenko" else (None, None)
    for lin, ang, inertia, sign, kappa in ((1, 5, s.Iz, 1.0, ky), (2, 4, s.Iy, -1.0, kz)):
        EI = E * inertia
        C[lin, lin] = L**3 / (3 * EI) + (L / (kappa * G * s.A) if kappa else 0.0)
        C[lin, ang] = C[ang, lin] = sign * L**2 / (2 * EI)
        C[ang, ang] = L / EI
    return C


def beam_axes(beam: str, axis: np.ndarray, y_axis) -> np.ndarray:
    """(3, 3) rotation whose columns are the beam axes x (along ``axis``), y, z, in the
    frame of ``axis`` (the link frame); y from ``y_axis`` or the default rule."""
    x = axis / np.linalg.norm(axis)
    y = np.eye(3)[np.argmin(np.abs(x))] if y_axis is None else np.asarray(y_axis, float)
    y = y - (y @ x) * x
    if np.linalg.norm(y) < 1e-9 * np.linalg.norm(y_axis if y_axis is not None else y):
        shown = np.asarray(y_axis, float).tolist()
        raise BeamError(beam, f"section y_axis {shown} is parallel to the beam {x.tolist()}")
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


def transport_stiffness(K: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(6, 6) stiffness K given in axes B re-expressed in axes E at the same point, with R
    (3, 3) the rotation of E in B (columns: E's axes in B): R6^T K R6, R6 = diag(R, R)."""
    R6 = np.zeros((6, 6))
    R6[:3, :3] = R6[3:, 3:] = R
    return R6.T @ K @ R6


@dataclass(frozen=True)
class _Site:
    """Where a beam sits: the link's frame, its parent joint, the end's placement."""

    link_frame: int
    joint: int  # parent joint of the link (the beam's start)
    end: str
    end_joint: int | None  # the moving end joint, or None for a fixed end
    end_frame: int  # the end's JOINT or FIXED_JOINT frame
    placement: pin.SE3  # the end's origin and axes in the parent joint's frame


def _site(model: pin.Model, beam: str, end: str | None) -> _Site:
    bodies = [f.name for f in model.frames if f.type == pin.BODY]
    if beam not in bodies:
        raise BeamError(beam, f"unknown link; expected one of {bodies[:12]}")
    fl = next(i for i, f in enumerate(model.frames) if f.type == pin.BODY and f.name == beam)
    kinds = (pin.JOINT, pin.FIXED_JOINT)
    children = [i for i, f in enumerate(model.frames) if f.parentFrame == fl and f.type in kinds]
    names = [model.frames[i].name for i in children]
    if end is None:
        if len(children) != 1:
            raise BeamError(beam, f"the link has {len(children)} child joints {names}: give end")
        end = names[0]
    if end not in names:
        known = model.existJointName(end) or any(
            f.name == end and f.type == pin.FIXED_JOINT for f in model.frames
        )
        what = "is not a child joint of the link" if known else "is not a joint of the model"
        raise BeamError(beam, f"end {end!r} {what}; expected one of {names}")
    fe = children[names.index(end)]
    frame = model.frames[fe]
    if frame.type == pin.JOINT:
        j = frame.parentJoint
        return _Site(fl, model.parents[j], end, j, fe, model.jointPlacements[j].copy())
    return _Site(fl, frame.parentJoint, end, None, fe, frame.placement.copy())


def _descendant_frames(model: pin.Model, root: int) -> set[int]:
    """``root`` and the frames after it in the frame tree that are on its joint: those the
    beam's tip carries. A moving joint after it (its JOINT frame, on that joint) ends the
    walk: the frames after that joint are placed in it and move with it."""
    joint = model.frames[root].parentJoint
    out, grew = {root}, True
    while grew:
        new = {
            i for i, f in enumerate(model.frames)
            if f.parentFrame in out and i not in out and f.parentJoint == joint
        }  # fmt: skip
        new.discard(0)
        out |= new
        grew = bool(new)
    return out


#: Per-velocity-coordinate fields of a Pinocchio model carried over to the new model.
_NV_ATTRIBUTES = (
    "lowerEffortLimit", "upperEffortLimit", "lowerVelocityLimit", "upperVelocityLimit",
    "armature", "damping", "rotorInertia", "rotorGearRatio", "lowerDryFrictionLimit",
    "upperDryFrictionLimit",
)  # fmt: skip


def _insert(model, geometries, site: _Site, name: str):
    """A copy of ``model`` (and of the geometry models) with a free-flyer ``name`` between
    the site's joint and its end; returns (model, geometries, old -> new joint index)."""
    if site.end_joint is not None:
        moved_frames = set()
        moved_joints = {site.end_joint}
    else:
        moved_frames = _descendant_frames(model, site.end_frame)
        moved_joints = {
            f.parentJoint for f in model.frames if f.type == pin.JOINT
            and f.parentJoint > 0 and f.parentFrame in moved_frames
        }  # fmt: skip
    Mv = site.placement
    children = {j: [] for j in range(model.njoints)}
    for j in range(1, model.njoints):
        children[model.parents[j]].append(j)
    siblings = children[site.joint]
    at = min((siblings.index(j) for j in moved_joints), default=len(siblings))
    siblings.insert(at, "V")
    children["V"] = sorted(moved_joints)
    for j in moved_joints:
        children[site.joint].remove(j)
    order, stack = [], list(reversed(children[0]))
    while stack:  # depth first, children in their original order
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    new, index = pin.Model(), {0: 0}
    new.name, new.gravity, new.inertias[0] = model.name, model.gravity, model.inertias[0]
    inertia_tip = pin.Inertia.Zero()
    for i in moved_frames:
        f = model.frames[i]
        inertia_tip = inertia_tip + Mv.actInv(f.placement).act(f.inertia)
    for j in order:
        if j == "V":
            index["V"] = new.addJoint(index[site.joint], pin.JointModelFreeFlyer(), Mv, name)
            new.inertias[index["V"]] = inertia_tip
            continue
        parent = "V" if j in moved_joints else model.parents[j]
        M = Mv.actInv(model.jointPlacements[j]) if j in moved_joints else model.jointPlacements[j]
        jm = model.joints[j]
        q, v = slice(jm.idx_q, jm.idx_q + jm.nq), slice(jm.idx_v, jm.idx_v + jm.nv)
        index[j] = jn = new.addJoint(index[parent], jm, M, model.names[j])
        new.inertias[jn] = model.inertias[j]
        nm = new.joints[jn]
        nq, nv = slice(nm.idx_q, nm.idx_q + nm.nq), slice(nm.idx_v, nm.idx_v + nm.nv)
        for attr in ("lowerPositionLimit", "upperPositionLimit"):
            getattr(new, attr)[nq] = getattr(model, attr)[q]
        for attr in _NV_ATTRIBUTES:
            if hasattr(model, attr):
                getattr(new, attr)[nv] = getattr(model, attr)[v]
    if moved_frames:  # their inertias move from the start to the tip
        dyn = model.inertias[site.joint].toDynamicParameters()
        dyn -= Mv.act(inertia_tip).toDynamicParameters()
        new.inertias[index[site.joint]] = _inertia(dyn, model.inertias[site.joint].mass)
    for i, f in enumerate(model.frames):
        if i == 0:
            continue
        joint, M = index[f.parentJoint], f.placement
        if i in moved_frames:
            joint, M = index["V"], Mv.actInv(f.placement)
        new.addFrame(pin.Frame(f.name, joint, f.parentFrame, M, f.type, f.inertia), False)
    new.addFrame(pin.Frame(name, index["V"], site.link_frame, pin.SE3.Identity(), pin.JOINT),
                 False)  # fmt: skip
    for entry in model.referenceConfigurations:
        new.referenceConfigurations[entry.key()] = map_configuration(model, new, entry.data())
    out = []
    for geo in geometries:
        if geo is None:
            out.append(None)
            continue
        g = geo.copy()
        for obj in g.geometryObjects:
            if obj.parentFrame in moved_frames:
                obj.parentJoint, obj.placement = index["V"], Mv.actInv(obj.placement)
            else:
                obj.parentJoint = index[obj.parentJoint]
        out.append(g)
    return new, out, index


@dataclass(frozen=True)
class InsertedBeam:
    """A beam of a model built by :func:`apply_beams`: its virtual joint ``joint`` (index)
    named ``name``, the link's frame ``link_frame`` (index, the beam's clamped start), and
    ``rest`` the virtual joint's placement at rest in the link frame (its translation, (3,)
    [m], is the undeflected beam from start to tip)."""

    name: str
    link_frame: int
    joint: int
    rest: pin.SE3


def inserted_beams(model: pin.Model) -> list[InsertedBeam]:
    """The beams (their elements) of ``model``, as :func:`apply_beams` builds them: its
    ``<link>_beam`` joint frames whose parent frame is the link's body frame, on the
    joint's parent joint; of a beam split into n elements, ``<link>_beam_1`` so, then
    ``<link>_beam_k`` (and last ``<link>_beam``) whose parent frame is the joint frame of
    ``<link>_beam_{k-1}``, on its joint (``link_frame``: the element's start)."""
    out = []
    for f in model.frames:
        start = model.frames[f.parentFrame]
        j = f.parentJoint
        if f.type != pin.JOINT or start.parentJoint != model.parents[j]:
            continue
        if start.type == pin.BODY:
            names = (f"{start.name}_beam", f"{start.name}_beam_1")
        else:
            head, _, k = start.name.rpartition("_beam_")
            names = (f"{head}_beam", f"{head}_beam_{int(k) + 1}") if k.isdigit() else ()
        if start.type in (pin.BODY, pin.JOINT) and f.name in names:
            rest = start.placement.actInv(model.jointPlacements[j])
            out.append(InsertedBeam(f.name, f.parentFrame, j, rest))
    return out


#: Mass left on a beam's start after its tip's share moved, relative to the link's mass,
#: below which it is rounding of a massless remainder.
MASSLESS_RTOL = 1e-12


def _inertia(dyn: np.ndarray, link_mass: float) -> pin.Inertia:
    """The inertia of the dynamic parameters ``dyn`` (10,) (m [kg], m c [kg m], the
    rotational inertia about the frame's origin [kg m^2]); a massless remainder keeps its
    rotational part and a zero lever (Pinocchio would divide the first moment by 0)."""
    if abs(dyn[0]) > MASSLESS_RTOL * max(link_mass, 1.0):
        return pin.Inertia.FromDynamicParameters(dyn)
    ixx, ixy, iyy, ixz, iyz, izz = dyn[4:]
    rotational = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return pin.Inertia(0.0, np.zeros(3), rotational)


def map_configuration(old: pin.Model, new: pin.Model, q: np.ndarray) -> np.ndarray:
    """(new.nq,) configuration of ``new`` with the values of ``q`` (old.nq,) on the joints
    of the same name, neutral on the others (the beams' virtual joints: undeflected)."""
    q, out = np.asarray(q, float), pin.neutral(new)
    for j in range(1, old.njoints):
        jo = old.joints[j]
        jn = new.joints[new.getJointId(old.names[j])]
        out[jn.idx_q : jn.idx_q + jn.nq] = q[jo.idx_q : jo.idx_q + jo.nq]
    return out


def _matrix(beam: str, what: str, value) -> np.ndarray:
    try:
        K = np.array([float(v) for v in np.asarray(value, dtype=object).reshape(-1)])
    except (TypeError, ValueError):
        raise BeamError(beam, f"{what} is {value!r}; expected 36 numbers") from None
    if K.size != 36:
        raise BeamError(beam, f"{what} has {K.size} numbers; expected 36 (a 6x6 matrix)")
    K = K.reshape(6, 6)
    sym = np.max(np.abs(K - K.T)) <= 1e-9 * np.max(np.abs(K))
    if not (np.all(np.isfinite(K)) and sym and np.all(np.linalg.eigvalsh(0.5 * (K + K.T)) > 0)):
        raise BeamError(beam, f"{what} {K.tolist()} is not symmetric positive definite")
    return 0.5 * (K + K.T)


def _tip_stiffness(beam: str, stiffness, what: str) -> np.ndarray:
    """(6, 6) symmetric tip stiffness ``stiffness()``, once it is finite and positive
    definite in floating point.

    Raises:
        BeamError: ``what`` (the values the stiffness came from) gives a compliance or a
            stiffness beyond the float range, or one that rounding leaves indefinite.
    """
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        try:
            K = stiffness()
            K = 0.5 * (K + K.T)
            np.linalg.cholesky(K)  # also refuses NaN
        except (ZeroDivisionError, OverflowError, np.linalg.LinAlgError):
            K = None
    if K is None or not np.isfinite(K).all():
        raise BeamError(
            beam,
            f"{what} give a tip compliance or stiffness beyond the floating point range or "
            "singular to rounding; expected a material and sizes of a real link",
        )
    return K


def element_count(beam: str, spec: Mapping) -> int:
    """The ``elements:`` of a beam's entry: an integer >= 1 (default 1)."""
    n = spec.get("elements", 1)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= MAX_ELEMENTS:
        raise BeamError(beam, f"elements is {n!r}; expected an integer from 1 to {MAX_ELEMENTS}")
    return int(n)


#: Most elements a beam may be split into.
MAX_ELEMENTS = 64


def beam_stiffness(
    model: pin.Model, beam: str, spec: Mapping, shapes: list[Shape] | None = None
) -> tuple[str | None, np.ndarray, BeamMass | None]:
    """(end, K, mass) of one beam: its end joint, its (6, 6) tip stiffness in the end
    joint's axes at its origin [N/m, N/rad, N m/rad], from ``spec`` (the keys of the
    ``beams:`` entry of a closure file: end, E, G, section, theory, or stiffness_6x6 /
    compliance_6x6 given in that same frame; density [kg/m^3]; elements: split into that
    many equal elements, K then that of one of them), and its section for its own mass
    (None without a section); ``shapes``: the link's URDF shapes, for ``section:
    geometry`` (:func:`geometry_section`)."""
    if not isinstance(spec, Mapping):
        raise BeamError(beam, f"specification is {spec!r}; expected a mapping of {BEAM_KEYS}")
    unknown = set(spec) - set(BEAM_KEYS)
    if unknown:
        raise BeamError(beam, f"unknown key(s) {sorted(unknown)}; expected {list(BEAM_KEYS)}")
    end = spec.get("end")
    if end is not None and not isinstance(end, str):
        raise BeamError(beam, f"end is {end!r}; expected a joint name")
    site = _site(model, beam, end)
    density = _positive(beam, "density [kg/m^3]", spec["density"]) if "density" in spec else None
    elements = element_count(beam, spec)
    given = [k for k in ("stiffness_6x6", "compliance_6x6") if k in spec]
    if given:
        if len(given) == 2 or any(k in spec for k in ("E", "G", "section", "theory")):
            raise BeamError(beam, f"give either {given[0]} or E, G and section, not both")
        if density is not None:
            raise BeamError(beam, f"density needs a section (its area), not {given[0]}")
        if elements > 1:
            raise BeamError(beam, f"elements needs E, G and a section, not {given[0]}")
        M = _matrix(beam, given[0], spec[given[0]])
        if given[0] == "stiffness_6x6":
            return site.end, M, None
        return (
            site.end,
            _tip_stiffness(beam, lambda: np.linalg.inv(M), f"compliance_6x6 {M.tolist()}"),
            None,
        )
    missing = [k for k in ("E", "G", "section") if k not in spec]
    if missing:
        raise BeamError(beam, f"missing {missing}; expected E, G, section (or stiffness_6x6)")
    E, G = _positive(beam, "E [Pa]", spec["E"]), _positive(beam, "G [Pa]", spec["G"])
    if not -1.0 < E / (2.0 * G) - 1.0 <= 0.5:  # an isotropic material (G in GPa, not Pa?)
        raise BeamError(
            beam,
            f"E = {E:.4g} Pa and G = {G:.4g} Pa give the Poisson ratio E / (2 G) - 1 = "
            f"{E / (2.0 * G) - 1.0:.4g}; expected one in (-1, 0.5] (both in Pa)",
        )
    theory = spec.get("theory", "euler-bernoulli")
    if theory not in THEORIES:
        raise BeamError(beam, f"theory {theory!r}; expected one of {list(THEORIES)}")
    link = model.frames[site.link_frame].placement
    M_LE = link.actInv(site.placement)  # the end in the link frame
    length = float(np.linalg.norm(M_LE.translation))
    if length <= 1e-12:
        raise BeamError(beam, f"length {length} m: end {site.end!r} is at the link's origin")
    given = spec["section"]
    if given == GEOMETRY:
        given = geometry_section(beam, shapes, M_LE.translation)
    section = section_from_spec(beam, given)
    if theory == "timoshenko" and None in section.kappa(E / (2 * G) - 1):
        raise BeamError(beam, "an explicit section needs kappa_y and kappa_z for timoshenko")
    R_LB = beam_axes(beam, M_LE.translation, section.y_axis)
    K = _tip_stiffness(
        beam,
        lambda: transport_stiffness(
            np.linalg.inv(clamped_compliance(length / elements, E, G, section, theory)),
            R_LB.T @ M_LE.rotation,
        ),
        f"E = {E:.4g} Pa, G = {G:.4g} Pa, length {length:.4g} m and the section (A = "
        f"{section.A:.4g} m^2, Iy = {section.Iy:.4g}, Iz = {section.Iz:.4g}, "
        f"J = {section.J:.4g} m^4)",
    )
    return site.end, K, BeamMass(section.A, section.Iy + section.Iz, density)


#: An anchor on a beam's link within this fraction of the beam's length of its tip is at
#: the tip (the same point written twice: its rounding, far below).
TIP_RTOL = 1e-9


def apply_beams(model: pin.Model, geometries, beams: Mapping[str, Mapping], urdf=None,
                anchors=()):  # fmt: skip
    """``model`` with ``beams`` (link name -> specification, see :func:`beam_stiffness`)
    inserted as 6-dof virtual joints ``<link>_beam``, applied one after the other.

    Args:
        model: the kinematic tree (not modified).
        geometries: geometry models (or None) of ``model``, carried over.
        beams: link name -> specification.
        urdf: the URDF file of ``model``, for ``section: geometry`` (None: not allowed).
        anchors: (joint index, placement in the joint's frame) of points of ``model``
            (the closures' anchors), carried over: an anchor at a beam's tip (to
            :data:`TIP_RTOL` of its length) moves with the tip, the others stay on their
            joints.

    Returns:
        (model, geometries, springs, anchors, masses): the new model, its geometry models,
        the block springs {virtual joint name: (6, 6) K [N/m, N/rad, N m/rad]}, the
        anchors on the new model and the sections of the beams that have one {virtual
        joint name: :class:`BeamMass`}.

    Raises:
        BeamError: a bad specification (the message names the beam and the value).
    """
    if not isinstance(beams, Mapping):
        raise InvalidInputError(f"beams must be a mapping link name -> beam, got {beams!r}")
    springs, masses = {}, {}
    anchors = [(int(j), pin.SE3(M)) for j, M in anchors]
    geometries = list(geometries)
    wanted = any(isinstance(b, Mapping) and b.get("section") == GEOMETRY for b in beams.values())
    shapes = urdf_shapes(urdf) if wanted and urdf is not None else None
    for beam, spec in beams.items():
        name = f"{beam}_beam"
        if model.existJointName(name):  # before the stiffness, which would measure the link
            # from the existing beam's joint (a length of 0)
            raise BeamError(beam, f"the link already has a beam (or the model a joint named "
                            f"{name!r}): one beam a link")  # fmt: skip
        link_shapes = None if shapes is None else shapes.get(beam, [])
        end, K, mass = beam_stiffness(model, beam, spec, link_shapes)
        site = _site(model, beam, end)
        tip, start = site.placement, model.frames[site.link_frame].placement
        length = float(np.linalg.norm(tip.translation - start.translation))
        model, geometries, step = _insert(model, geometries, site, name)
        anchors = [
            (model.getJointId(name), tip.actInv(M))
            if j == site.joint
            and np.linalg.norm(M.translation - tip.translation) <= TIP_RTOL * length
            else (step[j], M)
            for j, M in anchors
        ]
        elements = [name] + [f"{name}_{k}" for k in range(1, element_count(beam, spec))]
        if len(elements) > 1:
            model, geometries, anchors = _split(model, geometries, anchors, name, len(elements))
        for element in elements:
            springs[element] = K
            if mass is not None:
                masses[element] = mass
    return model, geometries, springs, anchors, masses


def _split(model, geometries, anchors, name: str, n: int):
    """``model`` with the beam of virtual joint ``name`` split into n equal elements: the
    virtual joints ``name_1`` .. ``name_{n-1}`` inserted at its nodes (k / n of the way
    from the start, in the tip's axes), each the start of the next element, ``name`` the
    last; returns (model, geometries, anchors) (:func:`apply_beams`)."""
    tip = model.getJointId(name)
    frame = model.getFrameId(name, pin.JOINT)
    start = model.frames[model.frames[frame].parentFrame].placement  # in the parent joint
    rest = model.jointPlacements[tip]  # the tip in the parent joint
    step = (rest.translation - start.translation) / n
    node = pin.SE3(rest.rotation, start.translation + step)  # the first node, parent joint
    parent_joint, parent_frame = model.parents[tip], model.frames[frame].parentFrame
    for k in range(1, n):
        site = _Site(parent_frame, parent_joint, name, tip, frame, node)
        element = f"{name}_{k}"
        model, geometries, index = _insert(model, geometries, site, element)
        anchors = [(index[j], M) for j, M in anchors]
        parent_joint = model.getJointId(element)
        parent_frame = model.getFrameId(element, pin.JOINT)
        tip, frame = model.getJointId(name), model.getFrameId(name, pin.JOINT)
        node = pin.SE3(np.eye(3), rest.rotation.T @ step)  # the next node, in this one
    model.frames[frame].parentFrame = parent_frame  # the last element starts at its node
    return model, geometries, anchors


def insert_beams(clm, beams: Mapping[str, Mapping]):
    """:class:`ClosedLoopModel` ``clm`` with ``beams`` (:func:`apply_beams`) on its links.

    Actuated joints, springs and locked joints keep their names; closure anchors are
    carried over on their joints, those at a beam's tip with the tip (a loop of an MJCF or
    SDF file closed at the end of a link that becomes a beam); an anchor elsewhere on the
    beam's link stays with the beam's start. A configuration of ``clm`` maps to the new
    model by :func:`map_configuration`.

    Raises:
        BeamError: a bad specification (the message names the beam and the value).
    """
    from .model import ClosedLoopModel, Closure

    geoms = [clm.visual_model, clm.collision_model]
    ends = [(k.joint1_id, k.joint1_placement) for c in clm.closures for k in [c.constraint]]
    ends += [(k.joint2_id, k.joint2_placement) for c in clm.closures for k in [c.constraint]]
    model, geoms, springs, ends, masses = apply_beams(clm.model, geoms, beams, anchors=ends)
    n = len(clm.closures)
    closures = [
        Closure(type(c.constraint)(model, *ends[i], *ends[n + i]), c.name)
        for i, c in enumerate(clm.closures)
    ]
    return ClosedLoopModel(
        model,
        closures,
        clm.actuated,
        {**clm.springs, **springs},
        clm.locked,
        geoms[0],
        geoms[1],
        clm.name,
        beam_masses={**clm.beam_masses, **masses},
    )

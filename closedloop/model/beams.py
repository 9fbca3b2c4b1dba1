"""Flexible links as 6-dof virtual springs from beam theory (the Virtual Joint Method).

A flexible link is a rigid body with a 6-dof virtual spring at its end (Pashkevich,
Klimchik and Chablat's Virtual Joint Method). A *beam* on a link is straight, from the
origin of the link's frame (its start, clamped) to the origin of its ``end`` joint (the
tip): its length is that distance. The tip carries the ``end`` joint and everything beyond
it; the link's other child joints stay rigid with the start (the end joint may be named
by its child link). The ``end`` may also be a frame of the link (a site, an operational
frame) or ``anchor:<closure name>``, a closure's anchor on the link: the tip then carries
that frame or anchor only, every child joint of the link staying with the start (one at
its origin too). :func:`apply_beams` puts a
6-dof virtual joint (a Pinocchio free flyer named ``<link>_beam``) between the link and
its ``end``, placed at the end joint's origin with the end joint's axes, and gives it the
beam's tip stiffness as an SPD block spring (:mod:`closedloop.model.closed_loop`). Its coordinates
dq = (v, w) are the twist of the tip (translation [m], small rotation [rad]) in the end
joint's axes, so the block is the tip stiffness in that frame, wrench (f [N], n [N m]).

Several beams on a link: a list of entries, each with its ``end`` and an optional
``start`` (the ``end`` of another beam of the list; default: the link's origin), each a
virtual joint ``<link>_beam_<end>`` placed after its start beam's (or on the link's joint),
straight from its start to its end; its tip carries its end and the ends of the beams that
start from it, the link's inertia and other child joints staying at the origin.

The tip stiffness from beam theory: :mod:`closedloop.model.beam_theory`; the sections and
``section: geometry``: :mod:`closedloop.model.beam_section`.

Inertia: the link's own inertia stays at the beam's start (on the link's parent joint);
bodies beyond a ``fixed`` end (merged by Pinocchio's URDF parser into the link's joint)
move with the tip. Frames keep their indices (the virtual joint's frame is appended);
joints from the virtual joint on get new indices; frames, geometry objects and closure
anchors beyond the tip follow it.

Elements and mass: ``elements: N`` (default 1) splits the beam into N equal elements, a
6-dof virtual joint at each node, ``<link>_beam_1`` .. ``<link>_beam_{N-1}``, then
``<link>_beam`` at the tip, all in the end joint's axes, each with the clamped stiffness of
length L / N (:func:`closedloop.model.beam_joints.inserted_beams` lists the elements, each
from its start node).
``density`` [kg/m^3] gives the beam a mass of its own
(:class:`~closedloop.model.beam_theory.BeamMass`, the consistent mass of
:mod:`closedloop.analysis.vibration`), with a section only.

Preload: the beam's energy is that of beam theory on the tip's displacement and rotation
in its rest axes, with the shortening of the bent beam in its axial elongation
(:mod:`closedloop.model.elastic`): an axial force softens (compression) or stiffens (tension) its
bending as the one-element beam-column does (0.2 % from the closed form at P = EI / L^2;
buckling of a clamped rod at 2.486 EI / L^2, Euler's pi^2 / 4 = 2.467). At zero deflection
it is the block above: the unloaded compliance does not depend on it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from closedloop.exceptions import BeamError, InvalidInputError
from closedloop.model.beam_joints import beam_link, inserted_beams, virtual_frames
from closedloop.model.beam_section import GEOMETRY, urdf_shapes
from closedloop.model.beam_theory import (
    ANCHOR_END,
    BeamSite,
    beam_site,
    beam_stiffness,
    element_count,
)


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


def _insert(model, geometries, site: BeamSite, name: str, carried=()):
    """A copy of ``model`` (and of the geometry models) with a free-flyer ``name`` between
    the site's joint and its end (and the ends of the sites ``carried``, on the same joint:
    those of the beams that start at this one's tip); returns (model, geometries, old ->
    new joint index)."""
    moved_frames, moved_joints = set(), set()
    for s in (site, *carried):
        if s.end_joint is not None:
            moved_joints.add(s.end_joint)
        elif s.end_frame is not None:  # None: a closure's anchor, the tip carries it only
            moved_frames |= _descendant_frames(model, s.end_frame)
    moved_joints |= {
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
        new.inertias[index[site.joint]] = _inertia(dyn, model.inertias[site.joint])
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


#: Mass left on a beam's start after its tip's share moved, relative to the link's mass,
#: below which it is rounding of a massless remainder; likewise the eigenvalues of its
#: rotational inertia, relative to the link's largest about its joint's origin.
MASSLESS_RTOL = 1e-12


def _rotational(dyn: np.ndarray) -> np.ndarray:
    """(3, 3) rotational inertia [kg m^2] of the dynamic parameters ``dyn`` (10,)."""
    ixx, ixy, iyy, ixz, iyz, izz = dyn[4:]
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def _inertia(dyn: np.ndarray, link: pin.Inertia) -> pin.Inertia:
    """The inertia of the dynamic parameters ``dyn`` (10,) (m [kg], m c [kg m], the
    rotational inertia about the frame's origin [kg m^2]) left on the link of inertia
    ``link`` when its tips' inertias moved. A massless remainder keeps its rotational part
    without its rounding (eigenvalues, negative ones too, within :data:`MASSLESS_RTOL` of
    the link's: what is left when the tips took the whole mass) and a zero lever
    (Pinocchio would divide the first moment by 0)."""
    before = link.toDynamicParameters()
    if abs(dyn[0]) > MASSLESS_RTOL * max(before[0], 1.0):
        return pin.Inertia.FromDynamicParameters(dyn)
    lam, V = np.linalg.eigh(_rotational(dyn))
    scale = np.abs(np.linalg.eigvalsh(_rotational(before))).max()
    lam[lam <= MASSLESS_RTOL * scale] = 0.0
    return pin.Inertia(0.0, np.zeros(3), (V * lam) @ V.T)


def map_configuration(old: pin.Model, new: pin.Model, q: np.ndarray) -> np.ndarray:
    """(new.nq,) configuration of ``new`` with the values of ``q`` (old.nq,) on the joints
    of the same name, neutral on the others (the beams' virtual joints: undeflected)."""
    q, out = np.asarray(q, float), pin.neutral(new)
    for j in range(1, old.njoints):
        jo = old.joints[j]
        jn = new.joints[new.getJointId(old.names[j])]
        out[jn.idx_q : jn.idx_q + jn.nq] = q[jo.idx_q : jo.idx_q + jo.nq]
    return out


#: A closure anchor within this fraction of a beam's length from its tip moves with the tip.
TIP_RTOL = 1e-9


def apply_beams(model: pin.Model, geometries, beams: Mapping[str, Mapping], urdf=None,
                anchors=(), anchor_names=()):  # fmt: skip
    """``model`` with ``beams`` (link name -> specification, see :func:`beam_stiffness`)
    inserted as 6-dof virtual joints ``<link>_beam`` (a list of beams on a link:
    ``<link>_beam_<end>`` each, module docstring), applied one after the other.

    Args:
        model: the kinematic tree (not modified).
        geometries: geometry models (or None) of ``model``, carried over.
        beams: link name -> specification.
        urdf: the URDF file of ``model``, for ``section: geometry`` (None: not allowed).
        anchors: (joint index, placement in the joint's frame) of points of ``model``
            (the closures' anchors), carried over: an anchor at a beam's tip (to
            :data:`TIP_RTOL` of its length) moves with the tip, the others stay on their
            joints.
        anchor_names: the closure's name of each of ``anchors`` (or empty): a beam's
            ``end: anchor:<closure name>`` is that closure's anchor on the beam's link.

    Returns:
        (model, geometries, springs, anchors, masses): the new model, its geometry models,
        the block springs {virtual joint name: (6, 6) K [N/m, N/rad, N m/rad]}, the
        anchors on the new model and the sections of the beams that have one {virtual
        joint name: :class:`~closedloop.model.beam_theory.BeamMass`}.

    Raises:
        BeamError: a bad specification (the message names the beam and the value).
        ModelFileError: ``section: geometry`` on a link whose URDF cylinder or box has a
            size or rpy that is not finite numbers in ASCII decimal notation.
    """
    if not isinstance(beams, Mapping):
        raise InvalidInputError(f"beams must be a mapping link name -> beam, got {beams!r}")
    springs, masses = {}, {}
    anchors = [(int(j), pin.SE3(M)) for j, M in anchors]
    geometries = list(geometries)
    wanted = any(
        isinstance(b, Mapping) and b.get("section") == GEOMETRY
        for spec in beams.values() for b in (spec if isinstance(spec, list | tuple) else [spec])
    )  # fmt: skip
    shapes = urdf_shapes(urdf) if wanted and urdf is not None else None
    for link, spec in beams.items():
        plan = _plan(link, spec)
        virtual = virtual_frames(model)
        had = [
            b.name for b in inserted_beams(model)
            if beam_link(model, model.getFrameId(b.name, pin.JOINT), virtual) == link
        ]  # fmt: skip
        clash = had + [name for name, _, _ in plan if model.existJointName(name)]
        if clash:  # before the stiffness, which would measure the link from the existing
            # beam's joint (a length of 0)
            raise BeamError(link, f"the link already has a beam (or the model a joint "
                            f"named {clash[0]!r}): one entry a link")  # fmt: skip
        link_shapes = None if shapes is None else shapes.get(link, [])
        named = [(f"{ANCHOR_END}{n}", *anchors[i]) for i, n in enumerate(anchor_names)]
        sites, stiffness, ends = {}, {}, {}  # on the model before this link's beams
        for name, start, entry in plan:
            at = None
            if start is not None:
                first = sites[ends[start]]
                rotation = model.frames[first.link_frame].placement.rotation
                at = pin.SE3(rotation, first.placement.translation)
            end, K, mass = beam_stiffness(model, link, entry, link_shapes, named, at)
            sites[name] = beam_site(model, link, end, named)
            stiffness[name] = (K, mass, element_count(link, entry))
            ends[sites[name].end] = name
        before = model
        for name, start, _ in plan:
            start = None if start is None else ends[start]
            carried = [n for n, _, _ in plan if n != name and _starts_from(plan, ends, n, name)]
            origin = pin.SE3.Identity() if start is None else sites[start].placement
            moved = [_moved(sites[n], before, model, start, origin) for n in (name, *carried)]
            site = moved[0]
            points = [m.placement.translation for m in moved]
            start_point = model.frames[site.link_frame].placement.translation
            length = float(np.linalg.norm(site.placement.translation - start_point))
            model, geometries, step = _insert(model, geometries, site, name, moved[1:])
            tip = site.placement
            anchors = [
                (model.getJointId(name), tip.actInv(M))
                if j == site.joint and min(
                    np.linalg.norm(M.translation - p) for p in points) <= TIP_RTOL * length
                else (step[j], M)
                for j, M in anchors
            ]  # fmt: skip
            K, mass, n = stiffness[name]
            elements = [name] + [f"{name}_{k}" for k in range(1, n)]
            if n > 1:
                model, geometries, anchors = _split(model, geometries, anchors, name, n)
            for element in elements:
                springs[element] = K
                if mass is not None:
                    masses[element] = mass
    return model, geometries, springs, anchors, masses


def _moved(site: BeamSite, before: pin.Model, model: pin.Model, start: str | None,
           origin: pin.SE3) -> BeamSite:  # fmt: skip
    """``site`` (on ``before``, the model without the link's beams) on ``model``, starting at
    the virtual joint ``start`` placed at ``origin`` in the link's parent joint frame (None:
    the link's origin, ``origin`` the identity)."""
    joint = before.names[site.joint] if start is None else start
    end_joint = None if site.end_joint is None else model.getJointId(before.names[site.end_joint])
    return BeamSite(
        site.link_frame if start is None else model.getFrameId(start, pin.JOINT),
        model.getJointId(joint), site.end, end_joint, site.end_frame,
        origin.actInv(site.placement),
    )  # fmt: skip


def _starts_from(plan, ends: dict, name: str, root: str) -> bool:
    """Whether the beam ``name`` of ``plan`` starts, through a chain of beams, at the tip of
    the beam ``root``."""
    start = {n: s for n, s, _ in plan}
    while start[name] is not None:
        name = ends[start[name]]
        if name == root:
            return True
    return False


def _plan(link: str, spec) -> list[tuple[str, str | None, Mapping]]:
    """(virtual joint name, start (the end of another beam, None: the link's origin), the
    entry without ``start``) of each beam of the link's entry ``spec``, each after the beam
    it starts from: a mapping is one beam ``<link>_beam``, a list one beam
    ``<link>_beam_<end>`` an item."""
    if isinstance(spec, Mapping):
        return [(f"{link}_beam", None, spec)]
    if not isinstance(spec, list | tuple) or not spec:
        raise BeamError(link, f"specification is {spec!r}; expected a mapping or a non-empty "
                        "list of them")  # fmt: skip
    items = []
    for item in spec:
        if not isinstance(item, Mapping) or not isinstance(item.get("end"), str):
            raise BeamError(link, f"list item {item!r}; expected a mapping with its end (a "
                            "joint, frame or anchor name)")  # fmt: skip
        start = item.get("start")
        if start is not None and not isinstance(start, str):
            raise BeamError(link, f"start {start!r}; expected the end of another beam")
        items.append((item["end"], start, {k: v for k, v in item.items() if k != "start"}))
    ends = [end for end, _, _ in items]
    for end, start, _ in items:
        if ends.count(end) > 1:
            raise BeamError(link, f"two beams end at {end!r}; expected one beam an end")
        if start is not None and start not in ends:
            raise BeamError(link, f"start {start!r} of the beam to {end!r} is not the end of "
                            f"a beam of the list; expected one of {ends} (or no start: the "
                            "link's origin)")  # fmt: skip
    ordered, done = [], set()
    while len(ordered) < len(items):
        ready = [it for it in items if it[0] not in done and (it[1] is None or it[1] in done)]
        if not ready:
            rest = [end for end in ends if end not in done]
            raise BeamError(link, f"the beams to {rest} start from each other (a cycle); "
                            "expected chains from the link's origin")  # fmt: skip
        ordered += ready
        done |= {end for end, _, _ in ready}
    return [(f"{link}_beam_{end}", start, entry) for end, start, entry in ordered]


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
        site = BeamSite(parent_frame, parent_joint, name, tip, frame, node)
        element = f"{name}_{k}"
        model, geometries, index = _insert(model, geometries, site, element)
        anchors = [(index[j], M) for j, M in anchors]
        parent_joint = model.getJointId(element)
        parent_frame = model.getFrameId(element, pin.JOINT)
        tip, frame = model.getJointId(name), model.getFrameId(name, pin.JOINT)
        node = pin.SE3(np.eye(3), rest.rotation.T @ step)  # the next node, in this one
    model.frames[frame].parentFrame = parent_frame  # the last element starts at its node
    return model, geometries, anchors

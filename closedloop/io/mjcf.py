"""What Pinocchio's MJCF parser leaves out or reads wrong, read from the XML here.

Pinocchio 4.1 keeps neither actuators nor joint stiffness, shifts hinge and slide limits by
``ref`` and converts slide ranges as angles, ignores ``limited`` and ``active``, orders the
equalities by name (keeping one of each name), reads only the first ``<compiler>``,
``<equality>`` and root body, ignores positions and orientations given by ``<default>``
classes, fails on ``class="main"``, reads upper-case ``eulerseq`` axes as lower-case,
drops what a ``<frame>`` or ``<replicate>`` holds (the mass of a body's geoms there too) and
ignores the compiler's mass settings.
It also anchors a ``<connect>`` or ``<weld>`` at the joint of its body, dropping the body's
placement relative to that joint (a body without joint of its own is then anchored at its
parent joint's origin). :func:`read_mjcf_extras` reads the file as MuJoCo does and refuses
what Pinocchio would silently get wrong; Pinocchio reads :func:`pinocchio_copy`;
:func:`match_parsed`, :func:`place_free_joints` and :func:`anchor_equalities` correct what
it built.
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.common.input_files import read_xml
from closedloop.exceptions import IgnoredFeatureWarning, ModelFileError
from closedloop.io.mjcf_xml import (
    MJCF_EQUALITIES,
    active_equalities,
    check_classes,
    check_composite,
    check_mass_settings,
    check_numbers,
    class_defaults,
    compiler_attributes,
    element_name,
    flatten_frames,
    joints_with_defaults,
    read_numbers,
    write_classes,
)

#: Name of the body that holds several root bodies for Pinocchio (:func:`pinocchio_copy`).
WORLD_BODY = "worldbody_bodies"
#: Configuration coordinates of each MJCF joint type (ball and free: quaternions).
JOINT_NQ = {"hinge": 1, "slide": 1, "ball": 4, "free": 7}


#: Shortest hinge or slide axis (norm, the axis is normalised) that MuJoCo accepts: below
#: it MuJoCo refuses the file ("axis too small in joint"; checked with MuJoCo 4.0).
MIN_AXIS_NORM = 1e-7


@dataclass(frozen=True)
class Equality:
    """One active ``<connect>`` or ``<weld>``, as MuJoCo reads it.

    Attributes:
        tag: ``"connect"`` or ``"weld"``.
        body1, body2: the bodies' names; ``"world"`` for the world (body2 omitted).
        anchor: shape (3,) [m]: a connect's point in body1's frame; a weld's point in
            body2's frame.
        relpose: a weld's explicit ``relpose`` (position [m] in body1's frame, then
            quaternion w x y z), shape (7,); None when absent or its quaternion is zero
            (the relative pose is then the one at ``qpos0``).
    """

    tag: str
    body1: str
    body2: str
    anchor: np.ndarray
    relpose: np.ndarray | None


@dataclass(frozen=True)
class MjcfExtras:
    """What :func:`read_mjcf_extras` reads from an MJCF file.

    Attributes:
        actuated: joints an actuator drives, each once, in order of first appearance.
        stiffness: joint name -> its ``stiffness`` text [N m/rad or N/m].
        closures: names of the active ``<connect>``, then ``<weld>`` equalities, each kind
            in file order (Pinocchio's order when it reads :func:`pinocchio_copy`); an
            unnamed one is ``<tag><i>``, the i-th of its kind in the file.
        undriven: actuators that drive no joint (name, else tag).
        limits: (configuration index, lower, upper) of every hinge and slide with a range,
            as MuJoCo reads it: hinge [rad] (from the compiler's angle unit), slide [m];
            ``ref`` does not shift it; (-inf, inf) for a ``limited="false"`` one.
        nq: configuration size of the file's joints.
        equalities: the active equalities, in :attr:`closures` order.
        unweighed: body name -> why Pinocchio reads its inertia differently from MuJoCo
            (:func:`closedloop.io.mjcf_xml.check_mass_settings`): its mass and inertia are
            not to be used.
    """

    actuated: tuple[str, ...]
    stiffness: dict[str, str]
    closures: tuple[str, ...]
    undriven: tuple[str, ...]
    limits: tuple[tuple[int, float, float], ...]
    nq: int
    equalities: tuple[Equality, ...]
    unweighed: dict[str, str]


def read_mjcf_extras(path: Path) -> MjcfExtras:
    """Actuators, joint stiffness, joint limits and closure names of an MJCF file.

    ``<default>`` classes and ``childclass`` are resolved as MuJoCo does. A hinge or slide
    with ``limited="false"`` has no limits, whatever its range. A body whose inertia
    Pinocchio reads differently from MuJoCo (a mesh geom, a geom outside the inertia group
    range) is not refused but recorded in :attr:`MjcfExtras.unweighed`.

    Raises:
        ModelFileError: invalid XML, ``<include>``, a ``<replicate>`` holding anything, an
            ``<inertial>`` inside a ``<frame>``, compiler mass settings that Pinocchio ignores
            (:func:`closedloop.io.mjcf_xml.check_mass_settings`), an equality other than
            connect/weld, without body1 or joining a body to itself, an ``active`` other than
            true/false, a repeated joint, body or equality name, an unknown joint type, a hinge or
            slide whose axis is the zero vector, a range or axis that is not numbers, a range whose
            lower bound is above its upper one, a joint with a nonzero stiffness but no name, a
            malformed position or orientation
            (:data:`~closedloop.io.mjcf_xml.NUMERIC_ATTRIBUTES`), a connect without anchor, a
            class that no ``<default>`` defines, a ``limited`` other than true/false/auto,
            ``euler`` angles with an upper-case (extrinsic) ``eulerseq``, a spring on a joint that
            Pinocchio merges into a composite joint (several joints in one body), a joint
            ``springdamper`` (MuJoCo derives its stiffness from the mass), a tendon with a stiffness
            (a spring coupling joints). The message names the file.
    """
    where = f"robot file {str(path)!r}"
    root = read_xml(path, where)
    if root.find(".//include") is not None:
        raise ModelFileError(f"{where}: <include> is not supported; merge the included files")
    if root.find(".//replicate/*") is not None:  # Pinocchio drops what it holds
        raise ModelFileError(
            f"{where}: <replicate> is not supported (Pinocchio's parser drops what it holds); "
            "expected its copies written out"
        )
    check_classes(root, where)
    _check_tendons(root, where)  # before the classes are written out and removed
    seq = compiler_attributes(root).get("eulerseq", "xyz")
    if seq != seq.lower() and root.find(".//*[@euler]") is not None:
        raise ModelFileError(
            f"{where}: <compiler> eulerseq={seq!r} has upper-case (extrinsic) axes, which "
            "Pinocchio reads as intrinsic; expected lower-case axes (extrinsic 'XYZ' is "
            "intrinsic 'zyx' with the angles in reverse order)"
        )
    equalities = active_equalities(root, where)
    check_numbers(root, where)
    anchored = tuple(_equality(e, where) for _, e in equalities)
    write_classes(root)  # the joints' attributes as in the copy Pinocchio reads
    flatten_frames(root, where)
    unweighed = check_mass_settings(root, where)
    joints = joints_with_defaults(root)
    explicit = [e.get("name") for e in root.iter() if e.tag in MJCF_EQUALITIES]
    for kind, names in (
        ("body", [b.get("name") for w in root.findall("worldbody") for b in w.iter("body")]),
        ("joint", [attrs.get("name") for _, attrs in joints]),
        ("equality", explicit),
    ):
        seen: set[str] = set()
        for name in filter(None, names):
            if name in seen:
                raise ModelFileError(
                    f"{where}: repeated {kind} name {name!r} (MuJoCo refuses it); expected "
                    f"one {kind} of each name"
                )
            seen.add(name)
    to_rad = 1.0 if compiler_attributes(root).get("angle", "degree") == "radian" else math.pi / 180
    of_body: dict[int, list[dict]] = {}  # the joints of each body (a composite if several)
    for body, attrs in joints:
        of_body.setdefault(id(body), []).append(attrs)
    stiffness, limits, nq = {}, [], 0
    for body, attrs in joints:
        kind, name = attrs.get("type", "hinge"), attrs.get("name")
        what = (
            f"joint {name!r}" if name else f"an unnamed {kind} joint of body {element_name(body)}"
        )
        if kind not in JOINT_NQ:
            raise ModelFileError(
                f"{where}: {what} has type {kind!r}; expected one of {', '.join(JOINT_NQ)}"
            )
        if kind in ("hinge", "slide"):
            axis = attrs.get("axis", "0 0 1")
            if not np.linalg.norm(read_numbers(axis, 3, where, f"axis of {what}")) >= MIN_AXIS_NORM:
                raise ModelFileError(
                    f"{where}: {what}: axis {axis!r} is the zero vector; expected a direction "
                    f"(norm >= {MIN_AXIS_NORM:g}, as MuJoCo requires)"
                )
            limited = attrs.get("limited", "auto")
            if limited not in ("true", "false", "auto"):
                raise ModelFileError(
                    f"{where}: {what} has limited={limited!r}; expected 'true', 'false' or 'auto'"
                )
            if limited == "false":  # MuJoCo ignores the range
                limits.append((nq, -math.inf, math.inf))
            elif "range" in attrs:
                lo, hi = read_numbers(attrs["range"], 2, where, f"range of {what}")
                if lo > hi:  # MuJoCo refuses it (limited) or ignores it (autolimits)
                    raise ModelFileError(
                        f"{where}: range of {what} is {attrs['range']!r}: lower above upper; "
                        "expected lower <= upper"
                    )
                scale = to_rad if kind == "hinge" else 1.0  # slides: metres, never converted
                limits.append((nq, lo * scale, hi * scale))
        if "springdamper" in attrs and np.all(
            read_numbers(attrs["springdamper"], 2, where, f"springdamper of {what}") > 0
        ):  # MuJoCo then computes the stiffness from the mass, which is not read here
            raise ModelFileError(
                f"{where}: {what} has springdamper={attrs['springdamper']!r}, whose stiffness "
                "MuJoCo derives from the mass and is not read here; expected stiffness [N m/rad "
                "or N/m] instead"
            )
        if "stiffness" in attrs:
            text = attrs["stiffness"]
            if name is None and read_numbers(text, 1, where, f"stiffness of {what}")[0] != 0:
                raise ModelFileError(
                    f"{where}: {what} has stiffness {text!r} but no name; name the joint "
                    "(its spring needs a name)"
                )
            if name is not None:
                stiffness[name] = text
            check_composite(body, name, text, of_body[id(body)], where)
            _check_springref(attrs, what, where)
        nq += JOINT_NQ[kind]
    actuators = [a for act in root.findall("actuator") for a in act]
    for a in actuators:
        if a.tag == "position" and a.get("joint"):
            warnings.warn(
                f"{where}: <position> actuator {element_name(a)} is a servo spring (kp) on joint "
                f"{a.get('joint')!r}; its kp is not read: the joint is a rigid actuator unless "
                "it has a stiffness (joint stiffness, or springs in a side file)",
                IgnoredFeatureWarning,
                stacklevel=2,
            )
    return MjcfExtras(
        tuple(dict.fromkeys(a.get("joint") for a in actuators if a.get("joint"))),
        stiffness,
        tuple(name for name, _ in equalities),
        tuple(a.get("name") or a.tag for a in actuators if not a.get("joint")),
        tuple(limits),
        nq,
        anchored,
        unweighed,
    )


def _equality(element: ET.Element, where: str) -> Equality:
    """The :class:`Equality` of a checked ``<connect>`` or ``<weld>`` (a ``<default>``
    class gives an equality neither anchor nor relpose)."""
    attrs = element.attrib
    what = f"<{element.tag}> {element_name(element)}"
    anchor = read_numbers(attrs.get("anchor", "0 0 0"), 3, where, f"anchor of {what}")
    relpose = read_numbers(attrs.get("relpose", "0 1 0 0 0 0 0"), 7, where, f"relpose of {what}")
    explicit = element.tag == "weld" and relpose[3:].any()  # MuJoCo: a zero quaternion = qpos0
    body1, body2 = attrs["body1"], attrs.get("body2", "world")
    if body1 == body2:
        raise ModelFileError(
            f"{where}: {what} joins body {body1!r} to itself (MuJoCo refuses it); expected "
            "two different bodies (body2 omitted: the world)"
        )
    return Equality(element.tag, body1, body2, anchor, relpose if explicit else None)


def _check_springref(attrs: dict[str, str], what: str, where: str) -> None:
    """Warn of a hinge or slide spring whose rest ``springref`` (MuJoCo's default: 0)
    differs from its ``ref``: MuJoCo's spring is then not at rest at ``qpos0``, where the
    springs are taken at rest (a ball or free joint's spring is at rest at ``qpos0``)."""
    if attrs.get("type", "hinge") not in ("hinge", "slide"):
        return
    if not read_numbers(attrs["stiffness"], 1, where, what)[0]:
        return
    text = attrs.get("springref", "0")
    rest = read_numbers(text, 1, where, f"springref of {what}")[0]
    if rest != read_numbers(attrs.get("ref", "0"), 1, where, f"ref of {what}")[0]:
        given = "" if "springref" in attrs else " (MuJoCo's default: no springref given)"
        warnings.warn(
            f"{where}: {what} has springref={text!r}{given}, not its ref "
            f"{attrs.get('ref', '0')!r}: MuJoCo's spring is at rest at qpos = springref; here "
            "it is taken at rest at qpos0 (write springref equal to ref)",
            IgnoredFeatureWarning,
            stacklevel=3,
        )


def _check_tendons(root: ET.Element, where: str) -> None:
    """Refuse a ``<tendon>`` with a stiffness (``<default>`` classes resolved): a spring
    coupling joints, which neither Pinocchio nor the springs per joint can hold."""
    defaults = class_defaults(root, "tendon")
    for tendon in (t for section in root.findall("tendon") for t in section):
        text = {**defaults.get(tendon.get("class", "main"), {}), **tendon.attrib}.get("stiffness")
        name = element_name(tendon)
        if text is not None and read_numbers(text, 1, where, f"stiffness of tendon {name}")[0]:
            raise ModelFileError(
                f"{where}: <{tendon.tag}> tendon {name} has stiffness {text!r}: a spring "
                "coupling joints is not read; expected springs on joints (joint stiffness)"
            )


def pinocchio_copy(path: Path, folder: Path) -> Path:
    """The copy of the MJCF file that Pinocchio reads, written in ``folder``.

    MuJoCo never sees it. It differs from the file where Pinocchio would misread it:

    * Pinocchio keeps only the first body under the first ``<worldbody>``; files written
      for MuJoCo put every leg and a free-jointed platform there (MuJoCo accepts a free
      joint only on such a top-level body). It also takes a lone root body without joint
      for the world itself, dropping its pose and its sites, and drops the sites of the
      ``<worldbody>`` itself. The copy moves those sites onto a root body ``world`` (MuJoCo's
      name of the world body) without joint at the origin, then the root bodies of every
      ``<worldbody>`` into one body ``WORLD_BODY`` without joint at the world origin
      (unless there is one root body, with a joint): no pose changes and the free joint's
      ``qpos0`` stays the body's pose in the world.
    * Pinocchio reads only the first ``<compiler>``, and the assets before it with the
      default directories: the copy has one, first, that merges them in order (MuJoCo's
      rule, later attributes winning); a relative ``meshdir``, ``texturedir`` or
      ``assetdir`` is made absolute so that the copy finds the assets.
    * Pinocchio ignores the ``pos`` of a joint and the ``pos`` and orientation of a geom
      or site that a ``<default>`` class gives, leaks a ``childclass`` into an element of
      another class, and fails on ``class="main"``: the copy writes on each joint, geom,
      site, mesh and material the attributes its class gives
      (:func:`closedloop.io.mjcf_xml.write_classes`), and has neither classes nor ``<default>``.
    * Pinocchio drops what a ``<frame>`` holds: the copy has no frames, what they held
      placed by their poses (:func:`closedloop.io.mjcf_xml.flatten_frames`).
    * Pinocchio 4.1 does not normalise the axis of an ``axisangle`` (the placement is then
      not a rotation): the copy's axes are unit vectors.
    * Pinocchio reads only the first ``<equality>``, ignores ``active``, and orders the
      equalities by name keeping one of each name: the copy has the active ones only, in
      one ``<equality>``, named by their rank, so that Pinocchio returns the connects, then
      the welds, each in file order (:attr:`MjcfExtras.closures`).
    * Pinocchio knows no body ``world``, MuJoCo's name of the world body: an equality's
      ``body2="world"`` is left out (the world, for both), and ``body1="world"`` takes
      the other body's name (:func:`anchor_equalities` places the anchors).

    Call it after :func:`read_mjcf_extras` has checked the file.

    Raises:
        ModelFileError: the file is not valid XML.
    """
    where = f"robot file {str(path)!r}"
    tree = ET.ElementTree(read_xml(path, where))
    root = tree.getroot()
    worlds = root.findall("worldbody")
    for extra in worlds[1:]:
        worlds[0].extend(list(extra))
        root.remove(extra)
    active = active_equalities(root, where)  # before the classes are written out
    write_classes(root)
    flatten_frames(root, where)
    sites = worlds[0].findall("site") if worlds else []
    if sites:  # Pinocchio drops them: they go on a body named as MuJoCo's world body
        holder = ET.Element("body", name="world")
        worlds[0].insert(0, holder)
        for site in sites:
            worlds[0].remove(site)
            holder.append(site)
    roots = worlds[0].findall("body") if worlds else []
    jointless = roots and all(roots[0].find(tag) is None for tag in ("joint", "freejoint"))
    if len(roots) > 1 or jointless:
        wrapper = ET.SubElement(worlds[0], "body", name=WORLD_BODY)
        for body in roots:
            worlds[0].remove(body)
            wrapper.append(body)
    compiler = ET.Element("compiler", compiler_attributes(root))
    for key in ("meshdir", "texturedir", "assetdir"):
        if key in compiler.attrib or (key != "assetdir" and "assetdir" not in compiler.attrib):
            compiler.set(key, str(path.parent.resolve() / compiler.get(key, "")))
    for element in root.findall("compiler") + root.findall("equality"):
        root.remove(element)
    root.insert(0, compiler)
    for e in root.iter():
        if "axisangle" in e.attrib:  # checked: 4 numbers, the axis not zero
            *axis, angle = e.get("axisangle").split()
            unit = np.array(axis, dtype=float) / np.linalg.norm(np.array(axis, dtype=float))
            e.set("axisangle", " ".join([*map(repr, unit.tolist()), angle]))
    equality = ET.SubElement(root, "equality")
    for rank, (_, element) in enumerate(active):
        if element.get("body1") == "world":  # Pinocchio has no body "world": MuJoCo's world
            element.set("body1", element.attrib.pop("body2"))  # body; the anchors it
        elif element.get("body2") == "world":  # computes are replaced (anchor_equalities)
            del element.attrib["body2"]
        element.set("name", f"{rank:09d}")
        equality.append(element)
    copy = folder / path.name
    tree.write(copy)
    return copy


def match_parsed(model: pin.Model, n_constraints: int, extras: MjcfExtras, path: Path) -> None:
    """Check that Pinocchio read the file's joints and closures; put in the joint limits.

    Pinocchio 4.1 shifts hinge and slide limits by ``ref`` (``ref="0.5" range="-1 1"``
    gives [-1.5, 0.5], while q is MuJoCo's qpos) and converts slide ranges with the angle
    unit (``range="-0.01 0.02"`` in degrees gives about [-1.7e-4, 3.5e-4] m): the limits of
    every hinge and slide with a range become the file's (:attr:`MjcfExtras.limits`).
    Pinocchio decides which joints are limited (those with a range).

    Args:
        model: Pinocchio's model of :func:`pinocchio_copy`, corrected in place.
        n_constraints: number of anchor constraints Pinocchio returned.
        extras: what :func:`read_mjcf_extras` read from the file.
        path: the robot file (for messages).

    Raises:
        ModelFileError: Pinocchio's configuration size or closure count differs from the
            file's.
    """
    if (model.nq, n_constraints) != (extras.nq, len(extras.closures)):
        raise ModelFileError(
            f"robot file {str(path)!r}: Pinocchio read {model.nq} joint coordinates and "
            f"{n_constraints} closures, the file has {extras.nq} and {len(extras.closures)} "
            f"({list(extras.closures)}); expected the same"
        )
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for q, lo, hi in extras.limits:
        lower[q], upper[q] = lo, hi
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper


def place_free_joints(model: pin.Model) -> None:
    """Correct Pinocchio's placement of free joints (call before :func:`anchor_equalities`).

    Pinocchio 4.1 places the free joint of a top-level body at pos = p, quat = R at
    (I, p - R p) in the world instead of the identity, while its ``qpos0`` holds (p, R):
    the body then sits at 2 p - R p, not at p (checked on a rotated platform). MuJoCo
    allows free joints on top-level bodies only, whose parent is the world (or
    :data:`WORLD_BODY` at the origin), so the right placement is the identity. Only that
    exact wrong placement is corrected.

    Args:
        model: Pinocchio's model, corrected in place.
    """
    q0 = model.referenceConfigurations["qpos0"]

    def misplaced(j: int) -> bool:  # the placement (I, p - R p) of Pinocchio 4.1, exactly
        jm, M = model.joints[j], model.jointPlacements[j]
        if jm.shortname() != "JointModelFreeFlyer" or model.parents[j] != 0 or M.isIdentity():
            return False
        X = pin.XYZQUATToSE3(q0[jm.idx_q : jm.idx_q + 7])
        wrong = X.translation - X.rotation @ X.translation
        return np.allclose(M.rotation, np.eye(3)) and np.allclose(M.translation, wrong)

    for j in [j for j in range(1, model.njoints) if misplaced(j)]:
        model.jointPlacements[j] = pin.SE3.Identity()


def anchor_equalities(model: pin.Model, extras: MjcfExtras) -> list:
    """The anchor constraints of the file's equalities, placed as MuJoCo places them.

    Pinocchio 4.1 computes each anchor in the frame of the body's joint as if the body
    were at that joint's origin: a ``<connect>`` on a body without joint of its own (a
    fixed child of a moving body) is anchored at the parent joint's origin, and its second
    point is computed from that wrong first one (a weld's points likewise). Here each
    anchor is placed from Pinocchio's frame of the body (its placement relative to its
    joint, ``model.frames``): a connect holds body1's point ``anchor`` and the point of
    body2 that coincides with it at ``qpos0``; a weld holds body2's frame moved to
    ``anchor`` and the frame of body1 that coincides with it at ``qpos0``, or, with an
    explicit ``relpose``, body1's frame moved by ``relpose``. Bodies that carry their
    joint keep Pinocchio's placements (their frame is the joint's).

    Args:
        model: Pinocchio's model, free joints placed (:func:`place_free_joints`).
        extras: what :func:`read_mjcf_extras` read from the file.

    Returns:
        One point (connect) or frame (weld) anchor constraint per :attr:`MjcfExtras.equalities`.
    """
    data = model.createData()
    pin.forwardKinematics(model, data, model.referenceConfigurations["qpos0"])

    def body(name: str) -> tuple[int, pin.SE3]:  # (joint, body frame in that joint's frame)
        if name == "world":
            return 0, pin.SE3.Identity()
        frame = model.frames[model.getFrameId(name, pin.FrameType.BODY)]
        return frame.parentJoint, frame.placement

    out = []
    for eq in extras.equalities:
        (j1, F1), (j2, F2) = body(eq.body1), body(eq.body2)
        if eq.tag == "connect":
            M1 = F1 * pin.SE3(np.eye(3), eq.anchor)
            M2 = data.oMi[j2].inverse() * data.oMi[j1] * M1
            out.append(pin.PointAnchorConstraintModel(model, j1, M1, j2, M2))
            continue
        M2 = F2 * pin.SE3(np.eye(3), eq.anchor)
        if eq.relpose is None:
            M1 = data.oMi[j1].inverse() * data.oMi[j2] * M2
        else:
            w, x, y, z = eq.relpose[3:]
            rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
            M1 = F1 * pin.SE3(rotation, eq.relpose[:3])
        out.append(pin.FrameAnchorConstraintModel(model, j1, M1, j2, M2))
    return out

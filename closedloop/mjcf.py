"""What Pinocchio's MJCF parser leaves out: actuators, joint stiffness, closure names."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from .exceptions import ModelFileError

#: MJCF equality constraints and the closure type each gives.
MJCF_EQUALITIES = {"connect": "3d", "weld": "6d"}
#: Name of the body that holds several root bodies for Pinocchio (:func:`single_root_copy`).
WORLD_BODY = "worldbody_bodies"


def read_mjcf_extras(path: Path) -> tuple[tuple[str, ...], dict[str, str], list[str], list[str]]:
    """(actuated joints, joint stiffness texts, closure names, actuators driving no joint).

    Pinocchio's MJCF parser keeps neither actuators nor joint stiffness: they are read
    from the XML here (``<default>`` classes and ``childclass`` resolved).

    Raises:
        ModelFileError: ``<include>``, an equality other than connect/weld, a stiffness
            that is not >= 0.
    """
    where = f"robot file {str(path)!r}"
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise ModelFileError(f"{where} is not valid XML: {e}") from None
    if root.find(".//include") is not None:
        raise ModelFileError(f"{where}: <include> is not supported; merge the included files")
    equalities = [e for eq in root.findall("equality") for e in eq]
    other = sorted({e.tag for e in equalities} - set(MJCF_EQUALITIES))
    if other:
        raise ModelFileError(f"{where}: equality <{other[0]}> is not supported (connect, weld)")
    names = []
    for tag in MJCF_EQUALITIES:  # Pinocchio returns the connects, then the welds
        same = [e for e in equalities if e.tag == tag]
        names += [e.get("name") or f"{tag}{i}" for i, e in enumerate(same)]
    stiffness = dict(_joint_attribute(root, "stiffness"))
    actuators = [a for act in root.findall("actuator") for a in act]
    return (
        tuple(a.get("joint") for a in actuators if a.get("joint")),
        stiffness,
        names,
        [a.get("name") or a.tag for a in actuators if not a.get("joint")],
    )


def single_root_copy(path: Path, folder: Path) -> Path | None:
    """A copy of the MJCF file in ``folder`` with its root bodies in one body, or None.

    Pinocchio's parser keeps only the first body under ``<worldbody>``; files written
    for MuJoCo put every leg and a free-jointed platform there (MuJoCo accepts a free
    joint only on such a top-level body). The copy, read by Pinocchio only, moves them
    into one body ``WORLD_BODY`` without joint at the world origin: no pose changes and
    the free joint's ``qpos0`` stays the body's pose in the world. Relative ``meshdir``,
    ``texturedir`` and ``assetdir`` are made absolute so that the copy finds the assets.
    None when the file has at most one root body (read it as it is).

    Raises:
        ModelFileError: the file is not valid XML.
    """
    try:
        tree = ET.parse(path)
    except (ET.ParseError, OSError) as e:
        raise ModelFileError(f"robot file {str(path)!r} is not valid XML: {e}") from None
    world = tree.getroot().find("worldbody")
    roots = world.findall("body") if world is not None else []
    if len(roots) < 2 or tree.getroot().find(".//include") is not None:
        return None  # one root, or <include>, refused by read_mjcf_extras
    wrapper = ET.Element("body", name=WORLD_BODY)
    for body in roots:
        world.remove(body)
        wrapper.append(body)
    world.append(wrapper)
    compilers = tree.getroot().findall("compiler") or [ET.SubElement(tree.getroot(), "compiler")]
    for compiler in compilers:
        for key in ("meshdir", "texturedir", "assetdir"):
            default = key == "meshdir" and "assetdir" not in compiler.attrib
            if key in compiler.attrib or default:
                compiler.set(key, str(path.parent.resolve() / compiler.get(key, "")))
    copy = folder / path.name
    tree.write(copy)
    return copy


def place_free_joints(model: pin.Model, constraints: list) -> list:
    """Correct Pinocchio's placement of free joints; the constraints re-anchored at qpos0.

    Pinocchio 4.1 places the free joint of a top-level body at pos = p, quat = R at
    (I, p - R p) in the world instead of the identity, while its ``qpos0`` holds (p, R):
    the body then sits at 2 p - R p, not at p (checked on a rotated platform). MuJoCo
    allows free joints on top-level bodies only, whose parent is the world (or
    :data:`WORLD_BODY` at the origin), so the right placement is the identity. The anchors
    Pinocchio computed at ``qpos0`` on the second body of each ``<connect>`` / ``<weld>``
    are recomputed with the corrected model (same first anchors, same ``qpos0``; a weld's
    explicit ``relpose`` is not kept). Only that exact wrong placement is corrected.

    Args:
        model: Pinocchio's model, corrected in place.
        constraints: its anchor constraints (point and frame).

    Returns:
        The constraints, re-anchored when a placement was corrected.
    """
    q0 = model.referenceConfigurations["qpos0"]

    def misplaced(j: int) -> bool:  # the placement (I, p - R p) of Pinocchio 4.1, exactly
        jm, M = model.joints[j], model.jointPlacements[j]
        if jm.shortname() != "JointModelFreeFlyer" or model.parents[j] != 0 or M.isIdentity():
            return False
        X = pin.XYZQUATToSE3(q0[jm.idx_q : jm.idx_q + 7])
        wrong = X.translation - X.rotation @ X.translation
        return np.allclose(M.rotation, np.eye(3)) and np.allclose(M.translation, wrong)

    bad = [j for j in range(1, model.njoints) if misplaced(j)]
    if not bad:
        return constraints
    for j in bad:
        model.jointPlacements[j] = pin.SE3.Identity()
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    out = []
    for c in constraints:
        oM1 = data.oMi[c.joint1_id] * c.joint1_placement
        M2 = data.oMi[c.joint2_id].inverse() * oM1
        out.append(type(c)(model, c.joint1_id, c.joint1_placement, c.joint2_id, M2))
    return out


def _joint_attribute(root: ET.Element, attribute: str) -> list[tuple[str, str]]:
    """(joint name, value of ``attribute``), ``<default>`` classes and childclass resolved."""
    defaults: dict[str, dict[str, str]] = {}

    def visit_default(elem: ET.Element, inherited: dict[str, str]) -> None:
        joint = elem.find("joint")
        defaults[elem.get("class", "main")] = attrs = {
            **inherited,
            **(joint.attrib if joint is not None else {}),
        }
        for child in elem.findall("default"):
            visit_default(child, attrs)

    def visit_body(elem: ET.Element, cls: str) -> None:
        cls = elem.get("childclass", cls)
        for joint in elem.findall("joint"):
            attrs = {**defaults.get(joint.get("class", cls), {}), **joint.attrib}
            if "name" in attrs and attribute in attrs:
                values.append((attrs["name"], attrs[attribute]))
        for body in elem.findall("body"):
            visit_body(body, cls)

    values: list[tuple[str, str]] = []
    for d in root.findall("default"):
        visit_default(d, {})
    for world in root.findall("worldbody"):
        visit_body(world, "main")
    return values

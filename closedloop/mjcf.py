"""What Pinocchio's MJCF parser leaves out: actuators, joint stiffness, closure names."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from .exceptions import ModelFileError

#: MJCF equality constraints and the closure type each gives.
MJCF_EQUALITIES = {"connect": "3d", "weld": "6d"}


def read_mjcf_extras(path: Path) -> tuple[tuple[str, ...], dict[str, str], list[str], list[str]]:
    """(actuated joints, joint stiffness texts, closure names, actuators driving no joint).

    Pinocchio's MJCF parser keeps neither actuators nor joint stiffness: they are read
    from the XML here (``<default>`` classes and ``childclass`` resolved).

    Raises:
        ModelFileError: ``<include>``, several root bodies (Pinocchio would keep only the
            first), an equality other than connect/weld, a stiffness that is not >= 0.
    """
    where = f"robot file {str(path)!r}"
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise ModelFileError(f"{where} is not valid XML: {e}") from None
    if root.find(".//include") is not None:
        raise ModelFileError(f"{where}: <include> is not supported; merge the included files")
    roots = root.findall("worldbody/body")
    if len(roots) > 1:
        raise ModelFileError(
            f"{where}: {len(roots)} root bodies under <worldbody>; Pinocchio keeps only the "
            "first: wrap every ground branch in one body"
        )
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

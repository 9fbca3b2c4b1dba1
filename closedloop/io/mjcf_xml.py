"""The MJCF XML as MuJoCo reads it, for :mod:`closedloop.io.mjcf`: parsing with checked
numbers, ``<compiler>`` settings, ``<default>`` classes (checked, and written out onto the
elements), ``<frame>`` elements (composed into what they hold), joints with their class
attributes, composite joints, active equalities.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import decimals
from closedloop.exceptions import ModelFileError

#: MJCF equality constraints and the closure type each gives.
MJCF_EQUALITIES = {"connect": "3d", "weld": "6d"}


#: Numeric attributes of a fixed count, on any element: Pinocchio 4.1 reads a malformed
#: one (a word, NaN, too few numbers) as zeros, the largest double or uninitialised memory.
#: Attributes of a position or an orientation and their number of values.
NUMERIC_ATTRIBUTES = {"pos": 3, "quat": 4, "euler": 3, "axisangle": 4, "xyaxes": 6, "zaxis": 3,
                      "anchor": 3, "relpose": 7, "fromto": 6}  # fmt: skip
#: Of those, the ones whose leading values may not all be zero (a rotation needs them).
NONZERO = {"quat": 4, "axisangle": 3, "zaxis": 3}


def check_numbers(root: ET.Element, where: str) -> None:
    """:class:`ModelFileError` for a malformed :data:`NUMERIC_ATTRIBUTES` value, a zero
    quaternion or rotation axis, a mass that is not a number >= 0, or a ``<connect>``
    without its ``anchor``."""
    for e in root.iter():
        what = f"<{e.tag}>" + (f" {e.get('name')!r}" if e.get("name") else "")
        for attr, count in NUMERIC_ATTRIBUTES.items():
            text = e.get(attr)
            if text is None:
                continue
            values = read_numbers(text, count, where, f"{attr} of {what}")
            if attr in NONZERO and not values[: NONZERO[attr]].any():
                raise ModelFileError(f"{where}: {attr} of {what} is {text!r}; expected a rotation "
                                     "(not all zeros)")  # fmt: skip
        if (
            e.get("mass") is not None
            and not read_numbers(e.get("mass"), 1, where, f"mass of {what}")[0] >= 0
        ):
            raise ModelFileError(f"{where}: mass of {what} is {e.get('mass')!r}; expected >= 0 kg "
                                 "(Pinocchio reads a negative one as 0)")  # fmt: skip
        if e.tag == "connect" and e.get("anchor") is None:
            raise ModelFileError(f'{where}: {what} has no anchor; expected anchor="x y z"')


def read_numbers(text: str, count: int, where: str, what: str) -> np.ndarray:
    """``count`` finite numbers written in ``text`` in ASCII decimal notation
    (:func:`closedloop.common.arrays.decimals`), or :class:`ModelFileError`."""
    try:
        values = decimals(text)
    except ValueError:
        values = np.array([])
    if values.shape != (count,) or not np.isfinite(values).all():
        raise ModelFileError(
            f"{where}: {what} is {text!r}; expected {count} finite numbers in ASCII decimal "
            "notation"
        )
    return values


def compiler_attributes(root: ET.Element) -> dict[str, str]:
    """Attributes of the ``<compiler>`` elements, merged in order (later ones win)."""
    return {k: v for c in root.findall("compiler") for k, v in c.attrib.items()}


def check_classes(root: ET.Element, where: str) -> None:
    """Refuse a ``class`` or ``childclass`` that no ``<default>`` defines (Pinocchio's
    parser fails on it with 'unordered_map::at')."""
    defined = {"main"} | {d.get("class", "main") for d in root.iter("default")}
    for elem in root.iter():
        for key in ("class", "childclass"):
            name = elem.get(key)
            if elem.tag != "default" and name is not None and name not in defined:
                label = f" {elem.get('name')!r}" if elem.get("name") else ""
                raise ModelFileError(
                    f"{where}: <{elem.tag}>{label} has {key}={name!r}; expected one of the "
                    f"<default> classes {sorted(defined)}"
                )


def class_defaults(root: ET.Element, tag: str) -> dict[str, dict[str, str]]:
    """Default class -> attributes it gives ``tag`` elements (inherited ones included)."""
    defaults: dict[str, dict[str, str]] = {}

    def visit(elem: ET.Element, inherited: dict[str, str]) -> None:
        own = elem.find(tag)
        defaults[elem.get("class", "main")] = attrs = {
            **inherited,
            **(own.attrib if own is not None else {}),
        }
        for child in elem.findall("default"):
            visit(child, attrs)

    for d in root.findall("default"):
        visit(d, {})
    return defaults


def joints_with_defaults(root: ET.Element) -> list[tuple[ET.Element, dict[str, str]]]:
    """(body, attributes) of every joint, in Pinocchio's order (depth first, a body's
    joints before its children), of a tree whose classes are written out
    (:func:`write_classes`); ``<freejoint>`` of type free."""
    joints: list[tuple[ET.Element, dict[str, str]]] = []

    def visit(body: ET.Element) -> None:
        for j in body:
            if j.tag == "joint":
                joints.append((body, dict(j.attrib)))
            elif j.tag == "freejoint":
                joints.append((body, {**j.attrib, "type": "free"}))
        for child in body.findall("body"):
            visit(child)

    for world in root.findall("worldbody"):
        visit(world)
    return joints


def element_name(element: ET.Element) -> str:
    """The quoted ``name`` attribute of ``element`` for a message, or ``(unnamed)``."""
    return repr(element.get("name")) if element.get("name") else "(unnamed)"


def check_composite(
    body: ET.Element, name: str | None, stiffness: str, attrs: list[dict], where: str
) -> None:
    """Refuse a nonzero ``stiffness`` on one of several joints of ``body``: Pinocchio merges
    them into one composite joint, named after the first, that no spring can name."""
    if len(attrs) > 1 and read_numbers(stiffness, 1, where, f"stiffness of joint {name!r}")[0]:
        names = [a.get("name") for a in attrs]
        raise ModelFileError(
            f"{where}: joint {name!r} has stiffness {stiffness!r}, but Pinocchio merges the "
            f"joints {names} of body {element_name(body)} into one composite joint "
            f"'Composite_{names[0]}' that has no spring per joint; expected one joint with a "
            "spring per body (nest a body for each joint)"
        )


#: Elements Pinocchio reads whose attributes a ``<default>`` class may give.
CLASSED = ("joint", "geom", "site", "mesh", "material")
#: Orientations other than ``quat``: one given by a class beats the element's ``quat``.
ALTERNATIVES = {"axisangle", "xyaxes", "zaxis", "euler"}
#: What ``fromto`` overrides.
PLACING = {"pos", "quat", *ALTERNATIVES}


def write_classes(root: ET.Element) -> None:
    """Write on each :data:`CLASSED` element the attributes MuJoCo gives it: its own, then
    its ``class``'s, else the ``childclass`` of the nearest enclosing body, else "main"
    (each class holding those of the classes around it); an alternative orientation
    (:data:`ALTERNATIVES`) beats ``quat``, the element's own beating its class's, and
    ``fromto`` beats both and ``pos``. Remove ``class``, ``childclass`` and ``<default>``."""
    defaults = {tag: class_defaults(root, tag) for tag in CLASSED}

    def visit(parent: ET.Element, cls: str) -> None:
        for e in list(parent):
            if e.tag == "default":
                parent.remove(e)
                continue
            if e.tag in CLASSED:
                given = defaults[e.tag].get(e.get("class", cls), {})
                if ALTERNATIVES.intersection(e.keys()):
                    given = {k: v for k, v in given.items() if k not in ALTERNATIVES}
                e.attrib = {**given, **e.attrib}
                if "fromto" in e.attrib:  # it places the element
                    e.attrib = {k: v for k, v in e.attrib.items() if k not in PLACING}
                elif ALTERNATIVES.intersection(e.keys()):
                    e.attrib.pop("quat", None)
            visit(e, e.get("childclass", cls))
            for key in ("class", "childclass"):
                e.attrib.pop(key, None)

    visit(root, "main")


def active_equalities(root: ET.Element, where: str) -> list[tuple[str, ET.Element]]:
    """(closure name, element) of the active equalities, in
    :attr:`closedloop.io.mjcf.MjcfExtras.closures` order, from every ``<equality>``
    section; classes resolved for ``active``."""
    found = [e for eq in root.findall("equality") for e in eq]
    other = sorted({e.tag for e in found} - set(MJCF_EQUALITIES))
    if other:
        raise ModelFileError(f"{where}: equality <{other[0]}> is not supported (connect, weld)")
    defaults = class_defaults(root, "equality")
    active = []
    for tag in MJCF_EQUALITIES:  # Pinocchio returns the connects, then the welds
        for i, e in enumerate([f for f in found if f.tag == tag]):
            name = e.get("name") or f"{tag}{i}"
            if e.get("body1") is None:
                raise ModelFileError(
                    f"{where}: <{tag}> {name!r} names no body1 (site equalities are not "
                    "supported); expected body1 and optionally body2"
                )
            state = {**defaults.get(e.get("class", "main"), {}), **e.attrib}.get("active", "true")
            if state not in ("true", "false"):
                raise ModelFileError(
                    f"{where}: <{tag}> {name!r} has active={state!r}; expected 'true' or 'false'"
                )
            if state == "true":
                active.append((name, e))
    return active


def rotation(element: ET.Element, compiler: dict[str, str]) -> np.ndarray:
    """Rotation (3, 3) that the orientation of ``element`` (checked numbers, classes written
    out) gives, as MuJoCo reads it: ``quat`` (w x y z), ``axisangle``, ``euler`` (in the
    compiler's ``angle`` unit and ``eulerseq``), ``xyaxes`` or ``zaxis``; else the identity."""
    scale = 1.0 if compiler.get("angle", "degree") == "radian" else np.pi / 180
    if "axisangle" in element.attrib:
        *axis, angle = decimals(element.get("axisangle"))
        return pin.AngleAxis(angle * scale, np.array(axis) / np.linalg.norm(axis)).matrix()
    if "euler" in element.attrib:
        R = np.eye(3)
        for axis, angle in zip(
            compiler.get("eulerseq", "xyz"), decimals(element.get("euler")), strict=True
        ):
            turn = pin.AngleAxis(angle * scale, np.eye(3)["xyz".index(axis.lower())]).matrix()
            R = R @ turn if axis.islower() else turn @ R  # lower case: about the moved axes
        return R
    if "xyaxes" in element.attrib:
        values = decimals(element.get("xyaxes"))
        x = values[:3] / np.linalg.norm(values[:3])
        y = values[3:] - x * (x @ values[3:])
        y /= np.linalg.norm(y)
        return np.column_stack([x, y, np.cross(x, y)])
    if "zaxis" in element.attrib:  # the shortest turn from the z axis; about x if opposite
        z = decimals(element.get("zaxis"))
        z /= np.linalg.norm(z)
        axis = np.cross([0.0, 0.0, 1.0], z)
        sin = np.linalg.norm(axis)
        axis = axis / sin if sin >= 1e-10 else np.array([1.0, 0.0, 0.0])
        return pin.AngleAxis(np.arctan2(sin, z[2]), axis).matrix()
    w, x, y, z = decimals(element.get("quat", "1 0 0 0"))
    return pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()


def flatten_frames(root: ET.Element, where: str) -> None:
    """Replace each ``<frame>`` by what it holds, placed as the frame places it (MuJoCo's
    rule; Pinocchio 4.1 drops what a frame holds): a held element's ``pos`` and orientation
    become the frame's pose composed with its own (written as ``pos`` and ``quat``), a
    ``fromto``'s two points and a joint's ``pos`` and ``axis`` are moved likewise. Call it
    with the classes written out (:func:`write_classes`).

    Raises:
        ModelFileError: an ``<inertial>`` inside a ``<frame>``.
    """
    compiler = compiler_attributes(root)
    parents = {child: parent for parent in root.iter() for child in parent}
    for frame in [e for e in root.iter() if e.tag == "frame"]:  # outer frames first
        if frame.find("inertial") is not None:
            raise ModelFileError(
                f"{where}: <frame> {element_name(frame)} holds an <inertial>; expected it in "
                "its body, outside any <frame>"
            )
        R, t = rotation(frame, compiler), decimals(frame.get("pos", "0 0 0"))
        parent = parents[frame]
        at = list(parent).index(frame)
        for e in list(frame):
            parent.insert(at, e)
            parents[e] = parent
            at += 1
            if e.tag == "joint":
                e.set("pos", _numbers(R @ decimals(e.get("pos", "0 0 0")) + t))
                e.set("axis", _numbers(R @ decimals(e.get("axis", "0 0 1"))))
            elif e.tag == "freejoint":  # the body's pose, whatever the frame
                continue
            elif "fromto" in e.attrib:
                ends = decimals(e.get("fromto")).reshape(2, 3)
                e.set("fromto", _numbers((ends @ R.T + t).ravel()))
            else:
                quaternion = pin.Quaternion(R @ rotation(e, compiler))
                for key in ALTERNATIVES:
                    e.attrib.pop(key, None)
                e.set("pos", _numbers(R @ decimals(e.get("pos", "0 0 0")) + t))
                e.set("quat", _numbers(np.r_[quaternion.w, quaternion.vec()]))
        parent.remove(frame)


def _numbers(values: np.ndarray) -> str:
    """``values`` written in full precision."""
    return " ".join(map(repr, np.asarray(values, dtype=float).tolist()))


def check_mass_settings(root: ET.Element, where: str) -> dict[str, str]:
    """Refuse the ``<compiler>`` settings that make MuJoCo's masses differ from those
    Pinocchio 4.1 reads (``boundmass``, ``boundinertia`` or ``settotalmass`` above 0), and
    return the bodies whose inertia Pinocchio reads differently from MuJoCo: in a body whose
    inertia comes from its geoms (``inertiafromgeom`` true, or auto and no ``<inertial>``),
    a geom whose ``group`` is outside the compiler's ``inertiagrouprange`` (MuJoCo leaves its
    mass out) or a mesh (Pinocchio gives it 1 kg and 1 kg m^2 about each axis at its origin,
    whatever its shape, ``mass`` and ``density``). Call it with the classes written out
    (:func:`write_classes`) and frames flattened (:func:`flatten_frames`).

    Returns:
        body name (``"(unnamed)"`` for a body without one) -> why its inertia is wrong
        (the reasons of a body joined by "; "), in file order.

    Raises:
        ModelFileError: a compiler mass setting above 0, a malformed ``inertiagrouprange``
            or geom ``group``.
    """
    compiler = compiler_attributes(root)
    for key in ("boundmass", "boundinertia", "settotalmass"):
        text = compiler.get(key, "0")
        if read_numbers(text, 1, where, f"<compiler> {key}")[0] > 0:
            raise ModelFileError(
                f"{where}: <compiler> {key}={text!r} changes MuJoCo's masses, which "
                f"Pinocchio's parser does not; expected no {key} (the masses written out)"
            )
    text = compiler.get("inertiagrouprange", "0 5")
    low, high = read_numbers(text, 2, where, "<compiler> inertiagrouprange")
    setting = compiler.get("inertiafromgeom", "auto")
    unweighed: dict[str, list[str]] = {}
    for body in root.iter("body"):
        if setting == "false" or (setting == "auto" and body.find("inertial") is not None):
            continue
        for geom in body.findall("geom"):
            name, group = element_name(geom), geom.get("group", "0")
            reasons = unweighed.setdefault(body.get("name") or "(unnamed)", [])
            if not low <= read_numbers(group, 1, where, f"group of geom {name}")[0] <= high:
                reasons.append(
                    f"geom {name} has group {group!r}, outside <compiler> "
                    f"inertiagrouprange={text!r}: MuJoCo leaves its mass out, Pinocchio's "
                    "parser does not"
                )
            if geom.get("type") == "mesh":
                reasons.append(
                    f"geom {name} is a mesh, to which Pinocchio's parser gives 1 kg and "
                    "1 kg m^2 whatever its shape"
                )
    return {body: "; ".join(reasons) for body, reasons in unweighed.items() if reasons}

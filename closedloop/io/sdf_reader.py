"""Reading the XML of an SDFormat robot file with checks (:mod:`closedloop.io.sdf` builds the
model from it): elements by name, poses resolved through frames, axes, limits, springs and
inertias, every error naming the file and the element.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import decimals
from closedloop.common.input_files import read_xml
from closedloop.exceptions import ModelFileError

#: SDF writes "no limit" as +-1e16.
NO_LIMIT = 1e16
#: Name of the model's own frame among the poses.
MODEL = "__model__"


class SdfReader:
    """The ``<model>`` of an SDF file, its elements by name, and the checked reading of
    their values (poses through frames, axes, limits, springs, inertias); every error a
    :class:`ModelFileError` naming the file."""

    def __init__(self, path: Path):
        self.path, self.where = path, f"SDF file {str(path)!r}"
        root = read_xml(path, self.where)
        if root.tag != "sdf":
            self.fail(f"root element is <{root.tag}>; expected <sdf>")
        version = root.get("version") or "1.6"
        if not re.fullmatch(r"\d+(\.\d+)*", version, re.ASCII):
            self.fail(f"version {version!r}; expected numbers such as '1.6'")
        self.version = tuple(int(v) for v in version.split(".")[:2])
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
        """Raise a :class:`ModelFileError` of ``message``, naming the file."""
        raise ModelFileError(f"{self.where}: {message}")

    def named(self, parent: ET.Element, tag: str) -> dict[str, ET.Element]:
        """The ``<tag>`` children of ``parent`` by their names; each must have a name, used
        once (a link's unique among links, another element's among them and the links, a
        frame's also among the joints)."""
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
        """The finite numbers of ``elem``'s text (a missing element has none), as many as
        one of the counts ``n``; ``what`` names the element in the error."""
        text = (elem.text or "") if elem is not None else ""
        try:
            v = decimals(text)
        except ValueError:
            self.fail(
                f"{what} is {text.strip()!r}; expected {' or '.join(map(str, n))} numbers in "
                "ASCII decimal notation"
            )
        if v.size not in n or not np.all(np.isfinite(v)):
            self.fail(
                f"{what} has {v.size} value(s) {text.strip()!r}; expected "
                f"{' or '.join(map(str, n))} finite numbers"
            )
        return v

    def number(self, elem: ET.Element, tag: str, default: float, what: str) -> float:
        """The one finite number of ``elem``'s child ``<tag>``, or ``default`` without it."""
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
        """The text of ``elem``'s child ``<tag>``, stripped; an error if it has none."""
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
        """(lower, upper) of an ``<axis>``'s ``<limit>`` [rad or m]: infinite where it has
        none or writes :data:`NO_LIMIT`; lower above upper is an error."""
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
        """The spatial inertia of ``link`` in its own frame (SI), from its ``<inertial>``
        (mass, pose, inertia tensor; SDF's defaults where one is missing: 1 kg at the
        origin, the identity tensor); an error if it is not positive definite."""
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

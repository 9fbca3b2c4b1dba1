"""Stiffness of a beam: the tip stiffness of a clamped straight beam from its section,
material and theory (the springs of :mod:`closedloop.model.beams`).

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
section's y axis is ``y_axis`` (a vector in the link frame) made orthogonal to the beam.
Default: the link frame axis most orthogonal to the beam (the smallest ``|component|`` of the
beam's unit vector), made orthogonal to it; when the two smallest components are within
``ALIGN_TOLERANCE`` of each other (a beam along a link axis, such as the z of a cylinder)
that choice is a tie that rounding would decide, so the default is refused with a
:class:`BeamError` asking for ``y_axis``, unless the section is axisymmetric in bending
(circle, tube, square, or explicit with Iy = Iz and equal shear coefficients), whose
stiffness does not depend on the axes. A beam end at ``0 0 1`` and one at ``1e-17 0 1``
thus get the same answer or the same refusal.

``section: geometry`` (URDF files only, :func:`urdf_shapes`) takes the section from the
link's ``<collision>`` elements, or its ``<visual>`` ones when it has none: they must hold
exactly one cylinder or box (other shapes, such as meshes, are ignored), whose axis must
lie along the beam within ``ALIGN_TOLERANCE``. A cylinder gives a circle of its diameter;
a box the rectangle of its two sides across the beam: the box axis along the beam is i
(x, y, z = 0, 1, 2), the section's y axis is box axis i + 1 (mod 3), b its size, and h
the size along box axis i + 2 (mod 3). The shape's length and position are not used (the
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import decimals, real_number
from closedloop.common.input_files import read_xml
from closedloop.exceptions import BeamError, ModelFileError, did_you_mean

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
        x = real_number(value)  # YAML 1.1 reads 2.1e11 as a string; True is not 1
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

    @property
    def axisymmetric(self) -> bool:
        """Whether its stiffness is the same about every axis across the beam (Iy = Iz to
        rounding and the same shear coefficients): then the section axes do not matter."""
        return math.isclose(self.Iy, self.Iz, rel_tol=1e-12) and self.kappa_y == self.kappa_z

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
    key (None: the model-wide default of :func:`closedloop.analysis.vibration.modes`)."""

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
            y = np.asarray([real_number(v) for v in y_axis]) if seq else None
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
    yaw [rad] in the link frame, ``where`` the file and link (for messages)."""

    source: str  # "collision" or "visual"
    kind: str
    sizes: dict[str, str]
    rpy: str
    where: str


def urdf_shapes(path) -> dict[str, list[Shape]]:
    """Link name -> its collision elements (its visual ones when it has none) of the URDF
    file ``path``, for ``section: geometry``."""
    out = {}
    for link in read_xml(path, f"robot file {str(path)!r}").iter("link"):
        where = f"robot file {str(path)!r}: link {link.get('name')!r}"
        for source in ("collision", "visual"):
            shapes = []
            for element in link.findall(source):
                geometry = element.find("geometry")
                origin = element.find("origin")
                rpy = "0 0 0" if origin is None else origin.get("rpy", "0 0 0")
                for g in [] if geometry is None else list(geometry)[:1]:
                    shapes.append(Shape(source, g.tag, dict(g.attrib), rpy, where))
            if shapes:
                out[link.get("name")] = shapes
                break
    return out


def _numbers(shape: Shape, attribute: str, text: str | None, n: int) -> np.ndarray:
    """The ``n`` finite numbers of the attribute ``<tag> attribute`` (such as
    ``<cylinder> radius``) of ``shape``'s element, written ``text`` in ASCII decimal
    notation (:func:`closedloop.common.arrays.decimals`).

    Raises:
        ModelFileError: naming the file, the link, the element, the attribute and ``text``.
    """
    try:
        x = decimals(text) if isinstance(text, str) else np.zeros(0)
    except ValueError:
        x = np.zeros(0)
    if x.shape != (n,) or not np.all(np.isfinite(x)):
        raise ModelFileError(
            f"{shape.where}: <{shape.source}> {attribute} is {text!r}; expected {n} finite "
            "numbers in ASCII decimal notation"
        )
    return x


def geometry_section(beam: str, shapes: list[Shape] | None, axis: np.ndarray) -> dict:
    """The section mapping (``{shape: circle, d}`` or ``{shape: rectangle, b, h, y_axis}``)
    of ``section: geometry`` (module docstring) for a beam along ``axis`` (3,) in the link
    frame, from the link's ``shapes`` (:func:`urdf_shapes`; None: not read from a URDF).

    Raises:
        BeamError: no URDF, no cylinder or box, several of them, a shape across the beam.
        ModelFileError: the shape's size or its origin's rpy is not finite numbers in ASCII
            decimal notation.
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
    R = pin.rpy.rpyToMatrix(*_numbers(shape, "<origin> rpy", shape.rpy, 3))
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
        radius = _numbers(shape, "<cylinder> radius", shape.sizes.get("radius"), 1)
        return {"shape": "circle", "d": float(2 * radius[0])}
    size = _numbers(shape, "<box> size", shape.sizes.get("size"), 3).tolist()
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


def beam_axes(beam: str, axis: np.ndarray, y_axis, *, axisymmetric: bool = False) -> np.ndarray:
    """(3, 3) rotation whose columns are the beam axes x (along ``axis``), y, z, in the
    frame of ``axis`` (the link frame); y from ``y_axis`` or the default rule (module
    docstring).

    Args:
        beam: the beam's name, for messages.
        axis: (3,) the beam's direction in the link frame (any length > 0) [m].
        y_axis: (3,) the section's y axis in the link frame, or None for the default.
        axisymmetric: the section's stiffness does not depend on its axes
            (:attr:`Section.axisymmetric`): a tied default is then taken as it comes.

    Raises:
        BeamError: ``y_axis`` along the beam; or no ``y_axis``, a tied default and a
            section that is not axisymmetric.
    """
    x = axis / np.linalg.norm(axis)
    if y_axis is None:
        order = np.argsort(np.abs(x), kind="stable")
        low, second = np.abs(x)[order[:2]]
        if second - low <= ALIGN_TOLERANCE and not axisymmetric:
            names = " and ".join("xyz"[i] for i in sorted(order[:2]))
            raise BeamError(
                beam,
                f"the default section axis is ambiguous: the beam {np.round(x, 6).tolist()} "
                f"(link frame) is as orthogonal to link axes {names} (within "
                f"{ALIGN_TOLERANCE}) and the section is not axisymmetric; expected a "
                "section y_axis",
            )
        y = np.eye(3)[order[0]]
    else:
        y = np.asarray(y_axis, float)
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


def _matrix(beam: str, what: str, value) -> np.ndarray:
    try:
        K = np.array([real_number(v) for v in np.asarray(value, dtype=object).reshape(-1)])
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


@dataclass(frozen=True)
class BeamSite:
    """Where a beam sits: the link's frame, its parent joint, the end's placement."""

    link_frame: int
    joint: int  # parent joint of the link (the beam's start)
    end: str
    end_joint: int | None  # the moving end joint, or None for a fixed end, a frame, an anchor
    end_frame: int | None  # the end's frame (JOINT, FIXED_JOINT or OP_FRAME); None: an anchor
    placement: pin.SE3  # the end's origin and axes in the parent joint's frame


#: Prefix of a beam's ``end`` that names a closure's anchor: ``anchor:<closure name>``.
ANCHOR_END = "anchor:"


def beam_site(
    model: pin.Model, beam: str, end: str | None, anchors: Sequence[tuple] = ()
) -> BeamSite:
    """Where the beam on link ``beam`` sits in ``model``, ending at ``end``: a child joint
    of the link, a frame of the link (a fixed joint's, a site, an operational frame) or
    ``anchor:<closure name>``, one of ``anchors`` (None: the link's only child joint); a
    name that is none of those may be the child link of a child joint (``coupler_end`` for
    ``coupler_end_joint``): that joint.

    Args:
        model: the kinematic tree.
        beam: the link's name.
        end: the end's name, or None.
        anchors: (``anchor:<closure name>``, joint index, placement in the joint's frame)
            of the closures' anchors (two a closure); those on the link's joint may end
            its beam. An anchor end has the link frame's axes.

    Raises:
        BeamError: an unknown link, or an end that is not one of its child joints, frames
            or anchors (the message lists those).
    """
    bodies = [f.name for f in model.frames if f.type == pin.BODY]
    if beam not in bodies:
        raise BeamError(beam, f"unknown link{did_you_mean(beam, bodies)}; expected one of "
                        f"{bodies[:12]}")  # fmt: skip
    fl = next(i for i, f in enumerate(model.frames) if f.type == pin.BODY and f.name == beam)
    link = model.frames[fl]
    kinds = (pin.JOINT, pin.FIXED_JOINT)
    children = [i for i, f in enumerate(model.frames) if f.parentFrame == fl and f.type in kinds]
    names = [model.frames[i].name for i in children]
    frames = [
        i for i, f in enumerate(model.frames)
        if f.parentFrame == fl and f.type == pin.OP_FRAME and f.parentJoint == link.parentJoint
    ]  # fmt: skip
    on_link = {}
    for k, j, M in anchors:
        if int(j) == link.parentJoint:
            on_link.setdefault(k, (int(j), pin.SE3(M)))
    ends = names + [model.frames[i].name for i in frames] + list(on_link)
    if end is None:
        if len(children) != 1:
            raise BeamError(beam, f"the link has {len(children)} child joints {names}: give "
                            f"end, one of {ends}")  # fmt: skip
        end = names[0]
    if end in on_link:
        j, M = on_link[end]
        return BeamSite(fl, j, end, None, None, pin.SE3(link.placement.rotation, M.translation))
    carried = [  # the child joints whose child link is named end
        k for k, i in enumerate(children)
        if any(f.type == pin.BODY and f.parentFrame == i and f.name == end for f in model.frames)
    ]  # fmt: skip
    at = ends.index(end) if end in ends else carried[0] if len(carried) == 1 else None
    if at is None:
        known = model.existJointName(end) or model.existFrame(end)
        known = known or any(k == end for k, _, _ in anchors)
        what = (
            "is not a child joint of the link, nor one of its frames or anchors"
            if known
            else "is not a joint of the model, nor a frame or a closure's anchor"
        )
        raise BeamError(beam, f"end {end!r} {what}{did_you_mean(end, ends)}; expected one of "
                        f"{ends}")  # fmt: skip
    fe = (children + frames)[at]
    frame = model.frames[fe]
    if frame.type == pin.JOINT:
        j = frame.parentJoint
        return BeamSite(fl, model.parents[j], end, j, fe, model.jointPlacements[j].copy())
    return BeamSite(fl, frame.parentJoint, end, None, fe, frame.placement.copy())


#: Most elements a beam may be split into.
MAX_ELEMENTS = 64


def element_count(beam: str, spec: Mapping) -> int:
    """The ``elements:`` of a beam's entry: an integer >= 1 (default 1)."""
    n = spec.get("elements", 1)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= MAX_ELEMENTS:
        raise BeamError(beam, f"elements is {n!r}; expected an integer from 1 to {MAX_ELEMENTS}")
    return int(n)


def beam_stiffness(
    model: pin.Model,
    beam: str,
    spec: Mapping,
    shapes: list[Shape] | None = None,
    anchors: Sequence[tuple] = (),
    start: pin.SE3 | None = None,
) -> tuple[str | None, np.ndarray, BeamMass | None]:
    """(end, K, mass) of one beam: its end joint, its (6, 6) tip stiffness in the end
    joint's axes at its origin [N/m, N/rad, N m/rad], from ``spec`` (the keys of the
    ``beams:`` entry of a closure file: end, E, G, section, theory, or stiffness_6x6 /
    compliance_6x6 given in that same frame; density [kg/m^3]; elements: split into that
    many equal elements, K then that of one of them), and its section for its own mass
    (None without a section); ``shapes``: the link's URDF shapes, for ``section:
    geometry`` (:func:`geometry_section`); ``anchors``: the closures' anchors an ``end``
    may name (:func:`beam_site`); ``start``: the beam's start (origin, and the link frame's
    axes, in which a section's y_axis is given) in the link's parent joint frame (None: the
    link frame)."""
    if not isinstance(spec, Mapping):
        raise BeamError(beam, f"specification is {spec!r}; expected a mapping of {BEAM_KEYS}")
    unknown = set(spec) - set(BEAM_KEYS)
    if unknown:
        raise BeamError(beam, f"unknown key(s) {sorted(unknown)}; expected {list(BEAM_KEYS)}")
    end = spec.get("end")
    if end is not None and not isinstance(end, str):
        raise BeamError(beam, f"end is {end!r}; expected a joint, frame or anchor name")
    site = beam_site(model, beam, end, anchors)
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
    link = model.frames[site.link_frame].placement if start is None else start
    M_LE = link.actInv(site.placement)  # the end in the link frame
    length = float(np.linalg.norm(M_LE.translation))
    if length <= 1e-12:
        raise BeamError(beam, f"length {length} m: end {site.end!r} is at the beam's start")
    given = spec["section"]
    if given == GEOMETRY:
        given = geometry_section(beam, shapes, M_LE.translation)
    section = section_from_spec(beam, given)
    if theory == "timoshenko" and None in section.kappa(E / (2 * G) - 1):
        raise BeamError(beam, "an explicit section needs kappa_y and kappa_z for timoshenko")
    R_LB = beam_axes(beam, M_LE.translation, section.y_axis, axisymmetric=section.axisymmetric)
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

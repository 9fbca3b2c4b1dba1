"""A beam's cross-section: its properties (area, second moments, torsion constant, shear
coefficients) from a mapping or from the link's URDF shape, and its axes in the link frame
(the sections of :mod:`closedloop.model.beam_theory`).

Cowper's shear coefficients of a Timoshenko beam (nu = E/(2G) - 1, the Poisson ratio):
circle 6(1+nu)/(7+6nu); tube 6(1+nu)(1+m^2)^2/((7+6nu)(1+m^2)^2 + (20+12nu)m^2),
m = d_inner/d; rectangle 10(1+nu)/(12+11nu); an explicit section gives ``kappa_y``,
``kappa_z``.

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
beam runs from its start to its end).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import decimals, real_number
from closedloop.common.input_files import read_xml
from closedloop.exceptions import BeamError, ModelFileError

SHAPES = {"circle": ("d",), "tube": ("d", "t"), "rectangle": ("b", "h")}
EXPLICIT = ("A", "Iy", "Iz", "J")
#: ``section: geometry``: the section from the link's URDF cylinder or box.
GEOMETRY = "geometry"
#: Largest angle [rad] between the axis of that shape and the beam (0.057 deg): far above
#: the rounding of angles written with 4 decimals in URDF files (1.5708 for pi/2 is off by
#: 3.7e-6 rad), far below a deliberate tilt; the section is used with the beam's axes.
ALIGN_TOLERANCE = 1e-3


def positive_number(beam: str, what: str, value) -> float:
    """``value`` of the beam's ``what`` (a section size, E, G, a density) as a finite float
    > 0.

    Raises:
        BeamError: naming the beam, ``what`` and ``value``.
    """
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
    kap = {k: positive_number(beam, f"section {k}", spec.pop(k)) for k in ("kappa_y", "kappa_z")
           if k in spec}  # fmt: skip
    shape = spec.pop("shape", None)
    if shape is not None and not isinstance(shape, str):
        raise BeamError(beam, f"section shape is {shape!r}; expected one of {list(SHAPES)}")
    if shape is None:
        if set(spec) != set(EXPLICIT):
            raise BeamError(beam, f"section keys {sorted(spec)}; expected shape: "
                            f"{'|'.join(SHAPES)} with its sizes, or {list(EXPLICIT)}")  # fmt: skip
        v = {k: positive_number(beam, f"section {k}", spec[k]) for k in EXPLICIT}
        return Section(v["A"], v["Iy"], v["Iz"], v["J"], "explicit", y_axis=y_axis, **kap)
    if shape not in SHAPES or set(spec) != set(SHAPES[shape]):
        expected = ", ".join(f"{s} ({', '.join(k)})" for s, k in SHAPES.items())
        raise BeamError(beam, f"section {shape!r} with {sorted(spec)}; expected one of {expected}")
    v = {k: positive_number(beam, f"section {k}", spec[k]) for k in SHAPES[shape]}
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

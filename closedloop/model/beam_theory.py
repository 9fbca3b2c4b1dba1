"""Stiffness of a beam: the tip stiffness of a clamped straight beam from its section,
material and theory (the springs of :mod:`closedloop.model.beams`).

Tip stiffness of a clamped straight beam (length L, beam axes: x along the beam, y and
z the section's principal axes), from its tip compliance C_b (wrench at the tip, beam
axes): axial L/(E A), torsion L/(G J); bending in the x-y plane (deflection along y,
Euler-Bernoulli, second moment Iz) C[v, f_y] = L^3/(3 E Iz), C[v, n_z] = C[th_z, f_y] =
L^2/(2 E Iz), C[th_z, n_z] = L/(E Iz); in the x-z plane the same with Iy and the sign of
the v-theta coupling reversed (a force along +z turns the tip about -y). Timoshenko adds
the shear compliance L/(kappa G A) to the deflection under the transverse force, with
the section's shear coefficients kappa (Cowper's,
:meth:`closedloop.model.beam_section.Section.kappa`).

The section, its axes and ``section: geometry``: :mod:`closedloop.model.beam_section`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import real_number
from closedloop.exceptions import BeamError, did_you_mean
from closedloop.model.beam_section import (
    GEOMETRY,
    Section,
    Shape,
    beam_axes,
    geometry_section,
    positive_number,
    section_from_spec,
)

THEORIES = ("euler-bernoulli", "timoshenko")
BEAM_KEYS = (
    "end", "E", "G", "section", "theory", "stiffness_6x6", "compliance_6x6", "density",
    "elements",
)  # fmt: skip


@dataclass(frozen=True)
class BeamMass:
    """What a beam's own mass needs besides its length: the section's area A [m^2] and
    polar second moment Ip = Iy + Iz [m^4], and the density [kg/m^3] of its ``density:``
    key (None: the model-wide default of :func:`closedloop.analysis.vibration.modes`)."""

    A: float
    Ip: float
    density: float | None


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
    geometry`` (:func:`closedloop.model.beam_section.geometry_section`); ``anchors``: the
    closures' anchors an ``end`` may name (:func:`beam_site`); ``start``: the beam's start
    (origin, and the link frame's axes, in which a section's y_axis is given) in the link's
    parent joint frame (None: the link frame)."""
    if not isinstance(spec, Mapping):
        raise BeamError(beam, f"specification is {spec!r}; expected a mapping of {BEAM_KEYS}")
    unknown = set(spec) - set(BEAM_KEYS)
    if unknown:
        raise BeamError(beam, f"unknown key(s) {sorted(unknown)}; expected {list(BEAM_KEYS)}")
    end = spec.get("end")
    if end is not None and not isinstance(end, str):
        raise BeamError(beam, f"end is {end!r}; expected a joint, frame or anchor name")
    site = beam_site(model, beam, end, anchors)
    density = (
        positive_number(beam, "density [kg/m^3]", spec["density"]) if "density" in spec else None
    )
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
    E, G = positive_number(beam, "E [Pa]", spec["E"]), positive_number(beam, "G [Pa]", spec["G"])
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

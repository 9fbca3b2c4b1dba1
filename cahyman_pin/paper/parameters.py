"""The report's section on its parameters (values, sources, what is assumed) and the
one rotation convention of every table and figure."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from cahyman_pin.backends.published import CHOICES
from cahyman_pin.geometry import plate_pose
from cahyman_pin.paper.cells import LOAD_SHORT
from cahyman_pin.paper.compare import TableValues, is_level
from cahyman_pin.paper.data import FIG67, LOAD_LABELS, TABLES
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.effects import NAMED_MASSES
from cahyman_pin.paper.numbers import two_decimals
from cahyman_pin.params import (
    BEAM_FIELDS,
    K_S_PRINTED,
    WEIGHT_FIELDS,
    CaHyManParams,
    params_file_fields,
    source,
)


def parameters_section(
    doc: Document, params: CaHyManParams, params_file: Path | None = None
) -> None:
    """The parameter table (values, sources, what is assumed) and the published backend's
    choices."""
    given = f"the parameter file {str(params_file)!r}" if params_file else "no parameter file"
    fields = params_file_fields(params_file) if params_file else frozenset()
    assumed = [f.name for f in dataclasses.fields(params) if _assumed(params, f.name, fields)]
    doc.add(
        Heading("Parameters and conventions"),
        Heading("Parameters", 3),
        Paragraph(
            f"The parameters used, from the defaults of cahyman_pin/params.py and {given}. "
            "'paper' marks a value printed in the paper, 'given' a value of the parameter "
            "file; the values flagged ASSUMED are not in the paper "
            f"({', '.join(assumed) if assumed else 'none here'}); they shape every number "
            "of this report, except the beam fields ("
            f"{', '.join(BEAM_FIELDS)}), which act only where links are beams (with "
            "links_as_beams, and in the section 'Lumped springs vs beam links'), and the "
            f"masses ({', '.join(WEIGHT_FIELDS[:-1])}), which act only through the weight: "
            f"those eq. (11) names ({', '.join(NAMED_MASSES)}) in its weight terms (the "
            "published column and the effect 'weights of eq. (11)'), all of them in the "
            "section 'The weight as a preload'; the consistent and generic columns and the "
            "fits do not depend on them. "
            f"The published column always takes K_s = {K_S_PRINTED:g} N/m as printed (the "
            "first of the choices below), whatever K_s is here (the backend 'published' of "
            "the API and of 'cahyman stiffness' takes the parameters' K_s instead, '--ks "
            "printed' for the printed value)."
        ),
        Table(
            ("parameter", "value (SI)", "assumed", "source"),
            tuple(
                (
                    f.name,
                    f"{getattr(params, f.name):g}",
                    "ASSUMED" if _assumed(params, f.name, fields) else "",
                    source(params, f.name, fields),
                )
                for f in dataclasses.fields(params)
            ),
        ),
        Heading("Choices made to run the published formulation", 3),
        Table(("place", "choice"), tuple(CHOICES)),
    )


def _assumed(params: CaHyManParams, name: str, given: frozenset[str] = frozenset()) -> bool:
    return source(params, name, given).startswith("assumed")


def conventions_section(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
    """The one rotation convention of every table and figure, and its one exception."""
    level = [tv.pose.label for tv in tables if tv.level]
    if is_level(plate_pose(FIG67.si[0], params).phi):
        level.append("Figs. 6, 7")
    rising = [
        f"{tv.pose.label} load {LOAD_SHORT[j]} ({two_decimals(TABLES[tv.pose.label][3, j])})"
        for tv in tables
        if tv.level
        for j in range(len(LOAD_LABELS))
        if TABLES[tv.pose.label][3, j] > 0
    ]
    doc.add(
        Heading("Conventions", 3),
        Paragraph(
            "Every table and figure gives displacements of M in world axes (dx, dy, dz [mm]) "
            "and rotations of the arm as increments of the paper's angles (dphi, dpsi, dtheta "
            "[deg], the paper's row order) of R = Rz(theta) Ry(pi/2 - phi) Rz(psi) at the "
            "plate's pose. The published column reads the published backend's C F_M the "
            "same way, but that is in the formulation's own coordinates (choices above), "
            "not a twist at M: translations of H (the plate, eq. 9) plus the arm's deflection "
            "in plate axes (eqs. 4, 5 as printed), with no lever arm (eq. 3), and rotations "
            "the plate's rotation vector plus the arm angle about -y_p. One exception: where "
            "the plate is level (phi = 90 deg: "
            f"{', '.join(level) if level else 'none of the tables'}) the plate "
            "normal is along z, theta and psi turn about the same axis and only their sum is "
            "defined, while a tilt of the normal has no defined direction. There the rotation "
            "is given as tilt (the angle by which the plate normal turns; for the paper, "
            "|dphi|, since phi is at its largest value, 90 deg, and any tilt lowers it) and yaw "
            "d(theta + psi) (for the paper, dpsi + dtheta)."
            + (
                f" The paper prints dphi > 0 there in {', '.join(rising)}, which no small "
                "rotation of a level plate gives."
                if rising
                else ""
            )
        ),
    )

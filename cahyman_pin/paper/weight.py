"""The report's section on the weight as a preload (what eq. (11) tries)."""

from __future__ import annotations

import warnings

import numpy as np

from cahyman_pin.api import stiffness
from cahyman_pin.geometry import plate_pose
from cahyman_pin.paper.compare import ROWS_LEVEL, ROWS_REGULAR, paper_coordinates
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.effects import eq11_masses, eq11_masses_text
from cahyman_pin.paper.numbers import fmt
from cahyman_pin.params import CaHyManParams
from closedloop.exceptions import JointLimitWarning


def weight_rows(params: CaHyManParams) -> list[tuple[str, np.ndarray, float]]:
    """(pose label, sag of M (6,) [m, rad], relative change of C) under the weight of the
    masses of the eq. (11) effect (:func:`eq11_masses`), as a preload (generic backend)."""
    heavy = params.replace(**eq11_masses(params))
    out = []
    for pose in TABLE_POSES:
        alpha, alpha4, s4 = pose.si
        unloaded = stiffness(alpha, alpha4, s4, params=heavy)
        with warnings.catch_warnings():  # at full or zero stroke the sag may pass a limit
            warnings.simplefilter("ignore", JointLimitWarning)
            weighed = stiffness(alpha, alpha4, s4, params=heavy, weight=True)
        change = np.linalg.norm(weighed.C - unloaded.C) / np.linalg.norm(unloaded.C)
        out.append((pose.label, weighed.details["compliance"].sag, float(change)))
    return out


def weight_section(doc: Document, params: CaHyManParams) -> None:
    """Add the section (module docstring) to ``doc``, for ``params``."""
    doc.add(
        Heading("The weight as a preload (what eq. (11) tries)"),
        Paragraph(
            "Eq. (11) puts the weights into the load matrix, divided by load components that "
            "are zero in the tables' columns. The consistent way is a preload: the machine "
            f"settles under its weight ({eq11_masses_text(params)}, as in the effect above, "
            "placed where eq. (11)'s lever arms put them: cahyman_pin/urdf_builder.py), and "
            "the compliance is the "
            "tangent one at that equilibrium (geometric stiffness and loop curvature "
            "included). Below: the sag of M from the unloaded pose (mm, and the paper's angles "
            "in deg, see 'Conventions') and "
            "the relative change of C (Frobenius norm), generic backend. A linear model's "
            "answer to a load does not depend on the weight; the tangent one changes by the "
            "amount shown, which is the size of what eq. (11) could add."
        ),
    )
    rows = []
    for (label, sag, change), pose in zip(weight_rows(params), TABLE_POSES, strict=True):
        plate = plate_pose(pose.si[0], params)
        v = paper_coordinates(sag, float(plate.phi), float(plate.theta))
        names = ROWS_LEVEL[3:] if len(v) == 5 else ROWS_REGULAR[3:]
        rot = ", ".join(
            f"{n.split(' [')[0]} {fmt(x, 3, '+')}" for n, x in zip(names, v[3:], strict=True)
        )
        rows.append((label, *(fmt(x, 3, "+") for x in v[:3]), rot, fmt(change, 2)))
    doc.add(Table(("pose", "dx [mm]", "dy [mm]", "dz [mm]", "rotation [deg]", "|dC| / |C|"),
                  tuple(rows)))  # fmt: skip

"""Accounting for the differences between the published tables and the consistent model.

Each effect is one damaged place of the paper's closed form (see
:data:`cahyman_pin.backend_published.CHOICES`), switched from its as-published reading to
its consistent one while every other place stays as published; the change it makes in
each table cell, in the paper's units, is its contribution.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from closedloop.exceptions import ClosedLoopError

from .backend_published import PublishedOptions
from .paper_compare import backend_compliance, paper_coordinates
from .paper_data import LOADS, TABLE_POSES, PaperPose
from .params import CaHyManParams


@dataclass(frozen=True)
class Effect:
    """A damaged place and the option change that repairs it."""

    name: str
    change: dict
    note: str


EFFECTS = (
    Effect("lever arm of eq. (3)", {"lever_arm": True},
           "plate twist at H transported to M (rotation x lever arm) before the sum"),
    Effect("K_s value", {"ks": "params"},
           "0.697 N/m as printed -> the assumed 0.697e6 N/m"),
    Effect("weights of eq. (11)", {"weights": False},
           "weight terms dropped (gravity belongs to a separate preload)"),
    Effect("A_d damage, eqs. (18)-(19)", {"a_d": "printed"},
           "A_d as printed (secant form, singular where y_1 = 0 or C_psi = 0) instead of "
           "the Jacobian of the closed-form kinematics"),
    Effect("K_T dropped in eq. (14)", {"leg_block": "3x3"},
           "leg block keeps K_Tk (condensed 3x3) instead of the printed first 2x2"),
    Effect("the arm model of eqs. (4)-(8)", {"serial_form": "series", "serial_frame": "world"},
           "C_ser = As diag(1/K) As^T in world axes instead of the pseudo-inverses"),
    Effect("the leg model and M_FN, M_FT", {"leg_block": "consistent", "m_fn": "consistent",
                                           "m_ft": "transport"},
           "three-spring leg compliance, G^T for M_FN and the wrench transport for M_FT"),
)  # fmt: skip


def cell_values(
    pose: PaperPose, params: CaHyManParams, options: PublishedOptions
) -> np.ndarray | None:
    """(n_rows, 3) table cells of the as-published backend with ``options``; None if singular."""
    cols = []
    try:
        for load in LOADS:
            C, phi, theta = backend_compliance("published", pose, params, load, options)
            cols.append(paper_coordinates(C @ load, phi, theta))
    except ClosedLoopError:
        return None
    return np.column_stack(cols)


def effect_changes(params: CaHyManParams) -> dict[str, dict[str, np.ndarray | None]]:
    """Change of every table cell when each effect is repaired alone.

    Returns:
        ``{effect name: {table label: (n_rows, 3) change [mm, deg] or None (singular)}}``.
    """
    base = {p.label: cell_values(p, params, PublishedOptions()) for p in TABLE_POSES}
    out: dict[str, dict[str, np.ndarray | None]] = {}
    for effect in EFFECTS:
        options = dataclasses.replace(PublishedOptions(), **effect.change)
        out[effect.name] = {}
        for p in TABLE_POSES:
            v = cell_values(p, params, options)
            out[effect.name][p.label] = None if v is None or base[p.label] is None else (
                v - base[p.label]
            )
    return out

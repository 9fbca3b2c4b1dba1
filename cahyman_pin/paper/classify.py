"""Every published cell classified: reproduced, explained by a named effect, or unexplained.

A printed cell is compared through its quantity (:mod:`cahyman_pin.paper.cells`; at the
level plate dphi through the tilt, dpsi and dtheta through their sum). With p the
published value, m the consistent model with the report's parameters and h the half-width
of the rounding of the printed digits, the first rule that holds gives the class:

1. *reproduced*: |m - p| <= h;
2. *explained* by the fitted stiffness values, or by the fitted dimensions
   (:mod:`cahyman_pin.paper.fit`): the fit is within h of p; size: its change of the cell;
3. *explained* by a damaged place of the paper's equations
   (:data:`cahyman_pin.paper.effects.EFFECTS`): leaving that one damage in place,
   m - (its repair's change), is within h of p; size: that change;
4. *explained* by the non-linearity of the published row (a linear quantity only): the
   residual after the stiffness fit is at most the distance the nearest linear triple
   must keep from this cell (:attr:`cahyman_pin.paper.cells.FloorTriple.shares`) plus h;
   size: column 3 - column 1 - column 2 of that row;
5. *unexplained*; size: the residual after the stiffness fit.
"""

from __future__ import annotations

from dataclasses import dataclass

from cahyman_pin.paper.cells import (
    linearity_floor,
    model_values,
    printed_cells,
    quantities,
    quantity_of_cell,
)
from cahyman_pin.paper.data import TABLES
from cahyman_pin.paper.effects import EFFECTS, effect_changes
from cahyman_pin.paper.fit import dimension_fit, stiffness_fit
from cahyman_pin.params import CaHyManParams

#: The three classes.
CLASSES = ("reproduced", "explained", "unexplained")


@dataclass(frozen=True)
class CellClass:
    """The class of one printed cell (values in mm or deg).

    Attributes:
        table, row, load: the cell (row index into the printed rows, load column).
        printed: the printed value.
        compared_as: the quantity's row label (e.g. "tilt [deg]" for a level dphi).
        published: the compared published value (p).
        reference: the consistent model with the report's parameters (m).
        stiffness_fit, dimension_fit: the two fits' values of the quantity.
        kind: one of :data:`CLASSES`.
        reason: the rule or the named effect.
        size: the effect's size, or the residual (see the module docstring).
    """

    table: str
    row: int
    load: int
    printed: float
    compared_as: str
    published: float
    reference: float
    stiffness_fit: float
    dimension_fit: float
    kind: str
    reason: str
    size: float


def _effect_at(changes, effect: str, table: str, row: str, load: int, rows) -> float | None:
    d = changes[effect][table]
    return None if d is None else float(d[rows.index(row), load])


def classify(params: CaHyManParams) -> tuple[CellClass, ...]:
    """The class of every printed cell, in :func:`printed_cells` order (54)."""
    qs = quantities(params)
    ref = model_values(params)
    sfit, dfit = stiffness_fit(params), dimension_fit(params)
    changes = effect_changes(params)
    share = {}
    for t in linearity_floor(params):
        share.update({k: (s, t.residual) for k, s in zip(t.indices, t.shares, strict=True)})
    out = []
    for table, row, load in printed_cells():
        k = quantity_of_cell(params, table, row, load)
        q = qs[k]
        p, m, h = q.published, ref[k], q.half_width
        rows = tuple(x.row for x in qs if x.table == table and x.load == load)
        kind, reason, size = "unexplained", "residual after the stiffness fit", sfit.values[k] - p
        if abs(m - p) <= h:
            kind, reason, size = "reproduced", "within the rounding", m - p
        elif abs(sfit.values[k] - p) <= h:
            kind, reason, size = "explained", "the fitted stiffness values", sfit.values[k] - m
        elif abs(dfit.values[k] - p) <= h:
            kind, reason, size = "explained", "the fitted dimensions", dfit.values[k] - m
        else:
            for e in EFFECTS:
                d = _effect_at(changes, e.name, table, q.row, load, rows)
                if d is not None and abs(m - d - p) <= h:
                    kind, reason, size = "explained", f"damage: {e.name}", -d
                    break
            else:
                if k in share and abs(sfit.values[k] - p) <= share[k][0] + h:
                    kind, reason, size = "explained", "non-linearity of the row", share[k][1]
        out.append(
            CellClass(table, row, load, float(TABLES[table][row, load]), q.row, p, float(m),
                      float(sfit.values[k]), float(dfit.values[k]), kind, reason, float(size))
        )  # fmt: skip
    return tuple(out)


def counts(classes: tuple[CellClass, ...]) -> dict[str, int]:
    """Number of cells per class."""
    return {c: sum(x.kind == c for x in classes) for c in CLASSES}


def largest_unexplained(classes: tuple[CellClass, ...]) -> CellClass | None:
    """The unexplained cell with the largest residual (None if there is none)."""
    un = [c for c in classes if c.kind == "unexplained"]
    return max(un, key=lambda c: abs(c.size)) if un else None

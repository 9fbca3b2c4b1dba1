"""Every published cell classified: reproduced, explained by a named effect, or unexplained.

A printed cell is compared through its quantity (:mod:`cahyman_pin.paper.cells`; at the
level plate dphi through the tilt, dpsi and dtheta through their sum). With p the
published value, m the consistent model with the report's parameters and h the half-width
of the rounding of the printed digits, the first rule that holds gives the class:

1. *reproduced*: ``|m - p|`` <= h;
2. *explained* by the fitted stiffness values, or by the fitted dimensions
   (:mod:`cahyman_pin.paper.fit`): the fit is within h of p; size: its change of the cell;
3. *explained* by a damaged place of the paper's equations
   (:data:`cahyman_pin.paper.effects.EFFECTS`): the change d that repairing it alone makes
   at the as-published backend matches the gap, ``|m - d - p|`` <= h (a first-order reading:
   the damages are taken as additive); size: -d. An effect shown with illustrative
   parameters (the masses of eq. (11)) explains nothing: the report's model has no such
   term;
4. *explained* by the non-linearity of the published row (a linear quantity only): the
   stiffness fit is within h of the weighted nearest triple of that row that adds up
   (column 3 = column 1 + column 2, :attr:`cahyman_pin.paper.cells.FloorTriple.nearest`),
   so that what separates it from the published cell is the row's non-linearity; size:
   p minus that nearest value;
5. *unexplained*; size: the residual after the stiffness fit.

h is the half-width of the rounding of the printed digits (0.005 mm or deg per printed
cell): the only tolerance that the printed numbers themselves justify.
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
#: A coarser rounding that many printed translations suggest (their second decimal is 0):
#: 0.1 mm, half-width 0.05 mm.
COARSE_STEP = 0.1


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
    nearest = {}
    for t in linearity_floor(params):
        nearest.update(dict(zip(t.indices, t.nearest, strict=True)))
    effects = [e for e in EFFECTS if not e.params_change]
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
            for e in effects:
                d = _effect_at(changes, e.name, table, q.row, load, rows)
                if d is not None and abs(m - d - p) <= h:
                    kind, reason, size = "explained", f"damage: {e.name}", -d
                    break
            else:
                if k in nearest and abs(sfit.values[k] - nearest[k]) <= h:
                    kind, reason, size = "explained", "non-linearity of the row", p - nearest[k]
        out.append(
            CellClass(table, row, load, float(TABLES[table][row, load]), q.row, p, float(m),
                      float(sfit.values[k]), float(dfit.values[k]), kind, reason, float(size))
        )  # fmt: skip
    return tuple(out)


def counts(classes: tuple[CellClass, ...]) -> dict[str, int]:
    """Number of cells per class."""
    return {c: sum(x.kind == c for x in classes) for c in CLASSES}


def largest_unexplained(classes: tuple[CellClass, ...], rotation: bool) -> CellClass | None:
    """The unexplained translation (or rotation) cell with the largest residual (None if
    there is none): millimetres and degrees are not compared."""
    un = [c for c in classes
          if c.kind == "unexplained" and c.compared_as.endswith("[deg]") == rotation]  # fmt: skip
    return max(un, key=lambda c: abs(c.size)) if un else None


def coarse_translations(classes: tuple[CellClass, ...]) -> tuple[int, int, int]:
    """(printed translations, those whose second printed decimal is 0, those of the
    latter that the reference model or a fit would reach within COARSE_STEP / 2 [mm] and
    that are not reproduced or explained by a fit now): how much a rounding to 0.1 mm
    would change the classes."""
    trans = [c for c in classes if c.compared_as.endswith("[mm]")]
    zero = [c for c in trans if round(abs(c.printed) * 100) % 10 == 0]
    half = COARSE_STEP / 2
    gained = [
        c for c in zero
        if not (c.kind == "reproduced" or c.reason.startswith("the fitted"))
        and min(abs(v - c.published) for v in (c.reference, c.stiffness_fit, c.dimension_fit))
        <= half
    ]  # fmt: skip
    return len(trans), len(zero), len(gained)

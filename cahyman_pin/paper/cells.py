"""The published cells as compared quantities, their weights and the linearity floor.

The 54 printed cells (3 tables x 6 rows x 3 loads, :data:`cahyman_pin.paper.data.TABLES`)
are compared through *quantities* in the paper's coordinates
(:func:`cahyman_pin.paper.compare.paper_coordinates`): at a regular pose (Table 3) each
cell is one quantity; where the plate is level (phi = 90 deg, Tables 1 and 2) dphi is
compared as the tilt ``|dphi|`` and dpsi, dtheta together as the yaw dpsi + dtheta, so 54
cells give 48 quantities. Values are in mm (translations) and deg (rotations).

Weights. The tables print two decimals, so each printed cell carries a rounding error
uniform in +-0.005 (sd 0.01/sqrt(12)); a yaw sums two printed cells. On top of that a
relative error :data:`RELATIVE_ERROR` of each published value is assumed, which makes the
weighting independent of the unit of each component (mm or deg):

    sd_q = sqrt(n_q 0.01^2 / 12 + (RELATIVE_ERROR p_q)^2),

n_q the number of printed cells of quantity q and p_q its published value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cahyman_pin.backends.consistent import consistent_breakdown
from cahyman_pin.paper.compare import ROWS_LEVEL, ROWS_REGULAR, is_level, paper_coordinates
from cahyman_pin.paper.data import LOADS, ROWS, TABLE_POSES, TABLES
from cahyman_pin.params import CaHyManParams

#: Unit of the last printed digit of every published cell (mm or deg).
PRINTED_STEP = 0.01
#: Relative error assumed for every published value (see the module docstring).
RELATIVE_ERROR = 0.10
#: Signs of the loads F, N, F+N in the linearity residual r = c_3 - c_1 - c_2.
LINEARITY_SIGNS = np.array([-1.0, -1.0, 1.0])
#: Short names of the three load columns.
LOAD_SHORT = ("F", "N", "F+N")


@dataclass(frozen=True)
class Quantity:
    """One compared quantity: a published cell, or two at the level plate (yaw).

    Attributes:
        table: table label ("Table 1", ...).
        load: load column 0, 1, 2 (:data:`cahyman_pin.paper.data.LOADS`).
        row: compared row label (:data:`~cahyman_pin.paper.compare.ROWS_REGULAR` or
            :data:`~cahyman_pin.paper.compare.ROWS_LEVEL`).
        cells: indices of the printed rows (:data:`~cahyman_pin.paper.data.ROWS`) it is
            made of.
        published: its published value [mm or deg].
        linear: False for the tilt, a norm; every other quantity is linear in the load.
    """

    table: str
    load: int
    row: str
    cells: tuple[int, ...]
    published: float
    linear: bool

    @property
    def half_width(self) -> float:
        """Half-width of the rounding interval of the printed digits [mm or deg]."""
        return 0.5 * PRINTED_STEP * len(self.cells)

    @property
    def sd(self) -> float:
        """Standard deviation given to the published value [mm or deg]."""
        return self.sd_with(RELATIVE_ERROR)

    def sd_with(self, relative_error: float) -> float:
        """Standard deviation with another relative error (0: the rounding alone)."""
        rounding = PRINTED_STEP * np.sqrt(len(self.cells) / 12.0)
        return float(np.hypot(rounding, relative_error * self.published))

    @property
    def label(self) -> str:
        """Where the value is printed: table, load and row."""
        return f"{self.table} {LOAD_SHORT[self.load]} {self.row}"


def _pose_parts(params: CaHyManParams):
    """[(C (6, 6) at M [SI], phi, theta [rad])] of the consistent model at the table poses
    (one batched call)."""
    si = [pose.si for pose in TABLE_POSES]
    b = consistent_breakdown(
        np.array([s[0] for s in si]),
        np.array([s[1] for s in si]),
        np.array([s[2] for s in si]),
        params,
    )
    return [(b.C[k], float(b.pose.phi[k]), float(b.pose.theta[k])) for k in range(len(si))]


def quantities(params: CaHyManParams) -> tuple[Quantity, ...]:
    """The 48 compared quantities, table by table, load by load, row by row."""
    out = []
    for pose, (_, phi, _) in zip(TABLE_POSES, _pose_parts(params), strict=True):
        p = TABLES[pose.label]
        level = is_level(phi)
        for j in range(len(LOADS)):
            if level:
                groups = ((0,), (1,), (2,), (3,), (4, 5))
                values = (*p[:3, j], abs(p[3, j]), p[4, j] + p[5, j])
                rows = ROWS_LEVEL
            else:
                groups = tuple((i,) for i in range(6))
                values = tuple(p[:, j])
                rows = ROWS_REGULAR
            for i, (g, v) in enumerate(zip(groups, values, strict=True)):
                linear = not (level and i == 3)
                out.append(Quantity(pose.label, j, rows[i], g, float(v), linear))
    return tuple(out)


def model_values(params: CaHyManParams) -> np.ndarray:
    """(48,) the consistent model's values of :func:`quantities` [mm or deg]."""
    return np.concatenate(
        [paper_coordinates(LOADS @ C, phi, theta).ravel() for C, phi, theta in _pose_parts(params)]
    )


def published_values(params: CaHyManParams) -> np.ndarray:
    """(48,) published values of :func:`quantities` [mm or deg]."""
    return np.array([q.published for q in quantities(params)])


def standard_deviations(
    params: CaHyManParams, relative_error: float = RELATIVE_ERROR
) -> np.ndarray:
    """(48,) standard deviation of every quantity [mm or deg] (:attr:`Quantity.sd`, or
    with another relative error: 0 for the rounding alone)."""
    return np.array([q.sd_with(relative_error) for q in quantities(params)])


@dataclass(frozen=True)
class FloorTriple:
    """What the non-linearity of one published row costs any linear model.

    Attributes:
        table, row: the table and compared row.
        indices: (3,) indices of the quantities of loads F, N, F+N.
        residual: column 3 - column 1 - column 2 of the published values [mm or deg].
        rms_floor: the least distance (root sum of squares over the three cells) of any
            triple with column 3 = column 1 + column 2 from the published one, ``|r|``/sqrt(3).
        chi2_floor: the least weighted sum of squares, r^2 / (sd_1^2 + sd_2^2 + sd_3^2).
        nearest: (3,) the weighted nearest triple with column 3 = column 1 + column 2
            (the one of ``chi2_floor``): the published values moved by -s_k r sd_k^2 /
            sum sd^2, s = (-1, -1, +1) [mm or deg].
    """

    table: str
    row: str
    indices: tuple[int, int, int]
    residual: float
    rms_floor: float
    chi2_floor: float
    nearest: tuple[float, float, float]


def linearity_floor(params: CaHyManParams) -> tuple[FloorTriple, ...]:
    """The floor of every linear row (the tilt, a norm, is only bound by the triangle
    inequality, see :func:`tilt_triangle_ok`)."""
    qs = quantities(params)
    out = []
    for pose in TABLE_POSES:
        for row in dict.fromkeys(q.row for q in qs if q.table == pose.label and q.linear):
            idx = tuple(
                next(
                    k for k, q in enumerate(qs) if (q.table, q.load, q.row) == (pose.label, j, row)
                )
                for j in range(3)
            )
            p = np.array([qs[k].published for k in idx])
            var = np.array([qs[k].sd for k in idx]) ** 2
            r = float(p[2] - p[0] - p[1])
            nearest = p - LINEARITY_SIGNS * r * var / var.sum()
            out.append(
                FloorTriple(
                    pose.label, row, idx, r, abs(r) / np.sqrt(3.0), r * r / var.sum(),
                    tuple(float(x) for x in nearest),
                )
            )  # fmt: skip
    return tuple(out)


def tilt_triangle_ok(params: CaHyManParams) -> dict[str, bool]:
    """Per level table: do the published tilts ``|dphi|`` of the three loads satisfy the
    triangle inequality ``|t1 - t2|`` <= t3 <= t1 + t2, as the tilt of any linear model does?"""
    qs = quantities(params)
    out = {}
    for pose in TABLE_POSES:
        t = [q.published for q in qs if q.table == pose.label and not q.linear]
        if t:
            out[pose.label] = abs(t[0] - t[1]) <= t[2] <= t[0] + t[1]
    return out


def printed_cells() -> tuple[tuple[str, int, int], ...]:
    """Every printed cell as (table, printed row index, load index): 3 x 6 x 3 = 54."""
    return tuple(
        (pose.label, i, j)
        for pose in TABLE_POSES
        for j in range(len(LOADS))
        for i in range(len(ROWS))
    )


def quantity_of_cell(params: CaHyManParams, table: str, row: int, load: int) -> int:
    """Index of the quantity a printed cell is compared through."""
    qs = quantities(params)
    return next(
        k for k, q in enumerate(qs) if q.table == table and q.load == load and row in q.cells
    )

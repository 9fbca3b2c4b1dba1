"""The published CaHyMan results: the paper's configurations, loads and Tables 1-3.

These are reference data typed from the paper, in the paper's units (mm, deg). Each
table is (6, 3): rows dx, dy, dz [mm], dphi, dpsi, dtheta [deg] (the paper's row order,
psi before theta), columns the three loads of :data:`LOADS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The paper, as its text gives it. The text names no venue and no date; its latest
#: reference is a paper "submitted" in 2001, so it dates from 2001 or later.
PAPER_AUTHORS = "G. Carbone, M. Ceccarelli, M. Teolis"
PAPER_TITLE = "A Numerical Evaluation of the Stiffness of CaHyMan (Cassino Hybrid Manipulator)"
PAPER_AFFILIATION = (
    "Laboratory of Robotics and Mechatronics, DiMSAT, University of Cassino, Cassino, Italy"
)
PAPER_LATEST_REFERENCE_YEAR = 2001


def citation() -> str:
    """The paper's citation, with what its text does not give said so."""
    return (
        f'{PAPER_AUTHORS}, "{PAPER_TITLE}", {PAPER_AFFILIATION}. The text names neither '
        f"venue nor year; its most recent reference is dated {PAPER_LATEST_REFERENCE_YEAR} "
        f"(submitted), so it is from {PAPER_LATEST_REFERENCE_YEAR} or later."
    )


@dataclass(frozen=True)
class PaperPose:
    """A configuration of the paper in its units: alpha_k, alpha_4 [deg], s_4 [mm]."""

    label: str
    alpha_deg: tuple[float, float, float]
    alpha4_deg: float
    s4_mm: float

    @property
    def si(self) -> tuple[np.ndarray, float, float]:
        """(alpha (3,) [rad], alpha_4 [rad], s_4 [m])."""
        return np.deg2rad(self.alpha_deg), float(np.deg2rad(self.alpha4_deg)), self.s4_mm * 1e-3

    def describe(self) -> str:
        """The pose's inputs in the paper's units (deg, mm), one line."""
        a = ", ".join(f"{x:g}" for x in self.alpha_deg)
        return f"alpha_1..3 = {a} deg, alpha_4 = {self.alpha4_deg:g} deg, s_4 = {self.s4_mm:g} mm"


#: The three tables' configurations (Table 3's caption misprints s_4 as "alpha_4 = 0mm").
TABLE_POSES = (
    PaperPose("Table 1", (90.0, 90.0, 90.0), 90.0, 50.0),
    PaperPose("Table 2", (30.0, 30.0, 30.0), 30.0, 0.0),
    PaperPose("Table 3", (45.0, 60.0, 75.0), 45.0, 0.0),
)

#: The three load columns F_M = (F_e [N], N_e [N m]) of every table.
LOADS = np.array(
    [
        [1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        [1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
    ]
)
LOAD_LABELS = ("Fe=(1,1,1) N, Ne=0", "Fe=0, Ne=(1,1,1) N m", "Fe=(1,1,1) N, Ne=(1,1,1) N m")

#: Row labels of the tables, in the paper's order.
ROWS = ("dx [mm]", "dy [mm]", "dz [mm]", "dphi [deg]", "dpsi [deg]", "dtheta [deg]")

#: Published displacements, (6, 3) per table: rows ROWS, columns LOADS.
TABLES = {
    "Table 1": np.array(
        [
            [0.10, -0.50, -0.50],
            [0.01, 0.01, 0.01],
            [0.37, -3.07, -2.70],
            [-0.92, -0.85, -0.74],
            [0.84, 1.52, 1.33],
            [-0.57, 0.99, 0.66],
        ]
    ),
    "Table 2": np.array(
        [
            [-0.50, 7.60, 7.10],
            [-0.40, 6.30, 5.90],
            [-0.40, 5.70, 5.30],
            [-1.01, 3.04, 2.87],
            [0.97, -2.49, -2.35],
            [-0.08, 0.21, 0.65],
        ]
    ),
    "Table 3": np.array(
        [
            [0.01, -0.30, -0.20],
            [0.01, -0.10, -0.10],
            [0.01, -0.20, -0.20],
            [-0.79, 0.22, 0.34],
            [0.78, -0.21, -0.33],
            [9.34, 0.43, -2.54],
        ]
    ),
}

#: Configurations of Figs. 5-7 (Fig. 5's swept variable takes its own range).
FIG5A = PaperPose("Fig. 5a", (60.0, 60.0, 60.0), 60.0, 25.0)
FIG5BCD = PaperPose("Fig. 5b-d", (60.0, 60.0, 60.0), 60.0, 50.0)
FIG67 = PaperPose("Figs. 6, 7", (60.0, 60.0, 60.0), 60.0, 50.0)


def linearity_residual(table: np.ndarray) -> np.ndarray:
    """(6,) column 3 minus (column 1 + column 2) of a published table (paper units)."""
    table = np.asarray(table, float)
    return table[:, 2] - (table[:, 0] + table[:, 1])

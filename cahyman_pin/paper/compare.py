"""Displacements of CaHyMan in the paper's table coordinates, for every backend.

The tables report, for a wrench at M, the displacement of M (dx, dy, dz [mm]) and the
rotation of the arm as increments of the paper's angles (dphi, dpsi, dtheta [deg]) of
R = Rz(theta) Ry(pi/2 - phi) Rz(psi), evaluated at the plate's pose. At phi = 90 deg
(Tables 1 and 2: all alpha_k equal, plate level) only theta + psi is defined: there the
rotation is compared as yaw d(theta + psi) and tilt (angle by which the plate normal
turns, = ``|dphi|`` there).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cahyman_pin.angles import COS_PHI_MIN, rotvec_to_euler_increments, yaw_tilt_increments
from cahyman_pin.api import CaHyManStiffness, stiffness
from cahyman_pin.backends.published import PublishedOptions, published_stiffness
from cahyman_pin.geometry import plate_pose
from cahyman_pin.paper.data import LOADS, TABLES, PaperPose
from cahyman_pin.params import CaHyManParams
from closedloop.exceptions import ClosedLoopError

#: Backends compared, in table-column order, with their titles (their registered names).
BACKENDS = {"published": "published", "consistent": "consistent", "generic": "generic"}
#: Row labels at a regular pose.
ROWS_REGULAR = ("dx [mm]", "dy [mm]", "dz [mm]", "dphi [deg]", "dpsi [deg]", "dtheta [deg]")
#: Row labels at phi = 90 deg (a level plate: theta and psi are one turn, the tilt ``|dphi|``).
ROWS_LEVEL = ("dx [mm]", "dy [mm]", "dz [mm]", "tilt [deg]", "yaw d(theta+psi) [deg]")


@dataclass(frozen=True)
class TableValues:
    """Displacements of one table, (n_rows, 3 loads), in the paper's units, per source."""

    pose: PaperPose
    level: bool
    rows: tuple[str, ...]
    values: dict[str, np.ndarray]


def is_level(phi: float) -> bool:
    """True when the plate is level (phi = 90 deg): the paper's angles are singular."""
    return abs(np.cos(phi)) < COS_PHI_MIN


def paper_coordinates(twist: np.ndarray, phi: float, theta: float) -> np.ndarray:
    """Twist at M -> table rows (mm, deg): 6 regular rows, or 5 rows at phi = 90 deg.

    Args:
        twist: (..., 6) (dx, dy, dz [m], rx, ry, rz [rad]) at M, world axes.
        phi, theta: plate angles at the pose [rad].

    Returns:
        (..., 6) (dx, dy, dz [mm], dphi, dpsi, dtheta [deg]), or (..., 5) (dx, dy, dz [mm],
        tilt, yaw d(theta + psi) [deg]) where the plate is level.
    """
    twist = np.asarray(twist, float)
    mm = twist[..., :3] * 1e3
    if is_level(phi):
        yaw, tilt = yaw_tilt_increments(twist[..., 3:], phi, theta)
        return np.concatenate([mm, np.rad2deg(np.stack([tilt, yaw], -1))], -1)
    d_phi, d_theta, d_psi = np.moveaxis(
        rotvec_to_euler_increments(twist[..., 3:], phi, theta), -1, 0
    )
    return np.concatenate([mm, np.rad2deg(np.stack([d_phi, d_psi, d_theta], -1))], -1)


def published_in_level_rows(table: np.ndarray) -> np.ndarray:
    """Published (6, 3) table -> (5, 3) rows of :data:`ROWS_LEVEL` (tilt = ``|dphi|``)."""
    return np.vstack([table[:3], np.abs(table[3]), table[4] + table[5]])


def backend_compliance(
    backend: str, pose: PaperPose, params: CaHyManParams, load=None, options=None
) -> tuple[np.ndarray, float, float]:
    """(C (6, 6) at M [SI], phi, theta [rad]) of one backend at a paper pose.

    The as-published backend takes the load (for its weight terms) and its options.
    """
    alpha, alpha4, s4 = pose.si
    if backend == "published":
        r = published_stiffness(alpha, alpha4, s4, params, options=options, load=load)
        return r.C, float(r.pose.phi), float(r.pose.theta)
    r = stiffness(alpha, alpha4, s4, params=params, backend=backend)
    return r.C, r.pose.phi, r.pose.theta


def backend_stiffness(backend: str, pose: PaperPose, params: CaHyManParams) -> CaHyManStiffness:
    """The API's stiffness of one backend at a paper pose: its K, det K and eigenvalues are
    those of :func:`cahyman_pin.api.stiffness` (from a square-root factor of C for the
    consistent and generic backends). The published backend takes the printed K_s, as its
    column of the tables, and no load (no weight terms).

    Raises:
        ClosedLoopError: the API's refusal (e.g. a closed form's C of numerical rank < 6).
    """
    if backend == "published":
        params = params.with_ks("printed")
    return stiffness(*pose.si, params=params, backend=backend)


def table_values(
    pose: PaperPose, params: CaHyManParams, options: PublishedOptions | None = None
) -> TableValues:
    """Every backend's displacements at a table pose, beside the published ones."""
    published = TABLES[pose.label]
    # the rows follow the pose, whichever backends fail there
    level = bool(is_level(plate_pose(pose.si[0], params).phi))
    rows = ROWS_LEVEL if level else ROWS_REGULAR
    values: dict[str, np.ndarray] = {}
    for backend in BACKENDS:
        cols = []
        for load in LOADS:
            try:
                C, phi, theta = backend_compliance(backend, pose, params, load, options)
                cols.append(paper_coordinates(C @ load, phi, theta))
            except ClosedLoopError:
                cols.append(np.full(len(rows), np.nan))
        values[backend] = np.column_stack(cols)
    values["paper"] = published_in_level_rows(published) if level else published
    return TableValues(pose, level, rows, values)

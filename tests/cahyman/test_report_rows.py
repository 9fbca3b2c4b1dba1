"""The report's computed rows, recomputed here from C and the load.

For every table, load column and backend, the row values are the displacement C F_M of
the backend converted to the paper's coordinates: translations in mm, rotations as
increments of the paper's angles of R = Rz(theta) Ry(pi/2 - phi) Rz(psi) (eq. 6). Here
the increments are central differences: the plate is turned by +-eps times the computed
rotation vector and the angles are read off the turned plate's rotation matrix, with no
use of :mod:`cahyman_pin.angles`. At the level plate of Tables 1 and 2 (phi = 90 deg) the
rows are the tilt of the plate normal and the yaw d(theta + psi). The recomputed rows must
equal :func:`cahyman_pin.paper.compare.table_values` and the numbers printed in
``report.md``, in the paper's row order (dphi, dpsi, dtheta).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cahyman_pin.api import stiffness
from cahyman_pin.backends.published import published_stiffness
from cahyman_pin.paper.compare import table_values
from cahyman_pin.paper.data import LOAD_LABELS, LOADS, TABLE_POSES, TABLES
from cahyman_pin.params import DEFAULT_PARAMS

BACKENDS = ("published", "consistent", "generic")
#: Row labels as the paper orders them (psi before theta), and at the level plate.
ROWS_REGULAR = ("dx [mm]", "dy [mm]", "dz [mm]", "dphi [deg]", "dpsi [deg]", "dtheta [deg]")
ROWS_LEVEL = ("dx [mm]", "dy [mm]", "dz [mm]", "tilt [deg]", "yaw d(theta+psi) [deg]")
LEVEL = {"Table 1": True, "Table 2": True, "Table 3": False}  # alpha_1 = alpha_2 = alpha_3

# The plate is turned by at most ROT_STEP [rad]: central differences of smooth angle
# functions then have truncation error ~ROT_STEP^2 = 1e-10 and round-off ~1e-16 / ROT_STEP
# = 1e-11 relative; 1e-7 leaves margin. Entries that vanish are compared to 1e-7 of the
# largest entry of their column.
ROT_STEP = 1e-5
FD_RTOL = 1e-7
# report.md prints 4 significant digits (relative rounding <= 5e-4) and "0" below 1e-9;
# the diff column 3 significant digits (<= 5e-3). A row swap or a sign error moves a cell
# by far more (Table 3: dpsi = -1.0 dtheta to 2 %).
MD_RTOL = 5e-4 + FD_RTOL
MD_ZERO = 1e-9
DIFF_RTOL = 5e-3 + FD_RTOL


def euler_angles(R: np.ndarray) -> np.ndarray:
    """(phi, theta, psi) [rad] of R = Rz(theta) Ry(pi/2 - phi) Rz(psi), cos(phi) > 0.

    Eq. (6): R[2, 2] = sin phi, R[:2, 2] = cos phi (cos theta, sin theta),
    R[2, :2] = cos phi (-cos psi, sin psi).
    """
    return np.array([
        np.arctan2(R[2, 2], np.hypot(R[0, 2], R[1, 2])),
        np.arctan2(R[1, 2], R[0, 2]),
        np.arctan2(R[2, 1], -R[2, 0]),
    ])  # fmt: skip


def yaw(R: np.ndarray) -> float:
    """theta + psi [rad] of R = Rz(theta) Ry(beta) Rz(psi): the sum is smooth at beta = 0.

    R[0, 0] + R[1, 1] = (1 + cos beta) cos(theta + psi), R[1, 0] - R[0, 1] the same with sin.
    """
    return float(np.arctan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1]))


def wrapped(x: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * x))


def rows_by_differences(twist: np.ndarray, R: np.ndarray, level: bool) -> np.ndarray:
    """Table rows (mm, deg) of a twist at M (world axes) with the plate at orientation R."""
    omega = twist[3:]
    n = np.linalg.norm(omega)
    eps = ROT_STEP / n if n > 0 else 1.0
    turned = [Rotation.from_rotvec(sign * eps * omega).as_matrix() @ R for sign in (1, -1)]
    if level:
        normal = R[:, 2]
        turns = [np.arctan2(np.linalg.norm(np.cross(normal, t[:, 2])), normal @ t[:, 2])
                 for t in turned]  # fmt: skip
        tilt = np.mean(turns) / eps
        d_yaw = wrapped(yaw(turned[0]) - yaw(turned[1])) / (2 * eps)
        rot = [tilt, d_yaw]
    else:
        change = wrapped(euler_angles(turned[0]) - euler_angles(turned[1]))
        d_phi, d_theta, d_psi = change / (2 * eps)
        rot = [d_phi, d_psi, d_theta]  # the paper's row order
    return np.concatenate([twist[:3] * 1e3, np.rad2deg(rot)])


def recomputed(pose, backend: str) -> np.ndarray:
    """(n_rows, 3) rows of one table for one backend, columns the loads of the paper."""
    alpha, alpha4, s4 = pose.si
    cols = []
    for load in LOADS:
        if backend == "published":
            r = published_stiffness(alpha, alpha4, s4, DEFAULT_PARAMS, load=load)
        else:
            r = stiffness(alpha, alpha4, s4, params=DEFAULT_PARAMS, backend=backend)
        assert np.isclose(np.cos(r.pose.phi), 0.0, atol=1e-12) == LEVEL[pose.label]
        cols.append(rows_by_differences(r.C @ load, r.pose.R, LEVEL[pose.label]))
    return np.column_stack(cols)


def paper_rows(label: str) -> np.ndarray:
    """The published table in the report's rows (level plate: tilt = |dphi|, yaw sum)."""
    t = TABLES[label]
    if LEVEL[label]:
        return np.vstack([t[:3], np.abs(t[3]), t[4] + t[5]])
    return t


@pytest.fixture(scope="module")
def expected():
    return {p.label: {b: recomputed(p, b) for b in BACKENDS} for p in TABLE_POSES}


def number(cell: str) -> float:
    return np.nan if cell == "n/a" else float(cell)


def markdown_tables(text: str) -> dict[str, tuple[list[str], list[list[str]]]]:
    """Caption -> (header, rows) of every captioned table of a report.md."""
    out = {}
    for m in re.finditer(r"^\*(.+)\*\n\n((?:\|.*\|\n)+)", text, flags=re.M):
        lines = [[c.strip() for c in line.strip().strip("|").split("|")]
                 for line in m.group(2).splitlines()]  # fmt: skip
        out[m.group(1)] = (lines[0], lines[2:])
    return out


@pytest.fixture(scope="module")
def markdown(default_report):
    return markdown_tables((default_report[0] / "report.md").read_text())


def assert_rows(actual, desired, err_msg=""):
    desired = np.asarray(desired, float)
    for j in range(desired.shape[1]):  # vanishing entries against their load column
        np.testing.assert_allclose(actual[:, j], desired[:, j], rtol=FD_RTOL,
                                   atol=FD_RTOL * np.abs(desired[:, j]).max(),
                                   err_msg=f"{err_msg}, load {j + 1}")  # fmt: skip


@pytest.mark.parametrize("pose", TABLE_POSES, ids=lambda p: p.label)
def test_table_values_are_C_times_the_load_in_paper_coordinates(pose, expected):
    tv = table_values(pose, DEFAULT_PARAMS)
    assert tv.level == LEVEL[pose.label]
    assert tv.rows == (ROWS_LEVEL if LEVEL[pose.label] else ROWS_REGULAR)
    for b in BACKENDS:
        assert tv.values[b].shape == expected[pose.label][b].shape, b
        assert_rows(tv.values[b], expected[pose.label][b], f"{pose.label}, {b}")
    np.testing.assert_array_equal(tv.values["paper"], paper_rows(pose.label))


def test_the_differences_read_the_angles_they_claim():
    """A turn about the plate normal is a pure dpsi, about world z a pure dtheta (Table 3)."""
    pose = TABLE_POSES[2]
    R = published_stiffness(*pose.si).pose.R
    for axis, row in ((R[:, 2], 4), (np.array([0.0, 0.0, 1.0]), 5)):
        rows = rows_by_differences(np.concatenate([np.zeros(3), 1e-3 * axis]), R, False)
        expected = np.zeros(6)
        expected[row] = np.rad2deg(1e-3)
        np.testing.assert_allclose(rows, expected, atol=1e-9)


@pytest.mark.parametrize("pose", TABLE_POSES, ids=lambda p: p.label)
def test_report_md_prints_the_recomputed_rows(pose, expected, markdown):
    rows_labels = ROWS_LEVEL if LEVEL[pose.label] else ROWS_REGULAR
    paper = paper_rows(pose.label)
    for j, load_label in enumerate(LOAD_LABELS):
        caption = f"{pose.label}, load {load_label}"
        assert caption in markdown, caption
        header, rows = markdown[caption]
        assert [r[0] for r in rows] == list(rows_labels), caption
        cells = np.array([[number(c) for c in r[1:]] for r in rows])
        col = {name: i for i, name in reversed(list(enumerate(header[1:])))}
        np.testing.assert_allclose(cells[:, col["paper"]], paper[:, j], rtol=MD_RTOL)
        for b in BACKENDS:
            want = expected[pose.label][b][:, j]
            got = cells[:, col[b]]
            atol = MD_ZERO + FD_RTOL * np.abs(want).max()
            np.testing.assert_allclose(
                got, want, rtol=MD_RTOL, atol=atol, err_msg=f"{caption}, {b}"
            )
            diff = cells[:, col[b] + 1]  # the "diff" column right of each backend
            assert header[col[b] + 2] == "diff", header
            np.testing.assert_allclose(diff, want - paper[:, j], rtol=DIFF_RTOL, atol=atol,
                                       err_msg=f"{caption}, {b} - paper")  # fmt: skip

"""The report with parameters far from the paper's: springs many orders apart.

References are independent of the report and of the API's algorithm: the consistent
closed form's square-root factor B (C = B B^T) inverted in 50 digits (mpmath) gives K,
det K and the eigenvalues of K; the level plate of Tables 1 and 2 follows from the pose
(alpha_1 = alpha_2 = alpha_3). The report used to form K = inv(C) for the consistent and
generic backends, which keeps only eps cond(K_s) of the smallest eigenvalues (0.6953
printed for 0.697 at cond(K_s) 4e13), and stopped with a ValueError where a backend fails
at every load of a level table.
"""

from __future__ import annotations

import re

import mpmath as mp
import numpy as np
import pytest

from cahyman_pin.backends.consistent import consistent_breakdown
from cahyman_pin.cli import main
from cahyman_pin.paper import figures
from cahyman_pin.paper.compare import ROWS_LEVEL, table_values
from cahyman_pin.paper.data import FIG5BCD, TABLE_POSES
from cahyman_pin.paper.differences import effects_section
from cahyman_pin.paper.document import Document, Paragraph, Table
from cahyman_pin.paper.matrices import matrices_section
from cahyman_pin.paper.summary import summary_section
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED

P = DEFAULT_PARAMS
#: Cranks 1e7 times stiffer, K_s as printed: scaled condition numbers 2e12 .. 4e13 at the
#: table and Fig. 5 poses, full rank for every backend (the old report ran to the end).
FAR = P.replace(K_b=P.K_b * 1e7, K_d=P.K_d * 1e7, K_s=K_S_PRINTED)
#: Cranks 1e9 times stiffer: the published formulation is singular at every table pose
#: and the API refuses the consistent backend (rank 5 by the rank rule); generic answers.
FARTHER = P.replace(K_b=P.K_b * 1e9, K_d=P.K_d * 1e9, K_s=K_S_PRINTED)
#: report.md prints 4 significant digits: relative rounding <= 5e-4.
PRINTED_RTOL = 5e-4
#: The summary's differences print 3 significant digits: relative rounding <= 5e-3.
SUMMARY_RTOL = 5e-3
#: K and det K from a square-root factor are accurate to about eps sqrt(cond(K_s)) per
#: eigenvalue (closedloop.common.conditioning): 1.5e-9 at cond(K_s) 4e13 (measured: 4e-10 on
#: det K); inv(C) erred by eps cond(K_s), 1e-4 .. 3e-3 here.
FACTOR_RTOL = 1e-8


def reference(pose, params):
    """(K (6, 6), det K, eigenvalues ascending (6,)) [SI] of the consistent closed form at
    ``pose``: its factor B inverted in 50 digits."""
    B = consistent_breakdown(*pose.si, params).B
    with mp.workdps(50):
        Bm = mp.matrix(B.tolist())
        K = (Bm * Bm.T) ** -1
        ev = sorted(mp.eigsy(K)[0])
        det = mp.det(K)
    return np.array(K.tolist(), dtype=float), float(det), np.array([float(e) for e in ev])


def _blocks(doc, kind):
    return [b for b in doc.blocks if isinstance(b, kind)]


def _matrices(params):
    doc = Document("t")
    matrices_section(doc, params)
    return doc


def _numbers(cells):
    return np.array([float(c) for c in cells])


def test_matrices_are_the_factor_numbers_not_those_of_inv_C():
    doc = _matrices(FAR)
    k_tables = [t for t in _blocks(doc, Table) if t.caption.startswith("K (generic)")]
    index_tables = [t for t in _blocks(doc, Table) if t.header[1] == "det K"]
    gaps = [p.text for p in _blocks(doc, Paragraph) if p.text.startswith("Largest difference")]
    assert len(k_tables) == len(index_tables) == len(gaps) == len(TABLE_POSES)
    for pose, k_table, index_table, gap in zip(TABLE_POSES, k_tables, index_tables, gaps,
                                               strict=True):  # fmt: skip
        K_ref, det_ref, ev_ref = reference(pose, FAR)
        printed = np.array([_numbers(row[1:]) for row in k_table.rows])
        np.testing.assert_allclose(printed, K_ref, rtol=PRINTED_RTOL,
                                   atol=FACTOR_RTOL * np.abs(K_ref).max())  # fmt: skip
        rows = {row[0]: row for row in index_table.rows}
        for backend in ("consistent", "generic"):
            _, det, ev = rows[backend]
            np.testing.assert_allclose(float(det), det_ref, rtol=PRINTED_RTOL)
            np.testing.assert_allclose(_numbers(ev.split(", ")), ev_ref, rtol=PRINTED_RTOL)
        # both backends within FACTOR_RTOL of the reference: they differ by twice that at most
        assert float(re.search(r"entry: (\S+)\.$", gap)[1]) < 2 * FACTOR_RTOL, gap


@pytest.mark.parametrize("backend", ["consistent", "generic"])
def test_figure5_det_is_that_of_the_factor(backend):
    _, det_ref, _ = reference(FIG5BCD, FAR)
    np.testing.assert_allclose(figures._det_K(backend, FIG5BCD, FAR), det_ref, rtol=FACTOR_RTOL)


def test_table_rows_follow_the_pose_where_backends_fail():
    """Table 1 is level (alpha_1 = alpha_2 = alpha_3): five rows for every backend, also
    for one that gives no cell (the published, singular there: it had six, the generic
    column five)."""
    tv = table_values(TABLE_POSES[0], FARTHER)
    assert tv.level and tv.rows == ROWS_LEVEL
    assert tv.values["published"].shape == (5, 3) and np.isnan(tv.values["published"]).all()
    for backend in ("consistent", "generic"):
        assert tv.values[backend].shape == (5, 3) and np.isfinite(tv.values[backend]).all()


def test_report_where_the_published_form_gives_nothing(tmp_path, capsys):
    """The whole report with FARTHER: written (it stopped with a ValueError), no 'nan', the
    refused published backend 'n/a' with its reason, the two others the reference's (the
    consistent backend refused these springs too, 18 orders apart, before its rank rule
    took its kinematic part)."""
    out = tmp_path / "r"
    (tmp_path / "p.yaml").write_text("K_b: 2.625e15\nK_d: 2.625e15\nK_s: 0.697\n")
    assert main(["report", "--params", str(tmp_path / "p.yaml"), "--out", str(out)]) == 0
    capsys.readouterr()
    text = (out / "report.md").read_text()
    assert not re.search(r"\bnan\b", text, re.IGNORECASE)
    section = text.split("## Stiffness matrices at the three configurations")[1]
    section = section.split("\n## ")[0]  # up to the next section
    for pose, part in zip(TABLE_POSES, section.split("### ")[1:], strict=True):
        rows = {r[0]: r for r in (
            [c.strip() for c in line.strip("|").split("|")] for line in part.splitlines()
            if line.startswith("| ")
        )}  # fmt: skip
        assert rows["published"][1:] == ["n/a", "n/a"]
        _, det_ref, ev_ref = reference(pose, FARTHER)
        for backend in ("consistent", "generic"):
            np.testing.assert_allclose(float(rows[backend][1]), det_ref, rtol=PRINTED_RTOL)
            np.testing.assert_allclose(_numbers(rows[backend][2].split(", ")), ev_ref,
                                       rtol=PRINTED_RTOL)  # fmt: skip


@pytest.mark.parametrize("params", [P, P.replace(K_T=P.K_T * 1e6)], ids=["paper", "K_T x 1e6"])
def test_springs_are_called_printed_only_when_they_are(params):
    """The texts that name the printed springs give the parameters' values: 1/K_T of a leg
    motor in deg per N m, called printed only at the paper's K_T."""
    tables = [table_values(pose, params) for pose in TABLE_POSES]
    doc = Document("t")
    summary_section(doc, params, tables)
    effects_section(doc, params, tables)
    text = " ".join(p.text for p in _blocks(doc, Paragraph))
    printed = params.K_T == P.K_T
    leg = f"{np.degrees(1.0 / params.K_T):.3g} deg per N m for a leg motor (1/K_T)"
    assert f"{'printed' if printed else 'given'} torsional stiffnesses imply" in text
    assert leg in text
    springs = "the other springs as the paper prints them" + (
        "" if printed else f" but K_T = {params.K_T:g}"
    )
    assert f"K_s = {params.K_s:g} N/m, assumed (the paper prints" in text
    assert f"and {springs}. With the printed K_s" in text


def test_summary_largest_differences_skip_only_the_missing_cells():
    """A backend without the cells of the first table: its largest differences are those
    of the other tables (the first table's NaN made them 'n/a')."""
    tables = [table_values(pose, P) for pose in TABLE_POSES]
    tables[0].values["published"][:] = np.nan
    doc = Document("t")
    summary_section(doc, P, tables)
    summary = next(t for t in _blocks(doc, Table) if t.header[0] == "backend")
    row = next(r for r in summary.rows if r[0] == "published")
    rest = [tv.values["published"] - tv.values["paper"] for tv in tables[1:]]
    expected = [max(np.abs(d[rows]).max() for d in rest) for rows in (slice(3), slice(3, None))]
    np.testing.assert_allclose(_numbers(row[1:3]), expected, rtol=SUMMARY_RTOL)

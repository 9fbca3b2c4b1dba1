"""The comparison report: every table cell and figure present, linearity from the data."""

import re

import numpy as np
import pytest

from cahyman_pin.cli import main
from cahyman_pin.paper import data as paper_data
from cahyman_pin.paper import report
from cahyman_pin.paper.data import LOAD_LABELS, TABLE_POSES, TABLES
from cahyman_pin.paper.document import Figure, Table

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    return out, report.build_report(out)


def _linearity_table():
    doc = report.Document("t")
    report._linearity(doc)
    return next(b for b in doc.blocks if isinstance(b, Table))


def _tables(doc, pattern):
    return [b for b in doc.blocks if isinstance(b, Table) and re.match(pattern, b.caption)]


def test_files_written(built):
    out, doc = built
    for name in ("report.md", "report.html", "fig5_detK.png", "fig6_force.png",
                 "fig7_torque.png"):  # fmt: skip
        assert (out / name).is_file(), name
    figures = [b for b in doc.blocks if isinstance(b, Figure)]
    assert len(figures) == 3
    for f in figures:
        assert f.path.read_bytes()[:8] == PNG_MAGIC
        assert f.path.stat().st_size > 20_000  # a plotted figure, not an empty canvas


def test_html_is_self_contained(built):
    out, _ = built
    html = (out / "report.html").read_text()
    assert html.count('src="data:image/png;base64,') == 3
    assert not re.search(r"""(src|href)=["']https?://""", html)


def test_every_table_cell_present(built):
    _, doc = built
    for pose in TABLE_POSES:
        tables = _tables(doc, rf"{pose.label}, load ")
        assert [t.caption for t in tables] == [f"{pose.label}, load {lab}" for lab in LOAD_LABELS]
        level = pose.label in ("Table 1", "Table 2")  # alpha_1 = alpha_2 = alpha_3: phi = 90
        for t in tables:
            assert t.header == ("row", "paper", "published", "diff", "consistent",
                                "diff", "generic", "diff")  # fmt: skip
            assert len(t.rows) == (5 if level else 6)
            for row in t.rows:
                assert len(row) == 8
                # published, consistent and generic values and their differences are numbers
                for cell in (row[1], *row[4:]):
                    float(cell)
            labels = [r[0] for r in t.rows]
            if level:
                assert labels[3:] == ["tilt [deg]", "yaw d(theta+psi) [deg]"]
            else:
                assert labels[3:] == ["dphi [deg]", "dpsi [deg]", "dtheta [deg]"]


def test_published_values_in_tables_match_the_paper(built):
    _, doc = built
    t = _tables(doc, r"Table 3, load Fe=0")[0]
    np.testing.assert_allclose([float(r[1]) for r in t.rows], TABLES["Table 3"][:, 1])
    t1 = _tables(doc, r"Table 1, load Fe=\(1,1,1\) N, Ne=0")[0]
    # level plate: tilt = |dphi| and yaw = dpsi + dtheta of the published column
    assert float(t1.rows[3][1]) == pytest.approx(0.92)
    assert float(t1.rows[4][1]) == pytest.approx(0.84 - 0.57)


def test_linearity_is_computed_from_the_published_values(monkeypatch, tmp_path):
    table = _linearity_table()
    for j, pose in enumerate(TABLE_POSES):
        p = TABLES[pose.label]
        expected = p[:, 2] - p[:, 0] - p[:, 1]
        np.testing.assert_allclose(
            [float(r[1 + j]) for r in table.rows], expected, atol=5e-3
        )  # printed to 0.01 like the data
    # change one published value: the check must follow it
    changed = {k: v.copy() for k, v in TABLES.items()}
    changed["Table 2"][0, 2] += 1.0
    monkeypatch.setattr(paper_data, "TABLES", changed)
    monkeypatch.setattr(report, "TABLES", changed)
    table = _linearity_table()
    assert float(table.rows[0][2]) == pytest.approx(1.0)


def test_cli_report(tmp_path, capsys):
    assert main(["report", "--out", str(tmp_path / "r")]) == 0
    assert (tmp_path / "r" / "report.html").is_file()
    assert "report written" in capsys.readouterr().out

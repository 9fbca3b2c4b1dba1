"""The comparison report: every table cell and figure present, linearity from the data; a
reader without the paper first meets the machine, its matrices and the report's terms."""

import re

import numpy as np
import pytest

from cahyman_pin.api import stiffness
from cahyman_pin.paper import data as paper_data
from cahyman_pin.paper import report
from cahyman_pin.paper import tables as tables_module
from cahyman_pin.paper.compare import table_values
from cahyman_pin.paper.data import LOAD_LABELS, TABLE_POSES, TABLES
from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph, Table
from cahyman_pin.params import DEFAULT_PARAMS, K_S_ASSUMED, K_S_PRINTED, SOURCES

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: report.md prints the summary's translations to 4 significant digits: rounding <= 5e-4.
PRINTED_RTOL = 5e-4
#: No rotation of M depends on K_s (its joint moves M along the arm): the rotation rows of
#: C with K_s = 0.697 and 0.697e6 N/m agree to the rounding of the solve (measured: exactly
#: 0); 1e-9 of the largest rotation entry leaves a wide margin, while the translation rows
#: differ by w w^T / K_s (1.4 m/N), whose trace holds to the same relative 1e-9.
ROTATION_RTOL = 1e-9
#: The three terms the report defines, and its definition of each (the term emphasised).
TERMS = {"eq. (": "*eq. (n)* is", "damaged place": "A *damaged place* is",
         "backend": "A *backend* is"}  # fmt: skip


@pytest.fixture(scope="module")
def built(default_report):
    return default_report


def _linearity_table():
    doc = Document("t")
    tables_module.linearity_section(doc)
    return next(b for b in doc.blocks if isinstance(b, Table))


def _tables(doc, pattern):
    return [b for b in doc.blocks if isinstance(b, Table) and re.match(pattern, b.caption)]


FIGURES = ("fig5_detK.png", "fig6_force.png", "fig7_torque.png", "tornado_dimensions.png")


def test_files_written(built):
    out, doc = built
    for name in ("report.md", "report.html", *FIGURES):
        assert (out / name).is_file(), name
    figures = [b for b in doc.blocks if isinstance(b, Figure)]
    assert {f.path.name for f in figures} >= set(FIGURES)
    for f in figures:
        assert f.path.read_bytes()[:8] == PNG_MAGIC
        assert f.path.stat().st_size > 20_000  # a plotted figure, not an empty canvas


def test_html_is_self_contained(built):
    out, doc = built
    html = (out / "report.html").read_text()
    n_figures = sum(isinstance(b, Figure) for b in doc.blocks)
    assert html.count('src="data:image/png;base64,') == n_figures
    assert not re.search(r"""(src|href)=["']https?://""", html)


def test_findings_come_first_and_the_contents_reach_every_section(built):
    """The machine, its matrices, then the summary and the figures before the tables, the
    parameters at the end; the contents after the title link to the id of every heading
    of report.html."""
    out, doc = built
    headings = [b.text for b in doc.blocks if isinstance(b, Heading) and b.level == 2]
    assert headings[:5] == ["CaHyMan and the paper", "Stiffness matrices at the three "
                            "configurations", "Summary", "Figures",
                            "Tables 1-3: displacement of M"]  # fmt: skip
    assert headings[-1] == "Parameters and conventions"
    html = (out / "report.html").read_text()
    ids = re.findall(r'<h[2-6] id="([^"]+)"', html)
    links = re.findall(r'<a href="#([^"]+)"', html)
    assert ids == links and len(ids) == sum(isinstance(b, Heading) for b in doc.blocks)
    assert html.index("<strong>Contents</strong>") < html.index('<h2 id="cahyman-and-the-paper">')


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
    monkeypatch.setattr(tables_module, "TABLES", changed)
    table = _linearity_table()
    assert float(table.rows[0][2]) == pytest.approx(1.0)


def _text(doc):
    return " ".join(b.text for b in doc.blocks if isinstance(b, Paragraph))


def test_text_errors_fixed(built):
    _, doc = built
    text = _text(doc)
    assert "1 to 3 deg per N m" not in text
    # the moment column's rotations of Table 3, as printed
    assert "Table 3: dphi, dpsi, dtheta = 0.22, -0.21, 0.43 deg" in text
    assert "than those of the model with the printed springs" not in text
    assert "consistent model with the report's parameters" in text
    # the paper cited with its authors and title
    assert 'G. Carbone, M. Ceccarelli, M. Teolis, "A Numerical Evaluation of the Stiffness' in text
    # the K_s effect explained: the pseudo-inverse puts K_4 and K_s side by side
    assert "(K_4 + K_s)/2" in text
    # one explanation of the level plate, in Conventions
    assert text.count("only their sum is defined") == 1


def test_rotation_median_ratio_against_the_generic_backend(built):
    # median |published| / |model| over the rotation rows, recomputed from table_values
    _, doc = built
    ratios = []
    for pose in TABLE_POSES:
        tv = table_values(pose, DEFAULT_PARAMS)
        m, p = tv.values["generic"][3:], tv.values["paper"][3:]
        keep = np.abs(m) > 0
        ratios.append(np.abs(p[keep]) / np.abs(m[keep]))
    median = np.median(np.concatenate(ratios))
    assert f"about {median:.0f} times (median) larger" in _text(doc)


def test_assumed_parameters_flagged(built):
    _, doc = built
    after = doc.blocks[doc.blocks.index(Heading("Parameters", 3)) :]
    table = next(b for b in after if isinstance(b, Table))
    assert table.header == ("parameter", "value (SI)", "assumed", "source")
    flags = {r[0]: r[2] for r in table.rows}
    for name, flag in flags.items():
        assert flag == ("ASSUMED" if SOURCES[name].startswith("assumed") else ""), name
    assert flags["a"] == flags["K_s"] == "ASSUMED" and flags["K_T"] == ""


def test_one_rotation_convention(built):
    # world rotation-vector labels appear only as coordinates of the K matrices
    _, doc = built
    for t in (b for b in doc.blocks if isinstance(b, Table)):
        labels = [*t.header, *(r[0] for r in t.rows)]
        assert not any(re.match(r"r[xyz] \[deg\]", str(x)) for x in labels), t.caption
    assert not any("rx [deg]" in str(c) for t in doc.blocks if isinstance(t, Table)
                   for r in t.rows for c in r)  # fmt: skip


def test_class_table_has_every_cell(built):
    _, doc = built
    t = next(b for b in doc.blocks if isinstance(b, Table) and b.caption.startswith("Class of"))
    assert len(t.rows) == 54
    i_class = t.header.index("class")
    assert {r[i_class] for r in t.rows} <= {"reproduced", "explained", "unexplained"}
    printed = [float(r[t.header.index("printed")]) for r in t.rows]
    expected = [TABLES[p.label][i, j] for p in TABLE_POSES for j in range(3) for i in range(6)]
    np.testing.assert_allclose(printed, expected)


def test_counts_in_the_text_are_those_of_the_class_table(built):
    # the counts in the summary and in the class section, against the class table's own
    # rows (counted here); the floor in the summary, against the floor table's rows summed
    _, doc = built
    t = next(b for b in doc.blocks if isinstance(b, Table) and b.caption.startswith("Class of"))
    kinds = [r[t.header.index("class")] for r in t.rows]
    n = {k: kinds.count(k) for k in ("reproduced", "explained", "unexplained")}
    text = " ".join(b.text for b in doc.blocks if isinstance(b, Paragraph))
    assert (
        f"{n['reproduced']} are reproduced, {n['explained']} explained by a named effect and "
        f"{n['unexplained']} unexplained"
    ) in text
    assert (
        f"Counts: {n['reproduced']} reproduced, {n['explained']} explained, "
        f"{n['unexplained']} unexplained, of 54."
    ) in text
    floor = _tables(doc, "Linearity floor per published row")[0]
    total = sum(float(r[floor.header.index("chi^2 floor")]) for r in floor.rows)
    m = re.search(r"at ([0-9.]+) or more", text)
    np.testing.assert_allclose(float(m.group(1)), total, rtol=5e-3)  # 3 digits per row
    # no cell is said to be explained by the non-linearity while the fit misses the row's
    # nearest linear value; Table 3 dtheta under F (9.34 deg) is unexplained
    row = next(r for r in t.rows if r[:3] == ("Table 3", "F", "dtheta [deg]"))
    assert row[t.header.index("class")] == "unexplained"


def test_printed_k_s_given_has_no_k_s_effect(tmp_path):
    """With K_s = 0.697 N/m given, the 'K_s value' effect changes nothing: its note and the
    K_s section say so (they read "0.697 -> 0.697e6" with changes of 0)."""
    doc = report.build_report(tmp_path, DEFAULT_PARAMS.replace(K_s=K_S_PRINTED))
    text = _text(doc)
    # the summary's K_s sentence: the parameters' value printed, the other one assumed
    assert f"K_s = {K_S_PRINTED:g} N/m, as the paper prints it in its section 4" in text
    assert f"With the assumed K_s = {K_S_ASSUMED:g} N/m (1e+06 times the printed" in text
    assert "none here: the parameters take K_s as printed, 0.697 N/m." in text
    assert "'K_s value' effect is zero here" in text
    assert "-> the assumed" not in text


def _reading_text(out) -> str:
    """report.md as it is read: the title, then the body, without the table of contents."""
    title, rest = (out / "report.md").read_text().split("\n", 1)
    return title + rest[rest.index("\n## ") :]


def _section_text(doc, heading: str) -> str:
    """The paragraphs of the level-2 section ``heading``."""
    start = doc.blocks.index(Heading(heading))
    end = next((k for k, b in enumerate(doc.blocks) if k > start and isinstance(b, Heading)
                and b.level == 2), len(doc.blocks))  # fmt: skip
    return " ".join(b.text for b in doc.blocks[start:end] if isinstance(b, Paragraph))


def test_the_report_opens_with_the_machine_then_its_matrices(built):
    """First the machine and what the paper claims (its configurations and loads, as typed
    from the paper), then the stiffness matrices, then the verdict and the forensics."""
    out, doc = built
    body = _reading_text(out).split("\n", 1)[1]
    assert body.startswith("## CaHyMan and the paper\n\nCaHyMan (Cassino Hybrid Manipulator) is")
    assert doc.blocks[0] == Heading("CaHyMan and the paper")
    machine = doc.blocks[1].text
    for words in (
        "CaPaMan",
        "telescopic arm",
        "three legs",
        "parallelogram",
        "mobile plate",
        "extremity M",
        "force F_e",
        "moment N_e",
        "torsional spring K_T ",
        "K_b and K_d",
        "K_T4",
        "K_s",
        "K_4",
        "Tables 1-3",
        "Fig. 5",
        "Figs. 6 and 7",
    ):
        assert words in machine, words
    for pose in TABLE_POSES:
        alphas = ", ".join(f"{a:g}" for a in pose.alpha_deg)
        assert (f"{pose.label}: alpha_1..3 = {alphas} deg, alpha_4 = {pose.alpha4_deg:g} deg, "
                f"s_4 = {pose.s4_mm:g} mm") in machine  # fmt: skip
    assert all(label in machine for label in LOAD_LABELS)
    sections = [b.text for b in doc.blocks if isinstance(b, Heading) and b.level == 2]
    matrices = sections.index("Stiffness matrices at the three configurations")
    assert matrices == 1
    forensics = ("Summary", "Tables 1-3: displacement of M", "Linearity of the published tables",
                 "Could any stiffness values or dimensions produce the tables?",
                 "Every published cell: reproduced, explained or unexplained",
                 "Where the differences come from")  # fmt: skip
    assert all(sections.index(h) > matrices for h in forensics)
    # the verdict table (the summary's) after the three K tables
    k_tables = [k for k, b in enumerate(doc.blocks)
                if isinstance(b, Table) and b.caption.startswith("K (generic)")]  # fmt: skip
    verdict = next(
        k
        for k, b in enumerate(doc.blocks)
        if isinstance(b, Table) and "largest rotation difference [deg]" in b.header
    )
    assert len(k_tables) == len(TABLE_POSES) and max(k_tables) < verdict


@pytest.mark.parametrize("term", TERMS)
def test_terms_are_defined_where_they_first_appear(built, term):
    """The first time report.md says "eq. (", "damaged place" or "backend" (title
    included, any case) is in the sentence that defines it."""
    out, _ = built
    text = _reading_text(out)
    first, at = text.lower().index(term.lower()), text.index(TERMS[term])
    assert at <= first < at + len(TERMS[term]), text[max(first - 100, 0) : first + 100]
    # "eqs. (n)-(m)" only after the definition of eq. (n), in its paragraph
    first_eqs = text.index("eqs. (")
    assert text.index(TERMS["eq. ("]) < first_eqs < text.index("\n", text.index(TERMS["eq. ("]))


def test_the_k_s_sentence_names_two_values_with_their_sources(built):
    """The summary's K_s sentence: the assumed value, the printed one and where each comes
    from (it called both "printed", with the same ratio for both and no reason why)."""
    _, doc = built
    summary = _section_text(doc, "Summary")
    assert K_S_ASSUMED != K_S_PRINTED
    assert (f"K_s = {K_S_ASSUMED:g} N/m, assumed (the paper prints {K_S_PRINTED:g} N/m in its "
            "section 4; the report takes 1e+06 times that)") in summary  # fmt: skip
    assert f"With the printed K_s = {K_S_PRINTED:g} N/m instead" in summary
    printed = re.findall(r"printed K_s = (\S+) N/m", summary)
    assert printed and all(float(x) == K_S_PRINTED for x in printed)
    assert "printed springs, K_s" not in summary


def test_k_s_turns_nothing_and_sets_the_translations(built):
    """What the K_s sentence claims, recomputed with the generic backend: the rotation rows
    of C do not depend on K_s, so the median ratio is the same for both values; the largest
    translations differ, as printed."""
    _, doc = built
    summary = _section_text(doc, "Summary")
    params = {K: DEFAULT_PARAMS.replace(K_s=K) for K in (K_S_ASSUMED, K_S_PRINTED)}
    for pose in TABLE_POSES:
        C = {K: stiffness(*pose.si, params=p).C for K, p in params.items()}
        rot = np.abs(C[K_S_ASSUMED][3:]).max()
        np.testing.assert_allclose(
            C[K_S_PRINTED][3:], C[K_S_ASSUMED][3:], rtol=0, atol=ROTATION_RTOL * rot
        )
        # K_s adds w w^T / K_s to the translations (w: the arm's unit direction), trace 1/K_s
        added = np.trace(C[K_S_PRINTED][:3, :3] - C[K_S_ASSUMED][:3, :3])
        np.testing.assert_allclose(added, 1 / K_S_PRINTED - 1 / K_S_ASSUMED, rtol=ROTATION_RTOL)
    median, largest = {}, {}
    for K, p in params.items():
        values = [table_values(pose, p).values for pose in TABLE_POSES]
        rot = np.concatenate([v["generic"][3:].ravel() for v in values])
        paper = np.concatenate([v["paper"][3:].ravel() for v in values])
        keep = np.abs(rot) > 0
        median[K] = np.median(np.abs(paper[keep]) / np.abs(rot[keep]))
        largest[K] = max(np.abs(v["generic"][:3]).max() for v in values)
    assert f"about {median[K_S_ASSUMED]:.0f} times (median) larger" in summary
    assert f"the median ratio is the same, {median[K_S_PRINTED]:.0f}:" in summary
    m = re.search(
        r"largest translation in the tables is (\S+) mm with K_s = (\S+) N/m and "
        r"(\S+) mm with (\S+) N/m, against at most (\S+) mm published",
        summary,
    )
    assert float(m[2]) == K_S_ASSUMED and float(m[4]) == K_S_PRINTED
    np.testing.assert_allclose(
        [float(m[1]), float(m[3])], [largest[K_S_ASSUMED], largest[K_S_PRINTED]], rtol=PRINTED_RTOL
    )
    assert float(m[5]) == np.abs([TABLES[p.label][:3] for p in TABLE_POSES]).max()

"""cahyman_pin.paper.document: report.md and the self-contained report.html rendered from it."""

import base64
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph, Table

# The first bytes of a PNG and a few more: the renderer embeds bytes, it does not decode them.
PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256))


class Page(HTMLParser):
    """Tables (rows of cell texts), image sources and every URL-valued attribute."""

    def __init__(self, text: str):
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self.images: list[str] = []
        self.urls: list[str] = []
        self.tags: set[str] = set()
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        a = dict(attrs)
        self.urls += [v for k, v in a.items() if k in ("src", "href", "data", "action")]
        if tag == "img":
            self.images.append(a["src"])
        elif tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


@pytest.fixture
def doc(tmp_path) -> tuple[Document, list[Path], list[Table]]:
    figures = []
    for k, name in enumerate(("fig a.png", "fig_b.png")):
        path = tmp_path / "figs" / name
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(PNG + bytes([k]))
        figures.append(path)
    tables = [
        Table(("row", "a [mm]", "|dC| / |C|"), (("dx", "1.5", "+2e-05"), ("dy", "-3", "0"))),
        Table(("backend", "det K"), (("published", "-2.3e+32"),), caption="Second table"),
    ]
    d = Document("A title")
    d.add(
        Heading("Section"),
        Paragraph("Text with x < 1e-6 and K_s, K_T4 and b_k = d_k."),
        tables[0],
        Figure(figures[0], "Fig. 1: first"),
        Heading("Sub", level=3),
        tables[1],
        Figure(figures[1], "Fig. 2: second"),
    )
    return d, figures, tables


def test_html_has_every_table_with_its_cells(doc):
    d, _, tables = doc
    page = Page(d.to_html())
    assert page.tables == [[list(t.header), *map(list, t.rows)] for t in tables]


def test_html_embeds_every_figure_and_refers_to_nothing_outside(doc):
    d, figures, _ = doc
    text = d.to_html()
    page = Page(text)
    assert len(page.images) == len(figures)
    for src, path in zip(page.images, figures, strict=True):
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix)
        assert base64.b64decode(src[len(prefix) :]) == path.read_bytes()
    assert all(url.startswith(("data:", "#")) for url in page.urls), page.urls
    assert not page.tags & {"link", "script", "iframe", "object"}
    assert not re.search(r"url\(", text)  # no stylesheet resource either


def test_html_keeps_the_text_headings_and_captions(doc):
    d, _, _ = doc
    text = d.to_html()
    assert "<title>A title</title>" in text and "<h1>A title</h1>" in text
    assert '<h2 id="section">Section</h2>' in text and '<h3 id="sub">Sub</h3>' in text
    assert "x &lt; 1e-6 and K_s, K_T4 and b_k = d_k." in text
    assert "Fig. 1: first" in text and "Second table" in text


def test_markdown_links_figures_relative_to_the_report(doc, tmp_path):
    d, _, _ = doc
    md = d.to_markdown(tmp_path)
    assert "![Fig. 1: first](<figs/fig a.png>)" in md
    assert "![Fig. 2: second](figs/fig_b.png)" in md
    assert "| row | a [mm] | \\|dC\\| / \\|C\\| |" in md
    assert str(tmp_path) not in md


def test_contents_link_to_every_heading_in_both_outputs(tmp_path):
    """A table of contents after the title, nested by level; each link's target is the id
    of its heading in the HTML, and GitHub's anchor of it in the Markdown (lower case,
    punctuation dropped, spaces as '-', repeats numbered)."""
    d = Document("T")
    d.add(
        Heading("Summary"),
        Paragraph("text"),
        Heading("Tables 1-3: displacement of M"),
        Heading("Table 1 (phi = 90 deg)", 3),
        Heading("Summary"),
    )
    md = d.to_markdown(tmp_path)
    contents = md.split("**Contents**")[1].split("## ")[0].strip().splitlines()
    assert contents == [
        "- [Summary](#summary)",
        "- [Tables 1-3: displacement of M](#tables-1-3-displacement-of-m)",
        "    - [Table 1 (phi = 90 deg)](#table-1-phi--90-deg)",
        "- [Summary](#summary-1)",
    ]
    assert md.index("**Contents**") < md.index("## Summary")
    page = d.to_html()
    ids = re.findall(r'<h[23] id="([^"]+)"', page)
    links = re.findall(r'<a href="#([^"]+)"', page)
    assert (
        ids
        == links
        == ["summary", "tables-1-3-displacement-of-m", "table-1-phi--90-deg", "summary-1"]
    )
    assert "<ul>\n<li><a" in page and page.count("<ul>") == 2  # one nested list


def test_a_document_without_headings_has_no_contents(tmp_path):
    d = Document("T")
    d.add(Paragraph("only text"))
    assert "Contents" not in d.to_markdown(tmp_path) and "Contents" not in d.to_html()

"""The report's builder: a list of blocks written as Markdown, rendered to HTML by Markdown.

A report is a :class:`Document` of headings, paragraphs, tables and figures. The same
blocks give ``report.md`` (figures linked as files next to it) and ``report.html``: that
Markdown rendered by Python-Markdown (``tables`` extension), every figure embedded as a
base64 data URI, so the page needs no other file and no network. Both start with a table
of contents whose links reach the section headings (their anchors: :func:`anchors`).
"""

from __future__ import annotations

import base64
import html
import mimetypes
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element

import markdown
from markdown.extensions import Extension
from markdown.treeprocessors import Treeprocessor

_STYLE = (
    "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
    "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;"
    "padding:2px 6px;text-align:right}th{background:#eee}img{max-width:100%}"
)


def _md_row(cells) -> str:
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


@dataclass(frozen=True)
class Heading:
    """A section heading; ``level`` is its Markdown level (2: ``##``, below the report's
    title), every heading listed in the table of contents, nested by level."""

    text: str
    level: int = 2


@dataclass(frozen=True)
class Paragraph:
    """A paragraph of Markdown text."""

    text: str


@dataclass(frozen=True)
class Table:
    """A table: its header cells, its rows of cells and an optional caption."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""


@dataclass(frozen=True)
class Figure:
    """An image file and its caption."""

    path: Path
    caption: str


Block = Heading | Paragraph | Table | Figure


class _EmbedImages(Treeprocessor):
    """Replace the ``src`` of every image (a file path) by the file's data URI."""

    def run(self, root: Element) -> None:
        for img in root.iter("img"):
            path = Path(img.get("src", ""))
            mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
            data = base64.b64encode(path.read_bytes()).decode("ascii")
            img.set("src", f"data:{mime};base64,{data}")


class _HeadingIds(Treeprocessor):
    """Give the section headings (h2 and below, in order) the ids of :func:`anchors`, the
    targets of the contents' links."""

    def __init__(self, md: markdown.Markdown, ids: list[str]):
        super().__init__(md)
        self.ids = ids

    def run(self, root: Element) -> None:
        headings = [e for e in root.iter() if e.tag in ("h2", "h3", "h4", "h5", "h6")]
        for element, anchor in zip(headings, self.ids, strict=True):
            element.set("id", anchor)


class _Embed(Extension):
    def __init__(self, ids: list[str]):
        super().__init__()
        self.ids = ids

    def extendMarkdown(self, md: markdown.Markdown) -> None:
        md.treeprocessors.register(_EmbedImages(md), "embed_images", 0)
        md.treeprocessors.register(_HeadingIds(md, self.ids), "heading_ids", 1)


def anchors(texts: list[str]) -> list[str]:
    """Anchor of each heading text, as GitHub makes them (so that the contents' links work
    in report.md there and in report.html): lower case, punctuation dropped, spaces as
    ``-``; a repeated anchor gets ``-1``, ``-2``, ... ."""
    out, seen = [], {}
    for text in texts:
        base = re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.append(base if n == 0 else f"{base}-{n}")
    return out


@dataclass
class Document:
    """Ordered blocks with a title."""

    title: str
    blocks: list[Block] = field(default_factory=list)

    def add(self, *blocks: Block) -> None:
        """Append ``blocks`` to the report, in order."""
        self.blocks.extend(blocks)

    def to_markdown(self, relative_to: Path) -> str:
        """The Markdown of the report, figures linked relative to the folder ``relative_to``."""
        base = Path(relative_to).resolve()
        return self._markdown(lambda p: Path(p).resolve().relative_to(base).as_posix())

    def to_html(self) -> str:
        """A self-contained HTML page: the Markdown rendered, every figure embedded, the
        section headings with the ids the contents link to."""
        body = markdown.markdown(
            self._markdown(lambda p: Path(p).resolve().as_posix()),
            extensions=["tables", _Embed(anchors([h.text for h in self._headings()]))],
            output_format="html",
        )
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style></head>"
            f"<body>\n{body}\n</body></html>\n"
        )

    def _headings(self) -> list[Heading]:
        return [b for b in self.blocks if isinstance(b, Heading)]

    def _contents(self) -> list[str]:
        """The table of contents: a nested list of links to the section headings (none
        for a document without any)."""
        headings = self._headings()
        if not headings:
            return []
        top = min(h.level for h in headings)
        out = ["**Contents**", ""]
        for h, anchor in zip(headings, anchors([h.text for h in headings]), strict=True):
            text = h.text.replace("[", "\\[").replace("]", "\\]")
            out.append("    " * (h.level - top) + f"- [{text}](#{anchor})")
        return [*out, ""]

    def _markdown(self, link: Callable[[Path], str]) -> str:
        out = [f"# {self.title}", "", *self._contents()]
        for b in self.blocks:
            if isinstance(b, Heading):
                out += ["#" * b.level + " " + b.text, ""]
            elif isinstance(b, Paragraph):
                out += [b.text, ""]
            elif isinstance(b, Table):
                if b.caption:
                    out += [f"*{b.caption}*", ""]
                out.append(_md_row(b.header))
                out.append("|" + "|".join("---" for _ in b.header) + "|")
                out += [_md_row(r) for r in b.rows]
                out.append("")
            elif isinstance(b, Figure):
                target = link(b.path)
                if any(c in target for c in " ()<>"):
                    target = f"<{target}>"
                out += [f"![{b.caption}]({target})", "", f"*{b.caption}*", ""]
        return "\n".join(out)

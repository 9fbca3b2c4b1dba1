"""The report's Tables 1-3 (every published cell next to the three backends) and the
linearity of the published tables."""

from __future__ import annotations

from cahyman_pin.paper.compare import BACKENDS, TableValues
from cahyman_pin.paper.data import LOAD_LABELS, TABLE_POSES, TABLES, linearity_residual
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.numbers import fmt, two_decimals


def _diff(v: float, ref: float) -> str:
    return fmt(v - ref, 3, "+")


def tables_section(doc: Document, tables: list[TableValues]) -> None:
    """Add Tables 1-3 to ``doc``: every published cell of ``tables`` next to the
    backends' values."""
    doc.add(Heading("Tables 1-3: displacement of M"))
    for tv in tables:
        pose = tv.pose
        doc.add(Heading(f"{pose.label}: {pose.describe()}", 3))
        if tv.level:
            p = TABLES[pose.label]
            doc.add(
                Paragraph(
                    "The plate is level here: rotations as tilt and yaw (see 'Conventions'). "
                    "The paper's printed dphi = "
                    f"{', '.join(fmt(x) for x in p[3])}, dpsi = "
                    f"{', '.join(fmt(x) for x in p[4])} and dtheta = "
                    f"{', '.join(fmt(x) for x in p[5])} deg for the three loads."
                )
            )
        header = ("row", "paper")
        for b in BACKENDS:
            header += (b, "diff")
        for j, label in enumerate(LOAD_LABELS):
            rows = []
            for i, row in enumerate(tv.rows):
                ref = tv.values["paper"][i, j]
                cells = (row, fmt(ref))
                for b in BACKENDS:
                    v = tv.values[b][i, j]
                    cells += (fmt(v), _diff(v, ref))
                rows.append(cells)
            doc.add(Table(header, tuple(rows), caption=f"{pose.label}, load {label}"))


def linearity_section(doc: Document) -> None:
    """Add the section on the linearity of the published tables to ``doc``."""
    doc.add(
        Heading("Linearity of the published tables"),
        Paragraph(
            "Every backend is linear, so column 3 (force and moment) must equal column 1 + "
            "column 2. The residual column 3 - (column 1 + column 2), computed from the "
            "published values:"
        ),
    )
    rows = tuple(
        (row, *(two_decimals(linearity_residual(TABLES[p.label])[i]) for p in TABLE_POSES))
        for i, row in enumerate(("dx [mm]", "dy [mm]", "dz [mm]", "dphi [deg]", "dpsi [deg]",
                                 "dtheta [deg]"))
    )  # fmt: skip
    doc.add(Table(("row", *(p.label for p in TABLE_POSES)), rows))

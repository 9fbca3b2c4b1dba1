"""The report's opening: what CaHyMan is, what the paper claimed, the terms used."""

from __future__ import annotations

from cahyman_pin.paper.data import citation
from cahyman_pin.paper.document import Document, Paragraph


def opening_section(doc: Document) -> None:
    doc.add(
        Paragraph(
            "This report compares the displacements published for CaHyMan (Tables 1-3, "
            "Figs. 5-7 of the paper below) with three backends: 'published' (the "
            "paper's closed-form matrices as printed, with the smallest choice at each "
            "damaged place), 'consistent' (the same closed-form structure with every damaged "
            "place resolved) and 'generic' (the Pinocchio model with loop closures and "
            "joint springs, solved by the general Jacobian method). All computations are in "
            "SI; tables are in the paper's units (mm, deg)."
        ),
        Paragraph("The paper: " + citation()),
    )

"""The report's opening: what CaHyMan is, what the paper claimed, and the terms the report
uses (eq. (n), damaged place, backend), each defined where it first appears.

The report is read by people who do not have the paper at hand: this section says what
the machine is, where its springs are and where it is loaded, what the paper computed
(Tables 1-3, Figs. 5-7), then defines the words the rest of the report is written in.
Every configuration and load it names comes from :mod:`cahyman_pin.paper.data`.
"""

from __future__ import annotations

from cahyman_pin.paper.data import FIG67, LOAD_LABELS, TABLE_POSES, citation
from cahyman_pin.paper.document import Document, Heading, Paragraph

#: The heading of the opening section.
TITLE = "CaHyMan and the paper"


def _machine() -> str:
    """What CaHyMan is, where its springs and its load are, and what the paper claims."""
    loads = "; ".join(LOAD_LABELS)
    poses = "; ".join(f"{p.label}: {p.describe()}" for p in TABLE_POSES)
    return (
        "CaHyMan (Cassino Hybrid Manipulator) is a parallel base with three degrees of "
        "freedom, CaPaMan, that carries a telescopic arm with two. CaPaMan's three legs "
        "stand on a fixed plate, evenly spaced around its centre; each leg k = 1, 2, 3 is an "
        "articulated parallelogram in a vertical plane, whose input crank b_k a motor turns "
        "to the angle alpha_k (the follower crank d_k follows), and whose coupler carries, "
        "on a radial slider, a connecting bar that ends in a ball joint under the mobile "
        "plate. On the mobile plate, at a point Q above its centre H, a motor turns the arm "
        "to the angle alpha_4 and a linear motor extends it by the stroke s_4; the arm ends "
        "at its extremity M, where the load is applied: a force F_e [N] and a moment N_e "
        "[N m]. The machine is elastic only in lumped springs: a torsional spring K_T in "
        "each leg's motor, axial springs K_b and K_d along each leg's two cranks, a "
        "torsional spring K_T4 in the arm's motor, an axial spring K_s in the linear motor "
        "with its link MM2, and an axial spring K_4 along the arm's link QM2, in series with "
        "K_s; every other part is rigid. The paper derives the stiffness matrix K of the "
        "machine at M in closed form and gives, in its Tables 1-3, the displacement of M "
        "(translations dx, dy, dz [mm] and increments dphi, dpsi, dtheta [deg] of the "
        f"angles of its orientation) under three loads ({loads}) at three configurations "
        f"({poses}); in Fig. 5, the determinant of K as each design parameter varies; in "
        "Figs. 6 and 7, the displacement of M as a force and a moment grow, at "
        f"{FIG67.describe()}."
    )


def _terms() -> str:
    """The definitions of eq. (n), damaged place and backend, in the order they are used."""
    return (
        "The terms of this report. *eq. (n)* is the paper's equation number n (eqs. (n)-(m) "
        "those from n to m); its formulation is eqs. (1)-(19). A *damaged place* is a "
        "place in those equations that cannot be computed as printed, or that computes "
        "something other than the stiffness at M: a 6x6 matrix multiplied by a 3x3 one "
        "(eq. (4)), the inverse of a matrix As with two equal columns (eqs. (4), (8)), "
        "symbols never defined (eqs. (14), (17)), a rotation of the plate added at M without "
        "its lever arm (eq. (3)); "
        "each is listed with the choice made there under 'Choices made to run the "
        "published formulation', and repaired one at a time under 'Where the differences "
        "come from'. A *backend* is one way of computing the compliance C = K^-1 (6x6, "
        "at M) at a configuration; the report compares three: 'published' (the paper's "
        "closed-form matrices as printed, with the smallest choice at each damaged place), "
        "'consistent' (the same closed-form structure with every damaged place resolved) "
        "and 'generic' (the Pinocchio model with loop closures and joint springs, solved "
        "by the general Jacobian method; what cahyman_pin.api.stiffness gives by "
        "default). All computations are in SI; tables are in the paper's units (mm, deg)."
    )


def opening_section(doc: Document) -> None:
    """The machine and the paper's claims, the citation, then the report's terms."""
    doc.add(
        Heading(TITLE),
        Paragraph(_machine()),
        Paragraph("The paper: " + citation()),
        Paragraph(_terms()),
    )

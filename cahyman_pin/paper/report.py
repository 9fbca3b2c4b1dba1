"""The comparison report: the paper's tables and figures against the three backends.

:func:`build_report` writes ``report.md``, a self-contained ``report.html`` and the
figures (PNG) into a folder (the command is ``cahyman report``, :mod:`cahyman_pin.cli.report`).
The report lists every parameter with its source (paper, assumed, or given).
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from cahyman_pin.api import stiffness
from cahyman_pin.backends.published import CHOICES
from cahyman_pin.paper.beams import beams_section
from cahyman_pin.paper.compare import BACKENDS, TableValues, backend_compliance, table_values
from cahyman_pin.paper.data import LOAD_LABELS, TABLE_POSES, TABLES, linearity_residual
from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph, Table
from cahyman_pin.paper.effects import EFFECTS, ILLUSTRATIVE_MASS, effect_changes
from cahyman_pin.paper.figures import figure5, figure_load
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED, CaHyManParams, source
from closedloop.compliance import TWIST_LABELS
from closedloop.exceptions import JointLimitWarning

#: Table cells (mm, deg) below this magnitude are rounding noise of exact zeros.
ZERO_CELL = 1e-9


def fmt(v: float, digits: int = 4, sign: str = "") -> str:
    """A number for a table cell ('n/a' for NaN, 0 for rounding noise below ZERO_CELL)."""
    if not np.isfinite(v):
        return "n/a"
    return "0" if abs(v) < ZERO_CELL else f"{v:{sign}.{digits}g}"


def _diff(v: float, ref: float) -> str:
    return fmt(v - ref, 3, "+")


def _two_decimals(v: float) -> str:
    """The precision of the published tables (0.01 mm or deg); no negative zero."""
    return f"{round(v, 2) + 0.0:.2f}"


def _matrix_rows(K: np.ndarray) -> tuple[tuple[str, ...], ...]:
    """Rows of a 6x6 matrix; entries below 1e-12 of the largest are shown as 0."""
    tiny = 1e-12 * np.max(np.abs(K))
    return tuple(
        (lab, *("0" if abs(x) < tiny else f"{x:.4g}" for x in K[i]))
        for i, lab in enumerate(TWIST_LABELS)
    )


def _intro(doc: Document, params: CaHyManParams, params_file: Path | None = None) -> None:
    given = f"the parameter file {str(params_file)!r}" if params_file else "no parameter file"
    assumed = [f.name for f in dataclasses.fields(params) if source(params, f.name).startswith(
        "assumed")]  # fmt: skip
    doc.add(
        Paragraph(
            "This report compares the displacements published for CaHyMan (Tables 1-3, "
            "Figs. 5-7 of the stiffness paper) with three backends: 'published' (the "
            "paper's closed-form matrices as printed, with the smallest choice at each "
            "damaged place), 'consistent' (the same closed-form structure with every damaged "
            "place resolved) and 'generic' (the Pinocchio model with loop closures and "
            "joint springs, solved by the general Jacobian method). All computations are in "
            "SI; tables are in the paper's units (mm, deg)."
        ),
        Heading("Parameters", 3),
        Paragraph(
            f"The parameters used, from the defaults of cahyman_pin/params.py and {given}. "
            "'paper' marks a value printed in the paper, 'given' a value of the parameter "
            "file; the values marked 'assumed' are not in the paper "
            f"({', '.join(assumed) if assumed else 'none here'}) and shape every number below. "
            f"The published backend always takes K_s = {K_S_PRINTED:g} N/m as printed (the "
            "first of the choices below), whatever K_s is here."
        ),
        Table(
            ("parameter", "value (SI)", "source"),
            tuple(
                (f.name, f"{getattr(params, f.name):g}", source(params, f.name))
                for f in dataclasses.fields(params)
            ),
        ),
        Heading("Choices made to run the published formulation", 3),
        Table(("place", "choice"), tuple(CHOICES)),
    )


def _summary(doc: Document, tables: list[TableValues]) -> None:
    """Findings in numbers, computed from the tables below."""
    gap = max(np.nanmax(np.abs(tv.values["consistent"] - tv.values["generic"])) for tv in tables)
    rows = []
    for b in BACKENDS:
        trans = [np.abs(tv.values[b][:3] - tv.values["paper"][:3]) for tv in tables]
        rot = [np.abs(tv.values[b][3:] - tv.values["paper"][3:]) for tv in tables]
        ratio = [np.abs(tv.values[b][3:]) / np.abs(tv.values["paper"][3:]) for tv in tables]
        rows.append((
            b,
            fmt(max(np.nanmax(t) for t in trans), 3),
            fmt(max(np.nanmax(r) for r in rot), 3),
            fmt(np.nanmedian(np.concatenate([r.ravel() for r in ratio])), 3),
        ))  # fmt: skip
    median_ratio = np.nanmedian(
        np.concatenate([np.abs(tv.values["generic"][3:] / tv.values["paper"][3:]).ravel()
                        for tv in tables])
    )  # fmt: skip
    lin = np.concatenate([linearity_residual(TABLES[tv.pose.label]) for tv in tables])
    lin = lin.reshape(len(tables), 6)
    doc.add(
        Heading("Summary"),
        Paragraph(
            "The consistent closed form and the generic Pinocchio backend, two independent "
            "implementations, agree on every table cell to within "
            f"{gap:.1e} (mm or deg). Neither they nor the published backend "
            "reproduces the published tables; the largest differences over the three "
            "tables are:"
        ),
        Table(
            (
                "backend",
                "largest translation difference [mm]",
                "largest rotation difference [deg]",
                "median ratio of rotation magnitudes, backend / published",
            ),
            tuple(rows),
        ),
        Paragraph(
            "The published tables are not linear in the load, which no linear model can "
            "reproduce: column 3 differs from column 1 + column 2 by up to "
            f"{np.max(np.abs(lin[:, :3])):.2g} mm in translation and "
            f"{np.max(np.abs(lin[:, 3:])):.3g} deg in rotation. The published rotations are "
            f"also about {1 / median_ratio:.0f} times (median) larger than those of the "
            "model with the printed springs (see 'Where the differences come from')."
        ),
    )


def _tables(doc: Document, tables: list[TableValues]) -> None:
    doc.add(Heading("Tables 1-3: displacement of M"))
    for tv in tables:
        pose = tv.pose
        doc.add(Heading(f"{pose.label}: {pose.describe()}", 3))
        if tv.level:
            p = TABLES[pose.label]
            doc.add(
                Paragraph(
                    "Here the plate is level (phi = 90 deg), where the angles of "
                    "R = Rz(theta) Ry(pi/2 - phi) Rz(psi) are singular: the plate normal is "
                    "along z, theta and psi turn about the same axis and only their sum (yaw) "
                    "is defined, while a tilt of the normal has no defined azimuth. The "
                    "rotations are therefore compared as tilt (for the paper, |dphi|) and yaw "
                    "(for the paper, dpsi + dtheta). The paper's own split is dpsi = "
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


def _linearity(doc: Document) -> None:
    doc.add(
        Heading("Linearity of the published tables"),
        Paragraph(
            "Every backend is linear, so column 3 (force and moment) must equal column 1 + "
            "column 2. The residual column 3 - (column 1 + column 2), computed from the "
            "published values:"
        ),
    )
    rows = tuple(
        (row, *(_two_decimals(linearity_residual(TABLES[p.label])[i]) for p in TABLE_POSES))
        for i, row in enumerate(("dx [mm]", "dy [mm]", "dz [mm]", "dphi [deg]", "dpsi [deg]",
                                 "dtheta [deg]"))
    )  # fmt: skip
    doc.add(Table(("row", *(p.label for p in TABLE_POSES)), rows))


def _effects(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
    doc.add(
        Heading("Where the differences come from"),
        Paragraph(
            "Each effect below is one damaged place, repaired alone while every other place "
            "stays as published; the numbers are the change it makes to the cells of the "
            "published backend (mm, deg), per load column. 'singular' marks a matrix the "
            "formulation cannot invert at that pose."
        ),
    )
    changes = effect_changes(params)
    for effect in EFFECTS:
        doc.add(Heading(effect.name, 3), Paragraph(effect.note + "."))
        rows = []
        for tv in tables:
            d = changes[effect.name][tv.pose.label]
            if d is None:
                rows.append((tv.pose.label, "singular", "singular", "singular"))
                continue
            rows += [(f"{tv.pose.label} {r}", *(fmt(x, 3, "+") for x in d[i]))
                     for i, r in enumerate(tv.rows)]  # fmt: skip
        doc.add(Table(("cell", *LOAD_LABELS), tuple(rows)))
    k_t4 = np.rad2deg(1.0 / params.K_T4)
    k_t = np.rad2deg(1.0 / params.K_T)
    doc.add(
        Heading("Euler singularity and the size of the published rotations", 3),
        Paragraph(
            "At Tables 1 and 2 the paper prints dpsi and dtheta separately although only their "
            "sum is defined there; their individual values cannot be compared with any model, "
            "so the comparison above uses yaw and tilt. Beyond the singularity, the published "
            "rotations are 1 to 3 deg per N m while the printed torsional stiffnesses imply "
            f"{k_t4:.3g} deg per N m for the arm motor (1/K_T4) and {k_t:.3g} deg per N m for a "
            "leg motor (1/K_T): no model with the printed springs reproduces the rotation rows, "
            "whereas the translation rows and the sign pattern of the rotations can be "
            "compared. The published tables are also not linear in the load (previous "
            "section), which no linear formulation can reproduce."
        ),
    )


def weight_rows(params: CaHyManParams) -> list[tuple[str, np.ndarray, float]]:
    """(pose label, sag of M (6,) [m, rad], relative change of C) under the weight of the
    illustrative masses of the eq. (11) effect, as a preload (generic backend)."""
    masses = {m: ILLUSTRATIVE_MASS for m in ("m_HQ", "m_QM", "m_MM2", "m_M4", "m_M5")}
    heavy = params.replace(**masses)
    out = []
    for pose in TABLE_POSES:
        alpha, alpha4, s4 = pose.si
        unloaded = stiffness(alpha, alpha4, s4, params=heavy)
        with warnings.catch_warnings():  # at full or zero stroke the sag may pass a limit
            warnings.simplefilter("ignore", JointLimitWarning)
            weighed = stiffness(alpha, alpha4, s4, params=heavy, weight=True)
        change = np.linalg.norm(weighed.C - unloaded.C) / np.linalg.norm(unloaded.C)
        out.append((pose.label, weighed.details["compliance"].sag, float(change)))
    return out


def _weight(doc: Document, params: CaHyManParams) -> None:
    doc.add(
        Heading("The weight as a preload (what eq. (11) tries)"),
        Paragraph(
            "Eq. (11) puts the weights into the load matrix, divided by load components that "
            "are zero in the tables' columns. The consistent way is a preload: the machine "
            "settles under its weight (the five named masses, each "
            f"{ILLUSTRATIVE_MASS} kg here as in the effect above, placed where eq. (11)'s "
            "lever arms put them: cahyman_pin/urdf_builder.py), and the compliance is the "
            "tangent one at that equilibrium (geometric stiffness and loop curvature "
            "included). Below: the sag of M from the unloaded pose (mm, deg, world axes) and "
            "the relative change of C (Frobenius norm), generic backend. A linear model's "
            "answer to a load does not depend on the weight; the tangent one changes by the "
            "amount shown, which is the size of what eq. (11) could add."
        ),
    )
    rows = [
        (label, *(fmt(1e3 * x, 3, "+") for x in sag[:3]),
         *(fmt(np.rad2deg(x), 3, "+") for x in sag[3:]), fmt(change, 2))
        for label, sag, change in weight_rows(params)
    ]  # fmt: skip
    doc.add(Table(("pose", "dx [mm]", "dy [mm]", "dz [mm]", "rx [deg]", "ry [deg]", "rz [deg]",
                   "|dC| / |C|"), tuple(rows)))  # fmt: skip


def _matrices(doc: Document, params: CaHyManParams) -> None:
    doc.add(
        Heading("Stiffness matrices at the three configurations"),
        Paragraph(
            "K at M, world axes, SI (N/m, N/rad, N m/rad), order dx dy dz rx ry rz, from the "
            "generic backend; eigenvalues and determinant for every backend (the published "
            "K is in its own mixed coordinates, see the choices above)."
        ),
    )
    for pose in TABLE_POSES:
        K = {}
        for b in BACKENDS:
            C, _, _ = backend_compliance(b, pose, params)
            K[b] = np.linalg.inv(C)
        doc.add(Heading(pose.label, 3))
        doc.add(
            Table(
                ("", *TWIST_LABELS),
                _matrix_rows(K["generic"]),
                caption=f"K (generic), {pose.describe()}",
            )
        )
        rows = []
        for b in BACKENDS:
            ev = np.linalg.eigvals(K[b])
            ev = ev[np.argsort(ev.real)]
            ev_text = ", ".join(
                f"{e.real:.4g}" if abs(e.imag) < 1e-9 * abs(e) else f"{e:.3g}" for e in ev
            )
            rows.append((b, f"{np.linalg.det(K[b]):.4g}", ev_text))
        rel = np.max(np.abs(K["consistent"] - K["generic"])) / np.max(np.abs(K["generic"]))
        doc.add(
            Table(("backend", "det K", "eigenvalues of K (ascending)"), tuple(rows)),
            Paragraph(
                f"Largest difference between the consistent and generic K, relative to the "
                f"largest entry: {rel:.2e}."
            ),
        )


def build_report(
    out: Path,
    params: CaHyManParams = DEFAULT_PARAMS,
    params_file: Path | None = None,
) -> Document:
    """Compute everything and write report.md, report.html and the figures into ``out``.

    Args:
        out: output folder (created).
        params: the parameters of every backend.
        params_file: the file ``params`` were read from, named in the report (None: none).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = Document("CaHyMan stiffness: the published tables against three backends")
    tables = [table_values(pose, params) for pose in TABLE_POSES]
    _intro(doc, params, params_file)
    _summary(doc, tables)
    _tables(doc, tables)
    _linearity(doc)
    _effects(doc, params, tables)
    _weight(doc, params)
    beams_section(doc, params)
    _matrices(doc, params)
    doc.add(
        Heading("Figures"),
        Paragraph(
            "det K is in SI (N^6/rad^3) and does not depend on the reference point: moving "
            "the point along the arm (Fig. 5d, s_4) only transports the same compliance, so "
            "det K of the consistent and generic models is constant there, whereas the "
            "published backend's K, in its own mixed coordinates, is not (crosses mark a negative "
            "determinant, which a symmetric positive definite K cannot have). Figs. 6 and 7 "
            "are linear in the load for every backend; the rotations are shown as the small "
            "rotation vector of the arm in world axes because the plate is level at this "
            "pose (phi = 90 deg)."
        ),
        Figure(figure5(out, params), "Fig. 5: det K versus alpha_k, b_k = d_k, alpha_4, L + s_4"),
        Figure(figure_load(out, params, torque=False), "Fig. 6: displacements versus force"),
        Figure(figure_load(out, params, torque=True), "Fig. 7: displacements versus moment"),
    )
    (out / "report.md").write_text(doc.to_markdown(out))
    (out / "report.html").write_text(doc.to_html())
    return doc

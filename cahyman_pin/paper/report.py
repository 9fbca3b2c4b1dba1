"""The comparison report: CaHyMan's stiffness, and the paper's tables and figures against
the three backends.

:func:`build_report` writes ``report.md``, a self-contained ``report.html`` and the
figures (PNG) into a folder (the command is ``cahyman report``, :mod:`cahyman_pin.cli.report`).
The report lists every parameter with its source (paper, assumed, or given).
"""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

from cahyman_pin.paper.beams import beams_section
from cahyman_pin.paper.compare import table_values
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.paper.differences import effects_section
from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph
from cahyman_pin.paper.explained import (
    classes_section,
    fit_section,
    floor_section,
    sensitivity_section,
)
from cahyman_pin.paper.figures import figure5, figure_load
from cahyman_pin.paper.matrices import matrices_section
from cahyman_pin.paper.opening import opening_section
from cahyman_pin.paper.parameters import conventions_section, parameters_section
from cahyman_pin.paper.summary import summary_section
from cahyman_pin.paper.tables import linearity_section, tables_section
from cahyman_pin.paper.weight import weight_section
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from closedloop.common.files import write_atomically
from closedloop.exceptions import InvalidInputError

#: The report's title: the machine's stiffness first, then the paper's tables checked.
TITLE = "CaHyMan's stiffness at the paper's configurations, and the published tables checked"


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

    Raises:
        InvalidInputError: parameters whose stroke cannot reach the paper's poses, or with
            links as beams. Any error (a pose the parameters make singular) leaves no file
            of this run behind.
    """
    if params.links_as_beams:
        raise InvalidInputError(
            "links_as_beams: the report compares the closed forms with the generic model on "
            "the paper's lumped springs (K_b, K_d, K_4); it shows the links as beams in its "
            "section 'Lumped springs vs beam links'. Remove links_as_beams from the parameters"
        )
    needed = max(pose.s4_mm for pose in TABLE_POSES) * 1e-3
    if params.s4_max < needed:
        raise InvalidInputError(
            f"s4_max = {params.s4_max:g} m: the paper's poses (Table 1, Figs. 5b, 5c) need a "
            f"stroke s_4 of {needed:g} m; give s4_max >= {needed:g}"
        )
    out = Path(out)
    existed = out.exists()
    before = set(out.iterdir()) if existed else set()
    try:
        with warnings.catch_warnings():  # NaN cells of a backend that fails at a pose
            warnings.filterwarnings("ignore", "All-NaN slice", RuntimeWarning)
            warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)
            return _write_report(out, params, params_file)
    except BaseException:  # no half report: what this run wrote goes
        for path in set(out.iterdir()) - before if out.exists() else ():
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        if not existed and out.exists():
            out.rmdir()
        raise


def _write_report(out: Path, params: CaHyManParams, params_file: Path | None) -> Document:
    """:func:`build_report` once its inputs are checked."""
    out.mkdir(parents=True, exist_ok=True)
    doc = Document(TITLE)
    tables = [table_values(pose, params) for pose in TABLE_POSES]
    opening_section(doc)  # the machine, the paper's claims and the terms first,
    matrices_section(doc, params)  # then what a user of the machine wants,
    summary_section(doc, params, tables)  # then the verdict and the figures (placed here,
    at = len(doc.blocks)  # computed last: a section that fails stops the run before them),
    tables_section(doc, tables)
    linearity_section(doc)
    floor_section(doc, params)
    fit_section(doc, params)
    classes_section(doc, params)
    effects_section(doc, params, tables)
    sensitivity_section(doc, out, params)
    weight_section(doc, params)
    beams_section(doc, params)
    parameters_section(doc, params, params_file)
    conventions_section(doc, params, tables)
    figures = Document(doc.title)
    _figures(figures, out, params)
    doc.blocks[at:at] = figures.blocks
    for name, text in (("report.md", doc.to_markdown(out)), ("report.html", doc.to_html())):
        write_atomically(out / name, lambda f, text=text: f.write(text), text=True)
    return doc


def _figures(doc: Document, out: Path, params: CaHyManParams) -> None:
    """Figs. 5-7, written into ``out``."""
    doc.add(
        Heading("Figures"),
        Paragraph(
            "det K is in SI (N^6/rad^3) and does not depend on the reference point: moving "
            "the point along the arm (Fig. 5d, s_4) only transports the same compliance, so "
            "det K of the consistent and generic models is constant there, whereas the "
            "published backend's K, in its own mixed coordinates, is not (crosses mark a negative "
            "determinant, which a symmetric positive definite K cannot have). Figs. 6 and 7 "
            "are linear in the load for every backend; the plate is level at their pose, so "
            "the rotations are tilt and yaw (see 'Conventions')."
        ),
        Figure(figure5(out, params), "Fig. 5: det K versus alpha_k, b_k = d_k, alpha_4, L + s_4"),
        Figure(figure_load(out, params, torque=False), "Fig. 6: displacements versus force"),
        Figure(figure_load(out, params, torque=True), "Fig. 7: displacements versus moment"),
    )

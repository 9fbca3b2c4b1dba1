"""The report's summary: its findings in numbers, computed from the tables below it."""

from __future__ import annotations

import numpy as np

from cahyman_pin.paper.cells import model_values, quantities
from cahyman_pin.paper.classify import classify, counts
from cahyman_pin.paper.compare import BACKENDS, TableValues
from cahyman_pin.paper.data import TABLES, linearity_residual
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.explained import fit_summary_rows
from cahyman_pin.paper.fit import dimension_fit
from cahyman_pin.paper.numbers import fmt
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED, SOURCES, SPRING_FIELDS, CaHyManParams


def summary_section(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
    """Findings in numbers, computed from the tables below."""
    gap = np.concatenate([(tv.values["consistent"] - tv.values["generic"]).ravel()
                          for tv in tables])  # fmt: skip
    both = np.isfinite(gap)
    na = ("'n/a' marks a cell a backend does not give, for the reason under 'Stiffness "
          "matrices at the three configurations'")  # fmt: skip
    if both.all():
        agree = f"agree on every table cell to within {np.max(np.abs(gap)):.1e} (mm or deg)"
    elif both.any():
        agree = (f"agree on the {np.count_nonzero(both)} of {both.size} table cells that both "
                 f"give to within {np.max(np.abs(gap[both])):.1e} (mm or deg; {na})")  # fmt: skip
    else:
        agree = f"cannot be compared here ({na})"
    rows = []
    for b in BACKENDS:
        # over the cells of every table (NaN: a cell the backend does not give)
        diff = [tv.values[b] - tv.values["paper"] for tv in tables]
        trans = np.abs(np.concatenate([d[:3] for d in diff], axis=None))
        rot = np.abs(np.concatenate([d[3:] for d in diff], axis=None))
        ratio = np.concatenate([np.abs(tv.values[b][3:] / tv.values["paper"][3:])
                                for tv in tables], axis=None)  # fmt: skip
        rows.append((b, fmt(np.nanmax(trans), 3), fmt(np.nanmax(rot), 3),
                     fmt(np.nanmedian(ratio), 3)))  # fmt: skip
    lin = np.concatenate([linearity_residual(TABLES[tv.pose.label]) for tv in tables])
    lin = lin.reshape(len(tables), 6)
    ratio, ratio_printed = (rotation_ratio(p) for p in (params, params.with_ks("printed")))
    fits = fit_summary_rows(params)
    chi2 = {name: c for name, c, _, _ in fits}
    classes = classify(params)
    n, n_cells, n_q = counts(classes), len(classes), len(quantities(params))
    dim_converged = dimension_fit(params).converged
    doc.add(
        Heading("Summary"),
        Paragraph(
            "The consistent closed form and the generic Pinocchio backend, two independent "
            f"implementations, {agree}. Neither they nor the published backend reproduces "
            "the published tables; the largest differences over the three tables are:"
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
            f"also about {ratio:.0f} times (median) larger than those of the consistent model "
            f"with the report's parameters ({_springs_text(params)}, K_s = {params.K_s:g} N/m); "
            f"with the printed K_s = {K_S_PRINTED:g} N/m the median ratio is {ratio_printed:.0f} "
            "(K_s, an axial spring of the arm, does not turn it)."
        ),
        Paragraph(
            "Could any stiffness values or dimensions of this machine produce the tables? "
            f"No. The weighted sum of squares (chi^2) over the {n_q} compared quantities, "
            f"which a model matching within the assumed errors would keep near {n_q}, is "
            f"{chi2[fits[0][0]]:.4g} for the reference model, {chi2[fits[1][0]]:.4g} for the "
            f"best stiffness values, {chi2[fits[2][0]]:.4g} for the best assumed dimensions "
            f"found ({'a local optimum' if dim_converged else 'a search stopped at its limit'}), "
            f"and {chi2[fits[3][0]]:.4g} for a machine that does not move at all; the "
            "non-linearity of the tables alone keeps any linear model, of this machine or any "
            f"other, at {chi2[fits[4][0]]:.4g} or more. Of the {n_cells} published cells, "
            f"{n['reproduced']} are "
            f"reproduced, {n['explained']} explained by a named effect and "
            f"{n['unexplained']} unexplained ('Every published cell')."
        ),
    )


def _springs_text(params: CaHyManParams) -> str:
    """The springs of ``params`` but K_s in words: the printed ones, or those that are not."""
    printed = [n for n in SPRING_FIELDS if SOURCES[n] == "paper"]
    given = [f"{n} = {getattr(params, n):g}" for n in printed
             if getattr(params, n) != getattr(DEFAULT_PARAMS, n)]  # fmt: skip
    return "the printed springs" + (f" but {', '.join(given)}" if given else "")


def rotation_ratio(params: CaHyManParams) -> float:
    """Median over the rotation quantities of |published| / |consistent model| (model
    values that are exactly 0 left out)."""
    m = model_values(params)
    p = np.array([q.published for q in quantities(params)])
    rot = np.array([q.row.endswith("[deg]") for q in quantities(params)]) & (np.abs(m) > 0)
    return float(np.median(np.abs(p[rot]) / np.abs(m[rot])))

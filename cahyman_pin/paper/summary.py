"""The report's summary: its findings in numbers, computed from the tables below it."""

from __future__ import annotations

import numpy as np

from cahyman_pin.paper.cells import model_values, published_values, quantities
from cahyman_pin.paper.classify import classify, counts
from cahyman_pin.paper.compare import BACKENDS, TableValues
from cahyman_pin.paper.data import TABLES, linearity_residual
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.explained import fit_summary_rows
from cahyman_pin.paper.fit import dimension_fit
from cahyman_pin.paper.numbers import fmt
from cahyman_pin.params import (
    DEFAULT_PARAMS,
    K_S_ASSUMED,
    K_S_PRINTED,
    SOURCES,
    SPRING_FIELDS,
    CaHyManParams,
)


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
            f"{np.max(np.abs(lin[:, 3:])):.3g} deg in rotation. " + _ks_text(params)
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
    """The springs of ``params`` other than K_s, in words: printed, but for those given."""
    printed = [n for n in SPRING_FIELDS if SOURCES[n] == "paper"]
    given = [f"{n} = {getattr(params, n):g}" for n in printed
             if getattr(params, n) != getattr(DEFAULT_PARAMS, n)]  # fmt: skip
    return "the other springs as the paper prints them" + (
        f" but {', '.join(given)}" if given else ""
    )


def _ks_source(K_s: float) -> str:
    """Where the parameters' K_s [N/m] comes from, in words."""
    if K_s == K_S_PRINTED:
        return "as the paper prints it in its section 4"
    if K_s == K_S_ASSUMED:
        return (
            f"assumed (the paper prints {K_S_PRINTED:g} N/m in its section 4; the report takes "
            f"{K_S_ASSUMED / K_S_PRINTED:.0e} times that)"
        )
    return f"given (the paper prints {K_S_PRINTED:g} N/m in its section 4)"


def _ks_text(params: CaHyManParams) -> str:
    """The published rotations against the consistent model's, with the parameters' K_s
    and with the other of the printed and assumed values (:data:`K_S_PRINTED`,
    :data:`K_S_ASSUMED`): the same ratio, since K_s turns nothing; then the translations,
    which K_s sets."""
    other = K_S_ASSUMED if params.K_s == K_S_PRINTED else K_S_PRINTED
    alt = params.replace(K_s=other)
    ratio, ratio_other = rotation_ratio(params), rotation_ratio(alt)
    other_text = (
        f"the printed K_s = {K_S_PRINTED:g} N/m"
        if other == K_S_PRINTED
        else f"the assumed K_s = {K_S_ASSUMED:g} N/m ({K_S_ASSUMED / K_S_PRINTED:.0e} times "
        "the printed value)"
    )
    reason = (
        f"the same, {ratio_other:.0f}: K_s, the axial spring of the arm's linear motor, lets "
        "M move along the arm and turns nothing, so no rotation depends on it"
        if f"{ratio_other:.0f}" == f"{ratio:.0f}"
        else f"{ratio_other:.0f}"
    )
    published = np.max(np.abs(published_values(params)[_translations(params)]))
    return (
        f"The published rotations are also about {ratio:.0f} times (median) larger than "
        "those of the consistent model with the report's parameters: "
        f"K_s = {params.K_s:g} N/m, {_ks_source(params.K_s)}, and {_springs_text(params)}. "
        f"With {other_text} instead, the median ratio is {reason}. It changes the "
        "translations: the consistent model's largest translation in the tables is "
        f"{fmt(_largest_translation(params))} mm with K_s = {params.K_s:g} N/m and "
        f"{fmt(_largest_translation(alt))} mm with {other:g} N/m, against at most "
        f"{fmt(published)} mm published."
    )


def _translations(params: CaHyManParams) -> np.ndarray:
    """(48,) bool: which quantities of :func:`quantities` are translations [mm]."""
    return np.array([q.row.endswith("[mm]") for q in quantities(params)])


def _largest_translation(params: CaHyManParams) -> float:
    """Largest ``|translation|`` of M [mm] of the consistent model over the tables' cells."""
    return float(np.max(np.abs(model_values(params)[_translations(params)])))


def rotation_ratio(params: CaHyManParams) -> float:
    """Median over the rotation quantities of ``|published|`` / ``|consistent model|`` (model
    values that are exactly 0 left out)."""
    m, p = model_values(params), published_values(params)
    rot = np.array([q.row.endswith("[deg]") for q in quantities(params)]) & (np.abs(m) > 0)
    return float(np.median(np.abs(p[rot]) / np.abs(m[rot])))

"""The report's sections on *could any stiffness values or dimensions produce the tables?*

The linearity floor of the published tables, the stiffness and dimension fits, the class
of every published cell and the sensitivity of every cell to the assumed dimensions
(:mod:`cahyman_pin.paper.cells`, :mod:`~cahyman_pin.paper.fit`,
:mod:`~cahyman_pin.paper.classify`), written into a :class:`Document`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cahyman_pin.paper.cells import (
    LOAD_SHORT,
    RELATIVE_ERROR,
    linearity_floor,
    model_values,
    printed_cells,
    published_values,
    quantities,
    standard_deviations,
    tilt_triangle_ok,
)
from cahyman_pin.paper.classify import (
    COARSE_STEP,
    classify,
    coarse_translations,
    counts,
    largest_unexplained,
)
from cahyman_pin.paper.data import ROWS
from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph, Table
from cahyman_pin.paper.figures import figure_tornado
from cahyman_pin.paper.fit import (
    DIMENSION_EVALUATIONS,
    DIMENSION_RANGE,
    IDLE_CHANGE,
    POLISH_ROUNDS,
    SENSITIVITY_STEP,
    STIFFNESS_GROUPS,
    STIFFNESS_RANGE,
    FitResult,
    dimension_fit,
    dimension_sensitivity,
    linear_optimum,
    linear_optimum_values,
    stiffness_fit,
)
from cahyman_pin.paper.numbers import fmt
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED, SOURCES, CaHyManParams

#: Columns of the two fit tables (stiffness values, dimensions).
FIT_COLUMNS = ("parameter", "printed in the paper", "reference", "fitted",
               "fitted / reference", "note")  # fmt: skip


def _is_rotation(params: CaHyManParams) -> np.ndarray:
    return np.array([q.row.endswith("[deg]") for q in quantities(params)])


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def fit_summary_rows(params: CaHyManParams) -> list[tuple[str, float, float, float]]:
    """(model, chi^2, RMS translation residual [mm], RMS rotation residual [deg]) of the
    reference model, both fits, a rigid machine (zero displacement) and the floor of any
    linear model (RMS of ``|r|``/sqrt(3) per row spread over its three cells)."""
    p, sd, rot = published_values(params), standard_deviations(params), _is_rotation(params)
    rows = []
    for name, v in (("reference model (the report's parameters)", model_values(params)),
                    ("best stiffness values", stiffness_fit(params).values),
                    ("best assumed dimensions", dimension_fit(params).values),
                    ("a rigid machine (every displacement 0)", np.zeros_like(p))):  # fmt: skip
        r = v - p
        rows.append((name, float(np.sum((r / sd) ** 2)), _rms(r[~rot]), _rms(r[rot])))
    floor = linearity_floor(params)
    per_cell = np.zeros(len(p))
    for t in floor:
        per_cell[list(t.indices)] = abs(t.residual) / 3.0  # the unweighted projection
    chi2 = sum(t.chi2_floor for t in floor)
    name = "floor of any linear model (a lower bound from the tables' non-linearity)"
    rows.append((name, chi2, _rms(per_cell[~rot]), _rms(per_cell[rot])))
    return rows


def floor_section(doc: Document, params: CaHyManParams) -> None:
    """What the published tables' own non-linearity costs any linear model."""
    floor = linearity_floor(params)
    ok = ", ".join(f"{k}: {'yes' if v else 'no'}" for k, v in tilt_triangle_ok(params).items())
    doc.add(
        Heading("The floor that the tables' non-linearity puts on any linear model", 3),
        Paragraph(
            "A linear model gives column 3 = column 1 + column 2 in every row (the loads add "
            "up: F + N). With r = column 3 - column 1 - column 2 of a published row, the "
            "nearest triple that adds up is |r|/sqrt(3) away (root sum of squares over the "
            "three cells, each cell moved by |r|/3); with the weights of the fit it costs at "
            "least r^2 / (sd_1^2 + sd_2^2 + sd_3^2) of chi^2. No linear model, of this "
            "machine or any other, can do better. The tilt of the level plate is a norm, not "
            "linear: any linear model's tilts satisfy the triangle inequality |t1 - t2| <= "
            "t3 <= t1 + t2, and the published |dphi| do "
            f"({ok}), so they add nothing to the floor."
        ),
        Table(
            ("table", "row", "r [mm or deg]", "|r|/sqrt(3)", "chi^2 floor"),
            tuple(
                (t.table, t.row, fmt(t.residual, 3, "+"), fmt(t.rms_floor, 3), fmt(t.chi2_floor, 3))
                for t in floor
            ),
            caption="Linearity floor per published row, from the published values",
        ),
        Paragraph(f"Total chi^2 floor: {sum(t.chi2_floor for t in floor):.4g}."),
    )


def _fit_rows(fit: FitResult, printed: dict[str, float], ratio: float) -> tuple:
    rows = []
    for n in fit.names:
        note = {
            "upper": f"at its upper bound ({ratio:g} x reference)",
            "lower": f"at its lower bound (reference / {ratio:g})",
            "": "",
        }[fit.at_bound[n]]
        if n in fit.unidentifiable:
            note = "; ".join(x for x in (note, "not identified by the cells") if x)
        rows.append((n, fmt(printed[n]) if n in printed else "not printed",
                     fmt(fit.reference[n]), fmt(fit.estimates[n]),
                     fmt(fit.estimates[n] / fit.reference[n], 4), note))  # fmt: skip
    return tuple(rows)


def _series_note(fit: FitResult) -> str:
    """K_4 and K_s act in series along the arm: only their series stiffness is identified."""
    if not {"K_s", "K_4"} <= set(fit.unidentifiable):
        return ""

    def series(k: dict[str, float]) -> float:
        return 1.0 / (1.0 / k["K_4"] + 1.0 / k["K_s"])

    return (
        " K_4 and K_s act in series along the arm, so the cells identify only their series "
        f"stiffness 1/(1/K_4 + 1/K_s): {fmt(series(fit.estimates))} N/m fitted, "
        f"{fmt(series(fit.reference))} N/m in the reference."
    )


def _optimum_row(params: CaHyManParams, relative_error: float) -> tuple[str, ...]:
    k, chi2, chi2_rigid = linear_optimum(params, relative_error)
    name = f"rounding and {relative_error:.0%} relative" if relative_error else "rounding alone"
    values = ", ".join(f"{n} = {'rigid' if np.isinf(v) else fmt(v)}" for n, v in k.items())
    qs = quantities(params)
    v = linear_optimum_values(params, relative_error)
    within = sum(
        abs(x - q.published) <= q.half_width for x, q in zip(v, qs, strict=True) if q.linear
    )
    n_lin = sum(q.linear for q in qs)
    return (name, fmt(chi2, 5), fmt(chi2_rigid, 5), f"{1 - chi2 / chi2_rigid:.1%}",
            f"{within} of {n_lin}", values)  # fmt: skip


def _converged(fit: FitResult) -> str:
    on = [n for n in fit.names if fit.at_bound[n]]
    return (
        "a local optimum: converged, and on the bounds ("
        + (", ".join(on) if on else "none")
        + ") chi^2 rises inwards; the valley may hold other optima"
    )


def _unconverged(fit: FitResult) -> str:
    return (
        f"the best values found in {POLISH_ROUNDS} rounds of the active set, each search "
        f"capped at {DIMENSION_EVALUATIONS} evaluations of the model; its chi^2, "
        f"{fit.chi2:.5g}, is an upper bound on what the assumed dimensions within the bounds "
        "can do, not their optimum"
    )


def fit_section(doc: Document, params: CaHyManParams) -> None:
    """The stiffness fit, the dimension fit and what they achieve."""
    sfit, dfit = stiffness_fit(params), dimension_fit(params)
    _, chi2_lin, _ = linear_optimum(params)
    linear = np.array([q.linear for q in quantities(params)])
    sd = standard_deviations(params)
    chi2_fit_lin = float(np.sum((sfit.residuals[linear] / sd[linear]) ** 2))
    printed = {n: getattr(DEFAULT_PARAMS, g[0]) for n, g in STIFFNESS_GROUPS.items()
               if SOURCES[g[0]] == "paper"}  # fmt: skip
    printed["K_s"] = K_S_PRINTED
    rigid = [n for n in sfit.names if sfit.at_bound[n] == "upper"]
    doc.add(
        Heading("Could any stiffness values or dimensions produce the tables?"),
        Paragraph(
            "Two weighted least-squares fits of the consistent model to the published cells, "
            f"in the paper's coordinates ({len(linear)} quantities from the "
            f"{len(printed_cells())} cells: at the level plate "
            "the tilt for dphi and the yaw for dpsi + dtheta, see 'Conventions'). Weights: "
            "each quantity's residual is divided by sd = sqrt(n 0.01^2/12 + "
            f"({RELATIVE_ERROR:g} p)^2), the rounding of its n printed cells (two decimals, mm "
            f"or deg) and a relative error of {RELATIVE_ERROR:.0%} of its published value p "
            "(an assumed error of the paper's own computation): each quantity then counts by "
            "its relative miss, whatever its unit, and the few large cells (Table 2, load N) "
            "do not outweigh the rest; the rounding alone would take 1 mm and 1 deg as alike. "
            "What changes under the rounding alone is shown below. Both fits run in log "
            "space (values stay positive) within bounds, by scipy.optimize.least_squares: the five "
            f"stiffness values between 1/{STIFFNESS_RANGE:g} and {STIFFNESS_RANGE:g} times the "
            "reference (dimensions fixed), the assumed dimensions between "
            f"1/{DIMENSION_RANGE:g} and {DIMENSION_RANGE:g} times the reference (springs "
            "fixed)."
        ),
        Table(
            FIT_COLUMNS,
            _fit_rows(sfit, printed, STIFFNESS_RANGE),
            caption="Stiffness fit [N/m, N m/rad]",
        ),
        Paragraph(
            "The compliance at M is linear in the spring compliances 1/K (each spring adds its "
            f"own term), so on the {int(linear.sum())} linear quantities the stiffness fit is "
            "a non-negative least-squares problem in the compliances, which is convex: its "
            "global optimum "
            f"(scipy.optimize.nnls) has chi^2 = {chi2_lin:.5g} over those quantities; the fit "
            f"above has {chi2_fit_lin:.5g} there. No set of positive stiffness values does "
            "better on those quantities. The fit makes "
            f"{', '.join(rigid) if rigid else 'no spring'} rigid: with any stiffness values "
            "this machine does little better than not moving at all (compare the rigid machine "
            "below)." + _series_note(sfit) + " The same optimum with "
            "weights from the rounding alone (millimetres and degrees taken as alike, the "
            "large cells dominating), next to a rigid machine:"
        ),
        Table(
            (
                "weights",
                "chi^2, best stiffness values",
                "chi^2, rigid machine",
                "share of chi^2 removed",
                "quantities within the rounding",
                "best stiffness values [N/m, N m/rad]",
            ),
            tuple(_optimum_row(params, e) for e in (RELATIVE_ERROR, 0.0)),
            caption="Global optimum of the stiffness values over the "
            f"{int(linear.sum())} linear quantities",
        ),
        Table(
            FIT_COLUMNS,
            _fit_rows(dfit, {}, DIMENSION_RANGE),
            caption="Dimension fit [m] (springs at the reference values"
            + (
                f"; {_converged(dfit)})"
                if dfit.converged
                else f"; not converged: {_unconverged(dfit)})"
            ),
        ),
        Table(
            ("model", "chi^2", "RMS translation residual [mm]", "RMS rotation residual [deg]"),
            tuple((n, fmt(c, 5), fmt(t, 3), fmt(r, 3)) for n, c, t, r in fit_summary_rows(params)),
            caption=f"What each model achieves on the {len(linear)} compared quantities",
        ),
    )


def _coarse(classes) -> str:
    n_trans, n_zero, n_gained = coarse_translations(classes)
    return (
        f" Of the {n_trans} printed translations, {n_zero} have 0 as their second decimal "
        f"(a uniform last digit would give about {n_trans / 10:.0f}): the translations may "
        f"have been rounded to {COARSE_STEP:g} mm, which the rounding above understates; "
        f"with a half-width of {COARSE_STEP / 2:g} mm for those cells, {n_gained} of them "
        "would be reached by the reference model or a fit."
    )


def classes_section(doc: Document, params: CaHyManParams) -> None:
    """The class of every published cell."""
    classes = classify(params)
    n = counts(classes)
    tail = ""
    for kind, rotation in (("translation", False), ("rotation", True)):
        w = largest_unexplained(classes, rotation)
        if w:
            tail += (f" The largest unexplained {kind} residual is {fmt(w.size, 3, '+')} "
                     f"({w.table}, load {LOAD_SHORT[w.load]}, {ROWS[w.row]}).")  # fmt: skip
    doc.add(
        Heading("Every published cell: reproduced, explained or unexplained"),
        Paragraph(
            "Each printed cell is compared through its quantity (at the level plate dphi as "
            "the tilt |dphi|, dpsi and dtheta through their sum). The first rule that holds "
            "gives its class, always against the half-width of the rounding of the printed "
            "digits (0.005 mm or deg per printed cell, the only tolerance the printed numbers "
            "justify): reproduced (the reference model is within the rounding); explained by "
            "the fitted stiffness values or the fitted dimensions (the fit is within the "
            "rounding; size: what the fit changes); explained by a damaged place of the "
            "paper's equations (the change its repair alone makes at the published backend, "
            "'Where the differences come from', matches the gap published - reference within "
            "the rounding, the damages taken as additive; size: minus that change; the weight "
            "terms, shown with masses the paper does not give, explain nothing); explained by the "
            "non-linearity of the published row (the stiffness fit is within the rounding of "
            "the weighted nearest triple of that row that adds up, the one of the floor "
            "above; size: published minus that value); otherwise unexplained, with its "
            "residual after the stiffness fit. "
            f"Counts: {n['reproduced']} reproduced, {n['explained']} explained, "
            f"{n['unexplained']} unexplained, of {len(classes)}." + tail + _coarse(classes)
        ),
        Table(
            (
                "table",
                "load",
                "printed row",
                "printed",
                "compared as",
                "reference",
                "stiffness fit",
                "dimension fit",
                "class",
                "reason",
                "size",
            ),
            tuple(
                (
                    c.table,
                    LOAD_SHORT[c.load],
                    ROWS[c.row],
                    fmt(c.printed),
                    c.compared_as,
                    fmt(c.reference, 3),
                    fmt(c.stiffness_fit, 3),
                    fmt(c.dimension_fit, 3),
                    c.kind,
                    c.reason,
                    fmt(c.size, 3, "+"),
                )
                for c in classes
            ),
            caption="Class of every published cell (mm, deg)",
        ),
    )


def sensitivity_section(doc: Document, out: Path, params: CaHyManParams) -> None:
    """Tornado of every cell against each assumed dimension, and the largest changes."""
    qs = quantities(params)
    rot = _is_rotation(params)
    sens = dimension_sensitivity(params)
    gap = published_values(params) - model_values(params)
    rows = []
    for name, (minus, plus) in sens.items():
        both = np.fmax(np.abs(minus), np.abs(plus))
        cells = []
        for mask, unit in ((~rot, "mm"), (rot, "deg")):
            k = int(np.flatnonzero(mask)[np.nanargmax(both[mask])])
            cells.append(
                f"{fmt(both[k], 3)} {unit} ({qs[k].label})" if both[k] >= IDLE_CHANGE else "0"
            )
        rows.append((name, fmt(getattr(params, name)), *cells))
    largest = np.nanmax([np.fmax(np.abs(m), np.abs(p)) for m, p in sens.values()], axis=0)
    idle = [
        n for n, (m, p) in sens.items() if np.nanmax(np.fmax(np.abs(m), np.abs(p))) < IDLE_CHANGE
    ]
    idle_text = ""
    if idle:
        why = " (the radial sliders take up any change of r_e)" if "r_e" in idle else ""
        idle_text = (f" {', '.join(idle)}: no cell changes by {IDLE_CHANGE:g} or more{why}, so the "
                     "tables cannot identify it.")  # fmt: skip
    doc.add(
        Heading("Sensitivity of every cell to the assumed dimensions"),
        Paragraph(
            f"Each assumed dimension multiplied by {1 - SENSITIVITY_STEP:g} and "
            f"{1 + SENSITIVITY_STEP:g} alone (-+{SENSITIVITY_STEP:.0%}), the consistent model "
            "with the report's springs. Over all cells and dimensions the largest change is "
            f"{fmt(np.max(largest[~rot]), 3)} mm and {fmt(np.max(largest[rot]), 3)} deg, "
            f"against gaps (published - model) of up to {fmt(np.max(np.abs(gap[~rot])), 3)} "
            f"mm and {fmt(np.max(np.abs(gap[rot])), 3)} deg." + idle_text
        ),
        Table(
            ("dimension", "reference [m]", "largest translation change", "largest rotation change"),
            tuple(rows),
            caption=f"Largest change of a cell for -+{SENSITIVITY_STEP:.0%} of each dimension",
        ),
        Figure(
            figure_tornado(out, params),
            f"Tornado: change of every compared cell (mm, deg) when one assumed dimension is "
            f"multiplied by {1 - SENSITIVITY_STEP:g} (light) or {1 + SENSITIVITY_STEP:g} "
            "(solid), cells sorted by their largest change; labels give the gap, published - "
            "model",
        ),
    )

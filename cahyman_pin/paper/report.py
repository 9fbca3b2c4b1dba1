"""The comparison report: the paper's tables and figures against the three backends.

:func:`build_report` writes ``report.md``, a self-contained ``report.html`` and the
figures (PNG) into a folder (the command is ``cahyman report``, :mod:`cahyman_pin.cli.report`).
The report lists every parameter with its source (paper, assumed, or given).
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import warnings
from pathlib import Path

import numpy as np

from cahyman_pin.api import stiffness
from cahyman_pin.backends.published import CHOICES
from cahyman_pin.geometry import plate_pose
from cahyman_pin.paper.beams import beams_section
from cahyman_pin.paper.cells import LOAD_SHORT, model_values, quantities
from cahyman_pin.paper.classify import classify, counts
from cahyman_pin.paper.compare import (
    BACKENDS,
    ROWS_LEVEL,
    ROWS_REGULAR,
    TableValues,
    backend_stiffness,
    is_level,
    paper_coordinates,
    table_values,
)
from cahyman_pin.paper.data import (
    FIG67,
    LOAD_LABELS,
    TABLE_POSES,
    TABLES,
    citation,
    linearity_residual,
)
from cahyman_pin.paper.document import Document, Figure, Heading, Paragraph, Table
from cahyman_pin.paper.effects import (
    EFFECTS,
    NAMED_MASSES,
    effect_changes,
    eq11_masses,
    eq11_masses_text,
    printed_arm_axial_stiffness,
)
from cahyman_pin.paper.explained import (
    classes_section,
    fit_section,
    fit_summary_rows,
    floor_section,
    sensitivity_section,
)
from cahyman_pin.paper.figures import figure5, figure_load
from cahyman_pin.paper.fit import dimension_fit
from cahyman_pin.paper.numbers import fmt, two_decimals
from cahyman_pin.params import (
    BEAM_FIELDS,
    DEFAULT_PARAMS,
    K_S_ASSUMED,
    K_S_PRINTED,
    SOURCES,
    SPRING_FIELDS,
    WEIGHT_FIELDS,
    CaHyManParams,
    params_file_fields,
    source,
)
from closedloop.common.files import write_atomically
from closedloop.elastostatics.compliance import TWIST_LABELS
from closedloop.exceptions import ClosedLoopError, InvalidInputError, JointLimitWarning


def _diff(v: float, ref: float) -> str:
    return fmt(v - ref, 3, "+")


def _matrix_rows(K: np.ndarray) -> tuple[tuple[str, ...], ...]:
    """Rows of a 6x6 matrix; entries below 1e-12 of the largest are shown as 0."""
    tiny = 1e-12 * np.max(np.abs(K))
    return tuple(
        (lab, *("0" if abs(x) < tiny else f"{x:.4g}" for x in K[i]))
        for i, lab in enumerate(TWIST_LABELS)
    )


def _intro(doc: Document) -> None:
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


def _parameters(doc: Document, params: CaHyManParams, params_file: Path | None = None) -> None:
    """The parameter table (values, sources, what is assumed) and the published backend's
    choices."""
    given = f"the parameter file {str(params_file)!r}" if params_file else "no parameter file"
    fields = params_file_fields(params_file) if params_file else frozenset()
    assumed = [f.name for f in dataclasses.fields(params) if _assumed(params, f.name, fields)]
    doc.add(
        Heading("Parameters and conventions"),
        Heading("Parameters", 3),
        Paragraph(
            f"The parameters used, from the defaults of cahyman_pin/params.py and {given}. "
            "'paper' marks a value printed in the paper, 'given' a value of the parameter "
            "file; the values flagged ASSUMED are not in the paper "
            f"({', '.join(assumed) if assumed else 'none here'}); they shape every number "
            "of this report, except the beam fields ("
            f"{', '.join(BEAM_FIELDS)}), which act only where links are beams (with "
            "links_as_beams, and in the section 'Lumped springs vs beam links'), and the "
            f"masses ({', '.join(WEIGHT_FIELDS[:-1])}), which act only through the weight: "
            f"those eq. (11) names ({', '.join(NAMED_MASSES)}) in its weight terms (the "
            "published column and the effect 'weights of eq. (11)'), all of them in the "
            "section 'The weight as a preload'; the consistent and generic columns and the "
            "fits do not depend on them. "
            f"The published column always takes K_s = {K_S_PRINTED:g} N/m as printed (the "
            "first of the choices below), whatever K_s is here (the backend 'published' of "
            "the API and of 'cahyman stiffness' takes the parameters' K_s instead, '--ks "
            "printed' for the printed value)."
        ),
        Table(
            ("parameter", "value (SI)", "assumed", "source"),
            tuple(
                (
                    f.name,
                    f"{getattr(params, f.name):g}",
                    "ASSUMED" if _assumed(params, f.name, fields) else "",
                    source(params, f.name, fields),
                )
                for f in dataclasses.fields(params)
            ),
        ),
        Heading("Choices made to run the published formulation", 3),
        Table(("place", "choice"), tuple(CHOICES)),
    )


def _assumed(params: CaHyManParams, name: str, given: frozenset[str] = frozenset()) -> bool:
    return source(params, name, given).startswith("assumed")


def _conventions(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
    """The one rotation convention of every table and figure, and its one exception."""
    level = [tv.pose.label for tv in tables if tv.level]
    if is_level(plate_pose(FIG67.si[0], params).phi):
        level.append("Figs. 6, 7")
    rising = [
        f"{tv.pose.label} load {LOAD_SHORT[j]} ({two_decimals(TABLES[tv.pose.label][3, j])})"
        for tv in tables
        if tv.level
        for j in range(len(LOAD_LABELS))
        if TABLES[tv.pose.label][3, j] > 0
    ]
    doc.add(
        Heading("Conventions", 3),
        Paragraph(
            "Every table and figure gives displacements of M in world axes (dx, dy, dz [mm]) "
            "and rotations of the arm as increments of the paper's angles (dphi, dpsi, dtheta "
            "[deg], the paper's row order) of R = Rz(theta) Ry(pi/2 - phi) Rz(psi) at the "
            "plate's pose. The published column reads the published backend's C F_M the "
            "same way, but that is in the formulation's own coordinates (choices above), "
            "not a twist at M: translations of H (the plate, eq. 9) plus the arm's deflection "
            "in plate axes (eqs. 4, 5 as printed), with no lever arm (eq. 3), and rotations "
            "the plate's rotation vector plus the arm angle about -y_p. One exception: where "
            "the plate is level (phi = 90 deg: "
            f"{', '.join(level) if level else 'none of the tables'}) the plate "
            "normal is along z, theta and psi turn about the same axis and only their sum is "
            "defined, while a tilt of the normal has no defined direction. There the rotation "
            "is given as tilt (the angle by which the plate normal turns; for the paper, "
            "|dphi|, since phi is at its largest value, 90 deg, and any tilt lowers it) and yaw "
            "d(theta + psi) (for the paper, dpsi + dtheta)."
            + (
                f" The paper prints dphi > 0 there in {', '.join(rising)}, which no small "
                "rotation of a level plate gives."
                if rising
                else ""
            )
        ),
    )


def _summary(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
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


def _tables(doc: Document, tables: list[TableValues]) -> None:
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
        (row, *(two_decimals(linearity_residual(TABLES[p.label])[i]) for p in TABLE_POSES))
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
        doc.add(Heading(effect.name, 3), Paragraph(effect.text(params) + "."))
        rows = []
        for tv in tables:
            d = changes[effect.name][tv.pose.label]
            if d is None:
                rows.append((tv.pose.label, "singular", "singular", "singular"))
                continue
            rows += [(f"{tv.pose.label} {r}", *(fmt(x, 3, "+") for x in d[i]))
                     for i, r in enumerate(tv.rows)]  # fmt: skip
        doc.add(Table(("cell", *LOAD_LABELS), tuple(rows)))
    _ks_note(doc, params, changes)
    k_t4 = np.rad2deg(1.0 / params.K_T4)
    k_t = np.rad2deg(1.0 / params.K_T)
    printed = all(getattr(params, n) == getattr(DEFAULT_PARAMS, n) for n in ("K_T4", "K_T"))
    springs = "printed" if printed else "given"
    qs = quantities(params)
    m = model_values(params)
    moment = [k for k, q in enumerate(qs) if q.load == 1 and q.row.endswith("[deg]")]
    pub = np.abs([qs[k].published for k in moment])
    t3 = [two_decimals(TABLES["Table 3"][i, 1]) for i in range(3, 6)]
    doc.add(
        Heading("Euler singularity and the size of the published rotations", 3),
        Paragraph(
            "At the level plate (Tables 1 and 2) the paper prints dpsi and dtheta separately; "
            "they are compared through yaw and tilt (see 'Conventions'). Under the unit "
            "moment (load N, N_e = (1, 1, 1) N m) the published "
            f"rotations are {two_decimals(pub.min())} to {two_decimals(pub.max())} deg in size "
            f"(Table 3: dphi, dpsi, dtheta = {', '.join(t3)} deg), while the {springs} torsional "
            f"stiffnesses imply {k_t4:.3g} deg per N m for the arm motor (1/K_T4) and "
            f"{k_t:.3g} deg per N m for a leg motor (1/K_T), and the consistent model turns by "
            f"{fmt(np.min(np.abs(m[moment])), 3)} to {fmt(np.max(np.abs(m[moment])), 3)} deg "
            f"under that load: no model with the {springs} springs reproduces the rotation rows, "
            "whereas the translation rows and the sign pattern of the rotations can be "
            "compared. The published tables are also not linear in the load (previous "
            "section), which no linear formulation can reproduce."
        ),
    )


def _ks_note(doc: Document, params: CaHyManParams, changes) -> None:
    """Why the printed K_s hardly changes the published backend, and the series arm a lot."""
    # n/a where the published formulation is singular at every pose of the tables
    size = {name: max((np.max(np.abs(d)) for d in changes[name].values() if d is not None),
                      default=math.nan)
            for name in ("K_s value", "the arm model of eqs. (4)-(8)")}  # fmt: skip
    pose = TABLE_POSES[0]
    _, alpha4, s4 = pose.si
    printed = params.K_s == K_S_PRINTED  # then the effect is 0: explained with the assumed
    K_s = K_S_ASSUMED if printed else params.K_s
    k_printed = printed_arm_axial_stiffness(params, K_S_PRINTED, alpha4, s4)
    k_assumed = printed_arm_axial_stiffness(params, K_s, alpha4, s4)
    doc.add(
        Heading("Why the value of K_s hardly matters to the published backend", 3),
        Paragraph(
            (
                f"The parameters take K_s as printed, {K_S_PRINTED:g} N/m: the 'K_s value' "
                f"effect is zero here (the figures below take the assumed {K_S_ASSUMED:g} N/m "
                "for it). Repairing the arm model moves the cells "
                if printed
                else f"Repairing the value of K_s changes the cells by at most "
                f"{fmt(size['K_s value'], 2)} mm, while repairing the arm model (with the "
                "printed K_s) moves them "
            )
            + (
                f"by up to {fmt(size['the arm model of eqs. (4)-(8)'], 3)} mm. In "
                if math.isfinite(size["the arm model of eqs. (4)-(8)"])
                else "by an amount it cannot tell (singular at every pose of the tables). In "
            )
            + "the printed arm model "
            "(eqs. 4-8) As has two equal columns (dL and ds_4 both move M along the arm), and "
            "its pseudo-inverse puts K_4 and K_s side by side: along the arm the stiffness is "
            f"(K_4 + K_s)/2, {fmt(k_printed, 5)} N/m with the printed K_s = {K_S_PRINTED:g} N/m "
            f"and {fmt(k_assumed, 5)} N/m with K_s = {K_s:g} N/m (computed from the "
            f"printed matrices at the {pose.label} pose), a difference of "
            f"{fmt(1e3 * (1 / k_printed - 1 / k_assumed), 3)} mm per N along the arm, the "
            f"size of the 'K_s value' effect{' with that value' if printed else ''}. The "
            "paper's text puts K_s in series with K_4 "
            "(the consistent arm model, As diag(1/K) As^T): there the printed value adds "
            f"1/K_s = {fmt(1e3 / K_S_PRINTED, 4)} mm per N, the arm model's effect, which no "
            "table shows; hence the assumed value."
        ),
    )


def weight_rows(params: CaHyManParams) -> list[tuple[str, np.ndarray, float]]:
    """(pose label, sag of M (6,) [m, rad], relative change of C) under the weight of the
    masses of the eq. (11) effect (:func:`eq11_masses`), as a preload (generic backend)."""
    heavy = params.replace(**eq11_masses(params))
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
            f"settles under its weight ({eq11_masses_text(params)}, as in the effect above, "
            "placed where eq. (11)'s lever arms put them: cahyman_pin/urdf_builder.py), and "
            "the compliance is the "
            "tangent one at that equilibrium (geometric stiffness and loop curvature "
            "included). Below: the sag of M from the unloaded pose (mm, and the paper's angles "
            "in deg, see 'Conventions') and "
            "the relative change of C (Frobenius norm), generic backend. A linear model's "
            "answer to a load does not depend on the weight; the tangent one changes by the "
            "amount shown, which is the size of what eq. (11) could add."
        ),
    )
    rows = []
    for (label, sag, change), pose in zip(weight_rows(params), TABLE_POSES, strict=True):
        plate = plate_pose(pose.si[0], params)
        v = paper_coordinates(sag, float(plate.phi), float(plate.theta))
        names = ROWS_LEVEL[3:] if len(v) == 5 else ROWS_REGULAR[3:]
        rot = ", ".join(
            f"{n.split(' [')[0]} {fmt(x, 3, '+')}" for n, x in zip(names, v[3:], strict=True)
        )
        rows.append((label, *(fmt(x, 3, "+") for x in v[:3]), rot, fmt(change, 2)))
    doc.add(Table(("pose", "dx [mm]", "dy [mm]", "dz [mm]", "rotation [deg]", "|dC| / |C|"),
                  tuple(rows)))  # fmt: skip


def _api_value(result, name: str):
    """``result.name`` of an API result, or the error of the API (``result`` itself when the
    call was refused)."""
    if isinstance(result, ClosedLoopError):
        return result
    try:
        return getattr(result, name)
    except ClosedLoopError as e:
        return e


def _eigenvalues_text(ev: np.ndarray) -> str:
    return ", ".join(f"{e.real:.4g}" if abs(e.imag) < 1e-9 * abs(e) else f"{e:.3g}" for e in ev)


def _matrices(doc: Document, params: CaHyManParams) -> None:
    doc.add(
        Heading("Stiffness matrices at the three configurations"),
        Paragraph(
            "K at M, world axes, SI (N/m, N/rad, N m/rad), order dx dy dz rx ry rz, from the "
            "generic backend (a matrix acts on small rotation vectors rx, ry, rz about the "
            "world axes: the paper's angles, singular at the level plate, cannot be its "
            "coordinates); eigenvalues and determinant for every backend (the published "
            "K is in its own mixed coordinates, see the choices under 'Parameters and "
            "conventions'). Every number is that "
            "of cahyman_pin.api.stiffness (the consistent and generic K from a square-root "
            "factor of C, not inv(C)); 'n/a' where the API gives none, for the reason stated."
        ),
    )
    for pose in TABLE_POSES:
        results = {}
        for b in BACKENDS:
            try:
                results[b] = backend_stiffness(b, pose, params)
            except ClosedLoopError as e:
                results[b] = e
        values = {b: {name: _api_value(r, name) for name in ("K", "det_K", "eigenvalues")}
                  for b, r in results.items()}  # fmt: skip
        doc.add(Heading(pose.label, 3))
        K_generic = values["generic"]["K"]
        if not isinstance(K_generic, ClosedLoopError):
            doc.add(
                Table(
                    ("", *TWIST_LABELS),
                    _matrix_rows(K_generic),
                    caption=f"K (generic), {pose.describe()}",
                )
            )
        rows, reasons = [], {}
        for b, v in values.items():
            for e in v.values():
                if isinstance(e, ClosedLoopError):
                    reasons.setdefault(b, str(e).rstrip("."))
            det, ev = v["det_K"], v["eigenvalues"]
            rows.append((
                b,
                "n/a" if isinstance(det, ClosedLoopError) else f"{det:.4g}",
                "n/a" if isinstance(ev, ClosedLoopError) else _eigenvalues_text(ev),
            ))  # fmt: skip
        doc.add(Table(("backend", "det K", "eigenvalues of K (ascending)"), tuple(rows)))
        if reasons:
            doc.add(Paragraph("n/a: " + "; ".join(f"{b}: {e}" for b, e in reasons.items()) + "."))
        K_consistent = values["consistent"]["K"]
        if not any(isinstance(K, ClosedLoopError) for K in (K_consistent, K_generic)):
            rel = np.max(np.abs(K_consistent - K_generic)) / np.max(np.abs(K_generic))
            doc.add(
                Paragraph(
                    f"Largest difference between the consistent and generic K, relative to "
                    f"the largest entry: {rel:.2e}."
                )
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
    doc = Document("CaHyMan stiffness: the published tables against three backends")
    tables = [table_values(pose, params) for pose in TABLE_POSES]
    _intro(doc)
    _summary(doc, params, tables)  # the findings first, then the figures (placed here,
    at = len(doc.blocks)  # computed last: a section that fails stops the run before them)
    _tables(doc, tables)
    _linearity(doc)
    floor_section(doc, params)
    fit_section(doc, params)
    classes_section(doc, params)
    _effects(doc, params, tables)
    sensitivity_section(doc, out, params)
    _weight(doc, params)
    beams_section(doc, params)
    _matrices(doc, params)
    _parameters(doc, params, params_file)
    _conventions(doc, params, tables)
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

"""The report's section *where the differences come from*: each damaged place of the
paper's equations repaired alone (:mod:`cahyman_pin.paper.effects`), and why the value of
K_s hardly matters to the published backend."""

from __future__ import annotations

import math

import numpy as np

from cahyman_pin.paper.cells import model_values, quantities
from cahyman_pin.paper.compare import TableValues
from cahyman_pin.paper.data import LOAD_LABELS, TABLE_POSES, TABLES
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.paper.effects import EFFECTS, effect_changes, printed_arm_axial_stiffness
from cahyman_pin.paper.numbers import fmt, two_decimals
from cahyman_pin.params import DEFAULT_PARAMS, K_S_ASSUMED, K_S_PRINTED, CaHyManParams


def effects_section(doc: Document, params: CaHyManParams, tables: list[TableValues]) -> None:
    """Add the section (module docstring) to ``doc``, for ``params`` and the computed
    ``tables``."""
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

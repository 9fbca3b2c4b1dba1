"""Accounting for the differences between the published tables and the consistent model.

Each effect is one damaged place of the paper's closed form (see
:data:`cahyman_pin.backends.published.CHOICES`), switched from its as-published reading to
its consistent one while every other place stays as published; the change it makes in
each table cell, in the paper's units, is its contribution.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cahyman_pin.backends.published import PublishedOptions, a_s, kss
from cahyman_pin.paper.compare import backend_compliance, paper_coordinates
from cahyman_pin.paper.data import LOADS, TABLE_POSES, PaperPose
from cahyman_pin.params import K_S_ASSUMED, K_S_PRINTED, CaHyManParams
from closedloop.exceptions import ClosedLoopError


@dataclass(frozen=True)
class Effect:
    """A damaged place and the option change that repairs it."""

    name: str
    change: dict
    note: str | Callable[[CaHyManParams], str]
    params_change: dict | Callable[[CaHyManParams], dict] = dataclasses.field(default_factory=dict)

    def text(self, params: CaHyManParams) -> str:
        """The note, for ``params``."""
        return self.note(params) if callable(self.note) else self.note

    def params(self, params: CaHyManParams) -> CaHyManParams:
        """``params`` with the effect's parameter change (a mapping, or one made from them)."""
        change = self.params_change(params) if callable(self.params_change) else self.params_change
        return params.replace(**change) if change else params


#: Mass [kg] given to each of the five named parts to show the weight terms of eq. (11)
#: when the parameters give none of them.
ILLUSTRATIVE_MASS = 0.5
#: The five masses that eq. (11) names.
NAMED_MASSES = ("m_HQ", "m_QM", "m_MM2", "m_M4", "m_M5")


def eq11_masses(params: CaHyManParams) -> dict[str, float]:
    """The five named masses [kg] of the weight terms: those of ``params`` when any is
    given (non-zero), else :data:`ILLUSTRATIVE_MASS` each."""
    given = {m: getattr(params, m) for m in NAMED_MASSES}
    return given if any(given.values()) else dict.fromkeys(NAMED_MASSES, ILLUSTRATIVE_MASS)


def eq11_masses_text(params: CaHyManParams) -> str:
    """How :func:`eq11_masses` chose the masses, for the report's text."""
    if any(getattr(params, m) for m in NAMED_MASSES):
        listed = ", ".join(f"{m} = {getattr(params, m):g} kg" for m in NAMED_MASSES)
        return f"the masses of the parameters ({listed})"
    return (f"an illustrative {ILLUSTRATIVE_MASS} kg for each of the five masses (the paper "
            "gives no masses, nor do the parameters)")  # fmt: skip


def _weights_note(params: CaHyManParams) -> str:
    return ("weight terms dropped (gravity belongs to a separate preload); shown with "
            + eq11_masses_text(params))  # fmt: skip


def _ks_effect_note(K_s: float) -> str:
    if K_s == K_S_PRINTED:
        return f"none here: the parameters take K_s as printed, {K_S_PRINTED:g} N/m"
    which = "the assumed" if K_s == K_S_ASSUMED else "the parameters'"
    return f"{K_S_PRINTED:g} N/m as printed -> {which} {K_s:g} N/m"


#: The effects, one per damaged place (:data:`cahyman_pin.backends.published.CHOICES`), in
#: the order the report lists them.
EFFECTS = (
    Effect("lever arm of eq. (3)", {"lever_arm": True},
           "plate twist at H transported to M (rotation x lever arm) before the sum"),
    Effect("K_s value", {"ks": "params"}, lambda p: _ks_effect_note(p.K_s)),
    Effect("weights of eq. (11)", {"weights": False}, _weights_note, eq11_masses),
    Effect("A_d damage, eqs. (18)-(19)", {"a_d": "printed"},
           "A_d as printed (secant form, singular where y_1, y_2 or C_psi = 2 z_1 - z_2 - "
           "z_3 is 0, eq. (19)'s divisors) instead of the Jacobian of the closed-form "
           "kinematics"),
    Effect("K_T dropped in eq. (14)", {"leg_block": "3x3"},
           "leg block keeps K_Tk (condensed 3x3) instead of the printed first 2x2"),
    Effect("the arm model of eqs. (4)-(8)", {"serial_form": "series", "serial_frame": "world"},
           "C_ser = As diag(1/K) As^T in world axes instead of the pseudo-inverses"),
    Effect("the leg model and M_FN, M_FT", {"leg_block": "consistent", "m_fn": "consistent",
                                           "m_ft": "transport"},
           "three-spring leg compliance, G^T for M_FN and the wrench transport for M_FT"),
)  # fmt: skip


def cell_values(
    pose: PaperPose, params: CaHyManParams, options: PublishedOptions
) -> np.ndarray | None:
    """(n_rows, 3) table cells of the as-published backend with ``options``; None if singular."""
    cols = []
    try:
        for load in LOADS:
            C, phi, theta = backend_compliance("published", pose, params, load, options)
            cols.append(paper_coordinates(C @ load, phi, theta))
    except ClosedLoopError:
        return None
    return np.column_stack(cols)


def effect_changes(params: CaHyManParams) -> dict[str, dict[str, np.ndarray | None]]:
    """Change of every table cell when each effect is repaired alone.

    Returns:
        ``{effect name: {table label: (n_rows, 3) change [mm, deg] or None (singular)}}``.
    """
    out: dict[str, dict[str, np.ndarray | None]] = {}
    for effect in EFFECTS:
        prm = effect.params(params)
        options = dataclasses.replace(PublishedOptions(), **effect.change)
        out[effect.name] = {}
        for p in TABLE_POSES:
            base = cell_values(p, prm, PublishedOptions())
            v = cell_values(p, prm, options)
            out[effect.name][p.label] = None if v is None or base is None else v - base
    return out


def printed_arm_axial_stiffness(params: CaHyManParams, K_s: float, alpha4: float, s4: float):
    """Axial stiffness [N/m] along the arm of the printed arm model of eqs. (4)-(8).

    The inverse of w^T pinv(Kss pinv(As)) w, w the arm direction in the in-plane arm
    coordinates (x, z, angle). As has two equal columns (dL and ds_4 both move M along
    the arm), so the pseudo-inverses put K_4 and K_s side by side, (K_4 + K_s) / 2,
    instead of in series, 1 / (1/K_4 + 1/K_s): a soft K_s then hardly changes anything.

    Args:
        K_s: the value of K_s [N/m]; alpha4 [rad], s4 [m]: the arm's pose.
    """
    w = np.array([np.cos(alpha4), np.sin(alpha4), 0.0])
    K = kss(alpha4, s4, params, K_s) @ np.linalg.pinv(a_s(alpha4, s4, params))
    return float(1.0 / (w @ np.linalg.pinv(K) @ w))

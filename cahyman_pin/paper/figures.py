"""The paper's figures recomputed with every backend: Fig. 5 a-d (det K) and Figs. 6, 7;
the tornado of the cells' sensitivity to the assumed dimensions.

Each function writes one PNG and returns its path. Sweeps show a progress bar on stderr.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

from cahyman_pin.paper.cells import LOAD_SHORT, model_values, published_values, quantities
from cahyman_pin.paper.compare import (
    BACKENDS,
    ROWS_LEVEL,
    ROWS_REGULAR,
    backend_compliance,
    backend_stiffness,
    is_level,
    paper_coordinates,
)
from cahyman_pin.paper.data import FIG5A, FIG5BCD, FIG67, TABLE_POSES, PaperPose
from cahyman_pin.paper.fit import (
    DIMENSIONS,
    IDLE_CHANGE,
    SENSITIVITY_STEP,
    dimension_sensitivity,
)
from cahyman_pin.params import CaHyManParams
from closedloop.common.files import save_figure
from closedloop.common.progress import progress
from closedloop.exceptions import ClosedLoopError

STYLES = {"published": ("tab:red", "--"), "consistent": ("tab:blue", "-"),
          "generic": ("k", ":")}  # fmt: skip
N_POINTS = 31


def _det_K(backend: str, pose: PaperPose, params: CaHyManParams) -> float:
    """det K of the API (:func:`cahyman_pin.paper.compare.backend_stiffness`), NaN where it
    has none."""
    try:
        return backend_stiffness(backend, pose, params).det_K
    except ClosedLoopError:
        return np.nan


def det_sweep(
    values: np.ndarray, make: Callable[[float], tuple[PaperPose, CaHyManParams]], label: str
) -> dict[str, np.ndarray]:
    """det K [SI, N^6/rad^3] per backend along a sweep; NaN where a backend fails."""
    out = {b: np.empty(len(values)) for b in BACKENDS}
    for i, v in enumerate(progress(values, len(values), label)):
        pose, params = make(float(v))
        for b in BACKENDS:
            out[b][i] = _det_K(b, pose, params)
    return out


def _plot_det(ax, x, dets, xlabel: str, title: str) -> None:
    for b, d in dets.items():
        color, ls = STYLES[b]
        ax.semilogy(x, np.abs(d), color=color, ls=ls, label=BACKENDS[b])
        neg = d < 0
        if np.any(neg):
            ax.semilogy(x[neg], np.abs(d[neg]), "x", color=color, label=f"{BACKENDS[b]} (det < 0)")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("|det K| [N^6/rad^3]")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def figure5(out_dir: Path, params: CaHyManParams) -> Path:
    """Fig. 5 a-d: det K versus alpha_k, b_k = d_k, alpha_4 and L + s_4."""
    base = FIG5BCD
    alphas = np.linspace(30.0, 90.0, N_POINTS)
    bs = np.linspace(0.04, 0.16, N_POINTS)
    a4s = np.linspace(0.0, 90.0, N_POINTS)
    s4s = np.linspace(0.0, params.s4_max * 1e3, N_POINTS)
    sweeps = [
        (alphas, lambda v: (PaperPose("", (v, v, v), FIG5A.alpha4_deg, FIG5A.s4_mm), params),
         "alpha_1 = alpha_2 = alpha_3 [deg]", "a) alpha_4 = 60 deg, s_4 = 25 mm"),
        (bs, lambda v: (base, params.replace(b=v)),
         "b_k = d_k [m]", "b) alpha_k = alpha_4 = 60 deg, s_4 = 50 mm"),
        (a4s, lambda v: (PaperPose("", base.alpha_deg, v, base.s4_mm), params),
         "alpha_4 [deg]", "c) alpha_k = 60 deg, s_4 = 50 mm"),
        (s4s, lambda v: (PaperPose("", base.alpha_deg, base.alpha4_deg, v), params),
         "L + s_4 [mm]", "d) alpha_k = alpha_4 = 60 deg, s_4 swept"),
    ]  # fmt: skip
    fig, axes = plt.subplots(2, 2, figsize=(10, 8))
    for ax, (x, make, xlabel, title), tag in zip(axes.flat, sweeps, "abcd", strict=True):
        dets = det_sweep(x, make, f"Fig. 5{tag}")
        shown = x + params.L * 1e3 if tag == "d" else x
        _plot_det(ax, shown, dets, xlabel, title)
    fig.suptitle("Fig. 5: determinant of the stiffness matrix at M (SI units)")
    fig.tight_layout()
    path = Path(out_dir) / "fig5_detK.png"
    save_figure(fig, path, dpi=110)
    return path


LOAD_RANGE = np.linspace(0.0, 10.0, 11)


def figure_load(out_dir: Path, params: CaHyManParams, torque: bool) -> Path:
    """Fig. 6 (force F_ex = F_ey = F_ez swept) or Fig. 7 (moment N_ex = N_ey = N_ez swept).

    The panels are the table rows (:func:`cahyman_pin.paper.compare.paper_coordinates`):
    displacement of M [mm] and, the plate being level at this pose (phi = 90 deg), the
    tilt and yaw d(theta + psi) of the arm [deg].
    """
    unit = np.r_[0, 0, 0, 1, 1, 1] if torque else np.r_[1, 1, 1, 0, 0, 0]
    fig, axes = plt.subplots(2, 3, figsize=(12, 7))
    rows = ROWS_REGULAR
    for b in progress(list(BACKENDS), len(BACKENDS), "Fig. 7" if torque else "Fig. 6"):
        try:
            C, phi, theta = backend_compliance(b, FIG67, params, load=unit)
        except ClosedLoopError:
            continue
        d = paper_coordinates(np.outer(LOAD_RANGE, C @ unit), phi, theta)
        rows = ROWS_LEVEL if is_level(phi) else ROWS_REGULAR
        color, ls = STYLES[b]
        for i in range(len(rows)):
            axes.flat[i].plot(LOAD_RANGE, d[:, i], color=color, ls=ls, label=BACKENDS[b])
    xlabel = "N_ex = N_ey = N_ez [N m]" if torque else "F_ex = F_ey = F_ez [N]"
    for ax, comp in zip(axes.flat, rows, strict=False):
        ax.set_xlabel(xlabel)
        ax.set_ylabel(comp)
        ax.grid(True, alpha=0.3)
    for ax in axes.flat[len(rows) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=8)
    name = "Fig. 7" if torque else "Fig. 6"
    fig.suptitle(f"{name}: displacement of M, {FIG67.describe()}")
    fig.tight_layout()
    path = Path(out_dir) / ("fig7_torque.png" if torque else "fig6_force.png")
    save_figure(fig, path, dpi=110)
    return path


def figure_tornado(out_dir: Path, params: CaHyManParams) -> Path:
    """Tornado of every compared quantity against each assumed dimension at -+20 %.

    One panel per table and kind (translations [mm], rotations [deg]); per quantity one
    bar per dimension from 0 to its change when that dimension is multiplied by 1.2
    (solid) and by 0.8 (light), the consistent model; quantities sorted by their largest
    change, the largest on top; the label gives the published minus the model value
    (gap). Dimensions that change no quantity are named in the title, not drawn.
    """
    qs = quantities(params)
    sens = dimension_sensitivity(params)
    gap = published_values(params) - model_values(params)
    largest = {n: np.nanmax(np.fmax(np.abs(m), np.abs(p))) for n, (m, p) in sens.items()}
    drawn = [n for n in DIMENSIONS if largest[n] >= IDLE_CHANGE]
    idle = [n for n in DIMENSIONS if n not in drawn]
    colours = dict(zip(drawn, plt.get_cmap("tab10").colors, strict=False))
    n_dim = len(drawn)
    step = f"{SENSITIVITY_STEP:.0%}"
    fig, axes = plt.subplots(len(TABLE_POSES), 2, figsize=(11, 16))
    for row_axes, pose in zip(axes, TABLE_POSES, strict=True):
        for ax, rotation in zip(row_axes, (False, True), strict=True):
            idx = [k for k, q in enumerate(qs) if q.table == pose.label
                   and q.row.endswith("[deg]") == rotation]  # fmt: skip
            size = [max((np.nanmax(np.abs([sens[n][0][k], sens[n][1][k]])) for n in drawn),
                        default=0.0) for k in idx]  # fmt: skip
            idx = [idx[i] for i in np.argsort(size, kind="stable")[::-1]]
            slots = np.arange(len(idx)) * (n_dim + 1)
            unit = "deg" if rotation else "mm"
            for d, name in enumerate(drawn):
                minus, plus = sens[name][0][idx], sens[name][1][idx]
                ax.barh(slots + d, plus, color=colours[name], height=0.9)
                ax.barh(slots + d, minus, color=colours[name], height=0.9, alpha=0.35)
            centres = [slot * (n_dim + 1) + (n_dim - 1) / 2 for slot in range(len(idx))]
            ax.set_yticks(centres)
            ax.set_yticklabels(
                [f"{LOAD_SHORT[qs[k].load]} {qs[k].row}\ngap {gap[k]:+.3g} {unit}" for k in idx],
                fontsize=7,
            )
            ax.invert_yaxis()
            ax.axvline(0.0, color="k", lw=0.6)
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
            ax.set_xlabel(f"change of the cell [{unit}]")
            ax.set_title(f"{pose.label}: {'rotations' if rotation else 'translations'}",
                         fontsize=9)  # fmt: skip
            ax.grid(True, axis="x", alpha=0.3)
    handles = [plt.Rectangle((0, 0), 1, 1, color=colours[n]) for n in drawn]
    if drawn:
        fig.legend(handles, drawn, loc="upper center", bbox_to_anchor=(0.5, 0.975), ncol=n_dim,
                   fontsize=9, title=f"solid: dimension +{step}, light: -{step}",
                   title_fontsize=8)  # fmt: skip
    no_change = f"; {', '.join(idle)}: no change" if idle else ""
    fig.suptitle(f"Change of every compared cell for -+{step} of each assumed dimension, "
                 f"consistent model{no_change}", y=0.995)  # fmt: skip
    fig.subplots_adjust(left=0.16, right=0.98, top=0.93, bottom=0.04, wspace=0.45, hspace=0.25)
    path = Path(out_dir) / "tornado_dimensions.png"
    save_figure(fig, path, dpi=80)
    return path

"""The paper's figures recomputed with every backend: Fig. 5 a-d (det K) and Figs. 6, 7.

Each function writes one PNG and returns its path. Sweeps show a progress bar on stderr.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from cahyman_pin.paper.compare import BACKENDS, backend_compliance
from cahyman_pin.paper.data import FIG5A, FIG5BCD, FIG67, PaperPose
from cahyman_pin.params import CaHyManParams
from closedloop.exceptions import ClosedLoopError
from closedloop.progress import progress

STYLES = {"published": ("tab:red", "--"), "consistent": ("tab:blue", "-"),
          "generic": ("k", ":")}  # fmt: skip
N_POINTS = 31


def _det_K(backend: str, pose: PaperPose, params: CaHyManParams) -> float:
    try:
        C, _, _ = backend_compliance(backend, pose, params)
        return float(1.0 / np.linalg.det(C))
    except (ClosedLoopError, np.linalg.LinAlgError):
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


LOAD_RANGE = np.linspace(0.0, 10.0, 11)
COMPONENTS = ("dx [mm]", "dy [mm]", "dz [mm]", "rx [deg]", "ry [deg]", "rz [deg]")


def figure_load(out_dir: Path, params: CaHyManParams, torque: bool) -> Path:
    """Fig. 6 (force F_ex = F_ey = F_ez swept) or Fig. 7 (moment N_ex = N_ey = N_ez swept).

    The six panels are the displacement of M (mm) and the small rotation vector of the arm
    (deg, world axes): at this pose the plate is level (phi = 90 deg), where the paper's
    dphi, dpsi, dtheta are not individually defined.
    """
    unit = np.r_[0, 0, 0, 1, 1, 1] if torque else np.r_[1, 1, 1, 0, 0, 0]
    fig, axes = plt.subplots(2, 3, figsize=(12, 7))
    for b in progress(list(BACKENDS), len(BACKENDS), "Fig. 7" if torque else "Fig. 6"):
        try:
            C, _, _ = backend_compliance(b, FIG67, params, load=unit)
        except ClosedLoopError:
            continue
        d = np.outer(LOAD_RANGE, C @ unit)
        d[:, :3] *= 1e3
        d[:, 3:] = np.rad2deg(d[:, 3:])
        color, ls = STYLES[b]
        for i, ax in enumerate(axes.flat):
            ax.plot(LOAD_RANGE, d[:, i], color=color, ls=ls, label=BACKENDS[b])
    xlabel = "N_ex = N_ey = N_ez [N m]" if torque else "F_ex = F_ey = F_ez [N]"
    for ax, comp in zip(axes.flat, COMPONENTS, strict=True):
        ax.set_xlabel(xlabel)
        ax.set_ylabel(comp)
        ax.grid(True, alpha=0.3)
    axes.flat[0].legend(fontsize=8)
    name = "Fig. 7" if torque else "Fig. 6"
    fig.suptitle(f"{name}: displacement of M, {FIG67.describe()}")
    fig.tight_layout()
    path = Path(out_dir) / ("fig7_torque.png" if torque else "fig6_force.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

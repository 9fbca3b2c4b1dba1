"""The figures of a path under a load (:class:`closedloop.analysis.path_results.PathResult`):
the error along the path before and after compensation, and the path in 3D with its
deflection amplified."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from closedloop.common.files import save_figure

#: Smallest value drawn on the figures' logarithmic axes [mm, mrad]: an exact
#: compensation's residual (rounding, 1e-13 m) stays visible, a zero drawn there.
LOG_FLOOR = 1e-12
#: The amplified deflection spans about this fraction of the path's extent (the 3D figure).
SHOWN_FRACTION = 0.15


def load_title(result) -> str:
    """The load of a path's title: the wrench if constant, else its range, and the weight."""
    w = result.wrenches
    if len(w) and np.all(w == w[0]):
        f, n = (", ".join(f"{x:.4g}" for x in part) for part in (w[0, :3], w[0, 3:]))
        text = f"force ({f}) N, torque ({n}) N m"
    else:
        top = np.max(np.linalg.norm(w[:, :3], axis=1), initial=0.0)
        text = f"wrench varying along the path (|f| up to {top:.4g} N)"
    return text + (", with gravity" if result.gravity is not None else "")


def plot_errors(result, path: Path) -> None:
    """PNG: the translation [mm] and rotation [mrad] errors of the frame along the path
    (norms, logarithmic axes) without compensation, with the first-order one and with the
    exact one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    i = np.arange(result.n)
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7.0, 5.2), dpi=100)
    for name, a, style in (
        ("without compensation", result.error, "-"),
        ("first-order compensation (C w)", result.residual_first_order, "--"),
        ("exact compensation", result.residual, ":"),
    ):
        t = 1e3 * np.linalg.norm(a[:, :3], axis=1)
        r = result.held_rotation(a[:, 3:])
        top.semilogy(i, np.maximum(t, LOG_FLOOR), style, label=name)
        bottom.semilogy(i, np.maximum(1e3 * r, LOG_FLOOR), style, label=name)
    top.set_ylabel("translation [mm]")
    bottom.text(0.01, 0.02, f"values below {LOG_FLOOR:g} drawn at {LOG_FLOOR:g}",
                transform=bottom.transAxes, fontsize=7)  # fmt: skip
    bottom.set_ylabel(f"{result.rotation_measure} [mrad]")
    bottom.set_xlabel("path point")
    top.legend(fontsize=8)
    top.set_title(
        f"error of {result.frame} along the path ({result.task} task; compensated: "
        f"{result.held})\n{load_title(result)}",
        fontsize=9,
    )
    fig.tight_layout()
    save_figure(fig, path)


def amplification(result) -> float:
    """A round factor (1, 2 or 5 times a power of ten) that shows the largest deflection as
    about :data:`SHOWN_FRACTION` of the path's extent (of the model's length L for a path
    that does not move); 1 without deflection."""
    d = np.max(np.linalg.norm(result.error[:, :3], axis=1), initial=0.0)
    extent = float(np.max(np.ptp(result.poses[:, :3], axis=0), initial=0.0)) if result.n else 0
    extent = extent or result.length
    if not d > 0.0:
        return 1.0
    raw = SHOWN_FRACTION * extent / d
    power = 10.0 ** math.floor(math.log10(raw))
    return max(step for step in (1.0, 2.0, 5.0) if step * power <= raw) * power


def plot_path(result, path: Path) -> None:
    """PNG: the programmed path of the frame's origin in 3D and the deflected one, the
    deflection amplified by :func:`amplification` (stated in the title)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = result.poses[:, :3]
    scale = amplification(result)
    fig = plt.figure(figsize=(6.4, 5.6), dpi=100)
    ax = fig.add_subplot(projection="3d")
    deflected = p + scale * result.error[:, :3]
    ax.plot(*p.T, "k-", marker="." if result.n < 50 else None, label="programmed path")
    ax.plot(*deflected.T, "r-", label=f"deflected path (deflection x {scale:g})")
    compensated = p + scale * result.residual[:, :3]
    ax.plot(*compensated.T, "g:", label=f"compensated (residual x {scale:g})")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ends = np.vstack([p, deflected, compensated])
    centre = 0.5 * (ends.min(axis=0) + ends.max(axis=0))
    half = 0.55 * float(np.max(np.ptp(ends, axis=0))) or 0.5 * result.length
    for set_limits, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
        set_limits(c - half, c + half)  # equal axes: the path's shape as it is
    ax.set_box_aspect((1.0, 1.0, 1.0))
    d = 1e3 * np.max(np.linalg.norm(result.error[:, :3], axis=1), initial=0.0)
    ax.set_title(
        f"{result.frame}: the path and its deflection, amplified {scale:g} times\n"
        f"(largest deflection {d:.4g} mm; {load_title(result)})",
        fontsize=9,
    )
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    save_figure(fig, path)

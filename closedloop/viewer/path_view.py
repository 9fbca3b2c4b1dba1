"""A path and its deflection in the meshcat viewer: the robot at one point of a path
(:class:`closedloop.analysis.path_results.PathResult`) drawn as
:mod:`closedloop.viewer.viewer` draws a deflection (the ghost at the point's unloaded pose,
the deflected robot under the point's wrench, linear, amplified), with the programmed path of
the frame's origin (black) and the deflected path (red: the path's computed deflection under
the wrench and the weight, amplified by the same factor) as lines.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import meshcat.geometry as mg
import numpy as np

from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.viewer.scene import DeflectionScene, deflection_scene
from closedloop.viewer.viewer import DeflectionViewer, check_output_path, drawn_geometry

#: Node of the path's lines, and their colours (RGB).
PATH = "path"
PATH_COLOR, DEFLECTED_COLOR = 0x111111, 0xD62728


def draw_path(viewer, programmed: np.ndarray, deflected: np.ndarray) -> None:
    """The lines through the points (n, 3) [m], world frame, of the programmed and the
    deflected path (a path of one point: nothing)."""
    node = viewer[PATH]
    node.delete()
    if len(programmed) < 2:
        return
    for name, points, color in (("programmed", programmed, PATH_COLOR),
                                ("deflected", deflected, DEFLECTED_COLOR)):  # fmt: skip
        geometry = mg.PointsGeometry(np.asarray(points, dtype=np.float32).T)
        node[name].set_object(mg.Line(geometry, mg.LineBasicMaterial(color=color, linewidth=2)))


def run_path_view(
    clm: ClosedLoopModel,
    result,
    *,
    point: int | None = None,
    html: str | Path | None = None,
    duration: float | None = None,
    out: Callable[[str], None] = print,
) -> DeflectionScene:
    """Show a path's point (default: the one of largest deflection) with the path's lines;
    write the page to ``html`` or serve it live until Ctrl-C (or for ``duration`` [s]).

    Args:
        clm: the model of the path, with its visual geometry.
        result: the :class:`~closedloop.analysis.path_results.PathResult`.
        point: the point shown (0 <= point < n).
        html, duration, out: as :func:`closedloop.viewer.viewer.run_view`.

    Raises:
        InvalidInputError: no visual geometry, a bad point, an output that cannot be written.
    """
    from closedloop.exceptions import InvalidInputError

    path = None if html is None else check_output_path(html)
    drawn_geometry(clm)
    if not result.n:
        raise InvalidInputError("the path has no point to show")
    if point is None:
        point = int(np.argmax(np.linalg.norm(result.error[:, :3], axis=1)))
    if not (isinstance(point, int) and 0 <= point < result.n):
        raise InvalidInputError(f"point {point!r}; expected 0 to {result.n - 1}")
    scene = deflection_scene(
        clm, result.q_target[point], result.frame, result.wrenches[point], check_limits=False
    )
    programmed = result.poses[:, :3]
    deflected = programmed + scene.scale * result.error[:, :3]
    text = (
        f"path point {point} of {result.n}; the path of {result.frame}: programmed (black), "
        f"deflected x{scene.scale:.3g} (red)"
    )
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, pose_text=text)
        draw_path(viewer.viewer, programmed, deflected)
        out(scene.summary())
        if path is not None:
            out(f"wrote {viewer.save_html(path)}")
        else:
            viewer.serve(duration, out)
    return scene

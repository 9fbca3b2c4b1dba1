"""Meshcat viewer of the deflection of a mechanism under a wrench, with a static export.

One meshcat scene (a meshcat server on 127.0.0.1, started for the viewer) holds two
Pinocchio :class:`~pinocchio.visualize.MeshcatVisualizer` of the same model:

* ``nominal``: the unloaded pose q, recoloured translucent (a ghost);
* ``deflected``: the amplified deflected pose integrate(q, s dq) in the model's colours,
  with the amplification s as its property ``amplification`` and in a text label;

and, under ``load`` (at the deflected origin of the loaded frame, world axes), the force
(red, one head) and moment (purple, two heads) as arrows of fixed length rho =
``LEVER_FRACTION`` L (L the model size; the label gives the magnitudes), and under
``compliance`` the compliance ellipsoids (translation green, rotation orange) of
:mod:`closedloop.viewer_scene`, whose radii are floored at ``ELLIPSOID_MIN_FRACTION`` L so
that a rigid direction shows as a flat disc. An animation (meshcat ``Animation``, open
"Animations" in the page's controls) ramps the load from 0 to the wrench.

The scene is translated so that the centre of the model's bounding box is at the origin
of the three.js world (the camera orbits about it); the grid and axes follow, so they
still mark the world ground plane and origin.

Example::

    scene = deflection_scene(clm, q, "P", [0, 0, -20, 0, 0, 0])
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene)
        viewer.save_html("fourbar.html")   # self-contained page, opens offline
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable
from pathlib import Path

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from pinocchio.visualize import MeshcatVisualizer
from pinocchio.visualize.meshcat_visualizer import Plane, applyScalingOnHomegeneousTransform

from .configuration import accepts_configuration
from .exceptions import InvalidInputError
from .model import ClosedLoopModel
from .viewer_scene import (
    LEVER_FRACTION,
    DeflectionScene,
    Ellipsoid,
    bounding_box,
    deflection_scene,
)

GHOST, DEFLECTED, LOAD, COMPLIANCE, LABEL = "nominal", "deflected", "load", "compliance", "label"
#: Colour and opacity (RGBA, 0..1) of the nominal pose.
GHOST_RGBA = (0.55, 0.62, 0.75, 0.3)
FORCE_COLOR, TORQUE_COLOR = 0xD62728, 0x9467BD
ELLIPSOID_COLORS = {"translation": 0x2CA02C, "rotation": 0xFF7F0E}
ELLIPSOID_OPACITY = 0.35
#: Arrow shaft radius and smallest drawn ellipsoid radius, per model size L.
SHAFT_FRACTION, ELLIPSOID_MIN_FRACTION = 0.006, 0.002
#: Camera: direction from the scene centre (world axes) and distance per model size L.
CAMERA_DIRECTION, CAMERA_DISTANCE = (0.45, -1.0, 0.5), 1.2
#: Label: width of a line's square text plane and height of its last line above the
#: highest origin, per L; font size [px] on the 256 px canvas of a line.
LABEL_WIDTH, LABEL_RISE, LABEL_FONT = 0.5, 0.1, 30
#: Duration of the load-ramp animation [s].
ANIMATION_DURATION = 2.0

Y_AXIS = np.array([0.0, 1.0, 0.0])  # axis of meshcat (three.js) cylinders and cones


def _pose(R: np.ndarray | None = None, p=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) homogeneous transform of rotation R (default identity) and translation p [m]."""
    T = np.eye(4)
    T[:3, 3] = p
    if R is not None:
        T[:3, :3] = R
    return T


def _y_to(d: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking the y axis to the unit vector d."""
    return pin.Quaternion.FromTwoVectors(Y_AXIS, d).matrix()


def _look_at(eye: np.ndarray) -> np.ndarray:
    """(4, 4) pose of a three.js camera (y up, looking along -z) at ``eye`` aimed at 0."""
    z = eye / np.linalg.norm(eye)
    x = np.cross(Y_AXIS, z)
    x /= np.linalg.norm(x)
    return _pose(np.column_stack([x, np.cross(z, x), z]), eye)


class DeflectionViewer:
    """Meshcat scene of a model's nominal and deflected poses (module docstring).

    Args:
        clm: model with visual geometry (load it with ``geometry=True``).
        viewer: a meshcat visualizer to draw into; default: a new one, with its own
            meshcat server on 127.0.0.1, stopped by :meth:`close`.

    Raises:
        InvalidInputError: the model has no visual geometry.
    """

    def __init__(self, clm: ClosedLoopModel, viewer: meshcat.Visualizer | None = None):
        if clm.visual_model is None or clm.visual_model.ngeoms == 0:
            raise InvalidInputError(
                f"model {clm.name!r} has no visual geometry to show; load it with geometry"
            )
        self.clm = clm
        self._owns_server = viewer is None
        if viewer is None:
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
                viewer = meshcat.Visualizer()
        self.viewer = viewer
        try:
            self.robots = {name: self._load_robot(name) for name in (GHOST, DEFLECTED)}
        except BaseException:
            self.close()
            raise
        for g in clm.visual_model.geometryObjects:
            node = self.robots[GHOST].getViewerNodeName(g, pin.GeometryType.VISUAL)
            self.viewer[node].set_property("color", list(GHOST_RGBA))

    def _load_robot(self, root: str) -> MeshcatVisualizer:
        robot = MeshcatVisualizer(self.clm.model, None, self.clm.visual_model)
        robot.initViewer(viewer=self.viewer)
        robot.loadViewerModel(rootNodeName=root)
        return robot

    # ------------------------------------------------------------------ drawing
    def show(
        self,
        scene: DeflectionScene,
        *,
        animate: bool = True,
        autoplay: bool = False,
        label: bool = True,
    ) -> None:
        """Draw ``scene`` (replacing any previous one).

        Args:
            scene: from :func:`closedloop.viewer_scene.deflection_scene` for this model.
            animate: add the load-ramp animation.
            autoplay: start the animation when the page opens (else the page shows the
                deflected pose and the animation waits for "play").
            label: draw the text label (amplification and load magnitudes).
        """
        if scene.q.shape != (self.clm.model.nq,):
            raise InvalidInputError("scene was computed for another model")
        for node in (LOAD, COMPLIANCE, LABEL):
            self.viewer[node].delete()
        self.robots[GHOST].display(scene.q)
        self.robots[DEFLECTED].display(scene.q_deflected)
        self.viewer[DEFLECTED].set_property("amplification", scene.scale)
        lo, hi = bounding_box(self.clm, scene.q)
        centre = 0.5 * (lo + hi)
        for node in ("/meshcat", "/Grid", "/Axes"):
            self.viewer[node].set_transform(_pose(p=-centre))
        camera = CAMERA_DISTANCE * scene.size * np.array(CAMERA_DIRECTION)
        camera /= np.linalg.norm(CAMERA_DIRECTION)
        eye = np.array([camera[0], camera[2], -camera[1]])  # world (z up) -> three.js (y up)
        self.viewer["/Cameras/default/rotated/<object>"].set_transform(_look_at(eye))
        self._draw_load(scene)
        for e in scene.ellipsoids:
            self._draw_ellipsoid(e, ELLIPSOID_MIN_FRACTION * scene.size)
        if label:
            self._draw_label(scene, centre + np.array([0.0, 0.0, 0.5 * (hi - lo)[2]]), camera)
        if animate:
            self._animate(scene, autoplay)

    def _draw_load(self, scene: DeflectionScene) -> None:
        node = self.viewer[LOAD]
        node.set_transform(_pose(p=scene.point_deflected))
        length, radius = LEVER_FRACTION * scene.size, SHAFT_FRACTION * scene.size
        for name, v, color, heads in (
            ("force", scene.wrench[:3], FORCE_COLOR, 1),
            ("torque", scene.wrench[3:], TORQUE_COLOR, 2),
        ):
            if np.any(v):
                self._draw_arrow(node[name], v / np.linalg.norm(v), length, radius, color, heads)

    @staticmethod
    def _draw_arrow(node, d: np.ndarray, length: float, radius: float, color, heads: int):
        """Arrow from the node origin along unit d: a cylinder and ``heads`` cones."""
        material = mg.MeshLambertMaterial(color=color)
        head = 5.0 * radius
        shaft = length - heads * head
        node.set_transform(_pose(_y_to(d)))
        node["shaft"].set_object(mg.Cylinder(shaft, radius), material)
        node["shaft"].set_transform(_pose(p=0.5 * shaft * Y_AXIS))
        for k in range(heads):
            cone = node[f"head{k}"]
            cone.set_object(mg.Cylinder(head, radiusTop=0.0, radiusBottom=2.5 * radius), material)
            cone.set_transform(_pose(p=(shaft + (k + 0.5) * head) * Y_AXIS))

    def _draw_ellipsoid(self, e: Ellipsoid, floor: float) -> None:
        if not np.any(e.radii > 0.0):
            return
        material = mg.MeshLambertMaterial(
            color=ELLIPSOID_COLORS[e.kind], opacity=ELLIPSOID_OPACITY, depthWrite=False
        )
        node = self.viewer[COMPLIANCE][e.kind]
        node.set_object(mg.Ellipsoid(np.maximum(e.radii, floor)), material)
        R = e.axes * np.sign(np.linalg.det(e.axes))  # a rotation, not a reflection
        node.set_transform(_pose(R, e.centre))

    def _draw_label(self, scene: DeflectionScene, top: np.ndarray, camera: np.ndarray):
        f, n = np.linalg.norm(scene.wrench[:3]), np.linalg.norm(scene.wrench[3:])
        lines = (
            f"deflection x{scene.scale:.4g}" + (" (auto)" if scene.auto_scaled else ""),
            f"{scene.frame}: |f| {f:.3g} N, |n| {n:.3g} N m",
        )
        width = LABEL_WIDTH * scene.size
        z = np.array([camera[0], camera[1], 0.0])  # face the camera, text upright
        z = z / np.linalg.norm(z) if np.any(z) else np.array([0.0, -1.0, 0.0])
        R = np.column_stack([np.cross([0.0, 0.0, 1.0], z), [0.0, 0.0, 1.0], z])
        for i, text in enumerate(lines):
            texture = mg.GenericTexture(
                {"type": "_text", "text": text, "font_size": LABEL_FONT, "font_face": "sans-serif"}
            )
            material = mg.MeshBasicMaterial(map=texture, transparent=True, depthWrite=False)
            node = self.viewer[LABEL][f"line{i}"]
            node.set_object(Plane(width, width), material)
            rise = LABEL_RISE * scene.size + 1.5 * (len(lines) - 1 - i) * LABEL_FONT / 256 * width
            node.set_transform(_pose(R, top + np.array([0.0, 0.0, rise])))

    def _animate(self, scene: DeflectionScene, autoplay: bool) -> None:
        frames = len(scene.ramp)
        animation = meshcat.animation.Animation(default_framerate=frames / ANIMATION_DURATION)
        robot, fid = self.robots[DEFLECTED], self.clm.frame_id(scene.frame)
        vm, vd = self.clm.visual_model, robot.visual_data
        for k, (t, q) in enumerate(zip(scene.ramp, scene.ramp_q, strict=True)):
            pin.framesForwardKinematics(robot.model, robot.data, q)
            pin.updateGeometryPlacements(robot.model, robot.data, vm, vd)
            with animation.at_frame(self.viewer, k) as frame:
                for i, g in enumerate(vm.geometryObjects):
                    T = applyScalingOnHomegeneousTransform(vd.oMg[i].homogeneous, g.meshScale)
                    frame[robot.getViewerNodeName(g, pin.GeometryType.VISUAL)].set_transform(T)
                frame[LOAD].set_transform(_pose(p=robot.data.oMf[fid].translation))
                grow = max(float(t), 1e-3)  # a zero scale makes three.js normals singular
                frame[LOAD].set_property("scale", "vector3", [grow] * 3)
        self.viewer.set_animation(animation, play=autoplay)

    # ------------------------------------------------------------------ output
    @property
    def url(self) -> str:
        """Address of the live page (http://127.0.0.1:PORT/static/)."""
        return self.viewer.url()

    def static_html(self) -> str:
        """Self-contained HTML page of the current scene (viewer code and data inline)."""
        return self.viewer.static_html()

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path``; returns the path.

        Raises:
            InvalidInputError: the file cannot be written.
        """
        path = Path(path)
        try:
            path.write_text(self.static_html(), encoding="utf-8")
        except OSError as e:
            raise InvalidInputError(f"cannot write HTML file {str(path)!r}: {e.strerror}") from None
        return path

    def serve(self, duration: float | None = None, out: Callable[[str], None] = print) -> None:
        """Print :attr:`url` and keep serving until Ctrl-C or for ``duration`` [s]."""
        out(f"meshcat viewer at {self.url} (Ctrl-C to stop)")
        end = np.inf if duration is None else time.monotonic() + duration
        with contextlib.suppress(KeyboardInterrupt):
            while (left := end - time.monotonic()) > 0.0:
                time.sleep(min(left, 0.5))

    def close(self) -> None:
        """Stop the meshcat server that this viewer started (if any)."""
        window = self.viewer.window
        if self._owns_server and getattr(window, "server_proc", None) is not None:
            window.zmq_socket.close(linger=0)
            window.server_proc.kill()
            window.server_proc.wait()
            window.server_proc = None

    def __enter__(self) -> DeflectionViewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def check_output_path(html: str | Path) -> Path:
    """``html`` as a Path whose folder exists (checked before any work)."""
    path = Path(html)
    if path.is_dir() or not path.parent.is_dir():
        raise InvalidInputError(
            f"HTML file {str(path)!r}: expected a file name in an existing folder"
        )
    return path


@accepts_configuration
def run_view(
    clm: ClosedLoopModel,
    q: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    *,
    scale: float | None = None,
    nonlinear: bool = False,
    close_loops: bool = False,
    rotational: bool = False,
    html: str | Path | None = None,
    duration: float | None = None,
    autoplay: bool = False,
    out: Callable[[str], None] = print,
) -> DeflectionScene:
    """Compute and show a deflection; write the page to ``html`` or serve it live.

    Args:
        clm, q, frame, wrench, scale, nonlinear, close_loops, rotational: as in
            :func:`closedloop.viewer_scene.deflection_scene` (a :class:`Configuration`
            may stand for clm and q).
        html: file for the self-contained page; None serves the live page (127.0.0.1)
            until Ctrl-C or for ``duration`` [s].
        autoplay: start the load-ramp animation when the page opens.
        out: receives the lines to print (summary, file or URL).

    Returns:
        The scene drawn.
    """
    path = None if html is None else check_output_path(html)
    if duration is not None and not (np.isfinite(duration) and duration >= 0.0):
        raise InvalidInputError(f"duration must be a finite number >= 0 [s], got {duration!r}")
    scene = deflection_scene(
        clm,
        q,
        frame,
        wrench,
        scale=scale,
        nonlinear=nonlinear,
        close_loops=close_loops,
        rotational=rotational,
    )
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, autoplay=autoplay)
        out(scene.summary())
        if path is not None:
            out(f"wrote {viewer.save_html(path)}")
        else:
            viewer.serve(duration, out)
    return scene

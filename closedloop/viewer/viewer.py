"""Meshcat viewer of the deflection of a mechanism under a wrench, with a static export.

One meshcat scene, served by :mod:`closedloop.viewer.server` (the meshcat server on
127.0.0.1 only, stopped with the viewer), holds:

* ``robots`` (:mod:`closedloop.viewer.mesh`, each mesh sent once): ``nominal``, the
  unloaded pose q as a translucent ghost (material overridden on a copy of the visual
  model, for every mesh type), and ``deflected``, the amplified deflected pose, each link
  moved rigidly along its own twist amplified by s (:mod:`closedloop.viewer.motion`),
  coloured by the magnitude of the real first-order displacement of
  its surface at the full load (meshes per vertex, primitives at their origin; colour bar
  in mm in the legend), or in the model's colours; the amplification s is the property
  ``amplification`` of ``/meshcat/robots``;
* ``load`` (at the deflected origin of the loaded frame, world axes): the force (red, one
  head) and moment (purple, two heads) as arrows of fixed length rho = ``LEVER_FRACTION``
  L (L the model size; the legend gives the components);
* ``compliance``: the compliance ellipsoids (translation green, rotation orange) of
  :mod:`closedloop.viewer.scene`, at most ``ELLIPSOID_MAX_FRACTION`` L (the legend shows
  the shrink factor) and at least ``ELLIPSOID_MIN_FRACTION`` L (a rigid direction shows
  as a flat disc);
* ``beams``: each flexible link's axis bent (:func:`closedloop.viewer.beam_curves.beam_curves`),
  a chain of thin cylinders from the beam's clamped start to its deflected tip;
* ``grid``: a square grid in the plane of the model's lowest point, its step a round
  length near L / ``GRID_DIVISIONS`` (meshcat's 20 m grid is hidden);
* an animation (meshcat ``Animation``, "Animations" in the page's controls) that ramps the
  load from 0 to the wrench and back, armed once the scene has loaded
  (:mod:`closedloop.viewer.page`, which also writes the HTML legend and the title);
* in the live page, an amplification slider: :meth:`DeflectionViewer.serve` hands the
  chosen value to a callback that redraws the scene (:func:`run_view` does), and the page
  reloads with it.

The scene is translated so that the centre of the robot (the box of both robots'
geometry) is at the origin of the three.js world (the camera orbits about it) and the
camera placed so that everything drawn (robots, arrows, ellipsoids, beams) is in view,
its clipping distances per its size (``CAMERA_NEAR``, ``CAMERA_FAR``: a model of
millimetres or of hundreds of metres is drawn); meshcat's axes follow, so they still
mark the world origin. An unbounded visual object (an MJCF floor plane) is not drawn: the
grid stands for it. A model without visual geometry is drawn as its skeleton, spheres at
the joints and rods between them (:mod:`closedloop.viewer.skeleton`).

Example::

    scene = deflection_scene(clm, q, "P", [0, 0, -20, 0, 0, 0])
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene)
        viewer.save_html("fourbar.html")   # self-contained page, opens offline
"""

from __future__ import annotations

import contextlib
import io
import json
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import meshcat
import numpy as np
import pinocchio as pin

from closedloop.common.files import write_atomically
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.exceptions import ClosedLoopError, InvalidInputError, ViewerError
from closedloop.kinematics.configuration import accepts_configuration
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.viewer.beam_curves import beam_curves
from closedloop.viewer.draw import (  # noqa: F401  (constants: part of this module's interface)
    ANIMATION_DURATION,
    BACKGROUND,
    BEAM_FRACTION,
    BEAMS,
    CAMERA,
    CAMERA_DIRECTION,
    CAMERA_FAR,
    CAMERA_MARGIN,
    CAMERA_NEAR,
    COMPLIANCE,
    ELLIPSOID_COLORS,
    ELLIPSOID_MIN_FRACTION,
    FORCE_COLOR,
    GHOST_RGBA,
    GRID,
    LOAD,
    TORQUE_COLOR,
    beam_clip,
    colormap,
    draw_beams,
    draw_ellipsoid,
    draw_grid,
    draw_load,
    ellipsoid_box,
    grid_step,
    homogeneous,
    legend_info,
    look_at,
)
from closedloop.viewer.ellipsoids import LEVER_FRACTION, unit_vector
from closedloop.viewer.mesh import ROBOTS, RobotPair, drawn_model
from closedloop.viewer.motion import frame_pose
from closedloop.viewer.page import overlay
from closedloop.viewer.scene import DeflectionScene, deflection_scene
from closedloop.viewer.server import (
    GET_CONTROL,
    SET_OVERLAY,
    insert_overlay,
    start_server,
    stop_server,
)
from closedloop.viewer.skeleton import skeleton_model

#: Seconds between two checks of the live page's slider while serving.
CONTROL_POLL = 0.2


class _Command:
    """A meshcat command given as its msgpack-ready dict (``window.send`` lowers it)."""

    def __init__(self, data: dict):
        self.data = data

    def lower(self) -> dict:
        return self.data


class DeflectionViewer:
    """Meshcat scene of a model's nominal and deflected poses (module docstring).

    Args:
        clm: the model, drawn with its visual geometry (load it with ``geometry=True``;
            unbounded objects, an MJCF floor plane, are not drawn) or, without any, as its
            skeleton (:func:`drawn_geometry`).
        viewer: a meshcat visualizer to draw into; default: a new one, with its own
            meshcat server on 127.0.0.1 (:mod:`closedloop.viewer.server`), stopped by
            :meth:`close`. The legend and the page script are in the live page of that
            server only (and in :meth:`static_html` always).

    Attributes:
        skeleton: the model is drawn as its skeleton (it has no visual geometry).

    Raises:
        InvalidInputError: a geometry that cannot be drawn, or neither visual geometry nor
            joints.
        ViewerError: the meshcat server cannot be started (the message says why).
    """

    def __init__(self, clm: ClosedLoopModel, viewer: meshcat.Visualizer | None = None):
        self.clm = clm
        drawn, self.skeleton = drawn_geometry(clm)
        self.robots = RobotPair(clm.model, drawn, GHOST_RGBA)
        self._server = None
        if viewer is None:
            try:
                self._server, zmq_url, _ = start_server()
            except RuntimeError as e:
                raise ViewerError(f"no meshcat viewer: {e}") from None
            try:
                with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
                    viewer = meshcat.Visualizer(zmq_url=zmq_url)
            except BaseException:
                self.close()
                raise
        self.viewer = viewer
        self.overlay = overlay(None, meshes=0, clips=0, autoplay=False, robots=ROBOTS)

    # ------------------------------------------------------------------ drawing
    def show(
        self,
        scene: DeflectionScene,
        *,
        animate: bool = True,
        autoplay: bool = False,
        legend: bool = True,
        pose_text: str | None = None,
        colour_by_displacement: bool = True,
    ) -> None:
        """Draw ``scene`` (replacing any previous one).

        Args:
            scene: from :func:`closedloop.viewer.scene.deflection_scene` for this model.
            animate: add the load-ramp animation.
            autoplay: play the animation once the page has loaded (else the page shows the
                deflected pose and the animation waits for "play" or the time slider).
            legend: write the HTML legend into the page.
            pose_text: the pose as the legend writes it (default: q, rad or m).
            colour_by_displacement: colour the deflected robot by the magnitude of the real
                (not amplified) first-order displacement of its surface at the full load,
                0 to the largest (colour bar in the legend, mm); False, or no deflection:
                the model's colours.
        """
        if scene.q.shape != (self.clm.model.nq,):
            raise InvalidInputError(
                f"scene of {scene.q.size} coordinates q; expected one of model "
                f"{self.clm.name!r} (nq = {self.clm.model.nq})"
            )
        for node in (LOAD, COMPLIANCE, GRID, BEAMS):
            self.viewer[node].delete()
        colours, colour_max = None, None
        if colour_by_displacement and scene.max_displacement > 0.0:
            magnitudes = self.robots.displacements(scene.q, scene.dq)
            top = max(float(np.max(m)) for m in magnitudes)
            if top > 0.0:  # else the deflection moves no geometry drawn: model colours
                colour_max = top
                colours = [
                    c if len(m) > 1 else c[0] for m in magnitudes for c in [colormap(m / top)]
                ]
        command = self.robots.command(scene.poses, scene.poses_deflected, colours)
        self.viewer.window.send(_Command(command))
        self.viewer[ROBOTS].set_property("amplification", scene.scale)
        floor = ELLIPSOID_MIN_FRACTION * scene.size
        lo, hi = self._bounds(scene, floor)
        robot = np.array(
            [self.robots.bounds(scene.poses), self.robots.bounds(scene.poses_deflected)]
        )
        centre = 0.5 * (robot[:, 0].min(axis=0) + robot[:, 1].max(axis=0))  # on the robot
        for node in ("/meshcat", "/Axes"):
            self.viewer[node].set_transform(homogeneous(p=-centre))
        self.viewer["/Grid"].set_property("visible", False)
        self.viewer["/Background"].set_property("top_color", list(BACKGROUND[0]))
        self.viewer["/Background"].set_property("bottom_color", list(BACKGROUND[1]))
        step = grid_step(scene.size)
        draw_grid(self.viewer, centre, lo[2], step, scene.size)
        # the sphere about the robot's centre that holds everything drawn
        radius = float(np.linalg.norm(np.maximum(hi - centre, centre - lo))) or 0.5 * scene.size
        camera = CAMERA_MARGIN * radius * np.array(CAMERA_DIRECTION)
        camera /= np.linalg.norm(CAMERA_DIRECTION)
        eye = np.array([camera[0], camera[2], -camera[1]])  # world (z up) -> three.js (y up)
        node = self.viewer[CAMERA]
        node.set_transform(look_at(eye))
        node.set_property("near", CAMERA_NEAR * radius)
        node.set_property("far", CAMERA_FAR * radius)
        draw_load(self.viewer, scene)
        for e in scene.ellipsoids:
            draw_ellipsoid(self.viewer, e, floor)
        draw_beams(self.viewer, scene.beams, BEAM_FRACTION * scene.size)
        clips = 0
        if animate:
            clips = self._animate(scene)
        info = None
        if legend:
            info = legend_info(self.clm, scene, pose_text, colour_max, self.robots.visual_model,
                               skeleton=self.skeleton)  # fmt: skip
        meshes = 2 * self.robots.visual_model.ngeoms
        args = {"meshes": meshes, "clips": clips, "autoplay": autoplay, "robots": ROBOTS}
        self.overlay = overlay(info, **args)
        if self._server is not None:  # the live page: with the amplification slider
            live = overlay(info, **args, slider=scene.scale)
            window = self.viewer.window
            window.zmq_socket.send_multipart([SET_OVERLAY, json.dumps(live).encode()])
            window.zmq_socket.recv()

    def _bounds(self, scene: DeflectionScene, floor: float) -> np.ndarray:
        """(2, 3) world box [m] of both robots' geometry, the arrows and the ellipsoids."""
        boxes = [self.robots.bounds(scene.poses), self.robots.bounds(scene.poses_deflected)]
        length = LEVER_FRACTION * scene.size
        for v in (scene.wrench[:3], scene.wrench[3:]):
            if np.any(v):
                tip = scene.point_deflected + length * unit_vector(v)
                boxes.append(np.array([tip, tip]))
        boxes += [ellipsoid_box(e, floor) for e in scene.ellipsoids if np.any(e.radii > 0.0)]
        boxes += [np.array([b.points.min(axis=0), b.points.max(axis=0)]) for b in scene.beams]
        boxes = np.array(boxes)
        return np.array([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])

    def _animate(self, scene: DeflectionScene) -> int:
        """Send the load-ramp animation (not playing); returns its number of clips."""
        frames = len(scene.ramp)
        fps = (frames - 1) / ANIMATION_DURATION
        fid = self.clm.frame_id(scene.frame)
        load = {"fps": fps, "name": "default", "tracks": []}
        position = {"name": ".position", "type": "vector3", "keys": []}
        grow = {"name": ".scale", "type": "vector3", "keys": []}
        for k, (t, poses) in enumerate(zip(scene.ramp, scene.ramp_poses, strict=True)):
            origin = frame_pose(self.clm.model, poses, fid)[:3, 3]
            position["keys"].append({"time": k, "value": origin.tolist()})
            g = max(float(t), 1e-3)  # a zero scale makes three.js normals singular
            grow["keys"].append({"time": k, "value": [g, g, g]})
        load["tracks"] = [position, grow]
        animations = [
            {"path": f"/meshcat/{ROBOTS}", "clip": self.robots.clip(scene.ramp_poses, fps)},
            {"path": f"/meshcat/{LOAD}", "clip": load},
        ]
        if scene.beams:
            curves = [beam_curves(self.clm.model, poses) for poses in scene.ramp_poses]
            animations.append({"path": f"/meshcat/{BEAMS}", "clip": beam_clip(curves, fps)})
        command = {
            "type": "set_animation",
            "path": "",
            "animations": animations,
            "options": {"play": False, "repetitions": 1},
        }
        self.viewer.window.send(_Command(command))
        return len(animations)

    # ------------------------------------------------------------------ output
    @property
    def url(self) -> str:
        """Address of the live page (http://127.0.0.1:PORT/static/)."""
        return self.viewer.url()

    def static_html(self) -> str:
        """Self-contained HTML page of the current scene (viewer code, data and legend inline)."""
        return insert_overlay(self.viewer.static_html(), self.overlay)

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path``; returns the path.

        Raises:
            InvalidInputError: the file cannot be written.
        """
        path, html = Path(path), self.static_html()
        try:
            write_atomically(path, lambda f: f.write(html), text=True)
        except OSError as e:
            raise InvalidInputError(f"cannot write HTML file {str(path)!r}: {e.strerror}") from None
        return path

    def poll_control(self) -> dict:
        """The latest control message of the live page (the slider), or {} (fetched once).

        Raises:
            InvalidInputError: this viewer did not start the server.
        """
        if self._server is None:
            raise InvalidInputError("the viewer draws into a server it did not start")
        self.viewer.window.zmq_socket.send_multipart([GET_CONTROL])
        return json.loads(self.viewer.window.zmq_socket.recv().decode("utf-8"))

    def serve(
        self,
        duration: float | None = None,
        out: Callable[[str], None] = print,
        on_amplification: Callable[[float], None] | None = None,
    ) -> None:
        """Print :attr:`url` and serve until Ctrl-C (SIGINT), SIGTERM or ``duration`` [s].

        Args:
            duration: seconds to serve; None: until a signal.
            out: receives the line giving the URL.
            on_amplification: called with each amplification chosen on the live page's
                slider (checked every ``CONTROL_POLL`` s); it redraws the scene.
        """
        end = np.inf if duration is None else time.monotonic() + duration
        with contextlib.suppress(KeyboardInterrupt), _sigterm_interrupts():
            out(f"meshcat viewer at {self.url} (Ctrl-C to stop)")  # signals handled from here
            while (left := end - time.monotonic()) > 0.0:
                time.sleep(min(left, CONTROL_POLL if on_amplification else 0.5))
                if on_amplification is not None and self._server is not None:
                    value = self.poll_control().get("amplification")
                    if isinstance(value, (int, float)) and np.isfinite(value) and value >= 0:
                        on_amplification(float(value))

    def close(self) -> None:
        """Stop the meshcat server that this viewer started (if any)."""
        if self._server is not None:
            viewer = getattr(self, "viewer", None)
            if viewer is not None:
                viewer.window.zmq_socket.close(linger=0)
            stop_server(self._server)
            self._server = None

    def __enter__(self) -> DeflectionViewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def _sigterm_interrupts():
    """SIGTERM raises KeyboardInterrupt (as SIGINT does) inside the block (main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(*_):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def drawn_geometry(clm: ClosedLoopModel) -> tuple[pin.GeometryModel, bool]:
    """The geometry of ``clm`` that the viewer draws, and whether it is the skeleton: its
    visual geometry (:func:`drawn_model`: an MJCF floor plane left out), or, when it has
    none (a robot file without visual elements other than a floor plane, or a model loaded
    without geometry), its skeleton (:func:`closedloop.viewer.skeleton.skeleton_model`).

    Raises:
        InvalidInputError: a model without any joint (no skeleton either).
    """
    drawn = None if clm.visual_model is None else drawn_model(clm.visual_model)
    if drawn is not None and drawn.ngeoms > 0:
        return drawn, False
    if clm.model.njoints < 2:
        raise InvalidInputError(
            f"model {clm.name!r} has no visual geometry and no joint to draw; expected a "
            "model with joints or visual elements"
        )
    return skeleton_model(clm), True


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
    legend: bool = True,
    pose: str | None = None,
    out: Callable[[str], None] = print,
    warn: Callable[[str], None] | None = None,
    check_limits: bool = True,
) -> DeflectionScene:
    """Compute and show a deflection; write the page to ``html`` or serve it live.

    Args:
        clm, q, frame, wrench, scale, nonlinear, close_loops, rotational: as in
            :func:`closedloop.viewer.scene.deflection_scene` (a :class:`~closedloop.Configuration`
            may stand for clm and q).
        html: file for the self-contained page; None serves the live page (127.0.0.1)
            until Ctrl-C or for ``duration`` [s].
        autoplay: play the load-ramp animation once the page has loaded.
        legend: write the HTML legend into the page.
        pose: the pose as the legend writes it (default: q, rad or m).
        out: receives the lines to print (summary, file or URL).
        warn: receives a warning line (a zero wrench: the view shows the unloaded pose).
        check_limits: as in :func:`closedloop.viewer.scene.deflection_scene`.

    Returns:
        The scene drawn.
    """
    path = None if html is None else check_output_path(html)
    drawn_geometry(clm)  # before any work
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
        check_limits=check_limits,
    )
    if warn is not None and not np.any(scene.wrench):
        warn("no load (--force, --torque): the view shows the unloaded pose")
    # the slider's scenes, at one q: the frame's compliance prepared once
    query = ComplianceQuery(clm, frame, "world", check_limits=check_limits)
    options = {"nonlinear": nonlinear, "close_loops": close_loops, "rotational": rotational,
               "check_limits": check_limits, "query": query}  # fmt: skip
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, autoplay=autoplay, legend=legend, pose_text=pose)
        out(scene.summary())
        if path is not None:
            out(f"wrote {viewer.save_html(path)}")
            return scene

        def amplify(value: float) -> None:  # the live page's slider
            try:
                shown = deflection_scene(clm, scene.q, frame, wrench, scale=value, **options)
            except ClosedLoopError as e:  # e.g. loops that cannot be closed: keep the view
                out(f"amplification x{value:.4g} not shown: {' '.join(str(e).split())}")
                return
            viewer.show(shown, autoplay=autoplay, legend=legend, pose_text=pose)
            out(shown.summary())

        viewer.serve(duration, out, on_amplification=amplify)
    return scene

"""Drawing constants and helpers of the deflection viewer (:mod:`closedloop.viewer.viewer`).

Colours, sizes per model size L, the camera, the grid, the arrows and ellipsoids, and the
contents of the legend (:func:`legend_info`, written by :mod:`closedloop.viewer.page`).
"""

from __future__ import annotations

import math

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.viewer.beam_curves import BeamCurve
from closedloop.viewer.ellipsoids import LEVER_FRACTION, Ellipsoid, unit_vector
from closedloop.viewer.motion import AUTO_FRACTION, ROTATION_CAP
from closedloop.viewer.scene import DeflectionScene

LOAD, COMPLIANCE, GRID, BEAMS = "load", "compliance", "grid", "beams"
#: meshcat path of the camera (three.js, y up), placed by the viewer.
CAMERA = "/Cameras/default/rotated/<object>"
#: Colour and opacity (RGBA, 0..1) of the nominal pose.
GHOST_RGBA = (0.55, 0.55, 0.6, 0.3)
FORCE_COLOR, TORQUE_COLOR = 0xD62728, 0x9467BD
ELLIPSOID_COLORS = {"translation": 0x2CA02C, "rotation": 0xFF7F0E}
ELLIPSOID_OPACITY = 0.35
GRID_COLOR = 0x7F7F7F
#: Colour of the drawn beam curves and their radius per model size L.
BEAM_COLOR, BEAM_FRACTION = 0x1F77B4, 0.004
#: Page background, top and bottom colours (RGB, 0..1): light, as in FEA post-processors.
BACKGROUND = ((1.0, 1.0, 1.0), (0.78, 0.81, 0.86))
#: Arrow shaft radius and smallest drawn ellipsoid radius, per model size L.
SHAFT_FRACTION, ELLIPSOID_MIN_FRACTION = 0.006, 0.002
#: The grid: about this many steps a model size, extending this many L from the centre.
GRID_DIVISIONS, GRID_EXTENT = 8, 0.9
#: Camera: direction from the scene centre (world axes); distance per radius of the drawn
#: bounding sphere (meshcat's vertical field of view is 75 deg: 1 / sin(37.5 deg) = 1.64;
#: more, so that the near side does not fill the view).
CAMERA_DIRECTION, CAMERA_MARGIN = (0.45, -1.0, 0.5), 2.0
#: Camera's near and far clipping distances per radius of the drawn bounding sphere
#: (meshcat's fixed 0.01 m and 100 m at a radius of 1 m): a model of a few millimetres,
#: closer than 0.01 m, or of a hundred metres, farther than 100 m, is not clipped away.
CAMERA_NEAR, CAMERA_FAR = 0.01, 100.0
#: Colour map of the deflected robot, displacement magnitude 0 -> largest (viridis stops).
COLORMAP = (
    (0.267, 0.005, 0.329),
    (0.229, 0.322, 0.546),
    (0.128, 0.567, 0.551),
    (0.369, 0.789, 0.383),
    (0.993, 0.906, 0.144),
)
#: Duration of the load-ramp animation [s] (one way).
ANIMATION_DURATION = 2.0

Y_AXIS = np.array([0.0, 1.0, 0.0])  # axis of meshcat (three.js) cylinders and cones


def homogeneous(R: np.ndarray | None = None, p=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) homogeneous transform of rotation R (default identity) and translation p [m]."""
    T = np.eye(4)
    T[:3, 3] = p
    if R is not None:
        T[:3, :3] = R
    return T


def y_to(d: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking the y axis to the unit vector d."""
    return pin.Quaternion.FromTwoVectors(Y_AXIS, d).matrix()


def look_at(eye: np.ndarray) -> np.ndarray:
    """(4, 4) pose of a three.js camera (y up, looking along -z) at ``eye`` aimed at 0."""
    z = eye / np.linalg.norm(eye)
    x = np.cross(Y_AXIS, z)
    x /= np.linalg.norm(x)
    return homogeneous(np.column_stack([x, np.cross(z, x), z]), eye)


def grid_step(size: float, divisions: int = GRID_DIVISIONS) -> float:
    """Round grid step [m] (1, 2 or 5 times a power of ten) nearest to size / divisions."""
    target = size / divisions
    power = 10.0 ** math.floor(math.log10(target))
    return min((m * power for m in (1.0, 2.0, 5.0, 10.0)), key=lambda x: abs(math.log(x / target)))


def colormap(t) -> np.ndarray:
    """(n, 3) RGB (0..1) of the values t in [0, 1] (clipped) on :data:`COLORMAP`."""
    t = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, 1.0)
    stops = np.asarray(COLORMAP)
    x = np.linspace(0.0, 1.0, len(stops))
    return np.column_stack([np.interp(t, x, stops[:, k]) for k in range(3)])


def ellipsoid_box(e: Ellipsoid, floor: float = 0.0) -> np.ndarray:
    """(2, 3) world-axis bounding box [m] of the drawn ellipsoid."""
    r = np.maximum(e.drawn_radii, floor)
    half = np.sqrt((e.axes**2) @ (r**2))
    return np.array([e.centre - half, e.centre + half])


def legend_info(
    clm: ClosedLoopModel,
    scene: DeflectionScene,
    pose: str | None = None,
    colour_max: float | None = None,
    visual_model: pin.GeometryModel | None = None,
    *,
    skeleton: bool = False,
) -> dict:
    """What the legend shows (:func:`closedloop.viewer.page.legend_rows`) for ``scene``.

    Args:
        clm: the model drawn (its name and colours).
        scene: the scene drawn.
        pose: the pose as written in the legend (default: q, rad or m).
        colour_max: largest surface displacement [m] when the deflected robot is coloured
            by displacement magnitude (the colour bar's top), else None (model colours).
        visual_model: the geometry drawn, whose colours the legend shows (default: the
            model's).
        skeleton: the geometry drawn is the model's skeleton (it has no visual geometry).
    """
    if pose is None:
        pose = "q = (" + ", ".join(f"{x:.4g}" for x in scene.q) + ") rad or m"
    colours = []
    shown = clm.visual_model if visual_model is None else visual_model
    for g in shown.geometryObjects:
        c = tuple(np.round(np.asarray(g.meshColor, dtype=float), 3))
        if c not in colours:
            colours.append(c)
    return {
        "model": clm.name,
        "frame": scene.frame,
        "pose": pose,
        "wrench": scene.wrench.tolist(),
        "scale": scene.scale,
        "auto_scaled": scene.auto_scaled,
        "kind": "nonlinear" if scene.nonlinear else "linear",
        "max_displacement": scene.max_displacement,
        "max_rotation": scene.max_rotation,
        "rotation_cap": ROTATION_CAP,
        "auto_fraction": AUTO_FRACTION,
        "reassembled": scene.reassembled,
        "size": scene.size,
        "frame_twist": scene.frame_twist.tolist(),
        "ghost_rgba": GHOST_RGBA,
        "deflected_rgba": colours,
        "arrow_length": LEVER_FRACTION * scene.size,
        "force_color": FORCE_COLOR,
        "torque_color": TORQUE_COLOR,
        "ellipsoids": [
            {
                "kind": e.kind,
                "radii_m": e.radii.tolist(),
                "shrink": e.shrink,
                "color": ELLIPSOID_COLORS[e.kind],
            }
            for e in scene.ellipsoids
        ],
        "grid_color": GRID_COLOR,
        "grid_step": grid_step(scene.size),
        "colour_max": colour_max,
        "colormap": COLORMAP,
        "mode": scene.mode,
        "skeleton": skeleton,
    }


def draw_grid(viewer, centre: np.ndarray, z: float, step: float, size: float) -> None:
    """Square grid of ``step`` [m] in the plane z [m] around ``centre``, +- GRID_EXTENT size."""
    n = max(1, math.ceil(GRID_EXTENT * size / step))
    x0, y0 = (np.round(centre[:2] / step)) * step
    ticks = np.arange(-n, n + 1) * step
    lines = []
    for t in ticks:
        lines += [[x0 + t, y0 - n * step, z], [x0 + t, y0 + n * step, z]]
        lines += [[x0 - n * step, y0 + t, z], [x0 + n * step, y0 + t, z]]
    geometry = mg.PointsGeometry(np.array(lines, dtype=np.float32).T)
    viewer[GRID].set_object(mg.LineSegments(geometry, mg.LineBasicMaterial(color=GRID_COLOR)))


def draw_load(viewer, scene: DeflectionScene) -> None:
    """Force and moment arrows (fixed length) at the deflected origin of the loaded frame."""
    node = viewer[LOAD]
    node.set_transform(homogeneous(p=scene.point_deflected))
    length, radius = LEVER_FRACTION * scene.size, SHAFT_FRACTION * scene.size
    for name, v, color, heads in (
        ("force", scene.wrench[:3], FORCE_COLOR, 1),
        ("torque", scene.wrench[3:], TORQUE_COLOR, 2),
    ):
        if np.any(v):
            draw_arrow(node[name], unit_vector(v), length, radius, color, heads)


def draw_arrow(node, d: np.ndarray, length: float, radius: float, color, heads: int):
    """Arrow from the node origin along unit d: a cylinder and ``heads`` cones."""
    material = mg.MeshLambertMaterial(color=color)
    head = 5.0 * radius
    shaft = length - heads * head
    node.set_transform(homogeneous(y_to(d)))
    node["shaft"].set_object(mg.Cylinder(shaft, radius), material)
    node["shaft"].set_transform(homogeneous(p=0.5 * shaft * Y_AXIS))
    for k in range(heads):
        cone = node[f"head{k}"]
        cone.set_object(mg.Cylinder(head, radiusTop=0.0, radiusBottom=2.5 * radius), material)
        cone.set_transform(homogeneous(p=(shaft + (k + 0.5) * head) * Y_AXIS))


def draw_ellipsoid(viewer, e: Ellipsoid, floor: float) -> None:
    """Translucent ellipsoid of the drawn radii (at least ``floor`` [m])."""
    if not np.any(e.radii > 0.0):
        return
    material = mg.MeshLambertMaterial(
        color=ELLIPSOID_COLORS[e.kind], opacity=ELLIPSOID_OPACITY, depthWrite=False
    )
    node = viewer[COMPLIANCE][e.kind]
    node.set_object(mg.Ellipsoid(np.maximum(e.drawn_radii, floor)), material)
    R = e.axes * np.sign(np.linalg.det(e.axes))  # a rotation, not a reflection
    node.set_transform(homogeneous(R, e.centre))


def beam_segments(curve: BeamCurve) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """(node name, R (3, 3), centre (3,) [m], length [m]) of each segment of a beam curve:
    the rotation taking y to the segment, world frame (a drawn segment is meshcat's unit
    cylinder, height 1 along y, scaled by its length along y)."""
    out = []
    p = curve.points
    for k in range(len(p) - 1):
        d = p[k + 1] - p[k]
        length = float(np.linalg.norm(d))
        R = y_to(d / length) if length > 0.0 else np.eye(3)
        out.append((f"{curve.name}_{k}", R, 0.5 * (p[k] + p[k + 1]), max(length, 1e-12)))
    return out


def draw_beams(viewer, curves: tuple[BeamCurve, ...], radius: float) -> None:
    """Each beam curve as a chain of cylinders of ``radius`` [m] (one node a segment)."""
    material = mg.MeshLambertMaterial(color=BEAM_COLOR)
    for curve in curves:
        for name, R, centre, length in beam_segments(curve):
            node = viewer[BEAMS][name]
            node.set_object(mg.Cylinder(1.0, radius), material)
            node.set_transform(homogeneous(R @ np.diag([1.0, length, 1.0]), centre))


def beam_clip(ramp_curves: list[tuple[BeamCurve, ...]], fps: float) -> dict:
    """Animation clip (three.js JSON, times in frames) of the beam segments, one key a
    pose: position, quaternion and length (scale along y) of each segment."""
    tracks = {}
    for k, curves in enumerate(ramp_curves):
        for curve in curves:
            for name, R, centre, length in beam_segments(curve):
                quat = pin.Quaternion(R).coeffs()  # x, y, z, w as three.js
                for prop, kind, value in (
                    ("position", "vector3", centre),
                    ("quaternion", "quaternion", quat),
                    ("scale", "vector3", (1.0, length, 1.0)),
                ):
                    track = tracks.setdefault(
                        (name, prop), {"name": f"{name}.{prop}", "type": kind, "keys": []}
                    )
                    track["keys"].append({"time": k, "value": [float(x) for x in value]})
    return {"fps": fps, "name": "default", "tracks": list(tracks.values())}

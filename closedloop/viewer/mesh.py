"""The nominal (ghost) and the deflected robot as one meshcat object, each mesh sent once.

Pinocchio's :class:`~pinocchio.visualize.MeshcatVisualizer` sends a ``.dae`` mesh as a
``_meshfile_object`` whose materials come from the file: meshcat's ``color`` property then
fails on the merged multi-material meshes (``setRGB`` of undefined) and a second robot
sends every mesh again. Here both robots are the children of one three.js object
(``set_object`` at ``/meshcat/robots``), whose ``geometries`` list holds each mesh once:

* meshes (``.dae``, ``.stl``, ``.obj``: the triangles Pinocchio loaded for the geometry
  object, vertices already scaled) as indexed float32 triangle buffers, drawn with flat
  shading; primitives (box, cylinder, sphere, capsule) as Pinocchio's meshcat primitives;
* materials from each geometry object's ``meshColor``: the deflected robot from the visual
  model, the ghost from a copy of it whose objects all carry the ghost colour and opacity
  (``overrideMaterial``, :func:`ghost_model`), so that every mesh type is translucent;
* or the deflected robot coloured per vertex (a colour attribute on a copy of the mesh's
  buffer, which its ghost then shares) or per primitive (:meth:`RobotPair.command`).

Tree: ``robots`` / ``nominal`` | ``deflected`` / one group a geometry object (its world
placement) / the mesh (its intrinsic transform and scale). The groups' names are
``ROOT_NAME`` (:func:`node_name`); an animation clip on ``/meshcat/robots/<object>``
moves the deflected groups (:meth:`RobotPair.clip`).
"""

from __future__ import annotations

import re
import uuid

import coal
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from pinocchio.visualize import MeshcatVisualizer
from pinocchio.visualize.meshcat_visualizer import loadMesh

from closedloop.analysis.batch_indices import row_norms
from closedloop.exceptions import InvalidInputError
from closedloop.viewer.motion import joint_jacobian

ROBOTS, GHOST, DEFLECTED = "robots", "nominal", "deflected"
#: meshcat path of the animated object (meshcat puts an object under ``<object>``).
ROBOTS_OBJECT = f"/meshcat/{ROBOTS}/<object>"
_RESERVED = re.compile(r"[\[\]\.:/\s]")  # three.js animation track-name syntax


def node_name(root: str, name: str) -> str:
    """Name of the group of geometry object ``name`` under ``root`` (unique in the tree)."""
    return f"{root}_{_RESERVED.sub('_', name)}"


#: Geometry without bounds (an MJCF floor ``plane``), not drawn: the viewer's grid shows
#: the floor, and such a plane would fill the view and the bounding box.
UNBOUNDED = (coal.Plane, coal.Halfspace)


def drawn_model(visual_model: pin.GeometryModel) -> pin.GeometryModel:
    """Copy of ``visual_model`` without its :data:`UNBOUNDED` objects (the ones drawn)."""
    drawn = pin.GeometryModel()
    for g in visual_model.geometryObjects:
        if not isinstance(g.geometry, UNBOUNDED):
            drawn.addGeometryObject(g)
    return drawn


def ghost_model(visual_model: pin.GeometryModel, rgba) -> pin.GeometryModel:
    """Copy of ``visual_model`` whose objects all carry the material colour ``rgba`` (0..1)."""
    ghost = visual_model.copy()
    for g in ghost.geometryObjects:
        g.overrideMaterial = True
        g.meshColor = np.array(rgba, dtype=float)
    return ghost


def _column_major(T: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(T, dtype=float).T.reshape(-1)]


def _material(rgba, flat: bool, vertex_colors: bool = False) -> dict:
    """three.js Phong material of colour ``rgba`` (0..1); translucent when alpha < 1."""
    r, g, b, a = (float(c) for c in rgba)
    colour = round(255 * r) << 16 | round(255 * g) << 8 | round(255 * b)
    translucent = a < 1.0
    material = mg.MeshPhongMaterial(
        color=colour,
        opacity=a,
        transparent=translucent,
        depthWrite=not translucent,
        flatShading=flat,
        vertexColors=vertex_colors,
    )
    return material.lower(None)


def _geometry(g: pin.GeometryObject) -> tuple[dict, np.ndarray, bool, np.ndarray | None]:
    """(three.js geometry, (4, 4) mesh matrix in the object frame, flat shading, (n, 3)
    vertices [m] in the object frame or None for a primitive) of ``g``."""
    geom = g.geometry
    if isinstance(geom, coal.ShapeBase) and not isinstance(geom, coal.ConvexBase):
        obj = MeshcatVisualizer.loadPrimitive(None, g)  # pinocchio's primitive mapping
        if obj is None:
            raise InvalidInputError(f"geometry {g.name!r}: cannot draw a {type(geom).__name__}")
        scale = np.diag([*np.asarray(g.meshScale, dtype=float), 1.0])
        return obj.lower(None), scale @ obj.intrinsic_transform(), False, None
    if isinstance(geom, (coal.BVHModelBase, coal.ConvexBase)):
        obj = loadMesh(geom)  # vertices as loaded (meshScale applied), triangle indices
        if isinstance(obj, mg.TriangularMeshGeometry):
            return obj.lower(None), np.eye(4), True, np.asarray(obj.vertices, dtype=float)
    raise InvalidInputError(
        f"geometry {g.name!r}: cannot draw a {type(geom).__name__} (no triangles)"
    )


def _mesh_key(index: int, g: pin.GeometryObject):
    """Geometry objects that show the same mesh file at the same scale share one buffer;
    a primitive (or a mesh without a file) is its own, keyed by its index ``index`` in the
    geometry model (not by ``id(g)``: Pinocchio hands out a new wrapper of the object at
    each access, and a freed wrapper's id is reused, which gave every primitive the
    geometry of the first one)."""
    if g.meshPath and isinstance(g.geometry, (coal.BVHModelBase, coal.ConvexBase)):
        return (g.meshPath, tuple(np.round(np.asarray(g.meshScale, dtype=float), 12)))
    return index


class RobotPair:
    """Geometry, materials and placements of the two robots (module docstring).

    Args:
        model: kinematic model.
        visual_model: its visual geometry, without unbounded objects (:func:`drawn_model`;
            not modified).
        ghost_rgba: colour and opacity (0..1) of the nominal pose.
    """

    def __init__(self, model: pin.Model, visual_model: pin.GeometryModel, ghost_rgba):
        self.model, self.visual_model = model, visual_model
        self.ghost_model = ghost_model(visual_model, ghost_rgba)
        self.data, self.geometry_data = model.createData(), visual_model.createData()
        self.geometries: dict = {}  # mesh key -> three.js geometry
        self.parts = []  # per geometry object: (geometry, mesh matrix, flat, vertices)
        for i, g in enumerate(visual_model.geometryObjects):
            key = _mesh_key(i, g)
            if key not in self.geometries:
                self.geometries[key] = _geometry(g)
            self.parts.append(self.geometries[key])
        self.corners = [_corners(g.geometry) for g in visual_model.geometryObjects]

    def placements(self, poses: np.ndarray) -> list[np.ndarray]:
        """(4, 4) world placement of each geometry object, carried rigidly by its parent
        joint placed at ``poses`` (njoints, 4, 4) (world frame)."""
        return [
            poses[g.parentJoint] @ g.placement.homogeneous
            for g in self.visual_model.geometryObjects
        ]

    def bounds(self, poses: np.ndarray) -> np.ndarray:
        """(2, 3) lowest and highest corner [m], world frame, of the geometry with the
        joints at ``poses`` (njoints, 4, 4)."""
        points = [  # the boxes are in the geometry object's frame (coal's, z-axis shapes)
            c @ T[:3, :3].T + T[:3, 3]
            for T, c in zip(self.placements(poses), self.corners, strict=True)
            if c is not None
        ]
        p = np.vstack(points)
        return np.array([p.min(axis=0), p.max(axis=0)])

    def displacements(self, q: np.ndarray, dq: np.ndarray) -> list[np.ndarray]:
        """First-order displacement magnitudes [m] of each geometry object under dq at q.

        Returns:
            Per geometry object: (n,) at its mesh vertices, or (1,) at its origin (primitive).
        """
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.visual_model, self.geometry_data)
        out = []
        for g, M, (_, _, _, vertices) in zip(
            self.visual_model.geometryObjects, self.geometry_data.oMg, self.parts, strict=True
        ):
            J = joint_jacobian(self.model, self.data, g.parentJoint)
            v, w = np.split(J @ dq, 2)  # joint origin velocity and angular velocity
            local = vertices if vertices is not None else np.zeros((1, 3))
            points = local @ M.rotation.T + M.translation
            r = points - self.data.oMi[g.parentJoint].translation
            out.append(row_norms(v + np.cross(w, r)))
        return out

    def command(
        self, nominal: np.ndarray, deflected: np.ndarray, colours: list | None = None
    ) -> dict:
        """The meshcat ``set_object`` command of both robots at their joint placements.

        Args:
            nominal, deflected: (njoints, 4, 4) joint placements (world frame) of the ghost
                and of the deflected robot.
            colours: per geometry object, RGB (0..1) of the deflected robot: (n, 3) at the
                mesh vertices or (3,) for a primitive; None: the model's colours. A mesh
                with vertex colours gets its own buffer (still shared with its ghost).
        """
        materials: dict = {}
        geometries = {g["uuid"]: g for g, _, _, _ in self.geometries.values()}

        def material(rgba, flat: bool, vertex_colors: bool = False) -> str:
            key = (tuple(np.round(np.asarray(rgba, dtype=float), 6)), flat, vertex_colors)
            if key not in materials:
                materials[key] = _material(rgba, flat, vertex_colors)
            return materials[key]["uuid"]

        shown = []  # per geometry object: (geometry uuid, deflected material uuid)
        for i, (g, (geometry, _, flat, _)) in enumerate(
            zip(self.visual_model.geometryObjects, self.parts, strict=True)
        ):
            c = None if colours is None else np.asarray(colours[i], dtype=np.float32)
            if c is not None and c.ndim == 2:
                coloured = {**geometry, "uuid": str(uuid.uuid1())}
                coloured["data"] = {**geometry["data"]}
                attributes = {**geometry["data"]["attributes"], "color": mg.pack_numpy_array(c.T)}
                coloured["data"]["attributes"] = attributes
                geometries[coloured["uuid"]] = coloured
                shown.append((coloured["uuid"], material((1.0, 1.0, 1.0, 1.0), flat, True)))
            elif c is not None:
                shown.append((geometry["uuid"], material((*c, 1.0), flat)))
            else:
                shown.append((geometry["uuid"], material(g.meshColor, flat)))
        used = {uid for uid, _ in shown}

        def group(root: str, vm: pin.GeometryModel, poses: np.ndarray) -> dict:
            children = []
            for g, T, (_, matrix, flat, _), (geometry, drawn) in zip(
                vm.geometryObjects, self.placements(poses), self.parts, shown, strict=True
            ):
                mesh = {
                    "uuid": str(uuid.uuid1()),
                    "type": "Mesh",
                    "name": "mesh",
                    "geometry": geometry,
                    "material": drawn if root == DEFLECTED else material(g.meshColor, flat),
                    "matrix": _column_major(matrix),
                }
                children.append(_group(node_name(root, g.name), T, [mesh]))
            return _group(root, np.eye(4), children)

        tree = _group(
            ROBOTS,
            np.eye(4),
            [
                group(GHOST, self.ghost_model, nominal),
                group(DEFLECTED, self.visual_model, deflected),
            ],
        )
        return {
            "type": "set_object",
            "path": f"/meshcat/{ROBOTS}",
            "object": {
                "metadata": {"version": 4.5, "type": "Object"},
                "geometries": [g for uid, g in geometries.items() if uid in used],
                "materials": list(materials.values()),
                "object": tree,
            },
        }

    def clip(self, ramp_poses: np.ndarray, fps: float) -> dict:
        """Animation clip (three.js JSON, times in frames) moving the deflected groups, one
        key a set of joint placements of ``ramp_poses`` (n, njoints, 4, 4)."""
        tracks = {}
        for k, poses in enumerate(ramp_poses):
            placed = self.placements(poses)
            for g, T in zip(self.visual_model.geometryObjects, placed, strict=True):
                name = node_name(DEFLECTED, g.name)
                quat = pin.Quaternion(T[:3, :3]).coeffs()  # x, y, z, w as three.js
                for prop, kind, value in (
                    ("position", "vector3", T[:3, 3]),
                    ("quaternion", "quaternion", quat),
                ):
                    track = tracks.setdefault(
                        (name, prop), {"name": f"{name}.{prop}", "type": kind, "keys": []}
                    )
                    track["keys"].append({"time": k, "value": [float(x) for x in value]})
        return {"fps": fps, "name": "default", "tracks": list(tracks.values())}


def _group(name: str, T: np.ndarray, children: list[dict]) -> dict:
    return {
        "uuid": str(uuid.uuid1()),
        "type": "Group",
        "name": name,
        "matrix": _column_major(T),
        "children": children,
    }


def _corners(geom) -> np.ndarray | None:
    """(8, 3) corners of the local axis-aligned box of a coal geometry [m], or None."""
    try:
        geom.computeLocalAABB()
        box = geom.aabb_local
        lo, hi = np.asarray(box.min_, dtype=float), np.asarray(box.max_, dtype=float)
    except (AttributeError, RuntimeError):
        return None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])

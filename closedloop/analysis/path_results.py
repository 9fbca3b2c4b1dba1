"""The result of a path under a load (:func:`closedloop.analysis.paths.follow_path`): its
per-point arrays, a summary, and its files (CSV, NPZ, figures)."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.analysis.stiffest import StiffestChoice
from closedloop.common.arrays import ReadOnlyArrays
from closedloop.common.files import output_folder, write_atomically
from closedloop.model.gravity import GravityLoad

#: Labels of a pose error's components (translation [m], rotation vector [rad]).
POSE_LABELS = ("dx", "dy", "dz", "rx", "ry", "rz")
#: Labels of an XYZQUAT pose and of a wrench.
XYZQUAT_LABELS = ("x", "y", "z", "qx", "qy", "qz", "qw")
WRENCH_LABELS = ("fx", "fy", "fz", "nx", "ny", "nz")
#: Units of the arrays of a :class:`PathResult`.
UNITS = {
    "targets": "m, 1 (x y z qx qy qz qw)",
    "poses": "m, 1 (x y z qx qy qz qw)",
    "wrenches": "N, N m",
    "q_target": "rad, m",
    "q_loaded": "rad, m",
    "q_compensated": "rad, m",
    "error": "m, rad",
    "residual": "m, rad",
    "deflection_first_order": "m, rad",
    "residual_first_order": "m, rad",
    "commands": "rad, m (per joint)",
    "commands_first_order": "rad, m (per joint)",
    "free": "rad",
    "deflection": "m",
    "default_deflection": "m",
}
#: What the rotation of a summary or a figure measures, by the compensated task.
ROTATION_MEASURES = {
    "pose": "rotation",
    "tool-axis": "tilt of the tool axis",
    "position": "rotation (not compensated)",
}
#: The per-point arrays, in the order of the NPZ file.
ARRAYS = (
    "targets", "wrenches", "poses", "q_target", "q_loaded", "error", "commands",
    "q_compensated", "residual", "commands_first_order", "deflection_first_order",
    "residual_first_order",
)  # fmt: skip


@dataclass(frozen=True)
class PathResult(ReadOnlyArrays):
    """A path followed under a load (arrays read-only, one row a point; SI; poses and errors
    of the frame's origin in world axes).

    The errors are measured from the *programmed pose* of each point, the frame's pose at
    ``q_target``: the target itself for a ``"pose"`` task; for ``"tool-axis"`` and
    ``"position"`` the target with the free rotation the inverse kinematics (or the
    stiffest-posture search) chose.

    Attributes:
        frame: the loaded frame.
        task: the task of the inverse kinematics (``"pose"``, ``"tool-axis"``,
            ``"position"``).
        held: the task the compensation meets (``"pose"`` when the model has six actuated
            joints or more, else ``task``:
            :func:`closedloop.analysis.path_points.compensated_rows`).
        joints: names of the actuated joints, the columns of the commands.
        joint_units: their units, ``"rad"`` or ``"m"``.
        targets: (n, 7) the path's targets, XYZQUAT (quaternions normalised, qw >= 0).
        wrenches: (n, 6) the process wrench at each point [N, N m], world axes, at the
            frame origin (dead load).
        gravity: the weight of links and payloads acting with the wrench, or None.
        poses: (n, 7) the programmed poses, XYZQUAT.
        q_target: (n, nq) the unloaded configurations meeting the targets (the inverse
            kinematics, continued point to point).
        q_loaded: (n, nq) the equilibria under the load with the actuators at the values
            of ``q_target`` (without compensation).
        error: (n, 6) the pose at ``q_loaded`` from the programmed pose (translation [m],
            rotation vector [rad]).
        commands: (n, n_act) the exactly compensated actuator values [rad, m].
        q_compensated: (n, nq) the equilibria under the load at ``commands``.
        residual: (n, 6) the pose at ``q_compensated`` from the programmed pose: the
            compensated rows meet it to the statics' tolerance.
        commands_first_order: (n, n_act) the first-order compensation: the inverse
            kinematics of the programmed pose moved against ``deflection_first_order``.
        deflection_first_order: (n, 6) the deflection of the linear model at ``q_target``
            (C w for a wrench alone) [m, rad].
        residual_first_order: (n, 6) the pose at the equilibrium under the load at
            ``commands_first_order`` from the programmed pose.
        stiffest: the free coordinates chosen and the gain
            (:class:`~closedloop.analysis.stiffest.StiffestChoice`), or None.
        length: the model's characteristic length L [m].
    """

    frame: str
    task: str
    held: str
    joints: tuple[str, ...]
    joint_units: tuple[str, ...]
    targets: np.ndarray
    wrenches: np.ndarray
    gravity: GravityLoad | None = field(repr=False)
    poses: np.ndarray = field(repr=False)
    q_target: np.ndarray = field(repr=False)
    q_loaded: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    commands: np.ndarray = field(repr=False)
    q_compensated: np.ndarray = field(repr=False)
    residual: np.ndarray = field(repr=False)
    commands_first_order: np.ndarray = field(repr=False)
    deflection_first_order: np.ndarray = field(repr=False)
    residual_first_order: np.ndarray = field(repr=False)
    stiffest: StiffestChoice | None = field(repr=False)
    length: float = field(repr=False)

    @property
    def n(self) -> int:
        """Number of points."""
        return len(self.targets)

    def summary(self) -> dict:
        """JSON-ready summary: the largest translation [m] and rotation [rad] (the part the
        compensation holds, ``rotation``: :meth:`held_rotation`) of the error, the
        first-order and the exact residuals, the point where each is reached, and the
        stiffest posture's gain (median and range)."""

        def largest(a: np.ndarray) -> dict:
            if not len(a):
                return {"translation_m": None, "rotation_rad": None}
            t, r = np.linalg.norm(a[:, :3], axis=1), self.held_rotation(a[:, 3:])
            return {
                "translation_m": float(t.max()),
                "at_point": int(t.argmax()),
                "rotation_rad": float(r.max()),
                "rotation_at_point": int(r.argmax()),
            }

        out = {
            "frame": self.frame,
            "task": self.task,
            "compensated": self.held,
            "points": self.n,
            "joints": dict(zip(self.joints, self.joint_units, strict=True)),
            "gravity": None if self.gravity is None else self.gravity.to_dict(),
            "rotation": self.rotation_measure,
            "error": largest(self.error),
            "residual_first_order": largest(self.residual_first_order),
            "residual": largest(self.residual),
        }
        if self.stiffest is not None and self.n:
            gain = self.stiffest.gain
            out["stiffest"] = {
                "max_change_rad": self.stiffest.max_change,
                "gain_median": float(np.median(gain)),
                "gain_min": float(gain.min()),
                "gain_max": float(gain.max()),
            }
        return out

    @property
    def rotation_measure(self) -> str:
        """What :meth:`held_rotation` measures (:data:`ROTATION_MEASURES`)."""
        return ROTATION_MEASURES[self.held]

    def held_rotation(self, rotation: np.ndarray) -> np.ndarray:
        """(n,) the part of rotation vectors (n, 3) [rad] (errors from the programmed
        poses) that the compensation holds (:data:`ROTATION_MEASURES`): their norm, or for
        a ``tool-axis`` compensation the norm of their part across the programmed tool axis
        (the tilt of the axis; the turn about it is free)."""
        if self.held != "tool-axis":
            return np.linalg.norm(rotation, axis=1)
        z = np.array([pin.XYZQUATToSE3(p).rotation[:, 2] for p in self.poses]).reshape(-1, 3)
        return np.linalg.norm(rotation - np.sum(rotation * z, axis=1)[:, None] * z, axis=1)

    def arrays(self) -> dict[str, np.ndarray]:
        """Name -> array: :data:`ARRAYS`, and with a stiffest posture ``free``,
        ``deflection``, ``default_deflection``."""
        out = {name: getattr(self, name) for name in ARRAYS}
        if self.stiffest is not None:
            s = self.stiffest
            out.update(
                free=s.free, deflection=s.deflection, default_deflection=s.default_deflection
            )
        return out

    def save(self, out: str | Path) -> list[Path]:
        """Write ``path.npz`` (every array of :meth:`arrays`, ``joints``, ``units``: a JSON
        object, array -> unit, and ``summary``: :meth:`summary` as JSON), ``path.csv``
        (one row a point: index, target, wrench, error, first-order and exact residuals,
        commands; with a stiffest posture its free coordinates and deflections),
        ``path_error.png`` and ``path_3d.png``
        (:mod:`closedloop.analysis.path_figures`); returns the paths.

        Raises:
            InvalidInputError: ``out`` is not a folder that can be written.
        """
        from closedloop.analysis.path_figures import plot_errors, plot_path

        out = output_folder(out)
        arrays = self.arrays()
        meta = {
            "joints": np.asarray(self.joints),
            "units": np.array(json.dumps({k: UNITS[k] for k in arrays})),
            "summary": np.array(json.dumps(self.summary())),
        }
        paths = [write_atomically(out / "path.npz", lambda f: np.savez(f, **arrays, **meta))]
        names, columns = self._columns()

        def write(f) -> None:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow(names)
            for i, row in enumerate(np.column_stack(columns).tolist()):
                writer.writerow([i, *map(repr, row)])

        paths.append(write_atomically(out / "path.csv", write, text=True, newline=""))
        paths += [out / "path_error.png", out / "path_3d.png"]
        plot_errors(self, paths[-2])
        plot_path(self, paths[-1])
        return paths

    def _columns(self) -> tuple[list[str], list[np.ndarray]]:
        """The CSV's column names (with units) and (n, k) blocks."""
        units = ["m"] * 3 + ["rad"] * 3
        pose = [f"{c}_{u}" for c, u in zip(POSE_LABELS, units, strict=True)]
        act = [f"{n}_{u}" for n, u in zip(self.joints, self.joint_units, strict=True)]
        names = ["point", *(f"target_{c}" for c in XYZQUAT_LABELS),
                 *(f"{c}_{'N' if c[0] == 'f' else 'Nm'}" for c in WRENCH_LABELS),
                 *(f"error_{c}" for c in pose), *(f"residual_first_order_{c}" for c in pose),
                 *(f"residual_{c}" for c in pose), *(f"command_{c}" for c in act),
                 *(f"command_first_order_{c}" for c in act)]  # fmt: skip
        columns = [self.targets, self.wrenches, self.error, self.residual_first_order,
                   self.residual, self.commands, self.commands_first_order]  # fmt: skip
        if self.stiffest is not None:
            s = self.stiffest
            names += [f"free_{k}_rad" for k in range(s.free.shape[1])]
            names += ["deflection_m", "default_deflection_m"]
            columns += [s.free, s.deflection[:, None], s.default_deflection[:, None]]
        return names, [c.reshape(self.n, -1) for c in columns]

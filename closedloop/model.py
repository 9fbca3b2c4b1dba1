"""A Pinocchio model with loop closures, actuated joints and a spring specification.

The kinematic tree is an ordinary :class:`pinocchio.Model`; every loop is closed by a
Pinocchio 4 anchor constraint (:class:`pinocchio.PointAnchorConstraintModel` for a 3D
point, :class:`pinocchio.FrameAnchorConstraintModel` for a 6D weld). Elasticity is
lumped into the joint coordinates: each velocity coordinate carries a stiffness that is

* ``0``      - passive (no spring, the default for every coordinate);
* ``k > 0``  - a linear spring [N m/rad for a revolute, N/m for a prismatic coordinate];
  "virtual" joints standing for link compliance are ordinary joints with a spring;
* ``inf``    - locked (rigid).

Actuated joints are the inputs of :func:`closedloop.assembly.assemble`. An actuated joint
without a spring is a rigid actuator (locked).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .arrays import frozen
from .conditioning import characteristic_length
from .exceptions import InvalidInputError, NameNotFoundError

AnchorConstraint = pin.PointAnchorConstraintModel | pin.FrameAnchorConstraintModel

#: Closure types of the closure-file convention and their Pinocchio constraint.
CLOSURE_TYPES = {"3d": pin.PointAnchorConstraintModel, "6d": pin.FrameAnchorConstraintModel}


@dataclass(frozen=True)
class Closure:
    """One loop closure: a Pinocchio anchor constraint and a display name."""

    constraint: AnchorConstraint
    name: str

    @property
    def kind(self) -> str:
        """``"3d"`` (point) or ``"6d"`` (frame weld)."""
        return "3d" if isinstance(self.constraint, pin.PointAnchorConstraintModel) else "6d"

    @property
    def size(self) -> int:
        """Number of residual rows (3 or 6)."""
        return self.constraint.residualSize()


def frame_id(model: pin.Model, name: str) -> int:
    """Index of frame ``name``; raises :class:`NameNotFoundError` listing the frames."""
    if not model.existFrame(name):
        raise NameNotFoundError("frame", name, [f.name for f in model.frames])
    return model.getFrameId(name)


def joint_id(model: pin.Model, name: str) -> int:
    """Index of joint ``name``; raises :class:`NameNotFoundError` listing the joints."""
    if not model.existJointName(name):
        raise NameNotFoundError("joint", name, list(model.names)[1:])
    return model.getJointId(name)


def closure_between_frames(model: pin.Model, frame_a: str, frame_b: str, kind: str) -> Closure:
    """Closure that makes frames ``frame_a`` and ``frame_b`` coincide.

    Args:
        model: the kinematic tree.
        frame_a, frame_b: frame names; for ``"3d"`` their origins coincide, for ``"6d"``
            their whole placements do.
        kind: ``"3d"`` or ``"6d"``.
    """
    if kind not in CLOSURE_TYPES:
        raise InvalidInputError(f"closure type {kind!r}; expected one of {sorted(CLOSURE_TYPES)}")
    fa, fb = model.frames[frame_id(model, frame_a)], model.frames[frame_id(model, frame_b)]
    constraint = CLOSURE_TYPES[kind](
        model, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    return Closure(constraint, f"{frame_a}<->{frame_b}")


def _linear_coordinates(model: pin.Model) -> np.ndarray:
    """(nv,) read-only mask of the translational velocity coordinates (prismatic, the
    linear part of a free flyer...), read off the joint motion subspaces: a coordinate is
    linear when it moves its joint without rotating it."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    mask = np.zeros(model.nv, dtype=bool)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nv:
            S = np.asarray(data.joints[j].S).reshape(6, jm.nv)
            mask[jm.idx_v : jm.idx_v + jm.nv] = ~np.any(S[3:] != 0.0, axis=0)
    return frozen(mask)


class ClosedLoopModel:
    """Kinematic tree + loop closures + actuated joints + per-coordinate stiffness.

    Args:
        model: Pinocchio model of the kinematic tree (frames included).
        closures: loop closures (:class:`Closure` or bare anchor constraints).
        actuated: names of the actuated joints (one coordinate each).
        springs: joint name -> stiffness, a number or one value per velocity coordinate of
            the joint [N m/rad or N/m]; ``0`` makes it passive, ``inf`` locks it.
        locked: names of joints held rigid.
        visual_model, collision_model: optional geometry for viewers.
        name: display name.

    Attributes:
        stiffness: (nv,) read-only stiffness of every velocity coordinate (0, >0 or inf).
        linear_coordinates: (nv,) read-only bool, True for translational coordinates [m]
            (prismatic, linear part of a free flyer), False for rotations [rad].
        linear_rows: (m,) read-only bool, True for the closure rows in metres (point
            closures, translation of welds), False for the rotation rows of welds [rad].
    """

    def __init__(
        self,
        model: pin.Model,
        closures: Iterable[Closure | AnchorConstraint] = (),
        actuated: Sequence[str] = (),
        springs: Mapping[str, float | Sequence[float]] | None = None,
        locked: Iterable[str] = (),
        visual_model: pin.GeometryModel | None = None,
        collision_model: pin.GeometryModel | None = None,
        name: str = "",
    ):
        self.model = model
        self._local = threading.local()
        self._pool: list[tuple[pin.Data, list]] = []
        self._memo: dict = {}
        self._length: float | None = None
        self.closures = tuple(
            c if isinstance(c, Closure) else Closure(c, f"closure{i}")
            for i, c in enumerate(closures)
        )
        self.visual_model = visual_model
        self.collision_model = collision_model
        self.name = name or model.name
        self.actuated = tuple(actuated)
        self.actuated_ids = tuple(joint_id(model, n) for n in self.actuated)
        for n, j in zip(self.actuated, self.actuated_ids, strict=True):
            if model.joints[j].nv != 1 or model.joints[j].nq != 1:
                raise InvalidInputError(
                    f"actuated joint {n!r} must have one coordinate (revolute or prismatic), "
                    f"it has nq={model.joints[j].nq}, nv={model.joints[j].nv}"
                )
        self.stiffness = self._stiffness_vector(springs or {}, locked)
        self.linear_coordinates = _linear_coordinates(model)
        rows = [i < 3 for c in self.closures for i in range(c.size)]
        self.linear_rows = frozen(np.array(rows, dtype=bool))

    # ------------------------------------------------------------------ workspaces
    @property
    def data(self) -> pin.Data:
        """This thread's Pinocchio Data of the model (one per thread, never shared).

        Functions that take ``(model, q)`` compute their kinematics here; a
        :class:`closedloop.configuration.Configuration` owns a Data of its own.
        """
        local = self._local
        if not hasattr(local, "data"):
            local.data = self.model.createData()
            local.constraint_datas = [c.constraint.createData() for c in self.closures]
        return local.data

    @property
    def constraint_datas(self) -> list:
        """This thread's constraint datas of the closures (see :attr:`data`)."""
        self.data  # noqa: B018  (creates this thread's workspace)
        return self._local.constraint_datas

    def acquire_workspace(self) -> tuple[pin.Data, list]:
        """A (Data, constraint datas) pair for the exclusive use of one owner.

        Taken from a pool of released workspaces (creating a Data costs more than a whole
        stiffness query); give it back with :meth:`release_workspace` when the owner is
        gone. ``list.pop`` and ``list.append`` are atomic, so owners in different threads
        never get the same pair.
        """
        try:
            return self._pool.pop()
        except IndexError:
            return self.model.createData(), [c.constraint.createData() for c in self.closures]

    def release_workspace(self, workspace: tuple[pin.Data, list]) -> None:
        """Return a workspace of :meth:`acquire_workspace` to the pool (at most 16 kept)."""
        if len(self._pool) < 16:
            self._pool.append(workspace)

    def memo(self, key, factory):
        """``factory()``, computed once per ``key`` for this model (immutable results only)."""
        try:
            return self._memo[key]
        except KeyError:
            return self._memo.setdefault(key, factory())

    @property
    def length(self) -> float:
        """Characteristic length L [m]: diagonal of the bounding box of the joint origins at
        the neutral configuration (1 m if they coincide), computed once; the default scale
        of the unit-free rules (:mod:`closedloop.conditioning`)."""
        if self._length is None:
            data = self.model.createData()
            pin.forwardKinematics(self.model, data, pin.neutral(self.model))
            self._length = characteristic_length([M.translation for M in data.oMi])
        return self._length

    def _stiffness_vector(self, springs, locked) -> np.ndarray:
        k = np.zeros(self.model.nv)
        for j in self.actuated_ids:
            k[self.model.joints[j].idx_v] = np.inf
        for name in locked:
            jm = self.model.joints[joint_id(self.model, name)]
            k[jm.idx_v : jm.idx_v + jm.nv] = np.inf
        for name, value in springs.items():
            jm = self.model.joints[joint_id(self.model, name)]
            values = (
                np.broadcast_to(np.asarray(value, float), (jm.nv,))
                if np.ndim(value) == 0
                else np.asarray(value, float)
            )
            if values.shape != (jm.nv,):
                raise InvalidInputError(
                    f"stiffness of joint {name!r} has {values.size} values; expected 1 or {jm.nv}"
                )
            if np.any(np.isnan(values)) or np.any(values < 0):
                raise InvalidInputError(
                    f"stiffness of joint {name!r} is {values.tolist()}; expected values >= 0 "
                    "(0 = passive, inf = locked)"
                )
            k[jm.idx_v : jm.idx_v + jm.nv] = values
        k.flags.writeable = False
        return k

    # ------------------------------------------------------------------ naming helpers
    def frame_id(self, name: str) -> int:
        """Index of frame ``name`` (raises :class:`NameNotFoundError`)."""
        return frame_id(self.model, name)

    def joint_id(self, name: str) -> int:
        """Index of joint ``name`` (raises :class:`NameNotFoundError`)."""
        return joint_id(self.model, name)

    def joint_v_slice(self, name: str) -> slice:
        """Slice of joint ``name`` in the velocity (tangent) vector."""
        jm = self.model.joints[self.joint_id(name)]
        return slice(jm.idx_v, jm.idx_v + jm.nv)

    @property
    def actuated_q_indices(self) -> np.ndarray:
        """(n_act,) indices of the actuated coordinates in q."""
        return np.array([self.model.joints[j].idx_q for j in self.actuated_ids], dtype=int)

    @property
    def actuated_v_indices(self) -> np.ndarray:
        """(n_act,) indices of the actuated coordinates in the tangent vector."""
        return np.array([self.model.joints[j].idx_v for j in self.actuated_ids], dtype=int)

    @property
    def n_constraints(self) -> int:
        """Total number of closure residual rows (redundant ones included)."""
        return sum(c.size for c in self.closures)

    def with_springs(
        self, springs: Mapping[str, float | Sequence[float]], locked: Iterable[str] = ()
    ) -> ClosedLoopModel:
        """Same model and closures with another spring specification."""
        return ClosedLoopModel(
            self.model,
            self.closures,
            self.actuated,
            springs,
            locked,
            self.visual_model,
            self.collision_model,
            self.name,
        )

    def check_configuration(self, q: np.ndarray) -> np.ndarray:
        """Validated copy of a configuration vector q (nq,)."""
        q = np.array(q, dtype=float).reshape(-1)
        if q.shape != (self.model.nq,):
            raise InvalidInputError(f"q has {q.size} values; expected nq={self.model.nq}")
        if not np.all(np.isfinite(q)):
            raise InvalidInputError(f"q contains non-finite values: {q.tolist()}")
        return q

    def __repr__(self) -> str:
        return (
            f"ClosedLoopModel({self.name!r}, nq={self.model.nq}, nv={self.model.nv}, "
            f"closures={len(self.closures)}, actuated={list(self.actuated)})"
        )

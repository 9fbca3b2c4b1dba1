"""A Pinocchio model with loop closures, actuated joints and a spring specification.

The kinematic tree is an ordinary :class:`pinocchio.Model`; every loop is closed by a
typed closure between two frames (:mod:`closedloop.model.closures`: a point, a weld, a
revolute, prismatic, cylindrical or universal joint cut open). Elasticity is
lumped into the joint coordinates: each velocity coordinate carries a stiffness that is

* ``0``      - passive (no spring, the default for every coordinate);
* ``k > 0``  - a linear spring [N m/rad for a revolute, N/m for a prismatic coordinate];
  "virtual" joints standing for link compliance are ordinary joints with a spring;
* ``inf``    - locked (rigid).

A spring may also couple the coordinates of one multi-dof joint: its stiffness is then a
symmetric positive definite (nv_j, nv_j) matrix (a *block*, e.g. the 6x6 tip stiffness of
a flexible link on a 6-dof virtual joint, :mod:`closedloop.model.beams`), its energy
1/2 dq_j^T K_j dq_j. The per-coordinate vector :attr:`ClosedLoopModel.stiffness` then
holds the block's diagonal (finite and > 0, so the 0/inf rules are unchanged) and
:attr:`ClosedLoopModel.spring_blocks` the blocks; :attr:`ClosedLoopModel.spring_matrix`
is the whole joint stiffness K_q (nv, nv), block diagonal.

Actuated joints are the inputs of :func:`closedloop.kinematics.assembly.assemble`. An actuated joint
without a spring is a rigid actuator (locked).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping, Sequence
from types import MappingProxyType

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import frozen
from closedloop.exceptions import InvalidInputError
from closedloop.model.closures import (
    AnchorConstraint,
    Closure,
    checked_closures,
    frame_id,
    joint_id,
    joint_names,
)
from closedloop.model.coordinates import checked_configuration, neutral_facts
from closedloop.model.reference import reference_of
from closedloop.model.spring_spec import (
    joint_stiffness,
    spring_matrix,
    spring_root,
    spring_spectra,
)

#: Workspaces (Data) kept per model for reuse: one per thread that queries at once.
POOL_SIZE = 4
#: Entries of :meth:`ClosedLoopModel.memo` past which those whose key carries a
#: parameter are dropped (a few tens of kB each on CaHyMan: the scaling at a length L).
MEMO_SIZE = 64


class ClosedLoopModel:
    """Kinematic tree + loop closures + actuated joints + per-coordinate stiffness.

    Args:
        model: Pinocchio model of the kinematic tree (frames included).
        closures: loop closures (:class:`Closure` or bare anchor constraints).
        actuated: names of the actuated joints (one coordinate each).
        springs: joint name -> stiffness, a number, one value per velocity coordinate of
            the joint [N m/rad or N/m] (``0`` makes it passive, ``inf`` locks it), or a
            symmetric positive definite (nv_j, nv_j) matrix coupling the joint's
            coordinates (units of coordinate i times coordinate j: N/m, N, N m/rad).
        locked: names of joints held rigid.
        visual_model, collision_model: optional geometry for viewers.
        name: display name.
        beam_masses: virtual beam joint name -> :class:`closedloop.model.beam_theory.BeamMass`, the
            sections (and densities) of the beams for their own mass
            (:mod:`closedloop.analysis.vibration`); filled by the loaders.
        unweighed_bodies: body (link) name -> why the model's inertia of that body is not
            the robot file's (an MJCF mesh geom, to which Pinocchio's parser gives 1 kg and
            1 kg m^2, or a geom outside the compiler's ``inertiagrouprange``); filled by the
            loaders. Stiffness queries do not need the inertias; gravity and natural
            frequencies refuse such a model (:meth:`require_inertias`). Read-only.

    Attributes:
        stiffness: (nv,) read-only stiffness of every velocity coordinate (0, >0 or inf);
            the diagonal of a block.
        spring_blocks: read-only mapping joint name -> (nv_j, nv_j) read-only SPD block
            (empty when every spring is per coordinate).
        linear_coordinates: (nv,) read-only bool, True for translational coordinates [m]
            (prismatic, linear part of a free flyer), False for rotations [rad].
        linear_rows: (m,) read-only bool, True for the closure rows in metres, False for
            the dimensionless [rad] ones (:data:`closedloop.model.closures.LINEAR_ROWS`).
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
        *,
        beam_masses: Mapping | None = None,
        unweighed_bodies: Mapping[str, str] | None = None,
        _neutral: tuple[np.ndarray, float] | None = None,  # with_springs: the same model
    ):
        if not isinstance(model, pin.Model):
            raise InvalidInputError(
                f"ClosedLoopModel: model must be a pinocchio.Model, got {type(model).__name__}"
            )
        self.model = model
        self._nq, self._unit_coordinates = model.nq, model.nq != model.nv
        self._local = threading.local()
        self._pool: list[tuple[pin.Data, list]] = []
        self._memo: dict = {}
        self._frame_ids: dict[str, int] = {}
        self.closures = checked_closures(model, closures)
        self.visual_model = visual_model
        self.collision_model = collision_model
        self.name = name or model.name
        self.beam_masses = MappingProxyType(dict(beam_masses or {}))
        self.unweighed_bodies: Mapping[str, str] = MappingProxyType(dict(unweighed_bodies or {}))
        self.actuated = joint_names("actuated", actuated)
        self.actuated_ids = tuple(joint_id(model, n) for n in self.actuated)
        for n, j in zip(self.actuated, self.actuated_ids, strict=True):
            if model.joints[j].nv != 1 or model.joints[j].nq not in (1, 2):
                raise InvalidInputError(
                    f"actuated joint {n!r} must have one coordinate (revolute, continuous or "
                    f"prismatic), it has nq={model.joints[j].nq}, nv={model.joints[j].nv}"
                )
        locked = joint_names("locked", locked)
        self._spec = (dict(springs or {}), locked)
        self.stiffness, blocks = joint_stiffness(model, springs or {}, locked, self.actuated_ids)
        self.spring_blocks: Mapping[str, np.ndarray] = MappingProxyType(blocks)
        self.linear_coordinates, self._length = _neutral or neutral_facts(model)
        rows = [r for c in self.closures for r in c.linear_rows]
        self.linear_rows = frozen(np.array(rows, dtype=bool))

    # ------------------------------------------------------------------ workspaces
    @property
    def data(self) -> pin.Data:
        """This thread's Pinocchio Data of the model (one per thread, never shared).

        Functions that take ``(model, q)`` compute their kinematics here; a
        :class:`closedloop.kinematics.configuration.Configuration` owns a Data of its own.
        """
        return self.workspace()[0]

    @property
    def constraint_datas(self) -> list:
        """This thread's constraint datas of the closures (see :attr:`data`)."""
        return self.workspace()[1]

    def workspace(self) -> tuple[pin.Data, list]:
        """This thread's (:attr:`data`, :attr:`constraint_datas`), created on first use."""
        try:
            return self._local.workspace
        except AttributeError:
            pair = self.model.createData(), [c.constraint.createData() for c in self.closures]
            self._local.workspace = pair
            return pair

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
        """Return a workspace of :meth:`acquire_workspace` to the pool (at most
        :data:`POOL_SIZE` kept: a Data grows like nv^2 and more)."""
        if len(self._pool) < POOL_SIZE:
            self._pool.append(workspace)

    def memo(self, key, factory, *args):
        """``factory(*args)``, computed once per ``key`` for this model (immutable results
        only).

        A key with a parameter is a tuple (e.g. ``("scaling", L)``): past
        :data:`MEMO_SIZE` entries those are dropped, so that a sweep of the parameter does
        not keep one entry a value.
        """
        try:
            return self._memo[key]
        except KeyError:
            pass
        value = factory(*args)  # outside the handler: its errors without the KeyError
        if isinstance(key, tuple) and len(self._memo) >= MEMO_SIZE:
            # a new dict, swapped in at once: a thread that reads the old one meanwhile
            # only computes its entry again
            self._memo = {k: v for k, v in list(self._memo.items()) if not isinstance(k, tuple)}
        return self._memo.setdefault(key, value)

    @property
    def length(self) -> float:
        """Characteristic length L [m]: the largest distance between two of the joint
        origins and frames (not the world origin) at the neutral configuration (1 m if they
        coincide), whatever the mechanism's place in the world; the default scale of the
        unit-free rules (:mod:`closedloop.common.conditioning`)."""
        return self._length

    def require_inertias(self, use: str) -> None:
        """Refuse ``use`` (a computation that needs the links' inertias, e.g. "the
        natural frequencies") on a model with ``unweighed_bodies``.

        Raises:
            InvalidInputError: the message names the bodies, why their inertia is wrong and
                the fix (an ``<inertial>`` in each body).
        """
        if len(self.unweighed_bodies) == 1:
            ((body, why),) = self.unweighed_bodies.items()
            raise InvalidInputError(
                f"{use} cannot be computed: Pinocchio's inertia of body {body!r} is not the "
                f"robot file's ({why}); give the body an <inertial> (mass, diaginertia)"
            )
        if self.unweighed_bodies:
            bodies = ", ".join(f"{b!r} ({why})" for b, why in self.unweighed_bodies.items())
            raise InvalidInputError(
                f"{use} cannot be computed: Pinocchio's inertias of bodies {bodies} are not "
                "the robot file's; give each of these bodies an <inertial> (mass, diaginertia)"
            )

    # ------------------------------------------------------------------ joint stiffness
    @property
    def springs(self) -> dict:
        """The spring specification given (joint name -> number, list or block), a copy."""
        return dict(self._spec[0])

    @property
    def locked(self) -> tuple[str, ...]:
        """Names of the joints given as locked."""
        return self._spec[1]

    @property
    def spring_matrix(self) -> np.ndarray:
        """(nv, nv) read-only joint stiffness K_q of the finite springs: the blocks and
        diag(k) elsewhere, 0 on passive and locked coordinates [N m/rad, N/m, N]."""
        return self.memo(
            "spring_matrix", spring_matrix, self.stiffness, self.spring_blocks, self.joint_v_slice
        )

    @property
    def spring_root(self) -> np.ndarray:
        """(nv, nv) read-only square root R of :attr:`spring_matrix`, K_q = R^T R: sqrt(k)
        on the diagonal, the transposed Cholesky factor (upper triangular) of each block
        [sqrt(N m), per the joint units]."""
        return self.memo(
            "spring_root", spring_root, self.stiffness, self.spring_blocks, self.joint_v_slice
        )

    def spring_forces(self, dq: np.ndarray) -> np.ndarray:
        """(nv,) generalised spring forces K_q dq [N m, N] of a deflection dq (nv,)
        (tangent of q [rad, m]); 0 on passive and locked coordinates.

        A block's forces are taken in its eigenbasis, K_j dq_j = V (lambda * (V^T dq_j)):
        their rounding is then that of the forces of a deflection within eps norm(dq_j)
        of dq_j, along each direction in proportion to its stiffness. The product
        K_j dq_j would leave eps norm(K_j) norm(dq_j) on every direction: on a soft
        direction of a stiff coupled block (a bushing of 1e9 beside 20 N m/rad)
        cond(K_j) eps of its force, a rounding that the nonlinear statics' balance test
        cannot get below.
        """
        k = self.stiffness
        f = np.where(np.isinf(k), 0.0, k) * dq
        spectra = self.memo(
            "spring_spectra", spring_spectra, self.spring_blocks, self.joint_v_slice
        )
        for v, lam, V in spectra:
            f[v] = V @ (lam * (V.T @ dq[v]))
        return f

    # ------------------------------------------------------------------ naming helpers
    def frame_id(self, name: str) -> int:
        """Index of frame ``name`` (raises :class:`NameNotFoundError`); remembered."""
        try:
            return self._frame_ids[name]
        except (KeyError, TypeError):  # TypeError: an unhashable name, refused below
            fid = frame_id(self.model, name)
            self._frame_ids[name] = fid
            return fid

    def joint_id(self, name: str) -> int:
        """Index of joint ``name`` (raises :class:`NameNotFoundError`)."""
        return joint_id(self.model, name)

    def coordinate_joint(self, i: int) -> str:
        """Name of the joint whose velocity coordinates include i (0 <= i < nv)."""
        model = self.model
        return next(
            model.names[j] for j in range(1, model.njoints)
            if model.joints[j].idx_v <= i < model.joints[j].idx_v + model.joints[j].nv
        )  # fmt: skip

    def joint_v_slice(self, name: str) -> slice:
        """Slice of joint ``name`` in the velocity (tangent) vector."""
        jm = self.model.joints[self.joint_id(name)]
        return slice(jm.idx_v, jm.idx_v + jm.nv)

    @property
    def actuated_q_indices(self) -> np.ndarray:
        """(n_act,) read-only indices of the actuated coordinates in q."""
        return self.memo("actuated_q", lambda: self._joint_indices("idx_q"))

    @property
    def actuated_v_indices(self) -> np.ndarray:
        """(n_act,) read-only indices of the actuated coordinates in the tangent vector."""
        return self.memo("actuated_v", lambda: self._joint_indices("idx_v"))

    def set_actuated(self, q: np.ndarray, values: np.ndarray) -> None:
        """Write the actuated joints' values (n_act,) [rad or m] into q (nq,) in place: the
        coordinate, or (cos, sin) for a continuous (unbounded revolute) joint."""
        idx = self.actuated_q_indices
        if not self.memo("any_unbounded_actuated", lambda: bool(self._unbounded_actuated().any())):
            q[idx] = values
            return
        unbounded = self._unbounded_actuated()
        values = np.asarray(values, dtype=float)
        q[idx[~unbounded]] = values[~unbounded]
        q[idx[unbounded]], q[idx[unbounded] + 1] = (
            np.cos(values[unbounded]),
            np.sin(values[unbounded]),
        )

    def actuated_values(self, q: np.ndarray) -> np.ndarray:
        """(n_act,) the actuated joints' values [rad or m] in q (nq,) (the angle of a
        continuous joint from its (cos, sin))."""
        unbounded, idx = self._unbounded_actuated(), self.actuated_q_indices
        values = np.array(q[idx], dtype=float)
        values[unbounded] = np.arctan2(q[idx[unbounded] + 1], q[idx[unbounded]])
        return values

    def _unbounded_actuated(self) -> np.ndarray:
        """(n_act,) bool: the actuated joint is continuous (nq = 2: cos, sin)."""
        joints = self.model.joints
        return self.memo(
            "unbounded_actuated",
            lambda: frozen(np.array([joints[j].nq == 2 for j in self.actuated_ids], dtype=bool)),
        )

    def _joint_indices(self, kind: str) -> np.ndarray:
        joints = self.model.joints
        return frozen(np.array([getattr(joints[j], kind) for j in self.actuated_ids], dtype=int))

    @property
    def n_constraints(self) -> int:
        """Total number of closure residual rows (redundant ones included)."""
        return self.linear_rows.size

    def with_springs(
        self, springs: Mapping[str, float | Sequence[float]], locked: Iterable[str] = ()
    ) -> ClosedLoopModel:
        """Same model and closures with another spring specification (blocks included)."""
        return ClosedLoopModel(
            self.model,
            self.closures,
            self.actuated,
            springs,
            locked,
            self.visual_model,
            self.collision_model,
            self.name,
            beam_masses=self.beam_masses,
            unweighed_bodies=self.unweighed_bodies,
            _neutral=(self.linear_coordinates, self._length),
        )

    def with_beams(self, beams: Mapping[str, Mapping]) -> ClosedLoopModel:
        """This model with flexible links: each beam (link name -> specification: end, E,
        G, section, theory, or stiffness_6x6; or a list of them with ``start``, several
        beams ``<link>_beam_<end>`` on the link) becomes a 6-dof virtual joint
        ``<link>_beam`` with its tip stiffness as a block spring
        (:func:`closedloop.model.beams.apply_beams`). The new model has more coordinates: map a
        configuration with :func:`closedloop.model.beams.map_configuration`.

        Actuated joints, springs and locked joints keep their names; closure anchors are
        carried over on their joints, those at a beam's tip with the tip (a loop of an MJCF
        or SDF file closed at the end of a link that becomes a beam); an anchor elsewhere on
        the beam's link stays with the beam's start. A beam's ``end: anchor:<closure
        name>`` ends it at that closure's anchor on the link.

        Raises:
            BeamError: a bad specification (the message names the beam and the value).
        """
        from closedloop.model.beams import apply_beams  # beam theory: on demand

        geoms = [self.visual_model, self.collision_model]
        ends = [(k.joint1_id, k.joint1_placement) for c in self.closures for k in [c.constraint]]
        ends += [(k.joint2_id, k.joint2_placement) for c in self.closures for k in [c.constraint]]
        names = [c.name for c in self.closures] * 2
        model, geoms, springs, ends, masses = apply_beams(
            self.model, geoms, beams, anchors=ends, anchor_names=names
        )
        n = len(self.closures)
        closures = [c.on(model, ends[i], ends[n + i]) for i, c in enumerate(self.closures)]
        return self._grown(model, closures, springs, geoms, masses)

    def with_closure_springs(self, springs: Mapping) -> ClosedLoopModel:
        """This model with the closures of ``springs`` (closure index -> 6 values or a 6x6
        [N/m, N m/rad]) made elastic by joints at each cut, reference configurations
        extended (:func:`closedloop.model.elastic_closures.with_elastic_closures`).

        Raises:
            InvalidInputError: a bad spring, or a closure that is elastic already (two
                springs in parallel on one pair are two closures of it, each given one).
        """
        from closedloop.model.elastic_closures import with_elastic_closures  # on demand

        model, closures, cut = with_elastic_closures(self.model, list(self.closures), springs)
        geoms = [self.visual_model, self.collision_model]
        return self._grown(model, closures, cut, geoms, {})

    def _grown(self, model, closures, springs, geoms, masses) -> ClosedLoopModel:
        """This model grown by joints (beams, a cut's): the added ``springs`` and beam
        ``masses`` merged over its own, ``geoms`` (visual, collision); the rest kept."""
        return ClosedLoopModel(
            model,
            closures,
            self.actuated,
            {**self.springs, **springs},
            self.locked,
            geoms[0],
            geoms[1],
            self.name,
            beam_masses={**self.beam_masses, **masses},
            unweighed_bodies=self.unweighed_bodies,
        )

    def check_configuration(self, q: np.ndarray) -> np.ndarray:
        """Validated copy of a configuration vector q (nq,)
        (:func:`closedloop.model.coordinates.checked_configuration`)."""
        return checked_configuration(self.model, q, self._nq, self._unit_coordinates)

    def reference_configuration(self) -> np.ndarray:
        """(nq,) new array: the model's reference configuration, the start of an assembly
        that is not given one (:func:`closedloop.model.reference.reference_of`)."""
        return reference_of(self.model)

    def __repr__(self) -> str:
        return (
            f"ClosedLoopModel({self.name!r}, nq={self.model.nq}, nv={self.model.nv}, "
            f"closures={len(self.closures)}, actuated={list(self.actuated)})"
        )

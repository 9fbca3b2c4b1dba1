"""The spring specification of a model as stiffnesses: one per velocity coordinate (``0``
passive, ``k > 0`` a spring, ``inf`` locked) and the symmetric positive definite blocks
that couple the coordinates of one joint (:mod:`closedloop.model.closed_loop`); the joint
stiffness matrix K_q they make, its square root and the blocks' spectra.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import frozen, real_array, symmetrized
from closedloop.exceptions import InvalidInputError
from closedloop.model.closures import joint_id


def check_locked_springs(springs: Mapping, locked: Iterable[str]) -> None:
    """InvalidInputError for joints both ``locked`` and given ``springs`` (names)."""
    both = sorted(set(locked) & set(springs))
    if both:
        raise InvalidInputError(
            f"joints {both} are both locked and given springs; expected one or the other "
            "(a lock is an infinite stiffness)"
        )


#: Relative asymmetry max|K - K^T| / max|K| above which a spring block is refused (a block
#: read from 36 printed numbers is symmetric to their ~1e-16 rounding).
BLOCK_SYMMETRY_RTOL = 1e-9


def _spd_block(name: str, K: np.ndarray, nv: int) -> np.ndarray:
    """Validated read-only (nv, nv) symmetric positive definite block of joint ``name``."""
    if K.shape != (nv, nv):
        raise InvalidInputError(
            f"stiffness block of joint {name!r} has shape {K.shape}; expected ({nv}, {nv})"
        )
    if not np.all(np.isfinite(K)):
        raise InvalidInputError(
            f"stiffness block of joint {name!r} has non-finite entries: {K.tolist()}"
        )
    K = symmetrized(
        K, BLOCK_SYMMETRY_RTOL, f"stiffness block of joint {name!r}",
        "a symmetric positive definite matrix",
    )  # fmt: skip
    try:
        np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        raise InvalidInputError(
            f"stiffness block of joint {name!r} is not positive definite (eigenvalues "
            f"{np.linalg.eigvalsh(K).tolist()}); expected a symmetric positive definite matrix"
        ) from None
    return frozen(K)


def joint_stiffness(
    model: pin.Model, springs: Mapping, locked: Iterable[str], actuated_ids: Iterable[int]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The stiffnesses of a spring specification (that of
    :class:`closedloop.model.closed_loop.ClosedLoopModel`).

    Args:
        model: the kinematic tree.
        springs: joint name -> a number, one value per velocity coordinate of the joint
            [N m/rad or N/m], or a symmetric positive definite (nv_j, nv_j) block.
        locked: names of the joints held rigid.
        actuated_ids: indices of the actuated joints (rigid unless given a spring).

    Returns:
        (k, blocks): (nv,) read-only stiffness of every velocity coordinate (0 passive,
        > 0, inf locked; a block's diagonal on its coordinates) and joint name -> its
        read-only (nv_j, nv_j) block.

    Raises:
        InvalidInputError: naming the joint and the value.
    """
    k = np.zeros(model.nv)
    for j in actuated_ids:
        k[model.joints[j].idx_v] = np.inf
    for name in locked:
        jm = model.joints[joint_id(model, name)]
        k[jm.idx_v : jm.idx_v + jm.nv] = np.inf
    if not isinstance(springs, Mapping):
        raise InvalidInputError(
            f"springs must be a mapping joint name -> stiffness, got {type(springs).__name__}"
        )
    check_locked_springs(springs, locked)
    blocks = {}
    for name, value in springs.items():
        jm = model.joints[joint_id(model, name)]
        if not jm.nv:
            raise InvalidInputError(
                f"joint {name!r} ({jm.shortname()}) has no coordinate of its own (a mimic "
                "joint follows its leader): give the spring to the joint it follows"
            )
        if isinstance(value, bool | np.bool_) or (
            isinstance(value, np.ndarray) and value.dtype.kind == "b"
        ):  # a list with a bool: real_array
            raise InvalidInputError(
                f"stiffness of joint {name!r} is {value!r}; expected a number >= 0 "
                "[N m/rad or N/m], not a bool"
            )
        value = real_array(value, f"stiffness of joint {name!r}")
        if value.ndim == 2 and value.size > 1:
            blocks[name] = _spd_block(name, value, jm.nv)
            k[jm.idx_v : jm.idx_v + jm.nv] = np.diag(blocks[name])
            continue
        if value.ndim == 2:  # a 1x1 block is a number
            value = value.reshape(-1)
        values = np.broadcast_to(value, (jm.nv,)) if value.ndim == 0 else value
        if values.shape != (jm.nv,):
            raise InvalidInputError(
                f"stiffness of joint {name!r} has {values.size} values; expected "
                + ("1" if jm.nv == 1 else f"1 or {jm.nv}")
            )
        if np.any(np.isnan(values)) or np.any(values < 0):
            raise InvalidInputError(
                f"stiffness of joint {name!r} is {values.tolist()}; expected values >= 0 "
                "(0 = passive, inf = locked)"
            )
        k[jm.idx_v : jm.idx_v + jm.nv] = values
    return frozen(k), blocks


def spring_matrix(
    k: np.ndarray, blocks: Mapping[str, np.ndarray], v_slice: Callable[[str], slice]
) -> np.ndarray:
    """(nv, nv) read-only joint stiffness K_q of the finite springs: the blocks and diag(k)
    elsewhere, 0 on passive and locked coordinates [N m/rad, N/m, N].

    Args:
        k: (nv,) stiffness of every velocity coordinate (0, > 0 or inf), as of
            :func:`joint_stiffness`.
        blocks: joint name -> its (nv_j, nv_j) symmetric positive definite block.
        v_slice: joint name -> its slice of the velocity (tangent) vector.
    """
    K = np.diag(np.where(np.isinf(k), 0.0, k))
    for name, block in blocks.items():
        v = v_slice(name)
        K[v, v] = block
    return frozen(K)


def spring_root(
    k: np.ndarray, blocks: Mapping[str, np.ndarray], v_slice: Callable[[str], slice]
) -> np.ndarray:
    """(nv, nv) read-only square root R of :func:`spring_matrix`, K_q = R^T R: sqrt(k) on
    the diagonal, the transposed Cholesky factor (upper triangular) of each block
    [sqrt(N m), per the joint units] (arguments: those of :func:`spring_matrix`)."""
    R = np.diag(np.sqrt(np.where(np.isinf(k), 0.0, k)))
    for name, block in blocks.items():
        v = v_slice(name)
        R[v, v] = np.linalg.cholesky(block).T
    return frozen(R)


def spring_spectra(blocks: Mapping[str, np.ndarray], v_slice: Callable[[str], slice]) -> tuple:
    """(velocity slice, (nv_j,) read-only eigenvalues, (nv_j, nv_j) read-only eigenvectors)
    of each spring block (arguments: those of :func:`spring_matrix`)."""
    out = []
    for name, block in blocks.items():
        lam, V = np.linalg.eigh(block)
        out.append((v_slice(name), frozen(lam), frozen(V)))
    return tuple(out)

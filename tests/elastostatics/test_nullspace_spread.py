"""The general (null-space) path of the compliance with springs many decades apart.

Expected values: C in mpmath at 50 digits from the same double-precision Jacobians
(Pinocchio's closure and frame Jacobians at the configuration): the admissible motions
are the null space of the closure rows, the motions the springs see those whose sprung
coordinates move, both by SVD at the gap between rounding and order-one singular values,
and C = J N (N^T K N)^-1 N^T J^T. No basis, QR or SVD of the library enters it.
"""

from __future__ import annotations

import mechanisms as mech
import mpmath
import numpy as np
import pytest

from closedloop import compliance
from closedloop.kinematics.configuration import Configuration

#: Digits of the reference: the springs below are up to 1e20 apart (scaled), and C is
#: wanted to 16 digits of its largest entries.
DIGITS = 50
#: Singular values below this times the largest are rounding (the redundant closure rows
#: of CaHyMan: ~1e-16; the rods of a Delta spinning about their axes move no spring); the
#: others are above 5e-2 on these mechanisms.
GAP = 1e-10
#: The general path's C against the reference, relative to the largest entry of the
#: unit-free C (lengths per L): 2e-14 or better measured on these mechanisms and on the
#: Stewart platform, the 3-RRR and the four-bar at spreads up to 1e20; the spring factor's
#: SVD after an unpivoted QR erred 1.2e-11 to 8e-10 on the cases below.
RTOL_GENERAL_PATH = 1e-12

ALPHA = np.deg2rad([45.0, 60.0, 75.0])


def _cahyman(K_T: float):
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS
    from cahyman_pin.urdf_builder import FRAME_M

    model = cahyman_model(DEFAULT_PARAMS.replace(K_T=K_T))
    return model.clm, model.assemble(ALPHA, 0.7, 0.02), FRAME_M


def _delta(**springs):
    m = mech.delta(**springs)
    return m.clm, m.q, m.frame


def _split(A, n: int):
    """Right singular vectors (n, r) and (n, n - r) of the mpmath matrix A (m, n) above
    and below the gap: its row space and its null space."""
    _, s, Vt = mpmath.svd_r(A, full_matrices=True)
    values = [s[i] for i in range(min(A.rows, n))]
    r = sum(1 for v in values if v > GAP * values[0])
    return (mpmath.matrix([[Vt[i, j] for i in part] for j in range(n)])
            for part in (range(r), range(r, n)))  # fmt: skip


def _reference_compliance(clm, q, frame) -> np.ndarray:
    """(6, 6) C [SI] in mpmath (module docstring), world axes at the frame origin."""
    state = Configuration(clm, q)
    k = clm.stiffness
    assert np.all(np.isfinite(k))  # no locked joint (a spring of inf) in these cases
    L = clm.length
    rows = np.where(clm.linear_rows, 1.0 / L, 1.0)[:, None]  # unit-free: lengths per L
    cols = np.where(clm.linear_coordinates, L, 1.0)
    A = state.closure_jacobian() * rows * cols
    with mpmath.workdps(DIGITS):
        _, N = _split(mpmath.matrix(A.tolist()), k.size)  # admissible, scaled coordinates
        sprung = mpmath.matrix([[N[i, c] for c in range(N.cols)] for i in np.flatnonzero(k)])
        N = mpmath.diag(cols.tolist()) * N * next(_split(sprung, N.cols))  # seen, SI
        K = mpmath.diag([mpmath.mpf(float(v)) for v in k])
        JN = mpmath.matrix(state.frame_jacobian(frame, "world").tolist()) * N
        C = JN * mpmath.inverse(N.T * K * N) * JN.T
        return np.array(C.tolist(), dtype=float)


@pytest.mark.parametrize(
    "build",
    [
        pytest.param(lambda: _cahyman(1e20), id="cahyman-leg-motors-1e20"),  # spread 1.1e17
        pytest.param(lambda: _delta(k_rod=2e15), id="delta-stiff-rods-2e15"),  # 6.9e12
        pytest.param(lambda: _delta(k_rod=2e19), id="delta-stiff-rods-2e19"),  # 6.9e16
        pytest.param(lambda: _delta(k_arm=np.full(3, 1e20), k_rod=1.0),
                     id="delta-stiff-arms"),  # 9.7e19
    ],
)  # fmt: skip
def test_the_general_path_keeps_soft_springs_beside_stiff_ones(build):
    """Springs 1e13 to 1e20 apart (scaled): the general path's C to rounding of its
    largest entries. Its spring factor, graded by the springs, lost them to
    eps sqrt(spread) (the soft springs' digits cancelled in its QR and SVD)."""
    clm, q, frame = build()
    C_ref = _reference_compliance(clm, q, frame)
    C = compliance(clm, q, frame, path="null-space").C
    d = np.r_[np.full(3, 1.0 / clm.length), np.ones(3)]  # unit-free: lengths per L
    scale = np.abs(C_ref * np.outer(d, d)).max()
    np.testing.assert_allclose(
        C * np.outer(d, d), C_ref * np.outer(d, d), rtol=0, atol=RTOL_GENERAL_PATH * scale
    )

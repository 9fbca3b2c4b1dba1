"""Maps at ill-conditioned points: det K, the condition numbers and the principal
stiffnesses of every point are those of its single query, above a scaled condition
number of 1e12 too (the map gave NaN there: it took them from the formed C), against
exact values as well, and the map's files carry the same numbers."""

import csv

import mpmath
import numpy as np
import pinocchio as pin
import pytest
from helpers import INDEX_GETTERS, UR5_JOINTS

import closedloop as cl
from cahyman_pin import api
from cahyman_pin.sweep import SweepResult, grid, sweep
from closedloop.analysis.maps import INDICES, column_name, stiffness_map
from closedloop.common.conditioning import ILL_CONDITIONED
from closedloop.exceptions import SingularConfigurationError

EPS = np.finfo(float).eps
#: The UR5's joint springs [N m/rad]: five stiff, a soft last wrist joint.
SPRINGS = np.array([1e4] * 5 + [1.0])
Q0 = np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2])
#: Elbow angles [rad] towards the stretched arm: cond(K_s) ~ 2.7e5 / elbow^2, from 3e8 to
#: 3e16 (1e12 crossed near 5e-4 rad); full rank down to 3e-6 rad (rank 5 at 1e-6).
ELBOW = np.geomspace(3e-2, 3e-6, 9)
#: Leg motor springs K_T [N m/rad] of CaHyMan beside the others (1e4 to 1e6 N/m): the
#: scaled condition number runs from 6e3 to 4e17 (1e12 crossed near K_T = 4e-6).
K_T = np.geomspace(1e2, 1e-12, 8)
#: CaHyMan's pose of the K_T sweep (regular: alpha 45..75 deg).
ALPHA, ALPHA4, S4 = np.deg2rad([45.0, 60.0, 75.0]), 0.7, 0.02
#: Equal but for the order of operations (the same functions on the same numbers).
ROUNDING = 1e-13
#: Digits of the exact reference: the 6x6 inverses and eigenvalues of a K of condition
#: 1e17 keep 50 - 17 digits, far below the double precision results' errors.
DIGITS = 50
#: Against the exact values, in units of eps sqrt(cond(K_s)) (det K and the condition
#: numbers, from the square-root factor: closedloop.common.conditioning) or eps cond(C_block)
#: (the principal stiffnesses, 1 / eigenvalues of a 3x3 block of the formed C, each known
#: to eps of the largest): at most 0.4 and 0.6 measured on this map; 10 leaves a
#: factor of 16.
EPS_UNITS = 10.0


def same_rtol(cond: float) -> float:
    """Map vs single query at a point of scaled condition number ``cond``: up to
    ILL_CONDITIONED the map's C, det K and SI condition number come from the formed C (the
    stacked path's, or a closed form's: batch_indices), within about eps cond of the
    single query's (at most 2.2e-8, EPS_UNITS times); above, it takes the single query's
    C and K: the same numbers but for rounding."""
    return max(ROUNDING, EPS_UNITS * EPS * min(cond, ILL_CONDITIONED))


@pytest.fixture(scope="module")
def ur5_map(ur5_urdf):
    """(model, map) of the UR5 over ELBOW, the other joints at Q0."""
    clm = cl.load_model(ur5_urdf, springs=dict(zip(UR5_JOINTS, SPRINGS, strict=True)))
    fixed = {n: v for n, v in zip(UR5_JOINTS, Q0, strict=True) if n != "elbow_joint"}
    return clm, stiffness_map(clm, "tool0", sweeps={"elbow_joint": ELBOW}, fixed=fixed)


def pose(elbow: float) -> np.ndarray:
    return np.r_[Q0[:2], elbow, Q0[3:]]


def exact_indices(ur5_urdf, q: np.ndarray, length: float) -> dict[str, float]:
    """The indices of K = J^-T diag(k) J^-1 in 50 digits, J the frame Jacobian of tool0
    (Pinocchio, world-aligned axes) of a serial arm whose six joints are sprung: det K =
    prod(k) / det(J)^2, the condition numbers of K and of K_s = D^-1 K D^-1
    (D = diag(1/L, 1/L, 1/L, 1, 1, 1)), the principal stiffnesses 1 / eigenvalues of the 3x3
    blocks of C = J diag(1/k) J^T; and ``cond_<kind>``, the condition number of a block."""
    model = pin.buildModelFromUrdf(str(ur5_urdf))
    J = pin.computeFrameJacobian(model, model.createData(), q, model.getFrameId("tool0"),
                                 pin.LOCAL_WORLD_ALIGNED)  # fmt: skip
    with mpmath.workdps(DIGITS):
        Jm = mpmath.matrix(J.tolist())
        C = Jm * mpmath.diag([1 / mpmath.mpf(k) for k in SPRINGS]) * Jm.T
        K = mpmath.inverse(C)
        d = [1 / mpmath.mpf(length)] * 3 + [mpmath.mpf(1)] * 3
        K_s = mpmath.matrix(6, 6)
        for a in range(6):
            for b in range(6):
                K_s[a, b] = K[a, b] / (d[a] * d[b])
        out = {"det_K": mpmath.fprod(SPRINGS.tolist()) / mpmath.det(Jm) ** 2}
        for name, M in (("condition_number_si", K), ("condition_number", K_s)):
            ev = mpmath.eigsy(M, eigvals_only=True)
            out[name] = max(ev) / min(ev)
        for kind, block in (("translational", range(3)), ("rotational", range(3, 6))):
            c = mpmath.eigsy(mpmath.matrix([[C[a, b] for b in block] for a in block]),
                             eigvals_only=True)  # fmt: skip
            out[f"min_{kind}"], out[f"max_{kind}"] = 1 / max(c), 1 / min(c)
            out[f"cond_{kind}"] = max(c) / min(c)
        return {name: float(v) for name, v in out.items()}


def test_ur5_map_across_cond_1e12_is_the_single_query_and_exact(ur5_urdf, ur5_map):
    """The UR5 with its elbow almost straight: every point's indices are its single
    query's (det K and the SI condition number were NaN above 1e12, and off by eps cond(C)
    below: 7e-5 at 3e11), and within eps sqrt(cond) of the exact values (eps cond(block)
    for the principal stiffnesses)."""
    clm, m = ur5_map
    assert np.all(m.status == "ok")
    for i, elbow in enumerate(ELBOW):
        single = cl.StiffnessIndices.from_result(cl.compliance(clm, pose(elbow), "tool0"))
        exact = exact_indices(ur5_urdf, pose(elbow), clm.length)
        cond = exact["condition_number"]
        for name, value in INDEX_GETTERS.items():
            got = m.indices[name][i]
            np.testing.assert_allclose(got, value(single), rtol=same_rtol(cond),
                                       err_msg=f"{name} at elbow {elbow:g}")  # fmt: skip
            if name.startswith(("min_", "max_")):  # 1 / eigenvalue of a block of C
                scale = exact[f"cond_{name[4:]}"]
            else:  # from the square-root factor
                scale = np.sqrt(cond)
            np.testing.assert_allclose(got, exact[name], rtol=EPS_UNITS * EPS * scale,
                                       err_msg=f"{name} at elbow {elbow:g}")  # fmt: skip
    assert m.indices["condition_number"][0] < 1e12 < m.indices["condition_number"][-1]


def test_ur5_map_files_carry_the_numbers(ur5_map, tmp_path):
    """map.npz and map.csv read back to the map's indices exactly, a number at every
    point (NaN above 1e12 before)."""
    _, m = ur5_map
    npz_path, csv_path = m.save(tmp_path, "condition_number_si")[:2]
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    with np.load(npz_path) as npz:
        for name in INDEX_GETTERS:
            column = [float(row[column_name(name, INDICES[name])]) for row in rows]
            np.testing.assert_array_equal(column, m.indices[name])  # repr: exact
            np.testing.assert_array_equal(npz[name], m.indices[name])
            assert np.isfinite(npz[name]).all(), name


@pytest.mark.parametrize("backend", ["generic", "consistent"])
def test_cahyman_spring_sweep_across_cond_1e12_is_the_single_query(backend, tmp_path):
    """CaHyMan's leg motors from 1e2 down to 1e-12 N m/rad (cond(K_s) 6e3 to 4e17): each
    point's indices are those of api.stiffness at that pose, whose K is from the
    backend's square-root factor (det K and the SI condition number were NaN above
    1e12); a point the query refuses, if any, is singular. The sweep's NPZ and CSV read
    back to the same numbers."""
    points = grid({"K_T": K_T}, alpha=ALPHA, alpha4=ALPHA4, s4=S4)
    res = sweep(points, backend=backend, executor="serial")
    crossed = 0
    for i in range(len(res)):
        params = points.params_at(i)
        try:
            ref = api.stiffness(ALPHA, ALPHA4, S4, params=params, backend=backend)
        except SingularConfigurationError:
            assert res.status[i] == "singular"
            continue
        assert res.status[i] == "ok"
        cond = ref.indices.scaled_condition_number
        crossed += cond > 1e12
        for name, value in INDEX_GETTERS.items():  # ref.det_K, ref.condition_number: these
            np.testing.assert_allclose(res.indices[name][i], value(ref.indices),
                                       rtol=same_rtol(cond),
                                       err_msg=f"{name} at K_T {params.K_T:g}")  # fmt: skip
    assert crossed >= 1
    npz_path, csv_path = res.save(tmp_path)
    loaded = SweepResult.load_npz(npz_path)
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    for name in INDEX_GETTERS:
        np.testing.assert_array_equal(loaded.indices[name], res.indices[name])
        column = [float(row[column_name(name, INDICES[name])]) for row in rows]
        np.testing.assert_array_equal(column, res.indices[name])  # repr: exact

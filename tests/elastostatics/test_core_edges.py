"""Edges of the core stiffness query: threads, near-singular poses, extreme spring values
and sizes, the loop-by-loop passive solve, bad inputs.

Each result is checked against something independent of the path under test: the
general ``path="null-space"``, closed forms of tests/mechanisms.py, CaHyMan's
``consistent`` closed-form backend, the exact scaling laws of units, or C = J K^-1 J^T
on Pinocchio's own Jacobian.
"""

from __future__ import annotations

import copy
import gc
import pickle
import re
import threading
from concurrent.futures import ThreadPoolExecutor

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_JOINTS

import closedloop as cl
import closedloop.elastostatics.partition as partition
from closedloop.common.conditioning import ILL_CONDITIONED, twist_scaling
from closedloop.elastostatics.springs import SPREAD_RESOLVED
from closedloop.exceptions import SingularConfigurationError
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import closure_residual

N_THREADS = 6
#: Rounding of the unit-free computation: C of a mechanism scaled by s (lengths) or by f
#: (springs) against the exact law of units, in norm (measured 5e-15; the scaled problem
#: is the same one, only the rounding of the scalings differs).
RTOL_UNITS = 1e-13
#: Two backward-stable computations of C at a pose of scaled condition number c differ by
#: up to a few eps * c in norm (eps = 2.2e-16): 1e-15 c, with a floor of 1e-13 (the fast
#: paths against the null-space path, measured 8e-12 at c = 1.4e10).
EPS_COND = 1e-15
RTOL_FLOOR = 1e-13
#: The condition number (beta_1 / beta_n)^2 from the singular values of a square-root factor
#: whose entries carry a few eps: its smallest singular value to about eps beta_1, so
#: eps sqrt(c) relative (measured 1.4 eps sqrt(c) at c = 2.7e4, springs times f, on
#: OpenBLAS's Haswell, SandyBridge and Nehalem kernels).
COND_SQRT_ULPS = 16.0
#: K from the square-root factor: its stiffest direction is known to about eps sqrt(c)
#: relative (README); against the closed form, 1e-15 sqrt(c) (measured 1e-9 at c = 1.4e14).
EPS_SQRT_COND = 1e-15
#: C = J diag(1/k) J^T written out against the library: rounding of 6x6 products.
RTOL_SERIAL = 1e-13
GEOMETRIC = [10.0**-k for k in range(1, 10)]


def _rel(actual, desired) -> float:
    """max |actual - desired| / max |desired| (the scaled comparison in norm)."""
    return float(np.abs(np.asarray(actual) - desired).max() / np.abs(desired).max())


def _outcome(clm, q, frame, path="auto"):
    """(result, None) or (None, type of the typed error) of one query."""
    try:
        return cl.compliance(clm, q, frame, path=path), None
    except (cl.MechanismError, cl.SingularConfigurationError) as e:
        return None, type(e)


def _assert_finite(res) -> None:
    for a in (res.C, res.G) + (() if res.stiffness_matrix is None else (res.K,)):
        assert np.isfinite(a).all()


def _same_decisions(clm, q, frame):
    """Fast and null-space paths at one pose: the same rank (or the same typed error),
    finite numbers, C equal to the conditioning's tolerance. Returns both (or Nones)."""
    fast, err_fast = _outcome(clm, q, frame)
    general, err_general = _outcome(clm, q, frame, "null-space")
    assert err_fast is err_general
    if fast is None:
        return None, None
    _assert_finite(fast)
    _assert_finite(general)
    assert fast.rank == general.rank
    assert fast.is_full_rank == (fast.stiffness_matrix is not None)
    c = max(general.condition_number, 1.0)
    assert abs(fast.condition_number / c - 1.0) < max(EPS_COND * c, RTOL_FLOOR)
    assert _rel(fast.C, general.C) <= max(EPS_COND * c, RTOL_FLOOR)
    if abs(np.log10(c / cl.ILL_CONDITIONED)) > 1e-3:  # not on the flag's threshold
        assert fast.ill_conditioned == general.ill_conditioned == (c > cl.ILL_CONDITIONED)
    return fast, general


# ---------------------------------------------------------------------------- threads
def _cahyman_poses(n, seed=11):
    from cahyman_pin.model import cahyman_model

    m, rng = cahyman_model(), np.random.default_rng(seed)
    return m.clm, [
        m.assemble(np.deg2rad(rng.uniform(40, 80, 3)), np.deg2rad(rng.uniform(20, 60)), 0.01)
        for _ in range(n)
    ]


def _fourbar_poses(n):
    clm, _, _ = mech.fourbar_case()
    return clm, [cl.assemble(clm, actuated=[a]).q for a in np.linspace(-0.8, 1.2, n)]


def _chain_angles(n_loops, n, seed=5):
    rng = np.random.default_rng(seed)
    return [rng.uniform(0.3, 1.2, n_loops) * rng.choice([-1, 1], n_loops) for _ in range(n)]


def _chain_poses(n):
    clm, _, _ = mech.fourbar_chain(np.full(30, 0.5))  # 60 passive coordinates: by blocks
    return clm, [mech.fourbar_chain(a)[1] for a in _chain_angles(30, n)]


FRAMES = {"fourbar": "P", "cahyman": "M", "chain": "tip"}
POSES = {"fourbar": _fourbar_poses, "cahyman": _cahyman_poses, "chain": _chain_poses}


def _numbers(res):
    return (res.C, res.G, res.stiffness_matrix, res.rank, res.path, res.condition_number)


def _assert_bit_identical(a, b) -> None:
    for x, y in zip(_numbers(a), _numbers(b), strict=True):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y


def _threaded(fn, items):
    """fn over items from N_THREADS threads released together (a barrier per round)."""
    barrier = threading.Barrier(N_THREADS)

    def run(item):
        barrier.wait()
        return fn(item)

    rounds = [items[i : i + N_THREADS] for i in range(0, len(items), N_THREADS)]
    out = []
    with ThreadPoolExecutor(N_THREADS) as pool:
        for r in rounds:
            assert len(r) == N_THREADS
            out += list(pool.map(run, r))
    return out


@pytest.mark.parametrize("name", sorted(POSES))
def test_threads_on_one_model_give_the_serial_results_bit_for_bit(name):
    clm, poses = POSES[name](2 * N_THREADS)
    frame = FRAMES[name]
    if name == "chain":
        assert partition.scaling(Configuration(clm, poses[0])).loop_blocks is not None
    serial = [cl.compliance(clm, q, frame) for q in poses]
    assert len({round(r.C[0, 0], 12) for r in serial}) == len(poses)  # different poses
    threaded = _threaded(lambda q: cl.compliance(clm, q, frame), poses)
    for a, b in zip(serial, threaded, strict=True):
        _assert_bit_identical(a, b)
    # and the paths agree with the general one (the threaded results are not just stable)
    for q, r in zip(poses[:2], serial[:2], strict=True):
        general = cl.compliance(clm, q, frame, path="null-space")
        assert _rel(r.C, general.C) < RTOL_FLOOR * 10


@pytest.mark.parametrize("name", sorted(POSES))
def test_concurrent_first_use_builds_the_caches_consistently(name):
    """Fresh models (empty per-model caches: scalings, index sets, loop blocks, workspace
    pool, frame ids) queried first by N_THREADS threads at once."""
    clm0, poses = POSES[name](N_THREADS)
    frame = FRAMES[name]
    reference = clm0.with_springs(clm0.springs, clm0.locked)
    serial = [cl.compliance(reference, q, frame) for q in poses]
    for _ in range(3):
        fresh = clm0.with_springs(clm0.springs, clm0.locked)
        threaded = _threaded(lambda q, m=fresh: cl.compliance(m, q, frame), poses)
        for a, b in zip(serial, threaded, strict=True):
            _assert_bit_identical(a, b)


def test_threads_mixing_frames_axes_paths_and_lengths_on_one_model():
    """Queries that share a model's caches under different keys (frames, axes, the
    length L of the per-model scalings, both paths), all at once on a fresh CaHyMan:
    bit-identical to the same queries made one by one on another fresh model."""
    clm0, poses = _cahyman_poses(2)
    L = clm0.length
    queries = [
        (q, frame, axes, length, path)
        for q in poses
        for frame, axes, length, path in (
            ("M", "world", None, "auto"),
            ("H", "local", None, "auto"),
            ("M", "local", 2.0 * L, "auto"),
            ("Q", "world", None, "null-space"),
            ("M", "world", 0.5 * L, "null-space"),
            ("H", "world", 2.0 * L, "auto"),
        )
    ]

    def query(m, item):
        q, frame, axes, length, path = item
        return cl.compliance(m, q, frame, axes, length=length, path=path)

    reference = clm0.with_springs(clm0.springs, clm0.locked)
    serial = [query(reference, item) for item in queries]
    assert len({r.path for r in serial}) == 2
    fresh = clm0.with_springs(clm0.springs, clm0.locked)
    threaded = _threaded(lambda item: query(fresh, item), queries)
    for a, b in zip(serial, threaded, strict=True):
        _assert_bit_identical(a, b)
        assert a.length == b.length


@pytest.mark.parametrize("name", sorted(POSES))
def test_one_configuration_shared_by_threads_at_first_use(name):
    """One Configuration (its own Data, constraint datas and lazily computed Jacobians)
    queried by N_THREADS threads at once, before any Jacobian of it was computed, at two
    frames' axes and both paths: the results of a configuration queried alone."""
    clm, poses = POSES[name](2)
    frame = FRAMES[name]
    calls = [(axes, path) for axes in ("world", "local") for path in ("auto", "null-space")]
    calls = (calls * N_THREADS)[:N_THREADS]
    for q in poses:
        alone = {c: cl.compliance(Configuration(clm, q), frame, c[0], path=c[1]) for c in calls}
        for _ in range(3):
            state = Configuration(clm, q)
            shared = _threaded(lambda c, s=state: cl.compliance(s, frame, c[0], path=c[1]), calls)
            for c, res in zip(calls, shared, strict=True):
                _assert_bit_identical(res, alone[c])


def test_a_copied_configuration_does_not_share_its_workspace_later():
    clm0, _, frame = mech.fourbar_case()
    qa, qb = (cl.assemble(clm0, actuated=[a]).q for a in (0.3, 1.0))
    expected = cl.compliance(clm0, qa, frame).C
    clm = clm0.with_springs(clm0.springs)  # a fresh pool
    state = Configuration(clm, qa)
    twin, deep = copy.copy(state), copy.deepcopy(state)
    assert len({id(state.data), id(twin.data), id(deep.data)}) == 3
    np.testing.assert_array_equal(cl.compliance(deep, frame).C, expected)
    del state, twin, deep
    gc.collect()
    a, b = Configuration(clm, qa), Configuration(clm, qb)
    assert a.data is not b.data
    np.testing.assert_array_equal(cl.compliance(a, frame).C, expected)


# ---------------------------------------------------------------------- near-singular
def test_stewart_towards_fichters_singularity():
    """psi = 90 deg - delta, delta -> 0 in geometric steps: both paths decide alike, K
    matches J^T diag(k) J to eps sqrt(cond), C its inverse to eps cond; past the rank
    threshold a MechanismError, never NaN."""
    errors = 0
    for delta in [*GEOMETRIC, 0.0]:
        m = mech.stewart_near_singular(delta)
        fast, general = _same_decisions(m.clm, m.q, m.frame)
        if fast is None:
            errors += 1
            assert delta < 1e-6  # cond(K) ~ 1.4 / delta^2 reaches 1e14 at 1e-7
            continue
        assert errors == 0  # once singular, it stays so closer in
        K_ref = mech.stewart_stiffness(m.geometry)
        c = general.condition_number
        for res in (fast, general):
            assert res.rank == 6
            assert _rel(res.K, K_ref) <= EPS_SQRT_COND * np.sqrt(c) + RTOL_FLOOR
            assert _rel(res.C, np.linalg.inv(K_ref)) <= EPS_COND * c + RTOL_FLOOR
        d = twist_scaling(fast.length)
        assert fast.ill_conditioned == (np.linalg.cond(K_ref / np.outer(d, d)) > ILL_CONDITIONED)
    assert errors >= 3  # the sequence reaches the singular side


def _rrr3_stretched(e):
    """3-RRR with leg 0 stretched to (l1 + l2) - e [m] (a serial singularity at e = 0)."""
    u = np.array([-0.0322, -0.9995, 0.0]) / np.linalg.norm([-0.0322, -0.9995])
    P = mech.RRR_BASE[0] + (sum(mech.RRR_LENGTHS[0]) - e) * u - mech.RRR_ANCHORS[0]
    return mech.rrr3((P[0], P[1], 0.0))


def _fivebar_stretched(e):
    """Five-bar with leg 0 stretched to (l1 + l2) - e [m] at 60 deg from its pivot."""
    E = mech.FIVEBAR_BASE[0] + (sum(mech.FIVEBAR_LENGTHS[0]) - e) * np.r_[0.5, 0.75**0.5, 0.0]
    return mech.fivebar((E[0], E[1]))


@pytest.mark.parametrize(
    "build, reference, rank",
    [
        (_rrr3_stretched, lambda g: np.linalg.inv(mech.rrr3_planar_stiffness(g)), 3),
        (_fivebar_stretched, mech.fivebar_planar_compliance, 2),
    ],
    ids=["rrr3", "fivebar"],
)
def test_planar_legs_towards_a_stretched_leg(build, reference, rank):
    """A leg stretching (e -> 0): same rank on both paths at every step, the in-plane C
    against the closed form to eps times the larger of cond(K_s) and 1 / sin^2 beta_0: the
    elbow angle of q comes from arccos, exact to eps / sin beta_0 only, and C depends on it
    through the rows d / (e x d) of the stretched leg 0, with a sensitivity 1 / sin beta_0."""
    planar = [0, 1, 5]  # dx, dy, rz
    for e in GEOMETRIC:
        m = build(e)
        fast, general = _same_decisions(m.clm, m.q, m.frame)
        assert fast.rank == rank  # out of plane rigid; in plane kept until e ~ 1e-14
        C_ref = reference(m.geometry)
        g = m.geometry
        end = g["C"][0] if "C" in g else g["E"]
        arm, distal = (g["B"][0] - g["A"][0])[:2], (end - g["B"][0])[:2]
        sin_beta = abs(mech.cross2(arm, distal)) / np.linalg.norm(arm) / np.linalg.norm(distal)
        c = max(general.condition_number, sin_beta**-2)
        for res in (fast, general):
            C = res.C[np.ix_(planar, planar)] if rank == 3 else res.C[:2, :2]
            ref = C_ref if rank == 3 else C_ref[:2, :2]
            assert _rel(C, ref) <= EPS_COND * c + RTOL_FLOOR


def test_cahyman_towards_alpha_1_zero():
    """alpha_1 -> 0 flattens the parallelogram of leg 1 (a change point): the generic model
    on both paths against the consistent closed form's C (not its rank decision, taken on
    other quantities), then a singular configuration: the assembly's
    SingularConfigurationError (the closure rows lose rank on the passive joints by the
    rule) or the query's MechanismError."""
    from cahyman_pin.backends.consistent import consistent_compliance
    from cahyman_pin.model import cahyman_model

    m = cahyman_model()
    alpha4, s4 = np.deg2rad(45.0), 0.01
    singular = 0
    for a in [*GEOMETRIC, 0.0]:
        alpha = np.array([a, np.deg2rad(60.0), np.deg2rad(75.0)])
        try:
            q = m.assemble(alpha, alpha4, s4)
        except SingularConfigurationError as e:
            assert "cannot assemble" in str(e)
            fast = None
        else:
            fast, general = _same_decisions(m.clm, q, "M")
        if fast is None:
            singular += 1
            assert a < 1e-5  # cond ~ 1.7e-1 / a^2: 1e14 near a = 4e-8 scaled, 1e-6 here
            continue
        assert singular == 0
        closed = consistent_compliance(alpha, alpha4, s4)
        c = general.condition_number
        for res in (fast, general):
            assert res.rank == 6
            assert _rel(res.C, closed) <= EPS_COND * c + RTOL_FLOOR
    assert singular >= 3


def _parallelogram_chain_reference(clm, q, frame):
    """(C (6, 6), G (nv, 6)) of a chain of parallelograms (:func:`mech.fourbar_chain`) on
    its parallelogram branch, where the rocker turns with the crank and the coupler
    against it, exactly: dq = T dq_cranks, C = (J T) diag(1/k) (J T)^T, J Pinocchio's."""
    J = _pinocchio_jacobian(clm, q, frame)
    n = clm.model.nv // 3
    T, k = np.zeros((clm.model.nv, n)), np.zeros(n)
    for i in range(n):
        for joint, sign in (("crank", 1.0), ("coupler", -1.0), ("rocker", 1.0)):
            T[clm.joint_v_slice(f"{joint}{i}"), i] = sign
        k[i] = clm.springs[f"crank{i}"]
    JT = J @ T
    return (JT / k) @ JT.T, (T / k) @ JT.T


def _loop_condition(t):
    """2-norm condition of the passive columns of a parallelogram loop at crank t: the
    closure point's velocity per coupler turn 0.2 (0, 1) and per rocker turn
    0.3 (-sin t, cos t) [m/rad]."""
    return np.linalg.cond(np.array([[0.0, -0.3 * np.sin(t)], [0.2, 0.3 * np.cos(t)]]))


def test_chain_with_one_loop_towards_its_change_point(monkeypatch):
    """A chain of 8 four-bars, loop 3 at crank t -> 0: the dense passive solve, the
    loop-by-loop one (forced) and the null-space path take the same decisions, and each
    matches the exact parallelogram kinematics to eps times the conditioning (that of the
    near-singular loop's passive columns, ~1/t, which bounds every path: measured 9e-12 on
    all three at t = 1e-5); at t = 0 a MechanismError on all three."""
    angles = np.array([0.8, -0.7, 0.9, 0.5, -0.6, 0.7, -0.8, 0.6])
    paths = {}
    for t in [*GEOMETRIC, 0.0]:
        a = angles.copy()
        a[3] = t
        dense_clm, q, frame = mech.fourbar_chain(a)
        assert partition.scaling(Configuration(dense_clm, q)).loop_blocks is None
        with monkeypatch.context() as mp:
            mp.setattr(partition, "BLOCK_PASSIVE", 1)
            block_clm, _, _ = mech.fourbar_chain(a)
            assert partition.scaling(Configuration(block_clm, q)).loop_blocks is not None
        blocks, err_blocks = _outcome(block_clm, q, frame)
        dense, general = _same_decisions(dense_clm, q, frame)
        if dense is None:
            assert err_blocks is cl.MechanismError
            paths[t] = None
            continue
        assert err_blocks is None
        _assert_finite(blocks)
        assert blocks.rank == dense.rank == general.rank == 3  # planar
        assert blocks.path == dense.path
        C_ref, G_ref = _parallelogram_chain_reference(dense_clm, q, frame)
        tol = EPS_COND * max(general.condition_number, _loop_condition(t)) + RTOL_FLOOR
        for res in (blocks, dense, general):
            assert _rel(res.C, C_ref) <= tol
            assert _rel(res.G, G_ref) <= tol
        paths[t] = blocks.path
    assert paths[0.1] == "partitioned" and paths[0.0] is None


#: Central differences of the closure residual along a unit joint motion, h = 1e-6:
#: truncation h^2 |residual''| (~1e-12 for these sizes) plus rounding eps L / h (~1e-10).
FD_STEP, ATOL_FD = 1e-6, 1e-8


def _closure_drift(clm, q, dq) -> float:
    """max |d residual / ds| along the unit motion dq / |dq|, by central differences."""
    v = dq / np.linalg.norm(dq)
    plus = closure_residual(clm, pin.integrate(clm.model, q, FD_STEP * v))
    minus = closure_residual(clm, pin.integrate(clm.model, q, -FD_STEP * v))
    return float(np.abs(plus - minus).max() / (2 * FD_STEP))


@pytest.mark.parametrize("where", ["cahyman", "chain-by-blocks"])
def test_near_singular_deflections_keep_the_loops_closed(where, monkeypatch):
    """The joint deflections G w of the fast paths move along the closures, by central
    differences of the residual at every step towards the change point (alpha_1 or one
    loop's crank t -> 0), where the passive motion X is least determined."""
    from cahyman_pin.model import cahyman_model

    if where != "cahyman":  # a new model per step: the cached CaHyMan keeps its scaling
        monkeypatch.setattr(partition, "BLOCK_PASSIVE", 1)
    for t in GEOMETRIC[:5]:  # both give a MechanismError from about 1e-6 on
        if where == "cahyman":
            m = cahyman_model()
            clm = m.clm
            q = m.assemble(np.array([t, np.deg2rad(60.0), np.deg2rad(75.0)]), 0.8, 0.01)
            frame = "M"
        else:
            a = np.array([0.8, -0.7, 0.9, t, -0.6, 0.7, -0.8, 0.6])
            clm, q, frame = mech.fourbar_chain(a)
            assert partition.scaling(Configuration(clm, q)).loop_blocks is not None
        res = cl.compliance(clm, q, frame)
        assert res.path in ("partitioned", "null-space")
        for column in res.G.T:
            if np.abs(column).max() > 0:
                assert _closure_drift(clm, q, column) < ATOL_FD


# ------------------------------------------------------- extreme springs and sizes
def _scaled_projector(V, length):
    """(6, 6) orthogonal projector on the unit-free form of rigid directions V (6, r).

    V is orthogonal (in SI numbers) to the range of C, the twists that wrenches produce;
    that range in scaled twists (d / L, r) is unit-free, and z is orthogonal to D^-1 y
    exactly when D^-1 z is orthogonal to y: the unit-free form is (L v, w)."""
    W = np.linalg.qr(np.r_[np.full(3, length), np.ones(3)][:, None] * V)[0]
    return W @ W.T


@pytest.mark.parametrize("s", [1e-8, 1e-4, 3.7, 1e4, 1e8])
def test_scaled_fourbar_follows_the_law_of_units(s):
    """Lengths times s, prismatic springs over s^2: C = D C_1 D, D = diag(s, s, s, 1, 1, 1),
    and the same rank, condition number, rigid directions (in scaled twists) and path."""
    unit, q1, _ = mech.fourbar_case()
    clm, q, frame = mech.scaled_fourbar(s)
    np.testing.assert_allclose(clm.length, s * unit.length, rtol=1e-15)
    D = np.r_[s, s, s, 1.0, 1.0, 1.0]
    for path in ("auto", "null-space"):
        ref = cl.compliance(unit, q1, frame, path=path)
        res = cl.compliance(clm, q, frame, path=path)
        assert (res.path, res.rank, res.mobility) == (ref.path, ref.rank, ref.mobility)
        assert _rel(res.C / np.outer(D, D), ref.C) < RTOL_UNITS
        np.testing.assert_allclose(res.condition_number, ref.condition_number, rtol=RTOL_UNITS)
        # the rigid directions, unit-free, span the same subspace
        np.testing.assert_allclose(
            _scaled_projector(res.rigid_directions, res.length),
            _scaled_projector(ref.rigid_directions, ref.length),
            atol=RTOL_UNITS,
        )


@pytest.mark.parametrize("s", [1e-9, 1e-6, 1e-3, 1e3, 1e6])
def test_scaled_fourbar_assembles_alike(s):
    """assemble() closes the loops to ASSEMBLY_TOL of the mechanism's size L whatever s:
    the same q (lengths times s) and C = D C_1 D at it. With an absolute 1e-12 m, a
    nanometre four-bar stayed open by 4e-5 of L (its compliance refused the assembly's q)
    and a micrometre one 3e-9 rad off."""
    from closedloop.kinematics.assembly import ASSEMBLY_TOL

    unit = mech.fourbar_case()[0]
    clm, _, frame = mech.scaled_fourbar(s)
    ref, asm = cl.assemble(unit, [0.3]), cl.assemble(clm, [0.3])
    assert asm.residual <= ASSEMBLY_TOL * clm.length
    D = np.where(unit.linear_coordinates, s, 1.0)  # nq = nv: revolute and prismatic joints
    np.testing.assert_allclose(asm.q / D, ref.q, rtol=0, atol=1e-11)  # Newton's last step
    Dw = np.r_[s, s, s, 1.0, 1.0, 1.0]
    C = cl.compliance(clm, asm.q, frame).C
    assert _rel(C / np.outer(Dw, Dw), cl.compliance(unit, ref.q, frame).C) < 1e-10


@pytest.mark.filterwarnings("ignore::closedloop.exceptions.JointLimitWarning")  # unscaled limits
@pytest.mark.parametrize("s", [1e-8, 1e-3, 1e3, 1e6])
def test_scaled_fourbar_equilibrium_follows_the_law_of_units(s):
    """The nonlinear equilibrium under a large load (the crank turns by 0.63 rad, the axial
    springs stretch by 1 % of L, 21 Newton iterations) of the four-bar scaled by s, forces
    over s:
    the same joint deflection, lengths times s, in as many iterations. The solver's rank
    rule, tolerances and step limits count lengths in units of the mechanism's size (with
    absolute ones, s = 1e-8 ended 8e-5 off, 1e-3 1e-8 off, and 1e6 did not converge)."""
    from closedloop.elastostatics.statics import solve_equilibrium

    unit, q1, frame = mech.fourbar_case()
    w1 = np.array([300.0, 0.0, -300.0, 0.0, 0.0, 0.0])
    ref = solve_equilibrium(unit, q1, frame, w1)
    clm, q, frame = mech.scaled_fourbar(s)
    eq = solve_equilibrium(clm, q, frame, np.r_[w1[:3] / s, w1[3:]])
    D = np.where(unit.linear_coordinates, s, 1.0)
    assert _rel(eq.joint_deflection / D, ref.joint_deflection) < RTOL_UNITS
    assert eq.iterations == ref.iterations


@pytest.mark.parametrize("f", [1e-6, 1e-3, 1e3, 1e9, 1e15])
def test_springs_times_f_give_compliance_over_f(f):
    """Every spring (numbers and coupled blocks) times f: C / f, the same path, rank and
    scaled condition number (four-bar, CaHyMan, a serial chain with 6x6 and 2x2 blocks)."""
    blocks = lambda: (*mech.serial_with_block()[:2], "tool")  # noqa: E731
    for build in (mech.fourbar_case, mech.cahyman_case, blocks):
        clm, q, frame = build()
        ref = cl.compliance(clm, q, frame)
        scaled = clm.with_springs({n: np.asarray(v) * f for n, v in clm.springs.items()})
        res = cl.compliance(scaled, q, frame)
        assert (res.path, res.rank) == (ref.path, ref.rank)
        assert _rel(res.C * f, ref.C) < RTOL_UNITS
        # (beta_1 / beta_6)^2 of factors whose entries differ by the rounding of sqrt(k f)
        cond_rtol = COND_SQRT_ULPS * np.finfo(float).eps * np.sqrt(ref.condition_number)
        np.testing.assert_allclose(res.condition_number, ref.condition_number, rtol=cond_rtol)


def _ur5(springs_by_joint):
    clm, q, frame = mech.ur5_case()
    return clm.with_springs(springs_by_joint), q, frame


def _pinocchio_jacobian(clm, q, frame):
    data = clm.model.createData()
    fid = clm.model.getFrameId(frame)
    return pin.computeFrameJacobian(clm.model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)


def test_mixed_springs_within_the_rank_rule_match_the_serial_formula():
    """1e-6 .. 2e7 on one UR5 (a ratio of 2e13, below the 1e14 of the rank rule):
    C = J diag(1/k) J^T and K = J^-T diag(k) J^-1 on Pinocchio's Jacobian (cond(J) ~ 10,
    so the closed forms are exact to ~1e-15), on both paths: K to eps sqrt(cond)."""
    k = np.array([1e-6, 1e7, 3e-4, 1e6, 1e-6, 2e7])
    clm, q, frame = _ur5(dict(zip(UR5_JOINTS, k, strict=True)))
    J = _pinocchio_jacobian(clm, q, frame)
    assert np.linalg.cond(J) < 100
    C_ref = (J / k) @ J.T
    J_inv = np.linalg.inv(J)
    K_ref = J_inv.T @ (k[:, None] * J_inv)
    for path in ("auto", "null-space"):
        res = cl.compliance(clm, q, frame, path=path)
        _assert_finite(res)
        assert _rel(res.C, C_ref) < RTOL_SERIAL
        assert res.ill_conditioned and res.rank == 6  # the rank is that of the kinematics
        c = res.condition_number
        assert _rel(res.K, K_ref) <= EPS_SQRT_COND * np.sqrt(c) + RTOL_FLOOR


@pytest.mark.parametrize("low, high", [(1e-6, 1e9), (1.0, 1e15), (1e-3, 1e12), (1e-2, 1e18),
                                       (1.0, 1e30)])  # fmt: skip
def test_springs_far_apart_are_springs_on_both_paths(low, high):
    """Springs 1e15 to 1e30 apart on one UR5 (a stiff motor beside a soft one): every
    spring is a spring, whatever the ratio (the springs' values do not decide which
    motions are spring-free). C = J diag(1/k) J^T on Pinocchio's Jacobian on the fast
    path at any spread, on the general one up to its SPREAD_RESOLVED (beyond: refused);
    K to eps sqrt(cond)."""
    k = np.where(np.arange(6) % 2 == 0, low, high)
    clm, q, frame = _ur5(dict(zip(UR5_JOINTS, k, strict=True)))
    J = _pinocchio_jacobian(clm, q, frame)
    C_ref = (J / k) @ J.T
    J_inv = np.linalg.inv(J)
    K_ref = J_inv.T @ (k[:, None] * J_inv)
    resolved = high / low <= SPREAD_RESOLVED
    for path in ("auto", "null-space") if resolved else ("auto",):
        res = cl.compliance(clm, q, frame, path=path)
        _assert_finite(res)
        assert _rel(res.C, C_ref) < RTOL_SERIAL
        assert res.ill_conditioned and res.rank == 6 and res.internal_mobilities == 0
        assert _rel(res.K, K_ref) <= EPS_SQRT_COND * np.sqrt(res.condition_number) + RTOL_FLOOR
    if not resolved:
        with pytest.raises(cl.SingularConfigurationError, match=r"span 1.0e\+30"):
            cl.compliance(clm, q, frame, path="null-space")


def test_the_general_path_keeps_a_soft_leg_beside_stiff_ones():
    """A Stewart platform whose leg springs span 1e20: the general path's C equals
    A^-1 diag(1/k) A^-T (A the inverse Jacobian by hand, cond(A) ~ 10) to rounding, as
    the fast path's does. Its spring factor diag(sqrt k) N is graded by rows; its SVD
    resolved the soft leg only to eps of the stiff one: 1.6e-6 of C, eps sqrt(1e20)."""
    k = mech.STEWART_K[0] * np.array([1.0, 1e4, 1e9, 1e13, 1e17, 1e20])
    m = mech.stewart(position=(0.05, -0.02, 1.1), psi=0.2, tilt=(0.1, -0.05), k=k)
    A_inv = np.linalg.inv(mech.stewart_inverse_jacobian(m.geometry["u"], m.geometry["r"]))
    C_ref = (A_inv / k) @ A_inv.T
    d = twist_scaling(m.clm.length)
    for path in ("auto", "null-space"):
        C = cl.compliance(m.clm, m.q, m.frame, path=path).C
        assert _rel(C * np.outer(d, d), C_ref * np.outer(d, d)) < RTOL_SERIAL


def test_springs_far_apart_are_answered_alike_at_every_scale():
    """Crank 1 N m/rad and axial springs r / L^2 (r the ratio of the scaled springs, 1e12
    to 1e19): the four-bar at every size s (1e-4, 1, 1e4) is answered on both paths with
    the same numbers, and its unit-free rank and condition number do not depend on s."""
    unit, _, _ = mech.fourbar_case()
    for r in 10.0 ** np.arange(12.0, 19.01, 1.75):
        k = r / unit.length**2
        by_size = []
        for s in (1e-4, 1.0, 1e4):
            clm, q, frame = mech.scaled_fourbar(
                s, {"crank": 1.0, "crank_axial": k, "rocker_axial": k}
            )
            fast, _ = _same_decisions(clm, q, frame)
            assert fast is not None
            by_size.append((fast.rank, fast.condition_number))
        assert len({rank for rank, _ in by_size}) == 1
        c = by_size[1][1]
        np.testing.assert_allclose([cond for _, cond in by_size], c, rtol=EPS_COND * c + 1e-12)


def test_infinite_spring_is_a_lock_and_zero_a_passive_joint():
    clm, q, frame = mech.fourbar_case()
    base = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    infinite = clm.with_springs({**base, "crank_axial": np.inf})
    locked = clm.with_springs({"crank": 50.0, "rocker_axial": 2e5}, locked=["crank_axial"])
    for path in ("auto", "null-space"):
        a = cl.compliance(infinite, q, frame, path=path)
        b = cl.compliance(locked, q, frame, path=path)
        np.testing.assert_array_equal(a.C, b.C)
        np.testing.assert_array_equal(a.G, b.G)
        assert a.rank == b.rank == 2  # the crank's axial motion of P is gone
        # the locked coordinate does not deflect (exactly on the fast path, which leaves it
        # out; to rounding of the null space, whose basis only nearly vanishes there)
        locked_rows = a.G[infinite.joint_v_slice("crank_axial")]
        assert np.abs(locked_rows).max() <= (0.0 if a.path == "partitioned" else 1e-14) * (
            np.abs(a.G).max()
        )
    zero = clm.with_springs({**base, "crank": 0.0})
    for path in ("auto", "null-space"):  # the crank turns freely: no equilibrium
        with pytest.raises(cl.MechanismError, match="'crank'"):
            cl.compliance(zero, q, frame, path=path)


def test_serial_formula_with_a_locked_joint():
    """UR5 with its elbow locked (inf): C = J_s diag(1/k_s) J_s^T without the elbow column."""
    k = np.array([2e3, 5e3, np.inf, 1e3, 7e2, 4e2])
    clm, q, frame = _ur5(dict(zip(UR5_JOINTS, k, strict=True)))
    J = _pinocchio_jacobian(clm, q, frame)
    free = np.isfinite(k)
    C_ref = (J[:, free] / k[free]) @ J[:, free].T
    for path in ("auto", "null-space"):
        res = cl.compliance(clm, q, frame, path=path)
        assert _rel(res.C, C_ref) < RTOL_SERIAL
        assert res.rank == 5


@pytest.mark.parametrize("value", [0.0, 1e5])
def test_a_joint_both_locked_and_sprung_is_locked_or_refused(value):
    clm, _, _ = mech.fourbar_case()
    spec = {"crank": 50.0, "crank_axial": value, "rocker_axial": 2e5}
    try:
        both = clm.with_springs(spec, locked=["crank_axial"])
    except cl.InvalidInputError as e:
        assert "crank_axial" in str(e)
        return
    assert np.isinf(both.stiffness[both.joint_v_slice("crank_axial")]).all()


@pytest.mark.parametrize("build", [mech.fourbar_case, mech.ur5_case], ids=["fourbar", "ur5"])
def test_every_joint_locked_gives_a_zero_compliance(build):
    clm, q, frame = build()
    rigid = clm.with_springs({n: np.inf for n in clm.springs})
    for path in ("auto", "null-space"):
        res = cl.compliance(rigid, q, frame, path=path)
        np.testing.assert_array_equal(res.C, 0.0)
        assert res.rank == 0 and res.rigid_directions.shape == (6, 6)
        with pytest.raises(cl.RigidDirectionsError):
            res.K  # noqa: B018


# ---------------------------------------------------------------------- bad inputs
@pytest.fixture(scope="module")
def fourbar_q():
    clm, q, frame = mech.fourbar_case()
    return clm, np.array(q), frame


@pytest.mark.parametrize(
    "bad, match",
    [
        (lambda q: np.r_[q[:-1], np.nan], r"non-finite values: \[.*nan\]"),
        (lambda q: np.r_[q[:-1], np.inf], r"non-finite values: \[.*inf\]"),
        (lambda q: np.r_[q[:-1], -np.inf], r"non-finite values: \[.*-inf\]"),
        (lambda q: q.astype(complex), "real numbers.*complex"),
        (lambda q: q + 1e-3j, "real numbers.*complex"),
        (lambda q: q[:-1], "q has 4 values; expected nq=5"),
        (lambda q: np.r_[q, 0.0], "q has 6 values; expected nq=5"),
        (lambda q: np.zeros(0), "q has 0 values; expected nq=5"),
        (lambda q: [str(x) for x in q], "q must be real numbers"),
        (lambda q: [0.3, [0.0, 1.0], 0.0, 0.0, 0.0], "q must be real numbers.*ragged"),
        (lambda q: np.array(q, dtype=object), "q must be real numbers"),
        (lambda q: q[None], r"one configuration, shape \(nq,\) = \(5,\), got shape \(1, 5\)"),
        (lambda q: q[:, None], r"got shape \(5, 1\)"),
        # numpy hands over the hidden values: a different pose, silently
        (lambda q: np.ma.masked_array(q, mask=[0, 0, 1, 0, 0]), r"masked entries at \[2\]"),
        (lambda q: [q.tolist()], r"got shape \(1, 5\)"),
    ],
)
def test_bad_q_is_a_typed_error_naming_it(fourbar_q, bad, match):
    clm, q, frame = fourbar_q
    for call in (lambda x: cl.compliance(clm, x, frame), lambda x: Configuration(clm, x)):
        with pytest.raises(cl.InvalidInputError, match=match):
            call(bad(q))


def test_integer_q_is_taken_as_floats():
    clm, _, frame = mech.ur5_case()
    q_int = np.array([0, -1, 1, 0, 1, 0])
    res = cl.compliance(clm, q_int, frame)
    ref = cl.compliance(clm, q_int.astype(float), frame)
    np.testing.assert_array_equal(res.C, ref.C)
    J = _pinocchio_jacobian(clm, q_int.astype(float), frame)
    assert _rel(res.C, J @ J.T / 1e4) < RTOL_SERIAL
    # an integer q that does not close the four-bar's loop is refused by the closure check
    fb, q, fb_frame = mech.fourbar_case()
    with pytest.raises(cl.OpenLoopError, match="does not close the loops"):
        cl.compliance(fb, np.round(q).astype(int), fb_frame)


@pytest.mark.parametrize("layout", ["read-only", "strided", "fortran-2d-row", "big-endian"])
def test_memory_layouts_of_q_give_the_same_result(fourbar_q, layout):
    clm, q, frame = fourbar_q
    ref = cl.compliance(clm, q.copy(), frame)
    if layout == "read-only":
        x = q.copy()
        x.flags.writeable = False
    elif layout == "strided":
        big = np.zeros(2 * q.size)
        big[::2] = q
        x = big[::2]
        assert not x.flags.c_contiguous
    elif layout == "fortran-2d-row":
        x = np.asfortranarray(np.tile(q, (2, 1)))[0]
        assert not x.flags.c_contiguous
    else:
        x = q.astype(">f8")
    res = cl.compliance(clm, x, frame)
    np.testing.assert_array_equal(res.C, ref.C)
    np.testing.assert_array_equal(res.q, q)
    assert not res.q.flags.writeable


def test_configuration_does_not_alias_a_strided_q(fourbar_q):
    clm, q, frame = fourbar_q
    big = np.zeros(2 * q.size)
    big[::2] = q
    state = Configuration(clm, big[::2])
    big[:] = 7.0
    np.testing.assert_array_equal(state.q, q)
    np.testing.assert_array_equal(cl.compliance(state, frame).C, cl.compliance(clm, q, frame).C)


@pytest.mark.parametrize(
    "frame, error, match",
    [
        ("nope", cl.NameNotFoundError, "unknown frame 'nope'; expected one of: 'universe'"),
        ("", cl.NameNotFoundError, "unknown frame ''"),
        ("p", cl.NameNotFoundError, "unknown frame 'p'"),
        (3, cl.InvalidInputError, r"frame name must be a str, got 3 \(int\)"),
        (b"P", cl.InvalidInputError, r"frame name must be a str, got b'P' \(bytes\)"),
        (np.str_("nope"), cl.NameNotFoundError, "unknown frame .*'nope'"),
    ],
)
def test_bad_frame_is_a_typed_error_naming_it(fourbar_q, frame, error, match):
    clm, q, _ = fourbar_q
    with pytest.raises(error, match=match):
        cl.compliance(clm, q, frame)
    with pytest.raises(error, match=match):
        Configuration(clm, q).frame_jacobian(frame)
    if isinstance(frame, str):
        with pytest.raises(error, match=match):
            cl.compliance(Configuration(clm, q), frame)


@pytest.mark.parametrize("frame", [3, b"P"])
def test_non_str_frame_of_a_configuration_is_a_typed_error(fourbar_q, frame):
    clm, q, _ = fourbar_q
    with pytest.raises(cl.InvalidInputError, match=f"frame name must be a str, got {frame!r}"):
        cl.compliance(Configuration(clm, q), frame)


def test_unhashable_frame_is_a_typed_error(fourbar_q):
    clm, q, _ = fourbar_q
    with pytest.raises(cl.InvalidInputError, match=r"frame name must be a str, got \['P'\]"):
        cl.compliance(clm, q, ["P"])


def test_bad_configuration_arguments_are_typed_errors(fourbar_q):
    clm, q, frame = fourbar_q
    for model, kind in (("fourbar", "str"), (None, "NoneType"), (clm.model, "Model")):
        with pytest.raises(cl.InvalidInputError, match=f"expected a ClosedLoopModel.*got {kind}"):
            Configuration(model, q)
    with pytest.raises(cl.InvalidInputError, match=r"> 0 .*got -2"):
        Configuration(clm, q, length=-2)
    state = Configuration(clm, q)
    with pytest.raises(cl.InvalidInputError, match="belong to the Configuration"):
        cl.compliance(state, frame, length=1.0)
    with pytest.raises(cl.InvalidInputError, match="belong to the Configuration"):
        cl.compliance(state, q, frame)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"axes": "WORLD"}, "axes 'WORLD'; expected one of"),
        ({"axes": None}, "axes None; expected one of"),
        ({"path": "fast"}, "path 'fast'; expected one of"),
        ({"length": 0.0}, "characteristic length must be finite and > 0"),
        ({"length": -1.0}, "characteristic length must be finite and > 0"),
        ({"length": np.nan}, "characteristic length must be finite and > 0 .* nan"),
        ({"length": np.inf}, "characteristic length must be finite and > 0 .* inf"),
        ({"length": 10**400}, "characteristic length must be finite and > 0 .* 1000"),
        ({"length": 5e-324}, r"length 5e-324 m is below 5\.56e-309 m, where the twist scaling"),
        ({"length": True}, r"characteristic length must be a real number \[m\], got True"),
        ({"length": 1j}, r"must be a real number \[m\], got 1j \(complex\)"),
        ({"length": "0.5"}, r"must be a real number \[m\], got '0.5' \(str\)"),
    ],
)
def test_bad_options_are_typed_errors_naming_them(fourbar_q, kwargs, match):
    clm, q, frame = fourbar_q
    with pytest.raises(cl.InvalidInputError, match=match):
        cl.compliance(clm, q, frame, **kwargs)


@pytest.mark.parametrize("length", [np.int64(2), np.int32(2), np.float32(2.0), 2])
def test_a_length_of_any_real_number_type_is_that_length(fourbar_q, length):
    clm, q, frame = fourbar_q
    expected = cl.compliance(clm, q, frame, length=2.0)
    for result in (cl.compliance(clm, q, frame, length=length),
                   cl.compliances(clm, q[None], frame, length=length)):  # fmt: skip
        assert result.length == 2.0
        np.testing.assert_array_equal(np.reshape(result.C, (6, 6)), expected.C)


def test_a_scalar_q_is_the_configuration_of_a_one_coordinate_model():
    model = pin.Model()
    model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "hinge")
    model.addFrame(pin.Frame("tip", 1, pin.SE3(np.eye(3), np.array([0.5, 0, 0])),
                             pin.FrameType.OP_FRAME))  # fmt: skip
    clm = cl.ClosedLoopModel(model, springs={"hinge": 100.0})
    np.testing.assert_array_equal(
        cl.compliance(clm, 0.2, "tip").C, cl.compliance(clm, [0.2], "tip").C
    )


def _results_with_arrays():
    """(name, result) of each result type whose arrays are read-only."""
    from cahyman_pin.api import stiffness
    from closedloop.analysis.maps import stiffness_map

    clm, q, frame = mech.ur5_case()
    fourbar, _, frame_fb = mech.fourbar_case()
    return {
        "ComplianceResult": cl.compliance(clm, q, frame),
        "PreloadedCompliance": cl.compliance(clm, q, frame, preload=[1.0, 0, 0, 0, 0, 0]),
        "BatchCompliance": cl.compliances(clm, [q, q], frame),
        "Equilibrium": cl.solve_equilibrium(clm, q, frame, [1.0, 0, 0, 0, 0, 0]),
        "Assembly": cl.assemble(fourbar, actuated=[0.3]),
        "StiffnessMap": stiffness_map(fourbar, frame_fb, sweeps={"crank": [0.2, 0.3]}, workers=1),
        "CaHyManStiffness": stiffness(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0),
    }


def test_unpickled_results_keep_their_arrays_read_only():
    for name, result in _results_with_arrays().items():
        copy_ = pickle.loads(pickle.dumps(result))
        arrays = {k: v for k, v in vars(copy_).items() if isinstance(v, np.ndarray)}
        arrays.update(
            {
                f"{k}[{i}]": a
                for k, v in vars(copy_).items()
                if isinstance(v, dict)
                for i, a in v.items()
                if isinstance(a, np.ndarray)
            }
        )
        assert arrays, name
        for key, a in arrays.items():
            assert not a.flags.writeable, (name, key)
            np.testing.assert_array_equal(a, np.asarray(_field(result, key)))


def _field(result, key: str):
    if "[" in key:
        name, item = key[:-1].split("[")
        return getattr(result, name)[item]
    return getattr(result, key)


def _floating_arm() -> tuple[cl.ClosedLoopModel, np.ndarray]:
    """A free-flyer base (a 6x6 spring) carrying a revolute arm; q with a unit quaternion."""
    model = pin.Model()
    base = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    arm = model.addJoint(base, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.2, 0, 0])), "arm")
    model.addFrame(pin.Frame("tip", arm, pin.SE3(np.eye(3), np.array([0.5, 0, 0])), pin.OP_FRAME))
    block = np.diag([1e5, 1e5, 1e5, 1e3, 1e3, 1e3])
    clm = cl.ClosedLoopModel(model, springs={"base": block, "arm": 200.0})
    q = pin.integrate(model, pin.neutral(model), np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6, 0.7]))
    return clm, q


@pytest.mark.parametrize("factor, message", [(2.0, r"\[.*\]: its quaternion"), (0.0, "norm 1")])
def test_a_quaternion_off_the_unit_sphere_is_refused_naming_its_joint(factor, message):
    clm, q = _floating_arm()
    bad = q.copy()
    bad[3:7] *= factor
    for call in (lambda: cl.compliance(clm, bad, "tip"), lambda: Configuration(clm, bad)):
        with pytest.raises(cl.InvalidInputError, match=f"joint 'base'.*{message}"):
            call()
    with pytest.raises(cl.InvalidInputError, match="configuration 1 of Q: q of joint 'base'"):
        cl.compliances(clm, [q, bad], "tip")


def test_a_quaternion_within_the_tolerance_is_normalised():
    """A quaternion typed to 9 digits gives the compliance of the unit one, in both
    paths (a non-unit quaternion would scale the base rotation's matrix)."""
    clm, q = _floating_arm()
    typed = np.round(q, 9)
    assert abs(np.linalg.norm(typed[3:7]) - 1.0) > 1e-12
    ref = cl.compliance(clm, q, "tip").C
    np.testing.assert_allclose(cl.compliance(clm, typed, "tip").C, ref, rtol=1e-8)
    np.testing.assert_allclose(cl.compliances(clm, [typed], "tip").C[0], ref, rtol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(Configuration(clm, typed).q[3:7]), 1.0, rtol=1e-15)


@pytest.mark.parametrize("k", [1e-310, 1e308])
def test_overflowing_springs_are_the_typed_error_even_with_warnings_as_errors(ur5_urdf, k):
    """Springs at the ends of the double range overflow C or K: the typed error naming the
    springs, and no numpy warning on the way (a warning filter set to "error" must not
    turn it into a RuntimeWarning)."""
    import warnings

    clm = cl.load_model(ur5_urdf, joint_stiffness=k, geometry=False)
    q = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        named = re.escape(f"springs from {k:.3g} to")
        with pytest.raises(cl.SingularConfigurationError, match=named):
            cl.compliance(clm, q, "tool0")
        with pytest.raises(cl.SingularConfigurationError, match="at configuration 0 of Q"):
            cl.compliances(clm, q[None], "tool0")

"""Sweeps: equal to point-by-point queries, independent of the executor, failures marked."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_close_in_norm

from cahyman_pin import api
from cahyman_pin.backends import registry
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.sweep import SweepResult, grid, pose_list, sweep
from cahyman_pin.sweep import execution as sweep_exec
from closedloop.analysis.map_engine import path_order
from closedloop.analysis.map_results import STATUS, status_code
from closedloop.exceptions import ClosedLoopError, InvalidInputError, SingularConfigurationError

#: Sweep against point-by-point api.stiffness. Both run the same functions on the same
#: inputs (CaHyManModel.assemble, closedloop.elastostatics.compliance.compliance at M, the formulas
# of  StiffnessIndices on the same C); the only difference is the start of the assembly
#: (the neighbour's configuration vs the closed-form guess), so the two configurations
#: agree within the assembly tolerance (closure residual 1e-12 m on links of 0.1 m), and
#: the indices within that relative error times their condition (det K is a product of
#: six eigenvalues): about 1e-11 observed.
SAME_PATH_RTOL = 1e-10
#: With the closed-form start the sweep assembles from the very configuration that
#: api.stiffness uses: only batched vs single linear algebra differs (rounding).
CLOSED_FORM_START_RTOL = 1e-13
#: The indices that need K: the API takes K from the square-root factor of the generic
#: solver, the batched sweep from inv(C); the two differ by about eps cond(C_SI), cond(C_SI)
#: ~ 4e3 here, i.e. 1e-12. The scaled condition number: the API's from the solver's
#: square-root factor, the sweep's from the eigenvalues of C_s (batch_rank): same bound.
K_PATH_RTOL = 1e-11
K_INDICES = ("det_K", "condition_number", "condition_number_si")
WRENCH = np.array([1.0, -2.0, 0.5, 0.3, 0.0, -0.2])
SCALAR_INDICES = (
    "det_K",
    "condition_number",
    "condition_number_si",
    "min_translational",
    "max_translational",
    "min_rotational",
    "max_rotational",
)
DEG = np.pi / 180.0


def small_grid(**kw):
    """12 poses around the paper's Fig. 5 configuration."""
    axes = {
        "alpha1": np.deg2rad([50.0, 60.0, 70.0]),
        "alpha4": np.deg2rad([20.0, 45.0, 60.0, 80.0]),
    }
    return grid(axes, alpha=np.deg2rad([60.0, 65.0, 70.0]), s4=0.025, **kw)


def pointwise(points, backend: str, i: int) -> api.CaHyManStiffness:
    return api.stiffness(
        points.alpha[i], points.alpha4[i], points.s4[i], params=points.params_at(i), backend=backend
    )


def scaled_condition(K: np.ndarray, length: float) -> float:
    """2-norm condition number of K_s = D^-1 K D^-1, D = diag(1/L, 1/L, 1/L, 1, 1, 1)."""
    d = np.r_[np.full(3, length), np.ones(3)]
    return float(np.linalg.cond(d[:, None] * K * d[None, :]))


def assert_matches_pointwise(result: SweepResult, rtol: float) -> None:
    """Every point against its own ``api.stiffness`` query: C, deflection and block indices
    within ``rtol``, det K and the condition numbers within max(rtol, K_PATH_RTOL); a
    failed point has the status of the query's exception and its message as reason."""
    pts = result.points
    for i in range(len(result)):
        if not result.ok[i]:
            with pytest.raises(ClosedLoopError) as error:
                pointwise(pts, result.backend, i)
            assert STATUS[status_code(error.value)] == result.status[i]
            assert result.reasons[i] == " ".join(str(error.value).split())
            continue
        ref = pointwise(pts, result.backend, i)
        assert_close_in_norm(result.C[i], ref.C, rtol)
        got = {name: result.indices[name][i] for name in SCALAR_INDICES}
        expected = {"det_K": ref.det_K, "condition_number_si": ref.condition_number}
        if ref.indices is not None:
            expected.update(
                condition_number=ref.indices.scaled_condition_number,
                min_translational=ref.indices.min_translational_stiffness.value,
                max_translational=ref.indices.max_translational_stiffness.value,
                min_rotational=ref.indices.min_rotational_stiffness.value,
                max_rotational=ref.indices.max_rotational_stiffness.value,
            )
        else:
            expected["condition_number"] = scaled_condition(ref.K, pts.params_at(i).length)
        for name, value in expected.items():
            tol = max(rtol, K_PATH_RTOL) if name in K_INDICES else rtol
            np.testing.assert_allclose(got[name], value, rtol=tol, err_msg=f"{name} at {i}")
        twist = ref.deflection(WRENCH).M
        assert_close_in_norm(result.indices["deflection"][i], twist, rtol)


# ---------------------------------------------------------------- points
@pytest.mark.parametrize(("shape", "outer"), [((3, 4), []), ((2, 3, 2), [2]), ((4, 1, 3), [0])])
def test_path_visits_every_point_once_by_unit_steps(shape, outer):
    order = path_order(shape, outer)
    assert sorted(order.tolist()) == list(range(int(np.prod(shape))))
    steps = np.diff(np.array(np.unravel_index(order, shape)), axis=1)
    assert np.all(np.abs(steps).sum(axis=0) == 1)  # one step along one axis
    for axis in outer:  # outer axes vary slowest: they change size - 1 times
        assert np.count_nonzero(steps[axis]) == shape[axis] - 1


def test_grid_inputs_and_validation():
    pts = small_grid()
    assert len(pts) == 12 and pts.shape == (3, 4)
    np.testing.assert_allclose(pts.alpha[:, 1:], np.deg2rad([[65.0, 70.0]] * 12))
    np.testing.assert_allclose(pts.alpha4.reshape(3, 4)[1], np.deg2rad([20.0, 45.0, 60.0, 80.0]))
    both = grid({"alpha": [1.0, 1.1]}, alpha4=0.5, s4=0.0)
    np.testing.assert_array_equal(both.alpha, [[1.0] * 3, [1.1] * 3])
    with pytest.raises(InvalidInputError, match="expected some of"):
        grid({"beta": [1.0]}, alpha=[1, 1, 1], alpha4=0.5, s4=0.0)
    with pytest.raises(InvalidInputError, match="do not sweep both"):
        grid({"alpha": [1.0], "alpha2": [1.0]}, alpha4=0.5, s4=0.0)
    with pytest.raises(InvalidInputError, match="give s4"):
        grid({"alpha": [1.0]}, alpha4=0.5)
    with pytest.raises(InvalidInputError, match="finite"):
        grid({"alpha": [1.0, np.nan]}, alpha4=0.5, s4=0.0)
    with pytest.raises(InvalidInputError, match="one per point"):
        pose_list(np.ones((3, 3)), [0.1, 0.2], 0.0)


# ---------------------------------------------------------------- equal to api.stiffness
def test_generic_sweep_equals_pointwise_queries():
    res = sweep(small_grid(), wrench=WRENCH, start="neighbour", executor="serial")
    assert np.all(res.status == "ok") and np.all(res.rank == 6)
    assert res.iterations.max() > 0  # the assemblies did run from neighbours
    assert_matches_pointwise(res, SAME_PATH_RTOL)


def test_a_chunk_is_queried_a_stack_at_a_time(monkeypatch):
    """The assembled points of a chunk are queried STACK at a time (the closure Jacobians
    the assemblies hand over are let go): with stacks of 4 the results are those of one
    stack, bit for bit (each configuration's computation does not depend on the others)."""
    import closedloop.analysis.map_engine as engine

    one = sweep(small_grid(), wrench=WRENCH, start="neighbour", executor="serial")
    monkeypatch.setattr(engine, "STACK", 4)
    parts = sweep(small_grid(), wrench=WRENCH, start="neighbour", executor="serial")
    assert len(one.C) > 4
    np.testing.assert_array_equal(parts.C, one.C)
    np.testing.assert_array_equal(parts.iterations, one.iterations)
    np.testing.assert_array_equal(parts.status, one.status)


def test_warm_starts_along_a_grid_line_extrapolate():
    """1 deg steps along alpha_1: from the third equal step on, the start is the quadratic
    extrapolation of the last three configurations (error of third order in the step),
    one Gauss-Newton step from closure; the second point starts from the linear one (two
    steps). Each point still equals its own api.stiffness query."""
    line = {"alpha1": np.deg2rad(np.linspace(50.0, 70.0, 21))}
    points = grid(line, alpha=np.deg2rad([50.0, 65.0, 70.0]), alpha4=np.deg2rad(45.0), s4=0.025)
    res = sweep(points, wrench=WRENCH, start="neighbour", executor="serial")
    assert res.iterations[2] == 2 and np.all(res.iterations[3:] == 1), res.iterations
    assert_matches_pointwise(res, SAME_PATH_RTOL)


def test_closed_form_start_reproduces_the_api_to_rounding():
    res = sweep(small_grid(), wrench=WRENCH, start="closed_form", executor="serial")
    assert np.all(res.status == "ok") and np.all(res.iterations == 0)
    assert_matches_pointwise(res, CLOSED_FORM_START_RTOL)


@pytest.mark.parametrize("backend", ["consistent", "published"])
def test_closed_form_sweeps_equal_pointwise_queries(backend):
    res = sweep(small_grid(), backend=backend, wrench=WRENCH, executor="serial")
    assert np.all(res.status == "ok")
    assert_matches_pointwise(res, SAME_PATH_RTOL)
    if backend == "published":  # not symmetric: no principal stiffnesses
        assert np.all(np.isnan(res.indices["min_translational"]))


def test_consistent_backend_evaluates_a_chunk_in_one_call(monkeypatch):
    calls = []
    original = sweep_exec.consistent_compliance

    def counting(alpha, alpha4, s4, params):
        calls.append(len(alpha4))
        return original(alpha, alpha4, s4, params)

    monkeypatch.setattr(sweep_exec, "consistent_compliance", counting)
    sweep(small_grid(), backend="consistent", executor="serial", chunk_size=5)
    assert calls == [5, 5, 2]


def test_design_sweep_rebuilds_the_model():
    pts = grid(
        {"b": [0.06, 0.08, 0.10], "alpha": np.deg2rad([55.0, 65.0])},
        alpha4=np.deg2rad(60.0),
        s4=0.05,
    )
    res = sweep(pts, wrench=WRENCH, executor="serial")
    assert np.all(res.status == "ok")
    assert_matches_pointwise(res, SAME_PATH_RTOL)
    det = res.grid_values("det_K")
    assert det.shape == (3, 2) and np.all(np.abs(np.diff(np.log(det[:, 0]))) > 0.01)
    ref = api.stiffness(pts.alpha[0], pts.alpha4[0], 0.05, params=DEFAULT_PARAMS.replace(b=0.06))
    np.testing.assert_allclose(det[0, 0], ref.det_K, rtol=SAME_PATH_RTOL)


# ---------------------------------------------------------------- executors
def test_serial_and_process_pool_results_are_identical():
    pts = small_grid()
    serial = sweep(pts, wrench=WRENCH, executor="serial", chunk_size=4)
    pooled = sweep(pts, wrench=WRENCH, workers=2, chunk_size=4)
    np.testing.assert_array_equal(pooled.C, serial.C)
    for name, values in serial.indices.items():
        np.testing.assert_array_equal(pooled.indices[name], values)
    np.testing.assert_array_equal(pooled.status, serial.status)


def test_dask_local_cluster_gives_the_serial_results():
    pytest.importorskip("dask.distributed", reason="dask[distributed] is not installed")
    from dask.distributed import Client, LocalCluster

    pts = small_grid()
    serial = sweep(pts, executor="serial", chunk_size=3)
    with (
        LocalCluster(
            processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        distributed = sweep(pts, executor=client.get_executor(), chunk_size=3)
    np.testing.assert_array_equal(distributed.C, serial.C)
    np.testing.assert_array_equal(distributed.indices["det_K"], serial.indices["det_K"])


def test_unknown_executor_is_refused():
    with pytest.raises(InvalidInputError, match="executor"):
        sweep(small_grid(), executor="threads")


# ---------------------------------------------------------------- failures
@pytest.mark.parametrize(
    ("backend", "start"),
    [("generic", "neighbour"), ("generic", "closed_form"), ("consistent", "neighbour")],
)
def test_unreachable_and_invalid_points_are_marked_not_raised(backend, start):
    # alpha_1 = -80 deg: legs too far apart in height; s_4 = 70 mm: beyond the stroke
    pts = grid(
        {"alpha1": np.deg2rad([90.0, 60.0, -80.0, 70.0]), "s4": [0.0, 0.03, 0.07]},
        alpha=np.deg2rad([90.0, 90.0, 90.0]),
        alpha4=0.7,
    )
    res = sweep(pts, backend=backend, wrench=WRENCH, start=start, executor="serial")
    status = res.status.reshape(pts.shape)
    assert np.all(status[:, 2] == "invalid")
    assert np.all(status[2, :2] == "unreachable")
    assert np.all(status[[0, 1, 3], :2] == "ok")
    for i, kind, reason in res.failures():
        assert kind in ("invalid", "unreachable") and reason
        assert np.isnan(res.indices["det_K"][i]) and np.all(np.isnan(res.C[i]))
    assert "outside the stroke" in res.reasons[2]
    assert "cannot be assembled" in res.reasons[6]
    assert_matches_pointwise(res, SAME_PATH_RTOL)  # the points after a failure too


@pytest.mark.parametrize(
    ("backend", "rtol"),
    [("generic", CLOSED_FORM_START_RTOL), ("consistent", SAME_PATH_RTOL),
     ("published", SAME_PATH_RTOL)],
)  # fmt: skip
def test_map_on_the_shared_engine_equals_api_point_by_point(backend, rtol):
    """CaHyMan's map gives the numbers of api.stiffness, point by point, failures with
    their reasons included, on a process pool with chunks that cut the design runs."""
    pts = grid(
        {"b": [0.07, 0.09], "alpha1": np.deg2rad([60.0, -80.0, 70.0]), "s4": [0.0, 0.07]},
        alpha=np.deg2rad([90.0, 90.0, 90.0]),
        alpha4=0.7,
    )
    res = sweep(pts, backend=backend, wrench=WRENCH, workers=2, chunk_size=5)
    assert set(res.status) == {"ok", "invalid", "unreachable"}
    assert_matches_pointwise(res, rtol)


def test_invalid_design_values_are_marked():
    pts = grid({"b": [0.08, -0.01]}, alpha=np.deg2rad([60.0] * 3), alpha4=0.5, s4=0.0)
    res = sweep(pts, backend="consistent", executor="serial")
    assert list(res.status) == ["ok", "invalid"] and "must be > 0" in res.reasons[1]


def test_rank_deficient_closed_form_is_a_singular_pose_as_in_the_api(monkeypatch):
    def rigid_about_z(params, alpha, alpha4, s4):  # no rotation about z
        return registry.BackendResult(C=np.diag([1e-6, 2e-6, 3e-6, 1e-3, 2e-3, 0.0]), pose=None)

    monkeypatch.setitem(registry._BACKENDS, "rigid_about_z", rigid_about_z)
    res = sweep(small_grid(), backend="rigid_about_z", executor="serial")
    assert np.all(res.status == "singular") and np.all(res.rank == 5)
    assert "numerical rank 5 < 6" in res.reasons[0]
    assert np.all(np.isnan(res.indices["det_K"])) and np.all(np.isnan(res.C))
    with pytest.raises(SingularConfigurationError, match="numerical rank 5 < 6"):
        pointwise(res.points, "rigid_about_z", 0)


def test_bad_arguments_raise():
    with pytest.raises(InvalidInputError, match="unknown backend"):
        sweep(small_grid(), backend="nope", executor="serial")
    with pytest.raises(InvalidInputError, match="wrench"):
        sweep(small_grid(), wrench=[1, 2, 3], executor="serial")
    with pytest.raises(InvalidInputError, match="workers"):
        sweep(small_grid(), workers=0)
    with pytest.raises(InvalidInputError, match="start"):
        sweep(small_grid(), start="cold", executor="serial")


# ---------------------------------------------------------------- files
def test_npz_round_trip_and_csv(tmp_path):
    pts = pose_list(
        np.deg2rad([[60.0, 65.0, 70.0], [-80.0, 90.0, 90.0], [50.0, 60.0, 70.0]]),
        np.deg2rad([45.0, 45.0, 30.0]),
        [0.01, 0.01, 0.02],
        design={"L": [0.15, 0.15, 0.2]},
    )
    res = sweep(pts, backend="consistent", wrench=WRENCH, executor="serial")
    paths = res.save(tmp_path, "s")
    assert [p.name for p in paths] == ["s.npz", "s.csv"]
    back = SweepResult.load_npz(paths[0])
    np.testing.assert_array_equal(back.C, res.C)
    np.testing.assert_array_equal(back.status, res.status)
    assert back.reasons == res.reasons and back.points.params == res.points.params
    np.testing.assert_array_equal(back.points.design["L"], [0.15, 0.15, 0.2])
    for name, values in res.indices.items():
        np.testing.assert_array_equal(back.indices[name], values)
    lines = paths[1].read_text().splitlines()
    assert len(lines) == 4 and lines[0].startswith("alpha1_rad,alpha2_rad,alpha3_rad")
    assert "alpha4_rad,s4_m,L_m,status" in lines[0]
    assert "unreachable" in lines[2] and "det_K" in lines[0]
    det = lines[0].split(",").index("det_K_N^6_per_rad^3")
    assert float(lines[1].split(",")[det]) == res.indices["det_K"][0]


def test_parquet_needs_pyarrow(tmp_path):
    res = sweep(small_grid(), backend="consistent", executor="serial")
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        with pytest.raises(InvalidInputError, match="pyarrow"):
            res.save_parquet(tmp_path / "s.parquet")
    else:
        assert res.save_parquet(tmp_path / "s.parquet").exists()


def test_results_keep_no_python_object_per_point():
    res = sweep(small_grid(), backend="consistent", wrench=WRENCH, executor="serial")
    arrays = [res.C, res.rank, res.data.codes, res.data.length, res.iterations,
              res.data.reason_codes, *res.indices.values()]  # fmt: skip
    assert all(isinstance(a, np.ndarray) and a.dtype != object for a in arrays)
    assert res.data.reason_texts == [""]  # every point ok: one shared empty reason
    assert res.data.codes.dtype == np.int8 and res.data.reason_codes.dtype == np.int32


@pytest.mark.parametrize("backend", ["generic", "consistent"])
def test_angles_beyond_one_turn_are_invalid_points_and_refused_alone(backend):
    """The cranks and the arm turn within +-2 pi (the URDF's limits). 45 "rad" (degrees
    passed to the radian API) was answered at 45 - 14 pi; now it is refused by name, and
    a sweep marks such a point invalid, as it marks a stroke beyond s4_max."""
    message = r"alpha = \(45, 45, 45\) rad = \(2578.31, 2578.31, 2578.31\) deg is beyond"
    with pytest.raises(InvalidInputError, match=message):
        api.stiffness([45.0] * 3, 0.5, 0.01, backend=backend)
    with pytest.raises(InvalidInputError, match=r"alpha_4 = \(-7\) rad"):
        api.stiffness(np.deg2rad([60.0] * 3), -7.0, 0.01, backend=backend)
    edge = api.stiffness(np.deg2rad([60.0] * 3), 2 * np.pi, 0.01, backend=backend)  # on the limit
    assert np.all(np.isfinite(edge.C))
    pts = grid({"alpha1": [1.0, 7.0]}, alpha=np.deg2rad([60.0] * 3), alpha4=0.7, s4=0.01)
    res = sweep(pts, backend=backend, executor="serial")
    assert list(res.status) == ["ok", "invalid"]
    assert "beyond the joints' limits of one turn" in res.reasons[1]


#: The lowest frequency of a sweep against cl.modes at the API's assembly of each pose: the
#: same eigenproblem on configurations that agree within the assembly tolerance (1e-12 m),
#: the frequencies' sensitivity to q being of order one: 1e-9 leaves a wide margin.
FREQUENCY_RTOL = 1e-9


def test_lowest_frequency_of_a_sweep_is_that_of_the_modes():
    import closedloop as cl
    from cahyman_pin.model import cahyman_model

    params = DEFAULT_PARAMS.replace(m_HQ=2.0, m_M4=1.0, m_b=0.3)
    alpha4 = np.deg2rad([20.0, 50.0, 80.0])
    pts = grid({"alpha4": alpha4}, alpha=np.deg2rad([80.0, 90.0, 100.0]), s4=0.03,
               params=params)  # fmt: skip
    res = sweep(pts, executor="serial", modes=True, start="neighbour")
    machine = cahyman_model(params)
    expected = [cl.modes(machine.clm, machine.assemble(np.deg2rad([80.0, 90.0, 100.0]), a, 0.03))
                .lowest_elastic_frequency for a in alpha4]  # fmt: skip
    np.testing.assert_allclose(res.indices["lowest_frequency"], expected, rtol=FREQUENCY_RTOL)


def test_lowest_frequency_scales_as_one_over_the_root_of_the_masses(tmp_path):
    """Every mass times 4 (the model has no other inertia): every frequency halves."""
    pts = grid({"m_HQ": np.array([1.0, 4.0]), "m_M4": np.array([0.5, 2.0])},
               alpha=np.deg2rad([80.0, 90.0, 100.0]), alpha4=0.7, s4=0.02)  # fmt: skip
    res = sweep(pts, executor="serial", modes=True)
    f = res.grid_values("lowest_frequency")
    np.testing.assert_allclose(f[1, 1], f[0, 0] / 2.0, rtol=1e-12)  # rounding of the solves
    assert np.isfinite(f).all() and f[0, 1] != f[1, 0]
    back = SweepResult.load_npz(res.save(tmp_path, "map")[0])
    np.testing.assert_array_equal(back.indices["lowest_frequency"], res.indices["lowest_frequency"])


@pytest.mark.parametrize(
    ("params", "backend", "message"),
    [(DEFAULT_PARAMS, "generic", "no mass"),
     (DEFAULT_PARAMS.replace(m_HQ=1.0), "consistent", "generic backend")],
)  # fmt: skip
def test_lowest_frequency_needs_masses_and_the_generic_backend(params, backend, message):
    pts = grid({"alpha4": np.array([0.2, 0.4])}, alpha=np.full(3, 1.5), s4=0.02, params=params)
    with pytest.raises(ClosedLoopError, match=message):
        sweep(pts, backend=backend, executor="serial", modes=True)

"""Edges of the stiffness maps: failures everywhere, at chunk borders, outside the joint
limits, a dead point, loads of extreme magnitude, the files of a map."""

import math
from concurrent.futures import ThreadPoolExecutor

import matplotlib.image
import numpy as np
import pytest
from helpers import REPO, assert_close_in_norm

import closedloop as cl
from closedloop.analysis.complete import classify
from closedloop.analysis.map_results import OK, ChunkResult
from closedloop.analysis.maps import INDICES, column_name, stiffness_map
from closedloop.analysis.model_source import ModelSource
from closedloop.analysis.tasks import run_tasks

#: The four-bar of urdf/fourbar.urdf with its ground link 0.42 m instead of 0.3 m: crank
#: 0.1 m, coupler 0.3 m, rocker 0.15 m; 0.1 + 0.42 > 0.3 + 0.15, so the crank cannot turn
#: fully (not Grashof). Crank angle theta turns the crank tip to 0.1 (sin theta, 0, cos theta)
#: about the rocker pivot D = (0.42, 0, 0); the loop closes while |tip - D| <= 0.45 m
#: (coupler and rocker stretched in line: the dead point), i.e. sin theta >= SIN_DEAD.
SIN_DEAD = (0.1**2 + 0.42**2 - 0.45**2) / (2 * 0.1 * 0.42)
THETA_DEAD = float(np.arcsin(SIN_DEAD))
WRENCH = np.array([3.0, 0.0, -2.0, 0.0, 0.4, 0.0])
#: As tests/analysis/test_maps.py: a chunk changes where its first point starts, within the
#: assembly tolerance (~1e-12) times the sensitivity of C; so does a map's pose against one
#: assembled apart (measured 1.2e-13).
CHUNK_RTOL = 1e-9


@pytest.fixture(scope="module")
def long_ground(tmp_path_factory):
    """(URDF path, closure file path) of the non-Grashof four-bar."""
    folder = tmp_path_factory.mktemp("fourbar")
    text = (REPO / "urdf" / "fourbar.urdf").read_text()
    rocker = '<origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>'
    assert text.count(rocker) == 1
    urdf = folder / "fourbar.urdf"
    urdf.write_text(text.replace(rocker, rocker.replace("0.3", "0.42")))
    closures = folder / "fourbar.yaml"
    closures.write_text((REPO / "urdf" / "fourbar.yaml").read_text())
    return urdf, closures


def reachable(theta: np.ndarray) -> np.ndarray:
    """The loop closes (the closed form above), away from the dead point by 1e-6."""
    return np.sin(theta) >= SIN_DEAD + 1e-6


def test_a_determinant_that_underflows_fails_its_point(ur5_urdf):
    """Springs of 1e-60 N m/rad on the UR5: det K ~ 1e-360 underflowed to 0.0 with status
    ok (a full-rank K has no zero determinant). The point fails, naming the index, as
    one whose index overflows; the single query's det K is a typed error too."""
    clm = cl.load_model(ur5_urdf, joint_stiffness=1e-60)
    fixed = {"shoulder_pan_joint": 0.3, "shoulder_lift_joint": -1.2, "wrist_1_joint": -0.6,
             "wrist_2_joint": 1.1, "wrist_3_joint": 0.2}  # fmt: skip
    m = stiffness_map(clm, "tool0", sweeps={"elbow_joint": [1.0, 1.4]}, fixed=fixed)
    assert list(m.status) == ["failed"] * 2
    assert all("the index det_K underflows" in r for r in m.reasons)


def test_an_index_that_overflows_fails_its_point(fourbar_urdf, fourbar_yaml):
    """A load of 1e308 N on soft springs: the deflection index overflows (it was inf with
    status ok, and the command said "no value at any point"). The point fails, naming the
    index, with no C and no index, as a point that cannot be computed."""
    stiff = cl.load_model(fourbar_urdf, fourbar_yaml)
    clm = stiff.with_springs({n: np.asarray(v) * 1e-8 for n, v in stiff.springs.items()})
    m = stiffness_map(clm, "P", sweeps={"crank": [0.3, 0.5]}, wrench=np.full(6, 1e308))
    assert list(m.status) == ["failed"] * 2
    assert all("the index deflection_translation overflows" in r for r in m.reasons)
    assert np.all(np.isnan(m.C)) and all(np.all(np.isnan(v)) for v in m.indices.values())
    fine = stiffness_map(clm, "P", sweeps={"crank": [0.3, 0.5]}, wrench=WRENCH)
    assert list(fine.status) == ["rank_deficient"] * 2  # planar: the same points, computed


def test_a_map_where_every_point_fails_writes_its_files(long_ground, tmp_path):
    clm = cl.load_model(*long_ground)
    cranks = np.array([-1.0, -1.5, -2.0])
    assert not np.any(reachable(cranks))
    m = stiffness_map(clm, "P", sweeps={"crank": cranks}, wrench=WRENCH)
    assert list(m.status) == ["unreachable"] * 3 and not np.any(m.ok)
    assert all("cannot close the loops" in r for r in m.reasons)
    assert np.all(np.isnan(m.C)) and np.all(m.data.rank == -1)
    npz, csv, png = m.save(tmp_path, index="deflection_translation")
    with np.load(npz, allow_pickle=False) as f:  # every key, no pickled object
        assert set(f.files) == {"crank", *INDICES, "C", "rank", "status", "reasons", "shape",
                                "joints", "inputs", "units"}  # fmt: skip
        np.testing.assert_array_equal(f["crank"], cranks)
        np.testing.assert_array_equal(f["inputs"], cranks[:, None])
        assert f["joints"].tolist() == ["crank"]
        for name in INDICES:
            assert np.all(np.isnan(f[name])), name
        assert np.all(np.isnan(f["C"])) and f["C"].shape == (3, 6, 6)
        np.testing.assert_array_equal(f["rank"], [-1, -1, -1])
        assert f["status"].tolist() == ["unreachable"] * 3
        assert f["reasons"].tolist() == list(m.reasons)
        np.testing.assert_array_equal(f["shape"], [3])
    lines = csv.read_text().splitlines()
    columns = [column_name(name, unit) for name, unit in INDICES.items()]
    assert lines[0] == ",".join(["crank_rad", *columns, "status", "reason"])
    assert lines[1].split(",")[: len(INDICES) + 2] == ["-1.0", *["nan"] * len(INDICES),
                                                       "unreachable"]  # fmt: skip
    assert png.stat().st_size > 5_000


def test_failed_first_points_of_chunks_and_chunk_sizes(long_ground):
    """Chunks of 1, 2 (a chunk starting on an unreachable point) and more than the map
    give the statuses of the closed form and the compliances of one serial chunk."""
    source = ModelSource(*map(str, long_ground))
    cranks = np.r_[np.linspace(-3.1, -2.96, 3), np.linspace(-2.5, -0.5, 5), np.linspace(0, 1, 6)]
    serial = stiffness_map(source, "P", sweeps={"crank": cranks}, chunk=len(cranks))
    expected = np.where(reachable(cranks), "rank_deficient", "unreachable")
    np.testing.assert_array_equal(serial.status, expected)
    assert serial.status[4] == "unreachable"  # the first point of a chunk of 2 (and of 1)
    for chunk in (1, 2, 3, 1000):
        other = stiffness_map(source, "P", sweeps={"crank": cranks}, chunk=chunk, workers=2)
        np.testing.assert_array_equal(other.status, serial.status)
        assert_close_in_norm(other.C[serial.ok].reshape(-1, 36),
                             serial.C[serial.ok].reshape(-1, 36), CHUNK_RTOL)  # fmt: skip


def test_one_point_map_equals_a_direct_query(fourbar_urdf, fourbar_yaml, tmp_path):
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    m = stiffness_map(clm, "P", sweeps={"crank": [0.7]}, wrench=WRENCH)
    q = cl.assemble(clm, [0.7], clm.reference_configuration()).q
    # the map's pose and this one, each assembled to the assembly tolerance
    assert_close_in_norm(m.C[0], cl.compliance(clm, q, "P").C, CHUNK_RTOL)
    assert [p.name for p in m.save(tmp_path)] == ["map.npz", "map.csv", "map.png"]


def test_points_outside_the_joint_limits_are_invalid(fourbar_urdf, fourbar_yaml):
    """urdf/fourbar.urdf limits the crank to [-6.3, 6.3] rad."""
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    pts = np.array([[0.5], [6.3], [7.0], [-6.4], [1e300], [0.6]])
    m = stiffness_map(clm, "P", points=pts, chunk=2)
    assert list(m.status) == ["rank_deficient", "rank_deficient"] + ["invalid"] * 3 + [
        "rank_deficient"
    ]
    assert m.reasons[2] == (
        "actuated joints outside their limits: crank = 7 (limits [-6.3, 6.3]); crank beyond "
        "2 pi: degrees? actuated values are in radians (numpy.radians)"
    )
    assert np.all(np.isnan(m.indices["min_translational"][2:5]))
    q = cl.assemble(clm, [0.6], clm.reference_configuration()).q  # after invalid points
    assert_close_in_norm(m.C[5], cl.compliance(clm, q, "P").C, CHUNK_RTOL)


def test_indices_stay_finite_up_to_the_dead_point(long_ground):
    """Near the dead point the passive closure Jacobian has a singular value ~ sqrt(d)
    (d: crank distance to it), so the softest stiffness vanishes like d: k_min / d is
    constant to first order (5 %: the next order at d = 1e-4 is ~1e-4 relative, the rest
    is the assembly tolerance at d = 1e-8)."""
    clm = cl.load_model(*long_ground)
    d = np.array([1e-4, 1e-5, 1e-6, 1e-7, 1e-8])
    m = stiffness_map(clm, "P", points=(THETA_DEAD + d)[:, None], wrench=WRENCH)
    assert np.all(m.status == "rank_deficient")  # computed (planar: rigid out of plane)
    for name in ("condition_number", "min_translational", "min_rotational",
                 "deflection_translation", "deflection_rotation"):  # fmt: skip
        assert np.all(np.isfinite(m.indices[name])), name
    ratio = m.indices["min_translational"] / d
    np.testing.assert_allclose(ratio, ratio[0], rtol=0.05)
    beyond = stiffness_map(clm, "P", points=[[THETA_DEAD - 1e-6]])
    assert beyond.status[0] == "unreachable" and np.isnan(beyond.indices["condition_number"][0])


@pytest.mark.parametrize("scale", [1e-200, 1e-30, 1e30, 1e200])
def test_deflection_is_linear_in_the_load_over_any_magnitude(fourbar_urdf, fourbar_yaml, scale):
    """|C (s w)| = s |C w| exactly in exact arithmetic; floating point keeps it to rounding
    (1e-14) unless |C w| under- or overflows on the way."""
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    kw = {"sweeps": {"crank": [0.3, 0.9]}}
    unit = stiffness_map(clm, "P", wrench=WRENCH, **kw)
    scaled = stiffness_map(clm, "P", wrench=scale * WRENCH, **kw)
    for name in ("deflection_translation", "deflection_rotation"):
        assert np.all(unit.indices[name] > 0)
        np.testing.assert_allclose(scaled.indices[name], scale * unit.indices[name], rtol=1e-14)
    zero = stiffness_map(clm, "P", wrench=np.zeros(6), **kw)
    np.testing.assert_array_equal(zero.indices["deflection_rotation"], [0.0, 0.0])


def test_heat_map_of_axes_in_any_order_is_the_sorted_one(tmp_path):
    import mechanisms as mech

    m = mech.stewart()
    lengths = m.geometry["lengths"]
    fixed = {f"leg{i}": lengths[i] for i in range(2, 6)}
    a0, a1 = lengths[0] + np.array([-0.02, 0.0, 0.02]), lengths[1] + np.array([0.0, 0.02])
    sorted_map = stiffness_map(m.clm, m.frame, sweeps={"leg0": a0, "leg1": a1}, fixed=fixed)
    mixed = stiffness_map(m.clm, m.frame, sweeps={"leg0": a0[[2, 0, 1]], "leg1": a1[::-1]},
                          fixed=fixed)  # fmt: skip
    a = matplotlib.image.imread(sorted_map.save(tmp_path / "a")[-1])
    b = matplotlib.image.imread(mixed.save(tmp_path / "b")[-1])
    np.testing.assert_array_equal(a, b)
    with pytest.raises(cl.InvalidInputError, match=r"values of swept joint 'leg1' must be dis"):
        stiffness_map(m.clm, m.frame, sweeps={"leg0": a0, "leg1": [a1[0], a1[0]]}, fixed=fixed)
    with pytest.raises(cl.InvalidInputError, match=r"sweep one or two joints"):
        stiffness_map(m.clm, m.frame, sweeps={"leg0": a0, "leg1": a1, "leg2": [lengths[2]]},
                      fixed={k: v for k, v in fixed.items() if k != "leg2"})  # fmt: skip


def test_thread_pool_serial_and_processes_agree_with_failures(long_ground):
    source = ModelSource(*map(str, long_ground))
    kw = {"sweeps": {"crank": np.linspace(-3.1, 1.0, 12)}, "wrench": WRENCH, "chunk": 3}
    serial = stiffness_map(source, "P", **kw)
    assert {"unreachable", "rank_deficient"} <= set(serial.status)
    with ThreadPoolExecutor(2) as pool:
        threads = stiffness_map(source, "P", executor=pool, **kw)
    processes = stiffness_map(source, "P", workers=2, **kw)
    for other in (threads, processes):
        np.testing.assert_array_equal(other.C, serial.C)
        assert other.reasons == serial.reasons
        for name in serial.indices:
            np.testing.assert_array_equal(other.indices[name], serial.indices[name])


def test_title_carries_units_fixed_inputs_and_a_load_of_any_magnitude():
    import mechanisms as mech

    from closedloop.analysis.maps import map_title

    m = mech.stewart()
    lengths = m.geometry["lengths"]
    fixed = {f"leg{i}": lengths[i] for i in range(1, 6)}
    wrench = np.array([1e-7, 0.0, -2.5e9, 0.0, 0.0, 3.0])
    res = stiffness_map(m.clm, m.frame, sweeps={"leg0": [lengths[0]]}, fixed=fixed, wrench=wrench)
    title = map_title(res, "det_K")
    assert title.startswith(f"det_K [N^6/rad^3] at {m.frame}\n")
    assert f"leg1 = {lengths[1]:.6g} m" in title and "leg0 =" not in title
    assert "force (1e-07, 0, -2.5e+09) N, torque (0, 0, 3) N m" in title.replace("\n", " ")


def cahyman_map(tmp_path, *argv):
    from cahyman_pin.cli import main

    assert main(["map", *argv, "--workers", "1", "--out", str(tmp_path)]) == 0
    return tmp_path


def test_cahyman_map_title_and_values_in_any_order(tmp_path):
    from cahyman_pin.cli.map import map_title
    from cahyman_pin.sweep import SweepResult

    common = ["--alpha4", "0,45", "--s4", "25", "--force", "1e-9", "0", "0",
              "--index", "deflection_translation"]  # fmt: skip
    a = cahyman_map(tmp_path / "a", "--alpha", "40,60,50", *common)
    b = cahyman_map(tmp_path / "b", "--alpha", "40,50,60", *common)
    pictures = [matplotlib.image.imread(f / "map_deflection_translation.png") for f in (a, b)]
    np.testing.assert_array_equal(*pictures)
    res = SweepResult.load_npz(a / "map.npz")
    title = map_title(res, "det_K", {"s4": (25.0, "mm")})
    expected = "s_4 = 25 mm, force (1e-09, 0, 0) N, torque (0, 0, 0) N m"
    assert title == "det_K at M, backend generic\n" + expected


def test_cahyman_alpha1_to_zero_marks_the_singular_points(tmp_path):
    """alpha_1 -> 0 folds leg 1 (the paper's singular pose): no 'ok' point carries a NaN
    index, every point without values is marked, and the last ok stiffness softens."""
    from cahyman_pin.sweep import SweepResult

    folder = cahyman_map(tmp_path, "--alpha1", "0,1e-6,1e-3,1e-2,0.1,1,5,20", "--alpha2", "60",
                         "--alpha3", "60", "--force", "1", "0", "0")  # fmt: skip
    res = SweepResult.load_npz(folder / "map.npz")
    ok = res.status == "ok"
    for name, values in res.indices.items():
        assert np.all(np.isfinite(values[ok])), name
        assert np.all(np.isnan(values[~res.ok])), name
    assert list(res.status) == ["singular"] * 2 + ["ok"] * 6
    # at alpha_1 = 0 and 1e-6 deg the assembly finds the singular configuration itself
    assert all("cannot assemble 'cahyman'" in reason and "a singular configuration" in reason
               for _, _, reason in res.failures())  # fmt: skip
    # leg 1 folds: its transmission ~ alpha_1, the softest stiffness ~ alpha_1^2 (2e-3
    # covers the next order up to 0.1 deg: 4e-4 observed)
    k = res.indices["min_translational"][2:5] / np.deg2rad([1e-3, 1e-2, 0.1]) ** 2
    np.testing.assert_allclose(k, k[0], rtol=2e-3)


@pytest.mark.parametrize("name", ["C", "file", "status"])
def test_a_joint_named_like_a_key_of_the_files(tmp_path, name):
    """The crank renamed: its values are in ``inputs`` (its name in ``joints``), the key of
    that name keeps its own meaning."""
    text = (REPO / "urdf" / "fourbar.urdf").read_text().replace('"crank"', f'"{name}"')
    (tmp_path / "fourbar.urdf").write_text(text)
    closures = (REPO / "urdf" / "fourbar.yaml").read_text().replace("crank:", f"{name}:")
    (tmp_path / "fourbar.yaml").write_text(closures.replace("[crank]", f"[{name}]"))
    clm = cl.load_model(tmp_path / "fourbar.urdf", tmp_path / "fourbar.yaml")
    assert clm.actuated == (name,)
    m = stiffness_map(clm, "P", sweeps={name: [0.3, 0.6]})
    npz = m.save(tmp_path / "out")[0]
    with np.load(npz, allow_pickle=False) as f:
        assert f["joints"].tolist() == [name]
        np.testing.assert_array_equal(f["inputs"], [[0.3], [0.6]])
        np.testing.assert_array_equal(f["C"], m.C)
        assert f["status"].tolist() == list(m.status)


def test_the_border_pass_crosses_a_long_gap_at_the_stride(long_ground, monkeypatch):
    """300 unreachable points then 20 reachable ones, chunks of 10: the pass assembles
    about one point in BORDER_STRIDE, not every failed point (a serial run's cost)."""
    from closedloop.analysis import map_engine

    clm = cl.load_model(*long_ground)
    cranks = np.r_[np.linspace(-2.5, -0.5, 300), np.linspace(0.0, 1.0, 20)]
    assert not np.any(reachable(cranks[:300])) and np.all(reachable(cranks[300:]))
    calls = []
    real = map_engine.assemble_connected

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(map_engine, "assemble_connected", counted)
    firsts = list(range(0, len(cranks), 10))
    starts = map_engine.border_starts(clm, cranks[:, None], firsts)
    assert len(calls) <= len(cranks) // map_engine.BORDER_STRIDE + len(firsts) + 2 * 16
    assert all(q is not None for q in starts)  # the first: the path's start


def test_more_workers_than_tasks_start_no_more_processes_than_tasks():
    """workers = 100000 for three tasks: one process per task at most (the pool forked
    every worker at the first submit: 619 processes, 30 GB, within 20 s of a 4-point
    map). The results are those of the serial run."""
    got = dict(run_tasks(math.sqrt, [1.0, 4.0, 9.0], workers=100_000))
    assert got == {0: 1.0, 1: 2.0, 2: 3.0}


def test_a_map_starts_on_the_mode_of_the_single_query(fourbar_urdf, fourbar_yaml):
    """The first point of a map is assembled as `closedloop stiffness --actuated` assembles
    it, on the mode of the file's configuration: at crank 1.0 the map's C was 176 % off
    the command's (the map solved it at once from the file's configuration)."""
    from closedloop.kinematics.driving import assemble_connected

    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    single = cl.compliance(clm, assemble_connected(clm, [1.0], clm.reference_configuration()).q,
                           "P").C  # fmt: skip
    for chunk in (1, 3):  # the first chunk, and the border pass of the others
        m = stiffness_map(clm, "P", sweeps={"crank": [1.0, 1.2, 1.4]}, chunk=chunk)
        assert_close_in_norm(m.C[0], single, 1e-9)


def test_a_closed_form_symmetric_but_for_rounding_is_classified_symmetric():
    """A map point's C from a closed form, symmetric but for +-1e-25 in an entry that
    vanishes: symmetric, ranked and ok (the entry-by-entry test took it for the
    non-symmetric C of a preload moment, whose principal stiffnesses are NaN)."""
    out = ChunkResult.empty(1)
    C = np.diag([1e-6, 2e-6, 3e-6, 1e-4, 2e-4, 3e-4])
    C[0, 5], C[5, 0] = 1e-25, -1e-25
    out.C[0], out.length[0] = C, 0.5
    assert classify(out).tolist() == [True]
    assert out.status[0] == OK and out.rank[0] == 6

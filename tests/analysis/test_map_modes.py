"""A map stays on the assembly mode the robot is driven along, whatever its chunks and
whatever the order in which its sweeps list their values.

The reference is independent of the map engine: the configurations of the mechanism
driven from its file's configuration through the points in ascending order of the swept
values (a boustrophedon in two dimensions) by steps of at most :data:`DRIVE_STEP`, each
assembled from the last by :func:`closedloop.assemble`, and the single query
:func:`closedloop.compliance` there.
"""

import numpy as np
import pytest
from helpers import assert_close_in_norm, driven, one_solve

import closedloop as cl
from closedloop.analysis.maps import grid_points, stiffness_map

#: Largest input step [rad] of the driven reference: 5 times below the map's continuation
#: step (closedloop.kinematics.driving.INPUT_STEP, 0.05 rad) and about 16 times below the grids'
# steps  here, so that it does not leave the assembly mode where the grid steps do not.
DRIVE_STEP = 0.01
#: A map point on the driven mode: the same configuration to the assembly tolerance
#: (closure residual ~1e-12 on links of ~0.5 m) times the sensitivity of C; 1e-12 observed.
#: A point on another mode is off by 0.8 % (five-bar) to 51 % (four-bar).
MODE_RTOL = 1e-9
#: The whole crank turn of the audit, as `--sweep crank=-3.141592653589793:
#: 3.0630528372500483:40`: a jump of 16 of its points (144 deg) lands on the other mode.
TURN = np.linspace(-np.pi, np.pi, 41)[:-1]
#: A grid of the five-bar's two inputs [rad] where every point assembles and the serial
#: run (steps of 0.15 rad) stays on the driven mode; chunks of 16, 40 and 100 switched
#: mode at their borders (69 to 93 of its 189 points).
LEG0 = np.linspace(-1.5, -0.3, 9)
LEG1 = np.linspace(-1.5, 1.5, 21)


@pytest.fixture(scope="module")
def fourbar_model(fourbar_urdf, fourbar_yaml):
    """The bundled four-bar, started by its maps from its reference configuration (its
    closure file's start:, the start of ``helpers.driven`` too)."""
    return cl.load_model(fourbar_urdf, fourbar_yaml)


@pytest.fixture(scope="module")
def turn_reference(fourbar_model):
    """(40, 6, 6) compliance at P driven through TURN in ascending order [SI]."""
    return np.array([cl.compliance(fourbar_model, q, "P").C for q in driven(fourbar_model, TURN)])


@pytest.fixture(scope="module")
def fivebar_model():
    """The bundled planar five-bar (two actuated cranks leg0, leg1)."""
    return cl.load_model(cl.data.path("fivebar5.urdf"), cl.data.path("fivebar5.yaml"))


@pytest.fixture(scope="module")
def grid_reference(fivebar_model):
    """(9, 21, 6, 6) compliance at distal1 on the LEG0 x LEG1 grid [SI] (:func:`driven_grid`)."""
    return driven_grid(fivebar_model, LEG0, LEG1)


def driven_grid(clm, LEG0, LEG1):
    """(n0, n1, 6, 6) compliance at distal1 on the LEG0 x LEG1 grid [SI], driven along the
    boustrophedon in ascending values (rows of LEG0, LEG1 back and forth)."""
    q = clm.reference_configuration()
    here = clm.actuated_values(q)
    out = np.empty((len(LEG0), len(LEG1), 6, 6))
    for i, leg0 in enumerate(LEG0):
        for j in range(len(LEG1)) if i % 2 == 0 else range(len(LEG1) - 1, -1, -1):
            target = np.array([leg0, LEG1[j]])
            steps = 1 + int(np.max(np.abs(target - here)) / DRIVE_STEP)
            for t in np.linspace(0.0, 1.0, steps + 1)[1:]:
                q = cl.assemble(clm, here + t * (target - here), q).q
            here = target
            out[i, j] = cl.compliance(clm, q, "distal1").C
    return out


def assert_on_mode(C, reference):
    """Every (6, 6) compliance of C (n, 6, 6) equals the reference's, to MODE_RTOL."""
    scale = np.max(np.abs(reference))
    off = np.max(np.abs(C - reference), axis=(1, 2)) > MODE_RTOL * scale
    assert not np.any(off), f"points on another mode: {np.flatnonzero(off).tolist()}"
    assert_close_in_norm(C.reshape(-1, 36), reference.reshape(-1, 36), MODE_RTOL)


def test_the_turn_has_a_jump_that_leaves_the_mode(fourbar_model, turn_reference):
    """The trap of the chunked maps exists: 16 points (144 deg) solved at once from the
    first point's configuration land on the other mode."""
    q0 = driven(fourbar_model, TURN[:1])[0]
    q = one_solve(fourbar_model, TURN[16:17], q0)
    C = cl.compliance(fourbar_model, q, "P").C
    assert np.linalg.norm(C - turn_reference[16]) > 0.1 * np.linalg.norm(turn_reference[16])


@pytest.mark.parametrize("chunk", [1, 8, 15, 16, 23, 31, 39, 40])
def test_a_crank_turn_stays_on_the_driven_mode_whatever_the_chunks(
    fourbar_model, turn_reference, chunk
):
    """Chunks of 15 to 31 points had points 16-31 on the other mode (C up to 51 % off):
    the border pass jumped 16 points and two half jumps confirmed it."""
    m = stiffness_map(fourbar_model, "P", sweeps={"crank": TURN}, chunk=chunk)
    assert np.all(m.ok)
    assert_on_mode(m.C, turn_reference)


@pytest.mark.parametrize("chunk", [7, 16, 40, 100, 189])
def test_a_grid_stays_on_the_driven_mode_whatever_the_chunks(fivebar_model, grid_reference, chunk):
    m = stiffness_map(fivebar_model, "distal1", sweeps={"leg0": LEG0, "leg1": LEG1},
                      chunk=chunk)  # fmt: skip
    assert np.all(m.ok)
    assert_on_mode(m.C, grid_reference.reshape(-1, 6, 6))


@pytest.mark.parametrize("chunk", [5, 16, 48])
def test_a_coarse_grid_is_driven_between_its_points(fivebar_model, chunk):
    """Grid steps of 0.24 and 0.43 rad, each solved at once, put 14 of 48 points on another
    mode than the robot driven there (C 2.9 % off), whatever the chunks: a step longer than
    INPUT_STEP is now driven in steps of at most INPUT_STEP, as --actuated reaches a pose."""
    coarse0, coarse1 = np.linspace(-1.5, -0.3, 6), np.linspace(-1.5, 1.5, 8)
    m = stiffness_map(fivebar_model, "distal1", sweeps={"leg0": coarse0, "leg1": coarse1},
                      chunk=chunk)  # fmt: skip
    assert np.all(m.ok)
    assert_on_mode(m.C, driven_grid(fivebar_model, coarse0, coarse1).reshape(-1, 6, 6))


def test_a_shuffled_sweep_gives_the_map_of_the_sorted_one(fourbar_model, turn_reference):
    """The crank's values listed shuffled: 19 of 40 points were on the other mode (the
    path walked the listed order, jumping across the turn)."""
    perm = np.random.default_rng(1).permutation(len(TURN))
    m = stiffness_map(fourbar_model, "P", sweeps={"crank": TURN[perm]})
    np.testing.assert_array_equal(m.inputs[:, 0], TURN[perm])  # results in the listed order
    assert_on_mode(m.C, turn_reference[perm])
    sorted_map = stiffness_map(fourbar_model, "P", sweeps={"crank": TURN})
    np.testing.assert_array_equal(m.C, sorted_map.C[perm])  # the same path: the same numbers
    for name, values in sorted_map.indices.items():
        np.testing.assert_array_equal(m.indices[name], values[perm], err_msg=name)


@pytest.mark.parametrize("chunk", [16, 189])
def test_a_shuffled_grid_gives_the_map_of_the_sorted_one(fivebar_model, grid_reference, chunk):
    rng = np.random.default_rng(2)
    p0, p1 = rng.permutation(len(LEG0)), rng.permutation(len(LEG1))
    m = stiffness_map(fivebar_model, "distal1", sweeps={"leg0": LEG0[p0], "leg1": LEG1[p1]},
                      chunk=chunk)  # fmt: skip
    assert m.shape == (9, 21)
    np.testing.assert_array_equal(m.inputs.reshape(9, 21, 2)[:, 0, 0], LEG0[p0])
    np.testing.assert_array_equal(m.inputs.reshape(9, 21, 2)[0, :, 1], LEG1[p1])
    assert_on_mode(m.C, grid_reference[np.ix_(p0, p1)].reshape(-1, 6, 6))


def test_the_path_walks_the_values_in_ascending_order():
    """Whatever the listed order, each step of the path goes to the next value up or down
    of one axis (in sorted order), starting from the smallest values."""
    clm = cl.load_model(cl.data.path("fivebar5.urdf"), cl.data.path("fivebar5.yaml"))
    v0, v1 = np.array([0.2, -0.4, 0.0, 0.1]), np.array([0.3, -0.2, 0.5])
    pts, shape, order = grid_points(clm, {"leg0": v0, "leg1": v1}, {})
    assert shape == (4, 3) and not order.flags.writeable
    assert sorted(order.tolist()) == list(range(12))
    walked = pts[order]
    ranks = np.column_stack([np.searchsorted(np.sort(v), walked[:, k])
                             for k, v in enumerate((v0, v1))])  # fmt: skip
    np.testing.assert_array_equal(ranks[0], [0, 0])
    np.testing.assert_array_equal(np.abs(np.diff(ranks, axis=0)).sum(axis=1), 1)


def test_a_grid_with_unreachable_points_ends_and_does_not_depend_on_the_chunks(
    fivebar_model, monkeypatch
):
    """The five-bar over +-1.5 rad in 16 x 16 points (a corner of 55 unreachable points),
    chunks of 50: the border pass walked a stretch of failed points, jumped past it, saw
    two half jumps disagree and walked it again, forever (more than 20 assemblies a point).
    It now assembles each point about once (its grid steps, 0.2 rad, exceed the
    continuation step: each is a step of the pass) and the stretches of failed points
    again: at most twice the points."""
    from closedloop.analysis import map_engine

    values = np.linspace(-1.5, 1.5, 16)
    sweeps = {"leg0": values, "leg1": values}
    pts, _, order = grid_points(fivebar_model, sweeps, {})
    calls = []
    real = map_engine.assemble_connected

    def counted(*args, **kwargs):
        calls.append(1)
        assert len(calls) <= 2 * len(pts), "the border pass does not end"
        return real(*args, **kwargs)

    monkeypatch.setattr(map_engine, "assemble_connected", counted)
    map_engine.border_starts(fivebar_model, pts[order], list(range(0, len(pts), 50)))
    monkeypatch.undo()
    serial = stiffness_map(fivebar_model, "distal1", sweeps=sweeps, chunk=len(pts))
    chunked = stiffness_map(fivebar_model, "distal1", sweeps=sweeps, chunk=50)
    assert np.count_nonzero(serial.status == "unreachable") == 55
    np.testing.assert_array_equal(chunked.status, serial.status)
    ok = serial.ok
    assert_on_mode(chunked.C[ok], serial.C[ok])

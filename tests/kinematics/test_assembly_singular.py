"""Assembly of models without loops and at a change point (closedloop.kinematics.assembly,
closedloop.kinematics.limits, the command line's ``--actuated``).

A model without loops has its actuated values set and nothing else (its passive joints,
which nothing determines, are a mechanism for the stiffness query), with no LAPACK call on
an empty matrix. At the parallelogram four-bar's change point the assembly is a
SingularConfigurationError from every start, not a neighbour admitted by the tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
from mechanisms import fourbar_chain

import closedloop as cl
from closedloop.cli.app import main
from closedloop.exceptions import EXIT_FAILED, SingularConfigurationError
from closedloop.kinematics.driving import assemble_connected, assemble_within_limits

#: The bundled four-bar's closure file without its loop, the crank actuated and sprung.
NO_LOOP = "closed_loop: []\nname_mot: [crank]\nsprings:\n  crank: 50.0\n  crank_axial: 1.0e+5\n"
#: C of a 1R + 1P chain computed two ways (the library's path, the closed form): rounding.
RTOL_C = 1e-12
#: Parallelogram pose a regular distance d >= 1e-6 rad from the change point against its
#: closed form [rad]: the closure residual after the assembly (about 1e-17 m per L) over
#: the smallest scaled singular value of the passive Jacobian there (about 0.3 d = 3e-7)
#: is 3e-11; rounding of the angles, 1e-16.
ATOL_NEAR = 1e-9
#: The change point of the parallelogram four-bar: crank along +x, all bars on the x axis.
CHANGE_POINT = np.pi / 2


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


def no_loop_fourbar(tmp_path, fourbar_urdf, closures: str = NO_LOOP) -> cl.ClosedLoopModel:
    return cl.load_model(fourbar_urdf, write(tmp_path, "c.yaml", closures), geometry=False)


def cli(capfd, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capfd.readouterr()
    return code, out, err


# ---------------------------------------------------------------- no loop
@pytest.mark.parametrize("solve", [cl.assemble, assemble_within_limits, assemble_connected])
def test_a_model_without_loops_has_its_actuated_values_set(capfd, tmp_path, fourbar_urdf, solve):
    """The closure file's ``closed_loop: []``: the crank is set, the passive coupler,
    rocker and rocker_axial keep their start values (nothing determines them). It was a
    LinAlgError from LAPACK's dgelsy on a matrix of no rows, with LAPACK's complaint
    printed."""
    clm = no_loop_fourbar(tmp_path, fourbar_urdf)
    q0 = np.array([-0.4, 0.002, 0.7, -0.2, 0.001])
    a = solve(clm, [0.3], q0)
    np.testing.assert_array_equal(a.q, [0.3, 0.002, 0.7, -0.2, 0.001])
    assert a.residual == 0.0
    assert capfd.readouterr() == ("", "")


def test_a_serial_chain_without_loops_has_the_compliance_of_its_springs(tmp_path, fourbar_urdf):
    """At the crank's end, moved by the crank (50 N m/rad) and its axial joint (1e5 N/m)
    only: C = j_1 j_1^T / 50 + j_2 j_2^T / 1e5 in world axes, j_1 the twist of a turn
    about y through the origin at the end 0.1 (sin t, 0, cos t) m, j_2 the translation
    along the crank; rank 2 (the passive joints elsewhere do not move it)."""
    clm = no_loop_fourbar(tmp_path, fourbar_urdf)
    t = 0.3
    res = cl.compliance(clm, cl.assemble(clm, [t]).q, "crank_end")
    j1 = np.array([0.1 * np.cos(t), 0.0, -0.1 * np.sin(t), 0.0, 1.0, 0.0])
    j2 = np.array([np.sin(t), 0.0, np.cos(t), 0.0, 0.0, 0.0])
    C = np.outer(j1, j1) / 50.0 + np.outer(j2, j2) / 1e5
    np.testing.assert_allclose(res.C, C, rtol=0, atol=RTOL_C * np.abs(C).max())
    assert res.rank == 2


def test_the_command_line_without_loops_is_a_mechanism(capfd, tmp_path, fourbar_urdf):
    """``--actuated`` on the four-bar without its loop, the coupler free: one line, exit 3
    (it was LAPACK's "On entry to DGELSY parameter number 5 had an illegal value", then
    "numerical failure: dgelsy failed (info=-5)")."""
    closures = write(tmp_path, "c.yaml", "closed_loop: []\nname_mot: [crank]\n")
    code, out, err = cli(capfd, "stiffness", str(fourbar_urdf), "--closures", str(closures),
                         "--frame", "P", "--actuated", "0.3")  # fmt: skip
    assert (code, out) == (EXIT_FAILED, "")
    assert err.startswith("closedloop: error: 'fourbar' is still a mechanism at frame 'P'")
    assert err.count("\n") == 1 and "'coupler'" in err


def test_an_mjcf_whose_only_connect_is_inactive_is_a_mechanism(capfd, tmp_path, fourbar_mjcf):
    connect = '<connect name="closedloop1"'
    text = fourbar_mjcf.read_text().replace(
        connect, connect.replace(" name", ' active="false" name')
    )
    model = write(tmp_path, "fourbar.xml", text)
    assert len(cl.load_model(model, geometry=False).closures) == 0
    code, out, err = cli(capfd, "stiffness", str(model), "--frame", "P", "--actuated", "0.3")
    assert (code, out) == (EXIT_FAILED, "")
    assert err.startswith("closedloop: error: 'fourbar' is still a mechanism at frame 'P'")
    assert err.count("\n") == 1


# ---------------------------------------------------------------- change point
@pytest.fixture(scope="module")
def parallelogram_urdf(tmp_path_factory, fourbar_urdf):
    """The bundled four-bar with its rocker 0.1 m (not 0.15): crank 0.1 m, coupler 0.3 m,
    rocker 0.1 m, pivots 0.3 m apart, a parallelogram. At crank t its branch is
    (t, 0, -t, t, 0) (the coupler stays along x); at t = pi/2 every bar is on the x axis,
    where it meets the crossed branch."""
    text = fourbar_urdf.read_text()
    rocker = '<origin xyz="0 0 0.15"/><axis xyz="0 0 1"/>'
    assert text.count(rocker) == 1
    return write(
        tmp_path_factory.mktemp("para"),
        "para.urdf",
        text.replace(rocker, rocker.replace("0.15", "0.1")),
    )


@pytest.fixture(scope="module")
def parallelogram(parallelogram_urdf, fourbar_yaml):
    return cl.load_model(parallelogram_urdf, fourbar_yaml, geometry=False)


def branch(t: float) -> np.ndarray:
    """(crank, crank_axial, coupler, rocker, rocker_axial) of the parallelogram branch."""
    return np.array([t, 0.0, -t, t, 0.0])


STARTS = {
    "neutral": None,
    "parallelogram branch": branch(1.2),
    "near, off the loop": np.array([1.6, 0.0, 0.1, 1.6, 0.0]),
    "far, off the loop": np.array([0.0, 0.0, 3.0, -2.0, 0.0]),
}


@pytest.mark.parametrize("start", STARTS)
@pytest.mark.parametrize("solve", [cl.assemble, assemble_connected])
def test_the_change_point_is_a_singular_configuration_from_every_start(parallelogram, solve,
                                                                       start):  # fmt: skip
    """The tolerance (1e-12 L on a residual quadratic in the distance) admitted poses up
    to 2.6e-6 rad from the collinear one, a different one from each start, each with its
    own compliance (1e8 m/N, or a MechanismError)."""
    with pytest.raises(SingularConfigurationError) as info:
        solve(parallelogram, [CHANGE_POINT], STARTS[start])
    message = str(info.value)
    assert message.startswith("cannot assemble 'fourbar' with actuated {'crank': 1.57079632679")
    assert "a singular configuration (the closures lose rank 1 on the passive joints" in message


@pytest.mark.parametrize("d", [1e-2, -1e-2, 1e-4, -1e-4, 1e-6, -1e-6])
def test_poses_near_the_change_point_are_assembled(parallelogram, d):
    """A regular pose d rad from the change point, driven from the branch 0.3 rad away,
    is the branch's closed form."""
    t = CHANGE_POINT + d
    a = assemble_connected(parallelogram, [t], branch(t - 0.3 * np.sign(d)))
    np.testing.assert_allclose(a.q, branch(t), rtol=0, atol=ATOL_NEAR)


def test_the_chain_s_change_point_is_singular():
    """The parallelogram of fourbar_chain (crank 0.3 m, coupler 0.2 m) at crank 0."""
    clm, _, _ = fourbar_chain([0.0])
    with pytest.raises(SingularConfigurationError, match=r"'crank0': 0\.0\}: a singular"):
        cl.assemble(clm, [0.0], np.array([0.3, -0.3, 0.3]))


def test_the_command_line_at_the_change_point_exits_3(capfd, parallelogram_urdf, fourbar_yaml):
    base = ["stiffness", str(parallelogram_urdf), "--closures", str(fourbar_yaml), "--frame", "P"]
    code, out, err = cli(capfd, *base, "--actuated", repr(CHANGE_POINT))
    assert (code, out) == (EXIT_FAILED, "")
    assert err.startswith("closedloop: error: cannot assemble 'fourbar' with actuated")
    assert "a singular configuration" in err and err.count("\n") == 1
    code, out, err = cli(capfd, *base, "--actuated", "1.5", "--json")
    assert code == 1 and err == ""  # 0.07 rad away: planar, C of rank 3 (K does not exist)


def test_a_start_at_the_change_point_checked_as_it_is(parallelogram):
    """max_iter = 0 moves nothing: the collinear start itself is the singular one."""
    with pytest.raises(SingularConfigurationError, match="a singular configuration"):
        cl.assemble(parallelogram, None, branch(CHANGE_POINT), max_iter=0)

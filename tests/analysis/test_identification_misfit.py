"""The diagnosis of a misfit (closedloop.analysis.misfit): the measurements that misfit
most, and the `actuated:` measurements assembled on another assembly mode than their
stated q or their neighbours; named in the warning, the Fit and the command line's line."""

import warnings

import numpy as np
import pytest
import scipy.stats
from helpers import driven, one_solve

import closedloop as cl
from closedloop.analysis.identification import Measurement, identify
from closedloop.analysis.misfit import other_modes, worst_measurements
from closedloop.cli.app import main
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT, ModelMisfitWarning
from closedloop.kinematics.driving import assemble_connected

TRUE = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
#: Crank angles [rad] where the four-bar driven from its start and one solve from the
#: neutral configuration (helpers.one_solve) are on two assembly modes (beyond 0.9 rad;
#: checked below).
CRANKS = (1.0, 1.1, 1.2, 1.3, 1.4)
#: The measurements (by crank) taken with the robot on the other assembly mode.
OTHER = (1, 3)
#: Wrenches per crank angle.
N_WRENCH = 2
SD = 1e-9


def _data(clm, other=OTHER, stated_q=True, seed=3):
    """Measurements at CRANKS, the twists of the driven mode except at the cranks
    ``other`` (those of the other mode), with the actuated values and (``stated_q``) the
    q the robot was in; and the indices of the measurements on the other mode."""
    on_path = driven(clm, CRANKS)
    single = [one_solve(clm, [a]) for a in CRANKS]
    assert min(np.abs(a - b).max() for a, b in zip(on_path, single, strict=True)) > 1.0
    rng, data, wrong = np.random.default_rng(seed), [], []
    for i, crank in enumerate(CRANKS):
        q = single[i] if i in other else on_path[i]
        C = cl.compliance(clm, q, "P").C
        for w in 10.0 * rng.normal(size=(N_WRENCH, 6)):
            if i in other:
                wrong.append(len(data))
            twist = C @ w + SD * rng.normal(size=6)
            data.append(Measurement.of(actuated=[crank], q=q if stated_q else None, wrench=w,
                                       twist=twist, sd=SD))  # fmt: skip
    return data, wrong


@pytest.fixture(scope="module")
def fourbar_true():
    return cl.load_model(cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml")).with_springs(
        TRUE
    )


def test_measurements_on_another_mode_than_their_stated_q_are_named(fourbar_true):
    data, wrong = _data(fourbar_true)
    with pytest.warns(ModelMisfitWarning) as caught:
        fit = identify(fourbar_true, data, "P", ["crank"])
    assert not fit.consistent
    assert fit.other_mode == dict.fromkeys(wrong, "stated q")
    assert fit.worst[0] in wrong  # the worst is one of them
    message = str(caught[0].message)
    assert "the measurements that misfit most: " in message
    assert f"{fit.worst[0]} (actuated [{data[fit.worst[0]].actuated[0]:.6g}], RMS" in message
    named = ", ".join(f"{i} (actuated [{CRANKS[i // N_WRENCH]:.6g}])" for i in wrong)
    assert f"measurement(s) {named} assembled on another assembly mode than their stated q" in (
        message
    )
    np.testing.assert_allclose(fit.measurement_rms, np.sqrt(np.mean(fit.residuals**2, axis=1)),
                               rtol=1e-15)  # fmt: skip
    assert fit.to_dict()["other_mode"] == {str(i): "stated q" for i in wrong}


def test_a_clean_data_set_names_none(fourbar_true):
    data, _ = _data(fourbar_true, other=())
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelMisfitWarning)
        fit = identify(fourbar_true, data, "P", ["crank"])
    assert fit.consistent and fit.worst == () and fit.other_mode == {}
    start = fourbar_true.reference_configuration()
    configs = [assemble_connected(fourbar_true, m.actuated, start).q for m in data]
    assert other_modes(fourbar_true, data, configs) == {}  # the checks themselves: none


def test_measurements_assembled_off_their_neighbours_mode_are_named(fourbar_true):
    """Actuated values alone, assembled on two modes (as a fall-back to a single solve
    would): the ones apart from their neighbours are named, whatever their twists."""
    data, wrong = _data(fourbar_true, stated_q=False)
    on_path = driven(fourbar_true, CRANKS)
    configs = [one_solve(fourbar_true, m.actuated) if i in wrong
               else on_path[CRANKS.index(m.actuated[0])] for i, m in enumerate(data)]  # fmt: skip
    assert other_modes(fourbar_true, data, configs) == dict.fromkeys(wrong, "neighbours")


def test_worst_measurements_follow_the_bonferroni_chi_square_quantile():
    """Sums of squares of 6 components against scipy.stats' quantile at 1e-6 / n."""
    n, significance = 10, 1e-6
    limit = scipy.stats.chi2.isf(significance / n, 6)
    r = np.zeros((n, 6))
    r[3, 0] = np.sqrt(limit * 1.01)  # just above
    r[7, :] = np.sqrt(limit * 0.99 / 6)  # just below
    r[5, 2] = np.sqrt(limit * 4.0)  # the worst
    one = scipy.stats.chi2.isf(significance / n, 1)
    r[8, 0] = np.sqrt(1.5 * one)  # above the limit of one component, below that of six
    assert 1.5 * one < limit
    sd = np.ones((n, 6))
    assert worst_measurements(r, sd, significance) == (5, 3)
    sd[8, 1:] = np.inf  # one measured component: its limit
    assert worst_measurements(r, sd, significance) == (5, 3, 8)


def _csv(path, data):
    lines = ["frame,q_0,q_1,q_2,q_3,q_4,actuated_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd"]
    lines += [",".join(["P", *(repr(float(x)) for x in (*m.q, *m.actuated, *m.wrench, *m.twist,
                                                          m.sd[0]))]) for m in data]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_the_command_names_the_measurements_on_another_mode(tmp_path, fourbar_true, capsys):
    data, wrong = _data(fourbar_true)
    assert data[0].q.size == 5
    code = main(["identify", "fourbar", "--measurements", _csv(tmp_path / "m.csv", data),
                 "--fit", "crank"])  # fmt: skip
    _, err = capsys.readouterr()
    assert code == EXIT_RANK_DEFICIENT and err.count("\n") == 1, err
    assert "another assembly mode than their stated q" in err
    assert all(f"{i} (actuated [" in err for i in wrong)


def test_no_limits_takes_measurements_outside_the_limits(tmp_path, fourbar_true, capsys):
    """A crank at 7 rad (its limit 6.3): refused, exit 2, unless --no-limits (a fit)."""
    start = fourbar_true.reference_configuration()
    q = assemble_connected(fourbar_true, [7.0], start, check_limits=False).q
    C = cl.compliance(fourbar_true, q, "P", check_limits=False).C
    w = np.array([[3.0, 0.0, -2.0, 0.0, 0.5, 0.0], [0.0, 1.0, 2.0, 0.3, 0.0, 0.0]])
    data = [Measurement.of(actuated=[7.0], wrench=x, twist=C @ x, sd=SD) for x in w]
    with pytest.raises(cl.InvalidInputError, match=r"measurement 0: .*outside their limits"):
        identify(fourbar_true, data, "P", ["crank"])
    fit = identify(fourbar_true, data, "P", ["crank"], check_limits=False)
    np.testing.assert_allclose(fit.estimates["crank"], TRUE["crank"], rtol=1e-6)
    lines = ["frame,actuated_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd"]
    lines += [",".join(["P", *(repr(float(v)) for v in (7.0, *m.wrench, *m.twist, SD))])
              for m in data]  # fmt: skip
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    args = ["identify", "fourbar", "--measurements", str(tmp_path / "m.csv"), "--fit", "crank"]
    assert main(args) == 2
    assert "outside their limits" in capsys.readouterr().err
    assert main([*args, "--no-limits"]) == EXIT_OK
    assert "crank = 50" in capsys.readouterr().out

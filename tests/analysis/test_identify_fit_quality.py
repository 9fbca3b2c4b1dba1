"""Fit quality of the identification: a model that does not fit its data is flagged (the
chi-square test of closedloop.analysis.identification), in the API and on the command line; the
units of the estimates and the messages of bad measurements."""

import warnings

import mechanisms as mech
import numpy as np
import pytest
import scipy.stats
from helpers import driven, one_solve

import closedloop as cl
from closedloop.analysis.identification import FIT_SIGNIFICANCE, Measurement, identify
from closedloop.cli.app import main
from closedloop.exceptions import EXIT_RANK_DEFICIENT, ModelMisfitWarning

FOURBAR_TRUE = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
#: Two assembly modes of the four-bar: below 0.8 rad both assemblies agree, beyond it one
#: solve from the neutral configuration (helpers.one_solve, cl.assemble before #45) lands
#: on the other mode than the one a robot driven from its start is on (that `actuated:`
#: gives).
CRANKS = (0.2, 0.6, 1.0, 1.4)
#: The limit of the test is a chi-square quantile written two ways (scipy.special's
#: inverse survival function, scipy.stats'): they agree to rounding of the inversion.
RTOL_QUANTILE = 1e-9
#: Longest error message for a bad `measurements` argument (one line, not an array dump).
LONGEST_MESSAGE = 300


def _measured(clm, configs, rng, sd, n_wrench=3, scale=10.0):
    """(actuated value, wrench, twist) of ``clm`` at each configuration, with Gaussian noise
    of ``sd`` (0: exact)."""
    rows = []
    for q in configs:
        C = cl.compliance(clm, q, "P").C
        for w in scale * rng.normal(size=(n_wrench, 6)):
            rows.append((q, w, C @ w + (sd * rng.normal(size=6) if sd else 0.0)))
    return rows


def _fourbar(fourbar_urdf, fourbar_yaml):
    return cl.load_model(fourbar_urdf, fourbar_yaml).with_springs(FOURBAR_TRUE)


def test_data_of_the_other_assembly_mode_are_flagged(fourbar_urdf, fourbar_yaml):
    """The audit's case: twists computed on one solve's configurations (the other mode
    beyond 0.8 rad), stated by their actuated values (the driven mode): one spring cannot
    explain them. Before, the fit said nothing (RMS 4e6, exit 0)."""
    clm = _fourbar(fourbar_urdf, fourbar_yaml)
    configs = [one_solve(clm, [a]) for a in CRANKS]
    on_path = driven(clm, CRANKS)
    assert np.abs(configs[-1] - on_path[-1]).max() > 1.0  # two modes, on purpose
    rows = _measured(clm, configs, np.random.default_rng(5), sd=0.0)
    data = [Measurement.of(actuated=[q[0]], wrench=w, twist=d, sd=1e-9) for q, w, d in rows]
    with pytest.warns(ModelMisfitWarning, match=r"the model does not fit the data: weighted "
                      r"residual RMS .* the standard errors assume a fit"):  # fmt: skip
        fit = identify(clm, data, "P", ["crank"])
    assert not fit.consistent and fit.residual_rms > 1e3 * fit.rms_limit
    assert fit.to_dict()["consistent"] is False


def test_the_limit_is_the_chi_square_quantile_of_the_noisy_components(fourbar_urdf,
                                                                      fourbar_yaml):  # fmt: skip
    """Consistent noisy data pass, with the limit of a chi-square of (in-plane components
    - parameters) degrees of freedom: the planar four-bar's out-of-plane twist components
    are zero in the data and in the model, whatever the springs, and carry no noise."""
    clm = _fourbar(fourbar_urdf, fourbar_yaml)
    rng = np.random.default_rng(7)
    rows = _measured(clm, driven(clm, CRANKS), rng, sd=1e-7)
    for row in rows:  # the noise of a planar measurement: in its plane only (dx, dz, ry)
        row[2][[1, 3, 5]] = 0.0
    data = [Measurement.of(q=q, wrench=w, twist=d, sd=1e-7) for q, w, d in rows]
    start = clm.with_springs({"crank": 20.0, "crank_axial": 4e5, "rocker_axial": 5e4})
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelMisfitWarning)
        fit = identify(start, data, "P", list(FOURBAR_TRUE))
    n, p = 6 * len(data), len(FOURBAR_TRUE)
    dof = 3 * len(data) - p  # in-plane components less the parameters
    expected = np.sqrt(scipy.stats.chi2.isf(FIT_SIGNIFICANCE, dof) / n)
    np.testing.assert_allclose(fit.rms_limit, expected, rtol=RTOL_QUANTILE)
    assert fit.consistent and fit.residual_rms < fit.rms_limit


@pytest.mark.parametrize("understated", [1.0, 3.0])
def test_standard_deviations_stated_too_small_are_flagged(understated):
    """UR5 data with noise of sd 1e-6 fit when stated at 1e-6 (an RMS near 1), and are
    flagged when stated three times too small (an RMS near 3, far above the limit of 108
    components, ~1.4): the standard errors would be three times too small."""
    joints = cl.load_model(cl.data.robot_file("ur5")).actuated
    truth = cl.load_model(cl.data.robot_file("ur5"), springs=dict(zip(joints, (3e4, 2.5e4,
                          1.5e4, 4e3, 3e3, 2e3), strict=True)))  # fmt: skip
    rng = np.random.default_rng(11)
    data = []
    for q in rng.uniform(-2.0, 2.0, (6, 6)):
        C = cl.compliance(truth, q, "tool0").C
        for w in 100.0 * rng.normal(size=(3, 6)):
            twist = C @ w + 1e-6 * rng.normal(size=6)
            data.append(Measurement.of(q=q, wrench=w, twist=twist, sd=1e-6 / understated))
    start = cl.load_model(cl.data.robot_file("ur5"), joint_stiffness=1e4)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = identify(start, data, "tool0", list(joints))
    misfit = [w for w in caught if issubclass(w.category, ModelMisfitWarning)]
    assert fit.consistent == (understated == 1.0) and len(misfit) == (understated != 1.0)
    assert 0.7 * understated < fit.residual_rms < 1.3 * understated  # noise of its sd


def test_the_command_says_the_model_does_not_fit_and_exits_1(tmp_path, capsys):
    """The audit's file: actuated values of the driven mode, twists of the other one."""
    clm = cl.load_model(cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml"))
    rows = _measured(clm, [one_solve(clm, [a]) for a in CRANKS],
                     np.random.default_rng(5), sd=0.0, n_wrench=2)  # fmt: skip
    lines = ["frame,actuated_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd"]
    lines += [",".join(["P", *(repr(float(x)) for x in (q[0], *w, *d, 1e-9))]) for q, w, d in rows]
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    for json in ([], ["--json"]):
        code = main(["identify", "fourbar", "--measurements", str(tmp_path / "m.csv"),
                     "--fit", "crank", *json])  # fmt: skip
        out, err = capsys.readouterr()
        assert code == EXIT_RANK_DEFICIENT, err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert err.startswith("closedloop: warning: the model does not fit the data")
        assert "the standard errors assume a fit" in err
        if json:
            assert '"consistent": false' in out
        else:
            assert "crank = " in out and out.rstrip().endswith("[N m/rad]")


def test_each_estimate_is_printed_with_its_unit(tmp_path, fourbar_urdf, fourbar_yaml, capsys):
    clm = _fourbar(fourbar_urdf, fourbar_yaml)
    rows = _measured(clm, driven(clm, (0.3, 0.8, 1.3)), np.random.default_rng(2), sd=0.0)
    lines = ["frame: P", "measurements:"]
    for q, w, d in rows:
        lines += [f"  - q: {q.tolist()}", f"    wrench: {w.tolist()}",
                  f"    twist: {d.tolist()}", "    sd: 1e-9"]  # fmt: skip
    (tmp_path / "m.yaml").write_text("\n".join(lines) + "\n")
    code = main(["identify", str(fourbar_urdf), "--closures", str(fourbar_yaml),
                 "--measurements", str(tmp_path / "m.yaml"), "--fit", *FOURBAR_TRUE])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    units = {line.split()[0]: line.split("[")[-1] for line in out.splitlines()[1:]}
    assert units == {"crank": "N m/rad]", "crank_axial": "N/m]", "rocker_axial": "N/m]"}


def test_the_units_of_a_fit_name_a_block_factor():
    clm, q, _ = mech.serial_with_block()
    rng = np.random.default_rng(3)
    data = []
    for w in 10.0 * rng.normal(size=(4, 6)):
        d = cl.compliance(clm, q, "tool").C @ w
        data.append(Measurement.of(q=q, wrench=w, twist=d, sd=1e-3 * np.abs(d).max()))
    fit = identify(clm, data, "tool", ["base", "flex"])
    assert fit.units == {"base": "N m/rad", "flex": "1"}


def test_an_array_of_measurements_is_refused_in_one_short_line(fourbar):
    clm, q = fourbar
    one = Measurement.of(q=q, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    with pytest.raises(cl.InvalidInputError, match=r"list of Measurement, got array\(") as e:
        identify(clm, np.array([one] * 200, dtype=object), "P", ["crank"])
    message = str(e.value)
    assert len(message) < LONGEST_MESSAGE and "ndarray of shape (200,)" in message, message


@pytest.mark.parametrize(
    ("twist", "wrench", "sd", "culprit"),
    [(1e300, 1.0, 1e-6, "the measured twist out of scale for its sd"),
     (1e-4, 1e300, 1e-6, "the wrench (or a start spring) out of scale for the sd"),
     (1e-4, 1.0, 1e-300, "an sd out of scale for the twist and the wrench")],
)  # fmt: skip
def test_a_measurement_out_of_scale_names_the_culprit(fourbar, twist, wrench, sd, culprit):
    """Before, every case said "a wrench or an sd out of scale", a twist of 1e300 too."""
    clm, q = fourbar
    good = Measurement.of(q=q, wrench=np.ones(6), twist=np.full(6, 1e-4), sd=1e-6)
    bad = Measurement.of(q=q, wrench=np.full(6, wrench), twist=np.full(6, twist), sd=sd)
    with pytest.raises(cl.InvalidInputError, match=r"^measurement 1: its weighted deflection") as e:
        identify(clm, [good, bad], "P", ["crank"])
    message = str(e.value)
    assert culprit in message and f"twist [{twist:g}" in message, message

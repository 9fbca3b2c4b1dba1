"""Elastostatic identification: synthetic data from known springs, derivatives, bad input."""

import mechanisms as mech
import numpy as np
import pytest
from helpers import assert_close_in_norm

import closedloop as cl
from closedloop.identification import (
    Measurement,
    compliance_derivative,
    identify,
    read_measurements,
)
from closedloop.io import load_urdf, robot_data_dir

#: Central differences of C in k (relative step 1e-4): truncation ~1e-8, rounding ~1e-12.
RTOL_DERIVATIVE = 1e-6
#: Noise-free data: the fit stops at the optimiser's tolerances, far below 1e-8.
RTOL_EXACT_FIT = 1e-8
#: Noisy data: |estimate - truth| within this many standard errors (a 4-sigma event has
#: probability 6e-5 per parameter; the seeds are fixed).
SIGMAS = 4.0
UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
              "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")  # fmt: skip
UR5_TRUE = dict(zip(UR5_JOINTS, (3e4, 2.5e4, 1.5e4, 4e3, 3e3, 2e3), strict=True))


def _ur5(springs):
    return load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", springs=springs)


def _synthetic(clm, frame, configs, rng, sd, n_wrench=3, scale=100.0):
    out = []
    for q in configs:
        C = cl.compliance(clm, q, frame).C
        for w in scale * rng.normal(size=(n_wrench, 6)):
            d = C @ w + (sd * rng.normal(size=6) if sd else 0.0)
            out.append(Measurement.of(q=q, wrench=w, twist=d, sd=sd or 1e-9))
    return out


def _ur5_configs(rng, n=6):
    return [rng.uniform(-2.0, 2.0, 6) for _ in range(n)]


def test_derivative_of_the_compliance_equals_central_differences(fourbar):
    clm, q = fourbar
    base = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    res = cl.compliance(clm.with_springs(base), q, "P")
    for name, k in base.items():
        h = 1e-4 * k
        plus = cl.compliance(clm.with_springs({**base, name: k + h}), q, "P").C
        minus = cl.compliance(clm.with_springs({**base, name: k - h}), q, "P").C
        rows = np.arange(clm.model.nv)[clm.joint_v_slice(name)]
        assert_close_in_norm(compliance_derivative(res, rows), (plus - minus) / (2 * h),
                             RTOL_DERIVATIVE)  # fmt: skip


def test_noise_free_data_are_fitted_exactly(fourbar):
    clm, _ = fourbar
    rng = np.random.default_rng(1)
    configs = [cl.assemble(clm, actuated=[a]).q for a in (0.2, 0.6, 1.0, 1.4)]
    data = _synthetic(clm, "P", configs, rng, sd=0.0)
    start = clm.with_springs({"crank": 20.0, "crank_axial": 4e5, "rocker_axial": 5e4})
    fit = identify(start, data, "P", ["crank", "crank_axial", "rocker_axial"])
    truth = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    for name, value in truth.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT)
    assert fit.success and fit.unidentifiable == ()


@pytest.mark.parametrize("seed", [0, 1])
def test_ur5_noisy_data_recover_the_springs_within_their_errors(seed):
    rng = np.random.default_rng(seed)
    truth = _ur5(UR5_TRUE)
    data = _synthetic(truth, "tool0", _ur5_configs(rng), rng, sd=1e-6)
    start = _ur5(dict.fromkeys(UR5_JOINTS, 1e4))
    fit = identify(start, data, "tool0", list(UR5_JOINTS))
    assert fit.unidentifiable == () and fit.n_measurements == 18
    for name in UR5_JOINTS:
        error = abs(fit.estimates[name] - UR5_TRUE[name])
        assert error <= SIGMAS * fit.std_errors[name], (name, error, fit.std_errors[name])
        assert fit.std_errors[name] < 0.05 * UR5_TRUE[name]  # the data do carry information
    assert 0.5 < fit.residual_rms < 1.5  # consistent with the stated noise
    np.testing.assert_allclose(np.diag(fit.correlations), 1.0, rtol=1e-12)


def test_springs_that_do_not_act_on_the_measured_frame_are_named():
    # measured at wrist_1_link: the wrist_2 and wrist_3 springs cannot be seen
    rng = np.random.default_rng(3)
    truth = _ur5(UR5_TRUE)
    data = _synthetic(truth, "wrist_1_link", _ur5_configs(rng), rng, sd=1e-6)
    fitted = ["shoulder_lift_joint", "elbow_joint", "wrist_2_joint", "wrist_3_joint"]
    fit = identify(_ur5(UR5_TRUE), data, "wrist_1_link", fitted)
    assert fit.unidentifiable == ("wrist_2_joint", "wrist_3_joint")
    assert fit.estimates["wrist_2_joint"] is None and fit.std_errors["wrist_3_joint"] is None
    assert fit.identified == ("shoulder_lift_joint", "elbow_joint")


def test_groups_tie_springs_to_one_value():
    rng = np.random.default_rng(4)
    springs = {**UR5_TRUE, "wrist_1_joint": 5e3, "wrist_2_joint": 5e3, "wrist_3_joint": 5e3}
    data = _synthetic(_ur5(springs), "tool0", _ur5_configs(rng), rng, sd=0.0)
    wrists = ("wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
    fit = identify(_ur5(dict.fromkeys(UR5_JOINTS, 1e4)), data, "tool0",
                   [*UR5_JOINTS[:3], wrists])  # fmt: skip
    np.testing.assert_allclose(fit.estimates["+".join(wrists)], 5e3, rtol=RTOL_EXACT_FIT)


def test_measurement_file(tmp_path, fourbar):
    clm, q = fourbar
    C = cl.compliance(clm, q, "P").C
    w = np.array([3.0, 0.0, -2.0, 0.0, 0.5, 0.0])
    path = tmp_path / "m.yaml"
    path.write_text(
        "frame: P\nmeasurements:\n"
        f"  - q: {q.tolist()}\n    wrench: {w.tolist()}\n    twist: {(C @ w).tolist()}\n"
        "    sd: 1e-6\n"
    )
    frame, data = read_measurements(path)
    assert frame == "P" and len(data) == 1
    np.testing.assert_array_equal(data[0].sd, np.full(6, 1e-6))
    np.testing.assert_array_equal(data[0].twist, C @ w)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"q": [0.0], "wrench": np.ones(5), "twist": np.zeros(6), "sd": 1.0}, r"wrench must be 6"),
        ({"q": [0.0], "wrench": np.ones(6), "twist": [0, 0, np.nan, 0, 0, 0], "sd": 1.0},
         r"measured twist must be 6 finite values"),
        ({"q": [0.0], "wrench": np.ones(6), "twist": np.zeros(6), "sd": 0.0},
         r"sd must be one or 6 finite values > 0"),
        ({"wrench": np.ones(6), "twist": np.zeros(6), "sd": 1.0}, r"exactly one of q and actuated"),
    ],
)  # fmt: skip
def test_bad_measurements_are_refused(kwargs, match):
    with pytest.raises(cl.InvalidInputError, match=match):
        Measurement.of(**kwargs)


def test_bad_fits_are_refused(fourbar):
    clm, q = fourbar
    one = [Measurement.of(q=q, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)]
    with pytest.raises(cl.NameNotFoundError, match=r"unknown joint 'nope'"):
        identify(clm, one, "P", ["nope"])
    with pytest.raises(cl.InvalidInputError, match=r"nothing to fit"):
        identify(clm, one, "P", [])
    stewart = mech.stewart()
    legs = [f"leg{i}" for i in range(6)]
    one_leg = [Measurement.of(q=stewart.q, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)]
    with pytest.raises(cl.InvalidInputError, match=r"6 measured components for 7 parameters"):
        identify(stewart.clm, one_leg, stewart.frame, [*legs, "leg0_ux"])
    with pytest.raises(cl.InvalidInputError, match=r"'coupler' needs a start value > 0"):
        identify(clm, one, "P", ["coupler"])
    with pytest.raises(cl.InvalidInputError, match=r"appears in two fitted parameters"):
        identify(clm, one, "P", ["crank", ("crank", "rocker_axial")])

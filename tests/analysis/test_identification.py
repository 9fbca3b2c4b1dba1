"""Elastostatic identification: synthetic data from known springs, derivatives, bad input."""

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm, driven, one_solve

import closedloop as cl
from closedloop.analysis.identification import Measurement, compliance_derivative, identify
from closedloop.analysis.measurements import read_measurements
from closedloop.io.loader import load_urdf, robot_data_dir

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


def _synthetic(clm, frame, configs, rng, sd, n_wrench=3, scale=100.0, exact_sd=1e-9):
    """Measurements of ``clm``; noise-free (``sd`` 0) data are stated at ``exact_sd``."""
    out = []
    for q in configs:
        C = cl.compliance(clm, q, frame).C
        for w in scale * rng.normal(size=(n_wrench, 6)):
            d = C @ w + (sd * rng.normal(size=6) if sd else 0.0)
            out.append(Measurement.of(q=q, wrench=w, twist=d, sd=sd or exact_sd))
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
         r"measured twist must be 6 values"),
        ({"q": [0.0], "wrench": np.ones(6), "twist": np.zeros(6), "sd": 0.0},
         r"sd must be one or 6 values > 0"),
        ({"wrench": np.ones(6), "twist": np.zeros(6), "sd": 1.0}, r"needs q or actuated"),
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
    with pytest.raises(cl.InvalidInputError, match=r"'coupler' needs a finite start value > 0"):
        identify(clm, one, "P", ["coupler"])
    with pytest.raises(cl.InvalidInputError, match=r"appears in two fitted parameters"):
        identify(clm, one, "P", ["crank_axial", ("crank_axial", "rocker_axial")])
    # one number in N m/rad and N/m at once (it was fitted, exit 0)
    with pytest.raises(cl.InvalidInputError, match=r"ties springs of different units"):
        identify(clm, one, "P", [("crank", "crank_axial")])


# ------------------------------------------------------------------ audit: the edges
FOURBAR_TRUE = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
FOURBAR_CRANKS = (0.2, 0.6, 1.0, 1.4)


def _fourbar_data(clm, rng, sd, springs=FOURBAR_TRUE, n_wrench=3, exact_sd=1e-9):
    truth = clm.with_springs(springs)
    # stated by q: any closed configuration; these (one solve from neutral, two of them on
    # the lower mode) are those the tolerances below were set on
    configs = [one_solve(clm, [a]) for a in FOURBAR_CRANKS]
    return _synthetic(truth, "P", configs, rng, sd=sd, n_wrench=n_wrench, exact_sd=exact_sd)


def test_block_springs_stay_when_other_springs_are_fitted():
    # the flexible joint's coupled 6x6 and the wrist's 3x3 must stay blocks in the fit
    clm, q, springs = mech.serial_with_block(wrist="spherical")
    rng = np.random.default_rng(5)
    data = _synthetic(clm, "tool", [q], rng, sd=0.0, n_wrench=3)
    fit = identify(clm.with_springs({**springs, "base": 500.0}), data, "tool", ["base"])
    np.testing.assert_allclose(fit.estimates["base"], springs["base"], rtol=RTOL_EXACT_FIT)
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-6)  # in sd = 1e-9 units


def test_derivative_with_respect_to_a_block_factor_equals_central_differences():
    clm, q, springs = mech.serial_with_block(wrist="spherical")
    res = cl.compliance(clm, q, "tool")
    for name in ("flex", "wrist"):
        K0, h = springs[name], 1e-4
        plus = cl.compliance(clm.with_springs({**springs, name: (1 + h) * K0}), q, "tool").C
        minus = cl.compliance(clm.with_springs({**springs, name: (1 - h) * K0}), q, "tool").C
        rows = np.arange(clm.model.nv)[clm.joint_v_slice(name)]
        assert_close_in_norm(compliance_derivative(res, rows, K0), (plus - minus) / (2 * h),
                             RTOL_DERIVATIVE)  # fmt: skip


def test_beam_young_modulus_is_fitted_as_a_factor_of_the_block():
    # the truth is built by beam theory with E and G both 1.3 times the start's (fixed
    # Poisson ratio): the fitted factor of each block is 1.3, the joint springs recovered
    alu = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}
    ends = {"upper_arm_link": "elbow_joint", "forearm_link": "wrist_1_joint"}

    def beams(factor):
        spec = {**alu, "E": factor * alu["E"], "G": factor * alu["G"]}
        return {link: {**spec, "end": end} for link, end in ends.items()}

    base = _ur5(UR5_TRUE)
    truth, start = base.with_beams(beams(1.3)), _ur5(dict.fromkeys(UR5_JOINTS, 1e4))
    start = start.with_beams(beams(1.0))
    rng = np.random.default_rng(6)
    configs = [
        cl.model.beams.map_configuration(base.model, truth.model, q) for q in _ur5_configs(rng)
    ]
    data = _synthetic(truth, "tool0", configs, rng, sd=0.0)
    fit = identify(start, data, "tool0", [*UR5_JOINTS, "upper_arm_link_beam",
                                          "forearm_link_beam"])  # fmt: skip
    assert fit.unidentifiable == ()
    np.testing.assert_allclose(fit.estimates["upper_arm_link_beam"], 1.3, rtol=RTOL_EXACT_FIT)
    np.testing.assert_allclose(fit.estimates["forearm_link_beam"], 1.3, rtol=RTOL_EXACT_FIT)
    for name in UR5_JOINTS:
        np.testing.assert_allclose(fit.estimates[name], UR5_TRUE[name], rtol=RTOL_EXACT_FIT)


CAHYMAN_GROUPS = {
    "K_T": ("alpha_1", "alpha_2", "alpha_3"),
    "K_b": tuple(f"{p}_{i}_axial" for i in (1, 2, 3) for p in ("b", "d")),
    "K_T4": ("alpha_4",),
    "K_s": ("s_4",),
    "K_4": ("arm_axial",),
}
CAHYMAN_TRUE = {"K_T": 3000.0, "K_b": 1.5e6, "K_T4": 1200.0, "K_s": 4e5, "K_4": 4e6}
#: Poses (alpha_1..3 [deg], alpha_4 [deg], s_4 [m]).
CAHYMAN_POSES = [(45.0, 60.0, 75.0, 45.0, 0.01), (80.0, 70.0, 60.0, 30.0, 0.04),
                 (60.0, 85.0, 50.0, 60.0, 0.02)]  # fmt: skip


@pytest.fixture(scope="module")
def cahyman():
    """(model with the true springs, configurations of CAHYMAN_POSES)."""
    from cahyman_pin.model import cahyman_model

    machine = cahyman_model()
    springs = {n: CAHYMAN_TRUE[g] for g, names in CAHYMAN_GROUPS.items() for n in names}
    configs = [machine.assemble(np.deg2rad(p[:3]), np.deg2rad(p[3]), p[4])
               for p in CAHYMAN_POSES]  # fmt: skip
    return machine.clm.with_springs(springs), configs


def test_cahyman_springs_are_recovered_and_its_series_arm_springs_named(cahyman):
    truth_model, configs = cahyman
    truth, groups = CAHYMAN_TRUE, CAHYMAN_GROUPS
    data = _synthetic(truth_model, "M", configs, np.random.default_rng(7), sd=0.0)
    start = truth_model.with_springs({n: 3.0 * v for n, v in truth_model.springs.items()})
    fit = identify(start, data, "M", list(groups.values()))
    # the telescope's spring K_s and the arm's K_4 both act along the arm, in series: the
    # tip sees only 1/K_s + 1/K_4
    assert fit.unidentifiable == ("s_4", "arm_axial")
    assert fit.confounded == (("s_4", "arm_axial"),)
    for g in ("K_T", "K_b", "K_T4"):
        np.testing.assert_allclose(fit.estimates["+".join(groups[g])], truth[g],
                                   rtol=RTOL_EXACT_FIT)  # fmt: skip
    tied = identify(start, data, "M", [*list(groups.values())[:3], ("s_4", "arm_axial")])
    np.testing.assert_allclose(
        tied.estimates["s_4+arm_axial"],
        2 / (1 / truth["K_s"] + 1 / truth["K_4"]),
        rtol=RTOL_EXACT_FIT,
    )
    for g in ("K_T", "K_b", "K_T4"):
        np.testing.assert_allclose(tied.estimates["+".join(groups[g])], truth[g],
                                   rtol=RTOL_EXACT_FIT)  # fmt: skip


@pytest.mark.parametrize("seed", [0, 1])
def test_cahyman_noisy_data_recover_the_springs_within_their_errors(cahyman, seed):
    # 10 um and 50 urad of noise on deflections of ~2 mm and ~10 mrad
    truth_model, configs = cahyman
    rng = np.random.default_rng(seed)
    sd = np.array([1e-5, 1e-5, 1e-5, 5e-5, 5e-5, 5e-5])
    data = []
    for q in configs:
        C = cl.compliance(truth_model, q, "M").C
        for w in rng.normal(size=(4, 6)) * np.array([100.0] * 3 + [10.0] * 3):
            data.append(Measurement.of(q=q, wrench=w, twist=C @ w + sd * rng.normal(size=6),
                                       sd=sd))  # fmt: skip
    start = truth_model.with_springs({n: 2.0 * v for n, v in truth_model.springs.items()})
    groups = [*list(CAHYMAN_GROUPS.values())[:3], ("s_4", "arm_axial")]
    fit = identify(start, data, "M", groups)
    series = 2 / (1 / CAHYMAN_TRUE["K_s"] + 1 / CAHYMAN_TRUE["K_4"])
    for name, value in zip(fit.names, [*list(CAHYMAN_TRUE.values())[:3], series], strict=True):
        error = abs(fit.estimates[name] - value)
        assert error <= SIGMAS * fit.std_errors[name], (name, error, fit.std_errors[name])
    assert 0.5 < fit.residual_rms < 1.5


@pytest.mark.parametrize("factor", [1e6, 1e-6])
def test_a_start_a_million_times_off_converges(fourbar, factor):
    clm, _ = fourbar
    data = _fourbar_data(clm, np.random.default_rng(8), sd=0.0)
    start = clm.with_springs({n: factor * v for n, v in FOURBAR_TRUE.items()})
    fit = identify(start, data, "P", list(FOURBAR_TRUE))
    for name, value in FOURBAR_TRUE.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT)


@pytest.mark.parametrize("decades", [(5.2, -4.6, 2.7), (5.1, 5.6, -5.8), (-4.2, 5.7, 4.7)])
def test_starts_off_by_up_to_a_million_each_way_converge(fourbar, decades):
    # the first steps from such starts reach springs 1e14 apart (a mechanism): rejected
    clm, _ = fourbar
    data = _fourbar_data(clm, np.random.default_rng(8), sd=0.0)
    start = {n: 10.0**e * v for (n, v), e in zip(FOURBAR_TRUE.items(), decades, strict=True)}
    fit = identify(clm.with_springs(start), data, "P", list(FOURBAR_TRUE))
    for name, value in FOURBAR_TRUE.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT)


#: Springs of the four-bar: all 1e-5 times (crank 5e-4 N m/rad) or 1e7 times (rocker
#: 2e12 N/m) the file's, and ratios of 1e9 and 1e12 in one model (1e15, 1e-3 beside
#: 1e12, is refused by the compliance itself: a spring below 1e-14 of the stiffest).
EXTREME_SPRINGS = [
    {n: 1e-5 * v for n, v in FOURBAR_TRUE.items()},
    {n: 1e7 * v for n, v in FOURBAR_TRUE.items()},
    {"crank": 1e-3, "crank_axial": 1e6, "rocker_axial": 2e6},
    {"crank": 1.0, "crank_axial": 1e12, "rocker_axial": 2e12},
]


@pytest.mark.parametrize("springs", EXTREME_SPRINGS)
def test_tiny_and_huge_stiffnesses_are_recovered(fourbar, springs):
    """Noise-free data stated at a precision that resolves the stiffest spring's share of
    the twists (at 1e-9 the axial springs of 1e12 N/m move the point by 1e-10 m: below the
    stated precision, they are rightly not identified). At a ratio of 1e12 the soft
    crank's twists reach 1e18 sd: one rounding of its log-stiffness moves them by ~100 sd,
    so the fit stops at a residual RMS ~0.5 and the stiff springs are recovered within
    their errors (~5e-8), not to 1e-8 (they did only when the common offset of a start
    three times off landed on the truth and a prior on the largest sensitivity held them
    there: test_identification_edges)."""
    clm, _ = fourbar
    exact_sd = 1e-9 * min(FOURBAR_TRUE[n] / v for n, v in springs.items())
    data = _fourbar_data(clm, np.random.default_rng(9), sd=0.0, springs=springs,
                         exact_sd=exact_sd)  # fmt: skip
    start = clm.with_springs({n: 3.0 * v for n, v in springs.items()})
    fit = identify(start, data, "P", list(FOURBAR_TRUE))
    for name, value in springs.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT,
                                   atol=SIGMAS * fit.std_errors[name])  # fmt: skip
    assert fit.consistent


def test_twists_that_a_rigid_spring_explains_best_are_unidentifiable(fourbar):
    """Zero twists under every load: the best fit is at infinite stiffness, where the
    optimiser stops anywhere (it reported 6.6e9 or 6.6e11 by the start, errors 1e3-1e5
    times the estimate, as identified); the data do not bound k: unidentifiable."""
    clm, _ = fourbar
    rng = np.random.default_rng(0)
    data = [Measurement.of(q=cl.assemble(clm, actuated=[a]).q, wrench=w, twist=np.zeros(6),
                           sd=1e-7)
            for a in (0.2, 0.6, 1.0) for w in 10.0 * rng.normal(size=(3, 6))]  # fmt: skip
    for factor in (1.0, 100.0):
        start = clm.with_springs({n: factor * v for n, v in FOURBAR_TRUE.items()})
        fit = identify(start, data, "P", list(FOURBAR_TRUE))
        assert fit.unidentifiable == tuple(FOURBAR_TRUE) and fit.identified == ()
        assert all(v is None for v in fit.estimates.values())


def test_mixed_units_recover_within_their_errors():
    # translations to 1 um, rotations to 50 urad: each component weighted by its own sd
    rng = np.random.default_rng(10)
    sd = np.array([1e-6, 1e-6, 1e-6, 5e-5, 5e-5, 5e-5])
    truth = _ur5(UR5_TRUE)
    data = []
    for q in _ur5_configs(rng):
        C = cl.compliance(truth, q, "tool0").C
        for w in 100.0 * rng.normal(size=(3, 6)):
            data.append(Measurement.of(q=q, wrench=w, twist=C @ w + sd * rng.normal(size=6),
                                       sd=sd))  # fmt: skip
    fit = identify(_ur5(dict.fromkeys(UR5_JOINTS, 1e4)), data, "tool0", list(UR5_JOINTS))
    for name in UR5_JOINTS:
        assert abs(fit.estimates[name] - UR5_TRUE[name]) <= SIGMAS * fit.std_errors[name]
    assert 0.5 < fit.residual_rms < 1.5


#: Monte Carlo of the standard errors: 100 fits; the sample standard deviation of 100
#: normal draws is within 1/sqrt(2 * 99) = 7% of the true one (1 sigma): 25% is 3.5 sigma.
MC_FITS = 100
RTOL_MC = 0.25


def test_standard_errors_match_the_scatter_of_many_noisy_fits(fourbar):
    clm, _ = fourbar
    rng = np.random.default_rng(11)
    configs = [cl.assemble(clm, actuated=[a]).q for a in FOURBAR_CRANKS]
    truth = clm.with_springs(FOURBAR_TRUE)
    wrenches = [(q, 10.0 * rng.normal(size=(2, 6))) for q in configs]
    exact = [(q, w, cl.compliance(truth, q, "P").C @ w) for q, ws in wrenches for w in ws]
    estimates, errors = [], []
    for _ in range(MC_FITS):
        data = [Measurement.of(q=q, wrench=w, twist=d + 1e-7 * rng.normal(size=6), sd=1e-7)
                for q, w, d in exact]  # fmt: skip
        fit = identify(truth, data, "P", list(FOURBAR_TRUE))
        estimates.append([fit.estimates[n] for n in FOURBAR_TRUE])
        errors.append([fit.std_errors[n] for n in FOURBAR_TRUE])
    np.testing.assert_allclose(np.std(estimates, axis=0, ddof=1), np.mean(errors, axis=0),
                               rtol=RTOL_MC)  # fmt: skip


def _series_chain():
    """Two prismatic springs in series along x (seen only through 1/k1 + 1/k2), then a
    revolute spring about z at 0.5 m from the tool."""
    m = pin.Model()
    a = m.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "s1")
    b = m.addJoint(a, pin.JointModelPX(), pin.SE3.Identity(), "s2")
    c = m.addJoint(b, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0.2, 0.0, 0.0])), "r")
    for j in (a, b, c):
        m.appendBodyToJoint(j, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
    m.addFrame(pin.Frame("tool", c, pin.SE3(np.eye(3), np.array([0.0, 0.5, 0.0])), pin.OP_FRAME))
    return cl.ClosedLoopModel(m, springs={"s1": 1e5, "s2": 3e5, "r": 200.0})


#: Starts of the series chain (s1, s2, r): near; s2 1e8 times stiffer (its sensitivity
#: 1e-8 of s1's: confounded with it, not "not seen"); three whose steps along the unseen
#: direction would make s2 vanish beside s1 without the prior of _solve.
SERIES_STARTS = [(1e4, 1e4, 50.0), (1e2, 1e10, 50.0), (1e7, 1e10, 1.0), (1e8, 1e10, 1e-2),
                 (1e9, 2e10, 1.0)]  # fmt: skip


@pytest.mark.parametrize("start", SERIES_STARTS)
def test_series_springs_are_reported_confounded(start):
    clm = _series_chain()
    rng = np.random.default_rng(12)
    data = _synthetic(clm, "tool", [np.zeros(3), np.array([0.1, 0.0, 0.7])], rng, sd=0.0)
    fit = identify(clm.with_springs(dict(zip(("s1", "s2", "r"), start, strict=True))), data,
                   "tool", ["s1", "s2", "r"])  # fmt: skip
    assert fit.unidentifiable == ("s1", "s2") and fit.confounded == (("s1", "s2"),)
    assert fit.estimates["s1"] is None and fit.std_errors["s2"] is None
    np.testing.assert_allclose(fit.estimates["r"], 200.0, rtol=RTOL_EXACT_FIT)
    # tied to one value they are identified: 1/k + 1/k = 1/1e5 + 1/3e5
    tied = identify(clm, data, "tool", [("s1", "s2"), "r"])
    np.testing.assert_allclose(tied.estimates["s1+s2"], 2 / (1 / 1e5 + 1 / 3e5),
                               rtol=RTOL_EXACT_FIT)  # fmt: skip


def test_forces_alone_do_not_load_a_spring_whose_axis_passes_through_the_frame():
    # wrist_3's axis passes through tool0: forces there have no moment about it
    rng = np.random.default_rng(13)
    truth = _ur5(UR5_TRUE)
    data = []
    for q in _ur5_configs(rng, 4):
        C = cl.compliance(truth, q, "tool0").C
        for f in 100.0 * rng.normal(size=(3, 3)):
            w = np.r_[f, 0.0, 0.0, 0.0]
            data.append(Measurement.of(q=q, wrench=w, twist=C @ w, sd=1e-9))
    fit = identify(_ur5(dict.fromkeys(UR5_JOINTS, 1e4)), data, "tool0", list(UR5_JOINTS))
    assert fit.unidentifiable == ("wrist_3_joint",)
    for name in UR5_JOINTS[:5]:
        np.testing.assert_allclose(fit.estimates[name], UR5_TRUE[name], rtol=RTOL_EXACT_FIT)


def test_the_ur5_stretched_singular_pose_still_identifies_its_springs():
    # q = 0: the arm stretched, the shoulder, elbow and wrist_1 axes parallel (rank J = 5);
    # the sensitivities are checked by central differences in log k, the fit exactly
    truth = _ur5(UR5_TRUE)
    q0 = np.zeros(6)
    rng = np.random.default_rng(14)
    data = _synthetic(truth, "tool0", [q0, q0 + np.r_[0, 0, 0, 0, 0.5, 0]], rng, sd=0.0)
    fit = identify(_ur5(dict.fromkeys(UR5_JOINTS, 1e4)), data, "tool0", list(UR5_JOINTS))
    columns = []
    for name in UR5_JOINTS:
        h = 1e-5
        plus = truth.with_springs({**UR5_TRUE, name: UR5_TRUE[name] * np.exp(h)})
        minus = truth.with_springs({**UR5_TRUE, name: UR5_TRUE[name] * np.exp(-h)})
        columns.append(np.concatenate([
            (cl.compliance(plus, m.q, "tool0").C - cl.compliance(minus, m.q, "tool0").C)
            @ m.wrench / (2 * h) for m in data]))  # fmt: skip
    s = np.linalg.svd(np.array(columns).T / np.linalg.norm(columns, axis=1), compute_uv=False)
    assert s[-1] > 1e-3 * s[0]  # well identifiable: the fit must name nothing
    assert fit.unidentifiable == ()
    for name in UR5_JOINTS:
        np.testing.assert_allclose(fit.estimates[name], UR5_TRUE[name], rtol=RTOL_EXACT_FIT)


#: Stewart platforms turned to delta [rad] from Fichter's singularity: the condition
#: number of C grows like 1/delta^2, the fit's rounding with it (4e-10 at 1e-4).
RTOL_NEAR_SINGULAR = {1e-2: RTOL_EXACT_FIT, 1e-3: RTOL_EXACT_FIT, 1e-4: 1e-7}


@pytest.mark.parametrize("delta", sorted(RTOL_NEAR_SINGULAR))
def test_near_a_parallel_singularity_the_legs_are_recovered(delta):
    m = mech.stewart_near_singular(delta)
    legs = [f"leg{i}" for i in range(6)]
    data = _synthetic(m.clm, m.frame, [m.q], np.random.default_rng(17), sd=0.0)
    fit = identify(m.clm.with_springs(dict.fromkeys(legs, 1e5)), data, m.frame, legs)
    for name in legs:
        np.testing.assert_allclose(fit.estimates[name], m.clm.springs[name],
                                   rtol=RTOL_NEAR_SINGULAR[delta])  # fmt: skip


def test_start_values_by_parameter_name(fourbar):
    clm, _ = fourbar
    springs = {"crank": 50.0, "crank_axial": 1.5e5, "rocker_axial": 1.5e5}
    data = _fourbar_data(clm, np.random.default_rng(18), sd=0.0, springs=springs)
    fit = identify(clm, data, "P", ["crank", ("crank_axial", "rocker_axial")],
                   start={"crank": 2e3, "crank_axial+rocker_axial": 3e3})  # fmt: skip
    np.testing.assert_allclose(fit.estimates["crank"], 50.0, rtol=RTOL_EXACT_FIT)
    np.testing.assert_allclose(fit.estimates["crank_axial+rocker_axial"], 1.5e5,
                               rtol=RTOL_EXACT_FIT)  # fmt: skip
    with pytest.raises(cl.InvalidInputError, match=r"'crank' needs a finite start value > 0"):
        identify(clm, data, "P", ["crank"], start={"crank": -5.0})
    with pytest.raises(cl.InvalidInputError, match=r"got 'big'"):
        identify(clm, data, "P", ["crank"], start={"crank": "big"})


def test_a_measurement_at_a_parallel_singularity_is_named():
    # Fichter's singularity: a platform twist leaves every leg still, no compliance exists
    far, at = mech.stewart_near_singular(0.3), mech.stewart_near_singular(0.0)
    data = [Measurement.of(q=m.q, wrench=np.ones(6), twist=np.zeros(6), sd=1e-6)
            for m in (far, at)]  # fmt: skip
    with pytest.raises(cl.MechanismError, match=r"^measurement 1: 'stewart' is still a mechanism"):
        identify(far.clm, data, far.frame, [f"leg{i}" for i in range(6)])


def test_repeated_measurements_shrink_the_errors_by_the_square_root_of_their_number():
    # six copies of the same data: the same estimates, errors sqrt(6) times smaller
    clm, _ = mech.fourbar_case()[:2]
    data = _fourbar_data(clm, np.random.default_rng(16), sd=0.0, n_wrench=2)
    once = identify(clm, data, "P", list(FOURBAR_TRUE))
    six = identify(clm, data * 6, "P", list(FOURBAR_TRUE))
    assert six.n_measurements == 6 * once.n_measurements
    for name in FOURBAR_TRUE:
        np.testing.assert_allclose(six.std_errors[name] * np.sqrt(6), once.std_errors[name],
                                   rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(six.correlations, once.correlations, atol=1e-9)


@pytest.mark.parametrize(
    ("sd", "match"),
    [(-1e-6, r"sd must be .* got -1e-06"), (float("nan"), r"sd must be .* got nan"),
     ([1e-6] * 3, r"sd must be one or 6 .* got \[1e-06, 1e-06, 1e-06\]"),
     ("x", r"sd must be real numbers, got 'x'"), (None, r"sd must be real numbers")],
)  # fmt: skip
def test_bad_standard_deviations_are_refused(sd, match):
    with pytest.raises(cl.InvalidInputError, match=match):
        Measurement.of(q=[0.0], wrench=np.ones(6), twist=np.zeros(6), sd=sd)


@pytest.mark.parametrize("key", ["q", "actuated", "twist", "wrench"])
def test_values_that_are_not_numbers_are_refused(key):
    kwargs = {"q": [0.0], "wrench": np.ones(6), "twist": np.zeros(6), "sd": 1.0}
    if key == "actuated":
        del kwargs["q"]
    kwargs[key] = ["x"] * 6
    with pytest.raises(cl.InvalidInputError, match=r"must be real numbers, got \['x'"):
        Measurement.of(**kwargs)


def test_measurements_that_do_not_fit_the_model_are_named(fourbar):
    clm, q = fourbar
    good = Measurement.of(q=q, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    short = Measurement.of(q=q[:3], wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    with pytest.raises(cl.InvalidInputError, match=r"measurement 1: q has 3 values; expected nq=5"):
        identify(clm, [good, short], "P", ["crank"])
    opened = q + np.array([0.0, 0.0, 0.1, 0.0, 0.0])  # the coupler turned: the loop opens
    open_loop = Measurement.of(q=opened, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    with pytest.raises(cl.OpenLoopError, match=r"^measurement 1: .*close"):
        identify(clm, [good, open_loop], "P", ["crank"])
    with pytest.raises(cl.InvalidInputError, match=r"q must be finite values"):
        Measurement.of(q=np.r_[q[:4], np.nan], wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    two = Measurement.of(actuated=[0.3, 0.1], wrench=np.ones(6), twist=np.zeros(6), sd=1.0)
    with pytest.raises(cl.InvalidInputError, match=r"measurement 0: 2 actuated values given"):
        identify(clm, [two], "P", ["crank"])
    with pytest.raises(cl.NameNotFoundError, match=r"nowhere"):
        identify(clm, [good], "nowhere", ["crank"])
    with pytest.raises(cl.InvalidInputError, match=r"start values for \['crnak'\], not fitted"):
        identify(clm, [good], "P", ["crank"], start={"crnak": 10.0})
    with pytest.raises(cl.InvalidInputError, match=r"list of Measurement"):
        identify(clm, good, "P", ["crank"])
    with pytest.raises(cl.InvalidInputError, match=r"list of joint names"):
        identify(clm, [good], "P", "crank")


def test_a_group_mixing_a_block_and_a_number_is_refused():
    clm, q, _ = mech.serial_with_block()
    one = [Measurement.of(q=q, wrench=np.ones(6), twist=np.zeros(6), sd=1.0)]
    with pytest.raises(cl.InvalidInputError, match=r"mixes block springs and numbers"):
        identify(clm, one, "tool", [("base", "flex")])


def test_measurements_given_by_actuated_values(fourbar):
    clm, _ = fourbar
    rng = np.random.default_rng(15)
    data = []
    # measured as the robot is driven there from its file's configuration: one assembly mode
    for a, q in zip(FOURBAR_CRANKS, driven(clm, FOURBAR_CRANKS), strict=True):
        C = cl.compliance(clm, q, "P").C
        for w in 10.0 * rng.normal(size=(3, 6)):
            data.append(Measurement.of(actuated=[a], wrench=w, twist=C @ w, sd=1e-9))
    fit = identify(clm.with_springs({"crank": 10.0, "crank_axial": 1e6, "rocker_axial": 1e4}),
                   data, "P", list(FOURBAR_TRUE))  # fmt: skip
    for name, value in FOURBAR_TRUE.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT)


def test_a_measurement_beyond_the_actuated_limits_is_named(fourbar):
    """crank = 7 rad lies beyond the four-bar's limits (+-6.3): the measurement was assembled
    (at 7 - 2 pi) and fitted; now it is refused, naming the measurement and the limit, as a
    map marks the same point invalid and the stiffness command refuses it."""
    clm, _ = fourbar
    C = cl.compliance(clm, cl.assemble(clm, actuated=[0.3]).q, "P").C
    w = np.array([1.0, 0.0, 2.0, 0.0, 0.3, 0.0])
    data = [Measurement.of(actuated=[a], wrench=w, twist=C @ w, sd=1e-9) for a in (0.3, 7.0)]
    with pytest.raises(cl.InvalidInputError, match=r"measurement 1: actuated joints outside "
                       r"their limits: crank = 7 \(limits \[-6.3, 6.3\]\)"):  # fmt: skip
        identify(clm, data, "P", ["crank"])
    with pytest.raises(
        cl.InvalidInputError, match=r"measurement 0: 2 actuated values given; expected 1"
    ):
        identify(clm, [Measurement.of(actuated=[0.3, 0.1], wrench=w, twist=w, sd=1.0)], "P",
                 ["crank"])  # fmt: skip

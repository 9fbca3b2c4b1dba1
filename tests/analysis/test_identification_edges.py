"""Identification at the edges: springs spanning ten decades, checked against a compliance
derived by hand (a serial chain: C = J diag(1/k) J^T, J the frame Jacobian in world axes
at the frame origin) and its Cramer-Rao covariance; non-finite configurations in files."""

import warnings

import numpy as np
import pinocchio as pin
import pytest
import scipy.special

import closedloop as cl
from closedloop.analysis.identification import FIT_SIGNIFICANCE, Measurement, identify
from closedloop.analysis.measurements import read_measurements

NAMES = ("j1", "j2", "j3", "j4")
#: 1e-2 N m/rad beside 1e8 N/m: the sensitivities of the fit span ten decades.
DECADES = np.array([1e-2, 1e8, 1e3, 1e5])
#: Starts: all three times off (a common offset reaches the truth) or each its own way,
#: the stiff prismatic spring ten times too soft.
STARTS = [(3.0, 3.0, 3.0, 3.0), (10.0, 0.1, 3.0, 0.3)]
#: 1 nm: the 1e8 N/m spring moves the tool by ~10 nm under ~1 N, resolved to a few %.
SD = 1e-9
#: |estimate - truth| within this many standard errors (probability 6e-5 per parameter at
#: a fixed seed).
SIGMAS = 4.0
#: The reported errors against the Cramer-Rao bound at the estimate: both are exact
#: derivatives, they differ by the rounding of the SVD of S (columns 1e10 apart: 1e-6).
RTOL_CRAMER_RAO = 1e-6
#: Monte Carlo: NOISY_FITS fits of fresh noise.
NOISY_FITS = 40


def _chain(springs):
    """RZ, PX, RY, RX in series, the tool off every axis."""
    m = pin.Model()
    parent = 0
    joints = (pin.JointModelRZ(), pin.JointModelPX(), pin.JointModelRY(), pin.JointModelRX())
    offsets = ((0.0, 0.0, 0.0), (0.3, 0.0, 0.0), (0.2, 0.1, 0.0), (0.1, 0.0, 0.2))
    for name, joint, xyz in zip(NAMES, joints, offsets, strict=True):
        parent = m.addJoint(parent, joint, pin.SE3(np.eye(3), np.array(xyz)), name)
        m.appendBodyToJoint(parent, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
    m.addFrame(pin.Frame("tool", parent, pin.SE3(np.eye(3), np.array([0.0, 0.4, 0.1])),
                         pin.OP_FRAME))  # fmt: skip
    return cl.ClosedLoopModel(m, springs=dict(zip(NAMES, springs, strict=True)))


def _jacobian(clm, q):
    data = clm.model.createData()
    pin.computeJointJacobians(clm.model, data, q)
    pin.updateFramePlacements(clm.model, data)
    return pin.getFrameJacobian(clm.model, data, clm.model.getFrameId("tool"),
                                pin.LOCAL_WORLD_ALIGNED)  # fmt: skip


@pytest.fixture(scope="module")
def loads():
    """[(q, J, w, exact twist)]: three poses, three unit-scale wrenches each."""
    clm = _chain(DECADES)
    rng = np.random.default_rng(31)
    out = []
    for q in rng.uniform(-1.0, 1.0, (3, 4)):
        J = _jacobian(clm, q)
        out += [(q, J, w, J @ ((J.T @ w) / DECADES)) for w in rng.normal(size=(3, 6))]
    return out


def _noisy(rows, rng):
    return [Measurement.of(q=q, wrench=w, twist=d + SD * rng.normal(size=6), sd=SD)
            for q, _, w, d in rows]  # fmt: skip


def _fit(data, factors):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a misfit is asserted through fit.consistent
        return identify(_chain(DECADES * factors), data, "tool", list(NAMES))


@pytest.mark.parametrize("factors", STARTS)
def test_springs_ten_decades_apart_are_fitted_with_their_cramer_rao_errors(loads, factors):
    """The prior that keeps unseen directions at the start weighed every offset by the
    largest sensitivity (1e10 times the stiff spring's): the 1e8 N/m spring stayed near its
    start of 1e7 (5.7e6, thousands of its reported errors off, residual RMS 49, flagged as
    a misfit)."""
    rows = loads
    fit = _fit(_noisy(rows, np.random.default_rng(32)), np.array(factors))
    assert fit.consistent and fit.unidentifiable == ()
    k = np.array([fit.estimates[n] for n in NAMES])
    se = np.array([fit.std_errors[n] for n in NAMES])
    assert np.all(np.abs(k - DECADES) <= SIGMAS * se), (k, se)
    # Cramer-Rao at the estimate: d(C w)/d log k_j = -(J_j . w) J_j / k_j, weighted by 1/sd
    S = np.vstack([np.column_stack([-(J[:, j] @ w) * J[:, j] / k[j] for j in range(4)])
                   for _, J, w, _ in rows]) / SD  # fmt: skip
    bound = k * np.sqrt(np.diag(np.linalg.inv(S.T @ S)))
    np.testing.assert_allclose(se, bound, rtol=RTOL_CRAMER_RAO)


def test_ten_decades_noisy_fits_scatter_as_their_errors_and_pass_the_chi_square(loads):
    """Over NOISY_FITS fits: the sum of squares of the weighted residuals has the mean of
    chi-square(dof) (its sample mean is within 5 of its standard deviations, sqrt(2 dof /
    NOISY_FITS)), no fit is flagged (1e-6 each), and the spread of each estimate matches
    the mean reported error within 45% (4 standard deviations of the sample standard
    deviation of 40 draws, 1/sqrt(78) = 11%)."""
    rows = loads
    rng = np.random.default_rng(33)
    fits = [_fit(_noisy(rows, rng), np.array(STARTS[1])) for _ in range(NOISY_FITS)]
    dof = 6 * len(rows) - len(NAMES)
    squares = [np.sum(f.residuals**2) for f in fits]
    assert abs(np.mean(squares) - dof) < 5.0 * np.sqrt(2.0 * dof / NOISY_FITS)
    assert all(f.consistent for f in fits)
    estimates = np.array([[f.estimates[n] for n in NAMES] for f in fits])
    errors = np.array([[f.std_errors[n] for n in NAMES] for f in fits])
    np.testing.assert_allclose(np.std(estimates, axis=0, ddof=1), errors.mean(axis=0),
                               rtol=0.45)  # fmt: skip


@pytest.mark.parametrize("key", ["q", "actuated"])
def test_a_non_finite_configuration_is_refused_naming_the_file(tmp_path, key):
    """A NaN or inf in q or actuated was read, and refused by identify without the file."""
    values = "[.nan, 0, 0, 0, 0]" if key == "q" else "[.inf]"
    path = tmp_path / "m.yaml"
    path.write_text(f"frame: P\nmeasurements:\n  - {{{key}: {values}, wrench: [1, 0, 0, 0, 0, "
                    "0], twist: [0, 0, 0, 0, 0, 0], sd: 1e-7}\n")  # fmt: skip
    with pytest.raises(cl.InvalidInputError, match=rf"measurement 0 of .*m\.yaml.*{key} must be "
                       "finite"):  # fmt: skip
        read_measurements(path)


def test_components_not_measured_weigh_nothing(loads, tmp_path):
    """Positions only (a laser tracker): sd = inf and twist NaN on the rotations. The fit
    equals the Cramer-Rao errors of the translations alone, and its chi-square test counts
    only the measured components (3 per measurement, not 6)."""
    rows = loads
    rng = np.random.default_rng(34)
    sd = np.r_[np.full(3, SD), np.full(3, np.inf)]
    data = [Measurement.of(q=q, wrench=w, twist=np.r_[d[:3] + SD * rng.normal(size=3),
                                                      np.full(3, np.nan)], sd=sd)
            for q, _, w, d in rows]  # fmt: skip
    fit = _fit(data, np.array(STARTS[0]))
    assert fit.consistent and fit.unidentifiable == ()
    k = np.array([fit.estimates[n] for n in NAMES])
    se = np.array([fit.std_errors[n] for n in NAMES])
    assert np.all(np.abs(k - DECADES) <= SIGMAS * se), (k, se)
    S = np.vstack([np.column_stack([-(J[:, j] @ w) * J[:3, j] / k[j] for j in range(4)])
                   for _, J, w, _ in rows]) / SD  # fmt: skip
    np.testing.assert_allclose(se, k * np.sqrt(np.diag(np.linalg.inv(S.T @ S))),
                               rtol=RTOL_CRAMER_RAO)  # fmt: skip
    assert np.all(fit.residuals[:, 3:] == 0.0)
    dof = 3 * len(rows) - len(NAMES)
    limit = np.sqrt(scipy.special.chdtri(dof, FIT_SIGNIFICANCE) / fit.residuals.size)
    np.testing.assert_allclose(fit.rms_limit, limit, rtol=1e-12)
    path = tmp_path / "m.yaml"  # the same in a file: .inf and .nan
    path.write_text(
        "frame: tool\nmeasurements:\n  - {q: [0, 0, 0, 0], wrench: [1, 0, 0, 0, 0, 0], "
        "twist: [0, 0, 0, .nan, .nan, .nan], sd: [1, 1, 1, .inf, .inf, .inf]}\n"
    )
    (m,) = read_measurements(path)[1]
    assert np.array_equal(m.sd[3:], np.full(3, np.inf)) and np.all(m.twist[3:] == 0.0)


@pytest.mark.parametrize(
    ("twist", "sd", "match"),
    [
        ([0, 0, 0, np.nan, 0, 0], 1e-7, "finite where sd is"),
        ([0] * 6, np.inf, "nothing is measured"),
        ([0] * 6, [1, 1, 1, 1, 1, np.nan], "sd must be"),
    ],
)
def test_a_twist_missing_where_sd_is_finite_is_refused(twist, sd, match):
    with pytest.raises(cl.InvalidInputError, match=match):
        Measurement.of(q=np.zeros(4), wrench=[1, 0, 0, 0, 0, 0], twist=twist, sd=sd)

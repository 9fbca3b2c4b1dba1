"""Loading robot files the library did not write: faults that used to pass silently or
without naming the file, and loading from several threads at once."""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, assert_close_in_norm

from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import (
    IgnoredFeatureWarning,
    InvalidInputError,
    ModelFileError,
    NameNotFoundError,
)
from closedloop.io import loader as io
from closedloop.io import robot_files
from closedloop.kinematics.assembly import assemble

# The MJCF and URDF four-bars are one mechanism read by two parsers: their compliances
# differ by rounding only (see RTOL_TWIN in test_io.py).
RTOL_TWIN = 1e-9
# How long a parse waits for a second one that a lock keeps out [s]: it only makes the
# test's interleaving happen on the code without the lock, and bounds the wait on the code
# with it (no assertion depends on it).
WAIT = 0.2


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------------ threads
def test_parses_in_two_threads_leave_stderr_where_it_was(tmp_path):
    """Each parse redirects file descriptor 2; without a lock, a parse that starts during
    another and ends after it restores the first one's temporary file as stderr."""
    keep, before = os.dup(2), os.fstat(2)
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()

    def first():
        first_in.set()
        second_in.wait(WAIT)

    def second():
        second_in.set()
        first_out.wait(WAIT)

    def run_first():
        robot_files.run_parser(first, tmp_path, "robot file")
        first_out.set()

    one = threading.Thread(target=run_first)
    two = threading.Thread(target=lambda: robot_files.run_parser(second, tmp_path, "robot file"))
    try:
        one.start()
        first_in.wait()
        two.start()
        one.join()
        two.join()
        after = os.fstat(2)
        assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)
    finally:
        os.dup2(keep, 2)
        os.close(keep)


# -------------------------------------------------------------- names from the files
@pytest.mark.parametrize(
    ("old", "new", "error", "match"),
    [
        ("closedloop1_B]", "nope_B]", NameNotFoundError, r"unknown frame 'nope_B'"),
        ("name_mot: [crank]", "name_mot: [crnk]", NameNotFoundError, r"unknown joint 'crnk'"),
        ("  crank: 50.0", "  crnk: 50.0", NameNotFoundError, r"unknown joint 'crnk'"),
        (
            "locked: []",
            "locked: [P_joint]",
            NameNotFoundError,
            r"unknown joint 'P_joint' \(a fixed",
        ),
        (
            "locked: []",
            "locked: [crank_axial]",
            InvalidInputError,
            r"joints \['crank_axial'\] are both",
        ),
    ],
)
def test_a_fault_of_the_closure_file_names_the_file(
    fourbar_urdf, fourbar_yaml, tmp_path, old, new, error, match
):
    text = fourbar_yaml.read_text()
    assert old in text
    side = write(tmp_path, "bad.yaml", text.replace(old, new, 1))
    with pytest.raises(error, match=f"^closure file {re.escape(repr(str(side)))}: " + match):
        io.load_model(fourbar_urdf, side, geometry=False)


def test_a_keyword_name_is_not_blamed_on_a_file(fourbar_urdf, fourbar_yaml):
    with pytest.raises(NameNotFoundError, match=r"^unknown joint 'crnk'"):
        io.load_model(fourbar_urdf, fourbar_yaml, springs={"crnk": 1.0}, geometry=False)


def test_an_mjcf_actuator_of_an_unknown_joint_names_the_robot_file(fourbar_mjcf, tmp_path):
    robot = write(
        tmp_path, "r.xml", fourbar_mjcf.read_text().replace('joint="crank"/>', 'joint="crnk"/>')
    )
    with pytest.raises(
        NameNotFoundError, match=f"^robot file {re.escape(repr(str(robot)))}: unknown joint 'crnk'"
    ):
        io.load_model(robot, geometry=False)
    side = write(tmp_path, "s.yaml", "springs: {rocker_axil: 1.0}\n")
    with pytest.raises(
        NameNotFoundError, match=f"^closure file {re.escape(repr(str(side)))}: unknown joint"
    ):
        io.load_model(fourbar_mjcf, side, geometry=False)


# --------------------------------------------------------- side file over the robot file
def test_a_side_file_locks_a_joint_the_mjcf_gives_a_spring(
    fourbar_mjcf, fourbar_urdf, fourbar_yaml, tmp_path
):
    """The lock replaces the file's spring (it used to be refused as both); the compliance
    is that of the URDF twin with the same joint locked."""
    mj = io.load_model(fourbar_mjcf, write(tmp_path, "s.yaml", "locked: [crank_axial]\n"))
    text = fourbar_yaml.read_text().replace("  crank_axial: 1.0e+5\n", "")
    twin = write(tmp_path, "t.yaml", text.replace("locked: []", "locked: [crank_axial]"))
    ur = io.load_model(fourbar_urdf, twin, geometry=False)
    np.testing.assert_array_equal(mj.stiffness, ur.stiffness)
    start = mj.reference_configuration()
    C_mj = compliance(mj, assemble(mj, [0.5], start).q, "P").C
    C_ur = compliance(ur, assemble(ur, [0.5], start).q, "P").C
    assert np.max(np.abs(C_ur)) > 1e-6
    assert_close_in_norm(C_mj, C_ur, RTOL_TWIN)


# ----------------------------------------------------- MJCF features that are not read
@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ('stiffness="1e5"', 'springdamper="0.01 1"', r"joint 'crank_axial' has springdamper"),
        (
            "<equality>",
            '<default><tendon stiffness="100"/></default><tendon><fixed name="t">'
            '<joint joint="crank" coef="1"/><joint joint="rocker" coef="-1"/></fixed></tendon>'
            "<equality>",
            r"<fixed> tendon 't' has stiffness '100'",
        ),
    ],
)
def test_mjcf_springs_that_are_not_read_are_refused(fourbar_mjcf, tmp_path, old, new, match):
    text = fourbar_mjcf.read_text()
    assert old in text
    with pytest.raises(ModelFileError, match=match):
        io.load_model(write(tmp_path, "r.xml", text.replace(old, new, 1)), geometry=False)


def test_mjcf_zero_springdamper_and_tendon_without_stiffness_load(fourbar_mjcf, tmp_path):
    text = fourbar_mjcf.read_text().replace('stiffness="1e5"', 'stiffness="1e5" springdamper="0 0"')
    text = text.replace("<equality>", '<tendon><fixed name="t" stiffness="0">'
                        '<joint joint="crank" coef="1"/></fixed></tendon><equality>')  # fmt: skip
    clm = io.load_model(write(tmp_path, "r.xml", text), geometry=False)
    assert clm.stiffness[clm.joint_v_slice("crank_axial")][0] == 1e5


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ('<motor name="crank_motor"', '<position name="crank_motor"', r"<position> actuator"),
        ('springref="0.5"', 'springref="0"', r"joint 'crank' has springref='0', not its ref"),
        # MuJoCo's default springref is 0, not ref: the spring is then at rest at qpos = 0
        ('springref="0.5" ', "", r"joint 'crank' has springref='0' \(MuJoCo's default"),
    ],
)
def test_mjcf_servo_and_spring_rest_that_are_not_read_warn(fourbar_mjcf, tmp_path, old, new, match):
    text = fourbar_mjcf.read_text()
    assert old in text
    with pytest.warns(IgnoredFeatureWarning, match=match):
        io.load_model(write(tmp_path, "r.xml", text.replace(old, new, 1)), geometry=False)


def test_mjcf_springref_at_ref_does_not_warn(fourbar_mjcf, tmp_path, recwarn):
    """The crank's springref is its ref; the slides have neither (both 0); a ball joint's
    spring is at rest at qpos0 whatever its springref (MuJoCo ignores it)."""
    io.load_model(fourbar_mjcf, geometry=False)
    text = (
        fourbar_mjcf.read_text()
        .replace(
            '<joint name="rocker_axial" type="slide"', '<joint name="rocker_axial" type="ball"'
        )
        .replace('stiffness="2e5"', 'stiffness="2e5" springref="0.1"')
    )
    io.load_model(write(tmp_path, "r.xml", text), geometry=False)
    assert not [w for w in recwarn if issubclass(w.category, IgnoredFeatureWarning)]


# -------------------------------------------------------------- YAML 1.1 number forms
@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("0100", r"number 0100 reads as 64 \(octal\)"),
        ("1:30", r"number 1:30 reads as 90 \(base 60\)"),
        # Python's float("0_3") is 3.0, YAML 1.1's 0_3 the octal 3 and 1_000.5 1000.5
        ("0_3", r"number 0_3 reads as 3 \(digits grouped by _\)"),
        ("1_000.5", r"number 1_000.5 reads as 1000.5 \(digits grouped by _\)"),
        ("0b101", r"number 0b101 reads as 5 \(binary\)"),
        # YAML 1.1 reads these as strings, which were then read by Python's float()
        ('"0_3"', r"stiffness of joint 'crank' is '0_3'; expected a number"),
        ("\u0663", r"stiffness of joint 'crank' is '\u0663'; expected a number"),  # Arabic-Indic 3
        ("\uff13", r"stiffness of joint 'crank' is '\uff13'; expected a number"),  # full-width 3
    ],
)
def test_yaml_numbers_that_yaml_versions_read_differently_are_refused(
    fourbar_urdf, fourbar_yaml, tmp_path, value, match
):
    text = fourbar_yaml.read_text().replace("crank: 50.0", f"crank: {value}")
    with pytest.raises(ModelFileError, match=match):
        io.load_model(fourbar_urdf, write(tmp_path, "c.yaml", text), geometry=False)


# ------------------------------------------------------------------------ beams
def test_a_loop_closed_at_a_beams_tip_follows_the_tip(tmp_path):
    """The four-bar's rocker as a beam, its loop closed at the rocker's end: from MJCF
    (closure built by the parser, before the beam) as from URDF (closures built after the
    beams, on a frame beyond the beam's fixed end). The MJCF anchor stayed with the
    beam's start, so that the beam changed C by 1e-17 instead of 0.7 %."""
    urdf = re.sub(
        r'<joint name="rocker_axial" type="prismatic">(.*?)</joint>',
        lambda m: (
            '<joint name="rocker_axial" type="fixed">'
            + re.sub(r"<axis[^>]*/>|<limit[^>]*/>", "", m.group(1))
            + "</joint>"
        ),
        (REPO / "urdf/fourbar.urdf").read_text(),
        flags=re.S,
    )
    yaml_text = (REPO / "urdf/fourbar.yaml").read_text().replace("  rocker_axial: 2.0e+5\n", "")
    mjcf = re.sub(
        r'\s*<joint name="rocker_axial"[^>]*/>', "", (REPO / "urdf/fourbar.xml").read_text()
    )
    beam = {"E": 7e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.006, "t": 0.001}}
    by_urdf = io.load_model(write(tmp_path, "a.urdf", urdf), write(tmp_path, "a.yaml", yaml_text),
                            beams={"rocker_link": {**beam, "end": "rocker_axial"}})  # fmt: skip
    mjcf_file = write(tmp_path, "b.xml", mjcf)
    by_mjcf = io.load_model(mjcf_file, beams={"rocker_link": {**beam, "end": "rocker_end_fixed"}})
    rigid = io.load_model(mjcf_file)
    C = [compliance(m, assemble(m, actuated=[0.5]).q, "P").C for m in (by_urdf, by_mjcf, rigid)]
    assert_close_in_norm(C[1], C[0], RTOL_TWIN)
    assert np.linalg.norm(C[1] - C[2]) > 1e-3 * np.linalg.norm(C[2])


def test_a_joint_locked_and_sprung_in_a_closure_file_names_the_file(tmp_path):
    yaml_text = (
        (REPO / "urdf/fourbar.yaml").read_text().replace("locked: []", "locked: [crank_axial]")
    )
    path = write(tmp_path, "c.yaml", yaml_text)
    with pytest.raises(InvalidInputError, match=r"c\.yaml.*\['crank_axial'\] are both locked and "
                       r"given springs"):  # fmt: skip
        io.load_model(REPO / "urdf/fourbar.urdf", path)

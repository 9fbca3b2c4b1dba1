"""Inputs of the command lines refused in one line: an overflowing stiffness, XML that
declares entities (every command, every format, meshes), an oversized file."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import one_error_line as one_line
from xml_files import DAE, LAUGHS, SDF, hostile_copy

from closedloop.cli.app import main as closedloop_main
from closedloop.common.input_files import SIZE_LIMITS
from closedloop.exceptions import EXIT_BAD_INPUT


def run(capsys, *argv) -> tuple[int, str, str]:
    code = closedloop_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_an_overflowing_joint_stiffness_is_refused(capsys):
    """1e999 was taken as inf: every actuated joint locked, then "give springs"."""
    code, out, err = run(capsys, "stiffness", "fourbar", "--frame", "P",
                         "--joint-stiffness", "1e999")  # fmt: skip
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert "argument --joint-stiffness: '1e999' is beyond the floating point range" in one_line(err)


def test_joint_stiffness_inf_still_locks_the_actuated_joints(capsys):
    code, out, err = run(capsys, "info", "ur5", "--joint-stiffness", "inf")
    assert (code, err) == (0, "")
    assert out.count("rigid (no spring)") == 6, out


# ------------------------------------------------------------------ hostile XML
#: Each command of ``closedloop`` that reads a model, after MODEL (``{out}``: a folder).
COMMANDS = {
    "stiffness": ["--frame", "P"],
    "deflect": ["--frame", "P"],
    "modes": [],
    "info": [],
    "view": ["--frame", "P", "--html", "{out}/view.html"],
    "map": ["--frame", "P", "--sweep", "crank=0:1:3", "--out", "{out}/map"],
    "identify": ["--measurements", "{out}/none.yaml", "--fit", "crank"],
}


@pytest.fixture(scope="module")
def hostile_files(tmp_path_factory, fourbar_urdf, fourbar_mjcf) -> dict[str, Path]:
    """A robot file of each format that declares the laughs, and an SDF robot whose mesh
    does."""
    folder = tmp_path_factory.mktemp("hostile")
    arm = folder / "arm.sdf"
    arm.write_text(SDF.format(name="arm", visual=""))
    files = {f.suffix: hostile_copy(f, folder, LAUGHS) for f in (fourbar_urdf, fourbar_mjcf, arm)}
    mesh = folder / "laughs.dae"
    mesh.write_text(DAE.format(doctype=LAUGHS, name="&lol9;"))
    visual = f'<visual name="v"><geometry><mesh><uri>{mesh}</uri></mesh></geometry></visual>'
    files["mesh"] = folder / "arm_mesh.sdf"
    files["mesh"].write_text(SDF.format(name="arm", visual=visual))
    return files


@pytest.mark.parametrize("suffix", [".urdf", ".xml", ".sdf"])
@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_refuses_xml_entities_in_one_line(
    capsys, tmp_path, hostile_files, command, suffix
):
    """The URDF was a traceback of xml.etree's ParseError from every command."""
    path = hostile_files[suffix]
    argv = [a.format(out=tmp_path) for a in COMMANDS[command]]
    code, out, err = run(capsys, command, path, *argv)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert f"{str(path)!r} declares the XML entity 'lol'" in one_line(err)
    assert list(tmp_path.iterdir()) == []  # no output file, no output folder


@pytest.mark.parametrize(
    "argv",
    [
        ["view", "--html", "{out}/view.html"],
    ],
)
def test_commands_that_read_meshes_refuse_xml_entities_in_them(
    capsys, tmp_path, hostile_files, argv
):
    springs = tmp_path.parent / f"{tmp_path.name}-springs.yaml"
    springs.write_text("crank: 1.0\n")
    command, *rest = (a.format(out=tmp_path) for a in argv)
    code, out, err = run(capsys, command, hostile_files["mesh"], "--frame", "arm",
                         "--springs", springs, *rest)  # fmt: skip
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert "laughs.dae' declares the XML entity 'lol'" in one_line(err)
    assert list(tmp_path.iterdir()) == []


def test_a_map_reads_no_mesh(capsys, tmp_path, hostile_files):
    """A map loads its model without visual geometry (its main process and its workers):
    the hostile mesh is never opened, the command goes on to its own checks (here the
    sweep of a joint that is not actuated)."""
    springs = tmp_path.parent / f"{tmp_path.name}-springs.yaml"
    springs.write_text("crank: 1.0\n")
    code, out, err = run(capsys, "map", hostile_files["mesh"], "--frame", "arm", "--springs",
                         springs, "--sweep", "crank=0:1:3", "--out", tmp_path / "map")  # fmt: skip
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert "'crank' is not an actuated joint" in one_line(err)
    assert list(tmp_path.iterdir()) == []


def test_an_oversized_springs_file_is_refused_naming_the_limit(capsys, tmp_path):
    """A 12 MB springs file took 55 s and 750 MB before its refusal."""
    path = tmp_path / "springs.yaml"
    with path.open("wb") as f:
        f.truncate(12_000_000)
    code, out, err = run(capsys, "info", "fourbar", "--springs", path)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert f"above the limit of {SIZE_LIMITS['YAML'] / 1e6:g} MB" in one_line(err)

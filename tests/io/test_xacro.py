"""xacro files and closure-file placeholders against the same models written out by hand,
their errors, and the files they refuse (no code runs, no other file is read)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from closedloop.cli.app import main
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import ExpressionError, InvalidInputError, ModelFileError
from closedloop.io.loader import load_model
from closedloop.kinematics.assembly import assemble

DATA = REPO / "tests" / "data" / "xacro"
# The same numbers reach Pinocchio either way (xacro writes Python's round-trip text of each
# value: 0.3 / 2 is the double of 0.15); 1e-13 leaves room for a sum taken in another order.
RTOL_SAME_MODEL = 1e-13


def joint_table(clm) -> list:
    """Name, placement and inertia of every joint of a model (the tree as Pinocchio holds it)."""
    m = clm.model
    return [(m.names[j], m.jointPlacements[j].homogeneous, m.inertias[j].toDynamicParameters())
            for j in range(m.njoints)]  # fmt: skip


def assert_same_model(a, b) -> None:
    for (na, Ma, Ia), (nb, Mb, Ib) in zip(joint_table(a), joint_table(b), strict=True):
        assert na == nb
        np.testing.assert_allclose(Ma, Mb, rtol=0, atol=1e-15)
        np.testing.assert_allclose(Ia, Ib, rtol=0, atol=1e-15)
    assert [f.name for f in a.model.frames] == [f.name for f in b.model.frames]
    assert a.actuated == b.actuated and sorted(a.springs) == sorted(b.springs)
    np.testing.assert_array_equal(a.stiffness, b.stiffness)


def test_fourbar_xacro_at_its_defaults_is_the_bundled_urdf():
    closures = REPO / "urdf" / "fourbar.yaml"
    by_hand = load_model(REPO / "urdf" / "fourbar.urdf", closures)
    xacro = load_model(DATA / "fourbar.urdf.xacro", closures)
    assert_same_model(xacro, by_hand)
    for crank in (0.3, 0.9, 1.6):
        q = assemble(by_hand, [crank]).q
        np.testing.assert_allclose(compliance(xacro, q, "P").C, compliance(by_hand, q, "P").C,
                                   rtol=RTOL_SAME_MODEL, atol=0)  # fmt: skip


def test_cantilever_xacro_and_placeholders_against_the_files_by_hand():
    args = {"d": 0.03, "L": 0.4, "tip_mass": 0.3}
    made = load_model(DATA / "cantilever.urdf.xacro", DATA / "cantilever.yaml", args=args)
    by_hand = load_model(DATA / "cantilever_by_hand.urdf", DATA / "cantilever_by_hand.yaml")
    assert_same_model(made, by_hand)
    assert dict(made.beam_masses) == dict(by_hand.beam_masses)
    q = assemble(by_hand, None).q
    C = compliance(made, q, "tip").C
    np.testing.assert_allclose(C, compliance(by_hand, q, "tip").C, rtol=RTOL_SAME_MODEL, atol=0)
    # and the beam is the one of beam theory: tip deflection L^3 / (3 E I) per newton
    inertia = np.pi / 64 * (0.03**4 - 0.024**4)
    np.testing.assert_allclose(C[2, 2], 0.4**3 / (3 * 7e10 * inertia), rtol=1e-12)


def test_xacro_leaves_no_file_behind(tmp_path):
    for name in ("fourbar.urdf.xacro", "materials.xacro"):
        (tmp_path / name).write_text((DATA / name).read_text())
    load_model(tmp_path / "fourbar.urdf.xacro", REPO / "urdf" / "fourbar.yaml",
               args={"crank": 0.12})  # fmt: skip
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fourbar.urdf.xacro", "materials.xacro"]


def test_missing_unused_and_bad_arguments():
    with pytest.raises(ExpressionError, match=r"cantilever.yaml', line 5: \$\{d\}: unknown "
                       r"name 'd'") as info:  # fmt: skip
        load_model(DATA / "cantilever.urdf.xacro", DATA / "cantilever.yaml")
    assert info.value.name == "d" and info.value.line == 5
    with pytest.raises(InvalidInputError, match=r"\['dd'\] used by none of"):
        load_model(DATA / "cantilever.urdf.xacro", DATA / "cantilever.yaml",
                   args={"d": 0.03, "dd": 1.0})  # fmt: skip
    with pytest.raises(InvalidInputError, match=r"\['d'\] used by none of"):
        load_model(REPO / "urdf" / "fourbar.urdf", REPO / "urdf" / "fourbar.yaml", args={"d": 1})


def xacro_file(tmp_path: Path, body: str, name: str = "m.urdf.xacro") -> Path:
    path = tmp_path / name
    path.write_text('<?xml version="1.0"?>\n<robot name="m" xmlns:xacro="http://www.ros.org/'
                    f'wiki/xacro">\n{body}\n</robot>\n')  # fmt: skip
    return path


def test_missing_xacro_argument_names_its_line(tmp_path):
    path = xacro_file(tmp_path, '<link name="a">\n<visual><geometry><sphere radius="$(arg r)"/>'
                      "</geometry></visual></link>")  # fmt: skip
    with pytest.raises(ExpressionError, match=r"line 4: \$\(arg r\): missing argument 'r'"):
        load_model(path)
    assert load_model(path, args={"r": 0.1}).model.nbodies == 1  # given: read


# What xacro's own evaluation would do with these, and why each is refused before it runs.
HOSTILE = {
    "read a file": ("${xacro.load_yaml('secret.yaml')}", r"a call of xacro.load_yaml"),
    "attribute": ("${xacro.dotify}", r"attribute access \(\.dotify\)"),
    "builtins": ("${python.vars(xacro)}", r"a call of python.vars"),
    "import": ("${__import__('os').system('touch pwned')}", "a call of"),
    "eval": ("$(eval __import__('os').system('touch pwned'))", "a \\$ that starts neither"),
    "environment": ("$(env HOME)", "a \\$ that starts neither"),
    "find": ("$(find pkg)", "a \\$ that starts neither"),
    "escape": ("$${__import__('os')}", "a \\$ that starts neither"),
    "format": ("${'%c' % 36}", "the operator"),
    "dollar string": ("${'$' + 'x'}", "the constant '\\$'"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_expressions_are_refused_before_xacro_runs(tmp_path, monkeypatch, case):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "secret.yaml").write_text("key: value\n")
    text, match = HOSTILE[case]
    path = xacro_file(tmp_path, f'<link name="a"><visual name="{text}"/></link>')
    with pytest.raises(ExpressionError, match=match) as info:
        load_model(path)
    assert info.value.file == str(path) and info.value.line == 3
    assert not (tmp_path / "pwned").exists()


def test_xacro_alone_would_read_the_file(tmp_path):
    """The threat is real: xacro's own evaluation reaches any file (why the scan exists)."""
    import xacro

    (tmp_path / "secret.yaml").write_text("key: the secret\n")
    path = xacro_file(tmp_path, "<link name=\"${xacro.load_yaml('secret.yaml').key}\"/>")
    assert "the secret" in xacro.process_file(str(path)).toxml()


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ('<xacro:include filename="${name}.xacro"/>', "expected a literal path"),
        ('<xacro:include filename="*.xacro"/>', "expected a literal path"),
        ('<xacro:include filename="none.xacro"/>', "does not exist"),
        ('<xacro:include filename="m.urdf.xacro"/>', "includes itself"),
        ("<!-- xacro:eval-comments -->", "xacro:eval-comments is refused"),
        ('<link name="a"', "not well-formed XML"),
    ],
)
def test_refused_files(tmp_path, body, match):
    with pytest.raises(ModelFileError, match=match):
        load_model(xacro_file(tmp_path, body))


def test_xml_entities_are_refused_in_one_line(tmp_path):
    laughs = "".join(f'<!ENTITY l{i} "&l{i - 1};&l{i - 1};">' for i in range(1, 30))
    path = tmp_path / "laughs.urdf.xacro"
    path.write_text(f'<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY l0 "ha">{laughs}]>\n'
                    '<robot name="m"><link name="&l29;"/></robot>\n')  # fmt: skip
    with pytest.raises(ModelFileError, match="line 2: a document type declaration") as info:
        load_model(path)
    assert "\n" not in str(info.value)


def test_an_included_file_is_checked_too(tmp_path):
    (tmp_path / "inc.xacro").write_text('<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                                        '\n<link name="${xacro.arg(\'x\')}"/></robot>')  # fmt: skip
    path = xacro_file(tmp_path, '<xacro:include filename="inc.xacro"/>')
    with pytest.raises(ExpressionError, match=r"inc.xacro', line 3: .*a call of xacro.arg"):
        load_model(path)


def test_command_line_takes_args(capsys, tmp_path):
    args = ["stiffness", str(DATA / "cantilever.urdf.xacro"), "--closures",
            str(DATA / "cantilever.yaml"), "--frame", "tip", "--json"]  # fmt: skip
    assert main([*args, "--arg", "d=0.03", "--arg", "L=0.4", "--arg", "tip_mass=0.3"]) == 0
    made = capsys.readouterr().out
    hand = [
        str(DATA / "cantilever_by_hand.urdf"),
        "--closures",
        str(DATA / "cantilever_by_hand.yaml"),
    ]
    assert main(["stiffness", *hand, "--frame", "tip", "--json"]) == 0
    by_hand = capsys.readouterr().out
    assert made == by_hand.replace("cantilever_by_hand.urdf", "cantilever.urdf.xacro")
    assert main(args) == 2  # d missing: one line naming the file, the line and the name
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cantilever.yaml', line 5: ${d}: unknown name 'd'" in err


def test_placeholders_in_an_mjcf_side_file(tmp_path):
    side = tmp_path / "side.yaml"
    side.write_text("springs:\n  crank: ${2 * k}\n")
    mjcf = REPO / "urdf" / "fourbar.xml"
    assert load_model(mjcf, side, args={"k": 60.0}).springs["crank"] == 120.0
    with pytest.raises(ExpressionError, match=r"side.yaml', line 2: .*unknown name 'k'"):
        load_model(mjcf, side)

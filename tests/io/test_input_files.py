"""Input files refused early and in one line: XML that declares entities (a robot file of
any format, a mesh), files beyond the size of their kind, numbers that are not plain ASCII
decimals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from xml_files import DAE, HOSTILE, LAUGHS, SDF, hostile_copy

import closedloop as cl
from closedloop.analysis.measurements import read_measurements
from closedloop.common.input_files import SIZE_LIMITS
from closedloop.exceptions import InvalidInputError, ModelFileError
from closedloop.io.closure_file import read_closure_file, read_springs_file


# ----------------------------------------------------------------------- hostile XML
@pytest.fixture
def sdf_file(tmp_path) -> Path:
    path = tmp_path / "arm.sdf"
    path.write_text(SDF.format(name="arm", visual=""))
    return path


@pytest.fixture(params=["urdf", "mjcf", "sdf"])
def robot_file(request, fourbar_urdf, fourbar_mjcf, sdf_file) -> Path:
    """A valid robot file of each format."""
    return {"urdf": fourbar_urdf, "mjcf": fourbar_mjcf, "sdf": sdf_file}[request.param]


@pytest.mark.parametrize("kind", HOSTILE)
def test_a_robot_file_that_declares_entities_is_refused_in_one_line(tmp_path, robot_file, kind):
    """The URDF case was xml.etree's ParseError and a traceback, after Pinocchio had read
    the file; the MJCF and SDF ones named the amplification or "undefined entity"."""
    path = hostile_copy(robot_file, tmp_path, HOSTILE[kind])
    with pytest.raises(ModelFileError, match=r"declares the XML entity 'lol'|entity 'lol9'") as e:
        cl.load_model(path, actuated=["crank"], geometry=False)
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_an_entity_declaration_alone_is_refused(tmp_path, fourbar_urdf):
    """One entity that expands to a word: harmless in size, refused all the same (one rule
    for every reader, whatever the entity holds)."""
    path = hostile_copy(fourbar_urdf, tmp_path, '<!DOCTYPE robot [<!ENTITY lol9 "fourbar">]>')
    with pytest.raises(ModelFileError, match=r"declares the XML entity 'lol9'"):
        cl.load_model(path, geometry=False)


def test_a_hostile_urdf_never_reaches_pinocchio(tmp_path, fourbar_urdf, monkeypatch):
    """Pinocchio's URDF reader (urdfdom, tinyxml2) read the file before the XML check."""
    calls = []
    monkeypatch.setattr(pin, "buildModelFromUrdf", lambda *a, **k: calls.append(a))
    path = hostile_copy(fourbar_urdf, tmp_path, LAUGHS)
    with pytest.raises(ModelFileError, match="declares the XML entity"):
        cl.load_model(path, geometry=False)
    assert calls == []


def test_pinocchio_s_urdf_reader_does_not_expand_entities(tmp_path, fourbar_urdf):
    """What the check above guards against, as Pinocchio 4.1 stands: tinyxml2 leaves an
    entity reference as it is written (neither the laughs nor another file's text)."""
    for kind, doctype in HOSTILE.items():
        model = pin.buildModelFromUrdf(str(hostile_copy(fourbar_urdf, tmp_path, doctype)))
        assert model.name == "&lol9;", kind


@pytest.fixture
def meshes(tmp_path) -> dict[str, Path]:
    """A plain mesh and two that declare entities, one of them used in the mesh's numbers
    (assimp, pugixml underneath, does not expand it and fails on the text)."""
    ok = tmp_path / "ok.dae"
    ok.write_text(DAE.format(doctype="", name="tri"))
    laughs = tmp_path / "laughs.dae"
    laughs.write_text(DAE.format(doctype=LAUGHS, name="&lol9;"))
    numbers = tmp_path / "numbers.dae"
    numbers.write_text(
        DAE.format(doctype='<!DOCTYPE root [<!ENTITY v "0 0 0 1 0 0 0 1 0">]>', name="tri")
        .replace(">0 0 0 1 0 0 0 1 0<", ">&v;<")
    )  # fmt: skip
    return {"ok": ok, "laughs": laughs, "numbers": numbers}


def robot_with_mesh(folder: Path, kind: str, mesh: Path, fourbar_urdf, fourbar_mjcf) -> Path:
    """The four-bar (URDF, MJCF) or the SDF arm with its first link drawn by ``mesh``."""
    if kind == "sdf":
        path = folder / "arm_mesh.sdf"
        visual = f'<visual name="v"><geometry><mesh><uri>{mesh}</uri></mesh></geometry></visual>'
        path.write_text(SDF.format(name="arm", visual=visual))
        return path
    if kind == "urdf":
        text = fourbar_urdf.read_text()
        link = text.index('<link name="crank_link">') + len('<link name="crank_link">')
        visual = f'<visual><geometry><mesh filename="{mesh}"/></geometry></visual>'
        path = folder / "fourbar_mesh.urdf"
    else:
        text = fourbar_mjcf.read_text()
        assets = f'<asset><mesh name="tri" file="{mesh}"/></asset>'
        text = text.replace("<worldbody>", assets + "<worldbody>", 1)
        link = text.index(">", text.index('<body name="crank_link"')) + 1
        visual = '<geom type="mesh" mesh="tri" contype="0" conaffinity="0" mass="0"/>'
        path = folder / "fourbar_mesh.xml"
    path.write_text(text[:link] + visual + text[link:])
    return path


@pytest.mark.parametrize("kind", ["urdf", "mjcf", "sdf"])
def test_a_mesh_that_declares_entities_is_refused_in_one_line(
    tmp_path, meshes, kind, fourbar_urdf, fourbar_yaml, fourbar_mjcf
):
    """Assimp read such a mesh without a word (the entity left unexpanded) or failed on its
    numbers with the C++ source's location in the message; the viewer then drew it."""
    options = {"actuated": ["crank"], "springs": {"crank": 1.0}} if kind == "sdf" else {}
    options["closures"] = fourbar_yaml if kind == "urdf" else None
    plain = robot_with_mesh(tmp_path, kind, meshes["ok"], fourbar_urdf, fourbar_mjcf)
    clm = cl.load_model(plain, **options)  # the robot and its plain mesh load
    assert [Path(g.meshPath).name for g in clm.visual_model.geometryObjects
            if g.meshPath.endswith(".dae")] == ["ok.dae"]  # fmt: skip
    for name in ("laughs", "numbers"):
        path = robot_with_mesh(tmp_path, kind, meshes[name], fourbar_urdf, fourbar_mjcf)
        # the entity in the numbers fails assimp's reading first, which names it
        with pytest.raises(ModelFileError, match=r"declares the XML entity 'lol'|\"&v;\"") as e:
            cl.load_model(path, **options)
        assert f"{name}.dae" in str(e.value) and "\n" not in str(e.value), str(e.value)
        cl.load_model(path, geometry=False, **options)  # no mesh is read without geometry


@pytest.mark.parametrize("kind", HOSTILE)
def test_urdf_readers_of_balls_and_beam_sections_refuse_entities(tmp_path, fourbar_urdf, kind):
    """The closure file's balls: and a beam's section: geometry read the URDF too."""
    path = hostile_copy(fourbar_urdf, tmp_path, HOSTILE[kind])
    closures = tmp_path / "balls.yaml"
    closures.write_text("closed_loop: []\ntype: []\nballs: [coupler]\n")
    with pytest.raises(ModelFileError, match="declares the XML entity"):
        cl.load_model(path, closures, geometry=False)
    from closedloop.model.beam_section import urdf_shapes

    with pytest.raises(ModelFileError, match="declares the XML entity"):
        urdf_shapes(path)


# ------------------------------------------------------------------------ sizes
def oversized(path: Path, kind: str) -> Path:
    """``path`` made one byte longer than the limit of its kind (a sparse file: no byte of
    it is written, and none may be read before the refusal)."""
    with path.open("wb") as f:
        f.truncate(SIZE_LIMITS[kind] + 1)
    return path


@pytest.mark.parametrize(
    ("name", "kind", "read"),
    [
        ("springs.yaml", "YAML", read_springs_file),
        ("closures.yaml", "YAML", read_closure_file),
        ("measurements.yaml", "YAML", read_measurements),
        ("measurements.csv", "CSV", read_measurements),
        ("robot.urdf", "XML", cl.load_model),
        ("robot.xml", "XML", cl.load_model),
        ("robot.sdf", "XML", cl.load_model),
    ],
)
def test_an_oversized_input_file_is_refused_naming_the_limit(tmp_path, name, kind, read):
    """A 12 MB springs file took 55 s and 750 MB of memory before its refusal."""
    path = oversized(tmp_path / name, kind)
    limit = SIZE_LIMITS[kind]
    with pytest.raises(ModelFileError, match=rf"above the limit of {limit / 1e6:g} MB") as e:
        read(path)
    assert str(path) in str(e.value) and f"{limit + 1} bytes" in str(e.value)


def test_the_bundled_files_are_far_below_the_limits():
    """The limits leave room: the largest bundled file is far from its kind's limit."""
    folder = cl.data.data_dir()
    for suffix, kind in ((".urdf", "XML"), (".xml", "XML"), (".yaml", "YAML")):
        largest = max(p.stat().st_size for p in folder.glob(f"*{suffix}"))
        assert largest < SIZE_LIMITS[kind] / 100, suffix


# ------------------------------------------------------------------------ numbers
@pytest.mark.parametrize(
    "text",
    [
        "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3d']\nsprings: {crank: 0x10}\n",
        "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3d']\n"
        "closure_springs: {0: [1, 1, 1, 1, 1, 0x10]}\n",
        "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3d']\n"
        "closure_springs: {0x0: [1, 1, 1, 1, 1, 1]}\n",
        "closed_loop: []\ntype: []\nbeams: {coupler_link: {end: coupler_end_joint, E: 0x10, "
        "G: 1, section: {shape: circle, d: 0.01}}}\n",
    ],
)
def test_hexadecimal_numbers_are_refused_in_closure_files(tmp_path, text):
    """0x10 read as 16 (a spring, a closure spring, a beam's E) and 0x0 as closure 0."""
    path = tmp_path / "closures.yaml"
    path.write_text(text)
    with pytest.raises(ModelFileError, match=r"0x.* is hexadecimal .*expected .*decimal"):
        read_closure_file(path)


def test_hexadecimal_numbers_are_refused_in_springs_and_measurement_files(tmp_path):
    springs = tmp_path / "springs.yaml"
    springs.write_text("crank: 0x10\n")
    with pytest.raises(ModelFileError, match=r"0x10 is hexadecimal"):
        read_springs_file(springs)
    data = tmp_path / "measurements.yaml"
    data.write_text(
        "frame: P\nmeasurements:\n- {actuated: [0.3], wrench: [0, 0, 0x10, 0, 0, 0], "
        "twist: [0, 0, 0, 0, 0, 0], sd: 1}\n"
    )
    with pytest.raises(ModelFileError, match=r"0x10 is hexadecimal"):
        read_measurements(data)


def test_overflowing_numbers_are_refused_in_measurement_files(tmp_path):
    """sd: 1.0e999 read as inf, "not measured", and 1e999 (a string to YAML 1.1) too."""
    for sd in ("1.0e999", "1e999"):
        data = tmp_path / "measurements.yaml"
        data.write_text(
            "frame: P\nmeasurements:\n- {actuated: [0.3], wrench: [0, 0, 1, 0, 0, 0], "
            f"twist: [0, 0, 1e-6, 0, 0, 0], sd: [1e-7, 1e-7, 1e-7, 1e-7, 1e-7, {sd}]}}\n"
        )
        with pytest.raises((ModelFileError, InvalidInputError), match="floating point range"):
            read_measurements(data)


@pytest.mark.parametrize(
    "value", [np.bool_(True), np.array(True), "1e999", "0x10", " 1e3x", "inf_", math.nan, -1.0]
)
def test_joint_stiffness_keyword_refuses_what_is_not_a_stiffness(fourbar_urdf, fourbar_yaml, value):
    """np.bool_(True) gave springs of 1.0 where True is refused; "1e999" gave inf (every
    joint locked) where a file refuses it."""
    with pytest.raises(InvalidInputError, match=r"joint stiffness .*expected a number >= 0"):
        cl.load_model(fourbar_urdf, fourbar_yaml, joint_stiffness=value, geometry=False)


@pytest.mark.parametrize(
    ("value", "k"),
    [(np.float32(2.5), 2.5), (np.int64(3), 3.0), ("4e2", 400.0), (math.inf, math.inf)],
)
def test_joint_stiffness_keyword_takes_numbers(ur5_urdf, value, k):
    clm = cl.load_model(ur5_urdf, joint_stiffness=value, geometry=False)
    assert clm.springs["elbow_joint"] == k

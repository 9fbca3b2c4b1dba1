"""``closedloop modes`` and ``cahyman modes``: JSON frequencies as the API's, one-line
errors."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from helpers import REPO

import closedloop as cl
from cahyman_pin.cli import main as cahyman_main
from closedloop.cli.app import main
from closedloop.cli.options import add_preload_arguments

UR5_Q = ("0.3", "-1.2", "1.4", "-0.6", "1.1", "0.2")


def run(capsys, entry, *argv: str) -> tuple[int, str, str]:
    status = entry(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_fourbar_json_frequencies_are_the_api_ones(capsys):
    code, out, err = run(capsys, main, "modes", "fourbar", "--actuated", "0.3", "--frame", "P",
                         "--json")  # fmt: skip
    assert code == 0 and err == ""
    doc = json.loads(out)
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    res = cl.modes(clm, cl.assemble(clm, actuated=[0.3]).q, frame="P")
    np.testing.assert_allclose(doc["frequencies"], res.frequencies, rtol=1e-12)
    assert doc["frame"] == "P" and len(doc["effective_masses"]) == 3


def test_text_lists_the_lowest_modes(capsys):
    code, out, _ = run(capsys, main, "modes", "ur5", "--q", *UR5_Q, "--joint-stiffness", "1e4",
                       "--n", "2")  # fmt: skip
    assert code == 0
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["1"], ["2"])]
    assert len(rows) == 2 and float(rows[0][1]) < float(rows[1][1])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (("--density", "-1"), "density -1"),
        (("--density", "7800"), "no beam with a section"),
        (("--n", "9"), "n = 9"),
        (("--frame", "nope"), "nope"),
        (("--preload", "0", "0", "1", "0", "0", "0"), "--preload"),
    ],
)
def test_bad_input_is_one_line(capsys, argv, message):
    code, out, err = run(capsys, main, "modes", "fourbar", "--actuated", "0.3", *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("closedloop: error: ") and message in err


def test_cahyman_modes_need_masses(capsys):
    code, out, err = run(capsys, cahyman_main, "modes")
    assert code == 2 and out == "" and err.count("\n") == 1 and "no mass" in err


def test_cahyman_modes_json(capsys):
    code, out, _ = run(capsys, cahyman_main, "modes", "--mass", "m_HQ=2", "--mass", "m_M4=1",
                       "--mass", "m_b=0.3", "--json")  # fmt: skip
    doc = json.loads(out)
    assert code == 0 and doc["frame"] == "M" and doc["masses_kg"]["m_HQ"] == 2.0
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    machine = cahyman_model(DEFAULT_PARAMS.replace(m_HQ=2.0, m_M4=1.0, m_b=0.3))
    q = machine.assemble(np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.05)  # defaults
    np.testing.assert_allclose(doc["frequencies"], cl.modes(machine.clm, q).frequencies,
                               rtol=1e-12)  # fmt: skip


def test_map_of_the_lowest_frequency(capsys, tmp_path):
    code, out, err = run(capsys, main, "map", "fourbar", "--frame", "P", "--sweep",
                         "crank=0.2:0.5:4", "--index", "lowest_frequency", "--out",
                         str(tmp_path))  # fmt: skip
    assert code == 0, err
    assert "lowest_frequency: min" in out and "[Hz]" in out
    data = np.load(tmp_path / "map.npz")
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    q = cl.assemble(clm, actuated=[0.2]).q
    np.testing.assert_allclose(data["lowest_frequency"][0], cl.modes(clm, q).frequencies[0],
                               rtol=1e-9)  # fmt: skip


def test_page_plays_a_mode(capsys, tmp_path):
    page = tmp_path / "mode.html"
    code, out, err = run(capsys, main, "modes", "fourbar", "--actuated", "0.3", "--frame", "P",
                         "--html", str(page), "--mode", "2", "--scale", "0.01")  # fmt: skip
    assert code == 0 and f"wrote {page}" in out, err
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    f = cl.modes(clm, cl.assemble(clm, actuated=[0.3]).q).frequencies[1]
    text = page.read_text()
    assert f"mode 2: natural frequency {f:.6g} Hz" in text  # the legend
    assert "shape amplified \u00d70.01 (given)" in text
    assert '"autoplay": true' in text and "set_animation" in text  # the page plays it


def test_mode_scene_swings_between_plus_and_minus_the_shape():
    import pinocchio as pin

    from closedloop.viewer.scene import mode_scene

    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    res = cl.modes(clm, cl.assemble(clm, actuated=[0.3]).q, frame="P")
    scene = mode_scene(clm, res.q, res.shapes[:, 0], res.frequencies[0], 1, "P", scale=0.02)
    np.testing.assert_allclose(scene.ramp[[0, -1]], [-1.0, 1.0], rtol=1e-15)
    for t, q in ((-1.0, scene.ramp_q[0]), (1.0, scene.ramp_q[-1])):
        expected = pin.integrate(clm.model, res.q, 0.02 * t * res.shapes[:, 0])
        np.testing.assert_allclose(q, expected, atol=1e-15)
    np.testing.assert_allclose(scene.frame_twist, res.twists[:, 0], rtol=1e-12, atol=1e-15)


def test_page_needs_a_frame(capsys, tmp_path):
    code, out, err = run(capsys, main, "modes", "fourbar", "--actuated", "0.3", "--html",
                         str(tmp_path / "x.html"))  # fmt: skip
    assert code == 2 and out == "" and err.count("\n") == 1 and "--html needs --frame" in err


def test_payload_without_gravity_adds_its_mass(capsys):
    code, out, err = run(capsys, main, "modes", "fourbar", "--actuated", "0.3", "--frame", "P",
                         "--payload", "2", "0.01", "0", "0", "--json")  # fmt: skip
    assert code == 0, err
    clm = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    q = cl.assemble(clm, actuated=[0.3]).q
    loaded = cl.modes(clm, q, payloads=[cl.Payload(2.0, "P", (0.01, 0.0, 0.0))])
    frequencies = json.loads(out)["frequencies"]
    np.testing.assert_allclose(frequencies, loaded.frequencies, rtol=1e-12)
    np.testing.assert_allclose(json.loads(out)["q"], q, rtol=0, atol=1e-12)  # no weight, no sag
    assert frequencies[0] < 0.5 * cl.modes(clm, q).frequencies[0]  # 2 kg on a light linkage


def test_cahyman_modes_under_gravity(capsys):
    code, out, err = run(capsys, cahyman_main, "modes", "--mass", "m_HQ=2", "--mass", "m_M4=1",
                         "--gravity", "--json")  # fmt: skip
    assert code == 0, err
    doc = json.loads(out)
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    machine = cahyman_model(DEFAULT_PARAMS.replace(m_HQ=2.0, m_M4=1.0))
    rest = machine.assemble(np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.05)
    res = cl.modes(machine.clm, rest, frame="M", gravity=(0.0, 0.0, -9.81))
    np.testing.assert_allclose(doc["frequencies"], res.frequencies, rtol=1e-9)
    np.testing.assert_allclose(doc["q"], res.q, rtol=0, atol=1e-12)
    assert doc["gravity_m_per_s2"] == [0.0, 0.0, -9.81]
    assert np.max(np.abs(np.asarray(doc["q"]) - rest)) > 1e-6  # it settled: not the rest pose


def test_cahyman_modes_of_the_links_as_beams(capsys):
    code, out, err = run(capsys, cahyman_main, "modes", "--links-as-beams", "--density", "2700",
                         "--n", "3", "--json")  # fmt: skip
    assert code == 0, err
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    machine = cahyman_model(DEFAULT_PARAMS.replace(links_as_beams=True))
    q = machine.assemble(np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.05)
    res = cl.modes(machine.clm, q, n=3, density=2700.0)
    np.testing.assert_allclose(json.loads(out)["frequencies"], res.frequencies, rtol=1e-9)


def test_cahyman_density_needs_the_links_as_beams(capsys):
    code, out, err = run(capsys, cahyman_main, "modes", "--density", "2700")
    assert code == 2 and out == "" and err.count("\n") == 1 and "--links-as-beams" in err


def test_cahyman_map_of_the_lowest_frequency(capsys, tmp_path):
    code, out, err = run(capsys, cahyman_main, "map", "--alpha4", "30,60", "--index",
                         "lowest_frequency", "--mass", "m_HQ=2", "--mass", "m_M4=1",
                         "--workers", "1", "--out", str(tmp_path))  # fmt: skip
    assert code == 0, err
    assert "lowest_frequency: min" in out and (tmp_path / "map_lowest_frequency.png").exists()
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    machine = cahyman_model(DEFAULT_PARAMS.replace(m_HQ=2.0, m_M4=1.0))
    q = machine.assemble(np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(60.0), 0.05)  # defaults
    data = np.load(tmp_path / "map.npz")
    expected = cl.modes(machine.clm, q).lowest_elastic_frequency
    np.testing.assert_allclose(data["index_lowest_frequency"][1], expected, rtol=1e-9)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (("--mass", "m_HQ=1"), "--index lowest_frequency"),
        (("--param", "m_HQ=1,2"), "--index lowest_frequency"),
        (("--index", "lowest_frequency"), "no mass"),
        (("--index", "lowest_frequency", "--mass", "m_HQ=1", "--backend", "consistent"),
         "generic backend"),
    ],
)  # fmt: skip
def test_cahyman_map_masses_are_for_the_frequency_only(capsys, tmp_path, argv, message):
    code, out, err = run(capsys, cahyman_main, "map", "--alpha4", "30,60", "--out",
                         str(tmp_path), *argv)  # fmt: skip
    assert code == 2 and out == "" and err.count("\n") == 1 and message in err


def test_payload_help_is_the_command_s_own(capsys):
    """The preload options take the help of --payload: the payload of ``modes`` sits at
    --frame and weighs only with --gravity; that of ``stiffness`` loads its frame."""
    parser = argparse.ArgumentParser()
    add_preload_arguments(parser, payload_help="a payload of this command")
    assert "a payload of this command" in " ".join(parser.format_help().split())
    helps = {}
    for command in ("modes", "stiffness"):
        code, out, _ = run(capsys, main, command, "--help")
        assert code == 0
        helps[command] = " ".join(out.split())
    modes = "a point mass at --frame, offset in its axes [m] (its weight too with --gravity)"
    stiffness = "a point mass at the loaded frame, offset in its axes [m] (needs --gravity)"
    assert modes in helps["modes"] and stiffness in helps["stiffness"]

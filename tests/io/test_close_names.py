"""Mistyped names offered the close valid ones ("did you mean"), case ignored: model,
bundled file and robot names, ball joints, beam links and ends, closure types."""

from __future__ import annotations

import pytest

import closedloop as cl
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError
from closedloop.io.closure_file import read_closure_file
from closedloop.io.data import resolve
from closedloop.model.closures import closure_between_frames


def test_a_mistyped_model_name_is_offered_the_close_one():
    with pytest.raises(ModelFileError, match=r"'ur55' .*did you mean 'ur5'"):
        resolve("ur55")
    with pytest.raises(ModelFileError, match=r"'fourbar_mjfc'.*did you mean 'fourbar_mjcf'"):
        resolve("fourbar_mjfc")
    with pytest.raises(ModelFileError, match=r"robot 'pnda'.*did you mean 'panda'"):
        cl.data.robot_file("pnda")
    with pytest.raises(ModelFileError, match=r"'fourbar.urfd'.*did you mean 'fourbar.urdf'"):
        cl.data.path("fourbar.urfd")


def test_a_mistyped_ball_joint_is_offered_the_close_one(tmp_path, fourbar_urdf):
    closures = tmp_path / "balls.yaml"
    closures.write_text("closed_loop: []\ntype: []\nballs: [couplr]\n")
    with pytest.raises(ModelFileError, match=r"balls: 'couplr' .*did you mean 'coupler'"):
        cl.load_model(fourbar_urdf, closures, geometry=False)


def test_mistyped_beam_links_and_ends_are_offered_the_close_ones(fourbar):
    clm, _ = fourbar
    spec = {"E": 2e11, "G": 8e10, "section": {"shape": "circle", "d": 0.01}}
    with pytest.raises(cl.BeamError, match=r"unknown link.*did you mean 'coupler_link'"):
        clm.with_beams({"coupler_lnk": {**spec, "end": "coupler_end_joint"}})
    with pytest.raises(cl.BeamError, match=r"end 'coupler_end_jont'.*did you mean "
                       r"'coupler_end_joint'"):  # fmt: skip
        clm.with_beams({"coupler_link": {**spec, "end": "coupler_end_jont"}})


def test_a_closure_type_in_another_case_is_offered_the_right_one(tmp_path, fourbar):
    path = tmp_path / "closures.yaml"
    path.write_text("closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3D']\n")
    with pytest.raises(ModelFileError, match=r"type '3D'.*did you mean '3d'"):
        read_closure_file(path)
    with pytest.raises(InvalidInputError, match=r"type 'Revolute'.*did you mean 'revolute'"):
        closure_between_frames(fourbar[0].model, "closedloop1_A", "closedloop1_B", "Revolute")


def test_did_you_mean_ignores_case_for_every_name(fourbar):
    """The rule of NameNotFoundError too: 'CRANK' is the joint 'crank'."""
    with pytest.raises(NameNotFoundError, match=r"did you mean 'crank'"):
        fourbar[0].joint_id("CRANK")


@pytest.mark.parametrize(
    ("name", "hint"),
    [
        ("ur55", "(did you mean 'ur5'?); the robot 'ur5' by name is "
                 "cl.load_model(cl.data.robot_file('ur5'))"),
        ("fourbarr", "the bundled model 'fourbar' is cl.load_model(cl.data.path('fourbar.urdf'), "
                     "cl.data.path('fourbar.yaml'))"),
    ],
)  # fmt: skip
def test_load_model_with_a_mistyped_name_offers_the_close_one(name, hint):
    """From Python a model name is no path: a mistyped one gets the close name and how to
    load it (the command line's did-you-mean)."""
    with pytest.raises(cl.ModelFileError) as err:
        cl.load_model(name)
    assert hint in str(err.value)

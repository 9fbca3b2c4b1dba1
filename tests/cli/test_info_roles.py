"""``closedloop info`` tells a beam's virtual joint from a spring by the model's structure
(:func:`closedloop.model.beam_joints.inserted_beams`), not by its name: several beams on a link
(``<link>_beam_<end>``) and a beam split into elements (``<link>_beam_1``, ...) are beams,
an ordinary joint named ``<link>_beam`` with a block spring is a spring."""

from __future__ import annotations

import json

import numpy as np
import pytest

from closedloop.cli.app import main
from closedloop.cli.info import model_info
from closedloop.io.loader import load_model
from closedloop.model.closed_loop import ClosedLoopModel

ROD = "{E: 2.1e11, G: 8.1e10, section: {shape: circle, d: 0.01}}"

#: A hub on a hinge with two fixed arms a and b.
HUB = """<robot name="hub">
<link name="base"/><link name="hub"/><link name="a"/><link name="b"/>
<joint name="hinge" type="revolute"><parent link="base"/><child link="hub"/>
<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="ja" type="fixed"><parent link="hub"/><child link="a"/><origin xyz="0.5 0 0"/></joint>
<joint name="jb" type="fixed"><parent link="hub"/><child link="b"/><origin xyz="0 0.3 0"/></joint>
</robot>"""


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _with(rod: str, **more) -> str:
    """The beam :data:`ROD` with more keys."""
    return rod[:-1] + "".join(f", {k}: {v}" for k, v in more.items()) + "}"


@pytest.mark.parametrize(
    ("beams", "expected"),
    [
        (f"  hub:\n    - {_with(ROD, end='ja')}\n    - {_with(ROD, end='jb')}\n",
         ["hub_beam_ja", "hub_beam_jb"]),
        (f"  hub: {_with(ROD, end='ja', elements=3)}\n", ["hub_beam_1", "hub_beam_2", "hub_beam"]),
    ],
    ids=["list", "elements"],
)  # fmt: skip
def test_info_names_the_beams_of_a_list_and_of_elements(capsys, tmp_path, beams, expected):
    """The virtual joints of a list of beams and of a beam's elements: role "beam", listed
    under beams (they were "sprung", "beams: none")."""
    (tmp_path / "hub.urdf").write_text(HUB)
    (tmp_path / "hub.yaml").write_text(f"name_mot: [hinge]\nbeams:\n{beams}")
    code, out, err = run(capsys, "info", tmp_path / "hub.urdf", "--closures", tmp_path / "hub.yaml",
                         "--json")  # fmt: skip
    assert code == 0 and err == ""
    info = json.loads(out)
    assert sorted(info["beams"]) == sorted(expected)
    roles = {j["name"]: j["role"] for j in info["joints"]}
    assert roles == {"hinge": "actuated", **dict.fromkeys(expected, "beam")}
    code, text, _ = run(capsys, "info", tmp_path / "hub.urdf", "--closures", tmp_path / "hub.yaml")
    assert code == 0 and f"beams: {', '.join(info['beams'])}\n" in text


def test_an_ordinary_joint_named_like_a_beam_with_a_block_spring_is_sprung(tmp_path):
    """A floating joint ``hub_beam`` (it carries the link b: no beam's virtual joint) with a
    6x6 spring: "sprung", no beam (it was a "beam" by its name)."""
    urdf = HUB.replace('name="jb" type="fixed"', 'name="hub_beam" type="floating"')
    (tmp_path / "named.urdf").write_text(urdf)
    plain = load_model(tmp_path / "named.urdf", geometry=False)
    assert plain.model.joints[plain.joint_id("hub_beam")].nv == 6
    K = np.diag([1e5, 1e5, 1e5, 50.0, 50.0, 50.0])
    clm = ClosedLoopModel(plain.model, (), ["hinge"], {"hub_beam": K})
    info = model_info(clm)
    assert info["beams"] == []
    assert {j["name"]: j["role"] for j in info["joints"]}["hub_beam"] == "sprung"

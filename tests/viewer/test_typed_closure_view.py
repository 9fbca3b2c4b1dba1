"""The deflection view of the spatial four-bar closed by a revolute closure at its pin C,
against the view of the four-bar written with the pin kept in the tree (the loop welded in
the rocker: no code of the typed closure on that side), and of the issue's sprung pin on
that closure (``closure_springs``) against the sprung pin in the tree: the scene's maths
and the static page's drawing of the links both descriptions share, and the natural modes
as drawn.

(``close_loops`` is not compared: its re-assembly keeps the amplified out-of-plane spring
deflections, which the planar loop's passive joints cannot close, on either description
alike, at any scale: an AssemblyError on both.)
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_close_in_norm
from spatial_fourbar import (
    PIN,
    PIN_CUT,
    SHARED_JOINTS,
    fourbar_as,
    fourbar_files,
    mapped_configuration,
    shared_values,
)
from test_viewer import EXTERNAL, commands, export, json_matrix, robot_groups, robots_object

import closedloop as cl
from closedloop.analysis.vibration import modes
from closedloop.cli.app import main
from closedloop.viewer.scene import deflection_scene, mode_scene

#: Two descriptions of one mechanism: the joint deflections agree to rounding (compliances
#: by factorisations of condition ~1e6 at most; the nonlinear equilibria solved to
#: rounding), so do the twists and drawn poses made from them (~1e-13 measured).
RTOL_SAME = 1e-8
WRENCH = [3.0, 2.0, -4.0, 0.3, -0.2, 0.1]  # [N, N m] at P, in and out of the plane
#: A given amplification: the automatic one depends on every joint origin, and the tree
#: has one more (the pin at C).
AMPLIFICATION = 30.0
DESCRIPTIONS = ("revolute closure", "pin in the tree, rocker welded")
#: The issue's sprung pin (20 N m/rad) on the revolute closure, and in the tree.
SPRUNG = {
    "sprung revolute closure": ("revolute closure", {"closure_springs": {0: PIN}}),
    "sprung pin in the tree": ("pin in the tree, rocker welded", {"springs": {"pin_C": 20.0}}),
}


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    """{description: (model with its visual boxes, q at crank = 0.4 rad)}; the sprung pin
    at the configuration of the tree with the pin free (its springs at rest there)."""
    out = {}
    for d in DESCRIPTIONS:
        clm = fourbar_as(tmp_path_factory.mktemp("views"), d, geometry=True)
        out[d] = clm, np.array(cl.assemble(clm, [0.4]).q)
    free, q_free = out["pin in the tree, rocker welded"]
    for d, (description, options) in SPRUNG.items():
        tmp = tmp_path_factory.mktemp("views")
        clm = fourbar_as(tmp, description, geometry=True, **options)
        out[d] = clm, mapped_configuration(clm, free, q_free, PIN_CUT)
    return out


def _shared(clm: cl.ClosedLoopModel) -> list[int]:
    """The ids in ``clm`` of the joints both descriptions have, in one order."""
    return [clm.model.getJointId(n) for n in SHARED_JOINTS]


@pytest.mark.parametrize(
    ("pair", "nonlinear"),
    [pytest.param(DESCRIPTIONS, False, id="revolute-linear"),
     pytest.param(DESCRIPTIONS, True, id="revolute-nonlinear"),
     pytest.param(tuple(SPRUNG), False, id="sprung-revolute-linear")],
)  # fmt: skip
def test_a_revolute_closure_is_drawn_deflected_as_the_pin_in_the_tree(views, pair, nonlinear):
    scenes = {d: deflection_scene(*views[d], "P", WRENCH, scale=AMPLIFICATION,
                                  nonlinear=nonlinear) for d in pair}  # fmt: skip
    (clm, scene), (twin, expected) = ((views[d][0], scenes[d]) for d in pair)
    assert scene.nonlinear is nonlinear and not scene.reassembled
    assert np.abs(scene.frame_twist[:3]).min() > 1e-6  # P moves in and out of the plane
    assert_close_in_norm(scene.frame_twist, expected.frame_twist, RTOL_SAME)
    if pair == tuple(SPRUNG):  # the spring counts: P moves otherwise without it
        bare = deflection_scene(*views["revolute closure"], "P", WRENCH, scale=AMPLIFICATION)
        change = np.abs(bare.frame_twist - scene.frame_twist).max()
        assert change > 0.01 * np.abs(scene.frame_twist).max()
    np.testing.assert_allclose(scene.point_deflected, expected.point_deflected,
                               atol=RTOL_SAME * AMPLIFICATION * scene.max_displacement)  # fmt: skip
    # the amplified configuration integrate(q, s dq), on the joints both have
    drawn_dq = AMPLIFICATION * np.abs(scene.dq).max()
    np.testing.assert_allclose(shared_values(clm, scene.q_deflected),
                               shared_values(twin, expected.q_deflected),
                               atol=RTOL_SAME * drawn_dq)  # fmt: skip
    ids, twin_ids = _shared(clm), _shared(twin)
    twists = scene.twists[ids]
    assert np.abs(twists).max() > 1e-3  # the links move (rad, m)
    assert_close_in_norm(twists, expected.twists[twin_ids], RTOL_SAME)
    # the drawn motion of every shared link at every load fraction of the ramp
    moved = scene.ramp_poses[:, ids] - scene.poses[ids]
    assert_close_in_norm(moved, expected.ramp_poses[:, twin_ids] - expected.poses[twin_ids],
                         RTOL_SAME)  # fmt: skip


def test_the_natural_modes_of_a_revolute_closure_are_drawn_as_the_pin_in_the_tree(views):
    """Each mode's frequency, and each shared link's swing (mode shapes mass-normalised:
    the same up to sign; the cut's halves weigh nothing on either description)."""
    (clm, q), (twin, q_twin) = (views[d] for d in DESCRIPTIONS)
    result, expected = modes(clm, q), modes(twin, q_twin)
    assert len(result.frequencies) == len(expected.frequencies) == 4  # 9 coordinates, 5 rows
    np.testing.assert_allclose(result.frequencies, expected.frequencies, rtol=RTOL_SAME)
    for i, frequency in enumerate(result.frequencies):
        scene = mode_scene(clm, q, result.shapes[:, i], frequency, i + 1, "P", scale=1.0)
        other = mode_scene(twin, q_twin, expected.shapes[:, i], frequency, i + 1, "P", scale=1.0)
        twists, twists_twin = scene.twists[_shared(clm)], other.twists[_shared(twin)]
        sign = np.sign(np.vdot(twists, twists_twin))
        assert_close_in_norm(twists, sign * twists_twin, RTOL_SAME)


def drawn_links(html: str, cmds: list[dict]) -> dict:
    """{(robot, geometry name): ((4, 4) placement [m], colour)} of the page of the
    spatial four-bar: the ghost ('nominal') and the deflected drawing of each link's box."""
    assert EXTERNAL.search(html) is None and "<title>spatial_fourbar: deflection at P" in html
    obj = robots_object(cmds)
    materials = {m["uuid"]: m["color"] for m in obj["materials"]}
    out = {}
    for root in ("nominal", "deflected"):
        for name, group in robot_groups(obj, root).items():
            (mesh,) = group["children"]
            out[root, name.removeprefix(f"{root}_")] = (json_matrix(group),
                                                        materials[mesh["material"]])  # fmt: skip
    return out


@pytest.mark.parametrize("route", ["python", "command line"])
def test_the_static_page_of_a_revolute_closure_draws_the_links_of_the_pin_in_the_tree(
    views, tmp_path, capsys, route
):
    """meshcat's static HTML, decoded: each link's box, ghost and deflected, at the
    placement of the tree description's, with the same colour (its real displacement).
    The page of the revolute closure from :class:`DeflectionViewer` or from
    ``closedloop view --html`` on its files (assembled at crank 0.4 from the drawing)."""
    tree, q_tree = views["pin in the tree, rocker welded"]
    scene = deflection_scene(tree, q_tree, "P", WRENCH, scale=AMPLIFICATION)
    expected = drawn_links(*export(tree, scene, tmp_path, name="tree.html"))
    if route == "python":
        clm, q = views["revolute closure"]
        scene = deflection_scene(clm, q, "P", WRENCH, scale=AMPLIFICATION)
        page = drawn_links(*export(clm, scene, tmp_path, name="closure.html"))
    else:
        urdf, closures = fourbar_files(tmp_path, "revolute closure", visual=True)
        html = tmp_path / "closure.html"
        code = main(["view", str(urdf), "--closures", str(closures), "--frame", "P",
                     "--actuated", "0.4", "--force", *map(str, WRENCH[:3]), "--torque",
                     *map(str, WRENCH[3:]), "--scale", str(AMPLIFICATION),
                     "--html", str(html)])  # fmt: skip
        captured = capsys.readouterr()
        assert (code, captured.err) == (0, "") and f"wrote {html}" in captured.out
        text = html.read_text(encoding="utf-8")
        page = drawn_links(text, commands(text))
    assert len(page) == 2 * 9 and page.keys() == expected.keys()  # a box on each moving link
    names = [name for root, name in page if root == "deflected"]
    moved = np.array([page["deflected", n][0] - page["nominal", n][0] for n in names])
    assert np.abs(moved[:, :3, 3]).max() > 1e-3  # drawn displaced by millimetres or more
    atol = RTOL_SAME * np.abs(moved).max()  # (float64 in the page: exact to rounding)
    for key in page:
        np.testing.assert_allclose(page[key][0], expected[key][0], atol=atol)
    colours = [page["deflected", n][1] for n in names]
    assert len(set(colours)) > 1  # coloured by their displacements, not one colour
    assert colours == [expected["deflected", n][1] for n in names]

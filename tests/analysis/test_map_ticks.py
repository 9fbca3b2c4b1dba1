"""The maps' pictures (``closedloop map``, ``cahyman map``): no two tick labels overlap,
measured on the figure drawn by matplotlib's Agg renderer. The hard cases: values that share
few leading digits (long labels, no offset) on an axis shortened by a colour bar, with many
points."""

from __future__ import annotations

import itertools
import math

import matplotlib
import numpy as np
import pytest
from helpers import REPO

from cahyman_pin.cli.map import map_figure as cahyman_figure
from cahyman_pin.sweep import grid, sweep
from closedloop.analysis.maps import map_figure, stiffness_map
from closedloop.io.loader import load_model

matplotlib.use("Agg")


def _drawn_labels(fig) -> list:
    """(text, window extent [px]) of every tick label that the figure shows: its axes' and
    its colour bars', the ticks inside each axis's view interval (as matplotlib draws)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            slack = 1e-10 * (hi - lo)  # a tick at an end of the view is drawn
            locs = axis.get_majorticklocs()
            for loc, tick in zip(locs, axis.get_major_ticks(len(locs)), strict=True):
                if not lo - slack <= loc <= hi + slack:
                    continue
                for text in (tick.label1, tick.label2):
                    if text.get_visible() and text.get_text():
                        labels.append((text.get_text(), text.get_window_extent(renderer)))
    return labels


def _assert_apart(fig) -> None:
    labels = _drawn_labels(fig)
    assert len(labels) >= 4, labels  # both axes labelled
    clashes = [(a, b) for (a, box_a), (b, box_b) in itertools.combinations(labels, 2)
               if box_a.overlaps(box_b)]  # fmt: skip
    assert not clashes, clashes


@pytest.fixture(scope="module")
def delta():
    return load_model(REPO / "urdf/delta.urdf", REPO / "urdf/delta.yaml")


#: Values of a swept axis whose labels are long: 0.36245, 0.169675, 0.081236 (no offset: the
#: values share too few leading digits), on many points.
LONG = {"0.3624": np.linspace(0.36243, 0.36286, 40),
        "0.1697": np.linspace(0.1696504, 0.1698369, 60),
        "0.0812": np.linspace(0.0812343, 0.0812512, 40)}  # fmt: skip


@pytest.mark.parametrize("values", list(LONG))
def test_closedloop_heat_map_tick_labels_do_not_overlap(delta, values):
    smap = stiffness_map(delta, "platform", sweeps={"arm0": np.linspace(-0.3, 0.3, 5),
                         "arm1": LONG[values]}, fixed={"arm2": 0.0})  # fmt: skip
    _assert_apart(map_figure(smap, "min_translational"))


def test_closedloop_curve_tick_labels_do_not_overlap(delta):
    smap = stiffness_map(delta, "platform", sweeps={"arm1": LONG["0.1697"]},
                         fixed={"arm0": 0.1, "arm2": 0.0})  # fmt: skip
    _assert_apart(map_figure(smap, "min_translational"))


@pytest.mark.parametrize(
    ("axis", "values", "shown"),
    [("s4", LONG["0.3624"] * 1e-3, ("mm", 1e-3)),  # a stroke of 0.36245 mm
     ("b", LONG["0.0812"], ("m", 1.0))],  # a design length of 0.081236 m
)  # fmt: skip
def test_cahyman_heat_map_tick_labels_do_not_overlap(axis, values, shown):
    points = grid({axis: values, "K_s": np.linspace(1e3, 4.21e5, 6)}, alpha=[math.pi / 3] * 3,
                  alpha4=0.0, s4=0.025)  # fmt: skip
    result = sweep(points, backend="consistent", executor="serial")
    fig = cahyman_figure(result, "det_K", {axis: shown, "K_s": ("N/m", 1.0)}, {})
    _assert_apart(fig)

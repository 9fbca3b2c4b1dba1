"""The gallery's teaching order (docs/gallery_order.py) lists every example once."""

from __future__ import annotations

import importlib.util

import pytest
from helpers import REPO


def _order_module():
    spec = importlib.util.spec_from_file_location("gallery_order", REPO / "docs/gallery_order.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_example_is_listed_once():
    order = _order_module().ORDER
    examples = sorted(p.name for p in (REPO / "examples").glob("plot_*.py"))
    assert sorted(order) == examples and len(set(order)) == len(order)


def test_the_key_sorts_by_the_list_and_refuses_an_unlisted_example():
    module = _order_module()
    key = module.TeachingOrder(str(REPO / "examples"))
    names = sorted(module.ORDER)  # file-name order
    assert sorted(names, key=key) == list(module.ORDER)
    assert key(str(REPO / "examples/plot_ur5.py")) == 1  # a path as well as a name
    with pytest.raises(ValueError, match=r"'plot_new\.py'"):
        key("plot_new.py")

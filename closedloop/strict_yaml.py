"""YAML as the project's input files need it: no key given twice, no number beyond the
double range taken as infinity.

PyYAML's safe loader keeps the last of two equal keys (``{crank: 5, crank: 7}`` is
``{crank: 7}``) and reads ``1.0e400`` as ``inf``, which for a stiffness means a locked
joint. Here both are errors; ``.inf`` (YAML's infinity) stays infinity.
"""

from __future__ import annotations

import math

import yaml


class _Loader(yaml.SafeLoader):
    """Safe loader that refuses repeated keys and overflowing numbers."""


def _mapping(loader: _Loader, node: yaml.MappingNode) -> dict:
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} is given twice", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep=True)


def _float(loader: _Loader, node: yaml.ScalarNode) -> float:
    value = loader.construct_yaml_float(node)
    if math.isinf(value) and "inf" not in node.value.lower():
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f"number {node.value} is beyond the floating point range (about 1.8e308); "
            "write .inf for infinity",
            node.start_mark,
        )
    return value


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor("tag:yaml.org,2002:float", _float)


def load(text: str):
    """The document of ``text`` (YAML), with the checks of the module docstring.

    Raises:
        yaml.YAMLError: invalid YAML, a repeated key, an overflowing number; the message
            gives the line.
    """
    return yaml.load(text, Loader=_Loader)


def overflowing(text: str) -> bool:
    """True when ``text``, a number written as a string, is beyond the double range (it
    reads as infinity without saying ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        return False
    return math.isinf(value) and "inf" not in text.lower()

"""YAML as the project's input files need it: no key given twice, no number beyond the
double range taken as infinity, no number that YAML 1.1 and 1.2 read differently.

PyYAML's safe loader keeps the last of two equal keys (``{crank: 5, crank: 7}`` is
``{crank: 7}``) and reads ``1.0e400`` as ``inf``, which for a stiffness means a locked
joint. Here both are errors; ``.inf`` (YAML's infinity) stays infinity. It also reads, as
YAML 1.1 says, a number with a leading zero as octal (``0100`` is 64) and one with colons
in base 60 (``1:30`` is 90), digits grouped by ``_`` (``1_000`` is 1000, ``0_3`` is 3)
and binary (``0b101`` is 5), where YAML 1.2 reads 100 and strings: all are errors.
A hexadecimal number (``0x10``, 16 in both) is refused too: numbers are plain ASCII
decimals. A number that YAML 1.1 reads as a string (``1e5``, without a decimal point) is
read by the model files with :func:`closedloop.common.arrays.decimal` (ASCII decimal
notation only, an overflowing ``1e999`` refused).
"""

from __future__ import annotations

import sys
from collections.abc import Hashable

import yaml

from closedloop.common.arrays import overflowing


class _Loader(yaml.SafeLoader):
    """Safe loader that refuses repeated keys and overflowing numbers."""


def _mapping(loader: _Loader, node: yaml.MappingNode) -> dict:
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if not isinstance(key, Hashable):
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} is a {type(key).__name__}; expected a name or a number",
                key_node.start_mark,
            )  # fmt: skip
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} is given twice", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep=True)


def _check_base(node: yaml.ScalarNode, value) -> None:
    """Refuse a YAML 1.1 number that YAML 1.2 reads otherwise: digits grouped by ``_``,
    binary, octal (leading zero) or base 60 (colons); and a hexadecimal one, which both
    read (``0x10`` is 16) but the project's rule does not: plain ASCII decimals."""
    digits = node.value.lstrip("+-")
    if digits[:2].lower() == "0x":
        raise yaml.constructor.ConstructorError(
            None, None, f"number {node.value} is hexadecimal ({value}); expected decimal "
            "notation", node.start_mark,
        )  # fmt: skip
    octal = isinstance(value, int) and digits[:1] == "0" and digits[1:2] not in ("", "b")
    kind = (
        "digits grouped by _" if "_" in digits
        else "binary" if digits[:2] == "0b"
        else "octal" if octal
        else "base 60" if ":" in digits
        else None
    )  # fmt: skip
    if kind is not None:
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f"number {node.value} reads as {value} ({kind}) in YAML 1.1, not in YAML 1.2; "
            "write it in decimal, without leading zeros or _",
            node.start_mark,
        )


def _float(loader: _Loader, node: yaml.ScalarNode) -> float:
    value = loader.construct_yaml_float(node)
    _check_base(node, value)
    if overflowing(node.value):
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f"number {node.value} is beyond the floating point range (about 1.8e308); "
            "write .inf for infinity",
            node.start_mark,
        )
    return value


def _int(loader: _Loader, node: yaml.ScalarNode) -> int:
    try:  # Python refuses to read an int of more than 4300 digits (ValueError)
        value = loader.construct_yaml_int(node)
        beyond = abs(value) > sys.float_info.max
    except ValueError:
        beyond = True
    else:
        _check_base(node, value)
    if beyond:
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f"number {node.value[:40]}{'...' if len(node.value) > 40 else ''} is beyond the "
            "floating point range (about 1.8e308)",
            node.start_mark,
        )
    return value


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor("tag:yaml.org,2002:float", _float)
_Loader.add_constructor("tag:yaml.org,2002:int", _int)


def load(text: str):
    """The document of ``text`` (YAML), with the checks of the module docstring.

    Raises:
        yaml.YAMLError: invalid YAML, a repeated key, a key that is a list or a mapping,
            an overflowing number, nesting too deep for the reader; the message gives the
            line where it can.
    """
    try:
        return yaml.load(text, Loader=_Loader)
    except RecursionError:
        raise yaml.YAMLError(
            f"nested too deep for the reader (Python's recursion limit, "
            f"{sys.getrecursionlimit()}); expected a shallower document"
        ) from None

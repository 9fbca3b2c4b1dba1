"""The arithmetic of parametric model files: the whitelist, the values (against the same
operations computed directly), the closure file's placeholders, their errors."""

from __future__ import annotations

import math
import operator

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from closedloop.exceptions import ExpressionError, InvalidInputError
from closedloop.io import strict_yaml
from closedloop.io.closure_file import read_closure_file
from closedloop.io.expressions import (
    Arguments,
    Refused,
    checked,
    names_in,
    number_text,
    substitute,
    value,
)

NAMES = {"d": 0.02, "L": 0.5, "k": 3.0}
OPERATORS = {"+": operator.add, "-": operator.sub, "*": operator.mul, "/": operator.truediv,
             "**": operator.pow}  # fmt: skip
FUNCTIONS = {"sqrt": math.sqrt, "sin": math.sin, "exp": math.exp, "atan": math.atan}


@st.composite
def expressions(draw, depth: int = 3) -> tuple[str, object]:
    """(text, value or the exception) of a random expression, its value computed with the
    same floating point operations, directly (no parser)."""
    if depth == 0 or draw(st.booleans()):
        if draw(st.booleans()):
            name = draw(st.sampled_from(sorted(NAMES)))
            return name, NAMES[name]
        x = draw(st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False))
        return f"({x!r})", x
    if draw(st.integers(0, 3)) == 0:
        name = draw(st.sampled_from(sorted(FUNCTIONS)))
        text, inner = draw(expressions(depth - 1))
        return f"{name}({text})", _apply(FUNCTIONS[name], inner)
    op = draw(st.sampled_from(sorted(OPERATORS)))
    (left, a), (right, b) = draw(expressions(depth - 1)), draw(expressions(depth - 1))
    return f"({left} {op} {right})", _apply(OPERATORS[op], a, b)


def _apply(f, *args):
    if any(isinstance(a, Exception) for a in args):
        return next(a for a in args if isinstance(a, Exception))
    try:
        return f(*args)
    except (ArithmeticError, ValueError, TypeError) as e:
        return e


@settings(max_examples=200, deadline=None)
@given(expressions())
def test_values_are_those_of_the_same_operations(case):
    text, expected = case
    good = isinstance(expected, float) and math.isfinite(expected)
    if not good:  # an error on the way, a complex or infinite result
        with pytest.raises(Refused):
            value(checked(text), NAMES)
        return
    # the same IEEE operations in the same order: the same double
    assert value(checked(text), NAMES) == expected


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("d.real", "attribute access (.real)"),
        ("__import__('os').system('true')", "call of __import__"),
        ("open('/etc/passwd')", "call of open"),
        ("(lambda: 1)()", "call of"),
        ("d[0]", "a subscript"),
        ("'abc'", "constant 'abc'"),
        ("True", "constant True"),
        ("d % 2", "the operator"),
        ("d if L else k", "a conditional expression"),
        ("d == 1", "a comparison"),
        ("sqrt(x=d)", "call of sqrt"),
        ("[d, L]", "a List"),
        ("_secret", "names beginning with _"),
        ("d +", "not an expression"),
        ("(" * 600 + "d" + ")" * 600, "characters; expected at most"),
    ],
)
def test_refused_before_any_value(text, reason):
    with pytest.raises(Refused, match=f"{reason}".replace("(", r"\(").replace(")", r"\)")):
        checked(text)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("sqrt(-d)", "no value"),
        ("1 / (d - d)", "division by zero"),
        ("10.0 ** 400", "beyond the floating point range"),
        ("(-8.0) ** (1 / 3)", "expected a finite real number"),
        ("1e308 * 10", "expected a finite real number"),
        ("dd * 2", "unknown name 'dd'"),
    ],
)
def test_no_value_is_refused(text, reason):
    with pytest.raises(Refused, match=reason):
        value(checked(text), NAMES)


def test_strings_only_where_xacro_compares_them():
    checked("side == 'left' and d > 0 or not k", strings=True)
    checked("0.1 if side == 'left' else -0.1", strings=True)
    with pytest.raises(Refused, match="constant"):
        checked("'$' + '{'", strings=True)  # a $ in a value would be evaluated again
    assert names_in(checked("sqrt(d) * L + pi")) == {"d", "L", "pi"}


@settings(max_examples=100, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_number_text_reads_back_exactly_in_yaml(x):
    text = number_text(x)
    assert yaml.safe_load(f"v: {text}")["v"] == x
    assert strict_yaml.load(f"v: {text}")["v"] == x


YAML = """\
# a comment with ${not evaluated}
closed_loop: [[a, b]]   # ${nor here}
type: ['3d']
springs: {j: ${k * 1e4}, "h#${k}": 1.0}
beams:
  link: {end: j, E: ${7e10}, G: 2.6e+10, section: {shape: tube, d: ${d}, t: ${d / 10}}}
"""


def test_placeholders_are_replaced_outside_comments():
    arguments = Arguments({"d": 0.02, "k": 3.0})
    text = substitute(YAML, arguments, "x.yaml", "closure file")
    doc = yaml.safe_load(text)
    assert doc["springs"] == {"j": 30000, "h#3": 1.0}  # a quoted # is no comment
    assert doc["beams"]["link"]["section"] == {"shape": "tube", "d": 0.02, "t": 0.002}
    assert doc["beams"]["link"]["E"] == 7e10
    assert "${not evaluated}" in text and "${nor here}" in text
    assert arguments.used == {"d", "k"}


@pytest.mark.parametrize(
    ("line", "name", "match"),
    [
        ("springs: {j: ${kk}}", "kk", r"line 2: \$\{kk\}: unknown name 'kk'"),
        ("springs: {j: ${sqrt(-k)}}", None, r"line 2: \$\{sqrt\(-k\)\}: no value"),
        ("springs: {j: ${k.real}}", None, r"attribute access"),
        ("springs: {j: ${k * 2", None, r"line 2: a \$\{ without its closing \}"),
    ],
)
def test_placeholder_errors_name_file_line_and_name(tmp_path, line, name, match):
    path = tmp_path / "c.yaml"
    path.write_text(f"closed_loop: []\n{line}\n")
    with pytest.raises(ExpressionError, match=match) as info:
        read_closure_file(path, arguments=Arguments({"k": 3.0}))
    assert info.value.file == str(path) and info.value.line == 2 and info.value.name == name
    assert str(path) in str(info.value)


def test_arguments_are_checked_once():
    for bad in ({"d": float("nan")}, {"d": True}, {"d": "0.1"}, {"1d": 0.1}, {"_d": 1.0}):
        with pytest.raises(InvalidInputError, match="argument"):
            Arguments(bad)
    arguments = Arguments({"d": 1.0, "e2": 2.0})
    arguments.used.add("d")
    with pytest.raises(InvalidInputError, match=r"\['e2'\] used by none of \['m.urdf'\]"):
        arguments.check_used(["m.urdf"])

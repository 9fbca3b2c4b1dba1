"""The arithmetic of parametric model files, read as data: never run as Python.

A parametric model takes its numbers from named arguments (``load_model(path, closures,
args={"d": 0.02})``, ``--arg d=0.02``): a xacro file's ``<xacro:arg>`` values
(:mod:`closedloop.io.xacro_files`) and a closure file's ``${expr}`` placeholders, evaluated
here with the same names (:func:`substitute`). An expression is parsed by Python's
``ast`` and checked against a whitelist before any value is computed
(:func:`checked`), then computed by walking the checked tree in floating point
(:func:`value`); Python's ``eval`` never sees the text. The whitelist:

* numbers, and the names of the arguments and of the constants ``pi``, ``e``, ``tau``;
* ``+ - * / // **`` and unary ``+ -`` (``%`` is left out: on strings it formats);
* calls of the math functions of :data:`FUNCTIONS` by name (``sqrt(d)``, ``radians(30)``).

Nothing else: no attribute access (``x.real``), no subscripts, no other calls, no names
that begin with ``_``, no strings (a xacro file's expressions, which may compare
strings, use :func:`checked` with ``strings=True``). An unknown name, a missing argument,
a result that is not a finite real number (``sqrt(-1)``, ``1/0``, ``10.0**400``) is an
:class:`~closedloop.exceptions.ExpressionError` naming the file, the line and the name.
"""

from __future__ import annotations

import ast
import math
import operator
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

from closedloop.exceptions import ExpressionError, InvalidInputError

#: Functions an expression may call, by name (those of ``math`` that xacro also offers).
FUNCTIONS = {
    "abs": abs, "min": min, "max": max, "sqrt": math.sqrt, "exp": math.exp, "log": math.log,
    "log10": math.log10, "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin,
    "acos": math.acos, "atan": math.atan, "atan2": math.atan2, "sinh": math.sinh,
    "cosh": math.cosh, "tanh": math.tanh, "hypot": math.hypot, "radians": math.radians,
    "degrees": math.degrees, "floor": math.floor, "ceil": math.ceil, "pow": math.pow,
}  # fmt: skip
#: Named constants, beside the arguments (an argument of the same name takes precedence).
CONSTANTS = {"pi": math.pi, "e": math.e, "tau": math.tau}
#: Longest expression read (a guard against the parser's recursion on deep nesting).
MAX_EXPRESSION = 1000

_BINARY = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
    ast.Div: operator.truediv, ast.FloorDiv: operator.floordiv, ast.Pow: operator.pow,
}  # fmt: skip
_UNARY = {ast.UAdd: operator.pos, ast.USub: operator.neg}
#: What xacro's expressions may use besides (``strings=True``): comparisons, ``and``,
#: ``or``, ``not``, ``a if c else b`` and strings (no ``$`` in them).
_COMPARISONS = (ast.Eq, ast.NotEq, ast.Lt, ast.LtE, ast.Gt, ast.GtE)
#: A closure file's placeholder.
PLACEHOLDER = re.compile(r"\$\{([^}]*)\}")
#: A name an argument may have.
NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


class Refused(ValueError):
    """An expression outside the whitelist or without a value (the caller names the file and
    line: :class:`~closedloop.exceptions.ExpressionError`).

    Attributes:
        reason: what is wrong, e.g. ``unknown name 'dd'``.
        name: the unknown name, or None.
    """

    def __init__(self, reason: str, name: str | None = None):
        self.reason, self.name = reason, name
        super().__init__(reason)


def checked(text: str, strings: bool = False) -> ast.expr:
    """The syntax tree of expression ``text``, once every node of it is on the whitelist
    (module docstring; ``strings``: also comparisons, ``and``/``or``/``not``, conditional
    expressions and strings without ``$``, as xacro's conditions need).

    Raises:
        Refused: a syntax error, or the first construct off the whitelist.
    """
    if len(text) > MAX_EXPRESSION:
        raise Refused(f"{len(text)} characters; expected at most {MAX_EXPRESSION}")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except (SyntaxError, ValueError, RecursionError, MemoryError) as e:
        raise Refused(f"not an expression ({getattr(e, 'msg', e)})") from None
    _check(tree, strings)
    return tree


def _check(node: ast.AST, strings: bool) -> None:
    kind = type(node)
    unary = kind is ast.UnaryOp and (
        type(node.op) in _UNARY or (strings and type(node.op) is ast.Not)
    )
    if kind is ast.Constant:
        ok = isinstance(node.value, int | float) and not isinstance(node.value, bool)
        if strings and isinstance(node.value, bool | str):
            ok = "$" not in str(node.value)
        if not ok:
            raise Refused(f"the constant {node.value!r}; expected a number")
    elif kind is ast.Name:
        if node.id.startswith("_"):
            raise Refused(f"the name {node.id!r}: names beginning with _ are refused", node.id)
    elif kind is ast.BinOp and type(node.op) in _BINARY:
        _check(node.left, strings)
        _check(node.right, strings)
    elif unary:
        _check(node.operand, strings)
    elif kind is ast.Call:
        name = node.func.id if isinstance(node.func, ast.Name) else None
        if name not in FUNCTIONS or node.keywords:
            called = name or ast.unparse(node.func)
            raise Refused(f"a call of {called}(...); expected only the math functions "
                          f"{', '.join(FUNCTIONS)}", name)  # fmt: skip
        for arg in node.args:
            _check(arg, strings)
    elif strings and kind is ast.Compare and all(isinstance(o, _COMPARISONS) for o in node.ops):
        for part in (node.left, *node.comparators):
            _check(part, strings)
    elif strings and kind in (ast.BoolOp, ast.IfExp):
        for part in node.values if kind is ast.BoolOp else (node.test, node.body, node.orelse):
            _check(part, strings)
    else:
        raise Refused(f"{_what(node)} is refused; expected arithmetic on names and numbers")


def _what(node: ast.AST) -> str:
    """A refused construct, in words."""
    if isinstance(node, ast.Attribute):
        return f"attribute access (.{node.attr})"
    if isinstance(node, ast.BinOp):
        return f"the operator {ast.unparse(node).replace(' ', '')!r}"[:60]
    names = {ast.Subscript: "a subscript", ast.Lambda: "a lambda", ast.Compare: "a comparison",
             ast.BoolOp: "and/or", ast.IfExp: "a conditional expression"}  # fmt: skip
    return names.get(type(node), f"a {type(node).__name__}")


def value(tree: ast.expr, names: Mapping[str, float]) -> float:
    """The value of a :func:`checked` tree (numbers only), in floating point.

    Args:
        names: argument name -> value; the :data:`CONSTANTS` besides.

    Raises:
        Refused: an unknown name, a domain or overflow error, a result that is not a
            finite real number.
    """
    try:
        result = _value(tree, names)
    except ZeroDivisionError:
        raise Refused("a division by zero") from None
    except OverflowError:
        raise Refused("a result beyond the floating point range") from None
    except (ValueError, TypeError) as e:
        if isinstance(e, Refused):
            raise
        raise Refused(f"no value ({e})") from None
    if not isinstance(result, float) or not math.isfinite(result):
        raise Refused(f"the value {result!r}; expected a finite real number")
    return result


def _value(node: ast.expr, names: Mapping[str, float]):
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            raise Refused(f"the constant {node.value!r}; expected a number")
        return float(node.value)
    if isinstance(node, ast.Name):
        if node.id in names:
            return float(names[node.id])
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        known = ", ".join([*sorted(names), *CONSTANTS])
        raise Refused(f"unknown name {node.id!r}; expected one of {known}", node.id)
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_value(node.left, names), _value(node.right, names))
    if isinstance(node, ast.UnaryOp):
        return _UNARY[type(node.op)](_value(node.operand, names))
    if isinstance(node, ast.Call):
        return float(FUNCTIONS[node.func.id](*(_value(a, names) for a in node.args)))
    raise Refused(f"{_what(node)} has no number value")


def names_in(tree: ast.expr) -> set[str]:
    """The names an expression reads (not the functions it calls)."""
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and id(n) not in called}


def number_text(x: float) -> str:
    """``x`` as a number YAML 1.1 and xacro read back exactly: an integral value as an
    integer (``2``), else Python's shortest round-trip text with a decimal point in the
    mantissa (``1.0e-05``: PyYAML reads ``1e-05`` as a string)."""
    x = float(x)
    if x.is_integer() and abs(x) < 2.0**53:
        return str(int(x))
    text = repr(x)
    mantissa, e, exponent = text.partition("e")
    if e and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


class Arguments:
    """The arguments of a parametric model (``load_model(..., args=)``), checked once, with
    the numeric defaults of its xacro file's ``<xacro:arg>`` elements and the names its files use.

    Args:
        values: name -> value (SI), or None.

    Raises:
        InvalidInputError: a name that is not an identifier starting with a letter, or a
            value that is not a finite real number.
    """

    def __init__(self, values: Mapping[str, float] | None = None):
        if values is not None and not isinstance(values, Mapping):
            raise InvalidInputError(
                f"load_model: args must be a mapping name -> number, got {type(values).__name__}"
            )
        self.values: dict[str, float] = {}
        for name, v in (values or {}).items():
            if not isinstance(name, str) or not NAME.fullmatch(name):
                raise InvalidInputError(
                    f"load_model: argument name {name!r}; expected a name of letters, digits "
                    "and _, starting with a letter"
                )
            number = isinstance(v, int | float) and not isinstance(v, bool)
            if not number or not math.isfinite(v):
                raise InvalidInputError(
                    f"load_model: argument {name}={v!r}; expected a finite real number"
                )
            self.values[name] = float(v)
        self.defaults: dict[str, float] = {}
        self.used: set[str] = set()

    def names(self) -> dict[str, float]:
        """name -> value of the placeholders: the arguments over the xacro defaults."""
        return {**self.defaults, **self.values}

    def check_used(self, files: Iterable[str]) -> None:
        """Refuse arguments that no file used (a misspelt name would change nothing).

        Args:
            files: the model's files, for the message.

        Raises:
            InvalidInputError: the unused names.
        """
        unused = sorted(set(self.values) - self.used)
        if unused:
            used = ", ".join(sorted(self.used)) or "none"
            raise InvalidInputError(
                f"load_model: argument(s) {unused} used by none of {list(files)}; the names "
                f"they use: {used}"
            )


def substitute(text: str, arguments: Arguments, path: str | Path, what: str) -> str:
    """``text`` of a YAML file with each ``${expr}`` replaced by its value
    (:func:`number_text`), comments left as they are; the names read are added to
    ``arguments.used``.

    Args:
        text: the file's text.
        arguments: the names' values (:meth:`Arguments.names`).
        path, what: the file and its kind (``"closure file"``), for the messages.

    Raises:
        ExpressionError: a placeholder that is refused or has no value, or a ``${`` without
            its ``}``; the message names the file, the line and the name.
    """
    names = arguments.names()
    lines = text.split("\n")
    for n, line in enumerate(lines):
        code = line[: _comment_start(line)]
        if "${" not in code:
            continue
        where = f"{what} {str(path)!r}, line {n + 1}"
        pieces, end = [], 0
        for match in PLACEHOLDER.finditer(code):
            expression = match.group(1)
            try:
                tree = checked(expression)
                number = value(tree, names)
            except Refused as e:
                raise ExpressionError(f"{where}: ${{{expression}}}: {e.reason}", str(path),
                                      n + 1, e.name, expression) from None  # fmt: skip
            arguments.used |= names_in(tree) & set(arguments.values)
            pieces += [code[end : match.start()], number_text(number)]
            end = match.end()
        rest = code[end:]
        if "${" in rest:
            raise ExpressionError(f"{where}: a ${{ without its closing }}", str(path), n + 1)
        lines[n] = "".join(pieces) + rest + line[len(code) :]
    return "\n".join(lines)


def _comment_start(line: str) -> int:
    """Where a YAML comment starts in ``line`` (a ``#`` at its start or after white space,
    outside quotes), or its length."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return i
    return len(line)

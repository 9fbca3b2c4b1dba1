"""xacro files (``*.xacro``): parametric URDF, read as data.

:func:`expanded_urdf` expands a xacro file (the ``xacro`` package of the package index,
ROS's macro language) with its ``<xacro:arg>`` elements set from ``load_model(..., args=)`` into a
temporary URDF beside it, which the URDF reader then loads.

**Trust model.** xacro computes its ``${...}`` expressions with Python's ``eval``, builtins
removed and names beginning with ``__`` refused: that is not a sandbox. Its expressions
reach ``xacro.load_yaml`` (which reads any file), ``python.type``, ``python.vars`` and the
other builtins of its ``python`` namespace; its substitution arguments run ``$(eval
...)`` (Python again), read ``$(env ...)`` and ``$(find ...)``; ``<xacro:include>`` reads
any file, and an expression's value (a macro parameter) is evaluated once more when it
holds ``${``. So every file xacro will read is checked here first (:func:`scan`), and
xacro runs only on files that pass:

* the XML has no document type declaration (``<!DOCTYPE``, where entities are declared:
  the billion laughs, external entities);
* every ``${expr}`` (in attributes and text) is on the whitelist of
  :func:`closedloop.io.expressions.checked` with strings: names, numbers, strings without
  ``$``, arithmetic, comparisons, ``and``/``or``/``not``, conditional expressions and the
  math functions; no attribute access (``xacro.load_yaml``), no subscripts, no other calls,
  no ``%`` (which formats strings);
* the only substitution argument is ``$(arg NAME)``; every other ``$`` is refused
  (``$(eval ...)``, ``$(find ...)``, the escapes ``$${`` and ``$$(``), so that no value
  ever holds a ``$`` that a later evaluation would read as an expression;
* an included file is named by a literal path (no expression, no wildcard), found, and
  checked the same way; ``xacro:eval-comments`` is refused (it would evaluate comments).

What the whitelist cannot bound is the size of a value: ``${'a' * 10**9}`` still takes a
gigabyte. A xacro file is data that cannot run code or read files; it is not protected
against exhausting memory or time.
"""

from __future__ import annotations

import contextlib
import re
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from closedloop.exceptions import ExpressionError, ModelFileError
from closedloop.io.expressions import NAME, Arguments, Refused, checked, number_text

#: Most nested ``<xacro:include>`` elements followed.
MAX_INCLUDE_DEPTH = 32
#: ``$(arg NAME)``, the one substitution argument taken.
ARG = re.compile(r"\$\(\s*arg\s+([A-Za-z][A-Za-z0-9_]*)\s*\)")
#: A ``${expr}`` as xacro reads it (up to the first ``}``).
EXPRESSION = re.compile(r"\$\{([^}]*)\}")
#: Held while xacro runs: its state is global to its module.
_XACRO_LOCK = threading.Lock()


@dataclass
class XacroScan:
    """What :func:`scan` found in a xacro file and the files it includes.

    Attributes:
        files: the files read, the top one first.
        declared: ``<xacro:arg>`` name -> (file, line, default text).
        uses: ``$(arg NAME)`` name -> (file, line) of its first use.
    """

    files: list[Path] = field(default_factory=list)
    declared: dict[str, tuple[Path, int, str]] = field(default_factory=dict)
    uses: dict[str, tuple[Path, int]] = field(default_factory=dict)


def scan(path: Path) -> XacroScan:
    """Check a xacro file and the files it includes before xacro reads them (module
    docstring).

    Raises:
        ModelFileError: XML that is not well formed or declares a document type, an include
            that is computed, missing or circular, ``xacro:eval-comments``.
        ExpressionError: a refused ``${expr}`` or ``$``; names the file and the line.
    """
    found = XacroScan()
    _scan_file(path, found, ())
    return found


def _scan_file(path: Path, found: XacroScan, chain: tuple[Path, ...]) -> None:
    where = f"xacro file {str(path)!r}"
    if path.resolve() in chain:
        raise ModelFileError(f"{where} includes itself (through {[str(p) for p in chain]})")
    if len(chain) >= MAX_INCLUDE_DEPTH:
        raise ModelFileError(f"{where}: includes nested deeper than {MAX_INCLUDE_DEPTH}")
    try:
        text = path.read_bytes()
    except OSError as e:
        raise ModelFileError(f"{where} cannot be read: {e.strerror}") from None
    found.files.append(path)
    parser = expat.ParserCreate()
    pieces: list[tuple[str, int]] = []  # the text since the last element, (data, line)
    includes: list[tuple[str, int, bool]] = []

    def refuse_doctype(*_):
        raise ModelFileError(f"{where}, line {parser.CurrentLineNumber}: a document type "
                             "declaration (<!DOCTYPE ...>, where XML entities are declared) "
                             "is refused; expected plain XML")  # fmt: skip

    def flush() -> None:
        if pieces:
            _check_text("".join(p for p, _ in pieces), path, pieces[0][1], found)
            pieces.clear()

    def start(tag: str, attributes: dict) -> None:
        flush()
        line = parser.CurrentLineNumber
        for value in attributes.values():
            _check_text(value, path, line, found)
        if tag == "xacro:arg" and "name" in attributes:
            found.declared.setdefault(attributes["name"], (path, line, attributes.get("default")))
        if tag == "xacro:include":
            name = attributes.get("filename", "")
            optional = attributes.get("optional", "").strip().lower() in ("true", "1")
            includes.append((name, line, optional))

    def comment(data: str) -> None:
        if "xacro:eval-comments" in data:
            raise ModelFileError(
                f"{where}, line {parser.CurrentLineNumber}: xacro:eval-comments is refused "
                "(it evaluates comments)"
            )

    parser.StartDoctypeDeclHandler = refuse_doctype
    parser.EntityDeclHandler = refuse_doctype
    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: flush()
    parser.CharacterDataHandler = lambda data: pieces.append((data, parser.CurrentLineNumber))
    parser.CommentHandler = comment
    try:
        parser.Parse(text, True)
    except expat.ExpatError as e:
        raise ModelFileError(f"{where} is not well-formed XML: {e}") from None
    for name, line, optional in includes:
        included = _include(path, name, line, optional)
        if included is not None:
            _scan_file(included, found, (*chain, path.resolve()))


def _include(path: Path, name: str, line: int, optional: bool) -> Path | None:
    """The file of an ``<xacro:include filename=...>`` of ``path`` at ``line`` (relative
    to ``path``'s folder), or None for a missing optional one."""
    where = f"xacro file {str(path)!r}, line {line}: xacro:include filename {name!r}"
    if not name or "$" in name or re.search(r"[*?[]", name):
        raise ModelFileError(f"{where}; expected a literal path (no expression, no wildcard)")
    target = Path(name) if Path(name).is_absolute() else path.parent / name
    if not target.is_file():
        if optional:
            return None
        raise ModelFileError(f"{where} does not exist or is not a file")
    return target


def _check_text(text: str, path: Path, line: int, found: XacroScan) -> None:
    """Check every ``$`` of an attribute value or a text that starts at ``line``."""
    at = text.find("$")
    while at >= 0:
        here = line + text.count("\n", 0, at)
        expression, arg = EXPRESSION.match(text, at), ARG.match(text, at)
        if expression is not None:
            try:
                checked(expression.group(1), strings=True)
            except Refused as e:
                raise ExpressionError(
                    f"xacro file {str(path)!r}, line {here}: ${{{expression.group(1)}}}: "
                    f"{e.reason}",
                    str(path),
                    here,
                    e.name,
                    expression.group(1),
                ) from None
            end = expression.end()
        elif arg is not None:
            found.uses.setdefault(arg.group(1), (path, here))
            end = arg.end()
        else:
            shown = text[at : at + 20]
            raise ExpressionError(
                f"xacro file {str(path)!r}, line {here}: {shown!r}: a $ that starts neither "
                "${expression} nor $(arg NAME) is refused (no $(eval), $(find), $(env), "
                "no $$ escapes)", str(path), here
            )  # fmt: skip
        at = text.find("$", end)


def declare_arguments(found: XacroScan, arguments: Arguments) -> None:
    """Record the xacro file's arguments in ``arguments``: those it declares or uses are
    used; a declared default that is a number is a default of the closure file's
    placeholders.

    Raises:
        ExpressionError: a ``$(arg NAME)`` whose NAME is neither given nor declared with a
            default (the missing argument, its file and line).
    """
    for name, (path, line, default) in found.declared.items():
        if not NAME.fullmatch(name):
            raise ModelFileError(f"xacro file {str(path)!r}, line {line}: xacro:arg name "
                                 f"{name!r}; expected letters, digits and _")  # fmt: skip
        if default is None and name not in arguments.values:
            raise ExpressionError(f"xacro file {str(path)!r}, line {line}: xacro:arg {name!r} "
                                  "has no default; give its value in args (--arg "
                                  f"{name}=VALUE)", str(path), line, name)  # fmt: skip
        try:
            arguments.defaults[name] = float(default)
        except (TypeError, ValueError):
            pass
    for name, (path, line) in found.uses.items():
        if name not in arguments.values and name not in found.declared:
            raise ExpressionError(
                f"xacro file {str(path)!r}, line {line}: $(arg {name}): missing argument "
                f"{name!r}; give it in args (--arg {name}=VALUE) or declare it with "
                "<xacro:arg name=... default=...>", str(path), line, name
            )  # fmt: skip
    arguments.used |= set(found.declared) | set(found.uses)


def expand(path: Path, arguments: Arguments) -> str:
    """The URDF text of xacro file ``path`` with its arguments set, once :func:`scan` has
    checked the files (module docstring).

    Raises:
        ModelFileError: the xacro package is missing, or xacro fails (its message, on one
            line, after the file's name).
        ExpressionError: see :func:`scan` and :func:`declare_arguments`.
    """
    try:
        import xacro
    except ImportError:
        raise ModelFileError(
            f"xacro file {str(path)!r}: reading xacro files needs the xacro package "
            "(pip install xacro)"
        ) from None
    declare_arguments(scan(path), arguments)
    mappings = {name: number_text(v) for name, v in arguments.values.items()}
    with _XACRO_LOCK:  # xacro keeps its files, arguments and symbols in module globals
        try:
            doc = xacro.process_file(str(path.resolve()), mappings=mappings, verbosity=0)
        except Exception as e:  # xacro's own errors are of several types
            message = " ".join(str(e).split()) or type(e).__name__
            raise ModelFileError(f"xacro file {str(path)!r}: {message}") from None
        finally:
            xacro.all_includes.clear()  # xacro lists every file it included, for ever
    return doc.toxml()


@contextlib.contextmanager
def expanded_urdf(path: Path, arguments: Arguments):
    """A temporary URDF file of xacro file ``path`` (:func:`expand`), removed at the end of
    the block: beside it, so that relative mesh paths resolve (in the temporary folder
    where its folder cannot be written)."""
    urdf = expand(path, arguments)
    try:
        handle = tempfile.NamedTemporaryFile(
            "w", suffix=".urdf", dir=path.parent, prefix=f".{path.name}-", delete=False
        )
    except OSError:  # a folder that cannot be written: package:// paths still resolve
        handle = tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False)
    try:
        with handle:
            handle.write(urdf)
        yield Path(handle.name)
    finally:
        Path(handle.name).unlink(missing_ok=True)

"""Cross-references of the docstrings: a name means what it means in the module that wrote it.

A docstring is written in its module, where ``:class:`InvalidInputError``` or ``:data:`IK_TOL```
name what the module imports or defines; it is rendered under the name it is documented by
(``closedloop.inverse_kinematics`` on an API page, whose context is ``closedloop``), where
Sphinx would not find them. Two hooks make such a reference resolve to the documented object
it names in Python, and leave any other unresolved (a warning, an error in CI):

* :func:`alias_exported_names`: each top-level name of a package (``closedloop.compliance``)
  is also reachable under the name of the module that defines it
  (``closedloop.elastostatics.compliance.compliance``), where the module page does not
  document it again;
* :func:`resolve_in_source_module`: a reference Sphinx did not find is looked up as Python
  would in the module whose docstring holds it.

A docstring's pointer to "the module docstring" (how the module works, the choices it makes)
becomes a link to the module's page, where that docstring is rendered
(:func:`link_module_docstrings`).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import inspect
import re
import sys
from types import ModuleType

from docutils import nodes
from sphinx import addnodes

PACKAGES = ("closedloop", "cahyman_pin")


@functools.cache
def exported_names() -> dict[str, str]:
    """Top-level name of each exported object by its defining module's name
    (``closedloop.elastostatics.compliance.compliance`` -> ``closedloop.compliance``): the
    module of a class or function itself, that of the package's table of exports for a
    constant."""
    names = {}
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        for name, module in package._EXPORTS.items():
            if name in package.__all__ and name not in getattr(package, "_SUBMODULES", ()):
                home = importlib.util.resolve_name(module, package_name)
                obj = getattr(importlib.import_module(home), name)
                if inspect.isclass(obj) or inspect.isroutine(obj):
                    home = obj.__module__
                names[f"{home}.{name}"] = f"{package_name}.{name}"
    return names


def alias_exported_names(app, env) -> None:
    """Each documented top-level name also under its defining module's name."""
    py = env.get_domain("py")
    for full, public in exported_names().items():
        entry = py.objects.get(public)
        if entry is not None and full not in py.objects:
            py.objects[full] = entry._replace(aliased=True)


def object_at(path: str):
    """The object of a dotted ``path`` (a module, then attributes), or None."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            obj = getattr(obj, part, None)
        return obj
    return None


def source_module(node: nodes.Node) -> str | None:
    """The module whose docstring holds ``node``: that of the innermost documented object
    around it (the defining module of ``closedloop.compliance``), else the page's module."""
    desc = node.parent
    while desc is not None and not isinstance(desc, addnodes.desc):
        desc = desc.parent
    if desc is None:
        return node.get("py:module")
    signature = next(iter(desc.findall(addnodes.desc_signature)), None)
    if signature is None or not signature.get("module"):
        return node.get("py:module")
    module, top = signature["module"], signature["fullname"].split(".")[0]
    homes = {public: full for full, public in exported_names().items()}
    if f"{module}.{top}" in homes:
        return homes[f"{module}.{top}"].rpartition(".")[0]
    defining = getattr(object_at(f"{module}.{top}"), "__module__", None)
    return defining if isinstance(defining, str) else module


def documented_name(obj) -> str | None:
    """The name ``obj`` is documented by: its top-level name if a package exports it, else
    its module and qualified name; None for an object without them."""
    if isinstance(obj, ModuleType):
        return obj.__name__
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not isinstance(module, str) or not isinstance(qualname, str) or "<" in qualname:
        return None
    head, _, rest = qualname.partition(".")
    name = exported_names().get(f"{module}.{head}", f"{module}.{head}")
    return f"{name}.{rest}" if rest else name


def attribute(obj, name: str):
    """``obj.name``, a submodule of a package included; None if there is none."""
    value = getattr(obj, name, None)
    if value is None and isinstance(obj, ModuleType):
        try:
            value = importlib.import_module(f"{obj.__name__}.{name}")
        except ImportError:
            return None
    return value


def value_homes(name: str, value) -> list[str]:
    """Where the packages' modules define or import ``value`` under ``name`` (a constant,
    which has no module of its own to tell)."""
    return [
        f"{module_name}.{name}"
        for module_name, module in list(sys.modules.items())
        if module_name.partition(".")[0] in PACKAGES
        and module is not None
        and vars(module).get(name, None) is value
    ]


def candidates(target: str, module_name: str, known) -> list[str]:
    """Documented names (``known(name)``) ``target`` may mean in the module ``module_name``,
    the best first: a name the module defines; the object Python finds there (defined or
    imported), with the attributes after it, the longest match first; a constant under the
    name of the one module that documents it among those that share it."""
    found = [f"{module_name}.{target}"]
    parts = target.split(".")
    obj = attribute(importlib.import_module(module_name), parts[0])
    if obj is None:
        obj = object_at(parts[0])
    matches, shared = [], []
    for i in range(len(parts)):
        if i:
            obj = attribute(obj, parts[i])
        if obj is None:
            break
        rest = parts[i + 1 :]
        if not (inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj)):
            shared = [".".join([h, *rest]) for h in value_homes(parts[i], obj)]
            shared = [name for name in shared if known(name)]
            break
        name = documented_name(obj)
        if name is not None:
            matches.append(".".join([name, *rest]))
    found += matches[::-1] + (shared if len(shared) == 1 else [])
    return [name for name in found if known(name)]


def resolve_in_source_module(app, env, node, contnode):
    """Resolve a Python reference Sphinx did not find in the module that wrote it
    (``missing-reference``); None leaves it unresolved."""
    if node.get("refdomain") != "py":
        return None
    module_name = source_module(node)
    if not module_name or module_name.partition(".")[0] not in PACKAGES:
        return None
    py = env.get_domain("py")
    target = node["reftarget"].lstrip(".~")
    found = candidates(target, module_name, lambda name: name in py.objects or name in py.modules)
    if not found:
        return None
    retry = node.deepcopy()
    retry["reftarget"], retry["refspecific"] = found[0], False
    return py.resolve_xref(
        env, node["refdoc"], app.builder, node["reftype"], found[0], retry, contnode
    )


#: "module docstring" (or "module doc"), possibly broken across lines, not already in markup.
MODULE_DOCSTRING = re.compile(r"(?<![`<])\bmodule(\s+)doc(string)?\b")


def defining_module(name: str, obj) -> str | None:
    """The module whose docstring a pointer in the docstring of ``obj``, documented as
    ``name``, means: that of the function, class or property, else (a constant) the module of
    the name it is exported as, else the longest module prefix of ``name``."""
    target = obj.fget if isinstance(obj, property) else obj
    module = getattr(target, "__module__", None) if callable(target) else None
    if isinstance(module, str) and module.partition(".")[0] in PACKAGES:
        return module
    homes = {public: full for full, public in exported_names().items()}
    name = homes.get(name, name)
    parts = name.split(".")
    for i in range(len(parts) - 1, 0, -1):
        if ".".join(parts[:i]) in sys.modules:
            return ".".join(parts[:i])
    return None


def link_module_docstrings(what: str, name: str, obj, lines: list[str]) -> None:
    """Make each pointer to "the module docstring" in ``lines`` (reST, in place) a link to
    the page of the module that wrote it (:func:`defining_module`)."""
    if what == "module":
        return
    module = defining_module(name, obj)
    if module is None:
        return
    text = "\n".join(lines)
    linked = MODULE_DOCSTRING.sub(lambda m: f":mod:`module{m[1]}doc{m[2] or ''} <{module}>`", text)
    if linked != text:
        lines[:] = linked.split("\n")

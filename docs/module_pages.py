"""The module reference: a page for every module of ``closedloop`` and ``cahyman_pin``.

Each page (``api/modules/<module>``, written at build time, linked from the package layout
page) renders the module's docstring and the public members it defines (not those it imports,
even if its ``__all__`` lists them), except those a hand-written API page documents
(``docs/api/*.md``), to which it links instead: a name is documented once.

The pages are orphans (in no table of contents): the sidebar of every page stays the
hand-written one, which keeps the build fast.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from pathlib import Path

from references import PACKAGES, exported_names

API = Path(__file__).resolve().parent / "api"
PAGES = API / "modules"
#: An autodoc directive of a hand-written API page, and the name it documents.
AUTODOC = re.compile(
    r"^\.\. auto(?:function|class|exception|data|method|attribute)::\s+(\S+)", re.M
)


def module_names() -> list[str]:
    """The modules of :data:`PACKAGES`, sorted: not the packages, not ``__main__`` (which runs
    its command when imported)."""
    names = []
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        prefix = f"{package_name}."
        names += [
            m.name
            for m in pkgutil.walk_packages(package.__path__, prefix)
            if not m.ispkg and not m.name.endswith(".__main__")
        ]
    return sorted(names)


def hand_written() -> set[str]:
    """The names the hand-written API pages document."""
    return {name for page in API.glob("*.md") for name in AUTODOC.findall(page.read_text())}


def page_text(module_name: str, exported: dict[str, str], documented: set[str]) -> str:
    """The reST of the page of ``module_name``."""
    module = importlib.import_module(module_name)
    elsewhere = {}
    for name in vars(module):
        full = f"{module_name}.{name}"
        public = exported.get(full, full)
        if not name.startswith("_") and public in documented:
            elsewhere[name] = public
    lines = [":orphan:", "", module_name, "=" * len(module_name), ""]
    lines += [f".. automodule:: {module_name}", "   :members:", "   :ignore-module-all:"]
    if elsewhere:
        lines.append(f"   :exclude-members: {', '.join(elsewhere)}")
        links = ", ".join(f":py:obj:`{public}`" for public in elsewhere.values())
        lines += ["", ".. rubric:: Documented on the API pages", "", f"{links}."]
    return "\n".join(lines) + "\n"


def write_module_pages(app) -> None:
    """Write the pages (a file only when its text changed: Sphinx rereads what is newer) and
    remove those of modules that are gone."""
    PAGES.mkdir(exist_ok=True)
    exported, documented = exported_names(), hand_written()
    names = module_names()
    for page in PAGES.glob("*.rst"):
        if page.stem not in names:  # a module removed or renamed
            page.unlink()
    for module_name in names:
        page = PAGES / f"{module_name}.rst"
        text = page_text(module_name, exported, documented)
        if not page.is_file() or page.read_text() != text:
            page.write_text(text)

"""Sphinx configuration of the closedloop documentation (``pip install ".[docs]"``).

Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html``. The gallery
(``examples/``) runs at build time; set ``CLOSEDLOOP_DOCS_NO_GALLERY=1`` to skip it while
editing prose.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib
from sphinx.ext.napoleon.docstring import GoogleDocstring

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "docs"))  # gallery_order, module_pages, references

from module_pages import write_module_pages  # noqa: E402
from references import (  # noqa: E402
    alias_exported_names,
    link_module_docstrings,
    resolve_in_source_module,
)

import closedloop  # noqa: E402
from closedloop.common.blas import single_threaded_blas  # noqa: E402

single_threaded_blas()  # the examples run many small queries in this process

project = "closedloop"
author = "The closedloop authors"
copyright = "2026, The closedloop authors"
release = closedloop.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinxarg.ext",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "gallery/*.ipynb", "gallery/*.py", "gallery/*.zip"]
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented"
autodoc_default_options = {"members": True, "show-inheritance": False}
#: Google-style sections through :func:`google_docstring` (Napoleon's own hook off).
napoleon_google_docstring = False
napoleon_numpy_docstring = False
napoleon_use_rtype = False
#: Every cross-reference must resolve (a warning otherwise, an error in CI), but those to
#: names outside the two packages that have no inventory on a machine without network.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"numpy\..*"),  # NumPy's arrays, random generators, linalg errors
    (r"py:.*", r"(pinocchio|pin)\..*"),  # Pinocchio's models, data, SE3 (Boost.Python)
    (r"py:.*", r"collections\.abc\..*"),  # Sequence, Mapping, Callable, Iterable
    (r"py:.*", r"meshcat\..*"),  # the viewer's server and visualizer
    (r"py:.*", r"yaml\..*"),  # PyYAML's errors
    (r"py:class", r"argparse\..*"),  # parsers, namespaces, argument type errors
    (r"py:class", r"pathlib\.Path"),
    (r"py:class", r"concurrent\.futures\..*"),  # executors and futures
]
#: No "smart" quotes or dashes: docutils would turn the ``--`` of an option into an en dash
#: in the command-line reference (argparse's help and epilogs), and a copied command fails.
smartquotes = False
suppress_warnings = ["myst.domains"]

html_theme = "furo"
html_title = f"closedloop {release}"
html_static_path = ["_static"]
html_favicon = "_static/favicon.png"

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "gallery_order.TeachingOrder",  # for teaching
    "plot_gallery": "False" if os.environ.get("CLOSEDLOOP_DOCS_NO_GALLERY") else "True",
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    # the examples that use a public name, listed on its API page (``minigallery``)
    "backreferences_dir": "api/generated",
    "doc_module": ("closedloop", "cahyman_pin"),
}

#: The viewer's self-contained page of the four-bar, written at build time and embedded by
#: the four-bar example (``_views/`` is a build product, not in git).
VIEWS = Path(__file__).resolve().parent / "_views"
VIEWS.mkdir(exist_ok=True)
html_static_path.append("_views")


#: MathJax served with the site (the pages open offline): the ``django-static-mathjax``
#: wheel's MathJax 3, of which the one-file TeX component and its fonts are copied.
mathjax_path = "mathjax/tex-chtml.js"


def copy_mathjax() -> None:
    """Copy MathJax's TeX component and its CommonHTML fonts into ``_views/mathjax``."""
    spec = importlib.util.find_spec("mathjax")
    if spec is None or spec.origin is None:
        raise RuntimeError("MathJax not installed: pip install '.[docs]'")
    es5 = Path(spec.origin).parent / "static" / "mathjax" / "es5"
    target = VIEWS / "mathjax"
    fonts = target / "output" / "chtml" / "fonts"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(es5 / "output" / "chtml" / "fonts", fonts)
    shutil.copy2(es5 / "tex-chtml.js", target / "tex-chtml.js")


def write_views(app) -> None:
    """Write the viewer pages the gallery embeds (``closedloop view ... --html``) and the
    MathJax files."""
    copy_mathjax()
    page = VIEWS / "fourbar_view.html"
    command = [sys.executable, "-m", "closedloop", "view", "fourbar", "--frame", "P"]
    command += ["--actuated", "0.3", "--force", "3", "0", "-20", "--html", str(page)]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    subprocess.run(command, check=True, env=env, capture_output=True, text=True)


class ProseAttributeDocstring(GoogleDocstring):
    """Napoleon's Google style, except that the first line of a data or attribute docstring
    stays text: the project's ``#:`` comments are prose, which Napoleon would split at their
    first colon into a type and a description."""

    def _consume_inline_attribute(self) -> tuple[str, list[str]]:
        lines = [self._lines.next(), *self._dedent(self._consume_to_end())]
        return "", self.__class__(lines, self._config).lines()


def google_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """Convert a docstring's Google-style sections to reST, in place (autodoc's event), its
    pointers to the module docstring made links to the module's page."""
    lines[:] = ProseAttributeDocstring(lines, app.config, app, what, name, obj, options).lines()
    link_module_docstrings(what, name, obj, lines)


def skip_tuple_fields(app, what, name, obj, skip, options) -> bool | None:
    """Skip a NamedTuple's fields ("Alias for field number 0"): its Attributes section
    documents them."""
    return True if (getattr(obj, "__doc__", None) or "").startswith("Alias for field") else None


def setup(app):
    app.connect("autodoc-process-docstring", google_docstring)
    app.connect("autodoc-skip-member", skip_tuple_fields)
    app.connect("builder-inited", write_views)
    app.connect("builder-inited", write_module_pages)
    app.connect("env-updated", alias_exported_names)
    app.connect("missing-reference", resolve_in_source_module)

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

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "docs"))  # gallery_order, the gallery's sort key

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
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
nitpicky = False
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


def setup(app):
    app.connect("builder-inited", write_views)

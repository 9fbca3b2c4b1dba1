"""The built documentation site in a real browser (headless Chromium).

The site is built by ``.ci/run`` (``python -m sphinx -n -W --keep-going -b html docs
docs/_build/html``), which sets ``CLOSEDLOOP_DOCS_HTML`` to the build folder. Without that
variable the tests are skipped, saying so; with it set and no built site there, they fail.
The pages are served on 127.0.0.1 from the build folder and loaded over the DevTools
protocol: the index page, the API page of ``closedloop.compliance``, the four-bar gallery
page (with the viewer's page embedded), the theory page, the search page, the task index
and a guide page with its glossary links. On each page: no JavaScript exception or console
error, no request that fails, every image decoded and every embedded page loaded; the
equations typeset offline; the search page finds ``compliance``; the task index lists its
tasks, each linked to the guide, every link of it reaches an existing page and anchor, and
its commands read as typed (``--frame``, never an en dash); a glossary link of the guide
lands on its term. And every public name of ``closedloop`` and ``cahyman_pin`` has an
entry in the API reference; the command-line reference lists every option of every
subcommand of both commands.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import http.server
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest
from helpers import FLAGS, browser, devtools_caller, devtools_page

import cahyman_pin
import closedloop

ENV = "CLOSEDLOOP_DOCS_HTML"
PAGE_TIMEOUT = 60.0  # [s] per page, Chromium's start included
#: Evaluated in the page once loaded: images not decoded, frames not loaded (an embedded
#: viewer page must have run its script: ``viewer`` defined), the number of each.
PROBE = """(function () {
  const images = Array.from(document.images);
  const frames = Array.from(document.querySelectorAll('iframe'));
  const badImages = images.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src);
  const badFrames = frames.filter(f => {
    const d = f.contentDocument;
    return !(d && d.readyState === 'complete' && f.contentWindow.viewer !== undefined);
  }).map(f => f.src);
  return JSON.stringify({images: images.length, frames: frames.length,
                         badImages: badImages, badFrames: badFrames});
})()"""
#: True once the search results are listed (Sphinx's search fills #search-results).
SEARCH_DONE = """(function () {
  const box = document.getElementById('search-results');
  if (!box) return null;
  const links = Array.from(box.querySelectorAll('ul li a')).map(a => a.textContent);
  const status = box.querySelector('p');
  return (links.length || (status && /did not match|found/i.test(status.textContent)))
    ? JSON.stringify(links) : null;
})()"""


@pytest.fixture(scope="module")
def site() -> Path:
    folder = os.environ.get(ENV)
    if not folder:
        pytest.skip(
            f"documentation site tests skipped: {ENV} is not set; build the site with "
            "`python -m sphinx -b html docs docs/_build/html` and set "
            f"{ENV}=docs/_build/html (.ci/run does both)"
        )
    site = Path(folder)
    assert (site / "index.html").is_file(), f"{ENV}={folder}: no built site (index.html)"
    return site


@pytest.fixture(scope="module")
def server(site):
    """Base URL of the site served on 127.0.0.1 (an ephemeral port) for the module."""
    handler = functools.partial(QuietHandler, directory=str(site))
    httpd = Server(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    httpd.shutdown()
    httpd.server_close()


class Server(http.server.ThreadingHTTPServer):
    def handle_error(self, request, client_address) -> None:
        """A browser closed before a reply was sent (its pages are done): not an error."""
        if not isinstance(sys.exc_info()[1], ConnectionError):
            super().handle_error(request, client_address)


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # no request lines in the test output
        pass


async def _visit(url: str, profile: Path, done: str | None) -> dict:
    """Load ``url``; (events of errors, the probe's report, ``done``'s value if given)."""
    proc = subprocess.Popen(
        [browser(), *FLAGS, "--no-proxy-server", f"--user-data-dir={profile}", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + PAGE_TIMEOUT
    try:
        ws = await devtools_page(proc, profile, deadline)
        errors, failed = [], []

        def record(message: dict) -> None:
            method, params = message.get("method"), message.get("params", {})
            if method == "Runtime.exceptionThrown":
                errors.append(params["exceptionDetails"].get("exception", {}).get("description")
                              or params["exceptionDetails"].get("text"))  # fmt: skip
            elif method == "Runtime.consoleAPICalled" and params.get("type") == "error":
                errors.append(" ".join(str(a.get("value", a.get("description"))) for a in
                                       params.get("args", [])))  # fmt: skip
            elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
                errors.append(f"{params['entry']['text']} ({params['entry'].get('url')})")
            elif method == "Network.loadingFailed" and not params.get("canceled"):
                failed.append(params.get("errorText"))
            elif method == "Network.responseReceived" and params["response"]["status"] >= 400:
                failed.append(f"{params['response']['status']} {params['response']['url']}")

        call = devtools_caller(ws, record)

        async def evaluate(expression: str):
            message = await call("Runtime.evaluate", expression=expression, returnByValue=True)
            return message.get("result", {}).get("result", {}).get("value")

        for domain in ("Runtime", "Log", "Network", "Page"):
            await call(f"{domain}.enable")
        await call("Page.navigate", url=url)
        while await evaluate("document.readyState") != "complete" or await evaluate(
            "location.href"
        ) in (None, "about:blank"):
            assert time.monotonic() < deadline, f"{url} did not load"
            await asyncio.sleep(0.05)
        value = None
        while True:  # embedded pages finish their scripts; the search fills its list
            report = json.loads(await evaluate(PROBE))
            value = await evaluate(done) if done else None
            if not report["badImages"] and not report["badFrames"] and (value or not done):
                break
            if time.monotonic() > deadline:
                break
            await asyncio.sleep(0.1)
        await asyncio.sleep(0.3)  # late errors
        await evaluate("1")  # reads the events that came meanwhile
        ws.close()
        return {"errors": errors, "failed": failed, "report": report, "value": value}
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the browser's own process group only
        proc.wait()


def visit(url: str, profile: Path, done: str | None = None) -> dict:
    return asyncio.run(asyncio.wait_for(_visit(url, profile, done), PAGE_TIMEOUT + 10))


def check_page(result: dict, url: str) -> None:
    assert not result["errors"], (url, result["errors"])
    assert not result["failed"], (url, result["failed"])
    assert not result["report"]["badImages"], (url, result["report"])
    assert not result["report"]["badFrames"], (url, result["report"])


def test_index_page_loads_without_errors(site, server, tmp_path):
    url = server + "index.html"
    result = visit(url, tmp_path)
    check_page(result, url)
    assert result["report"]["images"] >= 1  # the picture of the front page


def test_api_page_of_compliance_loads_and_documents_it(site, server, tmp_path):
    text = (site / "api" / "queries.html").read_text()
    assert 'id="closedloop.compliance"' in text and 'id="closedloop.compliances"' in text
    url = server + "api/queries.html"
    check_page(visit(url, tmp_path), url)


def test_gallery_page_shows_its_figure_and_the_embedded_viewer(site, server, tmp_path):
    url = server + "gallery/plot_fourbar.html"
    result = visit(url, tmp_path)
    check_page(result, url)
    assert result["report"]["images"] >= 1  # the figure of the example
    assert result["report"]["frames"] == 1  # the viewer's page, loaded with its scene


def test_theory_page_typesets_its_equations_offline(site, server, tmp_path):
    url = server + "theory.html"
    result = visit(url, tmp_path, "document.querySelectorAll('mjx-container').length || null")
    check_page(result, url)
    assert result["value"] and result["value"] >= 10, result["value"]  # MathJax ran


def test_search_finds_compliance(site, server, tmp_path):
    url = server + "search.html?q=compliance"
    result = visit(url, tmp_path, SEARCH_DONE)
    check_page(result, url)
    links = json.loads(result["value"] or "[]")
    assert links, "the search for 'compliance' listed no page"
    assert any("ompliance" in link for link in links), links


def test_every_public_name_has_an_api_entry(site):
    """Each name of ``closedloop.__all__`` and ``cahyman_pin.__all__`` is documented on an
    API page (a public submodule by its members)."""
    text = "".join(p.read_text() for p in (site / "api").glob("*.html"))
    ids = set(re.findall(r'id="([^"]+)"', text))
    missing = [
        f"{package.__name__}.{n}"
        for package in (closedloop, cahyman_pin)
        for n in package.__all__
        if f"{package.__name__}.{n}" not in ids
        and not any(i.startswith(f"{package.__name__}.{n}.") for i in ids)
    ]
    assert not missing, f"public names without an entry in docs/api/: {missing}"


#: An en or em dash where a command's option would start (`` –frame``): smart dashes
#: from docutils, or typed into a docstring, make a copied command fail.
SMART_DASH_OPTION = re.compile(r"(?:^|[\s>(\[])[\u2013\u2014][A-Za-z]")


def test_no_smart_dash_before_an_option_name(site):
    bad = []
    for page in sorted(site.rglob("*.html")):
        text = re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8"))
        bad += [f"{page.relative_to(site)}: ...{text[max(m.start() - 30, 0):m.end() + 20]!r}"
                for m in SMART_DASH_OPTION.finditer(text)]  # fmt: skip
    assert not bad, "\n".join(bad[:20])


def cli_sections(site: Path) -> dict[str, str]:
    """The HTML of each section of the command-line reference by its id, up to the next
    section (``closedloop-stiffness``, ``closedloop-stiffness-named-arguments``, ...)."""
    chunks = (site / "cli.html").read_text(encoding="utf-8").split('<section id="')[1:]
    return {chunk.split('"', 1)[0]: chunk for chunk in chunks}


@pytest.mark.parametrize("prog", ["closedloop", "cahyman"])
def test_the_cli_reference_shows_every_subcommand_s_options(site, prog):
    """Each subcommand of both commands has its section on the command-line reference,
    every option of it listed there (the command's own parser holds the subcommands'
    help lines only: the page is built from :func:`reference_parser`)."""
    from cahyman_pin.cli import reference_parser as cahyman_reference
    from closedloop.cli.app import reference_parser as closedloop_reference

    parser = {"closedloop": closedloop_reference, "cahyman": cahyman_reference}[prog]()
    (action,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sections = cli_sections(site)
    missing = []
    for name, sub in action.choices.items():
        html = "".join(v for k, v in sections.items() if k == f"{prog}-{name}"
                       or k.startswith(f"{prog}-{name}-"))  # fmt: skip
        assert html, f"cli.html has no section for {prog} {name}"
        missing += [
            f"{prog} {name} {option}"
            for a in sub._actions
            if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)
            for option in a.option_strings
            if option.startswith("--") and f"<kbd>{option}</kbd>" not in html
        ]
    assert not missing, missing
    examples = {"closedloop": ("stiffness", "--frame"), "cahyman": ("map", "--param")}
    name, option = examples[prog]
    assert f"<kbd>{option}</kbd>" in sections[f"{prog}-{name}-named-arguments"]


#: The task index as the browser shows it, once its content is there: its tasks (the
#: third-level sections, each with its links), every link of the page (resolved by the
#: browser), the text of its command-line blocks as a reader selects and copies it, and any
#: error message the theme's style sheet draws (Furo draws one over a table of contents).
TASKS_READ = """(function () {
  const article = document.querySelector('article');
  if (!article || !article.querySelector('div.highlight-bash pre')) return null;
  const tasks = Array.from(article.querySelectorAll('section section section')).map(s => ({
    id: s.id, title: s.querySelector('h3').textContent.replace(/\u00b6|#$/g, '').trim(),
    links: Array.from(s.querySelectorAll('a[href]')).map(a => a.href)}));
  const links = Array.from(document.querySelectorAll('a[href]')).map(a => a.href);
  const code = Array.from(article.querySelectorAll('div.highlight-bash pre'))
    .map(p => p.textContent);
  const shown = Array.from(article.querySelectorAll('*'))  // the theme's warnings are drawn
    .map(e => getComputedStyle(e, '::before').content)     // by its style sheet, not text
    .filter(c => /error/i.test(c));
  return JSON.stringify({tasks: tasks, links: links, code: code, shown: shown});
})()"""
#: At least this many tasks on the task index (the page lists about twenty).
MIN_TASKS = 20
#: Smart dashes and quotes: a command copied with one of them fails.
SMART = re.compile("[\u2010-\u2015\u2018\u2019\u201c\u201d]")


def check_link(url: str, server: str, pages: dict) -> str | None:
    """Why ``url`` (an absolute URL the browser resolved) does not reach a page and anchor
    of the site served at ``server``, or None; ``pages`` caches the pages read (URL -> HTML).
    A link outside the site is not followed (the tests run offline)."""
    page, _, anchor = url.partition("#")
    if not page.startswith(server):
        return None
    if page not in pages:
        try:
            with urllib.request.urlopen(page, timeout=10) as reply:
                pages[page] = reply.read().decode("utf-8", "replace")
        except OSError as error:  # urllib's HTTPError (a 404) is an OSError
            pages[page] = None
            return f"{url}: {error}"
    if pages[page] is None:
        return f"{url}: the page does not load"
    anchor = urllib.parse.unquote(anchor)
    if anchor and f'id="{anchor}"' not in pages[page]:
        return f"{url}: no element with id {anchor!r} on the page"
    return None


def test_task_index_lists_its_tasks_with_working_links(site, server, tmp_path):
    url = server + "tasks.html"
    result = visit(url, tmp_path, TASKS_READ)
    check_page(result, url)
    assert result["value"], "the task index shows no command-line block"
    page = json.loads(result["value"])
    assert not page["shown"], page["shown"]  # an error drawn on the page (the theme's)
    tasks = page["tasks"]
    assert len(tasks) >= MIN_TASKS, [t["title"] for t in tasks]
    for task in tasks:  # each task: its guide section (and, where there is one, its example)
        assert any("/guide/" in link for link in task["links"]), task
    assert sum(any("/gallery/plot_" in link for link in t["links"]) for t in tasks) >= 15
    pages: dict = {}
    broken = [
        why for link in sorted(set(page["links"])) if (why := check_link(link, server, pages))
    ]
    assert not broken, "\n".join(broken)
    assert len(pages) >= 30  # the guide pages, the gallery, the glossary: all followed


def test_a_command_copied_from_the_task_index_reads_as_typed(site, server, tmp_path):
    """The text of the task index's command-line blocks, as the browser renders it: no
    smart dash or quote anywhere, the options with their two hyphens; a copied command
    is taken by the command line's parser."""
    from closedloop.cli.app import build_parser

    url = server + "tasks.html"
    result = visit(url, tmp_path, TASKS_READ)
    check_page(result, url)
    code = json.loads(result["value"])["code"]
    text = "\n".join(code)
    assert not SMART.findall(text), sorted(set(SMART.findall(text)))
    for option in ("--frame", "--joint-stiffness", "--q", "--actuated", "--force", "--out"):
        assert f" {option} " in text, option
    line = next(row for row in text.splitlines() if row.startswith("closedloop stiffness ur5 "))
    assert line == (
        "closedloop stiffness ur5 --frame tool0 --q 0 -1.0 1.5 -0.5 1.2 0.3 --joint-stiffness 1e4"
    )
    args = build_parser("stiffness").parse_args(shlex.split(line)[1:])
    assert (args.frame, args.joint_stiffness) == ("tool0", 1e4)


#: On a guide page: the link of a glossary term, once the page is there.
GLOSSARY_LINK = """(function () {
  const a = document.querySelector('article a[href*="glossary.html#term-rank-rule"]');
  return a ? a.href : null;
})()"""
#: On the glossary: the element that the address's anchor names, and the term it defines.
TERM_AT_ANCHOR = """(function () {
  const id = decodeURIComponent(location.hash.slice(1));
  const dt = id && document.getElementById(id);
  if (!dt) return null;
  let dd = dt.nextElementSibling;  // a term of several names: its other dt first
  while (dd && dd.tagName !== 'DD') dd = dd.nextElementSibling;
  return JSON.stringify({tag: dt.tagName, term: dt.firstChild.textContent.trim(),
                         definition: dd ? dd.textContent : ''});
})()"""


def test_a_glossary_link_of_the_guide_lands_on_its_term(site, server, tmp_path):
    url = server + "guide/conditioning.html"
    result = visit(url, tmp_path, GLOSSARY_LINK)
    check_page(result, url)
    link = result["value"]
    assert link and link.startswith(server + "glossary.html#term-"), link
    (tmp_path / "glossary").mkdir()  # a fresh browser profile
    landed = visit(link, tmp_path / "glossary", TERM_AT_ANCHOR)
    check_page(landed, link)
    assert landed["value"], f"{link}: the glossary has no element of the link's anchor"
    term = json.loads(landed["value"])
    assert term["tag"] == "DT" and term["term"] == "rank rule", term
    assert "RANK_RTOL" in term["definition"], term

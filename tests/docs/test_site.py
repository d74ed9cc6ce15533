"""The documentation site as its readers get it: built with the README's command (``.ci/run``
builds it before the tests; a missing build is made here), opened in a real browser
(Debian's headless Chromium, offline). The index, an API page and a tutorial load without a
console message; the API page's equations are typeset by MathJax (served with the site) and
the tutorial's figures are on the page; the site's search finds ``JPDA``; and every link of
the README into ``docs/`` names a page the site has."""

from __future__ import annotations

import functools
import http.server
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from tests.browser import CHROMIUM, open_in_chromium

REPO = Path(__file__).resolve().parents[2]
SITE = REPO / "docs" / "_build" / "html"
BUILD = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html", "docs",
         "docs/_build/html"]
# the theme logs what it does (its colour mode, the sidebar's scroll, the search field's
# focus) with console.log under its prefix "[PST]: "; Chromium prints console.log and
# console.error alike, so those lines are set aside by their prefix and any other fails
THEME_LOG = '"[PST]: '
browser = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine "
                             "(.ci/run installs it)")


@pytest.fixture(scope="module")
def site() -> Path:
    if not (SITE / "index.html").exists():
        subprocess.run(BUILD, cwd=REPO, check=True, timeout=900)
    return SITE


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # the test's output is the browser's, not a log
        pass


@pytest.fixture(scope="module")
def served(site) -> str:
    """The site served on loopback, as a reader hosting it would (a page opened from disk
    cannot fetch the search's result summaries): its root address. Stopped afterwards."""
    handler = functools.partial(QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(10)


def messages(console: list[str]) -> list[str]:
    """The console's messages but the theme's own log lines."""
    return [m for m in console if not m.startswith(THEME_LOG)]


def test_the_readme_builds_the_site_with_this_command():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "python -m sphinx -W --keep-going -b html docs docs/_build/html" in readme


def readme_links() -> list[str]:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    return re.findall(r"\]\((docs/[^)#\s]+)(?:#[^)]*)?\)", readme)


def page_of(link: str) -> str:
    """The built page a README link into ``docs/`` is: a Markdown page by its name, a
    tutorial or example script by the gallery page sphinx-gallery makes of it, a gallery's
    ``README.rst`` by the gallery's index."""
    rel = Path(link).relative_to("docs")
    if rel.parts[0] in ("tutorials", "examples"):  # a script, or the gallery's README.rst
        name = "index.html" if rel.name == "README.rst" else rel.with_suffix(".html").name
        return str(Path(f"auto_{rel.parts[0]}") / name)
    return str(rel.with_suffix(".html"))


def test_every_readme_link_into_docs_is_a_page_of_the_site(site):
    links = readme_links()
    assert len(links) >= 10
    missing = [link for link in links if not (site / page_of(link)).exists()]
    assert not missing, f"README links with no page in the built site: {missing}"


def test_every_gallery_script_has_its_page(site):
    for kind in ("tutorials", "examples"):
        scripts = sorted((REPO / "docs" / kind).glob("*.py"))
        assert scripts, kind
        missing = [s.name for s in scripts if not (site / f"auto_{kind}" / (s.stem + ".html"))
                   .exists()]
        assert not missing, missing


@browser
@pytest.mark.parametrize("page", ["index.html", "api/trackkit.filters.kalman.html",
                                  "auto_tutorials/t03_core_from_python.html"])
def test_pages_load_without_a_console_message(served, page, tmp_path):
    dom, console, _ = open_in_chromium(served + page, tmp_path, wait_ms=8000)
    assert messages(console) == [], console
    assert "<title>" in dom and "trackkit" in dom


@browser
def test_the_api_page_equations_are_typeset(served, tmp_path):
    dom, console, shot = open_in_chromium(served + "api/trackkit.filters.kalman.html",
                                          tmp_path, wait_ms=10000)
    assert messages(console) == [], console
    maths = re.findall(r'<(?:span|div) class="math[^"]*">(.*?)</(?:span|div)>', dom, re.S)
    assert len(maths) >= 3
    # MathJax replaced each formula's TeX by its typeset form
    assert all("mjx-container" in m for m in maths), [m[:80] for m in maths
                                                      if "mjx-container" not in m]
    shutil.copy(shot, tmp_path / "api-equations.png")


@browser
def test_the_tutorial_shows_its_figures(site, served, tmp_path):
    page = site / "auto_tutorials" / "t03_core_from_python.html"
    dom, console, shot = open_in_chromium(served + "auto_tutorials/t03_core_from_python.html",
                                          tmp_path, wait_ms=4000)
    assert messages(console) == [], console
    images = re.findall(r'<img[^>]+src="([^"]+sphx_glr_[^"]+\.png)"', dom)
    assert images
    from matplotlib.image import imread

    for src in images:
        img = imread(page.parent / src)
        assert img.shape[0] > 100 and np.std(img[..., :3]) > 0.05  # a drawing, not a blank


@browser
def test_search_finds_jpda(served, tmp_path):
    dom, console, _ = open_in_chromium(served + "search.html?q=JPDA", tmp_path, wait_ms=15000)
    assert messages(console) == [], console
    results = re.search(r'<ul[^>]*class="search"[^>]*>(.*?)</ul>', dom, re.S)
    assert results, "no search results list"
    hits = re.findall(r'<a href="([^"]+)"', results.group(1))
    assert any("trackkit.tracking.association" in h for h in hits), hits[:20]

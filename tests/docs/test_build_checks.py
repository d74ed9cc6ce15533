"""The site's build checks can fail: a small probe site, built with the site's own extension
(``docs/_ext/trackkit_docs.py``) and the settings of ``docs/conf.py`` that matter here
(nitpicky cross-references, warnings as errors), is refused when a public name has no
docstring or a docstring names an object that does not exist, and is accepted once both are
mended."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

CONF = f"""
import sys
sys.path[:0] = [{str(REPO / 'docs' / '_ext')!r}, {{here!r}}]
extensions = ["sphinx.ext.autodoc", "trackkit_docs"]
trackkit_api_pages = False
nitpicky = True
"""


def build(tmp: Path, module: str) -> subprocess.CompletedProcess:
    src = tmp / "src"
    src.mkdir(exist_ok=True)
    (src / "conf.py").write_text(CONF.format(here=str(src)), encoding="utf-8")
    (src / "probe.py").write_text(textwrap.dedent(module), encoding="utf-8")
    sys.path[:0] = [str(src), str(REPO / "docs" / "_ext")]
    try:
        import trackkit_docs  # the generator of the site's API pages

        sys.modules.pop("probe", None)
        page = trackkit_docs.module_page("probe")
    finally:
        del sys.path[:2]
    (src / "index.rst").write_text(page, encoding="utf-8")
    return subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", "-E", str(src), str(tmp / "out")],
                          capture_output=True, text=True, timeout=120)


def test_a_public_name_without_a_docstring_fails_the_build(tmp_path):
    p = build(tmp_path, '''
        """A probe."""
        __all__ = ["documented", "bare"]
        def documented():
            """Has one."""
        def bare():
            pass
        ''')
    assert p.returncode != 0
    assert "probe.bare is public and has no docstring" in p.stderr


def test_a_broken_cross_reference_fails_the_build(tmp_path):
    p = build(tmp_path, '''
        """A probe."""
        __all__ = ["f"]
        def f():
            """Like :func:`g`, which does not exist."""
        ''')
    assert p.returncode != 0
    assert "py:func reference target not found: g" in p.stderr


def test_the_mended_probe_builds(tmp_path):
    p = build(tmp_path, '''
        """A probe.

        The update, as an indented block after a paragraph:

            x+ = x- + K nu

        and a line of code:

            z = f(x)
        """
        __all__ = ["f", "g"]
        def f():
            """Like :func:`g`."""
        def g():
            """Named by :func:`f`."""
        ''')
    assert p.returncode == 0, p.stderr
    page = (tmp_path / "out" / "index.html").read_text(encoding="utf-8")
    # the equation kept as the plain-text block it is, the code shown as Python
    assert "<pre><span></span>x+ = x- + K nu" in page
    assert '<span class="n">z</span> <span class="o">=</span>' in page


GALLERY_CONF = f"""
import sys
sys.path[:0] = [{str(REPO / 'docs' / '_ext')!r}]
extensions = ["sphinx_gallery.gen_gallery", "trackkit_docs"]
trackkit_api_pages = False
exclude_patterns = ["scripts"]
sphinx_gallery_conf = {{"examples_dirs": ["scripts"], "gallery_dirs": ["auto"],
                        "filename_pattern": "/", "abort_on_example_error": True,
                        "write_computation_times": False}}
"""


def build_gallery(tmp: Path, script: str) -> subprocess.CompletedProcess:
    src = tmp / "src"
    (src / "scripts").mkdir(parents=True)
    (src / "conf.py").write_text(GALLERY_CONF, encoding="utf-8")
    (src / "scripts" / "README.rst").write_text("Scripts\n=======\n", encoding="utf-8")
    (src / "scripts" / "nap.py").write_text(textwrap.dedent(script), encoding="utf-8")
    (src / "index.rst").write_text("Probe\n=====\n\n.. toctree::\n\n   auto/index\n",
                                   encoding="utf-8")
    return subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", "-E", str(src), str(tmp / "out")],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_a_gallery_script_over_its_budget_fails_the_build(tmp_path):
    p = build_gallery(tmp_path, '''
        """
        A nap
        =====

        .. budget: 0.1 s
        """
        import time

        time.sleep(0.5)
        ''')
    assert p.returncode != 0
    assert "scripts/nap.py took 0.5 s, budget 0.1 s" in p.stderr


def test_a_gallery_script_that_raises_fails_the_build(tmp_path):
    p = build_gallery(tmp_path, '''
        """
        A fall
        ======
        """
        raise RuntimeError("the example broke")
        ''')
    assert p.returncode != 0
    assert "the example broke" in p.stderr + p.stdout


def test_a_gallery_script_within_its_budget_builds(tmp_path):
    p = build_gallery(tmp_path, '''
        """
        A blink
        =======

        .. budget: 5 s
        """
        import time

        time.sleep(0.05)
        ''')
    assert p.returncode == 0, p.stderr

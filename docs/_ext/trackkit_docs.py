"""The site's own Sphinx extension: the API pages, cross-references by object, the docstring
checks and the gallery's time budgets.

- **API pages.** One page per public module of trackkit (``docs/api/``, written at each build
  from the package tree, so a new module cannot be left out), grouped by package; a package
  page lists the names its ``__all__`` exports. A module's members are its ``__all__``, or,
  without one, the names it defines that do not start with an underscore.
- **Cross-references by object.** A docstring may name an object where users import it
  (``trackkit.filters.EKF``) or where it is defined (``trackkit.filters.kalman.EKF``); both
  resolve to the one place it is documented. A reference that names no documented object
  stays a warning, which ``-W`` makes an error.
- **Docstrings.** A public name without a docstring is a warning. An indented block after a
  paragraph (the docstrings' equations and code, written to read well in ``help()``) is shown
  as the literal block it is, not merged into a paragraph.
- **Time budgets.** Each gallery script runs within its budget (:data:`BUDGET_S`, or a
  ``.. budget: N s`` comment in the script's docstring); the build fails when one overruns.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import pkgutil
import re
import textwrap
from pathlib import Path

from sphinx.application import Sphinx
from sphinx.errors import ExtensionError
from sphinx.util import logging

logger = logging.getLogger(__name__)

DOCS = Path(__file__).resolve().parents[1]
API = DOCS / "api"
BUDGET_S = 30.0  # a gallery script's default time budget, seconds on one core
SKIPPED = ("trackkit.cli", "trackkit.renamed")  # the command line has its own page

PACKAGES = {
    "trackkit": "The top level: beliefs and the subpackages",
    "trackkit.angles": "Angles: wrapping and bearing conventions",
    "trackkit.linalg": "Batched linear algebra",
    "trackkit.belief": "Beliefs: Gaussians, particles, innovations",
    "trackkit.models": "Motion and sensor models",
    "trackkit.filters": "Filters and smoothers",
    "trackkit.optimize": "Optimisers: GA, PSO, ICA",
    "trackkit.eval": "Metrics and bounds: RMSE, NEES, PCRLB, OSPA, GOSPA",
    "trackkit.io": "Reading and writing recorded data",
    "trackkit.sim": "Simulation",
    "trackkit.tracking": "Multi-target tracking",
    "trackkit.identify": "Vessel manoeuvring-model identification",
    "trackkit.network": "The decentralised bearings-only network",
    "trackkit.scenario": "Scenarios",
    "trackkit.experiments": "Experiments: Monte Carlo, sweeps, campaigns",
    "trackkit.report": "Reports",
}


# --------------------------------------------------------------------------------------------
# the API pages
# --------------------------------------------------------------------------------------------


def public_modules(package: str) -> list[str]:
    """The modules of ``package`` (itself first) that the reference documents: not private
    (no underscore), not the command line."""
    mod = importlib.import_module(package)
    names = [package]
    if hasattr(mod, "__path__"):
        for info in pkgutil.iter_modules(mod.__path__, package + "."):
            leaf = info.name.rsplit(".", 1)[1]
            if not leaf.startswith("_") and not info.name.startswith(SKIPPED):
                names.append(info.name)
    return names


def members(module: str) -> list[str]:
    """The public names a module's page documents: its ``__all__`` where it has one, else
    the names it defines without a leading underscore."""
    mod = importlib.import_module(module)
    if hasattr(mod, "__all__"):
        return [n for n in mod.__all__ if not inspect.ismodule(getattr(mod, n, None))]
    return [n for n, v in vars(mod).items()
            if not n.startswith("_") and getattr(v, "__module__", None) == module
            and (inspect.isclass(v) or inspect.isfunction(v))]


def _title(text: str) -> str:
    return f"{text}\n{'=' * len(text)}\n"


def module_page(module: str) -> str:
    own = members(module)
    mod = importlib.import_module(module)
    defined = [n for n in own if getattr(getattr(mod, n, None), "__module__", module) == module]
    out = [_title(f"``{module}``"), f".. automodule:: {module}",
           "   :no-members:", ""]
    return "\n".join(out + entries(mod, module, defined))


def entries(mod, path: str, names: list[str]) -> list[str]:
    """The autodoc directives of ``names`` of ``mod``, documented as ``path.NAME``."""
    out = []
    for name in names:
        obj = getattr(mod, name)
        kind = "autoclass" if inspect.isclass(obj) else (
            "autofunction" if callable(obj) else "autodata")
        out += [f".. {kind}:: {path}.{name}"]
        out += ["   :members:", "   :show-inheritance:", ""] if kind == "autoclass" else [""]
    return out


def home_of(obj: object, name: str, modules: list[str]) -> str | None:
    """The module among ``modules`` whose page documents ``obj`` (exported as ``name``), or
    None: a constant, or a name from a private module, is documented where it is exported."""
    mod = getattr(obj, "__module__", None) if inspect.isclass(obj) or callable(obj) else None
    candidates = [mod] if mod else modules
    for m in candidates:
        if m in modules and name in members(m) and \
                getattr(importlib.import_module(m), name, None) is obj:
            return m
    return None


def package_page(package: str, modules: list[str]) -> str:
    exported = members(package) if package != "trackkit" else []
    title = f"``{package}``: {PACKAGES[package]}"
    out = [_title(title), f".. automodule:: {package}", "   :no-members:", ""]
    mod = importlib.import_module(package)
    subs = [m for m in modules if m != package]
    here = [n for n in exported if home_of(getattr(mod, n), n, subs) is None]
    if exported:
        out += ["Public names", "------------", "", ".. autosummary::", ""]
        out += [f"   {n}" for n in exported]
        out += [""]
    out += entries(mod, package, here)
    if subs:
        out += ["Modules", "-------", "", ".. toctree::", "   :maxdepth: 1", ""]
        out += [f"   {m}" for m in subs]
    return "\n".join(out) + "\n"


def write_if_changed(path: Path, text: str) -> None:
    """Write a generated page only when its text changed: an unchanged page keeps its mtime,
    so Sphinx does not read it again."""
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def write_api_pages(app: Sphinx) -> None:
    if not app.config.trackkit_api_pages:
        return
    API.mkdir(exist_ok=True)
    wanted = {}
    for package in PACKAGES:
        modules = public_modules(package) if package != "trackkit" else ["trackkit"]
        if not hasattr(importlib.import_module(package), "__path__"):
            wanted[package] = module_page(package)
            continue
        wanted[package] = package_page(package, modules)
        for m in modules[1:]:
            wanted[m] = module_page(m)
    index = [_title("API reference"),
             "Every public name of trackkit, by package, from the layers at the top (what the",
             "command line runs) down to the batched linear algebra. Each module's page gives",
             "its docstring (the equations it implements) and its public names.", "",
             ".. toctree::", "   :maxdepth: 1", ""]
    index += [f"   {p}" for p in PACKAGES]
    wanted["index"] = "\n".join(index) + "\n"
    for name, text in wanted.items():
        write_if_changed(API / f"{name}.rst", text)
    for stale in API.glob("*.rst"):
        if stale.stem not in wanted:
            stale.unlink()


# --------------------------------------------------------------------------------------------
# cross-references by object
# --------------------------------------------------------------------------------------------


def _lookup(path: str) -> object | None:
    """The object a dotted path names, importing the longest module prefix."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return None
        return obj
    return None


def canonical(obj: object) -> str | None:
    if inspect.ismodule(obj):
        return obj.__name__
    mod, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{mod}.{qual}" if mod and qual else None


def resolve_by_object(app: Sphinx, env, node, contnode):
    """A reference the Python domain did not find, looked up by the object it names: the
    path as written, then inside the current class, module and its parent packages."""
    if node.get("refdomain") != "py":
        return None
    from sphinx.util.nodes import make_refnode

    target = node["reftarget"].lstrip("~.")
    module = node.get("py:module") or ""
    scopes = [f"{module}.{node['py:class']}" if node.get("py:class") else None, module]
    while "." in module:
        module = module.rsplit(".", 1)[0]
        scopes.append(module)
    objects = env.get_domain("py").objects
    for cand in [f"{s}.{target}" for s in scopes if s] + [target]:
        obj = _lookup(cand) if cand.startswith("trackkit") else None
        names = [canonical(obj) if obj is not None else None, cand]
        if obj is not None and names[0] is None:  # a constant: where its module documents it
            package, leaf = cand.rsplit(".", 1)
            names += [f for f in objects if f.startswith(package + ".")
                      and f.rsplit(".", 1)[1] == leaf and _lookup(f) is obj]
        for full in filter(None, names):
            if full in objects:
                entry = objects[full]
                return make_refnode(app.builder, node["refdoc"], entry.docname,
                                    entry.node_id, contnode)
    return None


# --------------------------------------------------------------------------------------------
# docstrings
# --------------------------------------------------------------------------------------------

_BULLET = re.compile(r"^(\s*)([-*+]|\d+\.|\(\w\))\s+")


def literal_blocks(lines: list[str]) -> list[str]:
    """Make each indented block that follows a paragraph a literal block, unless the
    paragraph is a directive or a field, ends in ``::`` already, or the block continues a
    list item. A block that parses as Python is shown as Python; any other (an equation, a
    table) as plain text."""
    out: list[str] = []
    para: list[str] = []  # the last run of non-blank lines before the current one
    run: list[str] = []
    for i, line in enumerate(lines):
        if not line.strip():
            if run:
                para, run = run, []
            out.append(line)
            continue
        if not run and para:
            base = _indent(para[0])
            bullet = _BULLET.match(para[0])
            item = bullet is not None and _indent(line) == len(bullet.group(0))
            head = para[0].lstrip()
            quiet = head.startswith(("..", ":", ">>>")) or para[-1].rstrip().endswith("::")
            if _indent(line) > base and not item and not quiet:
                header = "::" if _is_python(_block(lines, i, base)) else ".. code-block:: text"
                last = max(j for j, x in enumerate(out) if x.strip())
                if header == "::" and out[last].rstrip().endswith(":"):
                    out[last] = out[last].rstrip() + ":"
                else:
                    out[last + 1:last + 1] = ["", " " * base + header]
        run.append(line)
        out.append(line)
    return out


def _block(lines: list[str], start: int, base: int) -> str:
    """The indented block that starts at ``lines[start]``: up to the first line not
    indented beyond ``base``."""
    end = start
    while end < len(lines) and (not lines[end].strip() or _indent(lines[end]) > base):
        end += 1
    return textwrap.dedent("\n".join(lines[start:end]))


def _is_python(code: str) -> bool:
    try:
        ast.parse(code)
    except SyntaxError:
        return False
    return True


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def process_docstring(app: Sphinx, what: str, name: str, obj, options, lines: list[str]):
    if what in ("data", "attribute") and not inspect.isclass(obj) and not callable(obj):
        doc = type(obj).__doc__
        own = inspect.cleandoc(doc if isinstance(doc, str) else "").splitlines()
        if [s.strip() for s in lines if s.strip()] == [s.strip() for s in own if s.strip()]:
            lines[:] = []  # autodoc fell back to the value's type's docstring (dict, tuple)
    lines[:] = literal_blocks(lines)
    if what in ("module", "class", "function", "exception") and not any(s.strip()
                                                                          for s in lines):
        if what == "class" and obj.__doc__:  # a docstring on the class, autodoc chose init
            return
        logger.warning(f"{name} is public and has no docstring", type="trackkit",
                       subtype="docstring")


# --------------------------------------------------------------------------------------------
# the gallery's time budgets
# --------------------------------------------------------------------------------------------

_BUDGET = re.compile(r"^\.\. budget: (\d+(?:\.\d+)?) s$", re.M)  # an rST comment


def check_budgets(app: Sphinx, exc: Exception | None) -> None:
    """Fail the build when a gallery script ran longer than its budget: ``.. budget: N s``
    in the script's docstring (an rST comment, so not shown), else :data:`BUDGET_S`. The
    time is sphinx-gallery's own measurement of the script's execution (``NAME.cost.json``
    beside its page)."""
    conf = getattr(app.config, "sphinx_gallery_conf", None)
    if exc is not None or not conf:
        return
    src_dir = Path(app.srcdir)
    over = []
    for src, out in zip(conf["examples_dirs"], conf["gallery_dirs"], strict=True):
        for script in sorted((src_dir / src).glob("*.py")):
            cost = src_dir / out / f"{script.stem}.cost.json"
            if not cost.exists():
                continue
            took = json.loads(cost.read_text(encoding="utf-8"))["time"]
            found = _BUDGET.search(script.read_text(encoding="utf-8"))
            budget = float(found.group(1)) if found else BUDGET_S
            if took > budget:
                over.append(f"{src}/{script.name} took {took:.1f} s, budget {budget:g} s")
    if over:
        raise ExtensionError("gallery scripts over their time budget: " + "; ".join(over))


def public_bases(app: Sphinx, name: str, obj, options, bases: list) -> None:
    """A class's bases as users see them: a private base (``_SigmaPointFilter``) is an
    implementation detail, shown as its own public bases."""
    i = 0
    while i < len(bases):
        b = bases[i]
        if getattr(b, "__name__", "").startswith("_") and hasattr(b, "__bases__"):
            bases[i:i + 1] = [x for x in b.__bases__ if x is not object]
        else:
            i += 1


def write_cli_page(app: Sphinx) -> None:
    """``cli.rst``: every command's ``--help``, as the terminal shows it (88 columns)."""
    if not app.config.trackkit_api_pages:
        return
    import os

    import typer
    from typer.testing import CliRunner

    from trackkit.cli import app as cli

    os.environ.setdefault("COLUMNS", "88")
    group = typer.main.get_command(cli)
    runner = CliRunner()
    out = [_title("The command line"),
           "``trackkit`` is one command with a subcommand per job. Each subcommand parses its",
           "options into a typed library object and calls one library function, named in",
           "the tutorials; this page is each subcommand's ``--help``.", ""]
    for name in group.list_commands(None):
        text = runner.invoke(cli, [name, "--help"], env={"NO_COLOR": "1", "COLUMNS": "88",
                                                         "TERM": "dumb"}).output
        out += [f"``trackkit {name}``", "-" * (len(name) + 13), "", ".. code-block:: text",
                ""]
        out += ["   " + line.rstrip() if line.strip() else "" for line in text.splitlines()]
        out += [""]
    write_if_changed(DOCS / "cli.rst", "\n".join(out) + "\n")


def compile_kernels(app: Sphinx) -> None:
    """numba's kernels compiled, or read from its cache, before the gallery runs: a fresh
    clone compiles them once (tens of seconds), and each script's budget is for the script.
    The tracker of recorded data takes the IMM and fixed-lag smoother kernels, the vessel
    identification the augmented EKF's."""
    if "sphinx_gallery.gen_gallery" not in app.config.extensions:
        return
    import time

    from trackkit.experiments.vessel_mc import run_vessel
    from trackkit.io import samples
    from trackkit.scenario.vessel import load_vessel
    from trackkit.tracking.recorded import TrackOptions, track_recording

    t0 = time.perf_counter()
    track_recording(samples.path("solent-ais"), TrackOptions(as_radar=True, max_scans=25))
    run_vessel(load_vessel("vessel-zigzag-20"), runs=1)
    logger.info(f"trackkit's compiled kernels ready in {time.perf_counter() - t0:.1f} s")


_HTML_ANCHOR = re.compile(r'^<a id="([\w-]+)"></a>$', re.M)


def html_anchors(app: Sphinx, docname: str, source: list[str]) -> None:
    """The Markdown pages mark their link targets as ``<a id="x"></a>`` (what GitHub
    renders); the site reads each as a MyST target ``(x)=``, so links to it resolve."""
    if app.env.doc2path(docname).suffix == ".md":
        source[0] = _HTML_ANCHOR.sub(r"(\1)=", source[0])


def setup(app: Sphinx) -> dict:
    app.setup_extension("sphinx.ext.autodoc")  # its events are connected below
    app.connect("source-read", html_anchors)
    app.connect("builder-inited", compile_kernels, priority=400)  # before the gallery runs
    app.add_config_value("trackkit_api_pages", True, "env")  # off: checks only (the tests)
    app.connect("builder-inited", write_cli_page)
    app.connect("autodoc-process-bases", public_bases)
    app.connect("builder-inited", write_api_pages)
    app.connect("missing-reference", resolve_by_object)
    app.connect("autodoc-process-docstring", process_docstring)
    app.connect("build-finished", check_budgets)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

"""The house rules: trackkit's packages import one way (the import-linter contracts in
pyproject.toml, docs/architecture.md), and no module reaches for another's private names.

The contracts are checked on the source as it is, and on a copy with one deliberate upward
import, one cycle and one private-module import added, which each must break them: a contract
that nothing can break would prove nothing.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PACKAGE = SRC / "trackkit"
LINT = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or "lint-imports"


def _lint(src: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` with the project's contracts over the package under ``src``."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    return subprocess.run([LINT, "--no-cache", str(ROOT / "pyproject.toml")], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)


def test_the_layers_run_one_way(tmp_path):
    run = _lint(SRC, tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 broken" in run.stdout


@pytest.fixture(scope="module")
def copy_of_src(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("src")
    shutil.copytree(PACKAGE, src / "trackkit", ignore=shutil.ignore_patterns("__pycache__"))
    return src


BREAKS = {
    # a filter that reaches up for the report: a lower layer importing a higher one
    "upward": ("filters/kalman.py", "from trackkit.report import html as _upward\n",
               "trackkit.filters is not allowed to import trackkit.report"),
    # two siblings of one package that import each other
    "cycle": ("scenario/schema.py", "from trackkit.scenario import build as _cycle\n",
              "No cycles are allowed in trackkit.scenario"),
    # a private module of io used outside io
    "private module": ("tracking/recorded.py", "from trackkit.io import _table as _private\n",
                       "trackkit.io._table"),
}


@pytest.mark.parametrize("kind", BREAKS)
def test_a_deliberate_break_of_the_layers_fails_the_contract(kind, copy_of_src, tmp_path):
    rel, line, message = BREAKS[kind]
    target = copy_of_src / "trackkit" / rel
    original = target.read_text()
    try:
        target.write_text(original + "\n" + line)
        run = _lint(copy_of_src, tmp_path)
    finally:
        target.write_text(original)
    assert run.returncode != 0, run.stdout
    assert message in run.stdout, run.stdout


def _module_of(path: Path, src: Path) -> str:
    parts = path.relative_to(src).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


#: a named tuple's own methods, public though they start with an underscore
NAMEDTUPLE_API = {"_make", "_replace", "_asdict", "_fields", "_field_defaults"}


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and name not in NAMEDTUPLE_API


def _own_private_module(module: str, name: str, here: str, src: Path) -> bool:
    """``from package import _module`` inside that package (the private-modules contract
    keeps such modules inside their package)."""
    path = src.joinpath(*module.split("."), name)
    inside = here.startswith(module + ".")
    return inside and (path.with_suffix(".py").is_file() or (path / "__init__.py").is_file())


def private_imports(path: Path, src: Path = SRC) -> list[str]:
    """Every private name another trackkit module imports in ``path``: ``from trackkit.x
    import _name``, and ``m._name`` on a trackkit module ``m`` it imported."""
    tree = ast.parse(path.read_text(), str(path))
    here = _module_of(path, src)
    found, modules = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("trackkit"):
            for a in node.names:
                if _private(a.name) and not _own_private_module(node.module, a.name, here, src):
                    found.append(f"{path.relative_to(src)}:{node.lineno}: "
                                 f"from {node.module} import {a.name}")
                modules[a.asname or a.name] = f"{node.module}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("trackkit") and a.asname:
                    modules[a.asname] = a.name
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and _private(node.attr)
                and isinstance(node.value, ast.Name) and node.value.id in modules):
            found.append(f"{path.relative_to(src)}:{node.lineno}: "
                         f"{modules[node.value.id]}.{node.attr}")
    return found


def test_no_module_imports_another_modules_private_name():
    found = [f for p in sorted(PACKAGE.rglob("*.py")) for f in private_imports(p)]
    assert not found, "private names used across modules:\n" + "\n".join(found)


def test_the_private_name_check_finds_one(tmp_path):
    sample = tmp_path / "trackkit" / "probe.py"
    sample.parent.mkdir()
    sample.write_text("from trackkit.report.html import _CSS\n"
                      "import trackkit.linalg as la\n"
                      "x = la._triu\n")
    found = private_imports(sample, tmp_path)
    assert [f.split(": ", 1)[1] for f in found] == ["from trackkit.report.html import _CSS",
                                                     "trackkit.linalg._triu"]


def test_the_layout_names_every_package_and_module():
    readme = (ROOT / "docs" / "architecture.md").read_text()
    block = readme[readme.index("```\nsrc/trackkit/"):]
    block = block[:block.index("\n```\n")]
    missing = []
    for p in sorted(PACKAGE.rglob("*.py")):
        rel = p.relative_to(PACKAGE)
        if p.name in ("__init__.py", "__main__.py") or rel.parts[0].startswith("_"):
            continue
        if rel.parts[0] == "io" and p.name.startswith("_"):
            continue  # io's private modules: the readers' shared parts
        if len(rel.parts) > 1 and f"{rel.parts[0]}/" not in block:
            missing.append(f"{rel.parts[0]}/")
        if p.name not in block:
            missing.append(str(rel))
    assert not missing, f"docs/architecture.md's layout does not name: {sorted(set(missing))}"


def test_no_two_modules_share_a_name_for_different_jobs():
    """A module's name says what it holds. The command line's modules are named for their
    commands (``cli/run.py`` is ``trackkit run``), and a package's ``base.py`` holds its base
    types; any other name is used once."""
    seen: dict[str, list[str]] = {}
    for p in PACKAGE.rglob("*.py"):
        rel = p.relative_to(PACKAGE)
        if p.name in ("__init__.py", "__main__.py", "base.py") or rel.parts[0] == "cli":
            continue
        seen.setdefault(p.name, []).append(str(rel))
    assert not {n: w for n, w in seen.items() if len(w) > 1}


#: a function longer than this cannot be read on one screen
MAX_FUNCTION_LINES = 120
#: a command's module stays short: options in, one library call, the summary out
MAX_CLI_MODULE_LINES = 400


def test_no_function_in_src_is_over_120_lines():
    long = []
    for p in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{p.relative_to(SRC)}::{node.name} ({n} lines)")
    assert not long, long


def test_the_command_modules_are_short():
    long = {p.name: n for p in (PACKAGE / "cli").glob("*.py")
            if (n := len(p.read_text().splitlines())) >= MAX_CLI_MODULE_LINES}
    assert not long, long

"""The README's examples, and those of the site's tour (``docs/tour.md``, where the README's
longer examples live), work as pasted on a fresh clone: every ```python block runs in a
fresh interpreter without an error or a warning, and every ``trackkit ...`` command of its
```bash blocks runs through the real command (``python -m trackkit.cli``), in order, in one
temporary directory (``tests/fixtures`` reachable there, as in a clone), with ``>``
redirection honoured, and exits 0.

Commands that would take more than about 30 s are shortened, and only in their run count or
duration (:func:`shortened` says which and how); each shortened command's own options are
parsed by the command first (:func:`test_shortened_commands_parse_as_written`). ``pip
install`` and ``pytest`` themselves are not run.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import typer

from tests.cli_helpers import trackkit

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
TOUR = REPO / "docs" / "tour.md"
PAGES = (README, TOUR)
RUNS = "2"  # Monte Carlo runs of a shortened command
SCANS = "20"  # scans tracked of a shortened recording


def blocks(lang: str, pages: tuple[Path, ...] = PAGES) -> list[str]:
    """The fenced ```LANG blocks of the README and the tour, in order."""
    text = "\n".join(p.read_text(encoding="utf-8") for p in pages)
    return re.findall(rf"^```{lang}\n(.*?)^```", text, re.S | re.M)


def commands() -> list[list[str]]:
    """Every ``trackkit`` command of the ```bash blocks as its words (a backslash-newline
    removed, as the shell does; comments dropped), in the README's order."""
    out = []
    for block in blocks("bash"):
        for line in block.replace("\\\n", "").splitlines():
            words = shlex.split(line, comments=True)
            if words[:1] == ["trackkit"]:
                out.append(words[1:])
    return out


def _set(args: list[str], option: str, value: str) -> list[str]:
    if option in args:
        i = args.index(option)
        return [*args[:i + 1], value, *args[i + 2:]]
    return [*args, option, value]


def shortened(args: list[str]) -> tuple[list[str], str]:
    """The command as the test runs it, and how it was shortened ("" if not):

    * ``run``, ``sweep``, ``network`` and ``identify`` of a bundled scenario (not of a log
      file): ``--runs 2`` (replacing the README's run count, or appended): a scenario's full
      Monte Carlo takes minutes;
    * ``track`` of a bundled recording (a name, not a file): ``--max-scans 20`` appended: a
      whole recording (the Solent one is 1 691 scans) takes minutes.
    """
    command, target = args[0], next((a for a in args[1:] if not a.startswith("-")), "")
    is_file = Path(target).suffix != ""
    if command in ("run", "sweep", "network") or (command == "identify" and not is_file):
        return _set(args, "--runs", RUNS), f"--runs {RUNS}"
    if command == "track" and not is_file:
        return [*args, "--max-scans", SCANS], f"--max-scans {SCANS} appended"
    return args, ""


def _run_dir(tmp: Path) -> Path:
    """A directory that looks like a clone's root for the README's relative paths."""
    (tmp / "tests").mkdir()
    (tmp / "tests" / "fixtures").symlink_to(REPO / "tests" / "fixtures")
    return tmp


# --------------------------------------------------------------------------------------------
# the Python blocks
# --------------------------------------------------------------------------------------------


def test_the_readme_has_its_examples():
    assert len(blocks("python", (README,))) >= 2
    assert len(blocks("bash", (README,))) >= 3
    assert len(blocks("python")) >= 5
    assert len(commands()) >= 20


@pytest.mark.parametrize("i", range(len(blocks("python"))))
def test_python_block_runs_as_pasted(i, tmp_path):
    code = blocks("python")[i]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(REPO / "src"), *filter(None, [os.environ.get("PYTHONPATH")])])}
    p = subprocess.run([sys.executable, "-W", "error", "-c", code], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, f"README python block {i} failed:\n{code}\n{p.stderr}"
    assert "Warning" not in p.stderr, p.stderr


# --------------------------------------------------------------------------------------------
# the commands
# --------------------------------------------------------------------------------------------


def test_shortened_commands_parse_as_written():
    """Each command the test shortens is first parsed as the README writes it: its options
    exist and their values pass the command's checks (click parses without running; typer
    may carry its own copy of click, so its usage errors are caught by what they offer)."""
    from trackkit.cli import app

    group = typer.main.get_command(app)
    n = 0
    for args in commands():
        if not shortened(args)[1]:
            continue
        n += 1
        with group.make_context("trackkit", list(args)) as ctx:
            sub = group.get_command(ctx, args[0])
            assert sub is not None, args
            try:
                sub.make_context(args[0], list(args[1:]), parent=ctx)
            except Exception as e:  # a usage error: the message is the point
                message = e.format_message() if hasattr(e, "format_message") else repr(e)
                pytest.fail(f"trackkit {shlex.join(args)}: {message}")
    assert n >= 5


def test_trackkit_list_in_the_readme_names_every_bundled_scenario():
    listed = trackkit("list")
    assert listed.code == 0, listed.text
    names = re.findall(r"^│ ([a-z0-9][a-z0-9-]*)", listed.out, re.M)
    assert len(names) >= 30
    block = next(b for b in blocks("bash") if "trackkit list" in b)
    missing = [n for n in names if not re.search(rf"(?<![\w-]){re.escape(n)}(?![\w-])", block)]
    assert not missing, f"README's trackkit list leaves out {missing}"


@pytest.mark.slow
def test_every_readme_command_runs_on_a_fresh_clone(tmp_path):
    cwd = _run_dir(tmp_path)
    failed = []
    for args in commands():
        args, _ = shortened(args)
        target = None
        if ">" in args:
            i = args.index(">")
            args, target = args[:i], args[i + 1]
        ran = trackkit(*args, cwd=cwd, timeout=600)
        if target is not None:
            (cwd / target).write_text(ran.out, encoding="utf-8")
        if ran.code != 0:
            failed.append(f"trackkit {shlex.join(args)}: exit {ran.code}\n{ran.text[-2000:]}")
    assert not failed, "\n\n".join(failed)

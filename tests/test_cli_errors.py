"""What a new user does to ``trackkit``, through the real command in a subprocess:
every mistake is one message in words that names the file, option or value, with the right
exit code, no traceback or numpy warning, and nothing written where it should not be; Ctrl-C
at any moment exits 130 with one line.

Scenario-content mistakes (filter options, absurd noise values, bad names) are in
``tests/test_scenario_errors.py``, the Python API's in ``tests/test_bad_input.py``; this
table holds the command-line and output-directory ones."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.cli_helpers import LEAKS, assert_user_error, trackkit

LOCK = ".trackkit.lock"  # trackkit.cli.LOCK_FILE, spelled out: the test reads the files


@dataclass
class Case:
    args: list[str]
    code: int
    names: list[str]
    #: prepares the working directory (a fresh tmp_path) before the command runs
    setup: Callable[[Path], None] = lambda cwd: None
    #: the files the working directory must hold afterwards (None: what setup left)
    after: set[str] | None = None
    env: dict[str, str] = field(default_factory=dict)


def _file(name: str, data: bytes = b"x\n") -> Callable[[Path], None]:
    return lambda cwd: (cwd / name).write_bytes(data)


def _dir(name: str) -> Callable[[Path], None]:
    return lambda cwd: (cwd / name).mkdir()


def _locked(cwd: Path) -> None:
    (cwd / "busy").mkdir()
    (cwd / "busy" / LOCK).write_text(f"{os.getpid()}\n")  # this test process: alive


def _listing(cwd: Path) -> set[str]:
    return {str(p.relative_to(cwd)) for p in cwd.rglob("*")}


CASES = {
    # the output directory: refused before any compute, named as the user wrote it
    "out-in-proc": Case(["run", "cv-position", "--out", "/proc/x"], 2, ["--out /proc/x"]),
    "out-below-a-file": Case(
        ["run", "cv-position", "--out", "existing-file/sub"], 2,
        ["--out existing-file/sub", "existing-file is a file"], _file("existing-file"),
        {"existing-file"}),
    "out-is-a-file": Case(["run", "cv-position", "--out", "existing-file"], 2,
                          ["--out existing-file", "not a directory"], _file("existing-file"),
                          {"existing-file"}),
    "out-in-use": Case(["run", "cv-position", "--out", "busy"], 2,
                       ["--out busy", "in use by another trackkit run",
                        f"pid {os.getpid()}", str(Path("busy") / LOCK)], _locked,
                       {"busy", f"busy/{LOCK}"}),
    # the scenario argument
    "scenario-is-a-directory": Case(["run", "adir"], 2, ["adir"], _dir("adir"), {"adir"}),
    "scenario-toml-is-a-directory": Case(["run", "adir.toml"], 2, ["adir.toml"],
                                         _dir("adir.toml"), {"adir.toml"}),
    "scenario-not-utf8": Case(["run", "latin.toml"], 2, ["latin.toml"],
                              _file("latin.toml", 'name = "Ålesund"\n'.encode("latin-1")),
                              {"latin.toml"}),
    "scenario-missing-file": Case(["run", "nowhere.toml"], 2, ["nowhere.toml"], after=set()),
    "unknown-scenario": Case(["run", "no-such-scenario"], 2, ["'no-such-scenario'", "bo-cv"],
                             after=set()),
    "show-unknown-scenario": Case(["show", "no-such-scenario"], 2, ["'no-such-scenario'"],
                                  after=set()),
    # option values
    "runs-zero": Case(["run", "cv-position", "--runs", "0"], 2, ["--runs", ": 0;"], after=set()),
    "runs-not-a-number": Case(["run", "cv-position", "--runs", "abc"], 2, ["--runs"],
                              after=set()),
    "seed-negative": Case(["run", "cv-position", "--seed", "-1"], 2, ["--seed", ": -1;"],
                          after=set()),
    "workers-zero": Case(["run", "cv-position", "--workers", "0"], 2, ["--workers", ": 0;"],
                         after=set()),
    "workers-and-scheduler": Case(["run", "cv-position", "--workers", "2", "--scheduler",
                                   "tcp://h:1"], 2, ["--workers 2", "--scheduler tcp://h:1",
                                                     "give one"], after=set()),
    "unknown-option": Case(["run", "--bogus"], 2, ["--bogus"], after=set()),
    # a run count whose per-run results cannot fit in memory: refused before any compute
    "runs-cannot-fit": Case(["run", "cv-position", "--runs", "1000000000000", "--out", "o"], 2,
                            ["runs = 1000000000000", "GiB", "at most"], after=set()),
    # a run count that the first block's timing says would take longer than --max-hours
    "runs-cannot-finish": Case(["run", "cv-position", "--runs", "100000", "--max-hours",
                                "0.0001", "--out", "o"], 2,
                               ["runs = 100000", "would take about", "--max-hours"],
                               after=set()),
    "max-hours-not-positive": Case(["run", "cv-position", "--max-hours", "0"], 2,
                                   ["--max-hours", "positive"], after=set()),
    "show-format": Case(["show", "bo-cv", "--format", "yaml"], 2, ["--format", "yaml"],
                        after=set()),
    "scheduler-not-an-address": Case(
        ["run", "cv-position", "--runs", "2", "--out", "o", "--scheduler", "notanaddress"], 2,
        ["notanaddress"], after=set()),
}
SLOW_CASES = {
    # Dask waits 30 s for a scheduler before giving up; 2 s takes the same path
    "scheduler-not-answering": Case(
        ["run", "cv-position", "--runs", "2", "--out", "o", "--scheduler", "tcp://127.0.0.1:1"],
        1, ["tcp://127.0.0.1:1"], after=set(),
        env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"}),
}


@pytest.mark.parametrize("case", [
    *(pytest.param(c, id=k) for k, c in CASES.items()),
    *(pytest.param(c, id=k, marks=pytest.mark.slow) for k, c in SLOW_CASES.items()),
])
def test_user_error_in_words(tmp_path, case):
    case.setup(tmp_path)
    before = _listing(tmp_path)
    ran = trackkit(*case.args, cwd=tmp_path, env=case.env)
    assert_user_error(ran, case.code, *case.names)
    assert ran.err.strip().count("\n") <= 8, ran.err  # a message, not a dump
    after = _listing(tmp_path)
    assert after == (before if case.after is None else case.after), (
        f"the command left {sorted(after - before)} and removed {sorted(before - after)}")


# --- Ctrl-C -------------------------------------------------------------------------------


_READY = """\
import importlib.machinery, importlib.util, os, sys
# the interpreter has finished its own start-up (site); trackkit's code comes next
os.write(int(os.environ["TRACKKIT_TEST_READY_FD"]), b"r")
# run the environment's own sitecustomize, if it has one, which this file hides
here = os.path.dirname(os.path.abspath(__file__))
spec = importlib.machinery.PathFinder.find_spec(
    "sitecustomize", [p for p in sys.path if os.path.abspath(p or ".") != here])
if spec is not None and spec.loader is not None:
    spec.loader.exec_module(importlib.util.module_from_spec(spec))
"""


def _start(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, float]:
    """Start ``python -m trackkit.cli ARGS``; returns it and the moment its interpreter
    finished starting up (from then on every instant is trackkit's to handle: before it,
    Python itself owns Ctrl-C, whatever the program)."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(_READY)
    r, w = os.pipe()
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1", "TRACKKIT_TEST_READY_FD": str(w),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(hook),
                                                       os.environ.get("PYTHONPATH")]))}
    env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.Popen([sys.executable, "-m", "trackkit.cli", *args], cwd=tmp_path, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         pass_fds=(w,))
    os.close(w)
    try:
        ready, _, _ = select.select([r], [], [], 60)
        assert ready and os.read(r, 1) == b"r", "the interpreter did not start"
    finally:
        os.close(r)
    return p, time.monotonic()


def _interrupt(p: subprocess.Popen, at: float) -> tuple[int, str, str]:
    time.sleep(max(0.0, at - time.monotonic()))
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=120)
    return p.returncode, out, err


def _assert_interrupted(code: int, out: str, err: str) -> None:
    text = out + err
    assert code == 130, f"exit {code}\n{text}"
    lines = [line for line in err.splitlines() if "interrupted" in line]
    assert len(lines) == 1, err
    for leak in (*LEAKS, "KeyboardInterrupt", "__set_name__"):
        assert leak not in text, f"{leak!r} leaked:\n{text}"


@pytest.mark.parametrize("delay", [0.1, 0.3, 0.5, 1.0, 2.0])
def test_ctrl_c_while_starting(tmp_path, delay):
    """Ctrl-C while the modules import (the first second or two): one line, exit 130,
    nothing written."""
    p, ready = _start(tmp_path, "run", "bo-cv", "--runs", "2000", "--out", "o")
    _assert_interrupted(*_interrupt(p, ready + delay))
    assert not (tmp_path / "o").exists()


def test_ctrl_c_while_computing_releases_the_lock(tmp_path):
    """Ctrl-C during the Monte Carlo (the lock exists from just before it starts): one line,
    exit 130, the lock released and the directory this run created removed."""
    p, _ = _start(tmp_path, "run", "bo-cv", "--runs", "2000", "--out", "o")
    lock = tmp_path / "o" / LOCK
    deadline = time.monotonic() + 120
    while not lock.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert lock.exists(), "the run never took its lock"
    assert lock.read_text().strip() == str(p.pid)
    _assert_interrupted(*_interrupt(p, time.monotonic() + 0.5))
    assert not (tmp_path / "o").exists()

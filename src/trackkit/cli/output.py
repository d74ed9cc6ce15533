"""What every command shares: errors in words and their exit codes, Ctrl-C, the output
directory (created, locked and listed in manifest.json before anything is computed) and the
progress bars (see the package doc for the exit codes)."""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from types import SimpleNamespace, TracebackType
from typing import Any

import click
import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

DEFAULT_OUT = Path("trackkit-out")
#: in the output directory while a run writes into it; holds the run's process id
LOCK_FILE = ".trackkit.lock"
#: a lock file without a readable pid younger than this may be one being written right now
_LOCK_GRACE_S = 10.0

#: process-wide flags of main(): whether it runs the command, whether "interrupted" was said
session = SimpleNamespace(main=False, announced=False, interrupt=False)

# --- errors in words --------------------------------------------------------------------------


def stderr() -> Console:
    return Console(stderr=True)


def is_interrupt(err: BaseException | None) -> bool:
    """A KeyboardInterrupt, or an error raised because of one (Python wraps an interrupt
    inside ``__set_name__`` in a RuntimeError, e.g. while pydantic builds a model class)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def say_interrupted(message: str = "interrupted") -> None:
    if session.main:  # a second Ctrl-C must not break the message into a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    session.announced = True
    stderr().print(Text(message, style="yellow"), soft_wrap=True)


def fail(message: str, code: int) -> None:
    text = Text("error: ", style="bold red")
    text.append(message or "unknown error", style="red")
    stderr().print(text, soft_wrap=True)
    raise typer.Exit(code)


def describe(err: BaseException) -> tuple[str, int]:
    """The message and exit code of an error a user can provoke."""
    if isinstance(err, UnicodeError):  # a ValueError, but its text names no file
        return f"cannot read text: {err}", 2
    if isinstance(err, ValueError):
        return str(err), 2
    if isinstance(err, MemoryError):
        return f"out of memory; try {_smaller_job()}", 1
    if isinstance(err, OSError):
        where = f": {err.filename}" if getattr(err, "filename", None) else ""
        return f"{err.strerror or err}{where}", 1
    return (f"unexpected {type(err).__name__}: {err} (this is a trackkit bug; "
            "TRACKKIT_DEBUG=1 shows the traceback)"), 1


def _current_context() -> Any:
    """The running command's context (typer keeps its own copy of click), or None."""
    try:
        from typer._click.globals import get_current_context
    except ImportError:  # a typer that uses click itself
        get_current_context = click.get_current_context
    return get_current_context(silent=True)


def _smaller_job() -> str:
    """How the running command's options make a smaller job (each names options it has)."""
    ctx = _current_context()
    command = ctx.info_name if ctx is not None else None
    if command == "track":
        return "fewer scans (--max-scans N or --until SECONDS)"
    if command == "identify":
        return "a shorter log, or fewer runs (--runs) of a vessel scenario"
    if command == "network":
        return "fewer runs (--runs)"
    return "fewer runs (--runs) or a smaller run.block in the scenario"


@contextmanager
def user_errors(state: SimpleNamespace | None = None) -> Iterator[SimpleNamespace]:
    """Any failure inside becomes one red message and an exit code (see the module doc):
    Ctrl-C -> 130, bad input (ValueError, incl. ScenarioError) -> 2, an OS error or anything
    else -> 1. ``TRACKKIT_DEBUG=1`` re-raises (except Ctrl-C) to keep the traceback. The
    yielded namespace's ``interrupted`` is the message a Ctrl-C prints."""
    state = state or SimpleNamespace(interrupted="interrupted")
    try:
        yield state
    except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
        raise
    except BaseException as err:
        if is_interrupt(err):
            say_interrupted(state.interrupted)
            raise typer.Exit(130) from None
        if not isinstance(err, Exception) or os.environ.get("TRACKKIT_DEBUG"):
            raise
        message, code = describe(err)
        fail(message, code)


# --- the output directory: checked, created and locked before any compute -------------------


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    if os.name == "nt":  # os.kill(pid, 0) would terminate it there; assume it is running
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    except OSError:
        return False
    return True


def _read_pid(lock: Path) -> int | None:
    try:
        return int(lock.read_text(encoding="ascii").strip())
    except (OSError, ValueError, UnicodeError):
        return None


@contextmanager
def _directory_guard(path: Path) -> Iterator[None]:
    """Serialise lock takeovers between trackkit processes (flock on the directory), so that
    two runs finding the same stale lock cannot both take it over. A no-op without flock."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


class OutputDir:
    """The output directory of one run: created (parents too) and locked on entry, so that a
    path that cannot be written fails before the Monte Carlo, and two runs cannot write into
    one directory. The lock file ``LOCK_FILE`` is created with O_EXCL and holds the pid; a
    lock whose process has died is taken over (``note`` says so). On exit the lock is
    released, and after a failure the directories this run created are removed if empty.
    Inside a command, the directory is also checked and its writes listed in manifest.json
    (``report.files.command_output``)."""

    def __init__(self, path: Path, label: str) -> None:
        self.path = path
        self.label = label  # how the user named it, for messages
        self.lock = path / LOCK_FILE
        self.created: list[Path] = []
        self.note: str | None = None
        self._locked = False
        self._manifest: Any = None

    def __enter__(self) -> OutputDir:
        self.created = self._create()
        try:
            self.note = self._acquire()
            run = _command_run(self.path)
            if run is not None:
                from trackkit.report.files import command_output

                self._manifest = command_output(self.path, self.label, run)
                self._manifest.__enter__()
        except BaseException:
            self._release()
            self._remove_created()
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, err: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._manifest is not None:
            self._manifest.__exit__(kind, err, tb)
            self._manifest = None
        self._release()
        if kind is not None:
            self._remove_created()

    def _create(self) -> list[Path]:
        p = self.path
        if p.is_dir():
            return []
        if p.exists():
            raise ValueError(f"{self.label} exists and is not a directory; expected a "
                             "directory for the report files (or a path to create one at)")
        missing, q = [], p
        while not q.exists() and q.parent != q:
            missing.append(q)
            q = q.parent
        if not q.is_dir():
            raise ValueError(f"{self.label}: cannot create the output directory, because "
                             f"{q} is a file, not a directory")
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ValueError(f"{self.label}: cannot create the output directory "
                             f"({err.strerror or err}, in {q}); choose a directory you can "
                             "write to") from None
        return missing[::-1]

    def _acquire(self) -> str | None:
        note = None
        with _directory_guard(self.path):
            for _ in range(2):
                try:
                    fd = os.open(self.lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
                except FileExistsError:
                    note = self._stale_or_busy()
                    self.lock.unlink(missing_ok=True)
                    continue
                except OSError as err:
                    raise ValueError(f"{self.label}: cannot write into the output directory "
                                     f"({err.strerror or err})") from None
                with os.fdopen(fd, "w", encoding="ascii") as f:
                    f.write(f"{os.getpid()}\n")
                self._locked = True
                return note
        raise ValueError(f"{self.label}: could not take the lock {self.lock}")

    def _stale_or_busy(self) -> str:
        """The note on taking over a stale lock; raises if the lock is held."""
        pid = _read_pid(self.lock)
        try:
            age = time.time() - self.lock.stat().st_mtime
        except OSError:
            age = 0.0
        held = _pid_alive(pid) if pid is not None else age < _LOCK_GRACE_S
        if held:
            who = f"pid {pid}" if pid is not None else "a process that is starting"
            raise ValueError(
                f"{self.label} is in use by another trackkit run ({who}; lock file "
                f"{self.lock}); wait for it to finish or choose another --out. If no "
                f"trackkit run is using it, delete {self.lock}")
        who = f"pid {pid}, no longer running" if pid is not None else "no readable pid"
        return f"took over the stale lock {self.lock} ({who})"

    def _release(self) -> None:
        if self._locked and _read_pid(self.lock) == os.getpid():
            self.lock.unlink(missing_ok=True)
        self._locked = False

    def _remove_created(self) -> None:
        for d in reversed(self.created):
            try:
                d.rmdir()
            except OSError:  # not empty or gone: leave it
                return


def _jsonable(value: Any) -> Any:
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, StrEnum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def _may_write(command: str, path: Path) -> tuple[str, ...]:
    """The report files a command may write into its output directory."""
    from trackkit.report.files import TRACKKIT_FILES

    if command == "run":
        from trackkit.report.tracking_report import TRACKING_FILES

        return (*TRACKKIT_FILES, *TRACKING_FILES)
    if command == "network":
        from trackkit.report.network_report import NETWORK_FILES

        return NETWORK_FILES
    if command == "identify":
        from trackkit.report.vessel_report import VESSEL_FILES

        return VESSEL_FILES
    if command == "track":
        from trackkit.report.track_pages import TRACK_FILES

        return TRACK_FILES
    if command == "sweep":
        from trackkit.report.sweep_report import sweep_outputs

        return tuple(sweep_outputs(path))
    return ()


def _command_run(path: Path) -> Any:
    """The running command as ``report.files.CommandRun`` (its name, its arguments, the
    files it may write), or None outside a command."""
    ctx = _current_context()
    if ctx is None or not ctx.info_name:
        return None
    from trackkit.report.files import CommandRun

    return CommandRun(ctx.info_name, {k: _jsonable(v) for k, v in ctx.params.items()},
                      _may_write(ctx.info_name, path))


def default_dir(scenario: str | None, sc: Any) -> str:
    """The default output directory's name: a scenario file's stem (my.toml -> my), a
    bundled scenario's name."""
    p = Path(scenario) if scenario else None
    if p is not None and (p.suffix == ".toml" or p.is_file()):
        return p.stem
    return str(sc.name)


def output_dir(out: Path | None, name: str) -> tuple[Path, str]:
    """The run's output directory and how to name it in messages. The default
    ``trackkit-out/NAME`` must be a directory inside ``trackkit-out``."""
    if out is not None:
        return out, f"--out {out}"
    target = DEFAULT_OUT / name
    base = DEFAULT_OUT.resolve()
    inside = target.resolve()
    plain = bool(name) and name not in (".", "..") and Path(name).name == name and (
        "\\" not in name)
    if not plain or inside.parent != base:
        raise ValueError(f"scenario name {name!r} cannot name a directory inside "
                         f"{DEFAULT_OUT}/ (expected a plain name such as 'my-scenario'); "
                         "rename the scenario or pass --out DIR")
    return target, f"the output directory {target}"


# --- progress ---------------------------------------------------------------------------------


def progress_bar(console: Console) -> Progress:
    return Progress(
        TextColumn("{task.description}", style="bold", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[unit]}"),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=console,
    )



def say_note(where: OutputDir) -> None:
    """The note of an output directory whose stale lock was taken over, if any."""
    if where.note:
        stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)


def deliver_interrupt() -> None:
    """Raise a Ctrl-C that arrived inside a finaliser (see ``entry._unraisable``)."""
    if session.interrupt:
        session.interrupt = False
        raise KeyboardInterrupt

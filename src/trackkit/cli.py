"""The ``trackkit`` command: list, show and run the bundled (or your own) scenarios, and track
recorded data.

    trackkit list
    trackkit show bo-cv [--format toml|json]
    trackkit run [NAME|FILE] [--runs N] [--seed S] [--out DIR] [--workers K] [--scheduler ADDR]
    trackkit sweep [NAME|FILE] --param PATH=V1,V2,... [--param ...] [--design grid|random|lhs]
                   [--points N] [--runs N] [--seed S] [--block B] [--workers K | --scheduler ADDR]
                   [--out DIR] [--fresh]
    trackkit network NAME|FILE [--runs N] [--seed S] [--out DIR] [--straight]
                     [--agents inprocess|processes]
    trackkit track FILE [--format ais|opensky|detections] [--as-radar] [radar, tracker and
                   input options] [--on-bad skip|stop] [--out DIR]
    trackkit identify LOG --inputs INPUTS.csv [--filter ekf|ukf|ckf|srckf|ls] [--period 1]
                      [--on-bad skip|stop] [--out DIR]
    trackkit identify NAME|FILE [--runs N] [--seed S] [--filter ...] [--out DIR]

Exit codes: 0 done; 1 a system error (disk full, a Dask scheduler that does not answer, an
unexpected failure); 2 bad input (a scenario error, a bad option value, an output directory
that cannot be created or written, or one that another run is writing into); 130
interrupted (Ctrl-C). Every failure is one message in words, no traceback
(``TRACKKIT_DEBUG=1`` keeps the traceback). The output directory is created, proven writable
and locked before anything is computed; report files appear only when complete, listed in its
``manifest.json`` (which command wrote them, with what arguments). A directory holding another
command's output, or files no manifest lists that the command would overwrite, is refused. The
default directory is ``trackkit-out/NAME``: a scenario file's name without ``.toml``, else the
bundled scenario's name.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    # Ctrl-C while the modules below import: nothing has been written and nothing is held, so
    # leave at once; a KeyboardInterrupt here would surface as a traceback from deep inside an
    # import (or as pydantic's "Error calling __set_name__")
    os.write(2, b"interrupted\n")
    os._exit(130)


def _started_as_command() -> bool:
    from multiprocessing import parent_process

    if parent_process() is not None:  # a worker process started by the command: not it
        return False
    return __name__ == "__main__" or os.path.basename(sys.argv[0] or "").startswith("trackkit")


try:
    _previous_sigint = signal.signal(signal.SIGINT, _interrupted_while_starting)
except ValueError:  # imported outside the main thread: signals are not ours to handle
    _previous_sigint = None

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from enum import StrEnum  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace, TracebackType  # noqa: E402
from typing import Annotated, Any  # noqa: E402

import click  # noqa: E402
import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.progress import (  # noqa: E402
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.syntax import Syntax  # noqa: E402
from rich.table import Table  # noqa: E402
from rich.text import Text  # noqa: E402

__all__ = ["app", "main", "LOCK_FILE"]

DEFAULT_OUT = Path("trackkit-out")
#: in the output directory while a run writes into it; holds the run's process id
LOCK_FILE = ".trackkit.lock"
#: a lock file without a readable pid younger than this may be one being written right now
_LOCK_GRACE_S = 10.0

class _FlagsWithoutType:
    """Help without a ``<bool>`` type beside a flag (``--help``, ``--straight``): a flag
    takes no value."""

    def get_params(self, ctx: click.Context) -> list[Any]:
        params = super().get_params(ctx)  # type: ignore[misc]
        for p in params:
            if getattr(p, "is_bool_flag", False) and not p.secondary_opts and (
                    p.metavar is None):
                p.metavar = ""
        return params


class _Group(_FlagsWithoutType, typer.core.TyperGroup):
    pass


class _Command(_FlagsWithoutType, typer.core.TyperCommand):
    pass


app = typer.Typer(
    name="trackkit",
    cls=_Group,
    help="Target tracking comparisons: Monte Carlo runs, PCRLB, tables, plots and reports.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

#: process-wide flags of main(): whether it runs the command, whether "interrupted" was said
_state = SimpleNamespace(main=False, announced=False, interrupt=False)


# --- the stages the CLI drives (imported lazily; tests replace these functions) ------------


def _bundled() -> dict[str, str]:
    from trackkit.scenario import bundled

    return bundled()


def _default_name() -> str:
    from trackkit.scenario import DEFAULT

    return DEFAULT


def _load(name_or_path: str) -> Any:
    from trackkit.scenario import load
    from trackkit.scenario.multitarget import is_multitarget, load_multitarget
    from trackkit.scenario.network import is_network, load_network
    from trackkit.scenario.vessel import is_vessel, load_vessel

    if is_network(name_or_path):  # [[agents]]: an agent network (trackkit network)
        return load_network(name_or_path)
    if is_vessel(name_or_path):  # a [vessel] table: a vessel's identification (identify)
        return load_vessel(name_or_path)
    if is_multitarget(name_or_path):  # a [scene] table: the multi-target tracker comparison
        return load_multitarget(name_or_path)
    return load(name_or_path)


def _is_multitarget(scenario: Any) -> bool:
    return hasattr(scenario, "scene") and hasattr(scenario, "trackers")


def _is_network(scenario: Any) -> bool:
    return hasattr(scenario, "agents") and hasattr(scenario, "network")


def _is_vessel(scenario: Any) -> bool:
    return hasattr(scenario, "vessel") and hasattr(scenario, "identification")


def _dumps(scenario: Any) -> str:
    from trackkit.scenario import dumps

    return dumps(scenario)


def _run(scenario: Any, **kwargs: Any) -> Any:
    from trackkit.eval.compare import compare

    return compare(scenario, **kwargs)


def _write(result: Any, out: Path) -> dict[str, Path]:
    from trackkit.report.files import write_report

    return write_report(result, out)


# --- errors in words --------------------------------------------------------------------------


def _stderr() -> Console:
    return Console(stderr=True)


def _is_interrupt(err: BaseException | None) -> bool:
    """A KeyboardInterrupt, or an error raised because of one (Python wraps an interrupt
    inside ``__set_name__`` in a RuntimeError, e.g. while pydantic builds a model class)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def _say_interrupted(message: str = "interrupted") -> None:
    if _state.main:  # a second Ctrl-C must not break the message into a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    _state.announced = True
    _stderr().print(Text(message, style="yellow"), soft_wrap=True)


def _fail(message: str, code: int) -> None:
    text = Text("error: ", style="bold red")
    text.append(message or "unknown error", style="red")
    _stderr().print(text, soft_wrap=True)
    raise typer.Exit(code)


def _describe(err: BaseException) -> tuple[str, int]:
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
def _user_errors(state: SimpleNamespace | None = None) -> Iterator[SimpleNamespace]:
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
        if _is_interrupt(err):
            _say_interrupted(state.interrupted)
            raise typer.Exit(130) from None
        if not isinstance(err, Exception) or os.environ.get("TRACKKIT_DEBUG"):
            raise
        message, code = _describe(err)
        _fail(message, code)


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
        from trackkit.report.tracks import TRACK_FILES

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


def _default_dir(scenario: str | None, sc: Any) -> str:
    """The default output directory's name: a scenario file's stem (my.toml -> my), a
    bundled scenario's name."""
    p = Path(scenario) if scenario else None
    if p is not None and (p.suffix == ".toml" or p.is_file()):
        return p.stem
    return str(sc.name)


def _output_dir(out: Path | None, name: str) -> tuple[Path, str]:
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


def _progress_bar(console: Console) -> Progress:
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


def _run_with_progress(scenario: Any, total: int, **kwargs: Any) -> Any:
    """The comparison with a progress bar of runs (``progress(done, total)``, ``done`` a
    float that moves within a block) and, when fuzzy systems are tuned first, one of
    optimiser generations (``tuning_progress(done, total)``)."""
    console = _stderr()
    with _progress_bar(console) as bar:
        runs = bar.add_task(str(getattr(scenario, "name", "runs")), total=total, unit="runs")
        tuning: list[Any] = []
        final = [total]

        def progress(done: float, of: int) -> None:
            _deliver_interrupt()
            final[0] = of
            bar.update(runs, completed=done, total=of)

        def tuning_progress(done: int, of: int) -> None:
            _deliver_interrupt()
            if not tuning:
                tuning.append(bar.add_task("tuning", total=of, unit="generations"))
            bar.update(tuning[0], completed=done, total=of)

        result = _run(scenario, progress=progress, tuning_progress=tuning_progress, **kwargs)
        _deliver_interrupt()
        bar.update(runs, completed=final[0], total=final[0])
    return result


# --- commands ---------------------------------------------------------------------------------


class Format(StrEnum):
    toml = "toml"
    json = "json"


SCENARIO_HELP = "Bundled scenario name (see trackkit list) or TOML file."


def _positive_hours(value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"{value}; expected a positive number of hours")
    return value


def _at_least(lowest: int) -> Any:
    """An option callback: the message names the value given (typer's own range check
    says only what the bound is)."""
    def check(value: int | None) -> int | None:
        if value is not None and value < lowest:
            raise typer.BadParameter(f"{value}; expected an integer >= {lowest}")
        return value

    return check


@app.command("list")
def list_scenarios() -> None:
    """List the bundled scenarios with one-line descriptions."""
    with _user_errors():
        from trackkit.scenario.multitarget import bundled_multitarget
        from trackkit.scenario.network import bundled_network

        scenarios = {**_bundled(), **bundled_multitarget(), **bundled_network(),
                     **_bundled_vessel()}
        default = _default_name()
        table = Table("scenario", "description", title="bundled scenarios",
                      title_justify="left")
        for name, description in scenarios.items():
            label = Text(name, style="bold")
            if name == default:
                label.append(" (default)", style="dim")
            table.add_row(label, Text(description))
        Console().print(table)
        from trackkit.io.samples import SAMPLES

        samples = Table("sample", "description", title="bundled samples (trackkit track NAME "
                        "--as-radar)", title_justify="left")
        for name, (_, description) in SAMPLES.items():
            samples.add_row(Text(name, style="bold"), Text(description))
        Console().print(samples)


@app.command()
def show(
    scenario: Annotated[str | None, typer.Argument(
        help=SCENARIO_HELP, show_default="the bundled default")] = None,
    fmt: Annotated[Format, typer.Option(
        "--format", "-f", help="TOML (what trackkit run reads) or JSON.")] = Format.toml,
) -> None:
    """Print a scenario with every default filled in (save it, edit it, run it)."""
    with _user_errors():
        sc = _load(scenario or _default_name())
        if fmt is Format.toml:
            text = _dumps(sc)
        else:
            text = json.dumps(sc.model_dump(mode="json"), indent=2)
        console = Console()
        if console.is_terminal:
            console.print(Syntax(text, fmt.value, theme="ansi_dark",
                                 background_color="default", word_wrap=True))
        else:  # piped: the exact text, no wrapping, so that it can be saved and read back
            typer.echo(text, nl=not text.endswith("\n"))


@app.command()
def run(
    scenario: Annotated[str | None, typer.Argument(
        help=SCENARIO_HELP, show_default="the bundled default")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=_at_least(1), help="Monte Carlo runs (at least 1).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=_at_least(0), help="Master seed (0 or more).",
        show_default="the scenario's run.seed")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/SCENARIO; for a file, its name without .toml")] = None,
    workers: Annotated[int | None, typer.Option(
        "--workers", "-w", callback=_at_least(1), help="Local Dask workers (at least 1).",
        show_default="none: in this process")] = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Dask scheduler address, e.g. tcp://host:8786.",
        show_default="none")] = None,
    max_hours: Annotated[float, typer.Option(
        "--max-hours", callback=_positive_hours, help="Refuse a run count that the first "
        "block's timing says would take longer (hours).")] = 24.0,
) -> None:
    """Run a Monte Carlo comparison; write results.json, timings.json, metrics.parquet,
    plots and report.html.

    The same scenario, seed and block size give bit-identical numbers on one machine, on any
    executor and any number of workers; another CPU agrees to rounding (see the README,
    "Determinism")."""
    with _user_errors() as state:
        sc = _load(scenario or _default_name())
        if _is_network(sc):
            raise ValueError(f"{scenario} is a network scenario; run it with "
                             f"`trackkit network {scenario}`")
        if _is_vessel(sc):
            raise ValueError(f"{scenario} is a vessel scenario; run it with "
                             f"`trackkit identify {scenario}`")
        target, label = _output_dir(out, _default_dir(scenario, sc))
        total = runs or getattr(getattr(sc, "run", None), "runs", None) or 1
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            if where.note:
                _stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)
            if _is_multitarget(sc):
                _run_multitarget(sc, where.path, runs=runs, seed=seed, workers=workers,
                                 scheduler=scheduler)
                state.interrupted = "interrupted"
                return
            result = _run_with_progress(sc, total, runs=runs, seed=seed, workers=workers,
                                        scheduler=scheduler, max_seconds=3600.0 * max_hours)
            with _stderr().status("writing the report"):
                paths = _write(result, where.path)
            state.interrupted = "interrupted"
            _print_summary(result, paths)


def _run_multitarget(sc: Any, out: Path, **kwargs: Any) -> None:
    """A multi-target scenario: every tracker on the same simulated scans (Monte Carlo),
    GOSPA, OSPA and the track counts; the report written into ``out``."""
    import numpy as np

    from trackkit.eval.tracking_run import run_multitarget
    from trackkit.report.tracking_report import write_tracking_report

    total = kwargs.get("runs") or sc.run.runs
    with _progress_bar(_stderr()) as bar:
        task = bar.add_task(str(sc.name), total=total, unit="runs")

        def progress(done: float, of: int) -> None:
            _deliver_interrupt()
            bar.update(task, completed=done, total=of)

        result, example = run_multitarget(sc, progress=progress, **kwargs)
        _deliver_interrupt()
    with _stderr().status("writing the report"):
        paths = write_tracking_report(result, sc, example, out)
    console = Console()
    headers = ["tracker", "GOSPA [m]", "OSPA [m]",
               f"confirmed within {sc.report.confirm_within_scans:g} scans",
               "false tracks / 100 scans", "breaks", "ID switches", "RMSE [m]"]
    scans = result.runs * result.times.size
    rows = []
    for name, r in result.trackers.items():
        s = r.summary
        rows.append([name, f"{r.mean_gospa:.1f}", f"{float(np.mean(r.ospa)):.1f}",
                     f"{100 * s['confirmed_within_fraction']:.1f}%",
                     f"{100 * s['false_tracks'] / scans:.2f}", str(s["breaks"]),
                     str(s["id_switches"]), f"{s['rmse']:.1f}"])
    console.print(_number_table(headers, rows, f"{sc.name}: {result.runs} runs, seed "
                                f"{result.seed}, c = {result.c:g} m", console))
    for note in sc.notes:
        console.print(Text(f"note: {note}", style="yellow"))
    html = paths.get("html")
    console.print(Text(f"wrote {len(paths)} files to {out}", style="green"))
    if html is not None:
        console.print(Text(f"report: {html}", style="green"))


# --- trackkit sweep: campaigns ---------------------------------------------------------------


class DesignName(StrEnum):
    grid = "grid"
    random = "random"
    lhs = "lhs"


#: point bars shown at once (the overall bars count every point)
_POINT_BARS = 8


def _sweep_listener(bar: Progress, console: Console) -> Any:
    """The campaign's progress on ``bar``: runs over the campaign, points finished, and a bar
    per point in progress. Dask's progress events arrive on another thread: only the main
    thread delivers a pending Ctrl-C."""
    import threading

    from trackkit.eval.sweep import Listener

    class Bars(Listener):
        def start(self, campaign: Any, stored_runs: list[int], stored_blocks: list[int],
                  finished: list[bool]) -> None:
            self.lock = threading.Lock()
            self.campaign, self.done, self.finished_ = campaign, list(stored_runs), finished
            self.rows: dict[int, Any] = {}
            n, runs = len(campaign.points), campaign.runs
            nb = campaign.blocks_per_point
            if any(stored_blocks):
                console.print(Text(
                    f"resuming: {sum(stored_blocks)} of {n * nb} blocks already stored "
                    f"({sum(finished)} of {n} points complete)", style="yellow"),
                    soft_wrap=True)
            self.overall = bar.add_task("campaign", total=n * runs, unit="runs",
                                        completed=sum(stored_runs))
            self.points = bar.add_task("points", total=n, unit="points",
                                       completed=sum(finished))

        def progress(self, i: int, runs_done: float) -> None:
            if threading.current_thread() is threading.main_thread():
                _deliver_interrupt()
            with self.lock:
                self.done[i] = max(self.done[i], runs_done)
                if i not in self.rows and len(self.rows) < _POINT_BARS and not (
                        self.finished_[i]):
                    label = self.campaign.points[i].label()
                    label = label if len(label) <= 48 else label[:45] + "..."
                    self.rows[i] = bar.add_task(f"  {label}", total=self.campaign.runs,
                                                unit="runs")
                if i in self.rows:
                    bar.update(self.rows[i], completed=self.done[i])
                bar.update(self.overall, completed=sum(self.done))

        def finished(self, i: int) -> None:
            with self.lock:
                self.finished_[i] = True
                bar.update(self.points, advance=1)
                task = self.rows.pop(i, None)
                if task is not None:
                    bar.remove_task(task)

    return Bars()


@app.command()
def sweep(
    scenario: Annotated[str | None, typer.Argument(
        help=SCENARIO_HELP, show_default="the bundled default")] = None,
    param: Annotated[list[str] | None, typer.Option(
        "--param", "-p", help="A swept field by its dotted path (as trackkit show prints it: "
        "observers.0.sensor.sigma_deg, sensor.sigma_deg for every observer, "
        "filters.EKF.motion.q for a filter's own assumption, filters.*.motion.q for every "
        "filter's): PATH=V1,V2,... (xF: the scenario's value times F) or, for --points, "
        "PATH=LOW:HIGH or PATH=log:LOW:HIGH. Repeat for each parameter.",
        show_default="the scenario's [sweep] table")] = None,
    design: Annotated[DesignName | None, typer.Option(
        "--design", help="The full grid of the values, or --points points drawn at random "
        "or by Latin hypercube (seeded by --seed).",
        show_default="the [sweep] table's, else grid")] = None,
    points: Annotated[int | None, typer.Option(
        "--points", callback=_at_least(1), help="random, lhs: the number of points; grid: "
        "the values per range.")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=_at_least(1), help="Monte Carlo runs per point.",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=_at_least(0), help="Campaign seed; each point's seed is a "
        "hash of it and the point's values.", show_default="the scenario's run.seed")] = None,
    block: Annotated[int | None, typer.Option(
        "--block", callback=_at_least(1), help="Runs per block, the unit of work and of "
        "checkpoints (results are bit-identical for the same block size).",
        show_default="the scenario's run.block")] = None,
    workers: Annotated[int | None, typer.Option(
        "--workers", "-w", callback=_at_least(1), help="Local Dask workers (at least 1).",
        show_default="none: in this process")] = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Dask scheduler address, e.g. tcp://host:8786.",
        show_default="none")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Campaign directory (created if missing): checkpoints and "
        "report.", show_default="trackkit-out/SCENARIO-sweep")] = None,
    fresh: Annotated[bool, typer.Option(
        "--fresh", help="Discard the blocks stored in the campaign directory and start "
        "afresh (needed when the scenario, sweep, runs, seed, block or code changed).")
    ] = False,
) -> None:
    """Run a Monte Carlo comparison at every point of a sweep over scenario fields; write
    sweep.parquet, sweep.csv, figures and report.html.

    Every finished block is stored in the campaign directory: run the same command again
    after an interruption and it resumes, with bit-identical results. A point's seed derives
    from the campaign seed and its values, so adding points leaves the others unchanged."""
    with _user_errors() as state:
        if workers and scheduler:
            raise ValueError(f"--workers {workers} and --scheduler {scheduler}: give one, "
                             "--workers for a local Dask cluster or --scheduler for a running "
                             "one")
        sc = _load(scenario or _default_name())
        if _is_network(sc) or _is_vessel(sc) or _is_multitarget(sc):
            raise ValueError(f"{scenario}: trackkit sweep runs single-target Monte Carlo "
                             "comparisons (the scenarios of trackkit run without [scene], "
                             "[[agents]] or [vessel])")
        from trackkit.eval.checkpoint import CampaignStore, CheckpointError
        from trackkit.eval.sweep import BlockFailed, parse_param, plan_campaign, run_campaign
        from trackkit.report.sweep_report import sweep_outputs, write_sweep_report

        params = [parse_param(p) for p in param or []]
        with _stderr().status("checking every point of the sweep"):
            campaign = plan_campaign(sc, params, design.value if design else None, points,
                                     runs, seed, block)
        target, label = _output_dir(out, f"{_default_dir(scenario, sc)}-sweep")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was stored in {target}"
            if where.note:
                _stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)
            store = CampaignStore(where.path, label)
            store.open(campaign.identity(), fresh=fresh, scenario_toml=_dumps(campaign.base),
                       outputs=sweep_outputs(where.path))
            state.interrupted = (f"interrupted; the finished blocks are stored in {target}: "
                                 "run the same command again to resume")
            console = _stderr()
            console.print(Text(
                f"{sc.name}: {campaign.design} design, {len(campaign.points)} points x "
                f"{campaign.runs} runs (block {campaign.block}, seed {campaign.seed}) -> "
                f"{target}", style="bold"), soft_wrap=True)
            try:
                with _progress_bar(console) as bar:
                    docs = run_campaign(campaign, store, workers=workers, scheduler=scheduler,
                                        listener=_sweep_listener(bar, console))
                    _deliver_interrupt()
            except BlockFailed as err:
                _fail(f"{err}. The campaign stopped; the blocks finished so far are stored in "
                      f"{target}: fix the cause and run the same command again to resume",
                      1)
            except CheckpointError as err:
                _fail(str(err), 1)
            with _stderr().status("writing the report"):
                paths = write_sweep_report(campaign, docs, where.path,
                                           [store.load_timings(p.id) for p in campaign.points])
            state.interrupted = "interrupted"
            _print_sweep_summary(campaign, docs, paths)


def _print_sweep_summary(campaign: Any, docs: list[dict], paths: dict[str, Path]) -> None:
    from trackkit.report.tables import Summary, display_unit, summary_rich_table

    console = Console()
    g = campaign.base.report.groups[0]
    unit, factor = display_unit(docs[0]["units"].get(g, "") if docs else "")
    paths_ = [p.path for p in campaign.params]
    # each swept value under its field's last name (the full paths in the caption)
    short = [q.rsplit(".", 1)[-1] for q in paths_]
    names = short if len(set(short)) == len(short) else paths_

    def num(v: Any, scale: float = 1.0) -> str:
        return "n/a" if v is None else f"{v * scale:.4g}"

    cells: list[list[str]] = []
    shown, limit = 0, 40
    for d in docs:
        for name, f in d["filters"].items():
            if shown == limit:
                break
            shown += 1
            cells.append([*(str(d["values"][q]) for q in paths_), name,
                         num(f["rmse"].get(g), factor), num(f["rmse_pcrlb"].get(g)),
                         num(f["anees"]), f"{f['diverged'] / d['runs']:.1%}"])
    caption = ", ".join(f"{n} = {q}" for n, q in zip(names, paths_, strict=True)
                        if n != q)
    table = Summary([*names, "filter", f"{g} RMSE [{unit}]", "RMSE / PCRLB", "ANEES",
                     "diverged"], cells, caption,
                    title=f"{campaign.base.name}: {len(campaign.points)} points x "
                    f"{campaign.runs} runs, seed {campaign.seed}")
    console.print(summary_rich_table(table, console.width))
    rows = sum(len(d["filters"]) for d in docs)
    if rows > shown:
        console.print(Text(f"... {rows - shown} more rows in {paths['csv']}", style="dim"))
    for note in campaign.notes:
        console.print(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    console.print(Text(f"wrote {len(paths)} files to {paths['html'].parent}", style="green"),
                  soft_wrap=True)
    console.print(Text(f"report: {paths['html']}", style="green"), soft_wrap=True)


class AgentsMode(StrEnum):
    """Where a network scenario's agents run (``trackkit network --agents``)."""

    inprocess = "inprocess"
    processes = "processes"


@app.command()
def network(
    scenario: Annotated[str, typer.Argument(
        help="Bundled network scenario name (net-baseline, net-limited, net-random; see "
        "trackkit list) or TOML file.")],
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=_at_least(1), help="Monte Carlo runs (at least 1).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=_at_least(0), help="Master seed (0 or more).",
        show_default="the scenario's run.seed")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/SCENARIO (trackkit-out/SCENARIO-straight with "
        "--straight)")] = None,
    straight: Annotated[bool, typer.Option(
        "--straight", help="Straight courses: no steering, whatever the scenario says "
        "(for comparison with the steered agents).")] = False,
    agents: Annotated[AgentsMode, typer.Option(
        "--agents", help="inprocess: every agent in this process (fast); processes: every "
        "agent its own operating-system process, talking over ZeroMQ on loopback (same "
        "results without message loss, slower).")] = AgentsMode.inprocess,
    compare_straight: Annotated[bool, typer.Option(
        "--compare-straight", help="Also run the same runs on straight courses and report "
        "whether steering pays (twice the time).")] = False,
    loss: Annotated[float | None, typer.Option(
        "--loss", help="Probability that one message delivery is lost, in [0, 1).",
        show_default="the scenario's network.loss")] = None,
    delay: Annotated[float, typer.Option(
        "--delay", help="Delivery delay of every message, simulated seconds (with --agents "
        "processes).")] = 0.0,
    kill: Annotated[list[str] | None, typer.Option(
        "--kill", help="AGENT@T or AGENT@T:RESTART: kill agent AGENT (numbered from 1) at "
        "simulated time T s and restart it at RESTART s (with --agents processes; may be "
        "repeated).")] = None,
    host: Annotated[str, typer.Option(
        "--host", help="Address the environment binds for the agents' ZeroMQ connections "
        "(with --agents processes; 0.0.0.0 to accept agents from other machines).")]
        = "127.0.0.1",
    advertise: Annotated[str | None, typer.Option(
        "--advertise", help="This machine's address as the agents' machines see it (with "
        "--host 0.0.0.0 and --launch).")] = None,
    launch: Annotated[list[str] | None, typer.Option(
        "--launch", help="AGENT=COMMAND: start agent AGENT (from 1) through COMMAND, e.g. "
        "'2=ssh boat2', on a machine with trackkit installed (may be repeated).")] = None,
    remote_python: Annotated[str, typer.Option(
        "--remote-python", help="The Python with trackkit installed on the --launch "
        "machines.")] = "python3",
    curve: Annotated[bool | None, typer.Option(
        "--curve/--no-curve", help="Authenticate and encrypt the agents' connections with "
        "ZeroMQ's CURVE, refusing and counting any other peer (with --agents processes).",
        show_default="on when --host is not a loopback address")] = None,
    keys: Annotated[Path | None, typer.Option(
        "--keys", help="Directory of CURVE certificates (server.key_secret, and "
        "client.key_secret or agent-N.key_secret) instead of keys made for the run; "
        "implies --curve.")] = None,
) -> None:
    """Run a network scenario (agents with bearing sensors that track targets together,
    after Jalalipoor and Kardehi Moghaddam 2021): Monte Carlo runs of the agents beside the
    centralised reference and the PCRLB; write results.json, timings.json, plots and
    report.html.

    The same scenario and seed give byte-identical results.json on one machine."""
    with _user_errors() as state:
        from trackkit.network.run import check_loss
        from trackkit.scenario.network import is_network, load_network

        if not is_network(scenario):
            p = Path(scenario)
            if p.suffix == ".toml" or p.exists():
                if p.is_file():  # (a missing or unreadable file: load_network says so)
                    _parse_toml(p)
                    raise ValueError(f"{scenario}: not a network scenario (it has no "
                                     "[[agents]] tables); run it with `trackkit run "
                                     f"{scenario}`, or see `trackkit show net-baseline` "
                                     "for a network scenario's fields")
            elif scenario in {**_bundled(), **_bundled_multitarget()}:
                raise ValueError(f"{scenario!r} is not a network scenario; run it with "
                                 f"`trackkit run {scenario}` (network scenarios: see "
                                 "trackkit list)")
        sc = load_network(scenario)
        if compare_straight and (straight or not sc.settings.steering):
            raise ValueError("--compare-straight compares steered agents with straight "
                             "courses; expected a scenario with settings.steering = true "
                             "and no --straight")
        outages = _outages(kill or [], len(sc.agents), sc.network.duration_s)
        launchers = _launchers(launch or [], len(sc.agents))
        if agents != AgentsMode.processes and (delay != 0.0 or outages or launchers
                                               or host != "127.0.0.1" or advertise
                                               or curve is not None or keys is not None):
            raise ValueError("--delay, --kill, --host, --advertise, --launch, --curve and "
                             "--keys act on agents in their own processes; expected "
                             "--agents processes with them")
        if loss is not None:
            check_loss(loss, "--loss")
        if not (math.isfinite(delay) and delay >= 0.0):
            raise ValueError(f"--delay {delay!r}; expected simulated seconds >= 0")
        if curve is False and agents == AgentsMode.processes:
            from trackkit.network.processes import is_loopback

            if not is_loopback(host):
                _stderr().print(Text(f"note: --no-curve with --host {host}: any machine that "
                                     "reaches it can connect and feed the agents bearings or "
                                     "tracks", style="yellow"), soft_wrap=True)
        name = _default_dir(scenario, sc) + ("-straight" if straight else "")
        target, label = _output_dir(out, name)
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            if where.note:
                _stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)
            _run_network(sc, where.path, runs=runs, seed=seed,
                         steering=False if straight else None, agents=str(agents.value),
                         compare_straight=compare_straight, loss=loss, delay=delay,
                         outages=outages, host=host, advertise=advertise,
                         launch=launchers or None, remote_python=remote_python,
                         curve=curve, keys=keys)
            state.interrupted = "interrupted"


def _parse_toml(path: Path) -> None:
    """Raise the reader's error in words (not UTF-8, not valid TOML, with line and column)
    before a file is called the wrong kind of scenario for lacking a table."""
    from trackkit.scenario import read_scenario

    read_scenario(path, None)


def _outages(specs: list[str], n_agents: int, duration: float
             ) -> list[tuple[int, float, float | None]]:
    """``--kill AGENT@T[:RESTART]`` (agent from 1, simulated s) as ``run_network_processes``
    outages (agent from 0)."""
    out: list[tuple[int, float, float | None]] = []
    given: dict[int, str] = {}
    for spec in specs:
        agent, _, when = spec.partition("@")
        at, _, rest = when.partition(":")
        try:
            a, k = int(agent), float(at)
            r = float(rest) if rest else None
        except ValueError:
            raise ValueError(f"--kill {spec!r}; expected AGENT@T or AGENT@T:RESTART, e.g. "
                             "2@400:500") from None
        if not 1 <= a <= n_agents:
            raise ValueError(f"--kill {spec!r}: agent {a}; expected 1 to {n_agents}")
        if not 0.0 <= k < duration or (r is not None and not k < r):
            back = "no restart" if r is None else f"restart at {r:g} s"
            raise ValueError(f"--kill {spec!r}: kill at {k:g} s, {back}; expected "
                             f"0 <= T < {duration:g} s and RESTART > T")
        if a in given:
            raise ValueError(f"--kill {given[a]!r} and --kill {spec!r}: agent {a} is killed "
                             "twice; expected one --kill per agent (AGENT@T:RESTART kills and "
                             "restarts it once)")
        given[a] = spec
        out.append((a - 1, k, r))
    return out


def _launchers(specs: list[str], n_agents: int) -> dict[int, list[str]]:
    """``--launch AGENT=COMMAND`` (agent from 1) as ``run_network_processes``' launch
    prefixes (agent from 0)."""
    import shlex

    out: dict[int, list[str]] = {}
    for spec in specs:
        agent, _, command = spec.partition("=")
        try:
            a = int(agent)
        except ValueError:
            a = 0
        cmd = shlex.split(command)
        if not (1 <= a <= n_agents and cmd):
            raise ValueError(f"--launch {spec!r}; expected AGENT=COMMAND with AGENT from 1 "
                             f"to {n_agents}, e.g. '2=ssh boat2'")
        out[a - 1] = cmd
    return out


def _bundled_multitarget() -> dict[str, str]:
    from trackkit.scenario.multitarget import bundled_multitarget

    return bundled_multitarget()


def _run_network(sc: Any, out: Path, **kwargs: Any) -> None:
    """A network scenario's Monte Carlo (``eval.network_mc``) with a progress bar of runs,
    its report written into ``out`` and a per-agent summary printed."""
    from trackkit.eval.network_mc import run_network_mc
    from trackkit.report.network_report import write_network_report

    compare = kwargs.pop("compare_straight", False)
    total = kwargs.get("runs") or sc.run.runs
    given = "--runs" if kwargs.get("runs") else "the scenario's run.runs; --runs N for fewer"
    where = ("in their own processes" if kwargs.get("agents") == "processes"
             else "in this process")
    _stderr().print(Text(
        f"{sc.name}: {total} Monte Carlo run{'' if total == 1 else 's'} ({given})"
        + (", then the same runs on straight courses" if compare else "")
        + f", agents {where} -> {out}", style="bold"), soft_wrap=True)
    with _progress_bar(_stderr()) as bar:

        def monte_carlo(label: str, **more: Any):
            task = bar.add_task(label, total=total, unit="runs")

            def progress(done: float, of: int) -> None:
                _deliver_interrupt()
                bar.update(task, completed=done, total=of)

            result = run_network_mc(sc, progress=progress, **{**kwargs, **more})
            _deliver_interrupt()
            return result

        mc = monte_carlo(str(sc.name))
        straight = (monte_carlo(f"{sc.name} (straight)", steering=False, keep_example=False)
                    if compare else None)
    with _stderr().status("writing the report"):
        paths = write_network_report(mc, sc, out, straight=straight)
    _print_network_summary(paths)


def _number_table(headers: list[str], rows: list[list[str]], title: str, console: Console
                  ) -> Any:
    """A summary table whose numbers are never cut at the console's width (folded instead;
    ``report.tables.summary_rich_table``)."""
    from trackkit.report.tables import Summary, summary_rich_table

    return summary_rich_table(Summary(headers, rows, "", title=title), console.width)


def _print_network_summary(paths: dict[str, Path]) -> None:
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    w = doc["windows"]["last"]
    mode = "steering" if doc["steering"] else "straight courses"
    headers = ["agent", "all held at the end", "GOSPA [m]",
               f"pos. RMSE {w[0]:g}-{w[1]:g} s [m]", "centralised [m]", "PCRLB [m]",
               "ratio to centralised", "ratio to PCRLB"]

    def per_target(v: list, spec: str) -> str:
        return " / ".join("-" if x is None else format(x, spec) for x in v)

    rows = [[str(e["agent"]), f"{100 * e['all_held_final_fraction']:.0f}%",
             "-" if e["gospa_mean"] is None else f"{e['gospa_mean']:.0f}",
             per_target(e["rmse_pos_last"], ".0f"),
             per_target(e["central_rmse_pos_last"], ".0f"),
             per_target(e["pcrlb_pos_last"], ".0f"),
             per_target(e["ratio_to_central_pos_last"], ".2f"),
             per_target(e["ratio_to_pcrlb_pos_last"], ".2f")] for e in doc["per_agent"]]
    console = Console()
    console.print(_number_table(headers, rows, f"{doc['scenario']}: {doc['runs']} runs, "
                                f"seed {doc['seed']}, {mode} (per target: 1 / 2 / ...)",
                                console))
    m = doc["messages"]
    console.print(Text(f"messages: {m['sent']} sent, {m['delivered']} delivered, "
                       f"{m['lost']} lost, {m['late']} late"))
    for o in doc["channel"]["outages"]:
        back = [x for x in o["recovered_after_s"] if x is not None]
        console.print(Text(
            f"agent {o['agent']} killed at {o['kill_at_s']:g} s, "
            + ("not restarted" if o["restart_at_s"] is None
               else f"restarted at {o['restart_at_s']:g} s")
            + ": held its tracks again after "
            + (f"{min(back):.0f}-{max(back):.0f} s" if back else "never")
            + f" ({len(back)} of {len(o['recovered_after_s'])} runs)"), soft_wrap=True)
    if doc["channel"].get("curve"):
        console.print(Text(f"CURVE: agents authenticated and encrypted; "
                           f"{doc['channel']['peers_refused']} peers refused"))
    c = doc.get("courses")
    if c is not None:
        console.print(Text(
            f"steering pays: {c['steering_pays']} (position RMSE {w[0]:g}-{w[1]:g} s "
            f"{c['rmse_steered_m']:.0f} m steered, {c['rmse_straight_m']:.0f} m straight, "
            f"ratio {c['ratio']:.2f}; steered lower in {100 * c['steered_lower_share']:.0f}% "
            f"of runs, paired t = {c['t']:.2f}, p = {c['p']:.2g})"), soft_wrap=True)
    html = paths.get("html")
    where = html.parent if html is not None else paths["results"].parent
    console.print(Text(f"wrote {len(paths)} files to {where}", style="green"), soft_wrap=True)
    if html is not None:
        console.print(Text(f"report: {html}", style="green"), soft_wrap=True)


def _print_summary(result: Any, paths: dict[str, Path]) -> None:
    from trackkit.report.tables import matching_rich_tables, rich_table

    console = Console()
    console.print(rich_table(result, width=console.width))
    # the error windows, the matching tables (J1-J4), the gap table: if present
    for table in matching_rich_tables(result, width=console.width):
        console.print(table)
    for note in getattr(result, "notes", []) or []:
        console.print(Text(f"note: {note}", style="yellow"))
    html = paths.get("html")
    where = html.parent if html is not None else next(iter(paths.values())).parent
    console.print(Text(f"wrote {len(paths)} files to {where}", style="green"))
    if html is not None:
        console.print(Text(f"report: {html}", style="green"))


# --- trackkit track: recorded data ------------------------------------------------------------


class TrackFormat(StrEnum):
    ais = "ais"
    opensky = "opensky"
    detections = "detections"


class AssociatorName(StrEnum):
    gnn = "gnn"
    jpda = "jpda"


class FilterName(StrEnum):
    ekf = "ekf"
    ukf = "ukf"


class OnBad(StrEnum):
    skip = "skip"
    stop = "stop"


#: defaults per input: a coastal marine radar over AIS traffic, an en-route air surveillance
#: radar over ADS-B, a generic tracker for a detections file (the plots are as recorded)
TRACK_PROFILES: dict[str, dict[str, float]] = {
    "ais": dict(period=3.0, sigma_range=20.0, sigma_bearing_deg=0.5, pd=0.9, clutter=10.0,
                max_range=40e3, min_range=50.0, q=0.05, v_std=10.0, gospa_c=500.0),
    "opensky": dict(period=10.0, sigma_range=50.0, sigma_bearing_deg=0.1, pd=0.9,
                    clutter=10.0, max_range=400e3, min_range=500.0, q=100.0, v_std=150.0,
                    gospa_c=2000.0),
    "detections": dict(sigma_range=20.0, sigma_bearing_deg=0.5, sigma_pos=20.0, pd=0.9,
                       clutter=10.0, q=1.0, v_std=50.0, gospa_c=1000.0),
}
_PROFILE_HELP = "ais {ais}, opensky {opensky}, detections {detections}"


def _profile_default(key: str, unit: str = "") -> str:
    vals = {f: (f"{p[key]:g}{unit}" if key in p else "-") for f, p in TRACK_PROFILES.items()}
    return _PROFILE_HELP.format(**vals)


def _number(lo: float | None = None, hi: float | None = None, *, open_lo: bool = True,
            open_hi: bool = False) -> Any:
    """An option callback for a float in a range; the message names the value given."""
    def check(value: float | None) -> float | None:
        if value is None:
            return value
        bad = not math.isfinite(value)
        if lo is not None:
            bad |= value <= lo if open_lo else value < lo
        if hi is not None:
            bad |= value >= hi if open_hi else value > hi
        if bad:
            lo_s = "" if lo is None else f"{'>' if open_lo else '>='} {lo:g}"
            hi_s = "" if hi is None else f"{'<' if open_hi else '<='} {hi:g}"
            raise typer.BadParameter(f"{value:g}; expected a finite number "
                                     f"{' and '.join(s for s in (lo_s, hi_s) if s)}")
        return value

    return check


def _header_of(path: Path) -> list[str]:
    if path.suffix.lower() in (".parquet", ".pq"):
        from trackkit.io._table import open_parquet

        return list(open_parquet(path).schema_arrow.names)
    from trackkit.io._table import _header

    return _header(str(path))


def _guess_format(path: Path, header: list[str]) -> TrackFormat:
    """The input's kind from its columns: AIS (MMSI), OpenSky (icao24) or detections."""
    names = {h.strip().lower() for h in header}
    if "mmsi" in names:
        return TrackFormat.ais
    if "icao24" in names:
        return TrackFormat.opensky
    if "time" in names and ({"x", "y"} <= names or {"range", "bearing"} <= names):
        return TrackFormat.detections
    raise ValueError(f"{path}: cannot tell the format from the columns "
                     f"{', '.join(map(repr, header))}; expected an MMSI column (AIS), icao24 "
                     "(OpenSky) or time with x, y or range, bearing (detections); pass "
                     "--format ais|opensky|detections (and --columns for other names)")


def _mapping(text: str | None, option: str, allowed: tuple[str, ...]) -> dict[str, str | None]:
    """``KEY=VALUE,KEY=VALUE`` (a value ``none`` is None), keys checked against ``allowed``."""
    out: dict[str, str | None] = {}
    if not text:
        return out
    for item in text.split(","):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise ValueError(f"{option} {text!r}: {item!r} is not KEY=VALUE; expected e.g. "
                             f"{option} {allowed[0]}=NAME,{allowed[1]}=NAME")
        if key not in allowed:
            raise ValueError(f"{option}: {key!r} is not a known key; expected one of "
                             f"{', '.join(allowed)}")
        out[key] = None if value.lower() == "none" else value
    return out


def _read_input(path: Path, fmt: TrackFormat, header: list[str], columns: str | None,
                units: str | None, on_bad: OnBad, progress: Any) -> tuple[Any, Any, bool]:
    """(Reports or Scans, ReadReport, whether the detections are range-bearing plots)."""
    from dataclasses import fields as dc_fields

    from trackkit import io as tio

    kw = dict(on_bad=on_bad.value, progress=progress, max_listed=100_000)
    if fmt is TrackFormat.ais:
        keys = tuple(f.name for f in dc_fields(tio.AisColumns))
        cols = tio.AisColumns(**_mapping(columns, "--columns", keys))
        return (*tio.read_ais_csv(path, cols, **kw), False)
    if fmt is TrackFormat.opensky:
        if columns:
            raise ValueError("--columns: the OpenSky reader uses OpenSky's own column names "
                             "(time, icao24, lat, lon, ...); use --format ais with --columns "
                             "for another layout of position reports")
        return (*tio.read_opensky_csv(path, **kw), False)
    given = _mapping(columns, "--columns",
                     ("time", "sensor", "x", "y", "z", "range", "bearing"))
    names = {h.strip().lower(): h.strip() for h in header}
    if not given and "range" in names and "bearing" in names and "x" not in names:
        given = {"range": names["range"], "bearing": names["bearing"]}
    if "sensor" not in given and "sensor" not in names:
        given["sensor"] = None  # every plot from one sensor
    un = tio.DetectionUnits(**_mapping(units, "--units", ("distance", "angle", "bearing",
                                                          "time")))
    dc = tio.DetectionColumns(**given)
    return (*tio.read_detections(path, dc, un, **kw), dc.polar)


def _tracker(sensor: Any, pd: float, clutter_density: float, q: float, v_std: float,
             associator: AssociatorName, filt: FilterName) -> tuple[Any, dict[str, Any]]:
    """The tracker of ``trackkit track``, and its description for the report."""
    import trackkit as tk
    from trackkit.tracking import GNN, JPDA, ScoreLogic, SinglePoint, Tracker

    # one new object per hundred false plots: a track is confirmed after two or three hits
    birth = clutter_density / 100
    logic = ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=pd, clutter_density=clutter_density,
                                 new_target_density=birth)
    f = tk.filters.EKF() if filt is FilterName.ekf else tk.filters.UKF()
    tracker = Tracker(f, tk.models.ConstantVelocity(dim=2, q=q), sensor, pd=pd,
                      clutter_density=clutter_density,
                      associator=GNN() if associator is AssociatorName.gnn else JPDA(),
                      logic=logic, initiator=SinglePoint(v_std=v_std))
    unit = "per_m_rad" if hasattr(sensor, "sigma_bearing") else "per_m2"
    desc = {"filter": filt.value.upper(), "motion": "constant velocity",
            "q_m2_s3": q, "associator": associator.value.upper(),
            "logic": (f"SPRT track score, alpha 0.01, beta 0.001: confirmed at a score of "
                      f"{logic.confirm_threshold:.3g}, deleted at a drop of "
                      f"{-logic.delete_threshold:.3g} below its maximum"),
            "initiator": "single point, velocity 0", "initial_velocity_std_m_s": v_std,
            "pd_assumed": pd, f"clutter_density_{unit}": clutter_density,
            "new_target_density": birth}
    return tracker, desc


@app.command()
def track(
    file: Annotated[Path, typer.Argument(
        help="Detections (CSV or Parquet), AIS CSV or OpenSky state-vector CSV, or a bundled "
        "sample: solent-ais, opensky-adsb (see trackkit list).")],
    fmt: Annotated[TrackFormat | None, typer.Option(
        "--format", "-f", help="What the file holds.",
        show_default="guessed from the columns")] = None,
    as_radar: Annotated[bool, typer.Option(
        "--as-radar", help="Make radar plots of the AIS/ADS-B positions (a virtual radar), "
        "track them and score the tracks against the reported positions (GOSPA). Required "
        "for AIS and OpenSky.")] = False,
    columns: Annotated[str | None, typer.Option(
        "--columns", help="Column mapping KEY=NAME,...: AIS keys time, id, lat, lon, course, "
        "speed, time_format, course_unit, speed_unit; detections keys time, sensor, x, y, "
        "range, bearing (NAME none: no such column).",
        show_default="the standard layout")] = None,
    units: Annotated[str | None, typer.Option(
        "--units", help="Units of a detections file KEY=VALUE,...: distance m|km|nmi, angle "
        "deg|rad, bearing nautical|math, time s|iso|unix|unix_ms.",
        show_default="distance=m,angle=deg,bearing=nautical,time=s")] = None,
    site_lat: Annotated[float | None, typer.Option(
        "--site-lat", callback=_number(-90, 90, open_lo=False), help="Radar site latitude "
        "(deg); for detections, the latitude of the origin of x, y (gives lat/lon columns "
        "and GeoJSON).", show_default="the data's median")] = None,
    site_lon: Annotated[float | None, typer.Option(
        "--site-lon", callback=_number(-180, 180, open_lo=False),
        help="Radar site longitude (deg).", show_default="the data's median")] = None,
    period: Annotated[float | None, typer.Option(
        "--period", callback=_number(0), help="Scan period (s).",
        show_default=_profile_default("period"))] = None,
    sigma_range: Annotated[float | None, typer.Option(
        "--sigma-range", callback=_number(0), help="Range noise std (m).",
        show_default=_profile_default("sigma_range"))] = None,
    sigma_bearing_deg: Annotated[float | None, typer.Option(
        "--sigma-bearing-deg", callback=_number(0), help="Bearing noise std (deg).",
        show_default=_profile_default("sigma_bearing_deg"))] = None,
    sigma_pos: Annotated[float | None, typer.Option(
        "--sigma-pos", callback=_number(0), help="Position noise std of x, y detections (m).",
        show_default=_profile_default("sigma_pos"))] = None,
    pd: Annotated[float | None, typer.Option(
        "--pd", callback=_number(0, 1), help="Detection probability.",
        show_default=_profile_default("pd"))] = None,
    clutter: Annotated[float | None, typer.Option(
        "--clutter", callback=_number(0, open_lo=False), help="False plots per scan.",
        show_default=_profile_default("clutter"))] = None,
    max_range: Annotated[float | None, typer.Option(
        "--max-range", callback=_number(0), help="Instrumented range (m).",
        show_default=_profile_default("max_range"))] = None,
    min_range: Annotated[float | None, typer.Option(
        "--min-range", callback=_number(0, open_lo=False), help="Blind range (m).",
        show_default=_profile_default("min_range"))] = None,
    max_gap: Annotated[float | None, typer.Option(
        "--max-gap", callback=_number(0), help="Longest gap between an object's reports "
        "bridged by interpolation (s).", show_default="max(3 periods, 120 s)")] = None,
    seed: Annotated[int, typer.Option(
        "--seed", "-s", callback=_at_least(0), help="Seed of the virtual radar.")] = 0,
    associator: Annotated[AssociatorName, typer.Option(
        "--associator", help="Data association.")] = AssociatorName.gnn,
    filt: Annotated[FilterName, typer.Option("--filter", help="Track filter.")] = FilterName.ekf,
    q: Annotated[float | None, typer.Option(
        "--q", callback=_number(0), help="Process noise of the constant-velocity model "
        "(m^2/s^3).", show_default=_profile_default("q"))] = None,
    v_std: Annotated[float | None, typer.Option(
        "--v-std", callback=_number(0), help="Velocity std of a new track (m/s).",
        show_default=_profile_default("v_std"))] = None,
    gospa_c: Annotated[float | None, typer.Option(
        "--gospa-c", callback=_number(0), help="GOSPA cut-off (m).",
        show_default=_profile_default("gospa_c"))] = None,
    on_bad: Annotated[OnBad, typer.Option(
        "--on-bad", help="Skip bad records (counted, and listed in skipped.csv) or stop at "
        "the first.")] = OnBad.skip,
    until: Annotated[float | None, typer.Option(
        "--until", callback=_number(0, open_lo=False), help="Track only the first SECONDS "
        "of the data.", show_default="all")] = None,
    max_scans: Annotated[int | None, typer.Option(
        "--max-scans", callback=_at_least(1), help="Track at most N scans.",
        show_default="all")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/track-STEM")] = None,
) -> None:
    """Track recorded data; write tracks (Parquet, CSV, GeoJSON), pictures, results.json and
    report.html. AIS and ADS-B need --as-radar: a virtual radar makes plots of the reported
    positions, and the tracks are scored against those positions with GOSPA. Try it on a
    bundled sample: trackkit track solent-ais --as-radar."""
    with _user_errors() as state:
        file = _sample_or_file(file)
        header = _header_of(file)
        kind = fmt or _guess_format(file, header)
        if kind is not TrackFormat.detections and not as_radar:
            raise ValueError(f"{file}: {kind.value} position reports are tracked through a "
                             "virtual radar; add --as-radar (trackkit track --help lists the "
                             "radar options)")
        if kind is TrackFormat.detections and as_radar:
            raise ValueError(f"{file}: --as-radar makes plots of AIS or ADS-B reports; a "
                             "detections file holds plots already, tracked as they are (drop "
                             "--as-radar)")
        if (site_lat is None) != (site_lon is None):
            raise ValueError("--site-lat and --site-lon: give both or neither")
        if units and kind is not TrackFormat.detections:
            raise ValueError(f"--units is for detections files; {file} is {kind.value}")
        given = dict(period=period, sigma_range=sigma_range,
                     sigma_bearing_deg=sigma_bearing_deg, sigma_pos=sigma_pos, pd=pd,
                     clutter=clutter, max_range=max_range, min_range=min_range, q=q,
                     v_std=v_std, gospa_c=gospa_c)
        # the options given, else the input's defaults (TRACK_PROFILES)
        opt = {**TRACK_PROFILES[kind.value],
               **{k: float(v) for k, v in given.items() if v is not None}}
        opt.update(max_gap=max_gap, seed=seed, site_lat=site_lat, site_lon=site_lon,
                   until=until, max_scans=max_scans)

        target, label = _output_dir(out, f"track-{file.stem}")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            if where.note:
                _stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)
            with _progress_bar(_stderr()) as bar:
                reading = bar.add_task("reading", total=max(file.stat().st_size, 1),
                                       unit="bytes")
                try:
                    data, read, polar = _read_input(
                        file, kind, header, columns, units, on_bad,
                        lambda done, total: bar.update(reading, completed=done, total=total))
                except ValueError as err:
                    raise ValueError(str(err).replace(
                        "[on_bad='stop'; pass on_bad='skip' to skip bad records]",
                        "[--on-bad stop; pass --on-bad skip to skip bad records]")) from None
                job = (_detections_job(file, data, read, polar, opt)
                       if kind is TrackFormat.detections else _radar_job(file, data, read, opt))
                tracker, desc = _tracker(job.sensor, opt["pd"], job.clutter_density, opt["q"],
                                         opt["v_std"], associator, filt)
                desc["gospa_c_m"] = opt["gospa_c"]
                job.config["tracker"] = desc
                tracking = bar.add_task("tracking", total=len(job.scans), unit="scans")
                from trackkit.tracking.history import run_tracker

                history, _ = run_tracker(tracker, job.scans,
                                         progress=lambda s: bar.update(tracking, completed=s))
            from trackkit.report.tracks import TrackReport, write_track_report

            rep = TrackReport(history, title=file.name, source=str(file), fmt=kind.value,
                              read=read, epoch=read.epoch, frame=job.frame, truth=job.truth,
                              gospa_c=opt["gospa_c"], config=job.config,
                              background=job.background, background_label=job.background_label,
                              site=job.site, max_range=job.max_range, notes=job.notes)
            with _stderr().status("writing the tracks and the report"):
                paths = write_track_report(rep, where.path)
            state.interrupted = "interrupted"
            _print_track_summary(read, job, paths)


def _sample_or_file(file: Path) -> Path:
    """The file, else the bundled sample of that name (a file of that name comes first)."""
    from trackkit.io import samples

    if not file.exists() and str(file) in samples.SAMPLES:
        return samples.path(str(file))
    if not file.is_file():
        what = "is not a file" if file.exists() else "no such file"
        raise ValueError(f"{file}: {what}; expected a detections, AIS or OpenSky file, or a "
                         f"bundled sample ({', '.join(samples.SAMPLES)})")
    return file


def _notes(read: Any) -> list[str]:
    notes = []
    if read.out_of_order:
        notes.append(f"{read.out_of_order} records were out of time order in the file and "
                     "were sorted by time before tracking")
    if read.duplicates:
        notes.append(f"{read.duplicates} exact duplicate records were dropped (the first "
                     "of each kept)")
    return notes


def _limit_scans(scans: Any, until: float | None, max_scans: int | None) -> Any:
    """The first scans: up to ``until`` s after the first, at most ``max_scans``."""
    import numpy as np

    from trackkit.tracking.scans import Scans

    n = len(scans)
    if until is not None and n:
        n = int(np.searchsorted(scans.times, scans.times[0] + until, side="right"))
    if max_scans is not None:
        n = min(n, max_scans)
    if n == len(scans):
        return scans
    off = scans.offsets[:n + 1]
    return Scans(scans.z[:off[-1]], off, scans.times[:n], scans.sensor[:n])


def _radar_job(file: Path, reports: Any, read: Any, opt: dict[str, Any]) -> SimpleNamespace:
    """The virtual radar's plots of AIS or ADS-B reports, and the truth to score against."""
    import numpy as np

    from trackkit.report.tracks import ground_geodetic
    from trackkit.sim.virtual_radar import VirtualRadar, virtual_radar

    if len(reports) == 0:
        raise ValueError(f"{file}: no usable position reports ({read.n_skipped} skipped); "
                         "nothing to track")
    frame = reports.frame  # at the data's median position
    if opt["site_lat"] is None:
        site = (0.0, 0.0)
    else:
        x, y, _ = frame.to_enu(opt["site_lat"], opt["site_lon"], 0.0)
        site = (float(x), float(y))
    radar = VirtualRadar(site=site, period=opt["period"], sigma_range=opt["sigma_range"],
                         sigma_bearing=math.radians(opt["sigma_bearing_deg"]), pd=opt["pd"],
                         clutter=opt["clutter"], max_range=opt["max_range"],
                         min_range=opt["min_range"], max_gap=opt["max_gap"])
    until = None if opt["until"] is None else float(reports.time[0]) + opt["until"]
    run = virtual_radar(reports, radar, opt["seed"], until=until, max_scans=opt["max_scans"])
    lat, lon = ground_geodetic(frame, np.array([site[0]]), np.array([site[1]]))
    # the reported positions the radar could see, for the picture
    t_end = float(run.scans.times[-1])
    near = (np.hypot(reports.x - site[0], reports.y - site[1]) <= radar.max_range) & (
        reports.time <= t_end)
    n_plots = int(run.scans.z.shape[0])
    config = {"virtual radar": {
        "site_lat_deg": round(float(lat[0]), 6), "site_lon_deg": round(float(lon[0]), 6),
        "site_x_m": site[0], "site_y_m": site[1], "period_s": radar.period,
        "sigma_range_m": radar.sigma_range, "sigma_bearing_deg": opt["sigma_bearing_deg"],
        "pd": radar.pd, "clutter_per_scan": radar.clutter, "min_range_m": radar.min_range,
        "max_range_m": radar.max_range, "max_gap_s": radar.gap,
        "still_distance_m": radar.still_distance, "still_gap_s": radar.still_gap,
        "seed": opt["seed"], "scans": len(run.scans), "plots": n_plots,
        "plots_of_objects": int(np.sum(run.origin >= 0)),
        "objects_in_file": int(len(reports.ids)), "objects_in_range": run.objects_seen}}
    notes = _notes(read) + [
        "The truth is the reported positions (AIS or ADS-B), interpolated linearly to the "
        "scan times; they carry their own errors (GNSS, tens of metres), so GOSPA has a "
        "floor of that size. The radar is 2-D: range is horizontal distance in the local "
        "frame, and every plot of a scan carries the scan's time.",
        f"Objects in range: {run.objects_seen} of {len(reports.ids)} in the file (an object "
        "outside the range, or with a single report, is not seen)."]
    if opt["until"] is not None or opt["max_scans"] is not None:
        notes.append(f"Limited to {len(run.scans)} scans (--until / --max-scans).")
    return SimpleNamespace(
        scans=run.scans, sensor=run.sensor, clutter_density=max(radar.clutter, 0.1)
        / radar.volume, truth=run.truth, frame=frame, site=site, max_range=radar.max_range,
        background=reports.position[near], background_label="reported positions",
        config=config, notes=notes, objects=len(reports.ids), seen=run.objects_seen,
        plots=n_plots)


def _detections_job(file: Path, scans: Any, read: Any, polar: bool, opt: dict[str, Any]
                    ) -> SimpleNamespace:
    """A detections file's plots, tracked as they are (no truth)."""
    import numpy as np

    import trackkit as tk
    from trackkit.io import EnuFrame

    if len(scans) == 0:
        raise ValueError(f"{file}: no usable detections ({read.n_skipped} skipped); nothing "
                         "to track")
    if scans.dim_z != 2:
        raise ValueError(f"{file}: detections with {scans.dim_z} coordinates; the tracker "
                         "takes 2-D plots (x, y or range, bearing)")
    scans = _limit_scans(scans, opt["until"], opt["max_scans"])
    z = scans.z
    if polar:  # range, bearing (rad, nautical, as the reader gives them) from x, y = 0, 0
        sensor = tk.models.RangeBearing(origin=(0.0, 0.0), sigma_range=opt["sigma_range"],
                                        sigma_bearing=math.radians(opt["sigma_bearing_deg"]))
        volume = max(float(z[:, 0].max()), 1.0) * 2 * math.pi if len(z) else 2 * math.pi
        points = np.stack([z[:, 0] * np.sin(z[:, 1]), z[:, 0] * np.cos(z[:, 1])], axis=-1)
        site: tuple[float, float] | None = (0.0, 0.0)
    else:
        sensor = tk.models.Position(dim=2, sigma=opt["sigma_pos"])
        volume = float(max(np.ptp(z[:, 0]), 1.0) * max(np.ptp(z[:, 1]), 1.0)) if len(z) else 1.0
        points = z
        site = None
    clutter = opt["clutter"]
    frame = (EnuFrame(opt["site_lat"], opt["site_lon"]) if opt["site_lat"] is not None
             else None)
    plots: dict[str, Any] = {"scans": len(scans), "plots": int(z.shape[0]),
                             "kind": "range, bearing" if polar else "x, y"}
    if polar:
        plots.update(sigma_range_m=opt["sigma_range"],
                     sigma_bearing_deg=opt["sigma_bearing_deg"])
    else:
        plots["sigma_pos_m"] = opt["sigma_pos"]
    plots.update(clutter_per_scan_assumed=clutter, measurement_volume=volume)
    config = {"plots": plots}
    notes = _notes(read)
    if frame is None:
        notes.append("No --site-lat/--site-lon: positions stay in the file's x, y (no "
                     "lat/lon columns, no GeoJSON).")
    return SimpleNamespace(
        scans=scans, sensor=sensor, clutter_density=max(clutter, 0.1) / volume, truth=None,
        frame=frame, site=site, max_range=None, background=points, background_label="plots",
        config=config, notes=notes, objects=None, seen=None, plots=int(z.shape[0]))


def _print_track_summary(read: Any, job: SimpleNamespace, paths: dict[str, Path]) -> None:
    console = Console()
    console.print(Text(read.summary()), soft_wrap=True)
    if "skipped" in paths:
        console.print(Text(f"  the skipped records are listed in {paths['skipped']}"),
                      soft_wrap=True)
    elif not read.n_skipped:
        console.print(Text("  no records skipped"))
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    res = doc["results"]
    radar = doc["config"].get("virtual radar")
    if radar is not None:
        console.print(Text(
            f"virtual radar at {radar['site_lat_deg']:.5f}, {radar['site_lon_deg']:.5f}: "
            f"{radar['scans']} scans of {radar['period_s']:g} s, {radar['plots']} plots "
            f"({radar['plots_of_objects']} of objects, the rest clutter); "
            f"{radar['objects_in_range']} of {radar['objects_in_file']} objects in range"),
            soft_wrap=True)
    else:
        console.print(Text(f"{job.plots} plots in {len(job.scans)} scans"))
    console.print(Text(f"tracks: {res['tracks_confirmed']} confirmed of "
                       f"{res['tracks_started']} started"), soft_wrap=True)
    if res["tracks_confirmed"] == 0:
        from trackkit.report.tracks import NO_TRACK_CONFIRMED

        console.print(Text(NO_TRACK_CONFIRMED, style="yellow"), soft_wrap=True)
    g = res.get("gospa")
    if g is not None:
        t = res["tracks"]
        rmse = "n/a" if t["rmse"] is None else f"{t['rmse']:.3g} m"
        console.print(Text(
            f"mean GOSPA {g['mean']:.4g} m (c = {g['c']:g} m; per scan on average "
            f"{g['objects_per_scan']:.1f} objects, {g['missed_per_scan']:.2f} missed, "
            f"{g['false_per_scan']:.2f} false tracks; localisation part "
            f"{g['localisation']:.4g} m^2); {t['truths_confirmed']} of {t['truths']} objects "
            f"tracked, {t['breaks']} track breaks, position RMSE {rmse}"),
            soft_wrap=True)
    html = paths.get("html")
    console.print(Text(f"wrote {len(paths)} files to {html.parent if html else ''}",
                       style="green"), soft_wrap=True)
    if html is not None:
        console.print(Text(f"report: {html}", style="green"), soft_wrap=True)


# --- trackkit identify: a vessel's model from a GPS/INS log or a vessel scenario ------------


class VesselFilter(StrEnum):
    ekf = "ekf"
    ukf = "ukf"
    ckf = "ckf"
    srckf = "srckf"
    ls = "ls"


#: the NMEA sentences the identifier reads
NMEA_TYPES = "GGA RMC VTG HDT THS ROT"
#: the NMEA log suffixes; any other log is the CSV form (.csv)
NMEA_SUFFIXES = (".nmea", ".log", ".txt")
#: a log shorter than this cannot show converged coefficients (the paper: 500 s)
_CONVERGED_AFTER_S = 500.0


def _bundled_vessel() -> dict[str, str]:
    from trackkit.scenario.vessel import bundled_vessel

    return bundled_vessel()


def _identify_kind(what: str) -> str:
    """``"log"`` or ``"scenario"`` for ``trackkit identify WHAT``; a ValueError in words when
    it is neither."""
    from trackkit.scenario.vessel import is_vessel

    p = Path(what)
    suffix = p.suffix.lower()
    if suffix in (*NMEA_SUFFIXES, ".csv"):
        if not p.is_file():
            why = "is not a file" if p.exists() else "no such file"
            raise ValueError(f"{what}: {why}; expected a GPS/INS log (NMEA 0183 "
                             f"{', '.join(NMEA_SUFFIXES)} or CSV .csv)")
        return "log"
    if p.is_dir():
        raise ValueError(f"{what}: is a directory; expected a GPS/INS log file (NMEA 0183 "
                         f"{', '.join(NMEA_SUFFIXES)} or CSV .csv) with --inputs, or a vessel "
                         "scenario (.toml or a bundled name)")
    if suffix == ".toml" or p.exists():
        if suffix != ".toml" and p.is_file():
            raise ValueError(f"{what}: unknown log type {suffix or '(no suffix)'!r}; expected "
                             f"an NMEA 0183 log ({', '.join(NMEA_SUFFIXES)}), the CSV form "
                             "(.csv) or a vessel scenario (.toml)")
        if p.is_file() and not is_vessel(what):
            _parse_toml(p)
            raise ValueError(f"{what}: not a vessel scenario (it has no [vessel] table); see "
                             "`trackkit show vessel-turning` for a vessel scenario's fields")
        return "scenario"  # (a missing or unreadable .toml: load_vessel says so)
    if is_vessel(what):
        return "scenario"
    others = {**_bundled(), **_bundled_multitarget()}
    from trackkit.scenario.network import bundled_network

    if what in others or what in bundled_network():
        raise ValueError(f"{what!r} is not a vessel scenario; `trackkit identify` takes a "
                         f"GPS/INS log or one of {sorted(_bundled_vessel())}")
    raise ValueError(f"{what}: no such log file and no bundled vessel scenario of that name; "
                     f"expected a GPS/INS log ({', '.join(NMEA_SUFFIXES)}, .csv) with "
                     f"--inputs, a vessel scenario .toml or one of {sorted(_bundled_vessel())}")


@app.command()
def identify(
    what: Annotated[str, typer.Argument(
        metavar="LOG|SCENARIO",
        help="A GPS/INS log, NMEA 0183 (.nmea, .log, .txt: GGA RMC VTG HDT THS ROT) or the "
        "CSV form (.csv: time, lat, lon, sog_kn, cog_deg, heading_deg, rot_deg_min), with "
        "--inputs; or a bundled vessel scenario (vessel-zigzag-20, vessel-turning, "
        "vessel-identify; see trackkit list) or a vessel scenario TOML file.")],
    inputs: Annotated[Path | None, typer.Option(
        "--inputs", "-i", help="The log's measured inputs, CSV with columns time, "
        "nozzle_deg (positive to starboard), rpm; they must cover the log's time span.",
        show_default="required with a log")] = None,
    filt: Annotated[VesselFilter | None, typer.Option(
        "--filter", help="Identifier: augmented EKF, UKF or CKF, or batch least squares "
        "(ls).", show_default="ekf; a scenario: its identification.filters")] = None,
    period: Annotated[float | None, typer.Option(
        "--period", callback=_number(0, 60), help="Grid period T of the pre-processed u, v, "
        "r (s), for a log.", show_default="1")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=_at_least(1), help="Monte Carlo runs (a scenario).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=_at_least(0), help="Master seed (a scenario).",
        show_default="the scenario's run.seed")] = None,
    on_bad: Annotated[OnBad, typer.Option(
        "--on-bad", help="Skip bad log and input lines (counted and named by line) or stop "
        "at the first.")] = OnBad.skip,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/identify-STEM, or trackkit-out/SCENARIO")] = None,
) -> None:
    """Identify a vessel's 16-coefficient manoeuvring model (Zolfagharnasab and Seif 2025;
    augmented EKF on u, v, r): from a recorded GPS/INS log and its inputs, or by running a
    vessel scenario (simulated sea trials, Monte Carlo). Prints the coefficients with their
    standard deviations and writes results.json, convergence, track, heading and trial plots
    and report.html; the identified model's 20 deg turn and 10/10 and 20/20 zig-zags with
    the IMO table."""
    with _user_errors() as state:
        kind = _identify_kind(what)
        if kind == "scenario":
            from trackkit.scenario.vessel import load_vessel

            given = [o for o, v in (("--inputs", inputs), ("--period", period)) if v is not None]
            if given:
                raise ValueError(f"{' and '.join(given)}: for a GPS/INS log; {what} is a "
                                 "vessel scenario, which simulates its sensors (its period is "
                                 "identification.period_s)")
            sc = load_vessel(what)
            target, label = _output_dir(out, _default_dir(what, sc))
            with OutputDir(target, label) as where:
                state.interrupted = f"interrupted; nothing was written to {target}"
                if where.note:
                    _stderr().print(Text(f"note: {where.note}", style="yellow"),
                                    soft_wrap=True)
                _run_vessel(sc, where.path, runs=runs, seed=seed,
                            filters=None if filt is None else [filt.value])
                state.interrupted = "interrupted"
            return
        given = [o for o, v in (("--runs", runs), ("--seed", seed)) if v is not None]
        if given:
            raise ValueError(f"{' and '.join(given)}: for a vessel scenario's Monte Carlo; "
                             f"{what} is a recorded log")
        if inputs is None:
            raise ValueError(f"{what}: a log needs its inputs: --inputs FILE.csv with columns "
                             "time, nozzle_deg, rpm")
        if not inputs.is_file():
            why = "is not a file" if inputs.exists() else "no such file"
            raise ValueError(f"--inputs {inputs}: {why}; expected a CSV with columns time, "
                             "nozzle_deg, rpm")
        log = Path(what)
        target, label = _output_dir(out, f"identify-{log.stem}")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            if where.note:
                _stderr().print(Text(f"note: {where.note}", style="yellow"), soft_wrap=True)
            _identify_log(log, inputs, where.path, filt=(filt or VesselFilter.ekf).value,
                          period=1.0 if period is None else period, on_bad=on_bad.value)
            state.interrupted = "interrupted"


@contextmanager
def _stage(what: str) -> Iterator[None]:
    """Say on stderr what the command is doing, as a line (seen in a pipe or a log too) and,
    on a terminal, a spinner while it lasts."""
    console = _stderr()
    console.print(Text(f"{what} ...", style="dim"), soft_wrap=True)
    with console.status(what):
        yield


def _filter_compiled(filt: str) -> bool:
    """Whether the identifier's compiled step is in numba's cache already (the EKF's fused
    step is compiled on its first run and cached beside its module)."""
    if filt != "ekf":
        return True
    try:
        from trackkit.identify import fused

        return Path(fused._step._cache._cache_file._index_path).is_file()
    except AttributeError:  # another numba: do not guess
        return True


def _stop_hint(err: ValueError, columns: str) -> ValueError:
    """A reader's message in the command's words (its options, not the function's)."""
    return ValueError(str(err).replace(
        "[on_bad='stop'; pass on_bad='skip' to skip bad records]",
        "[--on-bad stop; pass --on-bad skip to skip bad records]").replace(
        " (pass a column mapping)", f"; expected the columns {columns}"))


def _check_log_usable(log: Path, nav: Any, read: Any, expected: str) -> None:
    """A log with no usable position is named as the culprit (before its inputs, which
    cannot be read against the times of a log without any)."""
    if read.rows_kept and nav.t_pos.size:
        return
    why = ", ".join(f"{n} {r}" for r, n in sorted(read.skipped.items(), key=lambda kv: -kv[1]))
    first = f"; first: {read.bad[0]}" if read.bad else ""
    kept = (f"{read.rows_kept} kept but none gives a position (GGA or RMC)" if read.rows_kept
            else f"none usable ({why or 'empty'}){first}")
    raise ValueError(f"{log}: no usable GPS/INS record: {read.rows_read} lines read, {kept}; "
                     f"expected {expected}")


def _identify_log(log: Path, inputs: Path, out: Path, *, filt: str, period: float,
                  on_bad: str) -> None:
    """Read, pre-process and identify a recorded log; write its report; print the
    coefficients, the standard trials and the IMO table."""
    from trackkit.eval.vessel_mc import identify_recorded
    from trackkit.io.navigation import INPUT_COLUMNS, preprocess, read_inputs_csv
    from trackkit.io.nmea import NAV_CSV_COLUMNS, read_nav_csv, read_nmea
    from trackkit.report.vessel_report import write_recorded_report

    console = Console()
    notes: list[str] = []
    with _stage(f"reading {log} and {inputs}"):
        try:
            if log.suffix.lower() == ".csv":
                nav, read = read_nav_csv(log, on_bad)
            else:
                nav, read = read_nmea(log, on_bad)
        except ValueError as err:
            raise _stop_hint(err, ", ".join(NAV_CSV_COLUMNS)) from None
        _check_log_usable(log, nav, read, (
            f"the columns {', '.join(NAV_CSV_COLUMNS)}" if log.suffix.lower() == ".csv" else
            f"NMEA 0183 sentences ({NMEA_TYPES}) with valid checksums"))
        fmt = "iso" if nav.epoch is not None else "seconds"  # a log without a date: both
        try:
            ins, iread = read_inputs_csv(inputs, on_bad, epoch=nav.epoch, time_format=fmt)
        except ValueError as err:
            raise _stop_hint(err, ", ".join(INPUT_COLUMNS)) from None
    console.print(Text(read.summary()), soft_wrap=True)
    console.print(Text(iread.summary()), soft_wrap=True)
    if nav.unsupported:
        console.print(Text("  sentence types not used: " + ", ".join(
            f"{k} {v}" for k, v in sorted(nav.unsupported.items()))), soft_wrap=True)
    if ins.t.size < 2:
        raise ValueError(f"--inputs {inputs}: {ins.t.size} usable records "
                         f"({iread.n_skipped} skipped); expected nozzle angle and rpm over "
                         "the log's time span")
    rate_source = "gyro"
    if nav.t_rate.size < 2 and nav.t_heading.size >= 2:  # no ROT: differentiate the heading
        rate_source = "heading"
        notes.append("the log has no rate of turn (ROT); the yaw rate is the differenced INS "
                     "heading")
    try:
        m = preprocess(nav, T=period, rate_source=rate_source)
    except ValueError as err:
        raise ValueError(f"{log}: {err}") from None
    if m.gaps:
        notes.append(f"{len(m.gaps)} gap(s) in the log's streams ("
                     + ", ".join(f"{g.stream} {g.start:.1f}-{g.end:.1f} s" for g in m.gaps[:5])
                     + ("..." if len(m.gaps) > 5 else "") + "): no measurement there, the "
                     "filter predicts across")
    doing = f"identifying the 16 coefficients with {filt} ({m.t.size} samples)"
    if not _filter_compiled(filt):
        doing = (f"compiling the {filt} filter (the first run only: about half a minute; "
                 f"later runs reuse it), then {doing}")
    with _stage(doing):
        rec = identify_recorded(m, ins, filter=filt, inputs_name=f"--inputs {inputs}")
    span = rec.t[-1] - rec.t[0]
    if span < _CONVERGED_AFTER_S:
        notes.append(f"the log is {span:.0f} s long; the paper's coefficients converged only "
                     f"after {_CONVERGED_AFTER_S:.0f} s: expect wide standard deviations")
    if not rec.stable:
        notes.append(f"the identified model is unstable in a straight line at the log's "
                     f"{rec.speed / 1852.0 * 3600.0:.1f} kn and {rec.rpm:.0f} rpm (an eigenvalue "
                     "of df/dx with a positive real part): its simulated trials diverge and "
                     "their metrics are not meaningful")
    if rec.dropped:
        notes.append(f"the first {rec.dropped} grid sample(s) lack a measurement and were "
                     "left out")
    with _stage(f"writing the report to {out}"):
        paths = write_recorded_report(rec, out, title=log.name, notes=notes, log_read=read,
                                      inputs_read=iread)
    _print_recorded_summary(paths, log, notes)


def _print_recorded_summary(paths: dict[str, Path], log: Path, notes: list[str]) -> None:
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    console = Console()
    limit = 100 * doc["rel_sd_limit"]
    table = Table("coefficient", "value", "std", "relative std", "identified",
                  title=f"{log.name}: {doc['filter']}, {doc['samples']} samples of "
                  f"{doc['period_s']:g} s (prime units: L = 19.6 m, U0 = 18 kn, n0 = 2000 rpm)",
                  title_justify="left")
    for name, c in doc["coefficients"].items():
        rel = "-" if c["rel_std"] is None else f"{100 * c['rel_std']:.0f}%"
        flag = (Text("yes") if c["identified"]
                else Text(f"no: std > {limit:.0f}% of the value", style="yellow"))
        table.add_row(name, _signed4(c["value"]), _signed4(c["std"]).lstrip("+"), rel, flag)
    console.print(table)
    n_id = doc["identified_count"]
    console.print(Text(f"{16 - n_id} of 16 coefficients are not identified by this log "
                       f"(standard deviation above {limit:.0f}% of the value)",
                       style="yellow" if n_id < 16 else ""), soft_wrap=True)
    _print_trials(doc["model_trials"])
    for note in notes:
        console.print(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    console.print(Text(f"wrote {len(paths)} files to {paths['results'].parent}",
                       style="green"), soft_wrap=True)
    console.print(Text(f"report: {paths['html']}", style="green"), soft_wrap=True)


def _signed4(v: float | None) -> str:
    return "-" if v is None else f"{v:+.4f}"


def _print_trials(mt: dict) -> None:
    """The standard trials' metrics and the IMO table of results.json's ``model_trials``."""
    from rich.markup import escape

    from trackkit.report.vessel_report import imo_rows

    truth = "truth" in mt
    console = Console()
    kn = mt["speed_mps"] * 3600.0 / 1852.0
    turn, z10, z20 = (mt["identified_run0"][k] for k in ("turn", "zigzag10", "zigzag20"))

    def f(v: float | None, spec: str, scale: float = 1.0) -> str:
        return "-" if v is None else format(v * scale, spec)

    deg = 180.0 / math.pi
    console.print(Text(
        f"identified model at {kn:.1f} kn, {mt['rpm']:.0f} rpm: 20 deg turn D/L "
        f"{f(turn['diameter_to_length'], '.2f')} (steady diameter "
        f"{f(turn['steady_diameter_m'], '.0f')} m, advance {f(turn['advance_m'], '.0f')} m, "
        f"tactical diameter {f(turn['tactical_diameter_m'], '.0f')} m); 10/10 overshoots "
        f"{f(z10['first_overshoot_rad'], '.1f', deg)} and "
        f"{f(z10['second_overshoot_rad'], '.1f', deg)} deg; 20/20 first overshoot "
        f"{f(z20['first_overshoot_rad'], '.1f', deg)} deg"), soft_wrap=True)
    head = ["criterion", "identified" + (" (run 0)" if truth else "")]
    head += (["truth", "runs passing"] if truth else []) + ["limit", "source"]
    table = Table(*(escape(h) for h in head), title="IMO MSC.137(76) (for reference only "
                  "below 100 m) and the paper's 2 <= D/L <= 7", title_justify="left")
    for row in imo_rows(mt["imo"], truth):
        table.add_row(*(escape(c) for c in row))
    console.print(table)


def _run_vessel(sc: Any, out: Path, **kwargs: Any) -> None:
    """A vessel scenario's Monte Carlo (``eval.vessel_mc.run_vessel``), its report written
    into ``out`` and a summary printed."""
    from trackkit.eval.vessel_mc import run_vessel
    from trackkit.report.vessel_report import write_vessel_report

    runs = kwargs.get("runs") or sc.run.runs
    with _stderr().status(f"{sc.name}: simulating and identifying, {runs} runs"):
        result = run_vessel(sc, **kwargs)
        _deliver_interrupt()
    with _stderr().status("writing the report"):
        paths = write_vessel_report(result, sc, out)
    _print_vessel_summary(paths, sc.notes)


def _print_vessel_summary(paths: dict[str, Path], notes: list[str]) -> None:
    from rich.markup import escape

    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    console = Console()
    shown = doc["shown_filter"]
    names = list(doc["filters"])
    truth = doc["truth"]["coefficients"]
    f0 = doc["filters"][shown]["coefficients_run0"]
    head = ["coefficient", "truth", f"{shown} run 0", "std"]
    head += [f"{n} median error" for n in names]
    table = Table(*head, title=f"{doc['scenario']}: {doc['runs']} runs, seed {doc['seed']}, "
                  f"identified from the {doc['data']} ({doc['samples']} samples of "
                  f"{doc['period_s']:g} s)", title_justify="left")
    for k, t in truth.items():
        errs = [doc["filters"][n]["rel_error_median"][k] for n in names]
        table.add_row(k, f"{t:+.3f}", f"{f0[k]['value']:+.4f}", f"{f0[k]['std']:.4f}",
                      *("-" if e is None else f"{100 * e:.1f}%" for e in errs))
    console.print(table)
    lo, hi = doc["nees_band"]
    per = Table("filter", "NEES median", escape(f"NEES in [{lo:.1f}, {hi:.1f}]"),
                "filtered u / v / r RMSE over the measurement's",
                title="per filter (medians over runs)", title_justify="left")
    for n, f in doc["filters"].items():
        r = f["body_rmse_over_noise_median"]
        per.add_row(n, f"{f['nees_median']:.1f}", f"{100 * f['nees_inside_fraction']:.0f}%",
                    "-" if r[0] is None else f"{r[0]:.2f} / {r[1]:.2f} / {r[2]:.2f}")
    console.print(per)
    tr = doc["trial"]
    if tr is not None:
        def m(v: float | None) -> str:
            return "-" if v is None else f"{v:.2f} m"

        console.print(Text(
            f"{tr['kind']} trial, {tr['duration_s']:g} s (medians over runs): raw GPS "
            f"{m(tr['gps_rmse_median_m'])} RMS from the truth, filtered track "
            f"{m(tr['filtered_rmse_median_m'])}; the identified model driven by the inputs "
            f"{m(tr['model_rmse_median_m'])} (largest {m(tr['model_max_error_median_m'])})"),
            soft_wrap=True)
    _print_trials(doc["model_trials"])
    for note in notes:
        console.print(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    console.print(Text(f"wrote {len(paths)} files to {paths['results'].parent}",
                       style="green"), soft_wrap=True)
    console.print(Text(f"report: {paths['html']}", style="green"), soft_wrap=True)


# --- the entry point --------------------------------------------------------------------------


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("trackkit")
        except PackageNotFoundError:  # run from a source tree without installing
            from trackkit import __version__ as v
        typer.echo(f"trackkit {v}")
        raise typer.Exit(0)


@app.callback()
def _options(version: Annotated[bool, typer.Option(
        "--version", callback=_print_version, is_eager=True,
        help="Print trackkit's version and exit.")] = False) -> None:
    pass


def _paragraphs(doc: str) -> str:
    """A docstring's paragraphs each on one line, so that rich wraps them to the terminal
    (typer's rich help keeps the hard line breaks of the source)."""
    import inspect

    return "\n\n".join(" ".join(p.split()) for p in inspect.cleandoc(doc).split("\n\n"))


for _info in app.registered_commands:
    if _info.cls in (None, typer.core.TyperCommand):  # typer fills in its default
        _info.cls = _Command
    _info.help = _paragraphs(_info.help or _info.callback.__doc__ or "")


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                      lineno: int, file: Any = None, line: str | None = None) -> None:
    # a user sees what happened, not numpy's source path and line
    _stderr().print(Text(f"warning: {message}", style="yellow"), soft_wrap=True)


def _unraisable(info: Any) -> None:
    # Ctrl-C inside a finaliser is swallowed by Python ("Exception ignored in ..."), and an
    # interrupt raised here again would be swallowed with it: remember it, and the next
    # progress report raises it in the main thread, where main() turns it into one line
    if isinstance(info.exc_value, KeyboardInterrupt):
        _state.interrupt = True
    elif os.environ.get("TRACKKIT_DEBUG"):
        sys.__unraisablehook__(info)


def _deliver_interrupt() -> None:
    """Raise a Ctrl-C that arrived inside a finaliser (see ``_unraisable``)."""
    if _state.interrupt:
        _state.interrupt = False
        raise KeyboardInterrupt


def _terminate(signum: int, frame: object) -> None:
    # SIGTERM: unwind like Ctrl-C, so that the lock and temporary files are removed
    raise KeyboardInterrupt


def _forget_handled_interrupt() -> None:
    # CPython (3.11) marks a KeyboardInterrupt that escapes any exec() of a string (dataclass,
    # namedtuple and pydantic class construction use them) as "unhandled" in a global flag,
    # even when it is caught later, and then ends the process by SIGINT instead of our exit
    # code; every exec() of a string starts by clearing that flag
    exec("None")


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``trackkit`` command (and ``python -m trackkit.cli``)."""
    _state.main, _state.announced = True, False
    try:
        _run_main(argv)
    finally:
        _forget_handled_interrupt()


def _run_main(argv: list[str] | None) -> None:
    try:
        try:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            signal.signal(signal.SIGTERM, _terminate)
        except ValueError:  # not the main thread
            pass
        sys.unraisablehook = _unraisable
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            app(args=argv, prog_name="trackkit")
    except SystemExit as done:
        if done.code == 130 and not _state.announced:
            _say_interrupted()
        raise
    except BaseException as err:
        if _is_interrupt(err):
            _say_interrupted()
            sys.exit(130)
        if os.environ.get("TRACKKIT_DEBUG") or not isinstance(err, Exception):
            raise
        message, code = _describe(err)
        _stderr().print(Text(f"error: {message}", style="red"), soft_wrap=True)
        sys.exit(code)


if _previous_sigint is not None and not _started_as_command():
    signal.signal(signal.SIGINT, _previous_sigint)  # imported as a library: hand Ctrl-C back

if __name__ == "__main__":
    main()

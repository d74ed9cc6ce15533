"""The ``trackkit`` command: list, show and run the bundled (or your own) scenarios.

    trackkit list
    trackkit show bo-cv
    trackkit run [NAME|FILE] [--runs N] [--seed S] [--out DIR] [--workers K] [--scheduler ADDR]

Bad input (a scenario error, a bad option value) exits with code 2 and one red error message,
no traceback, before anything is written; report files appear only when complete.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

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
from rich.syntax import Syntax
from rich.table import Table
from rich.text import Text

__all__ = ["app", "main"]

DEFAULT_OUT = Path("trackkit-out")

app = typer.Typer(
    name="trackkit",
    help="Target tracking comparisons: Monte Carlo runs, PCRLB, tables, plots and reports.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


# --- the stages the CLI drives (imported lazily; tests replace these functions) ------------


def _bundled() -> dict[str, str]:
    from trackkit.scenario import bundled

    return bundled()


def _default_name() -> str:
    from trackkit.scenario import DEFAULT

    return DEFAULT


def _load(name_or_path: str) -> Any:
    from trackkit.scenario import load

    return load(name_or_path)


def _run(scenario: Any, **kwargs: Any) -> Any:
    from trackkit.eval.montecarlo import run_scenario

    return run_scenario(scenario, **kwargs)


def _write(result: Any, out: Path) -> dict[str, Path]:
    from trackkit.report.files import write_report

    return write_report(result, out)


# --- helpers ----------------------------------------------------------------------------------


def _stderr() -> Console:
    return Console(stderr=True)


@contextmanager
def _user_errors() -> Iterator[None]:
    """Bad input (ValueError, incl. ScenarioError) -> exit 2; an OS error -> exit 1; both as
    a red message without traceback (set ``TRACKKIT_DEBUG=1`` to get the traceback)."""
    try:
        yield
    except KeyboardInterrupt:
        _fail("interrupted; no report was written", 130)
    except (ValueError, OSError) as err:
        if os.environ.get("TRACKKIT_DEBUG"):
            raise
        if isinstance(err, ValueError):
            _fail(str(err), 2)
        where = f": {err.filename}" if getattr(err, "filename", None) else ""
        _fail(f"{getattr(err, 'strerror', None) or err}{where}", 1)


def _fail(message: str, code: int) -> None:
    text = Text("error: ", style="bold red")
    text.append(message or "unknown error", style="red")
    _stderr().print(text, soft_wrap=True)
    raise typer.Exit(code)


def _progress_bar(console: Console) -> Progress:
    return Progress(
        TextColumn("{task.description}", style="bold", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("runs"),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=console,
    )


def _run_with_progress(scenario: Any, total: int, **kwargs: Any) -> Any:
    console = _stderr()
    with _progress_bar(console) as bar:
        task = bar.add_task(str(getattr(scenario, "name", "runs")), total=total)

        def progress(done: int, of: int) -> None:
            bar.update(task, completed=done, total=of)

        result = _run(scenario, progress=progress, **kwargs)
        bar.update(task, completed=bar.tasks[0].total)
    return result


def _dump(scenario: Any) -> str:
    try:
        data = scenario.model_dump(mode="json")
    except TypeError:
        data = scenario.model_dump()
    return json.dumps(data, indent=2, default=str)


# --- commands ---------------------------------------------------------------------------------


@app.command("list")
def list_scenarios() -> None:
    """List the bundled scenarios with one-line descriptions."""
    with _user_errors():
        scenarios = _bundled()
        default = _default_name()
    table = Table("scenario", "description", title="bundled scenarios", title_justify="left")
    for name, description in scenarios.items():
        label = Text(name, style="bold")
        if name == default:
            label.append(" (default)", style="dim")
        table.add_row(label, Text(description))
    Console().print(table)


@app.command()
def show(
    scenario: Annotated[
        str | None, typer.Argument(help="Bundled scenario name or TOML file [default: the "
                                        "bundled default].")
    ] = None,
) -> None:
    """Print a scenario with every default filled in."""
    with _user_errors():
        sc = _load(scenario or _default_name())
        to_toml: Callable[[], str] | None = getattr(sc, "to_toml", None)
        text, lexer = (to_toml(), "toml") if to_toml is not None else (_dump(sc), "json")
    console = Console()
    if console.is_terminal:
        console.print(Syntax(text, lexer, theme="ansi_dark", background_color="default",
                             word_wrap=True))
    else:  # piped: the exact text, no wrapping, so that it can be saved and parsed
        typer.echo(text)


@app.command()
def run(
    scenario: Annotated[
        str | None, typer.Argument(help="Bundled scenario name or TOML file [default: the "
                                        "bundled default].")
    ] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", min=1, help="Monte Carlo runs [default: the scenario's].")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", min=0, help="Master seed [default: the scenario's].")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output directory "
                                             "[default: trackkit-out/SCENARIO].")] = None,
    workers: Annotated[int | None, typer.Option("--workers", "-w", min=1,
                                                help="Local Dask workers.")] = None,
    scheduler: Annotated[str | None, typer.Option("--scheduler",
                                                  help="Dask scheduler address.")] = None,
) -> None:
    """Run a Monte Carlo comparison; write results.json, metrics.parquet, plots, report.html."""
    with _user_errors():
        sc = _load(scenario or _default_name())
        target = out if out is not None else DEFAULT_OUT / str(sc.name)
        if target.exists() and not target.is_dir():
            raise ValueError(f"--out {str(target)!r} exists and is not a directory")
        total = runs or getattr(getattr(sc, "run", None), "runs", None) or 1
        result = _run_with_progress(sc, total, runs=runs, seed=seed, workers=workers,
                                    scheduler=scheduler)
        with _stderr().status("writing the report"):
            paths = _write(result, target)
    _print_summary(result, paths)


def _print_summary(result: Any, paths: dict[str, Path]) -> None:
    from trackkit.report.tables import matching_rich_tables, rich_table

    console = Console()
    console.print(rich_table(result, width=console.width))
    for table in matching_rich_tables(result):  # seed 000's J1-J4 and tuning, when present
        console.print(table)
    for note in getattr(result, "notes", []) or []:
        console.print(Text(f"note: {note}", style="yellow"))
    html = paths.get("html")
    where = html.parent if html is not None else next(iter(paths.values())).parent
    console.print(Text(f"wrote {len(paths)} files to {where}", style="green"))
    if html is not None:
        console.print(Text(f"report: {html}", style="green"))


def main() -> None:
    """Entry point (``python -m trackkit.cli``)."""
    app()


if __name__ == "__main__":
    main()

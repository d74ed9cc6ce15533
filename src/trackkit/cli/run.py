"""``trackkit run``: a scenario's Monte Carlo comparison, run by the runner of its kind
(``RUNNERS``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.text import Text

from trackkit.cli import stages
from trackkit.cli.entry import app
from trackkit.cli.option_types import (
    SCENARIO_HELP,
    Scheduler,
    Workers,
    at_least,
    one_executor,
    positive_hours,
)
from trackkit.cli.output import (
    OutputDir,
    default_dir,
    deliver_interrupt,
    output_dir,
    progress_bar,
    say_note,
    stderr,
    user_errors,
)
from trackkit.cli.summaries import number_table, print_summary


@dataclass(frozen=True)
class RunOptions:
    """``trackkit run``'s options (None: the scenario's own)."""

    runs: int | None = None
    seed: int | None = None
    workers: int | None = None
    scheduler: str | None = None
    max_hours: float = 24.0


@app.command()
def run(
    scenario: Annotated[str | None, typer.Argument(
        help=SCENARIO_HELP, show_default="the bundled default")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=at_least(1), help="Monte Carlo runs (at least 1).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=at_least(0), help="Master seed (0 or more).",
        show_default="the scenario's run.seed")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/SCENARIO; for a file, its name without .toml")] = None,
    workers: Workers = None,
    scheduler: Scheduler = None,
    max_hours: Annotated[float, typer.Option(
        "--max-hours", callback=positive_hours, help="Refuse a run count that the first "
        "block's timing says would take longer (hours).")] = 24.0,
) -> None:
    """Run a Monte Carlo comparison; write results.json, timings.json, metrics.parquet,
    plots and report.html.

    The same scenario, seed and block size give bit-identical numbers on one machine, on any
    executor and any number of workers; another CPU agrees to rounding (see the README,
    "Determinism")."""
    with user_errors() as state:
        one_executor(workers, scheduler)
        sc = stages.load(scenario or stages.default_name())
        runner = RUNNERS[stages.kind_of(sc)]
        if runner.command is not None:
            raise ValueError(f"{scenario} is a {stages.kind_of(sc)} scenario; run it with "
                             f"`trackkit {runner.command} {scenario}`")
        target, label = output_dir(out, default_dir(scenario, sc))
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            say_note(where)
            runner.run(sc, where.path, state, RunOptions(runs, seed, workers, scheduler,
                                                         max_hours))


def _run_comparison(sc: Any, out: Path, state: SimpleNamespace, o: RunOptions) -> None:
    """A single-target scenario: every filter on the same runs against the PCRLB."""
    total = o.runs or getattr(getattr(sc, "run", None), "runs", None) or 1
    result = _run_with_progress(sc, total, runs=o.runs, seed=o.seed, workers=o.workers,
                                scheduler=o.scheduler, max_seconds=3600.0 * o.max_hours)
    with stderr().status("writing the report"):
        paths = stages.write(result, out)
    state.interrupted = "interrupted"
    print_summary(result, paths)


def _run_with_progress(scenario: Any, total: int, **kwargs: Any) -> Any:
    """The comparison with a progress bar of runs (``progress(done, total)``, ``done`` a
    float that moves within a block) and, when fuzzy systems are tuned first, one of
    optimiser generations (``tuning_progress(done, total)``)."""
    console = stderr()
    with progress_bar(console) as bar:
        runs = bar.add_task(str(getattr(scenario, "name", "runs")), total=total, unit="runs")
        tuning: list[Any] = []
        final = [total]

        def progress(done: float, of: int) -> None:
            deliver_interrupt()
            final[0] = of
            bar.update(runs, completed=done, total=of)

        def tuning_progress(done: int, of: int) -> None:
            deliver_interrupt()
            if not tuning:
                tuning.append(bar.add_task("tuning", total=of, unit="generations"))
            bar.update(tuning[0], completed=done, total=of)

        result = stages.run(scenario, progress=progress, tuning_progress=tuning_progress,
                             **kwargs)
        deliver_interrupt()
        bar.update(runs, completed=final[0], total=final[0])
    return result


def _run_multitarget(sc: Any, out: Path, **kwargs: Any) -> None:
    """A multi-target scenario: every tracker on the same simulated scans (Monte Carlo),
    GOSPA, OSPA and the track counts; the report written into ``out``."""
    import numpy as np

    from trackkit.experiments.tracking_run import run_multitarget
    from trackkit.report.tracking_report import write_tracking_report

    total = kwargs.get("runs") or sc.run.runs
    with progress_bar(stderr()) as bar:
        task = bar.add_task(str(sc.name), total=total, unit="runs")

        def progress(done: float, of: int) -> None:
            deliver_interrupt()
            bar.update(task, completed=done, total=of)

        result, example = run_multitarget(sc, progress=progress, **kwargs)
        deliver_interrupt()
    with stderr().status("writing the report"):
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
    console.print(number_table(headers, rows, f"{sc.name}: {result.runs} runs, seed "
                                f"{result.seed}, c = {result.c:g} m", console))
    for note in sc.notes:
        console.print(Text(f"note: {note}", style="yellow"))
    html = paths.get("html")
    console.print(Text(f"wrote {len(paths)} files to {out}", style="green"))
    if html is not None:
        console.print(Text(f"report: {html}", style="green"))


@dataclass(frozen=True)
class Runner:
    """How ``trackkit run`` runs a kind of scenario: ``run(scenario, out, state, options)``
    inside the locked output directory, or another command that runs it."""

    run: Callable[[Any, Path, SimpleNamespace, RunOptions], None] | None = None
    command: str | None = None


def _run_scene(sc: Any, out: Path, state: SimpleNamespace, o: RunOptions) -> None:
    _run_multitarget(sc, out, runs=o.runs, seed=o.seed, workers=o.workers,
                     scheduler=o.scheduler)
    state.interrupted = "interrupted"


#: the runner of each kind of scenario (``stages.kind_of``)
RUNNERS: dict[str, Runner] = {
    "comparison": Runner(_run_comparison),
    "multitarget": Runner(_run_scene),
    "network": Runner(command="network"),
    "vessel": Runner(command="identify"),
}

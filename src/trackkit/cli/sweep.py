"""``trackkit sweep``: a campaign of Monte Carlo comparisons over scenario fields, stored block
by block so that it resumes after an interruption."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import Progress
from rich.text import Text

from trackkit.cli import stages
from trackkit.cli.entry import app
from trackkit.cli.option_types import SCENARIO_HELP, Scheduler, Workers, at_least, one_executor
from trackkit.cli.output import (
    OutputDir,
    default_dir,
    deliver_interrupt,
    fail,
    output_dir,
    progress_bar,
    say_note,
    stderr,
    user_errors,
)
from trackkit.cli.summaries import print_sweep_summary


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

    from trackkit.experiments.sweep import Listener

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
                deliver_interrupt()
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
        "--points", callback=at_least(1), help="random, lhs: the number of points; grid: "
        "the values per range.")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=at_least(1), help="Monte Carlo runs per point.",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=at_least(0), help="Campaign seed; each point's seed is a "
        "hash of it and the point's values.", show_default="the scenario's run.seed")] = None,
    block: Annotated[int | None, typer.Option(
        "--block", callback=at_least(1), help="Runs per block, the unit of work and of "
        "checkpoints (results are bit-identical for the same block size).",
        show_default="the scenario's run.block")] = None,
    workers: Workers = None,
    scheduler: Scheduler = None,
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
    with user_errors() as state:
        one_executor(workers, scheduler)
        sc = stages.load(scenario or stages.default_name())
        if stages.kind_of(sc) != "comparison":
            raise ValueError(f"{scenario}: trackkit sweep runs single-target Monte Carlo "
                             "comparisons (the scenarios of trackkit run without [scene], "
                             "[[agents]] or [vessel])")
        from trackkit.experiments.checkpoint import CampaignStore, CheckpointError
        from trackkit.experiments.sweep import BlockFailed, parse_param, plan_campaign, run_campaign
        from trackkit.report.sweep_report import sweep_outputs, write_sweep_report

        params = [parse_param(p) for p in param or []]
        with stderr().status("checking every point of the sweep"):
            campaign = plan_campaign(sc, params, design.value if design else None, points,
                                     runs, seed, block)
        target, label = output_dir(out, f"{default_dir(scenario, sc)}-sweep")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was stored in {target}"
            say_note(where)
            store = CampaignStore(where.path, label)
            store.open(campaign.identity(), fresh=fresh, scenario_toml=stages.dumps(campaign.base),
                       outputs=sweep_outputs(where.path))
            state.interrupted = (f"interrupted; the finished blocks are stored in {target}: "
                                 "run the same command again to resume")
            console = stderr()
            console.print(Text(
                f"{sc.name}: {campaign.design} design, {len(campaign.points)} points x "
                f"{campaign.runs} runs (block {campaign.block}, seed {campaign.seed}) -> "
                f"{target}", style="bold"), soft_wrap=True)
            try:
                with progress_bar(console) as bar:
                    docs = run_campaign(campaign, store, workers=workers, scheduler=scheduler,
                                        listener=_sweep_listener(bar, console))
                    deliver_interrupt()
            except BlockFailed as err:
                fail(f"{err}. The campaign stopped; the blocks finished so far are stored in "
                      f"{target}: fix the cause and run the same command again to resume",
                      1)
            except CheckpointError as err:
                fail(str(err), 1)
            with stderr().status("writing the report"):
                paths = write_sweep_report(campaign, docs, where.path,
                                           [store.load_timings(p.id) for p in campaign.points])
            state.interrupted = "interrupted"
            print_sweep_summary(campaign, docs, paths)

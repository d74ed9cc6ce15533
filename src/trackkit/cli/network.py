"""``trackkit network``: a network scenario's agents, in this process or each in its own (over
ZeroMQ, locally or on other machines), beside the centralised reference and the PCRLB."""

from __future__ import annotations

import math
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.text import Text

from trackkit.cli import stages
from trackkit.cli.entry import app
from trackkit.cli.option_types import Scheduler, Workers, at_least, one_executor
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
from trackkit.cli.summaries import print_network_summary


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
        "--runs", "-n", callback=at_least(1), help="Monte Carlo runs (at least 1).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=at_least(0), help="Master seed (0 or more).",
        show_default="the scenario's run.seed")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/SCENARIO (trackkit-out/SCENARIO-straight with "
        "--straight)")] = None,
    straight: Annotated[bool, typer.Option(
        "--straight", help="Straight courses: no steering, whatever the scenario says "
        "(for comparison with the steered agents).")] = False,
    agents: Annotated[AgentsMode, typer.Option(
        "--agents", help="inprocess: every agent in this process, or the Dask worker's "
        "(fast); processes: every agent its own operating-system process, talking over "
        "ZeroMQ on loopback (same results without message loss, slower).")]
        = AgentsMode.inprocess,
    block: Annotated[int | None, typer.Option(
        "--block", callback=at_least(1), help="Runs stepped together in process, each block "
        "one Dask task (results are bit-identical for any block size).",
        show_default="25, the fastest per run")] = None,
    workers: Workers = None,
    scheduler: Scheduler = None,
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

    With --workers or --scheduler the blocks of runs go to Dask, each block one task.
    The same scenario and seed give byte-identical results.json on one machine, in this
    process or on any number of Dask workers."""
    with user_errors() as state:
        from trackkit.network.inprocess import check_loss
        from trackkit.network.processes import Deployment

        one_executor(workers, scheduler)
        if agents == AgentsMode.processes and (workers or scheduler):
            raise ValueError("--agents processes runs every agent in its own process, driven "
                             "from this one; --workers and --scheduler send blocks of runs "
                             "to Dask with the agents in the worker's process: expected "
                             "--agents inprocess with --workers or --scheduler")
        sc = _load_network(scenario)
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
                stderr().print(Text(f"note: --no-curve with --host {host}: any machine that "
                                     "reaches it can connect and feed the agents bearings or "
                                     "tracks", style="yellow"), soft_wrap=True)
        name = default_dir(scenario, sc) + ("-straight" if straight else "")
        target, label = output_dir(out, name)
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            say_note(where)
            _run_network(sc, where.path, runs=runs, seed=seed,
                         steering=False if straight else None, agents=str(agents.value),
                         compare_straight=compare_straight, loss=loss, delay=delay,
                         workers=workers, scheduler=scheduler,
                         **({} if block is None else {"block": block}),
                         outages=outages, deployment=Deployment(
                             host=host, advertise=advertise, launch=launchers or None,
                             remote_python=remote_python, curve=curve, keys=keys))
            state.interrupted = "interrupted"


def _load_network(scenario: str) -> Any:
    """The network scenario ``scenario``; another kind of scenario is named as such."""
    from trackkit.scenario.network import is_network, load_network

    if not is_network(scenario):
        p = Path(scenario)
        if p.suffix == ".toml" or p.exists():
            if p.is_file():  # (a missing or unreadable file: load_network says so)
                stages.parse_toml(p)
                raise ValueError(f"{scenario}: not a network scenario (it has no "
                                 "[[agents]] tables); run it with `trackkit run "
                                 f"{scenario}`, or see `trackkit show net-baseline` "
                                 "for a network scenario's fields")
        elif scenario in {**stages.bundled(), **stages.bundled_multitarget()}:
            raise ValueError(f"{scenario!r} is not a network scenario; run it with "
                             f"`trackkit run {scenario}` (network scenarios: see "
                             "trackkit list)")
    return load_network(scenario)


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


def _run_network(sc: Any, out: Path, **kwargs: Any) -> None:
    """A network scenario's Monte Carlo (``experiments.network_mc``) with a progress bar of runs,
    its report written into ``out`` and a per-agent summary printed."""
    from trackkit.experiments.network_mc import run_network_mc
    from trackkit.report.network_report import write_network_report

    compare = kwargs.pop("compare_straight", False)
    total = kwargs.get("runs") or sc.run.runs
    given = "--runs" if kwargs.get("runs") else "the scenario's run.runs; --runs N for fewer"
    where = _where(kwargs.get("agents"), kwargs.get("workers"), kwargs.get("scheduler"))
    stderr().print(Text(
        f"{sc.name}: {total} Monte Carlo run{'' if total == 1 else 's'} ({given})"
        + (", then the same runs on straight courses" if compare else "")
        + f", {where} -> {out}", style="bold"), soft_wrap=True)
    with progress_bar(stderr()) as bar:

        def monte_carlo(label: str, **more: Any):
            task = bar.add_task(label, total=total, unit="runs")

            def progress(done: float, of: int) -> None:
                deliver_interrupt()
                bar.update(task, completed=done, total=of)

            result = run_network_mc(sc, progress=progress, **{**kwargs, **more})
            deliver_interrupt()
            return result

        mc = monte_carlo(str(sc.name))
        straight = (monte_carlo(f"{sc.name} (straight)", steering=False, keep_example=False)
                    if compare else None)
    with stderr().status("writing the report"):
        paths = write_network_report(mc, sc, out, straight=straight)
    print_network_summary(paths)


def _where(agents: str | None, workers: int | None, scheduler: str | None) -> str:
    """Where the runs' agents execute, for the opening line."""
    if agents == "processes":
        return "agents in their own processes"
    if scheduler:
        return f"blocks of runs on the Dask scheduler at {scheduler}"
    if workers:
        return f"blocks of runs on {workers} local Dask worker{'' if workers == 1 else 's'}"
    return "agents in this process"

"""``trackkit identify``: a vessel's manoeuvring model from a recorded GPS/INS log and its
inputs, or from a vessel scenario's simulated sea trials (Monte Carlo)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.text import Text

from trackkit.cli import stages
from trackkit.cli.entry import app
from trackkit.cli.option_types import OnBad, at_least, number
from trackkit.cli.output import (
    OutputDir,
    default_dir,
    deliver_interrupt,
    output_dir,
    say_note,
    stderr,
    user_errors,
)
from trackkit.cli.summaries import print_recorded_summary, print_vessel_summary
from trackkit.experiments.vessel_log import LogOptions


class VesselFilter(StrEnum):
    ekf = "ekf"
    ukf = "ukf"
    ckf = "ckf"
    srckf = "srckf"
    ls = "ls"


#: the NMEA log suffixes; any other log is the CSV form (.csv)
NMEA_SUFFIXES = (".nmea", ".log", ".txt")


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
            stages.parse_toml(p)
            raise ValueError(f"{what}: not a vessel scenario (it has no [vessel] table); see "
                             "`trackkit show vessel-turning` for a vessel scenario's fields")
        return "scenario"  # (a missing or unreadable .toml: load_vessel says so)
    if is_vessel(what):
        return "scenario"
    others = {**stages.bundled(), **stages.bundled_multitarget()}
    vessels = sorted(stages.bundled_vessel())
    from trackkit.scenario.network import bundled_network

    if what in others or what in bundled_network():
        raise ValueError(f"{what!r} is not a vessel scenario; `trackkit identify` takes a "
                         f"GPS/INS log or one of {vessels}")
    raise ValueError(f"{what}: no such log file and no bundled vessel scenario of that name; "
                     f"expected a GPS/INS log ({', '.join(NMEA_SUFFIXES)}, .csv) with "
                     f"--inputs, a vessel scenario .toml or one of {vessels}")


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
        "--period", callback=number(0, 60), help="Grid period dt of the pre-processed u, v, "
        "r (s), for a log.", show_default="1")] = None,
    runs: Annotated[int | None, typer.Option(
        "--runs", "-n", callback=at_least(1), help="Monte Carlo runs (a scenario).",
        show_default="the scenario's run.runs")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", "-s", callback=at_least(0), help="Master seed (a scenario).",
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
    with user_errors() as state:
        kind = _identify_kind(what)
        if kind == "scenario":
            from trackkit.scenario.vessel import load_vessel

            given = [o for o, v in (("--inputs", inputs), ("--period", period)) if v is not None]
            if given:
                raise ValueError(f"{' and '.join(given)}: for a GPS/INS log; {what} is a "
                                 "vessel scenario, which simulates its sensors (its period is "
                                 "identification.period_s)")
            sc = load_vessel(what)
            target, label = output_dir(out, default_dir(what, sc))
            with OutputDir(target, label) as where:
                state.interrupted = f"interrupted; nothing was written to {target}"
                say_note(where)
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
        target, label = output_dir(out, f"identify-{log.stem}")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            say_note(where)
            _identify_log(LogOptions(log, inputs, (filt or VesselFilter.ekf).value,
                                     1.0 if period is None else period, on_bad.value),
                          where.path)
            state.interrupted = "interrupted"


@contextmanager
def _stage(what: str) -> Iterator[None]:
    """Say on stderr what the command is doing, as a line (seen in a pipe or a log too) and,
    on a terminal, a spinner while it lasts."""
    console = stderr()
    console.print(Text(f"{what} ...", style="dim"), soft_wrap=True)
    with console.status(what):
        yield


def _stop_hint(err: ValueError) -> ValueError:
    """A reader's message in the command's words (its options, not the function's)."""
    return ValueError(str(err).replace(
        "[on_bad='stop'; pass on_bad='skip' to skip bad records]",
        "[--on-bad stop; pass --on-bad skip to skip bad records]"))


def _identify_log(options: LogOptions, out: Path) -> None:
    """Identify a recorded log (``experiments.vessel_log.identify_log``); write its report;
    print the coefficients, the standard trials and the IMO table."""
    from trackkit.experiments.vessel_log import identify_log
    from trackkit.report.vessel_report import write_recorded_report

    console = Console()
    try:
        ident = identify_log(options, stage=_stage,
                             say=lambda text: console.print(Text(text), soft_wrap=True))
    except ValueError as err:
        raise _stop_hint(err) from None
    with _stage(f"writing the report to {out}"):
        paths = write_recorded_report(ident.result, out, title=options.log.name,
                                      notes=ident.notes, log_read=ident.log_read,
                                      inputs_read=ident.inputs_read)
    print_recorded_summary(paths, options.log, ident.notes)


def _run_vessel(sc: Any, out: Path, **kwargs: Any) -> None:
    """A vessel scenario's Monte Carlo (``experiments.vessel_mc.run_vessel``), its report written
    into ``out`` and a summary printed."""
    from trackkit.experiments.vessel_mc import run_vessel
    from trackkit.report.vessel_report import write_vessel_report

    runs = kwargs.get("runs") or sc.run.runs
    with stderr().status(f"{sc.name}: simulating and identifying, {runs} runs"):
        result = run_vessel(sc, **kwargs)
        deliver_interrupt()
    with stderr().status("writing the report"):
        paths = write_vessel_report(result, sc, out)
    print_vessel_summary(paths, sc.notes)

"""Option types and checks shared by the commands (a bad value is named in the message)."""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, Any

import typer

SCENARIO_HELP = "Bundled scenario name (see trackkit list) or TOML file."


def positive_hours(value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"{value}; expected a positive number of hours")
    return value


def at_least(lowest: int) -> Any:
    """An option callback: the message names the value given (typer's own range check
    says only what the bound is)."""
    def check(value: int | None) -> int | None:
        if value is not None and value < lowest:
            raise typer.BadParameter(f"{value}; expected an integer >= {lowest}")
        return value

    return check


def number(lo: float | None = None, hi: float | None = None, *, open_lo: bool = True,
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


#: the Dask options of the commands that run blocks of Monte Carlo runs (run, sweep,
#: network)
Workers = Annotated[int | None, typer.Option(
    "--workers", "-w", callback=at_least(1), help="Local Dask workers (at least 1).",
    show_default="none: in this process")]
Scheduler = Annotated[str | None, typer.Option(
    "--scheduler", help="Dask scheduler address, e.g. tcp://host:8786.", show_default="none")]


def one_executor(workers: int | None, scheduler: str | None) -> None:
    """``--workers`` and ``--scheduler`` together are refused: each names where blocks run."""
    if workers and scheduler:
        raise ValueError(f"--workers {workers} and --scheduler {scheduler}: give one, "
                         "--workers for a local Dask cluster or --scheduler for a running "
                         "one")


class OnBad(StrEnum):
    skip = "skip"
    stop = "stop"

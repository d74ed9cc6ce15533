"""``trackkit list`` and ``trackkit show``: the bundled scenarios and samples, and a scenario
with every default filled in."""

from __future__ import annotations

import json
from enum import StrEnum
from typing import Annotated

import typer
from rich.console import Console
from rich.syntax import Syntax
from rich.table import Table
from rich.text import Text

from trackkit.cli import stages
from trackkit.cli.entry import app
from trackkit.cli.option_types import SCENARIO_HELP
from trackkit.cli.output import user_errors


class Format(StrEnum):
    toml = "toml"
    json = "json"


@app.command("list")
def list_scenarios() -> None:
    """List the bundled scenarios with one-line descriptions."""
    with user_errors():
        from trackkit.scenario.multitarget import bundled_multitarget
        from trackkit.scenario.network import bundled_network

        scenarios = {**stages.bundled(), **bundled_multitarget(), **bundled_network(),
                     **stages.bundled_vessel()}
        default = stages.default_name()
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
    with user_errors():
        sc = stages.load(scenario or stages.default_name())
        if fmt is Format.toml:
            text = stages.dumps(sc)
        else:
            text = json.dumps(sc.model_dump(mode="json"), indent=2)
        console = Console()
        if console.is_terminal:
            console.print(Syntax(text, fmt.value, theme="ansi_dark",
                                 background_color="default", word_wrap=True))
        else:  # piped: the exact text, no wrapping, so that it can be saved and read back
            typer.echo(text, nl=not text.endswith("\n"))

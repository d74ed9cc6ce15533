"""Summary tables of a Monte Carlo comparison: one row per filter, plus the PCRLB row.

Columns: time-averaged RMSE per error group, efficiency RMSE/PCRLB per group, ANEES, ANIS,
fraction of steps with the average NEES inside its 95% bounds, diverged runs, and filter time
per run-step. Values are SI inside; the only unit conversion (radians to degrees for angle
groups) happens here, in :func:`display_unit`, and the plots use the same function.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

from rich import box
from rich.table import Table
from rich.text import Text

from trackkit.eval.results import MonteCarloResult

__all__ = ["display_unit", "Summary", "summary", "rich_table", "html_table"]

_DEG = 180.0 / math.pi
_CONVERT = {"rad": ("deg", _DEG), "rad/s": ("deg/s", _DEG), "rad/s^2": ("deg/s^2", _DEG)}


def display_unit(unit: str) -> tuple[str, float]:
    """Report label and factor for an SI unit: ``"rad" -> ("deg", 180/pi)``; others unchanged."""
    return _CONVERT.get(unit, (unit, 1.0))


def _num(value: float, digits: int = 4) -> str:
    return f"{value:.{digits}g}" if math.isfinite(value) else "n/a"


def _fixed(value: float) -> str:
    return f"{value:.2f}" if math.isfinite(value) else "n/a"


def _seconds(value: float) -> str:
    if not math.isfinite(value):
        return "n/a"
    if value < 1e-3:
        return f"{value * 1e6:.3g} µs"
    if value < 1.0:
        return f"{value * 1e3:.3g} ms"
    return f"{value:.3g} s"


@dataclass
class Summary:
    """A table as strings: column headers (``\\n`` marks a line break), one row per filter
    (PCRLB row last), a caption."""

    headers: list[str]
    rows: list[list[str]]
    caption: str


def summary(result: MonteCarloResult) -> Summary:
    """The summary table of ``result`` as display strings (angle groups in degrees)."""
    groups = [g for g in result.groups if any(g in f.rmse_mean for f in result.filters.values())]
    bounded = [g for g in groups if math.isfinite(result.pcrlb_mean.get(g, math.nan))]
    headers = ["filter"]
    for g in groups:
        label, _ = display_unit(result.groups[g])
        headers.append(f"RMSE {g}\n[{label}]")
    headers += [f"RMSE/PCRLB\n{g}" for g in bounded]
    headers += ["ANEES", "ANIS", "NEES in\n95% bounds", "diverged\nruns", "time\nper step"]

    rows: list[list[str]] = []
    for name, f in result.filters.items():
        row = [name]
        for g in groups:
            _, factor = display_unit(result.groups[g])
            row.append(_num(f.rmse_mean.get(g, math.nan) * factor))
        row += [_fixed(result.efficiency(name, g)) for g in bounded]
        inside = f"{100 * f.nees_in_bounds:.0f}%" if math.isfinite(f.nees_in_bounds) else "n/a"
        row += [_num(f.anees, 3), _num(f.anis, 3), inside, f"{f.diverged}/{result.runs}",
                _seconds(f.seconds_per_step)]
        rows.append(row)
    if bounded:
        row = ["PCRLB"]
        for g in groups:
            _, factor = display_unit(result.groups[g])
            row.append(_num(result.pcrlb_mean.get(g, math.nan) * factor))
        row += ["1.00"] * len(bounded) + ["", "", "", "", ""]
        rows.append(row)

    t0 = float(result.times[result.start]) if 0 <= result.start < len(result.times) else 0.0
    caption = (f"{result.scenario}: {result.runs} runs, seed {result.seed}, {result.steps} steps "
               f"of {result.dt:g} s; averages over t >= {t0:g} s")
    return Summary(headers, rows, caption)


def _natural_width(s: Summary) -> int:
    cols = [[*h.split("\n"), *(r[i] for r in s.rows)] for i, h in enumerate(s.headers)]
    return sum(max(map(len, c)) + 3 for c in cols)


def rich_table(result: MonteCarloResult, width: int | None = None) -> Table:
    """The summary as a ``rich`` table: one row per filter and a PCRLB row; when ``width``
    (the console width) is given and the table would not fit, transposed (one column per
    filter and a PCRLB column, one row per metric)."""
    s = summary(result)
    n_filters = len(result.filters)
    table = Table(title=f"trackkit: {result.scenario}", caption=s.caption, header_style="bold",
                  box=box.SIMPLE_HEAD)
    if width is None or _natural_width(s) <= width:
        for i, h in enumerate(s.headers):
            table.add_column(Text(h), justify="left" if i == 0 else "right")
        for i, row in enumerate(s.rows):
            table.add_row(*map(Text, row), style="italic" if i >= n_filters else None,
                          end_section=i == n_filters - 1)
        return table
    table.add_column("metric", justify="left")
    for i, row in enumerate(s.rows):
        table.add_column(Text(row[0]), justify="right", style="italic" if i >= n_filters else None)
    for j, h in enumerate(s.headers[1:], start=1):
        table.add_row(Text(h.replace("\n", " ")), *(Text(row[j]) for row in s.rows))
    return table


def html_table(result: MonteCarloResult) -> str:
    """The summary as an HTML ``<table>`` (escaped, no styling beyond class names)."""
    s = summary(result)
    esc = html.escape
    head = "".join(f"<th>{esc(h).replace(chr(10), '<br>')}</th>" for h in s.headers)
    body = []
    for i, row in enumerate(s.rows):
        cls = ' class="bound"' if i >= len(result.filters) else ""
        cells = f"<th>{esc(row[0])}</th>" + "".join(f"<td>{esc(c)}</td>" for c in row[1:])
        body.append(f"<tr{cls}>{cells}</tr>")
    return (f'<table class="summary">\n<caption>{esc(s.caption)}</caption>\n'
            f"<thead><tr>{head}</tr></thead>\n<tbody>\n" + "\n".join(body) + "\n</tbody>\n</table>")

"""Summary tables of a Monte Carlo comparison: one row per filter, plus the PCRLB row.

Columns: time-averaged RMSE per error group, efficiency RMSE/PCRLB per group, ANEES, ANIS,
fraction of steps with the average NEES inside its 95% bounds, diverged runs, and filter time
per run-step. Values are SI inside; the only unit conversion (radians to degrees for angle
groups) happens here, in :func:`display_unit`, and the plots use the same function.

When the scenario asks for Naseri Solhdar's metrics (``report.matching``), two more tables shaped
like the thesis's Tables 3-1, 3-3, 4-1 and 5-1..5-3 (rows J1-Z^i, J2-Z^i, J3-X^j, J4; one
column per filter): the Monte Carlo mean of the per-run values and run 0 alone (the thesis's
tables are single fixed-seed runs). When fuzzy systems were tuned, a table shaped like
Table 3-2 (optimizer, BEST, MEAN, WORST final cost). See :func:`matching_summaries`.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field

import numpy as np
from rich import box
from rich.console import Group
from rich.table import Table
from rich.text import Text

from trackkit.experiments.results import MonteCarloResult

__all__ = [
    "averaging_window", "display_unit", "Summary", "summary", "rich_table", "html_table", "short",
    "channel_labels", "state_labels", "matching_values", "matching_summary", "tuning_summary",
    "matching_summaries", "summary_rich_table", "summary_html_table", "matching_rich_tables",
    "matching_html_tables", "classification_summary", "gap_summary", "window_summaries",
    "fit_rich_table",
]

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
    title: str = ""
    #: indices of the rows that end a section (a rule is drawn below them)
    sections: list[int] = field(default_factory=list)


def summary(result: MonteCarloResult) -> Summary:
    """The summary table of ``result`` as display strings (angle groups in degrees)."""
    groups = [g for g in result.groups if any(g in f.rmse_mean for f in result.filters.values())]
    bounded = [g for g in groups if math.isfinite(result.pcrlb_mean.get(g, math.nan))]
    headers = ["filter", "rank"]
    for g in groups:
        label, _ = display_unit(result.groups[g])
        headers.append(f"RMSE {g}\n[{label}]")
    headers += [f"RMSE/PCRLB\n{g}" for g in bounded]
    headers += ["ANEES", "ANIS", "NEES in\n95% bounds", "diverged\nruns", "time\nper step"]

    rank = ranks(result)
    rows: list[list[str]] = []
    for name, f in result.filters.items():
        row = [name, str(rank[name]) if name in rank else "-"]
        for g in groups:
            _, factor = display_unit(result.groups[g])
            row.append(_num(f.rmse_mean.get(g, math.nan) * factor))
        row += [_fixed(result.efficiency(name, g)) for g in bounded]
        inside = f"{100 * f.nees_in_bounds:.0f}%" if math.isfinite(f.nees_in_bounds) else "n/a"
        row += [_num(f.anees, 3), _num(f.anis, 3), inside, f"{f.diverged}/{result.runs}",
                _seconds(f.seconds_per_step)]
        rows.append(row)
    if bounded:
        row = ["PCRLB", ""]
        for g in groups:
            _, factor = display_unit(result.groups[g])
            row.append(_num(result.pcrlb_mean.get(g, math.nan) * factor))
        row += ["1.00"] * len(bounded) + ["", "", "", "", ""]
        rows.append(row)

    w = averaging_window(result)
    span = (f"t = {w['from_s']:g} to {w['to_s']:g} s ({w['steps']} steps)"
            if w["from_s"] is not None else "no steps")
    caption = (f"{result.scenario}: {result.runs} runs, seed {result.seed}, {result.steps} steps "
               f"of {result.dt:g} s; averages over {span}")
    return Summary(headers, rows, caption)


def window_summaries(result: MonteCarloResult) -> list[Summary]:
    """One table per error window (``report.windows``), shaped like :func:`summary`: per
    filter the RMSE over the window's steps per group, RMSE/PCRLB, ANEES, ANIS and the share
    of the window's steps with the average NEES inside its 95% bounds, and the PCRLB row
    (diverged runs and timings are whole-run numbers: see the summary). Empty without
    windows."""
    out = []
    for w, (a, b) in result.windows.items():
        k0, k1 = result.window_steps[w]
        groups = [g for g in result.groups
                  if any(g in f.windows[w]["rmse"] for f in result.filters.values())]
        bounds = result.pcrlb_windows[w]
        bounded = [g for g in groups if math.isfinite(bounds.get(g, math.nan))]
        headers = ["filter"]
        for g in groups:
            label, _ = display_unit(result.groups[g])
            headers.append(f"RMSE {g}\n[{label}]")
        headers += [f"RMSE/PCRLB\n{g}" for g in bounded]
        headers += ["ANEES", "ANIS", "NEES in\n95% bounds"]
        rows = []
        for name, f in result.filters.items():
            fw = f.windows[w]
            row = [name]
            for g in groups:
                row.append(_num(fw["rmse"].get(g, math.nan) * display_unit(result.groups[g])[1]))
            row += [_fixed(result.efficiency(name, g, w)) for g in bounded]
            inside = fw["nees_in_bounds"]
            row += [_num(fw["anees"], 3), _num(fw["anis"], 3),
                    f"{100 * inside:.0f}%" if math.isfinite(inside) else "n/a"]
            rows.append(row)
        if bounded:
            row = ["PCRLB"]
            for g in groups:
                row.append(_num(bounds.get(g, math.nan) * display_unit(result.groups[g])[1]))
            rows.append(row + ["1.00"] * len(bounded) + ["", "", ""])
        t = np.asarray(result.times, dtype=float)
        span = (f"t = {t[k0]:g} to {t[k1 - 1]:g} s ({k1 - k0} steps)" if k1 > k0
                else "no steps")
        caption = (f"{result.scenario}: error window {w!r} = [{a:g}, {b:g}] s, {span}; "
                   f"{result.runs} runs. RMSE = sqrt(mean over the window's steps of the "
                   "per-step mean squared error over runs); the PCRLB likewise.")
        out.append(Summary(headers, rows, caption, title=f"Error window {w}: {a:g}-{b:g} s",
                           sections=[len(result.filters) - 1] if bounded else []))
    return out


def fit_rich_table(s: Summary, width: int | None = None, plain_rows: int | None = None
                   ) -> Table:
    """A :class:`Summary` as a ``rich`` table; when ``width`` (the console width) is given and
    the table would not fit, transposed (one column per row of the summary, one row per
    metric), as :func:`rich_table` does. Rows from ``plain_rows`` on (the bound) are
    italic."""
    n = len(s.rows) if plain_rows is None else plain_rows
    if width is None or _natural_width(s) <= width:
        table = summary_rich_table(s)
        if plain_rows is not None:
            for i in range(n, len(s.rows)):
                table.rows[i].style = "italic"
        return table
    return _transposed(s, n, s.title or None, width)


def _transposed(s: Summary, plain_rows: int, title: str | None, width: int | None = None
                ) -> Table | Group:
    """``s`` with one column per row and one row per metric (rows from ``plain_rows`` on
    italic): the form that fits a narrow terminal (folded into several tables when even
    this is wider than ``width``)."""
    columns = [("metric", None)] + [(row[0], "italic" if i >= plain_rows else None)
                                    for i, row in enumerate(s.rows)]
    rows = [([h.replace("\n", " "), *(row[j] for row in s.rows)], None, False)
            for j, h in enumerate(s.headers[1:], start=1)]
    return _number_table(title, s.caption, columns, rows, width)


#: the narrowest the label column is made before the number columns are folded
_LABEL_MIN = 14


def _number_width(header: str, cells: list[str]) -> int:
    """A number column's width: its longest cell, or its header's longest word."""
    return max([len(c) for c in cells] + [len(w) for w in header.split()] + [1])


def _folds(widths: list[int], label: int, width: int | None) -> list[list[int]]:
    """The number columns (indices from 1) of each table the columns fold into: as many as
    fit beside the label column in ``width`` (a column takes its width and 3 characters
    of padding and rule)."""
    if width is None:
        return [list(range(1, len(widths) + 1))]
    room = width - min(label, _LABEL_MIN) - 5
    out: list[list[int]] = [[]]
    used = 0
    for j, w in enumerate(widths, start=1):
        if out[-1] and used + w + 3 > room:
            out.append([])
            used = 0
        out[-1].append(j)
        used += w + 3
    # as many tables, their columns shared out evenly when they fit so
    per = -(-len(widths) // len(out))
    even = [list(range(1 + i, min(i + per, len(widths)) + 1))
            for i in range(0, len(widths), per)]
    if len(even) == len(out) and all(sum(widths[j - 1] + 3 for j in f) <= room for f in even):
        return even
    return out


def _number_table(title: str | None, caption: str | None,
                  columns: list[tuple[str, str | None]],
                  rows: list[tuple[list[str], str | None, bool]], width: int | None = None
                  ) -> Table | Group:
    """A table of a label column and number columns that never cuts a number: each number
    column is at least as wide as its longest cell (its header wraps at spaces); when they
    do not fit in ``width`` beside the labels, the table folds into several, each with the
    label column. ``columns``: (header, style); ``rows``: (cells, style, end of section)."""
    widths = [_number_width(h, [r[0][j] for r in rows]) for j, (h, _) in enumerate(columns)]
    folds = _folds(widths[1:], widths[0], width)
    fixed: dict[int, int | None] = {j: None for fold in folds for j in fold}
    if width is not None:  # rich's own squeeze can push a column below its numbers
        room = width - min(widths[0], _LABEL_MIN) - 5
        for fold in folds:
            spare = room - sum(widths[j] + 3 for j in fold)
            for j in fold:  # a header on one line where there is room for it
                natural = max([widths[j]] + [len(x) for x in columns[j][0].split("\n")])
                fixed[j] = widths[j] + min(max(spare, 0), natural - widths[j])
                spare -= fixed[j] - widths[j]
    tables = []
    for k, fold in enumerate(folds):
        table = Table(title=title if k == 0 else None,
                      caption=caption if len(folds) == 1 else None,
                      header_style="bold", box=box.SIMPLE_HEAD)
        table.add_column(Text(columns[0][0]), justify="left", overflow="fold",
                         min_width=min(widths[0], _LABEL_MIN), style=columns[0][1])
        for j in fold:
            table.add_column(Text(columns[j][0], overflow="fold"), justify="right",
                             min_width=widths[j], width=fixed[j], style=columns[j][1])
        for cells, style, end in rows:
            table.add_row(Text(cells[0]), *(Text(cells[j]) for j in fold), style=style,
                          end_section=end)
        tables.append(table)
    if len(tables) == 1:
        return tables[0]
    return Group(*tables, *([Text(caption, style="dim")] if caption else []))


def ranks(result: MonteCarloResult) -> dict[str, int]:
    """Each filter's place, 1 the best: by RMSE over the PCRLB of the first group that has a
    bound (else by the first group's RMSE), time-averaged as in the summary; a filter whose
    number is not finite (no steps, or diverged to nan) gets no place."""
    groups = [g for g in result.groups if any(g in f.rmse_mean for f in result.filters.values())]
    if not groups:
        return {}
    bounded = [g for g in groups if math.isfinite(result.pcrlb_mean.get(g, math.nan))]
    if bounded:
        score = {n: result.efficiency(n, bounded[0]) for n in result.filters}
    else:
        score = {n: f.rmse_mean.get(groups[0], math.nan) for n, f in result.filters.items()}
    placed = sorted((v, n) for n, v in score.items() if math.isfinite(v))
    return {n: i + 1 for i, (_, n) in enumerate(placed)}


def averaging_window(result: MonteCarloResult) -> dict:
    """The steps behind the time averages: ``from_s`` and ``to_s`` (seconds from the scenario
    start, both steps included; None when the window is empty), ``first_step`` and
    ``steps``."""
    times = np.asarray(result.times, dtype=float).reshape(-1)
    start = max(0, int(result.start))
    inside = times[start:]
    return {"from_s": float(inside[0]) if inside.size else None,
            "to_s": float(inside[-1]) if inside.size else None,
            "first_step": start, "steps": int(inside.size)}


def _natural_width(s: Summary) -> int:
    cols = [[*h.split("\n"), *(r[i] for r in s.rows)] for i, h in enumerate(s.headers)]
    return sum(max(map(len, c)) + 3 for c in cols)


def rich_table(result: MonteCarloResult, width: int | None = None) -> Table | Group:
    """The summary as a ``rich`` table: one row per filter and a PCRLB row; when ``width``
    (the console width) is given and the table would not fit, transposed (one column per
    filter and a PCRLB column, one row per metric)."""
    s = summary(result)
    n_filters = len(result.filters)
    title = f"trackkit: {result.scenario}"
    if width is not None and _natural_width(s) > width:
        return _transposed(s, n_filters, title, width)
    columns = [(h, None) for h in s.headers]
    rows = [(row, "italic" if i >= n_filters else None, i == n_filters - 1)
            for i, row in enumerate(s.rows)]
    return _number_table(title, s.caption, columns, rows, width)


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


# --- Naseri Solhdar's thesis: the thesis metrics J1-J4 and the tuning of the fuzzy systems
# -------------------

#: state components named like the error groups, for the 3-D [x, y, z, vx, vy, vz] state
_STATE_3D = (("x", "m"), ("y", "m"), ("z", "m"), ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"))
_WHICH = ("mean", "run0")


def short(value: float) -> str:
    """Four significant digits, positional (MATLAB's ``format short`` look of the thesis's
    tables): 0.3091, 2.976, 42.22, 12950; scientific only below 1e-4 or from 1e6; "n/a" when
    not finite."""
    v = float(value)
    if not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    rounded = f"{v:.3e}"  # 4 significant digits; the exponent after rounding
    exponent = int(rounded.split("e")[1])
    if not -4 <= exponent < 6:
        return rounded
    return f"{float(rounded):.{max(0, 3 - exponent)}f}"


def channel_labels(m: int) -> list[str]:
    """Measurement channel names Z1..Zm (the thesis's Z^i)."""
    return [f"Z{i + 1}" for i in range(m)]


def _three_d(result: MonteCarloResult) -> bool:
    """Whether the scenario is 3-D: a 3-D observer track or a z/vz error group."""
    ex = result.example
    observer = None if ex is None else np.asarray(ex.observer)
    return (observer is not None and observer.ndim == 2 and observer.shape[1] == 3) or bool(
        {"z", "vz"} & set(result.groups))


def state_labels(result: MonteCarloResult, n: int) -> list[tuple[str, str | None]]:
    """(name, SI unit or None) of each of the n state components: the error-group names x, y,
    z, vx, vy, vz for a 3-D constant-velocity state [x, y, z, vx, vy, vz], else X1..Xn (with
    the unit of an error group ``x<j>`` when the scenario reports one)."""
    if n == 6 and _three_d(result):
        return list(_STATE_3D)
    out = []
    for j in range(n):
        unit = result.groups.get(f"x{j + 1}")
        out.append((f"X{j + 1}", unit if unit not in (None, "", "-") else None))
    return out


def _matching_filters(result: MonteCarloResult) -> list[str]:
    return [name for name, f in result.filters.items() if f.matching]


def matching_values(result: MonteCarloResult, which: str = "mean"
                    ) -> tuple[list[str], list[str], np.ndarray] | None:
    """The J1-J4 table as numbers: ``(row labels, filter names, values (rows, filters))`` in
    SI units, ``which`` = "mean" (over the Monte Carlo runs) or "run0" (the first run); None
    when the result has no matching data. Rows: J1-Z<i> (the raw measurement noise, the same
    for every filter), J2-Z<i>, J3-<state component> (the thesis's J1 of chapters 4-5), J4."""
    if which not in _WHICH:
        raise ValueError(f"which = {which!r}; expected one of {_WHICH}")
    names = _matching_filters(result)
    if not names and result.j1 is None:
        return None

    def pick(a) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        return a.mean(0) if which == "mean" else a[0]

    first = result.filters[names[0]].matching if names else {}
    m = (np.shape(result.j1)[-1] if result.j1 is not None
         else np.shape(first.get("J2", np.empty((0, 0))))[-1])
    n = np.shape(first.get("J3", np.empty((0, 0))))[-1]
    channels = channel_labels(m)
    labels: list[str] = []
    columns: list[list[float]] = [[] for _ in names]
    if result.j1 is not None:
        j1 = pick(result.j1)
        labels += [f"J1-{c}" for c in channels]
        for col in columns:
            col += j1.tolist()
    for key, tags in (("J2", channels),
                      ("J3", [name if unit is None else f"{name} [{display_unit(unit)[0]}]"
                              for name, unit in state_labels(result, n)])):
        if key not in first:
            continue
        labels += [f"{key}-{t}" for t in tags]
        for col, name in zip(columns, names, strict=True):
            values = result.filters[name].matching.get(key)
            if key == "J3" and values is not None:  # display units (factor 1 for m, m/s)
                factors = [display_unit(u)[1] if u else 1.0 for _, u in state_labels(result, n)]
                col += (pick(values) * np.asarray(factors)).tolist()
            else:
                col += (pick(values).tolist() if values is not None else [math.nan] * len(tags))
    if "J4" in first:
        labels.append(f"J4 (alpha {result.dom_alpha:g})")
        for col, name in zip(columns, names, strict=True):
            values = result.filters[name].matching.get("J4")
            col.append(float(pick(values)) if values is not None else math.nan)
    values = np.array(columns, dtype=float).T if names else np.empty((len(labels), 0))
    return labels, names, values


def matching_summary(result: MonteCarloResult, which: str = "mean") -> Summary | None:
    """The J1-J4 table (see :func:`matching_values`) as display strings, 4 significant
    digits; None without matching data."""
    got = matching_values(result, which)
    if got is None:
        return None
    labels, names, values = got
    if names:
        rows = [[label, *map(short, row)] for label, row in zip(labels, values, strict=True)]
        headers = ["criterion", *names]
    else:  # J1 alone (no filter has the matching metrics)
        j1 = np.asarray(result.j1, dtype=float)
        rows = [[label, short(v)] for label, v in
                zip(labels, j1.mean(0) if which == "mean" else j1[0], strict=True)]
        headers = ["criterion", "all filters"]
    sections, last = [], None
    for i, label in enumerate(labels):
        key = label.split("-")[0].split(" ")[0]
        if last is not None and key != last:
            sections.append(i - 1)
        last = key
    if which == "mean":
        title = f"Naseri Solhdar metrics: Monte Carlo mean over {result.runs} runs"
        how = f"mean of the per-run values over {result.runs} runs"
    else:
        title = "Naseri Solhdar metrics: run 0 (one fixed-seed run, as in the thesis)"
        how = f"run 0 alone (the first run of seed {result.seed})"
    caption = (f"{result.scenario}: {how}; SI units. J1: raw noise RMS; J2: noise-free minus "
               "estimated measurement RMS; J3: state RMSE (the thesis's J1 in chapters 4-5); "
               "J4: alpha sum_i RMS DOM(i,i).")
    return Summary(headers, rows, caption, title=title, sections=sections)


def tuning_summary(result: MonteCarloResult) -> Summary | None:
    """One row per tuned filter, shaped like the thesis's Table 3-2: optimizer, independent
    runs, population x iterations, BEST / MEAN / WORST final cost over the runs, wall time;
    None when nothing was tuned."""
    if not result.tuning:
        return None
    headers = ["filter", "optimizer", "runs", "population\nx iterations", "BEST", "MEAN",
               "WORST", "seconds"]
    rows = [[name, str(t.optimizer), str(t.runs), f"{t.population} x {t.iterations}",
             short(t.best), short(t.mean), short(t.worst), _num(float(t.seconds), 3)]
            for name, t in result.tuning.items()]
    caption = (f"{result.scenario}: final cost alpha sum_i RMS DOM(i,i) (alpha "
               f"{result.dom_alpha:g}) over each optimiser's independent runs; the filter "
               "uses the best run's fuzzy system.")
    return Summary(headers, rows, caption, title="Tuning of the fuzzy systems (off-line)")


def matching_summaries(result: MonteCarloResult) -> list[Summary]:
    """The tables of Naseri Solhdar's metrics present in ``result``: J1-J4 mean and run 0
    (with matching data), then the tuning table (when tuned). Empty for other scenarios."""
    out = [matching_summary(result, "mean"), matching_summary(result, "run0"),
           tuning_summary(result)]
    return [s for s in out if s is not None]


def summary_rich_table(s: Summary, width: int | None = None) -> Table | Group:
    """A :class:`Summary` as a ``rich`` table (first column left, the rest right; folded into
    several when wider than ``width``: no number is ever cut)."""
    rows = [(row, None, i in s.sections) for i, row in enumerate(s.rows)]
    return _number_table(s.title or None, s.caption, [(h, None) for h in s.headers], rows,
                         width)


def summary_html_table(s: Summary) -> str:
    """A :class:`Summary` as an HTML ``<table class="summary">`` (escaped; the title is not
    included: the page puts it in a heading)."""
    esc = html.escape
    head = "".join(f"<th>{esc(h).replace(chr(10), '<br>')}</th>" for h in s.headers)
    body = []
    for i, row in enumerate(s.rows):
        cls = ' class="section-end"' if i in s.sections else ""
        cells = f"<th>{esc(row[0])}</th>" + "".join(f"<td>{esc(c)}</td>" for c in row[1:])
        body.append(f"<tr{cls}>{cells}</tr>")
    return (f'<table class="summary">\n<caption>{esc(s.caption)}</caption>\n'
            f"<thead><tr>{head}</tr></thead>\n<tbody>\n" + "\n".join(body) + "\n</tbody>\n</table>")


def matching_rich_tables(result: MonteCarloResult, width: int | None = None
                         ) -> list[Table | Group]:
    """The error-window tables (:func:`~trackkit.report.tables.window_summaries`,
    transposed when wider than ``width``), :func:`~trackkit.report.tables.matching_summaries`,
    the missing-measurement table (:func:`~trackkit.report.tables.gap_summary`) and the
    classification table (:func:`~trackkit.report.tables.classification_summary`), when
    present, as ``rich`` tables (printed after :func:`~trackkit.report.tables.rich_table`)."""
    n = len(result.filters)
    windows = [fit_rich_table(s, width, n) for s in window_summaries(result)]
    extra = [t for t in (gap_summary(result), classification_summary(result)) if t is not None]
    return windows + [summary_rich_table(s, width)
                      for s in matching_summaries(result) + extra]


def classification_summary(result: MonteCarloResult) -> Summary | None:
    """"Classification": one row per filter that classifies (JTC, MultiFilterJTC). With a
    true class: its probability at the end (mean and 10th percentile over runs), the share of
    runs that end above 0.9, the median time from which it stays above 0.9, and the filter's
    time per run-step; without one, each class's mean probability at the end. None when no
    filter classifies."""
    names = result.classifiers()
    if not names:
        return None
    summaries = {n: result.classification(n) for n in names}
    truths = {c.get("true_class") for c in summaries.values()}
    if truths != {None}:
        headers = ["filter", "true class", "P(true) at\nthe end, mean", "P(true) at the\n"
                   "end, 10th pct.", "runs ending\nabove 0.9", "decided\n(median) [s]",
                   "time\nper step"]
        rows = []
        for n, c in summaries.items():
            if c.get("true_class") is None:
                rows.append([n, "n/a", "", "", "", "",
                             _seconds(result.filters[n].seconds_per_step)])
                continue
            rows.append([n, c["true_class"], _num(c["final_true_mean"], 4),
                         _num(c["final_true_p10"], 4), f"{100 * c['above']:.1f}%",
                         _num(c["decided_s"], 4),
                         _seconds(result.filters[n].seconds_per_step)])
        caption = (f"{result.scenario}: the probability each filter puts on the true class, "
                   f"over {result.runs} runs; decided: the time from which it stays above "
                   "0.9 (n/a when most runs never get there).")
    else:
        classes = sorted({k for c in summaries.values() for k in c["classes"]})
        headers = ["filter", *[f"P({k}) at\nthe end, mean" for k in classes], "time\nper step"]
        rows = [[n, *[_num(dict(zip(c["classes"], c["final_mean"], strict=True)).get(
            k, math.nan), 4) for k in classes], _seconds(result.filters[n].seconds_per_step)]
            for n, c in summaries.items()]
        caption = (f"{result.scenario}: each class's probability at the end, mean over "
                   f"{result.runs} runs (the scenario names no true class: report.true_class)."
                   )
    return Summary(headers, rows, caption, title="Classification")


def gap_summary(result: MonteCarloResult) -> Summary | None:
    """"Error over the gap and after, per handler": each filter's handler, the fraction of
    (run, step) pairs fed a pseudo-measurement, and per error group the RMSE over the steps
    [gaps] hides and over the ``after_gap_s`` after them (all runs). None when the scenario
    has neither [gaps] nor a filter with a handler."""
    handlers = {n: f.gaps.get("handler") for n, f in result.filters.items()}
    if result.gap_steps is None and not any(handlers.values()):
        return None
    groups = list(result.groups) if result.gap_steps is not None else []
    headers = ["filter", "handler", "pseudo-\nmeasurements"]
    for g in groups:
        label, _ = display_unit(result.groups[g])
        headers += [f"RMSE {g}\ngap [{label}]", f"RMSE {g}\nafter [{label}]"]
    rows = []
    for name in result.filters:
        row = [name, handlers[name] or "B0", f"{100 * result.pseudo_fraction(name):.1f}%"]
        for g in groups:
            _, factor = display_unit(result.groups[g])
            row += [_num(result.gap_rmse(name, g, w) * factor) for w in ("gap", "after")]
        rows.append(row)
    if result.gap_steps is None:
        where = "no [gaps]: measurements missing at random only"
    else:
        t = np.asarray(result.times, dtype=float)
        gap, after = result.gap_steps, result.after_steps
        where = (f"gap: {len(gap)} steps (t = {_spans(t, gap)} s); after: the "
                 f"{result.after_gap_s:g} s after each gap ({len(after)} steps"
                 + (f", t = {_spans(t, after)} s)" if len(after) else ")"))
    caption = (f"{where}. pseudo-measurements: the share of (run, step) pairs fed one. RMSE "
               f"over all {result.runs} runs.")
    return Summary(headers, rows, caption, title="Error over the gap and after, per handler")


def _spans(t: np.ndarray, steps: np.ndarray) -> str:
    """The times of runs of consecutive steps, as "a-b, c-d"."""
    if len(steps) == 0:
        return "none"
    cuts = np.flatnonzero(np.diff(steps) > 1) + 1
    parts = np.split(steps, cuts)
    return ", ".join(f"{t[p[0]]:g}" if len(p) == 1 else f"{t[p[0]]:g}-{t[p[-1]]:g}"
                     for p in parts)


def matching_html_tables(result: MonteCarloResult) -> list[tuple[str, str]]:
    """:func:`matching_summaries` as ``(title, HTML table)`` pairs."""
    return [(s.title, summary_html_table(s)) for s in matching_summaries(result)]

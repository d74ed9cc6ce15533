"""A campaign's report files (``trackkit sweep``): the sweep table, its figures and one page.

Files, written into the campaign directory all or nothing (``files.write_atomically``):

- ``sweep.parquet`` and ``sweep.csv``: one row per point and filter: ``point`` (its id),
  ``seed`` (its master seed), one column per swept parameter (named by its path; a
  parameter given as factors holds their text, ``x0.1``), ``filter``, ``runs``, then per
  error group ``g`` of the scenario's report: ``rmse_g``, ``pcrlb_g`` and ``rmse_pcrlb_g``
  (RMSE over the PCRLB, time averaged from ``report.average_from_s``), then ``anees``,
  ``anis``, ``nees_in_bounds``, ``diverged`` (runs) and ``diverged_share``; then, for each
  error window ``w`` of the scenario (``report.windows``), ``rmse_g_w``, ``pcrlb_g_w``,
  ``rmse_pcrlb_g_w`` and ``anees_w`` over the window's steps. SI units
  (radians for angles; the Parquet fields carry them as ``unit`` metadata); a missing value
  is null (Parquet) or empty (CSV); CSV floats are written as the shortest text that
  reads back to the same double.
- ``sweep.json``: the design: parameters, every point's id, values and seed.
- ``lines-PARAM.png``: each headline metric against each swept parameter, one colour per
  filter (the other parameters fixed at each of their levels, up to three line styles, else
  at their middle level); a random or Latin-hypercube design is shown as points.
- ``heatmap-METRIC.png``: for a grid over two parameters, each metric over the grid, one
  panel per filter (log colours where it spans more than 30x; the scenario's own setting,
  ``x1`` for factors, framed).
- ``heatmap-ratio_rmse_GROUP.png``: for a grid over two parameters, each filter's RMSE over
  the reference filter's at the same point (same truths and measurements): the reference is
  the scenario's published table's (``[report] published``, e.g. the EKF of Hashemi and Alfi
  (2019)), else the scenario's first filter. Where the paper gives that filter's ratio, the panel's
  title gives it beside ours at the scenario's own setting, and a dashed contour runs where
  ours crosses it.
- ``report.html``: the settings, the table of headline metrics, each published ratio beside
  ours (at the scenario's own setting, the point nearest the paper's value, our lowest and
  highest, and how many points are at or below it) and the figures inlined.
- ``timings.json``: each point's filters' wall-clock time per run-step (not deterministic).

The table, ``sweep.json`` and the points' results are the same bytes for the same command,
whatever the executor, the workers or the interruptions.
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from trackkit.experiments.sweep import factor_of
from trackkit.report.files import write_atomically, write_json
from trackkit.report.html import CSS, data_uri
from trackkit.report.plots import save_figure
from trackkit.report.tables import display_unit
from trackkit.scenario.schema import PublishedSpec

__all__ = ["sweep_table", "write_sweep_csv", "write_sweep_report", "render_sweep_html",
           "line_figures", "heatmap_figures", "ratio_figures", "ratio_grids",
           "published_rows", "reference_filter", "sweep_outputs", "headline_metrics",
           "SWEEP_PARQUET", "SWEEP_CSV", "SWEEP_JSON", "SWEEP_HTML", "SWEEP_TIMINGS"]

#: The campaign's table, one row per point and filter, as Parquet.
SWEEP_PARQUET = "sweep.parquet"
#: The same table as CSV.
SWEEP_CSV = "sweep.csv"
#: The campaign's results document.
SWEEP_JSON = "sweep.json"
#: The campaign's HTML report.
SWEEP_HTML = "report.html"
#: The campaign's wall-clock times.
SWEEP_TIMINGS = "timings.json"
_FIXED = (SWEEP_PARQUET, SWEEP_CSV, SWEEP_JSON, SWEEP_HTML, SWEEP_TIMINGS)
_FIGURE = re.compile(r"(lines|heatmap)-[A-Za-z0-9._-]+\.png")
_DPI = 100
_STYLES = ("-", "--", ":")


def sweep_outputs(out_dir: str | Path) -> list[str]:
    """The report files of a campaign present in ``out_dir`` (what ``--fresh`` removes)."""
    d = Path(out_dir)
    figures = sorted(p.name for p in d.iterdir() if _FIGURE.fullmatch(p.name)) if (
        d.is_dir()) else []
    return [*_FIXED, *figures]


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "x"


# --- the table ----------------------------------------------------------------------------


def _param_type(values: Iterable[Any]) -> pa.DataType:
    values = list(values)
    if all(isinstance(v, bool) for v in values):
        return pa.bool_()
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return pa.int64()
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return pa.float64()
    return pa.string()


def _param_cell(v: Any, kind: pa.DataType) -> Any:
    if kind == pa.string():
        return v if isinstance(v, str) else json.dumps(v)
    if kind == pa.float64():
        return float(v)
    return v


def sweep_table(campaign: Any, docs: Sequence[dict]) -> pa.Table:
    """One row per point (design order) and filter (scenario order); see the module doc."""
    groups = list(campaign.base.report.groups)
    units = dict(docs[0]["units"]) if docs else {}
    paths = [p.path for p in campaign.params]
    kinds = {path: _param_type(d["values"][path] for d in docs) for path in paths}
    cols: dict[str, list] = {"point": [], "seed": []}
    cols.update({path: [] for path in paths})
    cols.update({"filter": [], "runs": []})
    for g in groups:
        cols.update({f"rmse_{g}": [], f"pcrlb_{g}": [], f"rmse_pcrlb_{g}": []})
    cols.update({"anees": [], "anis": [], "nees_in_bounds": [], "diverged": [],
                 "diverged_share": []})
    windows = list(campaign.base.report.windows)
    unit_of: dict[str, str | None] = {}
    for w in windows:  # the scenario's error windows, each metric again over its steps
        for g in groups:
            cols.update({f"rmse_{g}_{w}": [], f"pcrlb_{g}_{w}": [], f"rmse_pcrlb_{g}_{w}": []})
            unit_of.update({f"rmse_{g}_{w}": units.get(g), f"pcrlb_{g}_{w}": units.get(g),
                            f"rmse_pcrlb_{g}_{w}": "1"})
        cols[f"anees_{w}"] = []
        unit_of[f"anees_{w}"] = "1"
    for d in docs:
        for name, f in d["filters"].items():
            cols["point"].append(d["point"])
            cols["seed"].append(d["seed_point"])
            for path in paths:
                cols[path].append(_param_cell(d["values"][path], kinds[path]))
            cols["filter"].append(name)
            cols["runs"].append(d["runs"])
            for g in groups:
                cols[f"rmse_{g}"].append(f["rmse"].get(g))
                cols[f"pcrlb_{g}"].append(d["pcrlb"].get(g))
                cols[f"rmse_pcrlb_{g}"].append(f["rmse_pcrlb"].get(g))
            for k in ("anees", "anis", "nees_in_bounds", "diverged"):
                cols[k].append(f[k])
            cols["diverged_share"].append(f["diverged"] / d["runs"])
            for w in windows:
                win = d["windows"][w]
                fw = win["filters"][name]
                for g in groups:
                    cols[f"rmse_{g}_{w}"].append(fw["rmse"].get(g))
                    cols[f"pcrlb_{g}_{w}"].append(win["pcrlb"].get(g))
                    cols[f"rmse_pcrlb_{g}_{w}"].append(fw["rmse_over_pcrlb"].get(g))
                cols[f"anees_{w}"].append(fw["anees"])
    fields = []
    for name in cols:
        unit = None
        if name in ("point", "filter"):
            kind = pa.string()
        elif name in ("seed", "runs", "diverged"):
            kind = pa.int64()
            unit = "runs" if name != "seed" else None
        elif name in kinds:
            kind = kinds[name]
        elif name in unit_of:
            kind, unit = pa.float64(), unit_of[name]
        else:
            kind = pa.float64()
            for prefix in ("rmse_pcrlb_", "rmse_", "pcrlb_"):
                if name.startswith(prefix):
                    unit = "1" if prefix == "rmse_pcrlb_" else units.get(name[len(prefix):])
                    break
            else:
                unit = "1"
        fields.append(pa.field(name, kind, metadata={"unit": unit} if unit else None))
    meta = {"scenario": campaign.base.name, "design": campaign.design, "seed": campaign.seed,
            "runs": campaign.runs, "block": campaign.block, "parameters": paths,
            "groups": units}
    schema = pa.schema(fields, metadata={"trackkit": json.dumps(meta)})
    return pa.Table.from_arrays([pa.array(v, type=f.type) for v, f in
                                 zip(cols.values(), fields, strict=True)], schema=schema)


def _csv_cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ""
    return str(v)


def write_sweep_csv(table: pa.Table, path: str | Path) -> Path:
    """The table as CSV (a header line, then rows; shortest round-trip floats)."""
    path = Path(path)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(table.column_names)
    for row in zip(*(table.column(i).to_pylist() for i in range(table.num_columns)),
                   strict=True):
        w.writerow([_csv_cell(v) for v in row])
    path.write_text(buf.getvalue(), encoding="utf-8")
    return path


# --- figures ------------------------------------------------------------------------------


def headline_metrics(campaign: Any, table: pa.Table) -> list[tuple[str, str]]:
    """(column, label) of the plotted metrics: the first group's RMSE and RMSE/PCRLB, ANEES
    and the share of runs that diverged."""
    g = campaign.base.report.groups[0]
    unit = json.loads(table.schema.metadata[b"trackkit"])["groups"].get(g, "")
    shown, _ = display_unit(unit)
    return [(f"rmse_{g}", f"{g} RMSE [{shown}]"), (f"rmse_pcrlb_{g}", f"{g} RMSE / PCRLB"),
            ("anees", "ANEES"), ("diverged_share", "share of runs diverged")]


def _column_values(table: pa.Table, name: str) -> np.ndarray:
    vals = table.column(name).to_pylist()
    return np.array([np.nan if v is None else v for v in vals], dtype=float)


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def _levels(values: Sequence[Any]) -> list[Any]:
    """The distinct values in order: numbers and factors (``x0.1``) sorted, others as they
    come."""
    uniq = list(dict.fromkeys(values))
    if _numeric(uniq):
        return sorted(uniq)
    if uniq and all(factor_of(v) is not None for v in uniq):
        return sorted(uniq, key=factor_of)
    return uniq


def _figure(w: float, h: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), layout="constrained")


def _scaled(table: pa.Table, column: str) -> np.ndarray:
    """A metric column in display units (degrees for an RMSE in radians)."""
    v = _column_values(table, column)
    if column.startswith("rmse_") and not column.startswith("rmse_pcrlb_"):
        unit = json.loads(table.schema.metadata[b"trackkit"])["groups"].get(column[5:], "")
        v = v * display_unit(unit)[1]
    return v


def line_figures(campaign: Any, table: pa.Table) -> dict[str, Any]:
    """``lines-PARAM`` -> a figure of the headline metrics against that parameter."""
    metrics = headline_metrics(campaign, table)
    filters = list(dict.fromkeys(table.column("filter").to_pylist()))
    colours = {f: f"C{i % 10}" for i, f in enumerate(filters)}
    paths = [p.path for p in campaign.params]
    values = {p: table.column(p).to_pylist() for p in paths}
    rows_filter = table.column("filter").to_pylist()
    scattered = campaign.design != "grid"
    n = campaign.base.state_dim
    out = {}
    for param in campaign.params:
        # factors (x0.1) are plotted at their number, on a log axis when they span decades
        x_all = [factor_of(v) if param.relative else v for v in values[param.path]]
        levels = _levels(x_all)
        numeric = _numeric(levels)
        others = [p for p in paths if p != param.path]
        combos = _levels([tuple(values[o][r] for o in others) for r in range(len(x_all))]) if (
            others and not scattered) else [()]
        note = ""
        if len(combos) > len(_STYLES):
            middle = tuple(_levels(values[o])[len(_levels(values[o])) // 2] for o in others)
            combos = [middle]
            note = "others at " + ", ".join(f"{o}={_fmt(v)}" for o, v in zip(others, middle,
                                                                              strict=True))
        fig = _figure(10.0, 7.0)
        axes = fig.subplots(2, 2).ravel()
        for ax, (column, label) in zip(axes, metrics, strict=True):
            y_all = _scaled(table, column)
            for f in filters:
                for k, combo in enumerate(combos):
                    rows = [r for r in range(len(x_all)) if rows_filter[r] == f and (
                        scattered or tuple(values[o][r] for o in others) == combo)]
                    if not rows:
                        continue
                    xs = [x_all[r] for r in rows]
                    pos = np.array(xs, dtype=float) if numeric else np.array(
                        [levels.index(x) for x in xs], dtype=float)
                    order = np.argsort(pos, kind="stable")
                    ys = y_all[rows][order]
                    if scattered:
                        ax.plot(pos[order], ys, "o", color=colours[f], ms=4, label=f)
                    else:
                        ax.plot(pos[order], ys, _STYLES[k], marker="o", ms=3,
                                color=colours[f], label=f if k == 0 else None)
            if column.startswith("rmse_pcrlb_"):
                ax.axhline(1.0, color="0.5", lw=0.8, ls=":")
            if column == "anees":
                ax.axhline(float(n), color="0.5", lw=0.8, ls=":")
            finite = y_all[np.isfinite(y_all)]
            if column != "diverged_share" and finite.size and finite.min() > 0 and (
                    finite.max() / finite.min() > 30):
                ax.set_yscale("log")
            if numeric and all(v > 0 for v in levels) and (
                    param.log or max(levels) / min(levels) >= 20):
                ax.set_xscale("log")
            if not numeric:
                ax.set_xticks(range(len(levels)), [_fmt(v) for v in levels])
            ax.set_xlabel(param.path + (" (factor of the scenario's value)"
                                        if param.relative else ""))
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
        handles, labels = axes[0].get_legend_handles_labels()
        if len(combos) > 1:
            from matplotlib.lines import Line2D

            for k, combo in enumerate(combos):
                handles.append(Line2D([], [], color="0.3", ls=_STYLES[k]))
                labels.append(", ".join(f"{o}={_fmt(v)}" for o, v in zip(others, combo,
                                                                         strict=True)))
        axes[0].legend(handles, labels, fontsize=7)
        title = f"{campaign.base.name}: metrics against {param.path}"
        fig.suptitle(title + (f" ({note})" if note else ""), fontsize=10)
        out[f"lines-{_slug(param.path)}"] = fig
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return v if isinstance(v, str) else json.dumps(v)


def _grid_of(campaign: Any, table: pa.Table) -> tuple[str, str, list, list, list, list] | None:
    """For a grid over two parameters: their paths, each row's values and the levels of
    each (x across, y up); else None."""
    if campaign.design != "grid" or len(campaign.params) != 2:
        return None
    px, py = (p.path for p in campaign.params)
    xs, ys = table.column(px).to_pylist(), table.column(py).to_pylist()
    return px, py, xs, ys, _levels(xs), _levels(ys)


def _matrix(rows_filter: list[str], f: str, xs: list, ys: list, lx: list, ly: list,
            v: np.ndarray) -> np.ndarray:
    m = np.full((len(ly), len(lx)), np.nan)
    for r in range(len(xs)):
        if rows_filter[r] == f:
            m[ly.index(ys[r]), lx.index(xs[r])] = v[r]
    return m


def _own_cell(campaign: Any, lx: list, ly: list) -> tuple[int, int] | None:
    """(row, column) of the base scenario's own setting in the grid, if it is a point."""
    own = [campaign.own_value(p) for p in campaign.params]
    if own[0] in lx and own[1] in ly:
        return ly.index(own[1]), lx.index(own[0])
    return None


def _frame(ax: Any, cell: tuple[int, int] | None) -> None:
    """Outline the scenario's own setting."""
    if cell is not None:
        from matplotlib.patches import Rectangle

        i, j = cell
        ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="k", lw=1.6))


def _label_axes(ax: Any, px: str, py: str, lx: list, ly: list) -> None:
    ax.set_xticks(range(len(lx)), [_fmt(x) for x in lx], fontsize=7)
    ax.set_yticks(range(len(ly)), [_fmt(y) for y in ly], fontsize=7)
    ax.set_xlabel(px, fontsize=8)
    ax.set_ylabel(py, fontsize=8)


def _annotate(ax: Any, m: np.ndarray, norm: Any) -> None:
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            val = m[i, j]
            if math.isfinite(val):
                dark = abs(float(norm(val)) - 0.5) > 0.3  # text on the darker ends
                ax.text(j, i, f"{val:.3g}", ha="center", va="center", fontsize=7,
                        color="w" if dark else "k")


def _plain_ticks(bar: Any) -> None:
    """A colour bar's ticks as numbers (0.5, 2), not powers of ten, on a log scale too."""
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import FuncFormatter, NullFormatter

    if isinstance(bar.norm, LogNorm):  # 1-2-5 in every decade the bar spans
        lo, hi = float(bar.norm.vmin), float(bar.norm.vmax)
        decades = range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
        ticks = [m * 10.0**e for e in decades for m in (1, 2, 5) if lo <= m * 10.0**e <= hi]
        if len(ticks) >= 2:
            bar.set_ticks(ticks)
        bar.ax.yaxis.set_minor_formatter(NullFormatter())
    bar.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))


def heatmap_figures(campaign: Any, table: pa.Table) -> dict[str, Any]:
    """For a grid over two parameters: ``heatmap-METRIC`` -> each metric over the grid, one
    panel per filter (a shared colour scale, logarithmic where the metric spans more than a
    factor 30; the scenario's own setting outlined)."""
    from matplotlib.colors import LogNorm, Normalize

    grid = _grid_of(campaign, table)
    if grid is None:
        return {}
    px, py, xs, ys, lx, ly = grid
    filters = list(dict.fromkeys(table.column("filter").to_pylist()))
    rows_filter = table.column("filter").to_pylist()
    own = _own_cell(campaign, lx, ly)
    ncol = min(len(filters), 4)
    nrow = -(-len(filters) // ncol)
    out = {}
    for column, label in headline_metrics(campaign, table):
        v = _scaled(table, column)
        grids = {f: _matrix(rows_filter, f, xs, ys, lx, ly, v) for f in filters}
        finite = v[np.isfinite(v)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        hi = hi if hi > lo else lo + 1.0
        norm = LogNorm(lo, hi) if lo > 0 and hi / lo > 30 else Normalize(lo, hi)
        fig = _figure(3.2 * ncol + 1.0, 2.8 * nrow + 0.6)
        axes = np.atleast_1d(fig.subplots(nrow, ncol)).ravel()
        image = None
        for ax, f in zip(axes, filters, strict=False):
            image = ax.imshow(grids[f], origin="lower", aspect="auto", cmap="viridis",
                              norm=norm)
            _annotate(ax, grids[f], norm)
            _frame(ax, own)
            _label_axes(ax, px, py, lx, ly)
            ax.set_title(f, fontsize=9)
        for ax in axes[len(filters):]:
            ax.set_visible(False)
        if image is not None:
            _plain_ticks(fig.colorbar(image, ax=list(axes[:len(filters)]), label=label,
                                      shrink=0.9))
        fig.suptitle(f"{campaign.base.name}: {label}"
                     + (" (framed: the scenario's own setting)" if own else ""), fontsize=10)
        out[f"heatmap-{_slug(column)}"] = fig
    return out


def reference_filter(campaign: Any, published: Sequence[PublishedSpec] = ()) -> str:
    """The filter the others are divided by: the published tables' reference filter when the
    campaign has it, else the scenario's first filter."""
    names = [f.name for f in campaign.base.filters]
    for pub in published:
        if pub.versus in names:
            return pub.versus
    return names[0]


def ratio_grids(campaign: Any, table: pa.Table, group: str, versus: str
                ) -> dict[str, np.ndarray]:
    """For a grid over two parameters: each filter's RMSE of ``group`` over the RMSE of
    ``versus`` at the same point (the same truths and measurements), rows along the second
    parameter's levels, columns along the first's; {} for another design."""
    grid = _grid_of(campaign, table)
    if grid is None or f"rmse_{group}" not in table.column_names:
        return {}
    _, _, xs, ys, lx, ly = grid
    rows_filter = table.column("filter").to_pylist()
    v = _column_values(table, f"rmse_{group}")
    ref = _matrix(rows_filter, versus, xs, ys, lx, ly, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        return {f: _matrix(rows_filter, f, xs, ys, lx, ly, v) / ref
                for f in dict.fromkeys(rows_filter) if f != versus}


def _ratio_groups(campaign: Any, published: Sequence[PublishedSpec]) -> list[str]:
    groups = campaign.base.report.groups
    return list(dict.fromkeys([groups[0], *(p.group for p in published if p.group in groups)]))


def ratio_figures(campaign: Any, table: pa.Table, published: Sequence[PublishedSpec] = ()
                  ) -> dict[str, Any]:
    """For a grid over two parameters: ``heatmap-ratio_rmse_GROUP`` -> each filter's RMSE
    over the reference filter's, one panel per filter, on a log colour scale centred at 1
    (blue: better than the reference). Where a published table gives the filter's ratio, a
    dashed contour marks the cells' boundary at the paper's value and the panel's title
    gives it beside ours at the scenario's own setting (framed)."""
    from matplotlib.colors import LogNorm

    grid = _grid_of(campaign, table)
    if grid is None:
        return {}
    px, py, _, _, lx, ly = grid
    versus = reference_filter(campaign, published)
    own = _own_cell(campaign, lx, ly)
    out = {}
    for g in _ratio_groups(campaign, published):
        ratios = ratio_grids(campaign, table, g, versus)
        if not ratios:
            continue
        finite = np.concatenate([m[np.isfinite(m) & (m > 0)] for m in ratios.values()])
        span = max(float(np.max(np.abs(np.log(finite)))), math.log(1.25)) if finite.size else (
            math.log(2.0))
        norm = LogNorm(math.exp(-span), math.exp(span))
        names = list(ratios)
        ncol = min(len(names), 3)
        nrow = -(-len(names) // ncol)
        fig = _figure(3.6 * ncol + 1.0, 3.0 * nrow + 0.7)
        axes = np.atleast_1d(fig.subplots(nrow, ncol)).ravel()
        image = None
        for ax, f in zip(axes, names, strict=False):
            m = ratios[f]
            image = ax.imshow(m, origin="lower", aspect="auto", cmap="RdBu_r", norm=norm)
            _annotate(ax, m, norm)
            _frame(ax, own)
            _label_axes(ax, px, py, lx, ly)
            title = f"{f} / {versus}"
            for pub in published:
                if pub.group != g or pub.versus != versus or f not in pub.rmse:
                    continue
                paper = pub.ratio(f)
                title += f"; paper {paper:.2f}"
                if own is not None and math.isfinite(m[own]):
                    title += f", ours {m[own]:.2f} (framed)"
                ok = np.isfinite(m)
                if m.shape[0] > 1 and m.shape[1] > 1 and ok.all() and (
                        m.min() < paper < m.max()):
                    cs = ax.contour(np.arange(len(lx)), np.arange(len(ly)), m,
                                    levels=[paper], colors="k", linestyles="--",
                                    linewidths=1.2)
                    ax.clabel(cs, fmt={paper: f"paper {paper:.2f}"}, fontsize=7)
            ax.set_title(title, fontsize=8)
        for ax in axes[len(names):]:
            ax.set_visible(False)
        if image is not None:
            _plain_ticks(fig.colorbar(image, ax=list(axes[:len(names)]),
                                      label=f"{g} RMSE / {versus}'s", shrink=0.9))
        fig.suptitle(f"{campaign.base.name}: {g} RMSE over the {versus}'s at each point"
                     + (" (dashed: the paper's ratio)" if published else ""), fontsize=10)
        out[f"heatmap-ratio_rmse_{_slug(g)}"] = fig
    return out


def published_rows(campaign: Any, table: pa.Table, published: Sequence[PublishedSpec]
                   ) -> list[dict[str, Any]]:
    """Each published ratio beside ours over a two-parameter grid: ours at the scenario's
    own setting, the point whose ratio is nearest the paper's, our range over the grid, and
    the points at or below the paper's ratio."""
    grid = _grid_of(campaign, table)
    if grid is None:
        return []
    px, py, _, _, lx, ly = grid
    own = _own_cell(campaign, lx, ly)
    rows = []
    for pub in published:
        ratios = ratio_grids(campaign, table, pub.group, pub.versus)
        for f in pub.filters():
            if f not in ratios:
                continue
            m, paper = ratios[f], pub.ratio(f)
            ok = np.isfinite(m)
            if not ok.any():
                continue

            def at(i: int, j: int) -> str:
                return f"{px}={_fmt(lx[j])}, {py}={_fmt(ly[i])}"

            near = np.unravel_index(np.nanargmin(np.where(ok, np.abs(m - paper), np.nan)),
                                    m.shape)
            lo = np.unravel_index(np.nanargmin(np.where(ok, m, np.nan)), m.shape)
            hi = np.unravel_index(np.nanargmax(np.where(ok, m, np.nan)), m.shape)
            rows.append({
                "ratio": f"{f} / {pub.versus} {pub.group} RMSE", "paper": paper,
                "source": pub.source,
                "own": float(m[own]) if own is not None and ok[own] else None,
                "own_at": at(*own) if own is not None else None,
                "nearest": float(m[near]), "nearest_at": at(*near),
                "min": float(m[lo]), "min_at": at(*lo), "max": float(m[hi]), "max_at": at(*hi),
                "at_or_below": int(np.sum(m[ok] <= paper)), "points": int(ok.sum())})
    return rows


# --- the page -----------------------------------------------------------------------------

# the reports' page and figure styles, and the sweep table's own
_SWEEP_CSS = CSS + """
table.sweep { border-collapse: collapse; margin: 1em 0; font-size: 0.85em; }
table.sweep th, table.sweep td { border-bottom: 1px solid #ddd; padding: 0.25em 0.6em; }
table.sweep td { text-align: right; font-variant-numeric: tabular-nums; }
table.sweep td.text { text-align: left; }
table.sweep thead th { border-bottom: 2px solid #888; text-align: left; }
"""


def _cell(v: Any) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else "n/a"
    return html.escape(str(v))


def _published_html(rows: Sequence[dict[str, Any]]) -> list[str]:
    esc = html.escape
    parts = ["<h2>Beside the published values</h2>",
             '<table class="sweep"><thead><tr><th>ratio</th><th>paper</th>'
             "<th>ours at the scenario's own setting</th><th>ours nearest the paper</th>"
             "<th>ours, lowest</th><th>ours, highest</th><th>points at or below the paper's"
             "</th></tr></thead><tbody>"]
    for r in rows:
        own = "not a point of the grid" if r["own"] is None else (
            f"{r['own']:.3f} ({esc(r['own_at'])})")
        parts.append(
            f'<tr><td class="text">{esc(r["ratio"])}</td><td>{r["paper"]:.3f}</td>'
            f"<td>{own}</td><td>{r['nearest']:.3f} ({esc(r['nearest_at'])})</td>"
            f"<td>{r['min']:.3f} ({esc(r['min_at'])})</td>"
            f"<td>{r['max']:.3f} ({esc(r['max_at'])})</td>"
            f"<td>{r['at_or_below']} of {r['points']}</td></tr>")
    parts.append("</tbody></table>")
    sources = list(dict.fromkeys(r["source"] for r in rows))
    parts.append('<p class="meta">Paper: ' + "; ".join(esc(x) for x in sources) + ". Its "
                 "ratio is its filter's RMSE over its reference filter's; ours is the same at "
                 "each point, over the same runs for every filter. The paper does not give its "
                 "filters' initial Q and R, so no one point is its setting: the table gives "
                 "ours at the scenario's own setting, the point nearest the paper's value and "
                 "the range over the grid.</p>")
    return parts


def render_sweep_html(campaign: Any, table: pa.Table, images: dict[str, Path | bytes],
                      notes: Sequence[str] = (),
                      beside: Sequence[dict[str, Any]] = (),
                      published: Sequence[PublishedSpec] = ()) -> str:
    """The campaign's page: settings, parameters, the headline table, our ratios beside the
    published ones (``beside``, from ``published_rows``) and the figures."""
    from trackkit import __version__
    from trackkit.experiments.checkpoint import code_version

    esc = html.escape
    code = code_version()
    metrics = headline_metrics(campaign, table)
    paths = [p.path for p in campaign.params]
    parts = ["<!DOCTYPE html>", '<html lang="en">', '<head><meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>trackkit sweep: {esc(campaign.base.name)}</title>",
             f"<style>{_SWEEP_CSS}</style></head>", "<body>",
             f"<h1>Sweep: {esc(campaign.base.name)}</h1>"]
    if campaign.base.description:
        parts.append(f"<p>{esc(campaign.base.description)}</p>")
    parts.append(
        f'<p class="meta">{campaign.design} design, {len(campaign.points)} points x '
        f"{campaign.runs} Monte Carlo runs (block {campaign.block}), campaign seed "
        f"{campaign.seed}. trackkit {esc(__version__)}, source {esc(code['source'])}, numpy "
        f"{esc(code['numpy'])}.</p>")
    parts.append("<h2>Parameters</h2><ul>")
    parts += [f"<li><code>{esc(p.path)}</code>: {esc(p.describe())}</li>"
              for p in campaign.params]
    parts.append("</ul>")
    head = ["point", *paths, "filter", *(label for _, label in metrics)]
    parts.append('<h2>Results</h2><table class="sweep"><thead><tr>'
                 + "".join(f"<th>{esc(h)}</th>" for h in head) + "</tr></thead><tbody>")
    cols = {c: table.column(c).to_pylist() for c in ["point", *paths, "filter",
                                                      *(c for c, _ in metrics)]}
    for r in range(table.num_rows):
        cells = [f'<td class="text">{_cell(cols["point"][r])}</td>']
        cells += [f"<td>{_cell(cols[p][r])}</td>" for p in paths]
        cells.append(f'<td class="text">{_cell(cols["filter"][r])}</td>')
        for c, _ in metrics:
            v = cols[c][r]
            if v is not None and c.startswith("rmse_") and not c.startswith("rmse_pcrlb_"):
                unit = json.loads(table.schema.metadata[b"trackkit"])["groups"].get(c[5:], "")
                v = v * display_unit(unit)[1]
            cells.append(f"<td>{_cell(v)}</td>")
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</tbody></table>")
    parts.append('<p class="meta">Every column of every metric group is in sweep.csv and '
                 "sweep.parquet (SI units); each point's full result in "
                 "points/ID/result.json.</p>")
    if beside:
        parts += _published_html(beside)
    all_notes = [
        "Each point's seed is a hash of the campaign seed and the point's values, so adding "
        "points leaves the others' runs unchanged; all filters at a point see the same truths "
        "and measurements.",
        "RMSE / PCRLB and ANEES are averaged over the steps from report.average_from_s; "
        f"ANEES is about n = {campaign.base.state_dim} for a consistent filter.",
        *campaign.notes, *notes]
    parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{esc(n)}</li>" for n in all_notes)
                 + "</ul>")
    if images:
        parts.append("<h2>Figures</h2>")
    for name, png in images.items():
        if name.startswith("lines-"):
            caption = "Headline metrics against " + name[len("lines-"):]
        elif name.startswith("heatmap-ratio_rmse_"):
            caption = (f"{name[len('heatmap-ratio_rmse_'):]} RMSE of each filter over the "
                       f"{reference_filter(campaign, published)}'s at each point (below 1, "
                       "blue: better)" + (
                           "; dashed: the paper's ratio, where ours crosses it" if published
                           else "") + "; framed: the scenario's own setting")
        else:
            caption = "Heat map over the grid: " + name[len("heatmap-"):]
        parts.append(f'<figure><img src="{data_uri(png)}" alt="{esc(name)}">'
                     f"<figcaption>{esc(caption)}</figcaption></figure>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# --- writing ------------------------------------------------------------------------------


def _timings(campaign: Any, timings: Sequence[dict | None]) -> dict:
    return {"units": {"seconds_per_step": "s of filter time per run and step"},
            "points": {p.id: (t or {}).get("seconds_per_step")
                       for p, t in zip(campaign.points, timings, strict=True)}}


def write_sweep_report(campaign: Any, docs: Sequence[dict], out_dir: str | Path,
                       timings: Sequence[dict | None] | None = None,
                       notes: Sequence[str] = (),
                       published: Sequence[PublishedSpec] | None = None) -> dict[str, Path]:
    """Write the campaign's report files into ``out_dir`` (see the module doc), all or
    nothing; figures of an earlier design that this one does not draw are removed.
    ``published``: the published tables to mark (default: the scenario's,
    ``trackkit.report.published``)."""
    table = sweep_table(campaign, docs)
    published = list(campaign.base.report.published if published is None else published)
    rows = published_rows(campaign, table, published)

    def write_all(folder: Path) -> dict[str, Path]:
        written = {"parquet": folder / SWEEP_PARQUET}
        pq.write_table(table, written["parquet"])
        written["csv"] = write_sweep_csv(table, folder / SWEEP_CSV)
        written["json"] = folder / SWEEP_JSON
        written["json"].write_text(json.dumps(campaign.document(), indent=2) + "\n",
                                   encoding="utf-8")
        figures = {**line_figures(campaign, table), **heatmap_figures(campaign, table),
                   **ratio_figures(campaign, table, published)}
        images = {}
        for name, fig in figures.items():
            images[name] = save_figure(fig, folder / f"{name}.png", dpi=_DPI,
                                       metadata={"Software": None})
            written[name] = images[name]
        written["html"] = folder / SWEEP_HTML
        written["html"].write_text(render_sweep_html(campaign, table, images, notes, rows,
                                                     published), encoding="utf-8")
        written["timings"] = write_json(
            _timings(campaign, timings or [None] * len(campaign.points)),
            folder / SWEEP_TIMINGS)
        return written

    return write_atomically(out_dir, write_all, sweep_outputs(out_dir))

"""One self-contained HTML page: scenario, summary table, Naseri Solhdar's J1-J4 and tuning tables
(when the result has them), notes, the PNGs inlined as base64 data URIs and the glossary of
the metrics, with inline CSS and no scripts, so it opens in a browser with no network."""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping
from pathlib import Path

from trackkit import __version__
from trackkit.experiments.results import MonteCarloResult
from trackkit.report.glossary import glossary_html
from trackkit.report.tables import (
    classification_summary,
    gap_summary,
    html_table,
    matching_html_tables,
    summary_html_table,
    window_summaries,
)

__all__ = ["data_uri", "render_html"]

_CAPTIONS = {
    "geometry": "Geometry of one run: truth, observer and estimates with 2-sigma ellipses.",
    "rmse": "RMSE against time; the PCRLB dashed (a lower bound for any unbiased estimator).",
    "nees": "Average NEES (and NIS) against time with the two-sided 95% chi-square bounds.",
    "matching": "Covariance matching in run 0: the diagonals of the measurement noise R in "
                "use, the innovation covariance S, the windowed innovation covariance C (zero "
                "until the window is full) and the degree of matching DOM = S - C, per "
                "measurement channel and filter.",
    "membership": "The tuned fuzzy systems: input sets NM..PM over the normalised DOM, output "
                  "centres IL..DL (the adjustment, in units of the initial noise) and the "
                  "resulting input-output curve.",
    "time": "Run 0 against time: the first state component's truth and each filter's estimate "
            "(top), and the measurements with each filter's pseudo-measurements (bottom); the "
            "gaps shaded.",
    "classes": "Class probability against time (Hosseini, Haeri and Khaloozadeh 2019, Fig. 4): "
               "each classifying "
               "filter's probability of the true class, mean over runs with the 10-90th "
               "percentile band (or, without a true class, the mean probability of each "
               "class).",
    "convergence": "Optimiser convergence: best-so-far DOM cost against iteration, median over "
                   "the independent runs with the min-max band.",
}

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1100px; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
.meta { color: #555; margin-top: 0; }
table.summary { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
table.summary caption { caption-side: bottom; color: #555; padding-top: 0.4em; text-align: left; }
table.summary th, table.summary td { border-bottom: 1px solid #ddd; padding: 0.3em 0.7em; }
table.summary td { text-align: right; font-variant-numeric: tabular-nums; }
table.summary th { text-align: left; }
table.summary thead th { border-bottom: 2px solid #888; }
table.summary tr.bound { font-style: italic; color: #555; }
table.summary tr.section-end th,
table.summary tr.section-end td { border-bottom: 1px solid #888; }
h3 { font-size: 1.05em; margin-bottom: 0.2em; }
figure { margin: 1.5em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { color: #555; font-size: 0.9em; }
dl.glossary dt { font-weight: bold; margin-top: 0.6em; }
dl.glossary dd { margin-left: 1.5em; color: #333; }
"""


def data_uri(png: str | Path | bytes) -> str:
    """A ``data:image/png;base64,...`` URI of a PNG file (path) or of PNG bytes."""
    raw = png if isinstance(png, bytes) else Path(png).read_bytes()
    return "data:image/png;base64," + base64.b64encode(raw).decode("ascii")


def notes_and_figures(notes: list[str], images: Mapping[str, str | Path | bytes],
                      captions: Mapping[str, str]) -> list[str]:
    """The "Notes" list and the "Figures" (inlined PNGs with their captions) of a page."""
    esc = html.escape
    parts = []
    if notes:
        parts.append("<h2>Notes</h2>\n<ul>")
        parts += [f"<li>{esc(n)}</li>" for n in notes]
        parts.append("</ul>")
    if images:
        parts.append("<h2>Figures</h2>")
    for name, png in images.items():
        parts.append(f'<figure><img src="{data_uri(png)}" alt="{esc(name)}">'
                     f"<figcaption>{esc(captions.get(name, name))}</figcaption></figure>")
    return parts


def _bound_rows(table: str, filters: int) -> str:
    """Mark the rows after the ``filters`` filter rows (the PCRLB) as the bound, as the
    summary table does."""
    lines = table.split("\n")
    rows = [i for i, line in enumerate(lines) if line.startswith("<tr")]
    for i in rows[filters:]:
        lines[i] = lines[i].replace("<tr>", '<tr class="bound">', 1)
    return "\n".join(lines)


def render_html(result: MonteCarloResult, images: Mapping[str, str | Path | bytes]) -> str:
    """The report page for ``result`` with ``images`` (figure name -> PNG path or bytes)."""
    esc = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        '<head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>trackkit: {esc(result.scenario)}</title>",
        f"<style>{CSS}</style></head>",
        "<body>",
        f"<h1>{esc(result.scenario)}</h1>",
    ]
    if result.description:
        parts.append(f"<p>{esc(result.description)}</p>")
    parts.append(f'<p class="meta">{result.runs} Monte Carlo runs, seed {result.seed}, '
                 f"{result.steps} steps of {result.dt:g} s. "
                 f"Generated by trackkit {__version__}.</p>")
    parts += ["<h2>Summary</h2>", html_table(result)]
    windows = window_summaries(result)
    if windows:
        parts.append("<h2>Error windows</h2>")
    for w in windows:
        parts += [f"<h3>{esc(w.title)}</h3>", _bound_rows(summary_html_table(w),
                                                           len(result.filters))]
    extra = matching_html_tables(result)
    if extra:
        parts.append("<h2>Naseri Solhdar metrics and tuning</h2>")
    for title, table in extra:
        parts += [f"<h3>{esc(title)}</h3>", table]
    gap = gap_summary(result)
    if gap is not None:
        parts += [f"<h2>{esc(gap.title)}</h2>", summary_html_table(gap)]
    classes = classification_summary(result)
    if classes is not None:
        parts += [f"<h2>{esc(classes.title)}</h2>", summary_html_table(classes)]
    parts += notes_and_figures(result.notes, images, _CAPTIONS)
    parts += ["<h2>Glossary</h2>", glossary_html()]
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)

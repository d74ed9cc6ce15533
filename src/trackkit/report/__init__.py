"""Report: summary tables, figures, results.json, metrics.parquet and a self-contained HTML page.

    from trackkit.report import write_report, rich_table
    paths = write_report(result, "out/")       # result: trackkit.eval.results.MonteCarloResult
    rich.print(rich_table(result))
"""

from trackkit.report.files import (
    metrics_table,
    results_document,
    write_metrics_parquet,
    write_report,
    write_results_json,
)
from trackkit.report.html import render_html
from trackkit.report.plots import make_plots, plot_geometry, plot_nees, plot_rmse
from trackkit.report.tables import display_unit, html_table, rich_table, summary

__all__ = [
    "write_report", "write_results_json", "write_metrics_parquet", "metrics_table",
    "results_document", "render_html", "make_plots", "plot_geometry", "plot_rmse", "plot_nees",
    "display_unit", "summary", "rich_table", "html_table",
]

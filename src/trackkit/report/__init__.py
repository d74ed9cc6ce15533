"""Report: summary tables, figures, results.json, metrics.parquet and a self-contained HTML page.

Typical use::

    from trackkit.report import write_report, rich_table
    paths = write_report(result, "out/")       # result: experiments.results.MonteCarloResult
    rich.print(rich_table(result))
    for table in matching_rich_tables(result):   # Naseri Solhdar's J1-J4 / tuning tables, if any
        rich.print(table)
"""

from trackkit.report.files import (
    metrics_table,
    results_document,
    write_metrics_parquet,
    write_report,
    write_results_json,
)
from trackkit.report.html import render_html
from trackkit.report.plots import (
    make_plots,
    plot_convergence,
    plot_geometry,
    plot_matching,
    plot_membership,
    plot_nees,
    plot_rmse,
)
from trackkit.report.tables import (
    display_unit,
    html_table,
    matching_html_tables,
    matching_rich_tables,
    matching_summaries,
    matching_summary,
    matching_values,
    rich_table,
    summary,
    tuning_summary,
)

__all__ = [
    "write_report", "write_results_json", "write_metrics_parquet", "metrics_table",
    "results_document", "render_html", "make_plots", "plot_geometry", "plot_rmse", "plot_nees",
    "plot_matching", "plot_membership", "plot_convergence",
    "display_unit", "summary", "rich_table", "html_table", "matching_values",
    "matching_summary", "tuning_summary", "matching_summaries", "matching_rich_tables",
    "matching_html_tables",
]

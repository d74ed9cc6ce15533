"""Summary tables: values, units at the edge (radians shown once as degrees), layouts."""

from __future__ import annotations

import io
import math

from rich.console import Console

from trackkit.report.tables import display_unit, html_table, rich_table, summary

from . import FILTERS, fake_result


def _render(table, width: int) -> str:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(table)
    return console.export_text()


def test_display_unit_converts_angles_only():
    assert display_unit("rad") == ("deg", 180 / math.pi)
    assert display_unit("rad/s")[0] == "deg/s"
    for unit in ("m", "m/s", "Hz", "s"):
        assert display_unit(unit) == (unit, 1.0)


def test_summary_values_and_units():
    r = fake_result()
    s = summary(r)
    col = {h: i for i, h in enumerate(s.headers)}
    assert "RMSE position\n[m]" in col and "RMSE velocity\n[m/s]" in col
    assert "RMSE course\n[deg]" in col  # rad -> deg in the header ...
    rows = {row[0]: row for row in s.rows}
    assert list(rows) == [*FILTERS, "PCRLB"]
    ekf = r.filters["EKF"]
    # ... and the values converted exactly once (not for metre groups)
    assert float(rows["EKF"][col["RMSE course\n[deg]"]]) == float(
        f"{math.degrees(ekf.rmse_mean['course']):.4g}")
    assert float(rows["EKF"][col["RMSE position\n[m]"]]) == float(
        f"{ekf.rmse_mean['position']:.4g}")
    assert float(rows["PCRLB"][col["RMSE course\n[deg]"]]) == float(
        f"{math.degrees(r.pcrlb_mean['course']):.4g}")
    # efficiency is unit-free: same value whatever the display unit
    eff = float(rows["UKF"][col["RMSE/PCRLB\ncourse"]])
    assert eff == round(r.efficiency("UKF", "course"), 2)
    assert rows["UKF"][col["diverged\nruns"]] == f"1/{r.runs}"
    assert rows["UKF"][col["NEES in\n95% bounds"]] == "50%"
    assert rows["EKF"][col["time\nper step"]] == "3 µs"
    assert rows["EKF"][col["ANEES"]] == f"{ekf.anees:.3g}"
    assert "averages over t = 20 to 98 s (40 steps)" in s.caption


def test_summary_without_bound_and_nan_values():
    r = fake_result()
    r.pcrlb, r.pcrlb_mean = {}, {}
    r.filters["EKF"].anis = float("nan")
    s = summary(r)
    assert [row[0] for row in s.rows] == list(FILTERS)  # no PCRLB row
    assert not any(h.startswith("RMSE/PCRLB") for h in s.headers)
    assert s.rows[0][s.headers.index("ANIS")] == "n/a"


def test_rich_table_wide_and_transposed():
    r = fake_result()
    wide = _render(rich_table(r, width=200), 200)
    assert "[deg]" in wide and "[m/s]" in wide and "PCRLB" in wide
    assert all(name in wide for name in FILTERS)
    header_line = next(line for line in wide.splitlines() if "RMSE position" in line)
    assert "diverged" in header_line  # one row per filter: metrics across
    narrow = _render(rich_table(r, width=70), 70)
    assert max(len(line.rstrip()) for line in narrow.splitlines()) <= 70
    assert "RMSE course [deg]" in narrow  # one row per metric, filters and PCRLB across
    filters_line = next(line for line in narrow.splitlines() if "metric" in line)
    assert filters_line.split() == ["metric", *FILTERS, "PCRLB"]


def test_html_table_is_escaped_markup():
    r = fake_result()
    r.filters["<b>EKF</b>"] = r.filters.pop("EKF")
    out = html_table(r)
    assert out.startswith('<table class="summary">') and out.rstrip().endswith("</table>")
    assert "&lt;b&gt;EKF&lt;/b&gt;" in out and "<b>" not in out
    assert "RMSE course<br>[deg]" in out
    assert out.count("<tr") == 1 + len(r.filters) + 1  # header, filters, PCRLB
    assert '<tr class="bound"><th>PCRLB</th>' in out


def test_summary_ranks_the_filters_by_rmse_over_the_bound():
    """The rank column orders the filters by the first bounded group's RMSE/PCRLB (1 the
    best), rows staying in the scenario's order; without a bound, by the first group's RMSE."""
    from trackkit.report.tables import ranks

    r = fake_result()
    s = summary(r)
    col = s.headers.index("rank")
    g = next(g for g in r.groups if math.isfinite(r.pcrlb_mean.get(g, math.nan)))
    by_efficiency = sorted(r.filters, key=lambda n: r.efficiency(n, g))
    got = {row[0]: row[col] for row in s.rows}
    assert [got[n] for n in by_efficiency] == [str(i + 1) for i in range(len(by_efficiency))]
    assert got["PCRLB"] == ""
    r.pcrlb, r.pcrlb_mean = {}, {}
    first = next(iter(r.groups))
    assert sorted(ranks(r), key=ranks(r).get) == sorted(
        r.filters, key=lambda n: r.filters[n].rmse_mean[first])

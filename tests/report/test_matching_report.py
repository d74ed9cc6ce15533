"""The report sections of Naseri Solhdar's scenarios: the J1-J4 tables (Monte Carlo mean and run 0),
the tuning table, the covariance-matching, membership-function and convergence figures, their place
in report.html and in the terminal, and their absence for a scenario without them."""

from __future__ import annotations

import base64
import io
import re
import shutil

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

from trackkit import cli
from trackkit.cli import stages
from trackkit.filters.fuzzy import INPUT_SETS, OUTPUT_SETS, fis
from trackkit.report import files, plots, tables
from trackkit.report.html import render_html

from . import fake_result
from .test_plots import png_size

NEW_FIGURES = ("matching", "membership", "convergence")


def _run(name: str, runs: int, cheap_tuning: bool = False):
    scenario = pytest.importorskip("trackkit.scenario")
    from trackkit.experiments.compare import compare

    data = scenario.load(name).model_dump()
    if cheap_tuning:
        for f in data["filters"]:
            if f.get("tune"):
                f["tune"].update(runs=2, iterations=3, population=10)
    return compare(scenario.parse(data, name), runs=runs)


@pytest.fixture(scope="module")
def uw():
    """uw-ch3-r (KF and three tuned OFKFs) with cheap tuning and 6 runs."""
    return _run("uw-ch3-r", runs=6, cheap_tuning=True)


@pytest.fixture(scope="module")
def uw_report(uw, tmp_path_factory):
    out = tmp_path_factory.mktemp("uw") / "report"
    return out, files.write_report(uw, out)


@pytest.fixture(scope="module")
def plain():
    """bo-cv: no matching metrics, nothing tuned."""
    return _run("bo-cv", runs=3)


def _render(renderable, width: int = 120) -> str:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(renderable)
    return console.export_text()


def _pick(a, which: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a.mean(0) if which == "mean" else a[0]


# --- number format -----------------------------------------------------------------------


@pytest.mark.parametrize("value, text", [
    (0.30912, "0.3091"), (2.97619, "2.976"), (3.0, "3.000"), (42.2233, "42.22"),
    (12947.0, "12950"), (1246.0, "1246"), (0.0, "0"), (-0.81214, "-0.8121"),
    (0.0050699, "0.005070"), (0.0113, "0.01130"), (999.96, "1000"), (999999.0, "1.000e+06"),
    (1.5e-6, "1.500e-06"), (2.5e7, "2.500e+07"), (float("nan"), "n/a"),
    (float("inf"), "n/a")])
def test_short_is_four_significant_digits(value, text):
    assert tables.short(value) == text


# --- the J1-J4 tables ----------------------------------------------------------------------


@pytest.mark.parametrize("which", ["mean", "run0"])
def test_matching_table_rows_columns_and_values(uw, which):
    s = tables.matching_summary(uw, which)
    names = list(uw.filters)
    assert s.headers == ["criterion", *names]
    labels = [row[0] for row in s.rows]
    assert labels == ["J1-Z1", "J1-Z2", "J2-Z1", "J2-Z2", "J3-X1", "J3-X2", "J3-X3",
                      "J4 (alpha 1000)"]
    assert s.sections == [1, 3, 6]  # J1 | J2 | J3 | J4
    expected = {}
    for col, name in enumerate(names, start=1):
        j = uw.filters[name].matching
        values = [*_pick(uw.j1, which), *_pick(j["J2"], which), *_pick(j["J3"], which),
                  float(_pick(j["J4"], which))]
        expected[name] = values
        for row, value in zip(s.rows, values, strict=True):
            assert row[col] == tables.short(value)
            assert float(row[col]) == pytest.approx(value, rel=6e-4)
    # J1 is the raw measurement noise: the same in every filter's column
    for row in s.rows[:2]:
        assert len(set(row[1:])) == 1
    # the numbers are those of results.json ("J": mean and run 0 per filter)
    doc = uw.to_json_dict()
    for name in names:
        js = doc["J"][name]
        flat = [*doc["J1"][which], *js["J2"][which], *js["J3"][which], js["J4"][which]]
        np.testing.assert_allclose(expected[name], flat, rtol=1e-12)
    assert ("over 6 runs" in s.title) if which == "mean" else ("run 0" in s.title)


def test_matching_values_are_the_arrays(uw):
    labels, names, values = tables.matching_values(uw, "run0")
    assert values.shape == (len(labels), len(names))
    kf = uw.filters["KF"].matching
    np.testing.assert_array_equal(values[2:4, 0], kf["J2"][0])
    np.testing.assert_array_equal(values[4:7, 0], kf["J3"][0])
    assert values[-1, 0] == kf["J4"][0]
    with pytest.raises(ValueError, match="which"):
        tables.matching_values(uw, "median")


def test_tuning_table(uw):
    s = tables.tuning_summary(uw)
    assert s.headers == ["filter", "optimizer", "runs", "population\nx iterations", "BEST",
                         "MEAN", "WORST", "seconds"]
    assert [row[0] for row in s.rows] == list(uw.tuning) == ["GAFKF", "PSOFKF", "OFKF"]
    for row in s.rows:
        t = uw.tuning[row[0]]
        assert row[1:4] == [t.optimizer, "2", "10 x 3"]
        best, mean, worst = map(float, row[4:7])
        assert best <= mean <= worst
        assert row[4:7] == [tables.short(t.best), tables.short(t.mean), tables.short(t.worst)]
        assert best == pytest.approx(t.best, rel=6e-4)
        assert mean == pytest.approx(t.mean, rel=6e-4)
        assert worst == pytest.approx(t.worst, rel=6e-4)
        assert float(row[7]) == pytest.approx(t.seconds, rel=6e-3)
    assert [r[1] for r in s.rows] == ["GA", "PSO", "ICA"]


def test_rich_tables_in_order(uw):
    out = [_render(t) for t in tables.matching_rich_tables(uw)]
    assert len(out) == 3
    assert "Monte Carlo mean over 6 runs" in out[0] and "run 0" in out[1]
    assert "Tuning" in out[2] and "WORST" in out[2]
    for text in out[:2]:
        header = next(line for line in text.splitlines() if "criterion" in line)
        assert header.split() == ["criterion", *uw.filters]
        assert "J4 (alpha 1000)" in text and "J3-X3" in text


def test_state_labels_3d_and_generic():
    r = fake_result(runs=5)
    rng = np.random.default_rng(1)
    r.example.observer = np.column_stack([r.example.observer, np.zeros(r.steps)])  # 3-D
    r.j1 = rng.random((5, 4))
    for f in r.filters.values():
        f.matching = {"J2": rng.random((5, 4)), "J3": rng.random((5, 6)), "J4": rng.random(5)}
    labels, names, values = tables.matching_values(r, "mean")
    assert labels == ["J1-Z1", "J1-Z2", "J1-Z3", "J1-Z4", "J2-Z1", "J2-Z2", "J2-Z3", "J2-Z4",
                      "J3-x [m]", "J3-y [m]", "J3-z [m]", "J3-vx [m/s]", "J3-vy [m/s]",
                      "J3-vz [m/s]", "J4 (alpha 1000)"]
    np.testing.assert_allclose(values[8:14, 1], r.filters["UKF"].matching["J3"].mean(0))
    r.example.observer = r.example.observer[:, :2]  # 2-D: a 6-state is not [x, y, z, v...]
    assert [lab for lab in tables.matching_values(r)[0] if lab.startswith("J3")] == [
        f"J3-X{j}" for j in range(1, 7)]


# --- figures and report.html -------------------------------------------------------------------


def test_report_writes_and_embeds_the_new_figures(uw, uw_report):
    out, paths = uw_report
    for name in NEW_FIGURES:
        assert paths[name] == out / plots.PLOT_FILES[name]
        width, height = png_size(paths[name])
        assert width >= 600 and height >= 400
    page = paths["html"].read_text(encoding="utf-8")
    uris = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)" alt="([a-z]+)"', page)
    embedded = {alt: base64.b64decode(uri) for uri, alt in uris}
    # a given (x1, x2, x3) state has no plan view: the time plot stands in for the geometry
    assert set(embedded) == {"time", "rmse", "nees", *NEW_FIGURES}
    for name in NEW_FIGURES:
        assert embedded[name] == paths[name].read_bytes()
    assert "<h2>Naseri Solhdar metrics and tuning</h2>" in page
    assert "<h3>Naseri Solhdar metrics: Monte Carlo mean over 6 runs</h3>" in page
    assert "<h3>Tuning of the fuzzy systems (off-line)</h3>" in page
    assert page.index("<h2>Summary</h2>") < page.index("Naseri Solhdar metrics") < page.index(
        "<h2>Figures</h2>")
    assert "<th>J3-X2</th>" in page and "<th>J4 (alpha 1000)</th>" in page
    s = tables.matching_summary(uw, "run0")
    kf = s.headers.index("KF")
    assert f"<th>J1-Z2</th>{''.join(f'<td>{c}</td>' for c in s.rows[1][1:])}" in page
    assert s.rows[-1][kf] in page


def test_matching_figure_plots_the_logs(uw):
    fig = plots.matching_figure(uw)
    logs = uw.example.logs
    m = 2
    assert len(fig.axes) == 4 * m
    axes = np.array(fig.axes).reshape(m, 4)
    for i in range(m):
        for j, key in enumerate(("R", "S", "C", "DOM")):
            lines = {ln.get_label(): ln for ln in axes[i, j].get_lines()}
            for name in uw.filters:
                np.testing.assert_array_equal(lines[name].get_ydata(), logs[name][key][:, i])
        assert axes[i, 3].get_yscale() == "linear"  # DOM changes sign
    assert axes[0, 0].get_ylabel().startswith("Z1") and axes[1, 0].get_ylabel().startswith("Z2")


def test_membership_figure_curve_is_the_fuzzy_system(uw):
    fig = plots.membership_figure(uw)
    assert len(fig.axes) == 3 * len(uw.tuning)
    for k, (name, t) in enumerate(uw.tuning.items()):
        a_in, a_out, a_xy = fig.axes[3 * k: 3 * k + 3]
        texts = {x.get_text() for x in a_in.texts}
        assert set(INPUT_SETS) <= texts
        assert set(OUTPUT_SETS) <= {x.get_text() for x in a_out.texts}
        curve = next(ln for ln in a_xy.get_lines() if ln.get_label() == "y(x)")
        np.testing.assert_allclose(curve.get_ydata(), fis(t.params, curve.get_xdata()))
        assert name in a_in.get_title()


def test_convergence_figure_median_and_band(uw):
    fig = plots.convergence_figure(uw)
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert len(lines) == len(uw.tuning)
    for line, t in zip(lines, uw.tuning.values(), strict=True):
        np.testing.assert_allclose(line.get_ydata(), np.median(t.history, axis=1))
        np.testing.assert_array_equal(line.get_xdata(), np.arange(t.iterations + 1))
    assert len(ax.collections) == len(uw.tuning)  # one min-max band each


def test_convergence_tolerates_infinite_costs(uw, tmp_path):
    t = next(iter(uw.tuning.values()))
    history = t.history
    try:
        t.history = np.array(history, dtype=float)
        t.history[0, :] = np.inf  # a candidate whose filter blew up
        path = plots.plot_convergence(uw, tmp_path / "c.png")
        png_size(path)
    finally:
        t.history = history


def test_cli_prints_the_tables_after_the_summary(uw, uw_report, tmp_path, monkeypatch):
    monkeypatch.setattr(stages, "load", lambda name: type("S", (), {"name": name, "run": None}))
    monkeypatch.setattr(stages, "run", lambda scenario, **kw: uw)
    monkeypatch.setattr(stages, "write", lambda result, out: uw_report[1])  # written already
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    res = CliRunner().invoke(cli.app, ["run", "uw", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert text.index("trackkit: uw-ch3-r") < text.index("Monte Carlo mean over 6 runs") \
        < text.index("run 0 (one fixed-seed run") < text.index("Tuning of the fuzzy systems")
    assert "J2-Z1" in text and "BEST" in text


# --- a scenario without matching data --------------------------------------------------------


def test_no_new_sections_without_matching(plain, tmp_path):
    assert plain.j1 is None and not plain.tuning
    assert tables.matching_values(plain) is None
    assert tables.matching_summaries(plain) == [] and tables.matching_rich_tables(plain) == []
    assert tables.tuning_summary(plain) is None
    for name in NEW_FIGURES:
        assert getattr(plots, f"{name}_figure")(plain) is None
    paths = files.write_report(plain, tmp_path / "out")
    assert not set(NEW_FIGURES) & set(paths)
    assert not any((tmp_path / "out" / plots.PLOT_FILES[n]).exists() for n in NEW_FIGURES)
    page = paths["html"].read_text(encoding="utf-8")
    assert "Naseri Solhdar" not in page and "<h3>" not in page


def test_stale_figures_removed_when_rewritten_without_matching(uw_report, plain, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(uw_report[0], out)
    assert (out / "membership.png").exists()
    files.write_report(plain, out)
    assert not any((out / plots.PLOT_FILES[n]).exists() for n in NEW_FIGURES)


def test_html_without_images_still_has_tables(uw):
    page = render_html(uw, {})
    assert page.count('<table class="summary">') == 4  # summary, mean, run 0, tuning

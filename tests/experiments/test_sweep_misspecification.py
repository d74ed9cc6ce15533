"""Mis-specifying every filter at once (``filters.*.PATH=xF``): every filter's value is its own
times the factor, the true R where a filter has none; the truth and the draws stay those of
the scenario; and the report draws each filter's heat maps and the ratio to the EKF with the
paper's ratio marked beside ours.

The campaign is a 2 x 2 grid (q x1, x100; R x0.1, x1) over the five filters of a 300 s
``dbt-receding``, 4 runs per point: a few seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackkit.experiments.checkpoint import CampaignStore
from trackkit.experiments.montecarlo import combine, run_blocks, with_run
from trackkit.experiments.sweep import (
    factor_of,
    parse_param,
    plan_campaign,
    point_document,
    run_campaign,
)
from trackkit.report.sweep_report import (
    heatmap_figures,
    published_rows,
    ratio_figures,
    ratio_grids,
    sweep_table,
    write_sweep_report,
)
from trackkit.scenario import load, parse
from trackkit.scenario.schema import PublishedSpec

from .test_sweep import short_bo_cv

FILTERS = ["EKF", "UKF", "AEKF", "MCEKF", "AMCEKF"]
#: the true R of the DBT scenarios: (2 deg)^2 in rad^2 and (0.3 Hz)^2
TRUE_R = [math.radians(2.0) ** 2, 0.3**2]
GRID = ("filters.*.motion.q=x1,x100", "filters.*.r0_diag_si=x0.1,x1")


def short_dbt(name: str = "dbt-receding"):
    d = load(name).model_dump()
    d["time"]["duration_s"] = 300.0
    d["report"]["average_from_s"] = 100.0
    d["report"]["windows"] = {"early": [100.0, 200.0], "late": [200.0, 300.0]}
    d["run"] = {"runs": 4, "seed": 5, "block": 4}
    return parse(d)


def without_filters(s) -> dict:
    d = s.model_dump()
    for k in ("filters", "run"):
        d.pop(k)
    return d


@pytest.fixture(scope="module")
def campaign():
    return plan_campaign(short_dbt(), [parse_param(p) for p in GRID])


@pytest.fixture(scope="module")
def docs(campaign, tmp_path_factory):
    store = CampaignStore(tmp_path_factory.mktemp("misspecified"))
    store.open(campaign.identity())
    return run_campaign(campaign, store)


# --- what a point's scenario holds ------------------------------------------------------------


def test_a_factor_sets_every_filters_value_times_its_own(campaign):
    base = short_dbt()
    assert [f.name for f in base.filters] == FILTERS
    assert all(f.r0_diag_si is None and f.motion.q == 1e-4 for f in base.filters)
    assert len(campaign.points) == 4
    for p in campaign.points:
        fq = factor_of(p.values["filters.*.motion.q"])
        fr = factor_of(p.values["filters.*.r0_diag_si"])
        assert {fq, fr} <= {1.0, 100.0, 0.1}
        for f in p.scenario.filters:
            assert f.motion.q == pytest.approx(1e-4 * fq, rel=1e-15)
            assert f.r0_diag_si == pytest.approx([fr * r for r in TRUE_R], rel=1e-12)
        # the truth, the sensor and the prior are the scenario's; so are the draws
        assert without_filters(p.scenario) == without_filters(base)
    assert len({p.seed for p in campaign.points}) == 1
    assert sorted(p.values["filters.*.motion.q"] for p in campaign.points) == [
        "x1", "x1", "x100", "x100"]


def test_a_factor_multiplies_a_filters_own_r0_and_the_targets_q_where_it_has_none():
    # the mis-specified variant believes R at half the truth: x2 gives the true R
    c = plan_campaign(load("dbt-approaching-misspecified"),
                      [parse_param("filters.*.r0_diag_si=x2")], runs=2)
    for f in c.points[0].scenario.filters:
        assert f.r0_diag_si == pytest.approx(TRUE_R, rel=1e-7)
    # bo-cv's filters have no motion of their own: the base is the target's q (1e-4)
    c = plan_campaign(short_bo_cv(), [parse_param("filters.*.motion.q=*10")], runs=2)
    s = c.points[0].scenario
    assert s.target.motion.q == 1e-4
    for f in s.filters:
        assert f.motion.model == "ConstantVelocity" and f.motion.q == pytest.approx(1e-3)
    assert c.points[0].values == {"filters.*.motion.q": "x10"}  # one spelling
    # a factor on the truth moves the filters' true R with it
    c = plan_campaign(short_dbt(), [parse_param("sensor.sigma_hz=x2"),
                                    parse_param("filters.*.r0_diag_si=x1")], runs=2)
    for f in c.points[0].scenario.filters:
        assert f.r0_diag_si == pytest.approx([TRUE_R[0], 4 * TRUE_R[1]], rel=1e-12)


def test_x1_everywhere_is_the_scenario_itself_bit_for_bit(tmp_path):
    s = short_dbt()
    c = plan_campaign(s, [parse_param("filters.*.motion.q=x1"),
                          parse_param("filters.*.r0_diag_si=x1")])
    store = CampaignStore(tmp_path)
    store.open(c.identity())
    (doc,) = run_campaign(c, store)
    point = c.points[0]
    plain = with_run(s, None, point.seed)
    ref, _ = point_document(point, combine(plain, run_blocks(plain, [0])))
    for name in FILTERS:
        assert doc["filters"][name]["rmse"] == ref["filters"][name]["rmse"], name


@pytest.mark.parametrize("param, words", [
    ("filters.*.motion.q=x0.1,1e-3", ["filters.*.motion.q", "mixes factors (x0.1)",
                                      "(0.001)", "all factors"]),
    ("filters.*.motion.q=x0", ["'x0'", "filters.*.motion.q", "finite number > 0"]),
    ("filters.*.motion.q=*abc", ["'*abc'", "factor xF or *F"]),
    ("filters.*.motion.q=x0.1:10", ["'x0.1:10'", "never a range"]),
    ("filters.*.motion.model=x2", ["filters.EKF.motion.model = ConstantVelocity",
                                   "multiplies a number or a list"]),
    ("filters.*.prior.mean=x2", ["filters.EKF.prior.mean is not set", "(x2)"]),
    ("time.*.step_s=x2", ["time is not a list", "* (every item)"]),
    ("*.q=x2", ["*.q begins with *", "filters.*.motion.q"]),
    ("filters.*.motion.q=x1e200", ["filters.*.motion.q", "1e+196"]),
])
def test_bad_factors_name_the_field_the_value_and_what_is_allowed(param, words):
    with pytest.raises(ValueError) as err:
        plan_campaign(short_dbt(), [parse_param(param)], runs=2)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_a_field_set_by_two_parameters_is_refused():
    with pytest.raises(ValueError, match=r"filters\.AMCEKF\.motion\.q, which filters\.\*\.motion"
                       r"\.q .* sets too"):
        plan_campaign(short_dbt(), [parse_param("filters.*.motion.q=x10"),
                                    parse_param("filters.AMCEKF.motion.q=1e-3")], runs=2)


# --- the report -------------------------------------------------------------------------------


def test_the_ratio_to_the_ekf_is_each_filters_rmse_over_the_ekfs_at_the_point(campaign, docs):
    table = sweep_table(campaign, docs)
    assert table.column("filters.*.motion.q").to_pylist()[:5] == ["x1"] * 5
    ratios = ratio_grids(campaign, table, "position", "EKF")
    assert list(ratios) == ["UKF", "AEKF", "MCEKF", "AMCEKF"]
    for d in docs:  # rows: R factor x0.1, x1; columns: q factor x1, x100
        i = ["x0.1", "x1"].index(d["values"]["filters.*.r0_diag_si"])
        j = ["x1", "x100"].index(d["values"]["filters.*.motion.q"])
        f = d["filters"]
        assert ratios["AMCEKF"][i, j] == f["AMCEKF"]["rmse"]["position"] / (
            f["EKF"]["rmse"]["position"])
    # mis-specification changes the filters' numbers, not the bound: one truth everywhere
    assert len({d["pcrlb"]["position"] for d in docs}) == 1
    assert len({d["filters"]["EKF"]["rmse"]["position"] for d in docs}) == 4


def test_the_table_has_each_windows_metrics(campaign, docs):
    table = sweep_table(campaign, docs).to_pylist()
    assert len(table) == len(docs) * len(FILTERS)
    for row in table:
        (d,) = [d for d in docs if d["point"] == row["point"]]
        for w in ("early", "late"):
            win = d["windows"][w]
            f = win["filters"][row["filter"]]
            assert row[f"rmse_position_{w}"] == f["rmse"]["position"]
            assert row[f"pcrlb_position_{w}"] == win["pcrlb"]["position"]
            assert row[f"rmse_pcrlb_position_{w}"] == f["rmse_over_pcrlb"]["position"]
            assert row[f"anees_{w}"] == f["anees"]
        # the windows are parts of the averaging span, not copies of it
        assert row["rmse_position_early"] != row["rmse_position_late"]
    schema = sweep_table(campaign, docs).schema
    assert schema.field("rmse_position_late").metadata == {b"unit": b"m"}
    assert schema.field("anees_late").metadata == {b"unit": b"1"}


def test_the_report_draws_every_filters_heat_maps_and_marks_the_papers_ratio(campaign, docs,
                                                                            tmp_path):
    table = sweep_table(campaign, docs)
    heat = heatmap_figures(campaign, table)["heatmap-rmse_pcrlb_position"]
    titles = [ax.get_title() for ax in heat.axes if ax.get_visible() and ax.get_title()]
    assert titles == FILTERS
    ticks = [t.get_text() for t in heat.axes[0].get_xticklabels()]
    assert ticks == ["x1", "x100"]

    # a dashed contour where our ratio crosses the paper's, none where it does not
    m = ratio_grids(campaign, table, "position", "EKF")["AMCEKF"]
    assert np.isfinite(m).all() and m.min() < m.max()
    inside = float(np.sqrt(m.min() * m.max()))
    ekf = 40.0
    crossing = PublishedSpec(versus="EKF", rmse={"EKF": ekf, "AMCEKF": inside * ekf},
                             source="test")
    beyond = PublishedSpec(versus="EKF", rmse={"EKF": ekf, "AMCEKF": 0.5 * m.min() * ekf},
                           source="test")
    for pub, contours in [(crossing, 1), (beyond, 0)]:
        fig = ratio_figures(campaign, table, [pub])["heatmap-ratio_rmse_position"]
        (ax,) = [a for a in fig.axes if a.get_title().startswith("AMCEKF / EKF")]
        assert f"paper {pub.ratio('AMCEKF'):.2f}" in ax.get_title()
        labels = [t.get_text() for t in ax.texts if t.get_text().startswith("paper")]
        assert len(labels) == contours
        assert (len(ax.collections) > 0) == bool(contours)

    out = tmp_path / "report"
    out.mkdir()
    paths = write_sweep_report(campaign, docs, out)
    assert {"heatmap-rmse_pcrlb_position", "heatmap-ratio_rmse_position",
            "heatmap-rmse_position"} <= set(paths)
    page = (out / "report.html").read_text(encoding="utf-8")
    (paper,) = load("dbt-receding").report.published
    assert paper.ratio("AMCEKF") == pytest.approx(41.3 / 87.36)
    assert "Beside the published values" in page and "AMCEKF / EKF position RMSE" in page
    assert f"<td>{paper.ratio('AMCEKF'):.3f}</td>" in page  # the paper's 0.473
    rows = {r["ratio"]: r for r in published_rows(campaign, table, [paper])}
    amc = rows["AMCEKF / EKF position RMSE"]
    assert amc["own"] == m[1, 0]  # the scenario's own setting: q x1, R x1
    assert amc["own_at"] == "filters.*.motion.q=x1, filters.*.r0_diag_si=x1"
    assert f"{amc['own']:.3f} ({amc['own_at']})" in page
    assert amc["at_or_below"] == int(np.sum(m <= paper.ratio("AMCEKF")))
    assert "MCEKF / EKF position RMSE" not in rows  # the paper has no MC-EKF column


@pytest.mark.parametrize(("published", "words"), [
    ({"versus": "EKF", "rmse": {"UKF": 1.0}, "source": "p"},
     ["report.published.0.versus", "'EKF'", "no rmse entry", "['UKF']"]),
    ({"versus": "EKF", "rmse": {"EKF": 1.0, "KFX": 2.0}, "source": "p"},
     ["report.published.0.rmse", "KFX", "not filters of this scenario"]),
    ({"versus": "EKF", "rmse": {"EKF": -1.0}, "source": "p"},
     ["report.published.0.rmse.EKF", "-1.0"]),
])
def test_a_published_table_names_the_scenarios_filters(published, words):
    from trackkit.scenario import ScenarioError

    d = load("dbt-receding").model_dump()
    d["report"]["published"] = [published]
    with pytest.raises(ScenarioError) as err:
        parse(d, "paper.toml")
    for w in words:
        assert w in str(err.value), (w, str(err.value))

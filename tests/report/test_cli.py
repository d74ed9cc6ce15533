"""The ``trackkit`` CLI. Most tests replace the scenario loader and the Monte Carlo engine by
fakes (``trackkit.cli._load`` etc.), so they test the CLI alone; ``test_cli_run_default_real``
runs the real default scenario once the engine exists."""

from __future__ import annotations

import importlib
import json
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from trackkit import cli
from trackkit.report import plots

from . import FILTERS, fake_result
from .test_files import ALL_FILES, check_results_json

runner = CliRunner()


class FakeScenarioError(ValueError):
    """Stands in for trackkit.scenario.ScenarioError (a ValueError)."""


def fake_scenario(name: str) -> SimpleNamespace:
    return SimpleNamespace(
        name=name, description="fake", run=SimpleNamespace(runs=20, seed=7),
        model_dump=lambda **kw: {"name": name, "run": {"runs": 20, "seed": 7},
                                 "time": {"step_s": 2.0}})


@pytest.fixture
def fake(monkeypatch):
    """Fake scenario stage and engine; records the calls."""
    calls = SimpleNamespace(load=[], run=[])

    def load(name):
        calls.load.append(name)
        if name in ("bad", "bad.toml"):
            raise FakeScenarioError("bad.toml: time.step_s = -1.0: must be > 0")
        return fake_scenario(name)

    def run(scenario, **kwargs):
        calls.run.append(kwargs)
        total = kwargs["runs"] or scenario.run.runs
        for done in range(0, total + 1, 5):
            kwargs["progress"](min(done, total), total)
        kwargs["progress"](total, total)
        return fake_result(runs=total, seed=kwargs["seed"] or scenario.run.seed)

    monkeypatch.setattr(cli, "_load", load)
    monkeypatch.setattr(cli, "_run", run)
    monkeypatch.setattr(cli, "_default_name", lambda: "fake_default")
    monkeypatch.setattr(cli, "_bundled", lambda: {"fake_default": "The default one.",
                                                  "other": "Another one."})
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    return calls


def test_list(fake):
    res = runner.invoke(cli.app, ["list"])
    assert res.exit_code == 0, res.output
    assert "fake_default (default)" in res.stdout and "The default one." in res.stdout
    assert "other" in res.stdout and "Another one." in res.stdout


def test_show(fake, monkeypatch):
    res = runner.invoke(cli.app, ["show", "other"])
    assert res.exit_code == 0, res.output
    assert fake.load == ["other"]
    assert json.loads(res.stdout) == {"name": "other", "run": {"runs": 20, "seed": 7},
                                      "time": {"step_s": 2.0}}
    with_toml = fake_scenario("t")
    with_toml.to_toml = lambda: 'name = "t"\n'
    monkeypatch.setattr(cli, "_load", lambda name: with_toml)
    res = runner.invoke(cli.app, ["show", "t"])
    assert res.exit_code == 0 and 'name = "t"' in res.stdout


def test_run_writes_everything(fake, tmp_path):
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "other", "--runs", "4", "--seed", "3", "--out",
                                  str(out), "--workers", "2", "--scheduler", "tcp://h:8786"])
    assert res.exit_code == 0, res.output
    assert fake.load == ["other"]
    (kwargs,) = fake.run
    assert {k: v for k, v in kwargs.items() if k != "progress"} == {
        "runs": 4, "seed": 3, "workers": 2, "scheduler": "tcp://h:8786"}
    assert {p.name for p in out.iterdir()} == ALL_FILES
    doc = json.loads((out / "results.json").read_text())
    check_results_json(doc)
    assert doc["runs"] == 4 and doc["seed"] == 3
    for name in FILTERS:
        assert name in res.stdout
    assert "PCRLB" in res.stdout and "[deg]" in res.stdout  # the summary table
    assert "report.html" in res.stdout
    assert "4/4" in res.stderr  # the progress bar finished


def test_run_without_scenario_uses_default(fake, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(cli.app, ["run"])
    assert res.exit_code == 0, res.output
    assert fake.load == ["fake_default"]
    assert fake.run[0]["runs"] is None and fake.run[0]["seed"] is None  # scenario's own
    out = tmp_path / "trackkit-out" / "fake_default"
    assert json.loads((out / "results.json").read_text())["runs"] == 20


@pytest.mark.parametrize("args", [["run", "bad.toml"], ["show", "bad"]])
def test_scenario_error_exit_2_one_line(fake, tmp_path, monkeypatch, args):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(cli.app, args)
    assert res.exit_code == 2
    assert res.stderr.strip() == "error: bad.toml: time.step_s = -1.0: must be > 0"
    assert "Traceback" not in res.output
    assert fake.run == [] and list(tmp_path.iterdir()) == []


def test_engine_value_error_writes_nothing(fake, tmp_path, monkeypatch):
    def run(scenario, **kwargs):
        kwargs["progress"](1, 20)
        raise ValueError("filters[1].name = 'XKF': expected one of EKF, UKF")

    monkeypatch.setattr(cli, "_run", run)
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "--out", str(out)])
    assert res.exit_code == 2
    assert "error: filters[1].name = 'XKF'" in res.stderr
    assert not out.exists()


def test_failure_while_writing_leaves_no_results(fake, tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device", "nees.png")

    monkeypatch.setattr(plots, "plot_nees", broken)
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "--out", str(out)])
    assert res.exit_code == 1
    assert res.stderr.strip().splitlines()[-1] == "error: No space left on device: nees.png"
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", [["--runs", "0"], ["--seed", "-1"], ["--workers", "0"]])
def test_bad_option_values_exit_2(fake, tmp_path, option):
    res = runner.invoke(cli.app, ["run", "--out", str(tmp_path / "o"), *option])
    assert res.exit_code == 2
    assert fake.run == [] and not (tmp_path / "o").exists()


def test_out_is_a_file_exit_2_before_running(fake, tmp_path):
    target = tmp_path / "file"
    target.write_text("x")
    res = runner.invoke(cli.app, ["run", "--out", str(target)])
    assert res.exit_code == 2 and "is not a directory" in res.stderr
    assert fake.run == [] and target.read_text() == "x"


def _engine_available() -> bool:
    try:
        montecarlo = importlib.import_module("trackkit.eval.montecarlo")
        importlib.import_module("trackkit.scenario")
    except ImportError:
        return False
    return hasattr(montecarlo, "run_scenario")


@pytest.mark.skipif(not _engine_available(), reason="trackkit.eval.montecarlo.run_scenario "
                    "not there yet")
def test_cli_run_default_real(tmp_path, monkeypatch):
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    out = tmp_path / "tmp"
    res = runner.invoke(cli.app, ["run", "--runs", "4", "--out", str(out)])
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert ALL_FILES - {"geometry.png"} <= names  # geometry only when the engine gives a run
    doc = json.loads((out / "results.json").read_text())
    check_results_json(doc)
    assert doc["runs"] == 4
    assert doc["scenario"] == importlib.import_module("trackkit.scenario").DEFAULT

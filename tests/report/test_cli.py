"""The ``trackkit`` CLI. Most tests replace the scenario loader and the comparison engine by
fakes (``trackkit.cli.stages.load`` etc.), so they test the CLI alone; the tests at the end run the
real engine in-process on a few runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from trackkit import cli
from trackkit.cli import stages
from trackkit.report import plots

from . import FILTERS, fake_result
from .test_files import ALL_FILES, check_results_json

runner = CliRunner()
WIDE = {"COLUMNS": "200", "NO_COLOR": "1"}


class FakeScenarioError(ValueError):
    """Stands in for trackkit.scenario.ScenarioError (a ValueError)."""


def fake_scenario(name: str) -> SimpleNamespace:
    return SimpleNamespace(
        name=name, description="fake", run=SimpleNamespace(runs=20, seed=7),
        model_dump=lambda **kw: {"name": name, "run": {"runs": 20, "seed": 7},
                                 "time": {"step_s": 2.0}})


@pytest.fixture
def fake(monkeypatch):
    """Fake scenario stage and engine; records the calls (and the output directory's state
    while the engine runs)."""
    calls = SimpleNamespace(load=[], run=[], during=[])

    def load(name):
        calls.load.append(name)
        if name in ("bad", "bad.toml"):
            raise FakeScenarioError("bad.toml: time.step_s = -1.0: must be > 0")
        return fake_scenario(name)

    def run(scenario, **kwargs):
        calls.run.append(kwargs)
        calls.during.append(sorted(p.name for p in calls.out.iterdir())
                            if getattr(calls, "out", None) and calls.out.is_dir() else None)
        kwargs["tuning_progress"](0, 6)
        kwargs["tuning_progress"](6, 6)
        total = kwargs["runs"] or scenario.run.runs
        for done in range(0, 4 * total + 1):  # a quarter of a run at a time, as floats
            kwargs["progress"](done / 4, total)
        return fake_result(runs=total, seed=kwargs["seed"] or scenario.run.seed)

    monkeypatch.setattr(stages, "load", load)
    monkeypatch.setattr(stages, "run", run)
    monkeypatch.setattr(stages, "dumps", lambda sc: f'name = "{sc.name}"\n\n[run]\nruns = 20\n')
    monkeypatch.setattr(stages, "default_name", lambda: "fake_default")
    monkeypatch.setattr(stages, "bundled", lambda: {"fake_default": "The default one.",
                                                  "other": "Another one."})
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    return calls


def _engine(monkeypatch, behaviour):
    """Replace the fake engine by ``behaviour(scenario, **kwargs)``."""
    monkeypatch.setattr(stages, "run", behaviour)


def test_list(fake):
    res = runner.invoke(cli.app, ["list"])
    assert res.exit_code == 0, res.output
    assert "fake_default (default)" in res.stdout and "The default one." in res.stdout
    assert "other" in res.stdout and "Another one." in res.stdout


def test_show_prints_toml_by_default_and_json_on_request(fake):
    res = runner.invoke(cli.app, ["show", "other"])
    assert res.exit_code == 0, res.output
    assert fake.load == ["other"]
    assert res.stdout == 'name = "other"\n\n[run]\nruns = 20\n'  # exactly, for a file
    res = runner.invoke(cli.app, ["show", "other", "--format", "json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {"name": "other", "run": {"runs": 20, "seed": 7},
                                      "time": {"step_s": 2.0}}
    res = runner.invoke(cli.app, ["show", "other", "--format", "yaml"])
    assert res.exit_code == 2 and "yaml" in res.output


@pytest.mark.parametrize("command, defaults", [
    ("run", ["the bundled default", "the scenario's run.runs", "the scenario's run.seed",
             "trackkit-out/SCENARIO", "none: in this process"]),
    ("show", ["the bundled default", "toml"]),
])
def test_help_shows_the_defaults(command, defaults):
    res = runner.invoke(cli.app, [command, "--help"], env=WIDE, terminal_width=200)
    assert res.exit_code == 0, res.output
    for default in defaults:
        assert default in res.output, f"{default!r} missing from\n{res.output}"
    assert res.output.count("[default:") >= len(defaults)


@pytest.mark.parametrize("executor, workers, scheduler", [
    (["--workers", "2"], 2, None),
    (["--scheduler", "tcp://h:8786"], None, "tcp://h:8786"),
])
def test_run_writes_everything(fake, tmp_path, executor, workers, scheduler):
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "other", "--runs", "4", "--seed", "3", "--out",
                                  str(out), *executor,
                                  "--max-hours", "2"], env=WIDE)  # the path fits one line
    assert res.exit_code == 0, res.output
    assert fake.load == ["other"]
    (kwargs,) = fake.run
    assert {k: v for k, v in kwargs.items() if "progress" not in k} == {
        "runs": 4, "seed": 3, "workers": workers, "scheduler": scheduler,
        "max_seconds": 7200.0}
    assert {p.name for p in out.iterdir()} == ALL_FILES | {"manifest.json"}
    doc = json.loads((out / "results.json").read_text())
    check_results_json(doc)
    assert doc["runs"] == 4 and doc["seed"] == 3
    for name in FILTERS:
        assert name in res.stdout
    assert "PCRLB" in res.stdout and "[deg]" in res.stdout  # the summary table
    # the path is printed whole; rich may wrap a long one (a pytest-xdist worker's tmp_path)
    assert "report.html" in res.stdout.replace("\n", "")
    assert "4/4 runs" in res.stderr  # the progress bar finished
    assert "tuning" in res.stderr and "6/6 generations" in res.stderr  # and the tuning one


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

    _engine(monkeypatch, run)
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "--out", str(out)])
    assert res.exit_code == 2
    assert "error: filters[1].name = 'XKF'" in res.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


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
    assert f"--out {target}" in res.stderr
    assert fake.run == [] and target.read_text() == "x"


def test_out_below_a_file_exit_2_before_running(fake, tmp_path):
    target = tmp_path / "file"
    target.write_text("x")
    res = runner.invoke(cli.app, ["run", "--out", str(target / "sub")])
    assert res.exit_code == 2, res.output
    assert f"--out {target / 'sub'}" in res.stderr and f"{target} is a file" in res.stderr
    assert fake.run == [] and target.read_text() == "x"


def test_output_directory_is_created_and_locked_while_the_engine_runs(fake, tmp_path):
    fake.out = tmp_path / "new" / "out"
    res = runner.invoke(cli.app, ["run", "--runs", "2", "--out", str(fake.out)])
    assert res.exit_code == 0, res.output
    assert fake.during == [[cli.LOCK_FILE]]  # created and locked before any compute
    assert {p.name for p in fake.out.iterdir()} == ALL_FILES | {"manifest.json"}  # no lock


def test_second_run_into_a_locked_directory_refuses(fake, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    lock = out / cli.LOCK_FILE
    lock.write_text(f"{os.getpid()}\n")  # a live process holds it
    res = runner.invoke(cli.app, ["run", "--out", str(out)], env=WIDE)
    assert res.exit_code == 2, res.output
    assert "in use by another trackkit run" in res.stderr
    assert f"pid {os.getpid()}" in res.stderr and str(lock) in res.stderr
    assert fake.run == [] and lock.read_text() == f"{os.getpid()}\n"
    assert [p.name for p in out.iterdir()] == [cli.LOCK_FILE]


def _dead_pid() -> int:
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)
    return int(child.stdout)


def test_stale_lock_is_taken_over_and_said(fake, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    pid = _dead_pid()
    (out / cli.LOCK_FILE).write_text(f"{pid}\n")
    res = runner.invoke(cli.app, ["run", "--runs", "2", "--out", str(out)], env=WIDE)
    assert res.exit_code == 0, res.output
    assert "took over the stale lock" in res.stderr and f"pid {pid}, no longer running" in (
        res.stderr)
    assert {p.name for p in out.iterdir()} == ALL_FILES | {"manifest.json"}


@pytest.mark.parametrize("failure, code, words", [
    (KeyboardInterrupt(), 130, "interrupted; nothing was written to"),
    (ValueError("runs = 0; expected at least 1"), 2, "error: runs = 0; expected at least 1"),
    (OSError(28, "No space left on device"), 1, "error: No space left on device"),
    (MemoryError(), 1, "error: out of memory; try fewer runs"),
    (TypeError("unsupported operand"), 1, "error: unexpected TypeError: unsupported operand"),
])
def test_every_exit_path_releases_the_lock(fake, tmp_path, monkeypatch, failure, code, words):
    def run(scenario, **kwargs):
        kwargs["progress"](0.5, 20)
        raise failure

    _engine(monkeypatch, run)
    out = tmp_path / "out"
    res = runner.invoke(cli.app, ["run", "--out", str(out)], env=WIDE)
    assert res.exit_code == code, res.output
    assert words in res.stderr
    assert "Traceback" not in res.output
    assert not out.exists()  # the lock is gone, and so is the directory this run created


def test_interrupt_inside_class_construction_is_an_interrupt(fake, tmp_path, monkeypatch):
    """Python 3.11 wraps an interrupt inside __set_name__ (pydantic building a model class
    while modules import) in a RuntimeError; that is still Ctrl-C, not a bug."""
    def run(scenario, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise RuntimeError("Error calling __set_name__ on 'Field' instance 'run_last'") \
                from err

    _engine(monkeypatch, run)
    res = runner.invoke(cli.app, ["run", "--out", str(tmp_path / "o")], env=WIDE)
    assert res.exit_code == 130, res.output
    assert "interrupted" in res.stderr and "__set_name__" not in res.output


def test_debug_keeps_the_traceback(fake, tmp_path, monkeypatch):
    def run(scenario, **kwargs):
        raise TypeError("unsupported operand")

    _engine(monkeypatch, run)
    monkeypatch.setenv("TRACKKIT_DEBUG", "1")
    res = runner.invoke(cli.app, ["run", "--out", str(tmp_path / "o")])
    assert isinstance(res.exception, TypeError)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["../../escaped", "..", ".", "a/b", "/abs/path"])
def test_default_output_stays_inside_trackkit_out(fake, tmp_path, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(stages, "load", lambda _: fake_scenario(name))
    res = runner.invoke(cli.app, ["run"], env=WIDE)
    assert res.exit_code == 2, res.output
    assert repr(name) in res.stderr and "--out DIR" in res.stderr
    assert fake.run == [] and list(tmp_path.iterdir()) == []


# --- the real engine, in-process, a few runs ---------------------------------------------------


def test_cli_run_default_real(tmp_path, monkeypatch):
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    out = tmp_path / "tmp"
    res = runner.invoke(cli.app, ["run", "--runs", "4", "--out", str(out)])
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert ALL_FILES - {"geometry.png"} <= names  # geometry only when the engine gives a run
    assert cli.LOCK_FILE not in names
    doc = json.loads((out / "results.json").read_text())
    check_results_json(doc)
    assert doc["runs"] == 4
    from trackkit.scenario import DEFAULT

    assert doc["scenario"] == DEFAULT
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["seconds_per_step"]) == set(doc["filters"])
    assert all(v > 0 for v in timings["seconds_per_step"].values())


def test_equal_seeds_give_byte_identical_results_json(tmp_path, monkeypatch):
    monkeypatch.delenv("TRACKKIT_DEBUG", raising=False)
    for out in ("a", "b"):
        res = runner.invoke(cli.app, ["run", "cv-position", "--runs", "3", "--seed", "11",
                                      "--out", str(tmp_path / out)])
        assert res.exit_code == 0, res.output
    a, b = ((tmp_path / out / "results.json").read_bytes() for out in ("a", "b"))
    assert a == b
    assert json.loads(a)["seed"] == 11
    res = runner.invoke(cli.app, ["run", "cv-position", "--runs", "3", "--seed", "12",
                                  "--out", str(tmp_path / "c")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "c" / "results.json").read_bytes() != a  # the seed matters

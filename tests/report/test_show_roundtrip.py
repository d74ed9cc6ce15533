"""``trackkit show NAME > x.toml && trackkit run x.toml`` gives the results of
``trackkit run NAME``, for every bundled scenario.

Every scenario: the shown TOML validates to a Scenario equal to the bundled one. Scenarios
without a tune block: both commands run through the real CLI (subprocesses, 3 runs) and their
results.json are compared byte for byte. The underwater (Naseri Solhdar) scenarios that tune fuzzy
systems (about 90 s of tuning each) run both in-process through ``compare`` at 2 runs: the tuning is
cached per scenario content in the process (trackkit.experiments.tuning), so the second costs
nothing and the shown scenario hits the bundled one's cache entry only if it is the same scenario.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import trackkit.scenario as S
from trackkit import cli
from trackkit.report.files import results_document

NAMES = sorted(S.bundled())
TUNED = [n for n in NAMES if any(f.tune is not None for f in S.load(n).filters)]
UNTUNED = [n for n in NAMES if n not in TUNED]
runner = CliRunner()


def _shown(name: str, tmp_path: Path) -> Path:
    res = runner.invoke(cli.app, ["show", name])
    assert res.exit_code == 0, res.output
    path = tmp_path / f"{name}-shown.toml"
    path.write_text(res.stdout, encoding="utf-8")
    return path


def test_list_is_the_bundled_scenarios():
    res = runner.invoke(cli.app, ["list"], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    for name in NAMES:
        assert name in res.stdout
    assert TUNED and UNTUNED  # both kinds are covered below


@pytest.mark.parametrize("name", NAMES)
def test_shown_toml_is_the_same_scenario(name, tmp_path):
    assert S.load(str(_shown(name, tmp_path))) == S.load(name)


def test_shown_json_is_the_same_scenario():
    res = runner.invoke(cli.app, ["show", "bo-cv", "--format", "json"])
    assert res.exit_code == 0, res.output
    assert S.parse(json.loads(res.stdout)) == S.load("bo-cv")


def _trackkit(*args: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    env.pop("TRACKKIT_DEBUG", None)
    return subprocess.Popen([sys.executable, "-m", "trackkit.cli", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.slow
@pytest.mark.parametrize("name", UNTUNED)
def test_show_then_run_gives_the_same_results(name, tmp_path):
    with (tmp_path / "x.toml").open("w", encoding="utf-8") as f:  # trackkit show > x.toml
        shown = subprocess.run([sys.executable, "-m", "trackkit.cli", "show", name],
                               stdout=f, stderr=subprocess.PIPE, text=True, timeout=120)
    assert shown.returncode == 0, shown.stderr
    # the two runs side by side: they share nothing but the machine
    runs = [_trackkit("run", *args, "--runs", "3", "--out", out, cwd=tmp_path)
            for args, out in ((["x.toml"], "from-file"), ([name], "bundled"))]
    for ran in runs:
        output, _ = ran.communicate(timeout=600)
        assert ran.returncode == 0, output
    a, b = ((tmp_path / out / "results.json").read_bytes() for out in ("from-file", "bundled"))
    assert a == b


@pytest.mark.slow
@pytest.mark.parametrize("name", TUNED)
def test_show_then_compare_gives_the_same_results_tuned(name, tmp_path):
    from trackkit.experiments.compare import compare

    docs = [json.dumps(results_document(compare(S.load(source), runs=2)), indent=2)
            for source in (str(_shown(name, tmp_path)), name)]
    assert docs[0] == docs[1]
    assert "tuning" in json.loads(docs[0])

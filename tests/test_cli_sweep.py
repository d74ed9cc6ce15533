"""``trackkit sweep``: a campaign interrupted by Ctrl-C and resumed gives the same bytes as one
run straight through; a changed campaign is refused unless ``--fresh``; bad values and a block
that always fails are reported in words."""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from trackkit import cli
from trackkit.experiments import sweep as sweep_module

from .cli_helpers import LEAKS, assert_user_error, trackkit
from .experiments.test_sweep import (
    BLOCK,
    BLOCKS,
    PARAMS,
    RUNS,
    SEED,
    full_bo_cv_toml,
    short_bo_cv,
    short_bo_cv_toml,
)

REPO = Path(__file__).resolve().parents[1]
runner = CliRunner()
ARGS = [a for p in PARAMS for a in ("--param", p)] + ["--runs", str(RUNS), "--block",
                                                       str(BLOCK), "--seed", str(SEED)]
DETERMINISTIC = ("sweep.parquet", "sweep.csv", "sweep.json")


def _invoke(args):
    res = runner.invoke(cli.app, args, env={"COLUMNS": "200", "NO_COLOR": "1"})
    return res


def deterministic_files(out: Path) -> dict[str, bytes]:
    files = {name: (out / name).read_bytes() for name in DETERMINISTIC}
    for d in sorted((out / "points").iterdir()):
        files[f"points/{d.name}/result.json"] = (d / "result.json").read_bytes()
    return files


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    return full_bo_cv_toml(tmp_path_factory.mktemp("scenario") / "bo.toml")


@pytest.fixture(scope="module")
def reference(scenario_file, tmp_path_factory):
    """The campaign run straight through, in this process."""
    out = tmp_path_factory.mktemp("straight") / "campaign"
    res = _invoke(["sweep", str(scenario_file), *ARGS, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out, deterministic_files(out)


def test_a_campaign_writes_its_table_figures_and_report(reference):
    out, files = reference
    names = {p.name for p in out.iterdir()}
    assert {"campaign.json", "scenario.toml", "points", "sweep.parquet", "sweep.csv",
            "sweep.json", "report.html", "timings.json", "lines-sensor.sigma_deg.png",
            "lines-filters.EKF.motion.q.png", "heatmap-rmse_position.png",
            "heatmap-rmse_pcrlb_position.png", "heatmap-anees.png",
            "heatmap-diverged_share.png", "heatmap-ratio_rmse_position.png"} <= names
    assert not any(n.startswith(".trackkit") or "tmp" in n for n in names)
    assert len([k for k in files if k.startswith("points/")]) == 9
    page = (out / "report.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == 7 and "<script" not in page
    assert "http://" not in page and "https://" not in page  # self-contained

    import pyarrow.parquet as pq

    table = pq.read_table(out / "sweep.parquet")
    assert table.num_rows == 9 * 7  # points x filters
    assert table.schema.field("rmse_position").metadata[b"unit"] == b"m"
    assert table.column("filters.EKF.motion.q").to_pylist()[::21] == [1e-5, 1e-4, 1e-3]


@pytest.mark.slow
def test_ctrl_c_then_the_same_command_resumes_bit_for_bit(scenario_file, reference, tmp_path):
    out = tmp_path / "campaign"
    cmd = [sys.executable, "-m", "trackkit.cli", "sweep", str(scenario_file), *ARGS, "--out",
           str(out)]
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 120 and p.poll() is None:  # the first point is done
            if list(out.glob("points/*/result.json")):
                break
            time.sleep(0.02)
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, stderr
    assert "run the same command again to resume" in stderr
    for leak in LEAKS:
        assert leak not in stdout + stderr
    stored = len(list(out.glob("points/*/block-*.tkb")))
    assert BLOCKS // 9 <= stored < BLOCKS, (
        f"{stored} blocks stored: the interrupt came too late to test")
    assert not (out / "sweep.csv").exists() and not list(out.rglob(".*tmp-*"))
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert re.search(rf"resuming: {stored} of {BLOCKS} blocks already stored", again.stderr)
    assert deterministic_files(out) == reference[1]


def test_a_changed_campaign_is_refused_unless_fresh(tmp_path):
    scenario = short_bo_cv_toml(tmp_path / "bo.toml")
    out = tmp_path / "camp"
    args = ["sweep", str(scenario), "--param", "sensor.sigma_deg=1,2", "--runs", "2",
            "--block", "1", "--out", str(out)]
    assert _invoke(args).exit_code == 0
    first = deterministic_files(out)
    res = _invoke(args)  # the same command again: nothing to do, the same files
    assert res.exit_code == 0 and deterministic_files(out) == first
    res = _invoke([*args, "--block", "2"])
    assert res.exit_code == 2
    assert "block size (--block) (was 1, is 2)" in res.output and "--fresh" in res.output
    text = scenario.read_text().replace("speed_kn = 8.0", "speed_kn = 9.0")
    scenario.write_text(text)
    res = _invoke(args)
    assert res.exit_code == 2
    assert re.search(r"scenario \(its hash was \w{12}, is \w{12}\)", res.output), res.output
    assert "Refusing to mix results" in res.output and deterministic_files(out) == first
    res = _invoke([*args, "--fresh"])
    assert res.exit_code == 0, res.output
    assert deterministic_files(out) != first


def test_bad_values_exit_2_naming_the_parameter(tmp_path):
    scenario = short_bo_cv_toml(tmp_path / "bo.toml")
    ran = trackkit("sweep", str(scenario), "--param", "sensor.sigma_deg=1,-2", "--runs", "2",
                   "--out", "o", cwd=tmp_path)
    assert_user_error(ran, 2, "--param sensor.sigma_deg=1,-2", "value -2",
                      "greater than 0")
    assert not (tmp_path / "o").exists()
    for args, words in [
        (["--param", "sensor.sigma_dg=1"], ["sensor.sigma_dg", "no field 'sigma_dg'"]),
        (["--param", "sensor.sigma_deg"], ["--param sensor.sigma_deg", "PATH=V1,V2"]),
        (["--param", "sensor.sigma_deg=1:4"], ["sensor.sigma_deg", "--points"]),
        (["--param", "filters.EKF.motion.q=x,1"], ["filters.EKF.motion.q", "value x"]),
        (["--param", "sensor.sigma_deg=1", "--workers", "2", "--scheduler", "tcp://h:1"],
         ["--workers 2", "--scheduler tcp://h:1", "give one"]),
        ([], ["nothing to sweep", "--param"]),
    ]:
        res = _invoke(["sweep", str(scenario), *args, "--runs", "2", "--out",
                       str(tmp_path / "o")])
        assert res.exit_code == 2, (args, res.output)
        for w in words:
            assert w in res.output, (w, res.output)
        assert "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


def test_a_block_that_always_fails_stops_the_campaign_naming_point_and_block(
        tmp_path, monkeypatch):
    scenario = short_bo_cv_toml(tmp_path / "bo.toml")
    out = tmp_path / "camp"
    args = ["sweep", str(scenario), "--param", "sensor.sigma_deg=1,2", "--runs", "4",
            "--block", "2", "--out", str(out)]
    real = sweep_module.run_blocks
    attempts = []

    def faulty(s, blocks, progress=None):
        if s.observers[0].sensor.sigma_deg == 2.0 and blocks == [1]:
            attempts.append(blocks)
            raise FloatingPointError("covariance of run 3 is not positive definite")
        return real(s, blocks, progress)

    monkeypatch.setattr(sweep_module, "run_blocks", faulty)
    res = _invoke(args)
    assert res.exit_code == 1, res.output
    assert len(attempts) == 3
    msg = " ".join(res.output.split())
    assert re.search(r"point \w{12} \(sensor\.sigma_deg=2\), block 1 \(runs 2-3\) failed 3 "
                     r"times: FloatingPointError: covariance of run 3 is not positive "
                     r"definite", msg), msg
    assert "run the same command again to resume" in msg and "Traceback" not in msg
    blocks = sorted(p.relative_to(out / "points").parts[1] for p in
                    out.glob("points/*/block-*.tkb"))
    assert blocks == ["block-000000.tkb", "block-000000.tkb", "block-000001.tkb"]
    assert not (out / "sweep.csv").exists()
    monkeypatch.setattr(sweep_module, "run_blocks", real)  # fixed: it resumes
    res = _invoke(args)
    assert res.exit_code == 0, res.output
    assert "resuming: 3 of 4 blocks already stored" in " ".join(res.output.split())


def test_the_readme_sweep_command_plans():
    readme = "\n".join((REPO / p).read_text(encoding="utf-8")
                       for p in ("README.md", "docs/tour.md"))
    lines = [x.split("#")[0] for x in readme.splitlines() if x.startswith("trackkit sweep ")]
    assert lines, "the README and the tour show no trackkit sweep command"
    from trackkit.scenario import bundled, load

    for line in lines:
        words = shlex.split(line)[2:]
        params = [sweep_module.parse_param(words[i + 1]) for i, w in enumerate(words)
                  if w == "--param"]
        assert params
        sc = load(words[0]) if words[0] in bundled() else short_bo_cv()  # my.toml: yours
        c = sweep_module.plan_campaign(sc, params, runs=2)
        assert len(c.points) >= 2


def test_a_pickled_block_is_refused_unread_and_fresh_recomputes_it(tmp_path):
    """A campaign directory someone else wrote, one of whose blocks is a pickle (as trackkit
    wrote them before) that would create a marker file when read: the resumed command stops,
    naming the file, and the marker is never created; --fresh computes the same files."""
    import json
    import pickle
    import zlib

    from .experiments.test_checkpoint import _Plant

    scenario = short_bo_cv_toml(tmp_path / "bo.toml")
    out, marker = tmp_path / "camp", tmp_path / "ran-code"
    args = ["sweep", str(scenario), "--param", "sensor.sigma_deg=1,2", "--runs", "2",
            "--block", "2", "--out", str(out)]
    assert _invoke(args).exit_code == 0
    first = deterministic_files(out)
    point = sorted((out / "points").iterdir())[0]
    (point / "result.json").unlink()
    block = point / "block-000000.tkb"
    key = json.loads(block.read_bytes().split(b"\n")[1])["key"]
    header = json.dumps({"key": key, "block": 0, "runs": 2}).encode() + b"\n"
    block.write_bytes(b"trackkit-block 1\n" + header
                      + zlib.compress(pickle.dumps({"x": _Plant(marker)})))
    res = _invoke(args)
    text = " ".join(res.output.split())
    assert res.exit_code == 1, res.output
    for words in (f"{point.name}/block-000000.tkb", "older trackkit", "cannot be read safely",
                  "--fresh"):
        assert words in text.replace(" /", "/"), res.output
    assert not marker.exists()
    res = _invoke([*args, "--fresh"])
    assert res.exit_code == 0, res.output
    assert deterministic_files(out) == first and not marker.exists()

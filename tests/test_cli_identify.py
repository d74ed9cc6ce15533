"""``trackkit identify`` (Zolfagharnasab and Seif 2025): a recorded GPS/INS log with its inputs (the
simulator-written fixture that crosses midnight), every bundled vessel scenario at a small
run count, bad logs and inputs, and byte-identical results for one seed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.cli_helpers import Ran, assert_user_error, trackkit
from trackkit import cli
from trackkit.cli import stages
from trackkit.models.manoeuvring import COEFFICIENT_NAMES
from trackkit.report.vessel_report import VESSEL_FILES

FIXTURES = Path(__file__).parent / "fixtures"
LOG = FIXTURES / "sar_trial.nmea"
INPUTS = FIXTURES / "sar_trial_inputs.csv"
IMO = {"advance", "tactical_diameter", "paper_band", "initial_turning", "first_overshoot_10",
       "second_overshoot_10", "first_overshoot_20"}


def _run(*args: str) -> Ran:
    """``trackkit ARGS`` in this process (the subprocess costs an interpreter start; the
    fixture's test runs the real command)."""
    res = CliRunner().invoke(cli.app, list(args), env={"COLUMNS": "200", "NO_COLOR": "1"})
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return Ran(res.exit_code, res.stdout, res.stderr)


def _files(out: Path) -> set[str]:
    return {p.name for p in out.iterdir()}


# --- a recorded log ---------------------------------------------------------------------------


def test_the_fixture_log_writes_its_report_and_prints_the_table(tmp_path):
    out = tmp_path / "out"
    ran = trackkit("identify", str(LOG), "--inputs", str(INPUTS), "--out", str(out))
    assert ran.code == 0, ran.text
    assert _files(out) == {"convergence.png", "track.png", "heading.png", "trials.png",
                           "report.html", "results.json", "manifest.json"}
    lines = ran.out.splitlines()
    for name in COEFFICIENT_NAMES:  # one row per coefficient, with its std
        assert any(line.strip("│ ").startswith(f"{name} ") for line in lines), name
    assert "relative std" in ran.out and "1996 records read, 1996 kept" in ran.out
    # 166 s cannot identify 16 coefficients: said, not hidden
    assert "not identified by this log" in ran.out
    assert "the log is 166 s long" in ran.out and "500 s" in ran.out
    doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert doc["samples"] == 167 and doc["start_s"] == 0.0 and doc["filter"] == "ekf"
    c = doc["coefficients"]
    assert list(c) == list(COEFFICIENT_NAMES)
    assert all(e["std"] > 0 and e["identified"] == (e["rel_std"] <= 0.5) for e in c.values())
    assert 0 < doc["identified_count"] < 16
    imo = {e["name"]: e for e in doc["model_trials"]["imo"]}
    assert set(imo) == IMO and imo["paper_band"]["lower"] == 2.0
    assert imo["paper_band"]["upper"] == 7.0
    assert imo["tactical_diameter"]["upper"] == pytest.approx(5 * 19.6)
    assert doc["log"]["records_kept"] == 1996 and doc["inputs"]["records_kept"] == 167
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "data:image/png;base64," in page and "<script" not in page


def test_identify_log_from_python_gives_what_the_command_writes(tmp_path):
    """The command is a thin shell over ``experiments.vessel_log.identify_log``: the same
    coefficients to the bit, the same notes, the same reads."""
    from trackkit.experiments.vessel_log import LogOptions, identify_log

    ident = identify_log(LogOptions(LOG, INPUTS))
    out = tmp_path / "out"
    ran = _run("identify", str(LOG), "--inputs", str(INPUTS), "--out", str(out))
    assert ran.code == 0, ran.text
    doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert [c["value"] for c in doc["coefficients"].values()] == ident.result.theta.tolist()
    assert [c["std"] for c in doc["coefficients"].values()] == ident.result.theta_std.tolist()
    assert doc["log"]["records_kept"] == ident.log_read.rows_kept == 1996
    assert any("the log is 166 s long" in n for n in ident.notes)
    assert all(n.split(";")[0] in ran.out.replace("\n", " ") for n in ident.notes)


def test_bad_log_lines_are_counted_and_named_and_nothing_good_is_dropped(tmp_path):
    lines = LOG.read_text(encoding="ascii").splitlines(keepends=True)
    lines[4] = lines[4][:-3] + "00\n"  # a wrong checksum on line 5
    lines.insert(9, "not an NMEA line\n")  # line 10
    bad = tmp_path / "bad.nmea"
    bad.write_text("".join(lines), encoding="ascii")
    ran = _run("identify", str(bad), "--inputs", str(INPUTS), "--out", str(tmp_path / "o"))
    assert ran.code == 0, ran.text
    assert "1997 records read, 1995 kept" in ran.out and "skipped 2" in ran.out
    assert f"{bad}:5:" in ran.out and f"{bad}:10:" in ran.out
    doc = json.loads((tmp_path / "o" / "results.json").read_text(encoding="utf-8"))
    assert doc["log"]["skipped_lines"] == [5, 10] and doc["samples"] == 167
    stop = _run("identify", str(bad), "--inputs", str(INPUTS), "--on-bad", "stop", "--out",
                str(tmp_path / "s"))
    assert_user_error(stop, 2, f"{bad}:5", "checksum", "--on-bad skip")
    assert not (tmp_path / "s").exists()  # a failed run leaves nothing behind


@pytest.mark.parametrize("case,names", [
    ("missing log", ["nope.nmea", "no such file"]),
    ("missing inputs", ["--inputs", "time, nozzle_deg, rpm"]),
    ("wrong column", ["angle", "is not known", "nozzle_deg"]),
    ("missing column", ["no column 'nozzle_deg'", "expected the columns time, nozzle_deg"]),
    ("short inputs", ["short.csv", "58.000", "166.000", "over the whole log"]),
    ("unknown log type", ["log.dat", "'.dat'", ".nmea"]),
    ("scenario with inputs", ["--inputs", "vessel-turning is a vessel scenario"]),
    ("log with runs", ["--runs", "recorded log"]),
    ("unknown name", ["vessel-nope", "vessel-identify"]),
])
def test_user_mistakes_exit_2_naming_the_field(case, names, tmp_path):
    csv = INPUTS.read_text(encoding="ascii").splitlines(keepends=True)
    files = {"short.csv": "".join(csv[:60]),
             "cols.csv": "".join(csv).replace("nozzle_deg", "angle", 1),
             "missing.csv": "".join(x.split(",")[0] + "," + x.split(",")[2] for x in csv),
             "log.dat": "x\n"}
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="ascii")
    out = ["--out", str(tmp_path / "out")]
    args = {
        "missing log": ["nope.nmea", "--inputs", str(INPUTS)],
        "missing inputs": [str(LOG)],
        "wrong column": [str(LOG), "--inputs", str(tmp_path / "cols.csv")],
        "missing column": [str(LOG), "--inputs", str(tmp_path / "missing.csv")],
        "short inputs": [str(LOG), "--inputs", str(tmp_path / "short.csv")],
        "unknown log type": [str(tmp_path / "log.dat"), "--inputs", str(INPUTS)],
        "scenario with inputs": ["vessel-turning", "--inputs", str(INPUTS)],
        "log with runs": [str(LOG), "--inputs", str(INPUTS), "--runs", "3"],
        "unknown name": ["vessel-nope"],
    }[case]
    ran = _run("identify", *args, *out)
    assert_user_error(ran, 2, *names)
    assert not (tmp_path / "out").exists()


def test_a_bad_scenario_file_exits_2_without_a_traceback(tmp_path):
    text = stages.dumps(stages.load("vessel-zigzag-20")).replace("nozzle_deg = 20.0",
                                                                   "nozzle_deg = 90.0")
    f = tmp_path / "bad.toml"
    f.write_text(text, encoding="utf-8")
    ran = trackkit("identify", str(f), "--out", str(tmp_path / "out"))
    assert_user_error(ran, 2, "bad.toml", "trial.nozzle_deg", "90.0", "35")


# --- the bundled scenarios --------------------------------------------------------------------


@pytest.mark.parametrize("name,runs,files", [
    ("vessel-turning", "1", set(VESSEL_FILES) - {"errors.png"}),
    ("vessel-identify", "2", set(VESSEL_FILES) - {"track.png", "heading.png"}),
])
def test_bundled_scenarios_at_a_small_run_count(name, runs, files, tmp_path):
    out = tmp_path / name
    ran = _run("identify", name, "--runs", runs, "--out", str(out))
    assert ran.code == 0, ran.text
    assert _files(out) == files | {"manifest.json"}
    doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert doc["runs"] == int(runs) and doc["scenario"] == name and doc["samples"] == 657
    assert "a1" in ran.out and "c3" in ran.out and "median error" in ran.out
    assert "note: Invented" in ran.out
    if name == "vessel-identify":
        assert list(doc["filters"]) == ["ekf", "ukf", "ckf", "ls"]
        assert doc["trial"] is None
    else:
        tr = doc["trial"]
        assert tr["kind"] == "turn" and 2.0 <= tr["metrics"]["truth"]["diameter_to_length"] <= 7
        assert tr["filtered_rmse_median_m"] < tr["gps_rmse_median_m"]


def test_zigzag_results_are_byte_identical_for_one_seed(tmp_path):
    paths = []
    for i, seed in enumerate(("5", "5", "6")):
        out = tmp_path / f"run{i}"
        ran = _run("identify", "vessel-zigzag-20", "--runs", "1", "--seed", seed,
                   "--filter", "ekf", "--out", str(out))
        assert ran.code == 0, ran.text
        paths.append(out / "results.json")
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b and a != c
    doc = json.loads(a)
    assert doc["trial"]["kind"] == "zigzag" and doc["seed"] == 5
    assert doc["trial"]["metrics"]["model_median"]["first_overshoot_rad"] is not None
    assert {"track.png", "heading.png", "convergence.png"} <= _files(tmp_path / "run0")


def test_the_square_root_ckf_identifies_the_log_where_the_ckf_fails(tmp_path):
    # the CKF's P- - K S K^T cancels into an indefinite covariance on this log (measured
    # u, v, r far more precise than coefficients known to their order of magnitude); the
    # square-root form's covariances are products of QR factors, and it agrees with the EKF
    ckf = _run("identify", str(LOG), "--inputs", str(INPUTS), "--filter", "ckf",
               "--out", str(tmp_path / "ckf"))
    assert ckf.code != 0 and "not positive definite" in ckf.err
    assert "Traceback" not in ckf.err
    dl = {}
    for f in ("srckf", "ekf"):
        ran = _run("identify", str(LOG), "--inputs", str(INPUTS), "--filter", f, "--out",
                   str(tmp_path / f))
        assert ran.code == 0, ran.err
        doc = json.loads((tmp_path / f / "results.json").read_text(encoding="utf-8"))
        assert doc["filter"] == f
        dl[f] = doc["model_trials"]["identified_run0"]["turn"]["diameter_to_length"]
    assert abs(dl["srckf"] / dl["ekf"] - 1) < 0.05, dl

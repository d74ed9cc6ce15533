"""A new user's first commands, run as the real ``trackkit`` command: each mistake is named
in words (the file, line, field or value), with no traceback or numpy warning, and leaves no
output directory behind."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.cli_helpers import assert_user_error, trackkit

FIXTURES = Path(__file__).parent / "fixtures"
LOG = FIXTURES / "sar_trial.nmea"
INPUTS = FIXTURES / "sar_trial_inputs.csv"


# --- identify: a log without any usable record is named, not its inputs ---------------------


@pytest.mark.parametrize("case", ["garbage", "checksums"])
def test_identify_names_the_log_that_has_no_usable_record(case, tmp_path):
    log = tmp_path / "trial.nmea"
    if case == "garbage":
        log.write_text("garbage\nmore garbage\n", encoding="ascii")
        names = ["trial.nmea:1", "malformed", "'garbage'"]
    else:  # every checksum replaced by a wrong one
        lines = LOG.read_text(encoding="ascii").splitlines(keepends=True)
        log.write_text("".join(re.sub(r"\*[0-9A-F]{2}(\r?\n)$", r"*00\1", x) for x in lines),
                       encoding="ascii")
        names = ["trial.nmea:1", "1996 lines read", "1996 checksum failure", "'00'"]
    out = tmp_path / "out"
    ran = trackkit("identify", str(log), "--inputs", str(INPUTS), "--out", str(out))
    assert_user_error(ran, 2, f"{log}: no usable GPS/INS record", *names)
    error = next(line for line in ran.err.splitlines() if line.startswith("error:"))
    assert "sar_trial_inputs.csv" not in error  # the inputs are not to blame
    assert not out.exists()


def test_identify_calls_a_directory_a_directory(tmp_path):
    d = tmp_path / "logs"
    d.mkdir()
    ran = trackkit("identify", str(d), "--inputs", str(INPUTS), "--out", str(tmp_path / "o"))
    assert_user_error(ran, 2, f"{d}: is a directory", "GPS/INS log file")
    assert "vessel scenario, which" not in ran.text
    assert not (tmp_path / "o").exists()


# --- a TOML syntax error is reported as such by every command --------------------------------


@pytest.mark.parametrize("command", ["network", "identify", "run", "sweep", "show"])
def test_a_toml_syntax_error_is_reported_with_its_line_and_column(command, tmp_path):
    f = tmp_path / "my.toml"
    f.write_text('name = "unterminated\n[[agents]]\n', encoding="utf-8")
    args = [] if command == "show" else ["--out", str(tmp_path / "out")]
    ran = trackkit(command, str(f), *args)
    assert_user_error(ran, 2, str(f), "not valid TOML", "line 1, column 21")
    assert "not a network scenario" not in ran.text and "not a vessel" not in ran.text
    assert not (tmp_path / "out").exists()


# --- messages in the user's words -------------------------------------------------------------


def test_a_second_kill_of_one_agent_is_named_by_the_options_given(tmp_path):
    out = tmp_path / "out"
    ran = trackkit("network", "net-baseline", "--agents", "processes", "--kill", "2@100",
                   "--kill", "2@300:400", "--out", str(out))
    assert_user_error(ran, 2, "--kill '2@100' and --kill '2@300:400'", "agent 2 is killed twice")
    assert "outages[" not in ran.text and not out.exists()
    late = trackkit("network", "net-baseline", "--agents", "processes", "--kill", "2@1e9",
                    "--out", str(out))
    assert_user_error(late, 2, "--kill '2@1e9'", "kill at 1e+09 s, no restart")
    assert "None" not in late.text and not out.exists()


AIS = ("Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots\n"
       "2016-01-12 13:02:11,1,50.8,-1.1,10,5\n2016-01-12 13:02:41,1,50.801,-1.1,10,5\n"
       "2016-01-12 13:03:11,1,50.802,-1.1,10,5\n2016-01-12 13:02:11,2,50.81,-1.12,10,5\n"
       "2016-01-12 13:03:11,2,50.812,-1.12,10,5\n")


def test_out_of_memory_names_the_options_of_the_command_that_ran(tmp_path):
    """A billion false plots per scan under a 3 GB address-space limit: track runs out of
    memory and says which of its own options make the job smaller (it has no --runs)."""
    import os
    import resource
    import subprocess
    import sys

    ais = tmp_path / "ais.csv"
    ais.write_text(AIS, encoding="ascii")
    out = tmp_path / "out"

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.run([sys.executable, "-m", "trackkit.cli", "track", str(ais), "--as-radar",
                        "--clutter", "1e9", "--out", str(out)], preexec_fn=limit, env=env,
                       capture_output=True, text=True, timeout=120)
    from tests.cli_helpers import Ran

    ran = Ran(p.returncode, p.stdout, p.stderr)
    assert_user_error(ran, 1, "out of memory", "--max-scans", "--until")
    assert "--runs" not in ran.text and not out.exists()


def test_track_lists_its_files_in_the_manifest(tmp_path):
    ais = tmp_path / "ais.csv"
    ais.write_text(AIS, encoding="ascii")
    ran = trackkit("track", str(ais), "--as-radar", "--out", str(tmp_path / "out"))
    assert ran.code == 0, ran.text
    doc = _check_manifest(tmp_path / "out", "track")
    assert doc["arguments"]["as_radar"] is True and doc["arguments"]["file"] == str(ais)


def test_help_cites_papers_wraps_paragraphs_and_shows_no_type_for_flags():
    for args in ([], ["network"], ["identify"], ["track"], ["run"], ["sweep"]):
        ran = trackkit(*args, "--help", env={"COLUMNS": "80"})
        assert ran.code == 0, ran.text
        for internal in ("seed 0", "issue ", "<bool>"):
            assert internal not in ran.out, (args, internal, ran.out)
    top = trackkit("--help", env={"COLUMNS": "100"}).out
    assert "Jalalipoor and Kardehi Moghaddam 2021" in top and "Zolfagharnasab and Seif" in top
    assert "--version" in top and "--help" in top
    # the command's description is one paragraph that rich fills to the width: every line
    # but its last is nearly full (a hard line break would leave a short one)
    track = trackkit("track", "--help", env={"COLUMNS": "80"}).out.splitlines()
    start = next(i for i, line in enumerate(track) if "Track recorded data" in line)
    end = next(i for i in range(start, len(track)) if not track[i].strip())
    assert end - start >= 3
    assert all(len(line.rstrip()) >= 65 for line in track[start:end - 1]), track[start:end]


def test_version_prints_the_installed_package_version():
    from importlib.metadata import version

    ran = trackkit("--version")
    assert ran.code == 0 and ran.out.strip() == f"trackkit {version('trackkit')}", ran.text


@pytest.mark.slow
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_ctrl_c_with_workers_says_interrupted_once_and_leaves_no_process(command, tmp_path):
    """Ctrl-C in a terminal reaches the whole process group, the Dask workers too: the
    command says "interrupted" once, no worker or nanny speaks, nothing is left running.
    ``run`` goes through the installed ``trackkit`` script when there is one (its worker
    processes import the script again)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from tests.experiments.test_sweep import short_bo_cv_toml

    out = tmp_path / "out"
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    env.pop("TRACKKIT_DEBUG", None)
    script = Path(sys.executable).with_name("trackkit")
    start = [str(script)] if script.is_file() else [sys.executable, "-m", "trackkit.cli"]
    if command == "run":
        args = [*start, "run", "--runs", "100000", "--workers", "2", "--out", str(out)]
    else:
        scenario = short_bo_cv_toml(tmp_path / "short.toml")
        args = [sys.executable, "-m", "trackkit.cli", "sweep", str(scenario), "--param",
                "sensor.sigma_deg=1,2,3,4", "--runs", "2000", "--workers", "2", "--out",
                str(out)]
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (out / ".trackkit.lock").exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(6.0)  # the local cluster's workers are up and computing
    os.killpg(p.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
    _, err = p.communicate(timeout=120)
    time.sleep(2.0)
    try:
        os.killpg(p.pid, 0)
        left = subprocess.run(["ps", "-o", "pid,args", "-g", str(p.pid)], capture_output=True,
                              text=True).stdout
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        left = ""
    assert p.returncode == 130, err
    assert err.count("interrupted") == 1, err
    assert "nanny" not in err.lower() and "distributed." not in err, err
    assert "Traceback" not in err and "WARNING" not in err and not left, left
    if command == "run":
        assert not out.exists() or not any(out.iterdir())
    else:
        assert "run the same command again to resume" in err


# --- output directories: one command's files, listed in manifest.json -------------------------


def _names(out: Path) -> set[str]:
    return {p.name for p in out.iterdir()}


def _check_manifest(out: Path, command: str) -> dict:
    """manifest.json names the command and lists exactly the other files, with their sizes
    and sha256."""
    import hashlib
    import json
    from importlib.metadata import version

    doc = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert doc["command"] == command and doc["trackkit"] == version("trackkit")
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", doc["time"])
    listed = {f["name"]: f for f in doc["files"]}
    kept = {k.rstrip("/") for k in doc["kept"]}
    assert set(listed) | kept == _names(out) - {"manifest.json"} and not set(listed) & kept
    for name, f in listed.items():
        data = (out / name).read_bytes()
        assert f["bytes"] == len(data) and f["sha256"] == hashlib.sha256(data).hexdigest()
    return doc


def test_run_lists_its_files_and_removes_its_own_stale_ones(tmp_path):
    out = tmp_path / "out"
    first = trackkit("run", "radar-crossing", "--runs", "1", "--out", str(out))
    assert first.code == 0, first.text
    assert {"xy.png", "gospa.png"} <= _names(out)
    (out / "notes.txt").write_text("mine", encoding="utf-8")  # the user's: kept
    ran = trackkit("run", "cv-position", "--runs", "2", "--out", str(out))
    assert ran.code == 0, ran.text
    names = _names(out)
    # the multi-target run's figures were listed by its manifest and not written again
    assert "xy.png" not in names and "gospa.png" not in names and "notes.txt" in names
    doc = _check_manifest(out, "run")
    assert doc["kept"] == ["notes.txt"]
    assert doc["arguments"]["scenario"] == "cv-position" and doc["arguments"]["runs"] == 2
    assert {"results.json", "rmse.png", "report.html"} <= names


def test_another_commands_directory_is_refused_and_left_as_it_was(tmp_path):
    out = tmp_path / "out"
    assert trackkit("run", "cv-position", "--runs", "2", "--out", str(out)).code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    ran = trackkit("network", "net-baseline", "--runs", "1", "--out", str(out))
    assert_user_error(ran, 2, f"--out {out}", "`trackkit run`", "`trackkit network`",
                      "another --out")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_files_no_manifest_lists_are_not_overwritten(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text("{}", encoding="utf-8")  # someone else's
    ran = trackkit("run", "cv-position", "--runs", "2", "--out", str(out))
    assert_user_error(ran, 2, f"--out {out}", "results.json", "no trackkit manifest.json",
                      "would overwrite")
    assert _names(out) == {"results.json"}
    assert (out / "results.json").read_text(encoding="utf-8") == "{}"


def test_a_scenario_file_gets_its_own_default_directory(tmp_path):
    import os

    import trackkit as tk

    text = trackkit("show", "cv-position").out
    (tmp_path / "my.toml").write_text(text, encoding="utf-8")
    # in another directory, the trackkit under test is still the one imported here
    src = str(Path(tk.__file__).resolve().parents[1])
    env = {"PYTHONPATH": os.pathsep.join([src, *filter(None, [os.environ.get("PYTHONPATH")])])}
    bundled = trackkit("run", "cv-position", "--runs", "2", cwd=tmp_path, env=env)
    assert bundled.code == 0, bundled.text
    mine = trackkit("run", "my.toml", "--runs", "2", cwd=tmp_path, env=env)
    assert mine.code == 0, mine.text
    assert _names(tmp_path / "trackkit-out") == {"cv-position", "my"}
    _check_manifest(tmp_path / "trackkit-out" / "my", "run")
    assert _check_manifest(tmp_path / "trackkit-out" / "cv-position", "run")[
        "arguments"]["scenario"] == "cv-position"


# --- terminal tables: no number cut at 80 columns or in a pipe --------------------------------


def _fits_80(ran) -> None:
    """The tables (everything before the notes and the paths written) fit 80 columns and
    cut nothing."""
    assert ran.code == 0, ran.text
    tables = re.split(r"^(?:note:|wrote |messages:)", ran.out, maxsplit=1, flags=re.M)[0]
    assert "…" not in tables, ran.out
    assert max(len(line.rstrip()) for line in tables.splitlines()) <= 80, ran.out


def test_run_tables_keep_every_number_at_80_columns_in_a_pipe(tmp_path):
    import json

    out = tmp_path / "out"
    ran = trackkit("run", "--runs", "2", "--out", str(out), env={"COLUMNS": "80"})
    _fits_80(ran)
    doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
    for name in doc["filters"]:
        assert f" {name} " in ran.out
    # the IEKF's ANEES is large: printed whole, with its exponent
    anees = doc["filters"]["IEKF"]["anees"]
    assert f"{anees:.3g}" in ran.out or f"{anees:.4g}" in ran.out, ran.out


def test_a_network_table_folds_instead_of_cutting(tmp_path):
    ran = trackkit("network", "net-baseline", "--runs", "1", "--out", str(tmp_path / "n"),
                   env={"COLUMNS": "80"})
    _fits_80(ran)
    # every agent's per-target values whole, on one line
    assert len(re.findall(r"\d\.\d\d / \d\.\d\d / \d\.\d\d", ran.out)) == 3 * 2
    assert len(re.findall(r" \d+ / \d+ / \d+ ", ran.out)) == 3 * 3
    _check_manifest(tmp_path / "n", "network")


def test_the_sweep_summary_shows_the_swept_values_not_a_hash(tmp_path):
    import json

    from tests.experiments.test_sweep import short_bo_cv_toml

    scenario = short_bo_cv_toml(tmp_path / "short.toml")
    out = tmp_path / "sweep"
    ran = trackkit("sweep", str(scenario), "--param", "sensor.sigma_deg=1,2", "--param",
                   "filters.*.motion.q=x0.5,x2", "--runs", "2", "--out", str(out),
                   env={"COLUMNS": "80"})
    _fits_80(ran)
    doc = json.loads((out / "sweep.json").read_text(encoding="utf-8"))
    for point in doc["points"]:
        assert point["id"][:6] not in ran.out  # no point hash
    head = next(line for line in ran.out.splitlines() if "sigma_deg" in line)
    assert head.split()[:3] == ["sigma_deg", "q", "filter"]
    rows = [line.split() for line in ran.out.splitlines() if line.strip()[:4] in ("1.0 ", "2.0 ")]
    assert {(r[0], r[1]) for r in rows} == {("1.0", "x0.5"), ("1.0", "x2"), ("2.0", "x0.5"),
                                            ("2.0", "x2")}
    assert "q = filters.*.motion.q" in ran.out
    # the report files are this write's; the stored blocks are kept beside them
    assert {"campaign.json", "points/"} <= set(_check_manifest(out, "sweep")["kept"])


# --- saying what a long command is doing ------------------------------------------------------


def test_identify_says_what_it_is_doing_on_stderr(tmp_path):
    out = tmp_path / "out"
    ran = trackkit("identify", str(LOG), "--inputs", str(INPUTS), "--out", str(out))
    assert ran.code == 0, ran.text
    stages = [line for line in ran.err.splitlines() if line.endswith(" ...")]
    assert [s.split()[0] for s in stages] == ["reading", "identifying", "writing"] or [
        s.split()[0] for s in stages] == ["reading", "compiling", "writing"], ran.err
    assert str(LOG) in stages[0] and str(INPUTS) in stages[0]
    assert "16 coefficients with ekf (167 samples)" in stages[1]
    assert str(out) in stages[2]
    _check_manifest(out, "identify")


def test_identify_says_it_compiles_the_filter_the_first_time(tmp_path):
    """An empty numba cache: the command says it compiles (about half a minute), and a
    Ctrl-C then stops it at once, in one line, leaving nothing behind."""
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "out"
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1",
           "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.Popen([sys.executable, "-m", "trackkit.cli", "identify", str(LOG),
                          "--inputs", str(INPUTS), "--out", str(out)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env)
    lines = []
    for line in p.stderr:
        lines.append(line)
        if line.startswith("compiling") or line.startswith("writing"):
            break
    p.send_signal(signal.SIGINT)
    _, rest = p.communicate(timeout=120)
    err = "".join(lines) + rest
    assert lines[-1].startswith("compiling the ekf filter (the first run only"), err
    assert "identifying the 16 coefficients" in lines[-1]
    assert p.returncode == 130 and err.count("interrupted") == 1, err
    assert "Traceback" not in err and not out.exists()


def test_network_says_how_many_runs_before_it_starts(tmp_path):
    f = tmp_path / "tiny.toml"
    from tests.test_network_scenarios import TINY

    f.write_text(TINY, encoding="utf-8")  # its run.runs = 2
    ran = trackkit("network", str(f), "--out", str(tmp_path / "o"))
    assert ran.code == 0, ran.text
    first = ran.err.splitlines()[0]
    assert first.startswith("net-tiny: 2 Monte Carlo runs (the scenario's run.runs; --runs N "
                            "for fewer), agents in this process -> "), ran.err
    assert "2/2 runs" in ran.err
    _check_manifest(tmp_path / "o", "network")


def test_an_agent_killed_without_restart_is_said_so(tmp_path):
    f = tmp_path / "tiny.toml"
    from tests.test_network_scenarios import TINY

    f.write_text(TINY, encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "1", "--agents", "processes", "--kill",
                   "2@20", "--out", str(tmp_path / "o"))
    assert ran.code == 0, ran.text
    assert "agent 2 killed at 20 s, not restarted" in ran.out and "None" not in ran.out

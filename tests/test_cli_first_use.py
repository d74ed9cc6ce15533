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
    assert "sar_trial_inputs.csv" not in ran.text  # the inputs are not to blame
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

"""Bad scenario files through the real CLI: a user's bad scenario file stops
``trackkit run`` with exit code 2 and a message that names the file, the field and the value,
with no traceback or numpy warning and nothing written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.cli_helpers import assert_user_error, trackkit
from trackkit import scenario as S

BO_CV = (Path(S.__file__).parent / "scenarios" / "bo-cv.toml").read_text(encoding="utf-8")


def _edit(old: str, new: str) -> Callable[[Path], Path]:
    """A bo-cv file with one line changed."""
    assert BO_CV.count(old) == 1, old

    def make(folder: Path) -> Path:
        p = folder / "bad.toml"
        p.write_text(BO_CV.replace(old, new), encoding="utf-8")
        return p
    return make


def _latin1(folder: Path) -> Path:
    p = folder / "latin1.toml"
    p.write_bytes(BO_CV.replace("Classic", "Classic \xb5").encode("latin-1"))
    return p


def _directory(folder: Path) -> Path:
    p = folder / "scenario.toml"
    p.mkdir()
    return p


UKF = 'type = "UKF"\n'
CASES = {
    # case: (make the file, names the message must carry besides the file's path)
    "ukf-alpha-not-a-number": (_edit(UKF, UKF + 'options = { alpha = "abc" }\n'),
                               ["filters.2.options.alpha", "'abc'", "UKF", "a number > 0"]),
    "ukf-alpha-negative": (_edit(UKF, UKF + "options = { alpha = -1.0 }\n"),
                           ["filters.2.options.alpha", "-1.0", "UKF", "a number > 0"]),
    "iekf-iterations-not-an-integer": (
        _edit("iterations = 5", "iterations = 2.5"),
        ["filters.1.options.iterations", "2.5", "IEKF", "an integer >= 1"]),
    "name-escapes-the-output-folder": (
        _edit('name = "bo-cv"', 'name = "../../escaped"'),
        ["name", "'../../escaped'", "plain file name"]),
    "name-is-an-absolute-path": (_edit('name = "bo-cv"', 'name = "/tmp/trackkit-abs"'),
                                 ["name", "'/tmp/trackkit-abs'", "plain file name"]),
    "process-noise-overflows": (_edit("q = 1e-4", "q = 1e300"),
                                ["target.motion.q", "1e+300", "expected q <="]),
    "bearing-noise-beyond-precision": (
        _edit("sigma_deg = 1.0", "sigma_deg = 1e-9"),
        ["observers.0.sensor.sigma_deg", "1e-09", "expected sigma_deg >="]),
    "not-utf8": (_latin1, ["not UTF-8", "0xb5", "line 4"]),
    "a-directory": (_directory, ["is a directory", "expected a scenario .toml file"]),
}


@pytest.mark.parametrize("case", CASES)
def test_a_bad_scenario_stops_the_run_in_words(case, tmp_path):
    make, names = CASES[case]
    bad = make(tmp_path)
    out = tmp_path / "out"
    ran = trackkit("run", str(bad), "--runs", "2", "--out", str(out), cwd=tmp_path)
    assert_user_error(ran, 2, str(bad), *names)
    assert "problem(s)" in ran.text or case in ("not-utf8", "a-directory")
    assert not out.exists(), "a refused scenario wrote output"
    assert not (tmp_path.parent / "escaped").exists() and not (tmp_path / "trackkit-out").exists()

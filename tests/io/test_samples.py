"""The recorded samples shipped in the package (trackkit.io.samples): found by name, shipped as
package data with their licence, small, and read cleanly."""

import fnmatch
import tomllib
from pathlib import Path

import numpy as np
import pytest

from trackkit.io import read_ais_csv, read_opensky_csv, samples

ROOT = Path(__file__).resolve().parents[2]


def test_samples_by_name_with_their_licence_as_package_data():
    assert set(samples.SAMPLES) == {"solent-ais", "opensky-adsb"}
    folder = Path(samples.__file__).parent
    shipped = [samples.path(n) for n in samples.SAMPLES] + [
        folder / "LICENSE-stonesoup-demo-data.txt"]
    assert all(p.is_file() and p.parent == folder for p in shipped)
    assert "MIT License" in shipped[-1].read_text(encoding="utf-8")
    assert sum(p.stat().st_size for p in shipped) < 600_000  # the package stays small
    # every file is matched by a package-data pattern, so that a wheel carries it
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["trackkit"]
    pkg = folder.parents[1]
    for p in shipped:
        rel = p.relative_to(pkg).as_posix()
        assert any(fnmatch.fnmatch(rel, pat) for pat in patterns), rel
    with pytest.raises(ValueError, match="no bundled sample named 'solent'; expected one of "
                                         "solent-ais, opensky-adsb"):
        samples.path("solent")


def test_solent_sample_reads_cleanly():
    r, rep = read_ais_csv(samples.path("solent-ais"), on_bad="stop")
    assert rep.rows_read == 2159 and rep.n_skipped == 0 and rep.duplicates == 1
    assert len(r.ids) == 77 and str(rep.epoch) == "2016-01-12T13:02:11.000000000"
    assert 590 < r.time[-1] - r.time[0] < 600                       # ten minutes
    assert np.hypot(r.x, r.y).max() < 30e3                          # all in the Solent


def test_opensky_sample_reads_cleanly():
    r, rep = read_opensky_csv(samples.path("opensky-adsb"), on_bad="stop")
    assert rep.rows_read == 1556 and rep.n_skipped == 0 and rep.duplicates == 104
    assert len(r.ids) == 62 and str(rep.epoch) == "2021-07-12T13:59:58.000000000"
    assert r.time[-1] - r.time[0] < 305                              # five minutes
    lat, lon, alt = r.geodetic()
    assert 49.9 < lat.min() and lat.max() < 54.6 and -5.1 < lon.min() and lon.max() < 1.7


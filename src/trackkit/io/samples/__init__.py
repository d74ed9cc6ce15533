"""Recorded data shipped with trackkit, so that there is something to track at once:

    trackkit track solent-ais --as-radar
    trackkit track opensky-adsb --as-radar

    from trackkit.io import samples, read_ais_csv
    reports, report = read_ais_csv(samples.path("solent-ais"))

* ``solent-ais``: the first 10 minutes (2159 reports of 77 vessels) of the Solent AIS
  recording of 12 January 2016, from 13:02:11 UTC (``SolentAIS_20160112_130211.csv``);
* ``opensky-adsb``: the first 5 minutes (1556 state vectors of 62 aircraft over England
  and Wales) of the OpenSky Network recording of 12 July 2021, from 14:00 UTC
  (``OpenSky_Plane_States.csv``).

Both are the first lines of the files, unchanged, from the Stone Soup project's demonstration
data (MIT licence, ``LICENSE-stonesoup-demo-data.txt`` beside them).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["SAMPLES", "path"]

_HERE = Path(__file__).resolve().parent

#: name -> (file in this folder, one-line description)
SAMPLES: dict[str, tuple[str, str]] = {
    "solent-ais": ("solent-ais.csv", "AIS: 77 vessels in the Solent, 10 minutes (Jan 2016)"),
    "opensky-adsb": ("opensky-adsb.csv",
                     "ADS-B (OpenSky): 62 aircraft over England and Wales, 5 minutes (Jul 2021)"),
}


def path(name: str) -> Path:
    """The file of a bundled sample, by name (see :data:`SAMPLES`)."""
    if name not in SAMPLES:
        raise ValueError(f"no bundled sample named {name!r}; expected one of "
                         f"{', '.join(SAMPLES)}")
    return _HERE / SAMPLES[name][0]

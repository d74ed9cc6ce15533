"""Recorded data in: readers of AIS, ADS-B and detection files, and the local frame.

    from trackkit import io as tio
    reports, report = tio.read_ais_csv(path)              # Solent layout; AisColumns(...) else
    reports, report = tio.read_opensky_csv(path)          # OpenSky state vectors
    reports, report = tio.read_recording(path)            # any layout in tio.LAYOUTS,
                                                          # recognised from its first lines
    scans, report = tio.read_detections(path, DetectionColumns(...), DetectionUnits(...))
    print(report.summary())                               # skipped, sorted, duplicates

Every reader validates with array operations, names a bad record's file, line and column,
and with ``on_bad="skip"`` (the default) skips and counts it (``on_bad="stop"`` raises at the
first). ``report.rows_read == report.rows_kept + report.n_skipped + report.duplicates``.
The AIS and ADS-B readers need only a record's time, identity and position: an optional field
(course, speed, heading, altitude) that is bad or "not available" is set missing, the record
kept, and counted by field and reason in ``report.set_missing``.
Positions are converted once to a local east-north-up frame (:class:`EnuFrame`, x east,
y north, z up, metres) at the data's median position or a given reference; times are float
seconds from ``report.epoch``.
"""

from trackkit.io._table import read_header
from trackkit.io.adsb import read_opensky_csv
from trackkit.io.ais import SOLENT, AisColumns, read_ais_csv
from trackkit.io.aivdm import read_aivdm
from trackkit.io.detections import DetectionColumns, DetectionUnits, read_detections
from trackkit.io.frames import (
    KNOT,
    NAUTICAL_MILE,
    EnuFrame,
    course_from_velocity,
    velocity_from_course,
)
from trackkit.io.layouts import LAYOUTS, Layout, read_recording, recognise
from trackkit.io.records import BadRecord, ReadReport, Reports
from trackkit.io.sbs import read_sbs
from trackkit.io.scans import Scan, Scans

__all__ = [
    "KNOT",
    "LAYOUTS",
    "NAUTICAL_MILE",
    "SOLENT",
    "Scan",
    "Scans",
    "AisColumns",
    "BadRecord",
    "DetectionColumns",
    "DetectionUnits",
    "EnuFrame",
    "Layout",
    "ReadReport",
    "Reports",
    "course_from_velocity",
    "read_ais_csv",
    "read_aivdm",
    "read_detections",
    "read_header",
    "read_opensky_csv",
    "read_recording",
    "read_sbs",
    "recognise",
    "velocity_from_course",
]

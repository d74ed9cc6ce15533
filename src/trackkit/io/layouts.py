"""The layouts of recorded AIS and ADS-B data that people have, recognised without options.

    layout = recognise("ais-2023-01-01.csv")       # LAYOUTS["noaa"], from the header
    reports, report = read_recording("ais-2023-01-01.csv")
    report.layout                                   # "noaa"

A CSV layout is recognised by its key columns (time, identity, latitude, longitude) in any
order, the names compared without case, spaces, underscores or a leading ``#``; other columns
are used where known (course, speed, heading) and otherwise ignored. NMEA AIS sentences and
SBS-1 (BaseStation) lines are recognised from the first lines. Only the first 64 KiB of a file
are read to tell. The layouts:

* ``solent``: ``Time, MMSI, Latitude_degrees, Longitude_degrees, COG_degrees, SOG_knots``
  (the Solent recording of Stone Soup's demo data);
* ``noaa``: NOAA MarineCadastre (``MMSI, BaseDateTime, LAT, LON, SOG, COG, Heading, ...``;
  releases differ in column order, the spelling ``TranscieverClass`` and extra columns such
  as ``ETA``). COG -49.6 is "not available" there (360 as a 12-bit field read as signed), as
  360 is; any other negative course is set missing as "outside [0, 360]";
* ``dma``: the Danish Maritime Authority (``# Timestamp, Type of mobile, MMSI, Latitude,
  Longitude, ..., ROT, SOG, COG, Heading, ...``), times ``dd/mm/yyyy HH:MM:SS``;
* ``opensky``: OpenSky state vectors (``time, icao24, lat, lon, ...``);
* ``nmea-ais``: raw AIS sentences ``!AIVDM``/``!AIVDO`` (:mod:`trackkit.io.aivdm`);
* ``sbs1``: ADS-B in the SBS-1 BaseStation format (:mod:`trackkit.io.sbs`).

Each layout maps to a tracker profile (``Layout.kind``): the AIS layouts to ``"ais"``, OpenSky
and SBS-1 to ``"opensky"``.
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass, field, replace

from trackkit.io import _reports
from trackkit.io._table import Progress, csv_header
from trackkit.io.adsb import read_opensky_csv
from trackkit.io.ais import AisColumns, read_ais_csv
from trackkit.io.aivdm import looks_like_aivdm, read_aivdm
from trackkit.io.records import ReadReport, Reports
from trackkit.io.sbs import looks_like_sbs, read_sbs

__all__ = ["LAYOUTS", "Layout", "read_recording", "recognise"]

SNIFF_BYTES = 1 << 16  # what is read to recognise a layout


@dataclass(frozen=True)
class Layout:
    """A layout: its ``name``, the tracker profile it maps to (``kind``), its ``title`` and,
    for CSV layouts, the accepted column names by role (normalised, see ``_norm``); the
    roles time, id, lat, lon are the key columns."""

    name: str
    kind: str
    title: str
    columns: dict[str, tuple[str, ...]] = field(default_factory=dict)
    time_format: str = "iso"
    codes: dict[str, tuple[float, ...]] = field(default_factory=dict)

    @property
    def expected(self) -> str:
        """The key columns, or the line format, in words (for error messages)."""
        if not self.columns:
            return {"nmea-ais": "!AIVDM/!AIVDO sentences",
                    "sbs1": "MSG,3,... lines of 22 fields"}[self.name]
        return ", ".join(self.columns[r][0] for r in KEYS)


KEYS = ("time", "id", "lat", "lon")
_AIS_CODES = {"course": (360.0,), "speed": (102.3,), "heading": (511.0,)}

#: The known layouts by name, in the order they are tried.
LAYOUTS: dict[str, Layout] = {lay.name: lay for lay in (
    Layout("solent", "ais", "AIS CSV, Solent layout", {
        "time": ("Time",), "id": ("MMSI",), "lat": ("Latitude_degrees",),
        "lon": ("Longitude_degrees",), "course": ("COG_degrees",), "speed": ("SOG_knots",)},
        codes=_AIS_CODES),
    Layout("noaa", "ais", "AIS CSV, NOAA MarineCadastre layout", {
        "time": ("BaseDateTime",), "id": ("MMSI",), "lat": ("LAT",), "lon": ("LON",),
        "course": ("COG",), "speed": ("SOG",), "heading": ("Heading",)},
        codes={**_AIS_CODES, "course": (360.0, -49.6)}),
    Layout("dma", "ais", "AIS CSV, Danish Maritime Authority layout", {
        "time": ("# Timestamp", "Timestamp"), "id": ("MMSI",), "lat": ("Latitude",),
        "lon": ("Longitude",), "course": ("COG",), "speed": ("SOG",),
        "heading": ("Heading",)}, time_format="%d/%m/%Y %H:%M:%S", codes=_AIS_CODES),
    Layout("opensky", "opensky", "ADS-B, OpenSky state vectors", {
        "time": ("time",), "id": ("icao24",), "lat": ("lat",), "lon": ("lon",)}),
    Layout("nmea-ais", "ais", "AIS, NMEA 0183 sentences"),
    Layout("sbs1", "opensky", "ADS-B, SBS-1 BaseStation"),
)}


def _norm(name: str) -> str:
    """A column name as compared: lower case, letters and digits only."""
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _first_lines(path: str) -> list[str]:
    with open(path, "rb") as fh:
        head = fh.read(SNIFF_BYTES)
    text = head.decode("utf-8-sig", errors="replace")
    lines = text.splitlines()
    if len(head) == SNIFF_BYTES and len(lines) > 1:
        lines = lines[:-1]  # the last may be cut
    return [ln for ln in lines if ln.strip()]


def _match(layout: Layout, header: list[str]) -> dict[str, str] | None:
    """The file's column of each role of ``layout``, or None when a key column is missing."""
    have = {_norm(h): h for h in header}
    found = {}
    for role, names in layout.columns.items():
        hit = next((have[_norm(n)] for n in names if _norm(n) in have), None)
        if hit is not None:
            found[role] = hit
    return found if all(k in found for k in KEYS) else None


def recognise(path: str | os.PathLike) -> Layout | None:
    """The layout of a file from its first lines, or None when none fits."""
    lines = _first_lines(os.fspath(path))
    if not lines:
        return None
    if looks_like_aivdm(lines):
        return LAYOUTS["nmea-ais"]
    if looks_like_sbs(lines):
        return LAYOUTS["sbs1"]
    header = [h.strip() for h in next(csv.reader([lines[0]]), [])]
    for layout in LAYOUTS.values():
        if layout.columns and _match(layout, header) is not None:
            return layout
    return None


def expected_layouts() -> str:
    """The known layouts and what recognises each, for an error message."""
    return "; ".join(f"{lay.title} ({lay.expected})" for lay in LAYOUTS.values())


def ais_columns(layout: Layout, header: list[str]) -> AisColumns:
    """The :class:`AisColumns` of an AIS CSV layout, with the file's own column names."""
    found = _match(layout, header)
    if found is None:
        raise ValueError(f"the header {', '.join(map(repr, header))} is not the {layout.title} "
                         f"(expected the columns {layout.expected})")
    c = layout.codes
    return AisColumns(time=found["time"], id=found["id"], lat=found["lat"], lon=found["lon"],
                      course=found.get("course"), speed=found.get("speed"),
                      heading=found.get("heading"), time_format=layout.time_format,
                      course_unavailable=c["course"], speed_unavailable=c["speed"],
                      heading_unavailable=c["heading"][0])


def read_recording(path: str | os.PathLike, layout: Layout | str | None = None,
                   on_bad: str = "skip", *, reference: _reports.Reference = None, epoch=None,
                   bounds: tuple[float, float, float, float] | None = None,
                   progress: Progress | None = None, max_listed: int = 100
                   ) -> tuple[Reports, ReadReport]:
    """Read a file of position reports in any known layout (recognised when ``layout`` is
    None); the arguments are those of :func:`~trackkit.io.read_ais_csv`."""
    path = os.fspath(path)
    lay = LAYOUTS[layout] if isinstance(layout, str) else layout or recognise(path)
    if lay is None:
        raise ValueError(f"{path}: not a known layout of position reports; expected "
                         f"{expected_layouts()} (or name the columns: AisColumns)")
    kw = dict(on_bad=on_bad, reference=reference, epoch=epoch, bounds=bounds,
              progress=progress, max_listed=max_listed)
    if lay.name == "nmea-ais":
        return read_aivdm(path, **kw)
    if lay.name == "sbs1":
        return read_sbs(path, **kw)
    if lay.name == "opensky":
        reports, report = read_opensky_csv(path, **kw)
        return reports, replace(report, layout=lay.name)
    return read_ais_csv(path, ais_columns(lay, csv_header(path)), layout=lay.name, **kw)

"""Small files in each recorded-data layout, written here from the published column lists and
message formats (NOAA MarineCadastre, Danish Maritime Authority, NMEA AIS sentences built with
pyais's encoder, SBS-1 BaseStation lines): a few vessels or aircraft on straight legs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

EPOCH = np.datetime64("2024-01-05T12:00:00", "s")
NOAA_COLUMNS = ["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG", "Heading", "VesselName",
                "IMO", "CallSign", "VesselType", "Status", "Length", "Width", "Draft", "Cargo",
                "TransceiverClass"]
DMA_COLUMNS = ["# Timestamp", "Type of mobile", "MMSI", "Latitude", "Longitude",
               "Navigational status", "ROT", "SOG", "COG", "Heading", "IMO", "Callsign", "Name",
               "Ship type", "Cargo type", "Width", "Length",
               "Type of position fixing device", "Draught", "Destination", "ETA",
               "Data source type", "A", "B", "C", "D"]


@dataclass
class Report:
    t: float  # s from EPOCH
    ident: int
    lat: float
    lon: float
    sog: float  # kn
    cog: float  # deg
    heading: float  # deg


def fleet(n: int = 4, steps: int = 40, dt: float = 6.0) -> list[Report]:
    """``n`` vessels on straight legs near 50.8 N, 1.1 W, a report every ``dt`` s, in time
    order."""
    out = []
    for k in range(steps):
        for v in range(n):
            t = k * dt + v * 0.5
            cog = (40.0 + 70.0 * v) % 360
            sog = 6.0 + v
            d = sog * 1852 / 3600 * t
            lat = 50.8 + 0.01 * v + d * np.cos(np.deg2rad(cog)) / 111_320
            lon = -1.1 + d * np.sin(np.deg2rad(cog)) / (111_320 * np.cos(np.deg2rad(50.8)))
            out.append(Report(t, 235_000_001 + v, lat, lon, sog, cog, round(cog)))
    return out


def iso(t: float) -> str:
    return str(EPOCH + np.timedelta64(int(round(t * 1000)), "ms"))


def write_noaa(path: Path, reports: list[Report], columns: list[str] | None = None,
               special: dict[int, dict[str, str]] | None = None) -> Path:
    """A NOAA MarineCadastre file; ``special[i]`` overrides fields of row ``i``."""
    columns = columns or NOAA_COLUMNS
    lines = [",".join(columns)]
    for i, r in enumerate(reports):
        row = {"MMSI": str(r.ident), "BaseDateTime": iso(r.t)[:19], "LAT": f"{r.lat:.6f}",
               "LON": f"{r.lon:.6f}", "SOG": f"{r.sog:.1f}", "COG": f"{r.cog:.1f}",
               "Heading": f"{r.heading:.0f}", "VesselName": f"VESSEL {r.ident % 100}",
               "IMO": "", "CallSign": "", "VesselType": "70", "Status": "0", "Length": "100",
               "Width": "20", "Draft": "5.5", "Cargo": "70", "TransceiverClass": "A",
               "TranscieverClass": "A", "ETA": ""}
        row.update((special or {}).get(i, {}))
        lines.append(",".join(row[c] for c in columns))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_dma(path: Path, reports: list[Report],
              special: dict[int, dict[str, str]] | None = None) -> Path:
    """A Danish Maritime Authority file (day-first times)."""
    lines = [",".join(DMA_COLUMNS)]
    for i, r in enumerate(reports):
        t = EPOCH + np.timedelta64(int(round(r.t)), "s")
        s = str(t)
        stamp = f"{s[8:10]}/{s[5:7]}/{s[0:4]} {s[11:19]}"
        row = dict.fromkeys(DMA_COLUMNS, "")
        row.update({"# Timestamp": stamp, "Type of mobile": "Class A", "MMSI": str(r.ident),
                    "Latitude": f"{r.lat:.6f}", "Longitude": f"{r.lon:.6f}",
                    "Navigational status": "Under way using engine", "ROT": "0.0",
                    "SOG": f"{r.sog:.1f}", "COG": f"{r.cog:.1f}", "Heading": f"{r.heading:.0f}",
                    "Name": f"VESSEL {r.ident % 100}", "Ship type": "Cargo",
                    "Data source type": "AIS"})
        row.update((special or {}).get(i, {}))
        lines.append(",".join(row[c] for c in DMA_COLUMNS))
    path.write_text("\n".join(lines) + "\n")
    return path


def sentences(msg: dict, seq_id: int = 0) -> list[str]:
    """``!AIVDM`` sentences of one message (pyais's encoder computes the checksums)."""
    from pyais import encode_dict

    return encode_dict(msg, talker_id="AI", sentence_type="VDM", radio_channel="A",
                       seq_id=seq_id)


def tag_block(t: int, source: str = "rx1") -> str:
    """An NMEA 4.10 tag block with unix time ``t`` and its checksum."""
    body = f"s:{source},c:{t}"
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"\\{body}*{x:02X}\\"


def position(r: Report, msg_type: int = 1, **over) -> dict:
    return {"type": msg_type, "mmsi": r.ident, "lat": r.lat, "lon": r.lon, "speed": r.sog,
            "course": r.cog, "heading": r.heading, "second": int(r.t) % 60, **over}


def unix(t: float) -> float:
    return float(EPOCH.astype("datetime64[s]").astype(np.int64)) + t


def sbs_line(msg: int, hex_ident: str, t: float, *, alt: str = "", speed: str = "",
             track: str = "", lat: str = "", lon: str = "", vrate: str = "",
             callsign: str = "") -> str:
    stamp = iso(t)
    date, tod = stamp[:10].replace("-", "/"), stamp[11:23]
    fields = ["MSG", str(msg), "1", "1", hex_ident, "1", date, tod, date, tod, callsign, alt,
              speed, track, lat, lon, vrate, "", "0", "0", "0", "0"]
    return ",".join(fields)

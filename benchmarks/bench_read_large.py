"""Reading AIS files larger than memory: peak RSS against the number of reports.

Writes generated AIS reports in the NOAA MarineCadastre layout (1 000 vessels, a report each
10 s, some courses "not available" as -49.6 and 360) into a temporary directory, then reads
each file with :func:`trackkit.io.read_recording` in a fresh process and reports its peak RSS
(``VmHWM``), the bytes of the output (:class:`~trackkit.io.Reports`), and what is held
above the output per report. Reading is streamed in blocks of a few MB, so the file itself is
never in memory; what grows with the file is the output and the arrays that sort it.

    nice python benchmarks/bench_read_large.py            # 1M, 3M, 10M reports
    nice python benchmarks/bench_read_large.py 200000 1000000
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

SIZES = (1_000_000, 3_000_000, 10_000_000)
VESSELS = 1000
BATCH = 200_000
COLUMNS = ("MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG", "Heading", "VesselName",
           "TransceiverClass")


def write_noaa(path: str, n: int, seed: int = 0) -> None:
    """``n`` reports of :data:`VESSELS` vessels drifting on straight legs, in time order."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(seed)
    lat0 = 40.0 + rng.uniform(0, 1, VESSELS)
    lon0 = -74.0 + rng.uniform(0, 1, VESSELS)
    cog = rng.uniform(0, 360, VESSELS)
    sog = rng.uniform(0, 20, VESSELS)
    start = np.datetime64("2024-01-01T00:00:00", "s")
    schema = pa.schema([(c, pa.string()) for c in COLUMNS])
    with pacsv.CSVWriter(path, schema, write_options=pacsv.WriteOptions(
            quoting_style="none")) as w:
        for a in range(0, n, BATCH):
            k = np.arange(a, min(a + BATCH, n))
            v = k % VESSELS
            t = k // VESSELS * 10
            d = sog[v] * 1852 / 3600 * t
            lat = lat0[v] + d * np.cos(np.deg2rad(cog[v])) / 111_320
            lon = lon0[v] + d * np.sin(np.deg2rad(cog[v])) / 85_000
            c = np.round(cog[v], 1).astype(str)
            c[k % 97 == 0] = "-49.6"
            c[k % 89 == 0] = "360.0"
            when = (start + t.astype("timedelta64[s]")).astype(str)
            cols = [(368_000_000 + v).astype(str), when, np.round(lat, 5).astype(str),
                    np.round(lon, 5).astype(str), np.round(sog[v], 1).astype(str), c,
                    np.round(cog[v]).astype(int).astype(str), np.full(len(k), "VESSEL"),
                    np.full(len(k), "A")]
            w.write_table(pa.table([pa.array(x) for x in cols], schema=schema))


def _status(key: str) -> int:
    """A field of /proc/self/status in bytes (VmRSS now, VmHWM the peak of this process;
    ru_maxrss would carry the parent's peak over the exec)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    raise KeyError(key)


def read_one(path: str) -> dict:
    """Read ``path`` (in this process) and measure."""
    from trackkit.io import read_recording

    base = _status("VmHWM")
    t0 = time.perf_counter()
    r, rep = read_recording(path)
    wall = time.perf_counter() - t0
    peak = _status("VmHWM")
    out = sum(getattr(r, k).nbytes for k in ("time", "code", "x", "y", "z", "vx", "vy", "vz",
                                              "line")) + sum(v.nbytes for v in r.extra.values())
    return {"reports": rep.rows_kept, "file_bytes": os.path.getsize(path), "wall_s": wall,
            "base_rss": base, "peak_rss": peak, "output_bytes": out,
            "course_missing": dict(rep.set_missing.get("course", {}))}


def main(sizes: tuple[int, ...]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        print(f"{'reports':>10} {'file MB':>8} {'read s':>7} {'peak RSS MB':>11} "
              f"{'output MB':>9} {'above output MB':>15} {'B/report':>8} "
              f"{'above output B/report':>21}")
        for n in sizes:
            path = os.path.join(tmp, f"noaa-{n}.csv")
            write_noaa(path, n)
            res = subprocess.run([sys.executable, __file__, "--read", path], check=True,
                                 capture_output=True, text=True)
            m = json.loads(res.stdout)
            os.unlink(path)
            held = m["peak_rss"] - m["base_rss"]
            above = held - m["output_bytes"]
            print(f"{m['reports']:>10} {m['file_bytes'] / 1e6:>8.0f} {m['wall_s']:>7.1f} "
                  f"{m['peak_rss'] / 1e6:>11.0f} {m['output_bytes'] / 1e6:>9.0f} "
                  f"{above / 1e6:>15.0f} {held / m['reports']:>8.0f} "
                  f"{above / m['reports']:>21.0f}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--read":
        print(json.dumps(read_one(sys.argv[2])))
    else:
        main(tuple(int(a) for a in sys.argv[1:]) or SIZES)

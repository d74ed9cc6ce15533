"""Reading holds memory in proportion to the reports it returns, never to the file: the peak
(numpy arrays and Python objects, traced by tracemalloc) is the same for files of the same
reports with wider columns that are ignored (the file is streamed in blocks, never held
whole), and each more report adds a few times its output bytes."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from trackkit.io import _table, read_recording

COLUMNS = ("MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG", "Heading", "VesselName",
           "TransceiverClass")


def _write(path, n: int, pad: int = 0) -> None:
    """``n`` NOAA-layout reports of 500 vessels; ``pad`` characters of vessel name each."""
    k = np.arange(n)
    v = k % 500
    t = (np.datetime64("2024-01-01T00:00:00", "s")
         + (k // 500 * 10).astype("timedelta64[s]")).astype(str)
    lat = np.round(40 + v * 1e-3 + k * 1e-7, 5).astype(str)
    lon = np.round(-74 + v * 1e-3 - k * 1e-7, 5).astype(str)
    cols = [(368_000_000 + v).astype(str), t, lat, lon, np.full(n, "10.2"),
            np.where(k % 97 == 0, "-49.6", "123.4"), np.full(n, "123"),
            np.full(n, "V" * (pad + 1)), np.full(n, "A")]
    schema = pa.schema([(c, pa.string()) for c in COLUMNS])
    pacsv.write_csv(pa.table([pa.array(c) for c in cols], schema=schema), path,
                    write_options=pacsv.WriteOptions(quoting_style="none"))


def _peak(path) -> tuple[int, int, int]:
    """(peak traced bytes, output bytes, reports kept) of reading ``path``."""
    tracemalloc.start()
    try:
        r, rep = read_recording(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rep.layout == "noaa" and rep.n_skipped == 0
    out = sum(getattr(r, k).nbytes for k in ("time", "code", "x", "y", "z", "vx", "vy", "vz",
                                              "line")) + sum(v.nbytes for v in r.extra.values())
    return peak, out, len(r)


def test_peak_memory_grows_with_the_reports_not_with_the_file(tmp_path, monkeypatch):
    # 64 KiB blocks and reads, so that small files are many blocks: pyarrow reads up to 32
    # blocks ahead of the parse, the fixed part of the peak
    monkeypatch.setattr(_table, "BLOCK_SIZE", 1 << 16)
    monkeypatch.setattr(_table, "READ_SIZE", 1 << 16)
    files = {name: tmp_path / f"{name}.csv" for name in ("small", "big", "wide", "wider")}
    _write(files["small"], 10_000)
    _write(files["big"], 100_000)
    _write(files["wide"], 4_000, pad=1000)
    _write(files["wider"], 4_000, pad=3000)
    extra_bytes = files["wider"].stat().st_size - files["wide"].stat().st_size
    assert extra_bytes > 7.5e6
    peak = {name: _peak(f) for name, f in files.items()}
    # the same reports in a file 8 MB larger: the same peak, within half a MB (a copy of the
    # file, or of its ignored columns, would add 8 MB)
    assert abs(peak["wider"][0] - peak["wide"][0]) < 0.5e6
    # ten times the reports: each more report holds a few times its output, nothing more
    (p_small, out_small, n_small), (p_big, out_big, n_big) = peak["small"], peak["big"]
    per_report = (p_big - p_small) / (n_big - n_small)
    out_per_report = (out_big - out_small) / (n_big - n_small)
    assert per_report < 5 * out_per_report

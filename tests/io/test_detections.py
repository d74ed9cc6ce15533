"""Detection files (CSV and Parquet, Cartesian and polar, unit options) to Scans."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from trackkit.io import NAUTICAL_MILE, DetectionColumns, DetectionUnits, read_detections
from trackkit.io.scans import Scans


def _scans():
    return Scans.from_scans([
        (0.0, 0, [[1.0, 2.0], [3.0, 4.0]]),
        (1.0, 0, np.empty((0, 2))),                  # a sweep that saw nothing
        (1.0, 1, [[5.5, 6.25]]),
        (2.5, 0, [[0.1, 1e-3], [-7.0, 8.0], [9.0, 9.0]]),
    ])


def test_scans_csv_reads_back_exactly(tmp_path):
    s = _scans()
    s.to_csv(tmp_path / "s.csv")
    r, rep = read_detections(tmp_path / "s.csv", DetectionColumns(x="z0", y="z1"))
    assert r.equals(s)
    assert rep.rows_read == rep.rows_kept == 7 and rep.n_skipped == rep.duplicates == 0
    assert rep.epoch is None


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_cartesian_in_km_with_iso_times_shuffled_and_duplicated(tmp_path, fmt):
    rows = [  # time, sensor, x km, y km (None: empty-scan marker)
        ("2024-03-01T10:00:01.5Z", 0, 1.0, 2.0),
        ("2024-03-01T10:00:00Z", 1, 0.5, -0.25),
        ("2024-03-01T10:00:00Z", 0, None, None),
        ("2024-03-01T10:00:01.5Z", 0, 3.0, 4.0),
        ("2024-03-01T10:00:01.5Z", 0, 1.0, 2.0),     # an exact duplicate
        ("2024-03-01T11:00:00+01:00", 1, 7.0, 8.0),  # = 10:00:00 UTC
    ]
    path = tmp_path / f"d.{fmt}"
    if fmt == "csv":
        path.write_text("t,radar,east_km,north_km\n" + "".join(
            f"{t},{c},{'' if x is None else x},{'' if y is None else y}\n" for t, c, x, y in rows))
    else:
        pq.write_table(pa.table({"t": [r[0] for r in rows], "radar": [r[1] for r in rows],
                                 "east_km": [r[2] for r in rows],
                                 "north_km": [r[3] for r in rows]}), path)
    s, rep = read_detections(path, DetectionColumns(time="t", sensor="radar", x="east_km",
                                                    y="north_km"),
                             DetectionUnits(distance="km", time="iso"))
    assert str(rep.epoch) == "2024-03-01T10:00:00.000000000"
    assert s.times.tolist() == [0.0, 0.0, 1.5] and s.sensor.tolist() == [0, 1, 0]
    assert s.counts.tolist() == [0, 2, 2]
    np.testing.assert_array_equal(s.z, [[500.0, -250.0], [7000.0, 8000.0],
                                        [1000.0, 2000.0], [3000.0, 4000.0]])
    assert rep.duplicates == 1 and rep.out_of_order == 3     # lines 3, 4 and 7
    assert rep.rows_read == rep.rows_kept + rep.n_skipped + rep.duplicates == 6


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_polar_units_and_conventions(tmp_path, fmt):
    t = [0.0, 0.0, 1.0]
    rng_nmi = [1.0, 2.0, 0.5]
    brg = [0.0, 90.0, 270.0]
    path = tmp_path / f"p.{fmt}"
    pq.write_table(pa.table({"time": t, "sensor": [2, 2, 2], "r": rng_nmi, "b": brg}), path) \
        if fmt == "parquet" else path.write_text(
            "time,sensor,r,b\n" + "".join(f"{a},2,{r},{b}\n" for a, r, b in
                                          zip(t, rng_nmi, brg, strict=True)))
    cols = DetectionColumns(range="r", bearing="b")
    s, _ = read_detections(path, cols, DetectionUnits(distance="nmi", angle="deg"))
    np.testing.assert_allclose(s.z[:, 0], np.array(rng_nmi) * NAUTICAL_MILE)
    np.testing.assert_allclose(s.z[:, 1], [0.0, np.pi / 2, -np.pi / 2])   # wrapped (-pi, pi]
    assert s.sensor.tolist() == [2, 2] and s.counts.tolist() == [2, 1]
    # the same numbers as mathematical angles (counter-clockwise from east)
    s, _ = read_detections(path, cols, DetectionUnits(distance="nmi", bearing="math"))
    np.testing.assert_allclose(s.z[:, 1], [np.pi / 2, 0.0, np.pi], atol=1e-15)


def test_radians_and_metres_cartesian_z(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("time,x,y,z\n0,1,2,3\n0.5,4,5,6\n")
    s, _ = read_detections(p, DetectionColumns(sensor=None, z="z"))
    assert s.dim_z == 3 and s.sensor.tolist() == [0, 0]
    p.write_text("time,sensor,r,b\n0,0,100,3.141592653589793\n")
    s, _ = read_detections(p, DetectionColumns(range="r", bearing="b"),
                           DetectionUnits(angle="rad"))
    assert s.z[0, 1] == pytest.approx(np.pi)


def test_bad_detection_records_named_or_fatal(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("time,sensor,x,y\n0,0,1,2\n0,-1,1,2\nx,0,1,2\n1,0,1,\n1,0,5,6,7\n2,0,inf,1\n\n"
                 "3,0,1,2\n")
    s, rep = read_detections(p)
    assert [(b.line, b.column, b.reason) for b in rep.bad] == [
        (3, "sensor", "bad sensor id"), (4, "time", "bad time"), (5, "y", "missing value"),
        (6, "*", "wrong number of fields"), (7, "x", "not finite"), (8, "*", "blank line")]
    assert s.times.tolist() == [0.0, 3.0] and rep.rows_kept == 2
    assert rep.rows_read == 8 == rep.rows_kept + rep.n_skipped
    with pytest.raises(ValueError, match=r"d.csv:3:sensor: bad sensor id \(value '-1'; "
                                         r"expected a non-negative integer sensor id\)"):
        read_detections(p, on_bad="stop")
    # Parquet records are named by row
    q = tmp_path / "d.parquet"
    pq.write_table(pa.table({"time": [0.0, 1.0], "sensor": [0, 0], "x": [1.0, None],
                             "y": [2.0, 3.0]}), q)
    with pytest.raises(ValueError, match=r"d.parquet:row 2:x: missing value"):
        read_detections(q, on_bad="stop")


def test_progress_and_option_errors(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("time,sensor,x,y\n" + "".join(f"{k},0,{k},1\n" for k in range(1000)))
    seen = []
    s, _ = read_detections(p, progress=lambda d, t: seen.append((d, t)))
    assert len(s) == 1000 and seen[-1] == (p.stat().st_size,) * 2
    with pytest.raises(ValueError, match="give both range and bearing"):
        DetectionColumns(range="r")
    with pytest.raises(ValueError, match="distance unit 'mi'"):
        DetectionUnits(distance="mi")
    with pytest.raises(ValueError, match="d.csv:1: no column 's'; the file has"):
        read_detections(p, DetectionColumns(x="x", y="y", time="time", sensor="s"))

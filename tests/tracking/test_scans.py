"""Scans: layout, validation (errors name the field), views, exact Parquet and CSV round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackkit.io.scans import Scan, Scans


def _example() -> Scans:
    return Scans.from_scans([
        (0.0, 0, [[1.0, 2.0], [3.0, 4.0]]),
        (0.5, 1, np.empty((0, 2))),
        (0.5, 0, [[0.1, 1 / 3]]),
        (2.0, 2, [[-0.0, 1e-300], [5e300, -7.25], [2.0, 2.0]]),
    ])


def _bitwise(a: Scans, b: Scans) -> None:
    assert a.equals(b)
    for x, y in zip((a.z, a.offsets, a.times, a.sensor), (b.z, b.offsets, b.times, b.sensor),
                    strict=True):
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()


def test_layout_and_iteration():
    s = _example()
    assert len(s) == 4 and s.dim_z == 2
    np.testing.assert_array_equal(s.offsets, [0, 2, 2, 3, 6])
    np.testing.assert_array_equal(s.counts, [2, 0, 1, 3])
    np.testing.assert_array_equal(s.scan_index, [0, 0, 2, 3, 3, 3])
    scans = list(s)
    assert [sc.time for sc in scans] == [0.0, 0.5, 0.5, 2.0]
    assert [sc.sensor for sc in scans] == [0, 1, 0, 2]
    assert scans[1].z.shape == (0, 2)
    assert isinstance(scans[3], Scan) and scans[3].z.shape == (3, 2)
    # views into the flat array, read-only
    assert np.shares_memory(scans[3].z, s.z)
    assert not scans[3].z.flags.writeable
    np.testing.assert_array_equal(s[-1].z, s.z[3:])
    assert s[2].time == 0.5
    with pytest.raises(IndexError):
        s[4]


def test_input_arrays_are_copied():
    z = np.ones((2, 1))
    s = Scans(z, [0, 2], [0.0], [0])
    z[0, 0] = 5.0
    assert s.z[0, 0] == 1.0


@pytest.mark.parametrize("kwargs,field", [
    (dict(z=[[1.0, np.nan]]), "z"),
    (dict(z=[[1.0, np.inf]]), "z"),
    (dict(z=[1.0, 2.0]), "z"),
    (dict(times=[1.0, 0.5]), "times"),
    (dict(times=[0.0, np.nan]), "times"),
    (dict(times=[[0.0, 1.0]]), "times"),
    (dict(offsets=[0, 2, 1]), "offsets"),
    (dict(offsets=[1, 1, 1]), "offsets"),
    (dict(offsets=[0, 1]), "offsets"),
    (dict(offsets=[0, 0.5, 1]), "offsets"),
    (dict(sensor=[0, -1]), "sensor"),
    (dict(sensor=[0]), "sensor"),
])
def test_validation_names_the_field(kwargs, field):
    base = dict(z=[[1.0, 2.0]], offsets=[0, 1, 1], times=[0.0, 1.0], sensor=[0, 1])
    base.update(kwargs)
    with pytest.raises(ValueError, match=rf"Scans\.{field}"):
        Scans(**base)


def test_equal_times_are_allowed():
    s = Scans(np.zeros((0, 3)), [0, 0, 0], [1.0, 1.0], [0, 1])
    assert len(s) == 2 and s.dim_z == 3


def test_parquet_round_trip(tmp_path):
    s = _example()
    s.to_parquet(tmp_path / "s.parquet")
    _bitwise(Scans.read_parquet(tmp_path / "s.parquet"), s)


def test_csv_round_trip_and_layout(tmp_path):
    s = _example()
    s.to_csv(tmp_path / "s.csv")
    text = (tmp_path / "s.csv").read_text().splitlines()
    assert text[0] == "scan,time,sensor,z0,z1"
    assert text[3] == "1,0.5,1,,"  # the empty scan
    assert text[4] == "2,0.5,0,0.1,0.3333333333333333"
    _bitwise(Scans.read_csv(tmp_path / "s.csv"), s)


def test_all_empty_round_trips(tmp_path):
    s = Scans(np.zeros((0, 2)), [0, 0, 0], [0.0, 1.0], [3, 3])
    s.to_parquet(tmp_path / "e.parquet")
    s.to_csv(tmp_path / "e.csv")
    _bitwise(Scans.read_parquet(tmp_path / "e.parquet"), s)
    _bitwise(Scans.read_csv(tmp_path / "e.csv"), s)
    _bitwise(Scans(np.zeros((0, 1)), [0], [], []), Scans(np.zeros((0, 1)), [0], [], []))


@pytest.mark.parametrize("body,where", [
    ("0,0.0,0,1.0,x\n", "line 2, column z1"),
    ("0,0.0,0,1.0\n", "line 2: 4 fields"),
    ("0,0.0,0,1.0,2.0\n0,1.0,0,1.0,2.0\n", "line 3, column scan"),
    ("0,0.0,0,1.0,2.0\n2,1.0,0,1.0,2.0\n", "line 3, column scan"),
    ("0,0.0,0,,\n0,0.0,0,1.0,2.0\n", "line 3: detection after an empty-scan row"),
    ("0,zero,0,1.0,2.0\n", "line 2"),
    ("0,1.0,0,1.0,2.0\n1,0.0,0,1.0,2.0\n", r"Scans\.times"),
])
def test_csv_bad_records(tmp_path, body, where):
    p = tmp_path / "bad.csv"
    p.write_text("scan,time,sensor,z0,z1\n" + body)
    with pytest.raises(ValueError, match=where):
        Scans.read_csv(p)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def scan_lists(draw):
    m = draw(st.integers(1, 3))
    sizes = draw(st.lists(st.integers(0, 4), min_size=0, max_size=6))
    times = sorted(draw(st.lists(finite, min_size=len(sizes), max_size=len(sizes))))
    out = []
    for k, t in zip(sizes, times, strict=True):
        vals = draw(st.lists(finite, min_size=k * m, max_size=k * m))
        out.append((t, draw(st.integers(0, 5)), np.array(vals, dtype=float).reshape(k, m)))
    return out, m


@settings(max_examples=60, deadline=None)
@given(scan_lists())
def test_round_trips_are_exact(tmp_path_factory, data):
    scans, m = data
    s = Scans.from_scans(scans, dim_z=m)
    d = tmp_path_factory.mktemp("rt")
    s.to_parquet(d / "s.parquet")
    s.to_csv(d / "s.csv")
    _bitwise(Scans.read_parquet(d / "s.parquet"), s)
    _bitwise(Scans.read_csv(d / "s.csv"), s)
    for (t, c, z), sc in zip(scans, s, strict=True):
        assert sc.time == t and sc.sensor == c
        assert sc.z.tobytes() == z.tobytes()

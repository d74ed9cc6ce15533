"""The campaign store (``trackkit.experiments.checkpoint``): atomic writes, the identity check that
refuses to mix campaigns, block files that read back as they were written or say why not."""

from __future__ import annotations

import io
import json
import os
import pickle
import zlib

import numpy as np
import pytest

from trackkit.experiments import checkpoint as ck
from trackkit.experiments import safestore
from trackkit.experiments.checkpoint import (
    CampaignMismatch,
    CampaignStore,
    CheckpointError,
    atomic_write,
    code_version,
)

IDENTITY = {"scenario": "a" * 64, "parameters": ["sensor.sigma_deg"], "seed": 1, "runs": 20,
            "block": 5, "code": {"trackkit": "0.1.0", "source": "0123456789abcdef",
                                 "numpy": "2.0", "python": "3.11.7"}}


def test_atomic_write_replaces_whole_or_not_at_all(tmp_path, monkeypatch):
    f = tmp_path / "x.json"
    atomic_write(f, "old\n")
    assert f.read_text() == "old\n"

    def broken(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ck.os, "replace", broken)
    with pytest.raises(OSError, match="No space"):
        atomic_write(f, b"new")
    assert f.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]  # no temporary left


def test_the_same_campaign_reopens_and_another_is_refused_naming_what_changed(tmp_path):
    store = CampaignStore(tmp_path, "--out DIR")
    assert store.open(IDENTITY, scenario_toml='name = "x"\n') is False
    assert json.loads((tmp_path / "campaign.json").read_text())["identity"]["seed"] == 1
    assert (tmp_path / "scenario.toml").is_file()
    assert CampaignStore(tmp_path).open(dict(IDENTITY)) is True
    changed = {**IDENTITY, "scenario": "b" * 64, "block": 10,
               "code": {**IDENTITY["code"], "source": "fedcba9876543210"}}
    with pytest.raises(CampaignMismatch) as err:
        CampaignStore(tmp_path, "--out DIR").open(changed)
    msg = str(err.value)
    for words in ("--out DIR", "scenario (its hash was aaaaaaaaaaaa, is bbbbbbbbbbbb)",
                  "block size (--block) (was 5, is 10)",
                  "code version (source 0123456789abcdef -> fedcba9876543210)", "--fresh"):
        assert words in msg, msg
    assert "seed" not in msg and "runs" not in msg.split("Refusing")[0]


def test_fresh_discards_the_campaigns_files_and_only_those(tmp_path):
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    store.save_block("p1", "k1", 0, 5, {"x": 1})
    (tmp_path / "sweep.csv").write_text("old")
    (tmp_path / "mine.txt").write_text("keep")
    other = {**IDENTITY, "runs": 40}
    store.open(other, fresh=True, outputs=["sweep.csv"])
    assert store.stored_blocks("p1") == set()
    assert not (tmp_path / "sweep.csv").exists() and (tmp_path / "mine.txt").read_text() == "keep"
    assert json.loads((tmp_path / "campaign.json").read_text())["identity"]["runs"] == 40


def test_blocks_without_a_manifest_are_not_trusted(tmp_path):
    (tmp_path / "points" / "p1").mkdir(parents=True)
    with pytest.raises(CampaignMismatch, match="no campaign.json"):
        CampaignStore(tmp_path).open(IDENTITY)
    (tmp_path / "campaign.json").write_text("{not json")
    with pytest.raises(CampaignMismatch, match="cannot be read"):
        CampaignStore(tmp_path).open(IDENTITY)


def test_blocks_read_back_bit_for_bit_and_damage_is_named(tmp_path):
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    value = {"sums": np.array([0.1, 1e-300, np.pi]), "names": ("a", "b"), 2: [np.nan, -0.0],
             "n": np.int64(7), "none": None}
    path = store.save_block("p1", "k1", 3, 5, value)
    assert path.name == "block-000003.tkb" and store.stored_blocks("p1") == {3}
    back = store.load_block("p1", "k1", 3)
    assert back["sums"].tobytes() == value["sums"].tobytes() and back["names"] == ("a", "b")
    assert np.array(back[2]).tobytes() == np.array([np.nan, -0.0]).tobytes()
    assert type(back["n"]) is np.int64 and back["n"] == 7 and back["none"] is None
    with pytest.raises(CheckpointError, match="holds block 3 of point key k1, expected block 3"
                                              " of k2"):
        store.load_block("p1", "k2", 3)
    raw = path.read_bytes()
    path.write_bytes(raw[:-20])
    with pytest.raises(CheckpointError, match=r"block-000003\.tkb: damaged .* delete it"):
        store.load_block("p1", "k1", 3)
    path.write_bytes(b"PK\x03\x04 something else")
    with pytest.raises(CheckpointError, match="not a trackkit block file"):
        store.load_block("p1", "k1", 3)


def test_a_point_recorded_with_another_key_is_refused(tmp_path):
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1", "values": {"a": 1}})
    store.prepare_point("p1", {"key": "k1", "values": {"a": 1}})  # the same: fine
    with pytest.raises(CampaignMismatch, match="stored key k1 is not k2"):
        store.prepare_point("p1", {"key": "k2"})


def test_temporaries_of_an_interrupted_write_are_removed_on_open(tmp_path):
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    tmp = store.point_dir("p1") / ".block-000000.tkb.tmp-0123456789ab"
    tmp.write_bytes(b"half")
    lock = tmp_path / ".trackkit.lock"
    lock.write_text(f"{os.getpid()}\n")
    CampaignStore(tmp_path).open(IDENTITY)
    assert not tmp.exists() and lock.exists()


def test_the_code_version_names_what_the_bits_depend_on():
    v = code_version()
    assert set(v) == {"trackkit", "source", "numpy", "python"}
    assert v["numpy"] == np.__version__ and len(v["source"]) == 16
    assert code_version() == v


def test_code_is_never_stored(tmp_path):
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    with pytest.raises(TypeError, match="cannot store a builtins.function"):
        store.save_block("p1", "k1", 0, 5, {"f": lambda x: x + 1})
    assert store.stored_blocks("p1") == set()


class _Plant:
    """What a crafted pickle would do when read: leave a marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _write_old_block(store, marker):
    """A block file as trackkit wrote them before (header line + zlib(pickle)), whose pickle
    creates ``marker`` when read."""
    header = json.dumps({"key": "k1", "block": 0, "runs": 5}).encode() + b"\n"
    body = pickle.dumps({"sums": np.zeros(3), "x": _Plant(marker)})
    path = store.point_dir("p1") / "block-000000.tkb"
    path.write_bytes(b"trackkit-block 1\n" + header + zlib.compress(body))
    return path


def test_a_pickled_block_is_refused_unread_naming_the_file(tmp_path):
    marker = tmp_path / "ran-code"
    store = CampaignStore(tmp_path / "campaign")
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    path = _write_old_block(store, marker)
    pickle.loads(zlib.decompress(path.read_bytes().split(b"\n", 2)[2]))  # the trap is armed
    assert marker.exists()
    marker.rmdir()
    with pytest.raises(CheckpointError) as err:
        store.load_block("p1", "k1", 0)
    msg = str(err.value)
    for words in (str(path), "older trackkit", "cannot be read safely", "--fresh"):
        assert words in msg, msg
    assert not marker.exists()


def test_a_crafted_structure_builds_no_other_type(tmp_path):
    """A block file in the current format that names a type trackkit does not store (here
    one whose constructor would write a file) is refused as damaged; nothing is built."""
    store = CampaignStore(tmp_path)
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    path = store.save_block("p1", "k1", 0, 5, {"sums": np.zeros(2)})
    magic, head, _, arrays = path.read_bytes().split(b"\n", 3)
    for bad in ('{"$o":"builtins.open","v":{"$d":[]}}', '{"$o":"tests.experiments.test_checkpoint.'
                '_Plant","v":{"$d":[["marker","x"]]}}', '{"$a":7}', '{"$x":1}'):
        path.write_bytes(b"\n".join([magic, head, bad.encode(), arrays]))
        with pytest.raises(CheckpointError, match=r"block-000000\.tkb: damaged \(ValueError"):
            store.load_block("p1", "k1", 0)
    objects = np.array([_Plant(tmp_path / "ran-code")], dtype=object)
    with pytest.raises(TypeError, match="dtype object"):
        safestore.dumps({"a": objects})
    buf = io.BytesIO()
    np.savez(buf, a0=objects)  # an archive holding a pickled array: numpy refuses it
    path.write_bytes(b"\n".join([magic, head, b'{"$a":0}', buf.getvalue()]))
    with pytest.raises(CheckpointError, match="damaged .*allow_pickle"):
        store.load_block("p1", "k1", 0)
    assert not (tmp_path / "ran-code").exists()


def test_a_campaign_of_the_pickle_format_is_refused_on_open(tmp_path):
    store = CampaignStore(tmp_path, "--out DIR")
    store.open(IDENTITY)
    store.prepare_point("p1", {"key": "k1"})
    old = {"identity": {**IDENTITY, "format": 1}}
    (tmp_path / "campaign.json").write_text(json.dumps(old))
    with pytest.raises(CampaignMismatch) as err:
        CampaignStore(tmp_path).open(IDENTITY)
    for words in ("campaign.json", "older trackkit", "cannot be read safely", "--fresh"):
        assert words in str(err.value), str(err.value)
    assert CampaignStore(tmp_path).open(IDENTITY, fresh=True) is False

"""The campaign store of ``trackkit sweep``: every finished Monte Carlo block of every point,
kept in the campaign's directory so that an interrupted campaign resumes where it stopped.

Layout of a campaign directory (``CampaignStore``)::

    campaign.json               what the stored blocks were computed from (``identity``)
    scenario.toml               the base scenario, resolved (for the record)
    points/<id>/point.json      the point's swept values, its seed and its key
    points/<id>/block-000003.tkb  block 3 of the point (header line + .npz of its arrays)
    points/<id>/result.json     the point's combined result, once all its blocks are stored
    points/<id>/timings.json    its filters' wall-clock time per run-step (not deterministic)

Every file is written atomically (``atomic_write``: a temporary file in the same directory,
flushed and fsync'ed, then ``os.replace``, then the directory fsync'ed), so a block file is
either complete or absent, whatever stops the process (Ctrl-C, SIGKILL, a lost machine).

``campaign.json`` holds the identity of the campaign: a hash of the base scenario, the swept
parameters, the campaign seed, the runs per point, the block size and the code version
(trackkit's version, a hash of the source files that compute a block, numpy's and Python's
versions). A store opened with another identity refuses, naming what changed, unless told to
start afresh. A point is identified by its swept values alone, so adding points (values, or
design points) to a campaign reuses every point already computed.

A block file is a line naming the format, a line of JSON (the block's point key, index, runs
and the structure of its value) and an ``.npz`` archive of its arrays
(``trackkit.experiments.safestore``): reading it builds numbers, strings, containers, arrays and
trackkit's block types only, and runs no code of the file's, so a campaign directory from
someone else is safe to open. Block files of older trackkit versions were pickles, which
can run code when read; they are refused, never opened.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
import uuid
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Any

from trackkit.experiments import safestore

__all__ = ["CampaignStore", "CampaignMismatch", "CheckpointError", "atomic_write",
           "code_version", "MANIFEST", "POINTS_DIR", "STORE_FORMAT"]

#: The file of a campaign directory holding the campaign's identity.
MANIFEST = "campaign.json"
SCENARIO_TOML = "scenario.toml"
#: The folder of a campaign directory holding one folder per point.
POINTS_DIR = "points"
POINT_JSON = "point.json"
RESULT_JSON = "result.json"
TIMINGS_JSON = "timings.json"
#: the store's own format; a change refuses older directories like a code change
STORE_FORMAT = 2
_MAGIC = b"trackkit-block 2\n"
#: the block files of store format 1: pickles, which can run code when read
_PICKLED = b"trackkit-block 1\n"
_BLOCK = re.compile(r"block-(\d{6,})\.tkb")
_TMP = re.compile(r"\..+\.tmp-[0-9a-f]{12}")
#: the parts of the package whose code changes a block's numbers are hashed; these are not
#: (reports, readers, the command line, other seeds' programmes)
_UNHASHED = ("report", "io", "identify", "network", "cli")
#: the identity's entries as messages name them
_NAMES = {"format": "store format", "scenario": "scenario", "parameters": "swept parameters",
          "seed": "campaign seed (--seed)", "runs": "runs per point (--runs)",
          "block": "block size (--block)", "code": "code version"}


@lru_cache(maxsize=1)
def _block_types() -> tuple[type, ...]:
    """The classes a block file may hold (``experiments.montecarlo.BlockResult`` and what it is
    made of); a block file naming any other is refused."""
    from trackkit.eval.metrics import MonteCarloMetrics
    from trackkit.experiments.montecarlo import BearingError, BlockResult, CourseError, SpeedError
    from trackkit.experiments.results import Example

    return (BlockResult, MonteCarloMetrics, Example, SpeedError, CourseError, BearingError)


class CampaignMismatch(ValueError):
    """The directory holds blocks of another campaign (a changed scenario, sweep, seed, runs,
    block size or code)."""


class CheckpointError(RuntimeError):
    """A stored file that cannot be read back (damaged on disk or not written by trackkit)."""


def _fsync_dir(path: Path) -> None:
    if os.name == "nt":  # pragma: no cover - directories cannot be opened there
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:  # some file systems do not sync directories
        pass
    finally:
        os.close(fd)


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` so that ``path`` is always either its old content or the
    whole new one: a temporary file in the same directory, fsync'ed, then ``os.replace``
    (and the directory fsync'ed, so the new name survives a power cut)."""
    path = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.tmp-{uuid.uuid4().hex[:12]}")
    try:
        with open(tmp, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)
    return path


def _json(doc: Any) -> str:
    return json.dumps(doc, indent=2, sort_keys=False, allow_nan=False) + "\n"


@lru_cache(maxsize=1)
def _source_hash() -> str:
    """sha256 over the package's source files that compute blocks (path and content)."""
    import trackkit

    root = Path(trackkit.__file__).parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root).as_posix()
        if rel.split("/")[0] in _UNHASHED or "__pycache__" in rel:
            continue
        h.update(rel.encode() + b"\0" + p.read_bytes() + b"\0")
    for p in sorted(root.rglob("*.toml")):  # bundled data models read (vessel data etc.)
        rel = p.relative_to(root).as_posix()
        if rel.startswith("models/"):
            h.update(rel.encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def code_version() -> dict[str, str]:
    """What the blocks' bits depend on besides the scenario: trackkit's version, a hash of
    its block-computing source files, numpy's and Python's versions."""
    import numpy as np

    import trackkit

    return {"trackkit": trackkit.__version__, "source": _source_hash(),
            "numpy": np.__version__, "python": ".".join(map(str, sys.version_info[:3]))}


def _differences(stored: dict, now: dict) -> list[str]:
    """What changed between two identities, in words."""
    out = []
    for key in list(_NAMES) + sorted((set(stored) | set(now)) - set(_NAMES)):
        a, b = stored.get(key), now.get(key)
        if a == b:
            continue
        name = _NAMES.get(key, key)
        if key == "code" and isinstance(a, dict) and isinstance(b, dict):
            parts = [f"{k} {a.get(k)} -> {b.get(k)}" for k in sorted(set(a) | set(b))
                     if a.get(k) != b.get(k)]
            out.append(f"{name} ({', '.join(parts)})")
        elif key == "scenario":
            out.append(f"{name} (its hash was {str(a)[:12]}, is {str(b)[:12]})")
        else:
            out.append(f"{name} (was {json.dumps(a)}, is {json.dumps(b)})")
    return out


class CampaignStore:
    """The stored blocks and results of one campaign in directory ``root`` (see the module
    doc). ``label`` names the directory in messages (e.g. ``--out DIR``)."""

    def __init__(self, root: str | Path, label: str | None = None) -> None:
        self.root = Path(root)
        self.label = label or str(self.root)
        self.points = self.root / POINTS_DIR

    # --- the campaign --------------------------------------------------------------------

    def open(self, identity: dict, fresh: bool = False, scenario_toml: str | None = None,
             outputs: Iterable[str] = ()) -> bool:
        """Check the stored identity against ``identity`` (or, with ``fresh``, discard
        every stored block and the ``outputs`` files first) and record it. Returns whether
        the directory already held this campaign. Raises ``CampaignMismatch`` naming what
        changed."""
        self.root.mkdir(parents=True, exist_ok=True)
        manifest = self.root / MANIFEST
        if fresh:
            self.discard(outputs)
        identity = {"format": STORE_FORMAT, **identity}
        self._remove_temporaries()
        if manifest.exists():
            try:
                stored = json.loads(manifest.read_text(encoding="utf-8"))["identity"]
            except (OSError, ValueError, KeyError, TypeError) as err:
                raise CampaignMismatch(
                    f"{self.label}: {manifest.name} cannot be read ({err}); it does not "
                    "describe the stored blocks, so they cannot be trusted: re-run with "
                    "--fresh to discard them, or choose another --out") from None
            if stored.get("format", 1) == 1 and (self.points.is_dir() and
                                                 any(self.points.iterdir())):
                raise CampaignMismatch(
                    f"{manifest}: written by an older trackkit, whose block files are pickles "
                    "(which can run code when read); they cannot be read safely and were not "
                    "opened. Re-run with --fresh to discard them and compute the campaign "
                    "again, or choose another --out")
            changed = _differences(stored, identity)
            if changed:
                raise CampaignMismatch(
                    f"{self.label} holds blocks of another campaign; changed since they were "
                    f"stored: {'; '.join(changed)}. Refusing to mix results: re-run with "
                    "--fresh to discard the stored blocks and start afresh, or choose another "
                    "--out")
            return True
        if self.points.exists() and any(self.points.iterdir()):
            raise CampaignMismatch(
                f"{self.label} holds {POINTS_DIR}/ but no {MANIFEST}, so what its blocks were "
                "computed from is unknown; re-run with --fresh to discard them, or choose "
                "another --out")
        self.points.mkdir(exist_ok=True)
        if scenario_toml is not None:
            atomic_write(self.root / SCENARIO_TOML, scenario_toml)
        atomic_write(manifest, _json({"identity": identity}))
        return False

    def discard(self, outputs: Iterable[str] = ()) -> None:
        """Remove the campaign's files (and only those): the manifest, the stored points and
        the named output files."""
        shutil.rmtree(self.points, ignore_errors=True)
        for name in (MANIFEST, SCENARIO_TOML, *outputs):
            (self.root / name).unlink(missing_ok=True)

    def _remove_temporaries(self) -> None:
        """Temporary files an interrupted write left behind (never whole blocks)."""
        dirs = [self.root] + ([d for d in self.points.iterdir() if d.is_dir()]
                              if self.points.is_dir() else [])
        for d in dirs:
            for p in d.iterdir():
                if _TMP.fullmatch(p.name) and p.is_file():
                    p.unlink(missing_ok=True)

    # --- points ----------------------------------------------------------------------------

    def point_dir(self, pid: str) -> Path:
        return self.points / pid

    def prepare_point(self, pid: str, header: dict) -> None:
        """Record a point (``header``: its values, seed and key) or check the recorded one."""
        d = self.point_dir(pid)
        d.mkdir(parents=True, exist_ok=True)
        f = d / POINT_JSON
        if f.exists():
            try:
                stored = json.loads(f.read_text(encoding="utf-8"))
            except (OSError, ValueError) as err:
                raise CheckpointError(f"{f}: cannot be read ({err}); delete the directory "
                                      f"{d} to compute the point again") from None
            if stored.get("key") != header.get("key"):
                raise CampaignMismatch(
                    f"{f}: the point's stored key {stored.get('key')} is not {header.get('key')}"
                    " (what its blocks were computed from differs); re-run with --fresh")
            return
        atomic_write(f, _json(header))

    def stored_blocks(self, pid: str) -> set[int]:
        d = self.point_dir(pid)
        if not d.is_dir():
            return set()
        return {int(m.group(1)) for p in d.iterdir() if (m := _BLOCK.fullmatch(p.name))}

    def _block_path(self, pid: str, block: int) -> Path:
        return self.point_dir(pid) / f"block-{block:06d}.tkb"

    def save_block(self, pid: str, key: str, block: int, runs: int, result: Any) -> Path:
        """Store block ``block`` (of ``runs`` runs) of point ``pid`` (whose key is ``key``)."""
        structure, arrays = safestore.dumps(result, _block_types())
        header = json.dumps({"key": key, "block": block, "runs": runs}) + "\n" + structure
        return atomic_write(self._block_path(pid, block),
                            _MAGIC + header.encode() + b"\n" + arrays)

    def load_block(self, pid: str, key: str, block: int) -> Any:
        """Block ``block`` of point ``pid``, checked to be that block of that point."""
        p = self._block_path(pid, block)
        hint = "delete it and re-run the same command to compute that block again"
        try:
            raw = p.read_bytes()
        except OSError as err:
            raise CheckpointError(f"{p}: cannot be read ({err.strerror or err})") from None
        if raw.startswith(_PICKLED):
            raise CheckpointError(
                f"{p}: written by an older trackkit, whose block files are pickles (which can "
                "run code when read); it cannot be read safely and was not opened. Re-run "
                "with --fresh to discard the stored blocks and compute them again")
        if not raw.startswith(_MAGIC):
            raise CheckpointError(f"{p}: not a trackkit block file; {hint}")
        head, _, rest = raw[len(_MAGIC):].partition(b"\n")
        structure, _, arrays = rest.partition(b"\n")
        try:
            header = json.loads(head)
            result = safestore.loads(structure, arrays, _block_types())
        except Exception as err:  # noqa: BLE001 - any damage reads as one message
            raise CheckpointError(f"{p}: damaged ({type(err).__name__}: {err}); {hint}") from None
        if header.get("key") != key or header.get("block") != block:
            raise CheckpointError(f"{p}: holds block {header.get('block')} of point key "
                                  f"{header.get('key')}, expected block {block} of {key}; {hint}")
        return result

    def has_result(self, pid: str) -> bool:
        return (self.point_dir(pid) / RESULT_JSON).is_file()

    def save_result(self, pid: str, doc: dict, timings: dict | None = None) -> None:
        d = self.point_dir(pid)
        if timings is not None:
            atomic_write(d / TIMINGS_JSON, _json(timings))
        atomic_write(d / RESULT_JSON, _json(doc))

    def load_result(self, pid: str) -> dict:
        p = self.point_dir(pid) / RESULT_JSON
        try:
            return json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            raise CheckpointError(f"{p}: cannot be read ({err}); delete it and re-run the same "
                                  "command to combine the point's blocks again") from None

    def load_timings(self, pid: str) -> dict | None:
        try:
            return json.loads((self.point_dir(pid) / TIMINGS_JSON).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

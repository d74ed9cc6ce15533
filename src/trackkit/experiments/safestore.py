"""A serialiser that cannot run code when it reads: a JSON description of a value's structure
and its numpy arrays in an ``.npz`` archive (read with ``allow_pickle=False``).

It stores what a Monte Carlo block is made of: ``None``, ``bool``, ``int``, ``float`` (nan and
infinities included), ``str``, lists, tuples, dicts (any of these as keys), numpy arrays and
scalars (any dtype but ``object``), and instances of the classes the caller names, by their
attributes (``vars``). Every array keeps its dtype, shape and bits; every float its bits
(``repr`` in JSON).

Reading builds only those types: a named class is looked up in the caller's table (never
imported) and filled in with ``cls.__new__`` and its attributes, so no constructor,
``__setstate__`` or other code of the file's choosing runs. Anything else in a file (an
unknown class, a malformed node, an object array) is refused with ``ValueError``.

The structure, as JSON (each object node has exactly one of these keys)::

    null, true, false, 1, 0.5, "text"      themselves
    {"$f": "nan" | "inf" | "-inf"}        a float JSON cannot write
    {"$a": 3}                             array "a3" of the archive
    {"$s": 3}                             numpy scalar: 0-d array "a3" of the archive
    {"$l": [...]}, {"$t": [...]}          list, tuple
    {"$d": [[key, value], ...]}           dict, in its order
    {"$o": "module.Class", "v": {...}}    an instance of a named class: its attributes
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["dumps", "loads"]


def _name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


class _Writer:
    def __init__(self, classes: Iterable[type]) -> None:
        self.classes = {c: _name(c) for c in classes}
        self.arrays: dict[str, np.ndarray] = {}

    def array(self, a: np.ndarray, kind: str) -> dict:
        if a.dtype.hasobject:
            raise TypeError(f"cannot store an array of dtype {a.dtype} (Python objects); "
                            "expected numbers, booleans or strings")
        i = len(self.arrays)
        self.arrays[f"a{i}"] = a
        return {kind: i}

    def node(self, x: Any) -> Any:
        t = type(x)
        if x is None or t in (bool, int, str):
            return x
        if t is float:
            return x if math.isfinite(x) else {"$f": repr(x)}
        if isinstance(x, np.ndarray):
            return self.array(x, "$a")
        if isinstance(x, np.generic):
            return self.array(np.asarray(x), "$s")
        if t in (list, tuple):
            return {"$l" if t is list else "$t": [self.node(v) for v in x]}
        if t is dict:
            return {"$d": [[self.node(k), self.node(v)] for k, v in x.items()]}
        if t in self.classes:
            return {"$o": self.classes[t], "v": self.node(dict(vars(x)))}
        raise TypeError(f"cannot store a {t.__module__}.{t.__qualname__} (not data: only "
                        "numbers, strings, lists, tuples, dicts, numpy arrays and trackkit's "
                        "block types are stored)")


def dumps(value: Any, classes: Iterable[type] = ()) -> tuple[str, bytes]:
    """``value`` as (its structure as one line of JSON, an ``.npz`` archive of its arrays,
    deflated). ``classes``: the classes whose instances may be stored (by their attributes).
    Raises ``TypeError`` naming anything else (a function, an unknown object)."""
    w = _Writer(classes)
    structure = json.dumps(w.node(value), allow_nan=False, separators=(",", ":"))
    buf = io.BytesIO()
    np.savez_compressed(buf, **w.arrays)
    return structure, buf.getvalue()


class _Reader:
    def __init__(self, arrays: Any, classes: Iterable[type]) -> None:
        self.arrays = arrays
        self.classes = {_name(c): c for c in classes}

    def array(self, i: Any) -> np.ndarray:
        if type(i) is not int or f"a{i}" not in self.arrays.files:
            raise ValueError(f"refers to array {i!r}, which the archive does not hold")
        return self.arrays[f"a{i}"]

    def node(self, x: Any) -> Any:
        if x is None or type(x) in (bool, int, float, str):
            return x
        if type(x) is not dict or len(x) != (2 if "$o" in x else 1):
            raise ValueError(f"malformed node {str(x)[:80]}")
        if "$o" in x:
            return self.instance(x["$o"], x.get("v"))
        ((tag, v),) = x.items()
        if tag == "$f" and v in ("nan", "inf", "-inf"):
            return float(v)
        if tag == "$a":
            return self.array(v)
        if tag == "$s":
            return self.array(v)[()]
        if tag in ("$l", "$t") and type(v) is list:
            items = [self.node(e) for e in v]
            return items if tag == "$l" else tuple(items)
        if tag == "$d" and type(v) is list:
            return {self.node(k): self.node(e) for k, e in (self.pair(p) for p in v)}
        raise ValueError(f"malformed node {str(x)[:80]}")

    @staticmethod
    def pair(p: Any) -> list:
        if type(p) is not list or len(p) != 2:
            raise ValueError(f"malformed dict entry {str(p)[:80]}")
        return p

    def instance(self, name: Any, attrs: Any) -> Any:
        cls = self.classes.get(name) if type(name) is str else None
        if cls is None:
            raise ValueError(f"names the type {name!r}, which is not one trackkit stores")
        state = self.node(attrs)
        if type(state) is not dict or not all(type(k) is str for k in state):
            raise ValueError(f"the attributes of a {name} are not a dict of names")
        obj = cls.__new__(cls)
        obj.__dict__.update(state)
        return obj


def loads(structure: str | bytes, archive: bytes, classes: Iterable[type] = ()) -> Any:
    """The value :func:`dumps` wrote. Builds only data and instances of ``classes``; raises
    ``ValueError`` for anything else in the file (and numpy's errors for a damaged archive)."""
    tree = json.loads(structure)
    with np.load(io.BytesIO(archive), allow_pickle=False) as arrays:
        return _Reader(arrays, classes).node(tree)

"""A small TOML writer for scenarios: ``dumps(scenario)`` is the resolved scenario (the fields
the file set and every default) as TOML that ``trackkit.scenario.load`` reads back to an equal
scenario.

The layout follows the bundled files: top-level values first, then a ``[table]`` per section
and a ``[[table]]`` per observer and filter, whose nested tables are inline and whose lists
of tables are arrays of inline tables, one per line. Floats are written with ``repr`` (the
shortest text that reads back to the same double), strings as TOML basic strings with every
character TOML requires escaped, and None (no value in TOML) is left out.
"""

from __future__ import annotations

import math
import re
from typing import Any

from pydantic import BaseModel

__all__ = ["dumps"]

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f",
            "\r": "\\r"}


def dumps(scenario: BaseModel) -> str:
    """The scenario with every default filled in, as TOML."""
    data = _drop_none(scenario.model_dump())
    lines: list[str] = []
    tables: list[tuple[str, Any]] = []
    for key, value in data.items():
        if isinstance(value, dict) or (_is_tables(value) and value):
            tables.append((key, value))
        else:
            lines.append(f"{_key(key)} = {toml_value(value, multiline=True)}")
    for key, value in tables:
        for table in value if isinstance(value, list) else [value]:
            header = f"[[{_key(key)}]]" if isinstance(value, list) else f"[{_key(key)}]"
            lines += ["", header]
            lines += [f"{_key(k)} = {toml_value(v, multiline=True)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_drop_none(v) for v in value]
    return value


def _is_tables(value: Any) -> bool:
    return isinstance(value, list) and all(isinstance(v, dict) for v in value)


def _key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else _string(key)


def _string(s: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped (TOML allows
    no raw control character but tab in a basic string; \\u for those without a short form)."""
    out = []
    for ch in s:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _float(v: float) -> str:
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    text = repr(v)  # "1e-05", "1e+300", "0.1": all valid TOML floats
    return text if any(c in text for c in ".en") else text + ".0"


def toml_value(v: Any, multiline: bool = False) -> str:
    """A TOML value; ``multiline`` puts a list of tables or of long strings one per line (an
    inline table must stay on one line; an array may span lines)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return _float(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, dict):
        if not v:
            return "{}"
        return "{ " + ", ".join(f"{_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list | tuple):
        items = [toml_value(x) for x in v]
        long = any(isinstance(x, dict) for x in v) or sum(map(len, items)) > 80
        if multiline and long and items:
            return "[\n" + "".join(f"  {item},\n" for item in items) + "]"
        return "[" + ", ".join(items) + "]"
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as TOML")

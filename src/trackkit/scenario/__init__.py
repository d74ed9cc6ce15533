"""Scenarios: TOML files validated against ``trackkit.scenario.schema``.

``load("bo-cv")`` reads a bundled scenario by name, ``load("my.toml")`` a file; errors name the
file, the field, the bad value and what is allowed.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from pydantic import ValidationError

from trackkit.scenario.schema import KNOT, Scenario

__all__ = ["Scenario", "ScenarioError", "load", "bundled", "DEFAULT", "KNOT"]

DEFAULT = "bo-cv"


class ScenarioError(ValueError):
    """A scenario file that cannot be used, with the file, field, value and expectation."""


def _bundled_dir():
    return resources.files("trackkit.scenario") / "scenarios"


def bundled() -> dict[str, str]:
    """Bundled scenario names and their one-line descriptions."""
    out = {}
    for f in sorted(_bundled_dir().iterdir(), key=lambda p: p.name):
        if f.name.endswith(".toml"):
            data = tomllib.loads(f.read_text())
            out[f.name[:-5]] = str(data.get("description", "")).split("\n")[0]
    return out


def _format(err: ValidationError, source: str) -> str:
    lines = [f"{source}: {err.error_count()} problem(s)"]
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"].removeprefix("Value error, ")
        if e["type"] == "extra_forbidden":
            msg = "unknown field (not allowed here)"
        value = e.get("input")
        shown = repr(value) if not isinstance(value, dict) else "{...}"
        if e["type"] == "missing":
            shown, msg = "(missing)", "required field"
        if len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"  {loc} = {shown}: {msg}")
    return "\n".join(lines)


def parse(data: dict, source: str = "<scenario>") -> Scenario:
    """Validate a scenario given as a dict (e.g. parsed TOML)."""
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(_format(err, source)) from None


def load(name_or_path: str | Path) -> Scenario:
    """Load a bundled scenario by name or a TOML file by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ScenarioError(f"{p}: no such scenario file")
        text, source = p.read_text(), str(p)
    else:
        f = _bundled_dir() / f"{name_or_path}.toml"
        if not f.is_file():
            raise ScenarioError(
                f"no bundled scenario named {str(name_or_path)!r}; expected one of "
                f"{sorted(bundled())} or a path to a .toml file"
            )
        text, source = f.read_text(), f"{name_or_path} (bundled)"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML: {err}") from None
    return parse(data, source)

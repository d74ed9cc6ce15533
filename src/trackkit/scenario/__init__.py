"""Scenarios: TOML files validated against ``trackkit.scenario.schema``.

``load("bo-cv")`` reads a bundled scenario by name, ``load("my.toml")`` a file; errors name the
file, the field, the bad value and what is allowed. ``dumps(scenario)`` writes a scenario, with
every default filled in, as TOML that ``load`` reads back to an equal scenario.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from trackkit.scenario.schema import KNOT, PLAIN_NAME, Scenario
from trackkit.scenario.toml_writer import dumps

__all__ = ["Scenario", "ScenarioError", "load", "parse", "validated", "dumps", "bundled", "DEFAULT",
           "KNOT"]

#: The bundled scenario a command runs when none is named.
DEFAULT = "bo-cv"


class ScenarioError(ValueError):
    """A scenario file that cannot be used, with the file, field, value and expectation."""


def _bundled_dir():
    return resources.files("trackkit.scenario") / "scenarios"


def descriptions(folder) -> dict[str, str]:
    """The scenario files of ``folder``: name -> the first line of its description."""
    out = {}
    for f in sorted(folder.iterdir(), key=lambda p: p.name):
        if f.name.endswith(".toml"):
            data = tomllib.loads(f.read_text(encoding="utf-8"))
            out[f.name[:-5]] = str(data.get("description", "")).split("\n")[0]
    return out


def bundled() -> dict[str, str]:
    """Bundled scenario names and their one-line descriptions."""
    return descriptions(_bundled_dir())


def _problem(loc: str, value: Any, message: str) -> str:
    """One line of a report: the field, its value and what is wrong."""
    shown = repr(value)
    if isinstance(value, dict) and len(shown) > 80:
        shown = "{...}"  # a whole table: the message says what in it is wrong
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return f"  {loc or '(top level)'} = {shown}: {message}"


def _format(problems: list[tuple[str, Any, str]], source: str) -> str:
    return "\n".join([f"{source}: {len(problems)} problem(s)"]
                     + [_problem(*p) for p in problems])


def _pydantic_problems(err: ValidationError) -> list[tuple[str, Any, str]]:
    out = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg, value = e["msg"].removeprefix("Value error, "), e.get("input")
        if e["type"] == "extra_forbidden":
            msg = "unknown field (not allowed here)"
        if e["type"] == "missing":
            out.append((loc, Missing(), "required field"))
            continue
        out.append((loc, value, msg))
    return out


class Missing:
    def __repr__(self) -> str:
        return "(missing)"


M = TypeVar("M", bound=BaseModel)


def validated(model: type[M], data: dict, source: str) -> M:
    """``data`` validated as ``model`` (a scenario schema); every problem is a ScenarioError
    naming ``source``, the field, the value and what is expected."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(_format(_pydantic_problems(err), source)) from None


def parse(data: dict, source: str = "<scenario>") -> Scenario:
    """Validate a scenario given as a dict (e.g. parsed TOML): the schema, then the numbers
    (``trackkit.scenario.build.numeric_problems``): every problem is a ScenarioError naming
    ``source``, the field, the value and what is expected."""
    from trackkit.scenario.build import numeric_problems

    scenario = validated(Scenario, data, source)
    problems = numeric_problems(scenario)
    if problems:
        raise ScenarioError(_format(problems, source))
    return scenario


def _read(p: Path) -> str:
    """The text of a scenario file, or a ScenarioError that names the path and the problem."""
    if p.is_dir():
        raise ScenarioError(f"{p}: is a directory; expected a scenario .toml file")
    if not p.is_file():
        raise ScenarioError(f"{p}: no such scenario file")
    raw = p.read_bytes()
    try:
        return raw.decode("utf-8-sig")  # tolerate the BOM some Windows editors write
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        raise ScenarioError(
            f"{p}: not UTF-8 text (byte 0x{raw[err.start]:02x} on line {line}); a scenario "
            "is a TOML file, which must be saved as UTF-8") from None


def bundled_file(folder, name: str):
    """The bundled scenario file ``folder/name.toml``, or None (also for a name that is not
    a plain file name)."""
    f = folder / f"{name}.toml"
    return f if PLAIN_NAME.fullmatch(name) and f.is_file() else None


def read_scenario(name_or_path: str | Path, folder, kind: str = "") -> tuple[dict, str]:
    """``(data, source)`` of a scenario file by path, or bundled in ``folder`` by name;
    ``kind`` names the kind of scenario in the error for an unknown name ("multi-target ",
    "network ")."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        text, source = _read(p), str(p)
    else:
        f = bundled_file(folder, str(name_or_path))
        if f is None:
            raise ScenarioError(
                f"no bundled {kind}scenario named {str(name_or_path)!r}; expected one of "
                f"{sorted(descriptions(folder))} or a path to a .toml file"
            )
        text, source = f.read_text(encoding="utf-8"), f"{name_or_path} (bundled)"
    try:
        return tomllib.loads(text), source
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML: {err}") from None


def holds_table(name_or_path: str | Path, folder, table: str, kind: type) -> bool:
    """Whether ``name_or_path`` names a scenario bundled in ``folder``, or a TOML file whose
    ``table`` is a ``kind`` (dict for ``[table]``, list for ``[[table]]``). A file that cannot
    be read or parsed is not claimed: another loader then reports its problem."""
    p = Path(name_or_path)
    if not (p.suffix == ".toml" or p.exists()):
        return bundled_file(folder, str(name_or_path)) is not None
    try:
        data = tomllib.loads(_read(p))
    except (ScenarioError, tomllib.TOMLDecodeError):
        return False
    return isinstance(data.get(table), kind)


def load(name_or_path: str | Path) -> Scenario:
    """Load a bundled scenario by name or a TOML file by path."""
    return parse(*read_scenario(name_or_path, _bundled_dir()))

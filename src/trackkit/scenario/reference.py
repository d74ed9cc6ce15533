"""The scenario reference, generated from the schema and the table of filter options.

    python -m trackkit.scenario.reference > docs/scenario-reference.md

Every field of every table: its unit (from the name's suffix, or the field's ``unit``), type
(in words, from the annotation and its constraints, never a library's repr), default, allowed
values and description (``Field(description=...)``); then each filter type's options from
``trackkit.scenario.options.FILTER_TYPES``. ``tests/test_scenario_schema.py``
checks that the committed file is current.
"""

from __future__ import annotations

import types
import typing
from typing import Any, Literal

import annotated_types as at
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from trackkit.scenario.options import FILTER_TYPES, Option
from trackkit.scenario.schema import Scenario
from trackkit.scenario.toml_writer import toml_value

__all__ = ["reference", "COMMAND"]

#: The command that writes ``docs/scenario-reference.md`` from the schemas.
COMMAND = "python -m trackkit.scenario.reference > docs/scenario-reference.md"

#: unit suffixes of field names, longest first (``_deg_s`` before ``_s``)
SUFFIXES = {"_deg_s": "deg/s", "_mps2": "m/s^2", "_mps": "m/s", "_kn": "kn", "_deg": "deg",
            "_hz": "Hz", "_db": "dB", "_si": "SI", "_m": "m", "_s": "s"}

_KINDS = {"int": "integer", "float": "number", "bool": "boolean", "choice": "string",
          "floats": "list of numbers", "pairs": "list of integers"}


def unit_of(name: str, info: FieldInfo) -> str:
    """The unit of a field: the ``unit`` the schema gives it (``r_diag_si``: SI squared),
    else its name's suffix."""
    extra = info.json_schema_extra
    if isinstance(extra, dict) and "unit" in extra:
        return str(extra["unit"])
    for suffix, unit in SUFFIXES.items():
        if name.endswith(suffix):
            return unit
    return ""


def _strip(tp: Any) -> tuple[Any, list[Any], bool]:
    """The type without Annotated and None: (type, constraints, optional)."""
    constraints: list[Any] = []
    optional = False
    while True:
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            tp, *meta = typing.get_args(tp)
            for m in meta:
                constraints += m.metadata if isinstance(m, FieldInfo) else [m]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            optional = optional or len(args) < len(typing.get_args(tp))
            if len(args) != 1:
                return tp, constraints, optional
            tp = args[0]
        else:
            return tp, constraints, optional


_NOUNS = {float: ("number", "numbers"), int: ("integer", "integers"),
          bool: ("boolean", "booleans"), str: ("string", "strings")}
_TUPLES = {2: ("pair", "pairs"), 3: ("triple", "triples")}


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _anchor(model: type[BaseModel]) -> str:
    return model.__name__.lower()


def _finite(tp: Any, constraints: list[Any]) -> bool:
    """A float refuses inf and nan when the schema says so (``allow_inf_nan=False``, whatever
    class pydantic keeps that in) or when it is bounded on both sides."""
    if tp is not float:
        return False
    if any(getattr(c, "allow_inf_nan", None) is False for c in constraints):
        return True
    lower = any(isinstance(c, (at.Gt, at.Ge)) for c in constraints)
    return lower and any(isinstance(c, (at.Lt, at.Le)) for c in constraints)


def type_words(tp: Any, plural: bool = False, bounds: bool = False,
               constraints: list[Any] | None = None) -> str:
    """A field's type in words, from its annotation and constraints alone (never a repr, so
    the reference reads the same whatever pydantic prints): ``list of pairs of finite numbers
    >= 0``, ``optional table (MotionSpec)``. ``bounds`` adds the constraints to the words,
    for the members of a tuple or a table, which the allowed column does not cover;
    ``constraints`` are those pydantic keeps beside the annotation (``FieldInfo.metadata``)."""
    tp, more, optional = _strip(tp)
    words = _words(tp, [*(constraints or []), *more], plural, bounds)
    return "optional " + words if optional and not plural else words


def _words(tp: Any, constraints: list[Any], plural: bool, bounds: bool) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if _is_model(tp):
        kind = "tables" if plural else "table"
        return f"{kind} ([{tp.__name__}](#{_anchor(tp)}))"
    if origin is list:
        inner, _, _ = _strip(args[0])
        if _is_model(inner):
            kind = "arrays of tables" if plural else "array of tables"
            return f"{kind} ([{inner.__name__}](#{_anchor(inner)}))"
        return ("lists of " if plural else "list of ") + type_words(args[0], True, bounds)
    if origin is tuple:
        return _tuple_words(args, plural)
    if origin is dict:
        kind = "tables" if plural else "table"
        return f"{kind} mapping names to {type_words(args[1], True, True)}"
    if origin is Literal:
        if not bounds:
            return _literal_noun(args, plural)
        return ("each one of " if plural else "one of ") + ", ".join(toml_value(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(type_words(a, plural, bounds) for a in args)
    if tp is Any:
        return "values" if plural else "any value"
    if tp not in _NOUNS:  # fail here rather than print a library's repr into the reference
        raise TypeError(f"the reference has no words for the type {tp!r}: add it to _NOUNS")
    noun = _NOUNS[tp][1 if plural else 0]
    words = ("finite " if _finite(tp, constraints) else "") + noun
    return " ".join([words, *(_bounds(constraints) if bounds else [])])


def _literal_noun(args: tuple[Any, ...], plural: bool) -> str:
    noun = _NOUNS[str if all(isinstance(a, str) for a in args) else int]
    return noun[1 if plural else 0]


def _tuple_words(args: tuple[Any, ...], plural: bool) -> str:
    parts = [type_words(a, False, True) for a in args]
    kind = _TUPLES.get(len(parts), (f"tuple of {len(parts)}", f"tuples of {len(parts)}"))
    kind = kind[1 if plural else 0]
    if len(set(parts)) == 1:
        return f"{kind} of {type_words(args[0], True, True)}"
    return f"{kind} ({', '.join(parts)})"


def _bounds(constraints: list[Any], items: str = "items") -> list[str]:
    out = []
    for c in constraints:
        if isinstance(c, at.Gt):
            out.append(f"> {c.gt}")
        elif isinstance(c, at.Ge):
            out.append(f">= {c.ge}")
        elif isinstance(c, at.Lt):
            out.append(f"< {c.lt}")
        elif isinstance(c, at.Le):
            out.append(f"<= {c.le}")
        elif isinstance(c, at.MinLen) and c.min_length > 0:
            out.append(f"at least {c.min_length} {items[:-1] if c.min_length == 1 else items}")
        elif isinstance(c, at.MaxLen):
            out.append(f"at most {c.max_length} {items}")
    return out


def _allowed(info: FieldInfo) -> str:
    tp, constraints, _ = _strip(info.annotation)
    parts = _bounds(list(info.metadata) + constraints,
                    "characters" if tp is str else "items")
    if typing.get_origin(tp) is Literal:
        parts.append(", ".join(toml_value(a) for a in typing.get_args(tp)))
    elif typing.get_origin(tp) is list:
        item, inner, _ = _strip(typing.get_args(tp)[0])
        if typing.get_origin(item) is Literal:
            parts.append("each one of " + ", ".join(toml_value(a) for a in typing.get_args(item)))
        else:
            parts += [f"each {b}" for b in _bounds(inner)]
    return "; ".join(parts)


def _default(info: FieldInfo) -> str:
    if info.default_factory is not None:
        value = info.default_factory()  # type: ignore[call-arg]
    elif info.default is PydanticUndefined:
        return "required"
    else:
        value = info.default
    if value is None:
        return "none"
    if isinstance(value, BaseModel):
        value = value.model_dump(exclude_defaults=True)
        return "all defaults" if not value else toml_value(value)
    return toml_value(value)


def _models(model: type[BaseModel], path: str, seen: dict[type, list[str]]) -> None:
    """Every model reachable from ``model`` with the paths where it appears."""
    seen.setdefault(model, []).append(path)
    if len(seen[model]) > 1:
        return
    for name, info in model.model_fields.items():
        tp, _, _ = _strip(info.annotation)
        is_list = typing.get_origin(tp) is list
        if is_list:
            tp, _, _ = _strip(typing.get_args(tp)[0])
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            sub = f"{path}.{name}" if path else name
            _models(tp, sub + ("[]" if is_list else ""), seen)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def _doc(model: type[BaseModel]) -> str:
    doc = model.__doc__ or ""
    return " ".join(line.strip() for line in doc.strip().splitlines()).replace("``", "`")


def _model_section(model: type[BaseModel], paths: list[str]) -> list[str]:
    title = ", ".join(f"`{p}`" for p in paths) if paths != [""] else "the top level"
    out = [f'<a id="{_anchor(model)}"></a>', "", f"## {model.__name__}: {title}", ""]
    if _doc(model):
        out += [_doc(model), ""]
    out += [_row(["field", "unit", "type", "default", "allowed", "description"]),
            "|---|---|---|---|---|---|"]
    for name, info in model.model_fields.items():
        words = type_words(info.annotation, constraints=list(info.metadata))
        out.append(_row([f"`{name}`", unit_of(name, info), words,
                         _default(info), _allowed(info), info.description or ""]))
    return out + [""]


def _option_row(o: Option) -> str:
    return _row([f"`{o.name}`", _KINDS[o.kind], o.shown_default(), o.allowed(), o.meaning])


def _filter_section() -> list[str]:
    out = ["## Filter types and their options", "",
           "`filters[].type` names the filter; `filters[].options` sets its options (names as "
           "in the filter's constructor in `trackkit.filters`). An option left out takes its "
           "default; an unknown option, a value of the wrong type or out of range is refused "
           "when the scenario is read.", ""]
    groups: dict[int, list[str]] = {}
    for name, t in FILTER_TYPES.items():
        groups.setdefault(id(t.options) if t.options else id(t), []).append(name)
    for names in groups.values():
        t = FILTER_TYPES[names[0]]
        out += [f"### {', '.join(names)}", ""]
        out += [f"- `{n}`: {FILTER_TYPES[n].meaning}" for n in names] + [""]
        if not t.options:
            out += ["No options.", ""]
            continue
        out += [_row(["option", "type", "default", "allowed", "meaning"]),
                "|---|---|---|---|---|"]
        out += [_option_row(o) for o in t.options] + [""]
    return out


def reference() -> str:
    """The scenario reference as Markdown."""
    out = [
        "# Scenario reference", "",
        f"Generated from `trackkit.scenario.schema` by `{COMMAND}`; do not edit by hand.", "",
        "A scenario is a TOML file (UTF-8); `trackkit show NAME` prints a bundled one with "
        "every default filled in, a good start for your own. Units are in the field names "
        "and converted to SI once, when the scenario is read:", "",
        _row(["suffix", "unit"]), "|---|---|",
        *[_row([f"`{s}`", u]) for s, u in SUFFIXES.items()], "",
        "Fields without a suffix give their unit in the unit column; `SI` means metres, "
        "seconds, radians and hertz, and a state vector (`target.state`, `prior.std`, "
        "`prior.mean`) lists SI values in trackkit's state order: positions, velocities, then "
        "extras (`[x, y, vx, vy]`, `[x, y, z, vx, vy, vz]`). `name` becomes the report's "
        "folder, `trackkit-out/NAME`, so it must be a plain file name. Values a run in double "
        "precision cannot carry (a covariance entry above 1e150, a first update whose noise "
        "is more than 1e6 times smaller than the predicted spread) are refused with the "
        "field that causes them.", "",
    ]
    seen: dict[type, list[str]] = {}
    _models(Scenario, "", seen)
    for model, paths in seen.items():
        out += _model_section(model, paths)
    out += _filter_section()
    return "\n".join(out).rstrip("\n") + "\n"


if __name__ == "__main__":
    print(reference(), end="")

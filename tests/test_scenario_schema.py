"""The scenario package: filter options validated from one table that agrees with
the constructors, plain scenario names, numbers a run cannot carry refused at load, ``load``
errors in words, TOML out (``dumps``) that reads back to an equal scenario, and the generated
scenario reference kept current."""

from __future__ import annotations

import copy
import inspect
import math
import tomllib
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

import trackkit.scenario as S
from trackkit.scenario.build import COV_LIMIT, PRECISION_LIMIT
from trackkit.scenario.options import FILTER_TYPES, make_filter
from trackkit.scenario.reference import COMMAND, reference
from trackkit.scenario.schema import FilterSpec, Scenario
from trackkit.scenario.toml_writer import _string

REPO = Path(__file__).resolve().parents[1]
BO_CV = (Path(S.__file__).parent / "scenarios" / "bo-cv.toml").read_text()


def bo_cv() -> dict:
    return copy.deepcopy(S.load("bo-cv").model_dump())


def problem(d: dict, source: str = "bad.toml") -> str:
    """The ScenarioError of parsing ``d``; it names ``source`` first."""
    with pytest.raises(S.ScenarioError) as err:
        S.parse(d, source)
    msg = str(err.value)
    assert msg.startswith(f"{source}: "), msg
    return msg


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --------------------------------------------------------------------------------------------
# 1. Filter options: one table, checked against the constructors
# --------------------------------------------------------------------------------------------


def _params(t) -> dict[str, inspect.Parameter]:
    sig = inspect.signature(t.constructor)
    return {n: p for n, p in sig.parameters.items()
            if n not in ("self", "base") and n not in t.fixed}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return list(a) == list(b)
    return type(a) is type(b) and a == b


# the annotation each kind of option must have in the constructor's signature
KIND_ANNOTATIONS = {"int": {"int"}, "float": {"float", "float | None"}, "bool": {"bool"},
                    "choice": {"str"}, "floats": {"ArrayLike", "tuple[float, float] | None"},
                    "pairs": {"tuple[tuple[int, int], ...] | None"}}


@pytest.mark.parametrize("type_", FILTER_TYPES)
def test_option_table_matches_the_constructor_signature(type_):
    t = FILTER_TYPES[type_]
    params = _params(t)
    assert [o.name for o in t.options] == list(params), (
        f"{type_}: the table's options differ from {t.constructor.__name__}'s arguments")
    for o in t.options:
        p = params[o.name]
        assert _same(o.default, p.default), (type_, o.name, o.default, p.default)
        assert str(p.annotation) in KIND_ANNOTATIONS[o.kind], (type_, o.name, p.annotation)
        assert o.meaning and o.allowed()
    # fixed arguments are arguments too, and the fuzzy base is a filter type of the table
    assert set(t.fixed) <= set(inspect.signature(t.constructor).parameters)
    assert t.base is None or t.base in FILTER_TYPES


def _probes(o) -> list[Any]:
    if o.kind == "int":
        return [-1, 0, 1, 2, 3, 25, 2.5, 5.0, True, "5"]
    if o.kind == "float":
        return [-1.0, 0.0, 1e-9, 0.5, 0.97, 1.0, 1.5, 1e7, math.nan, math.inf, "abc", [1.0]]
    if o.kind == "bool":
        return [True, False, 1, "yes"]
    if o.kind == "choice":
        return [*o.choices, "nope", 1]
    if o.kind == "pairs":
        return [[0, 0], [0, 1, 1, 0], [0, 0, 1], [-1, 0], [0.5, 1], "0 0"]
    if o.size == 2:
        return [[1e-3, 1e3], [2.0, 2.0], [2.0, 1.0], [0.0, 1.0], [-1.0, 1.0], [1.0],
                [1.0, math.inf], "1, 2"]
    good = list(map(float, o.default))
    bad_width = good[:5] + [0.0] + good[6:]
    unordered = [good[1], good[0]] + good[2:]
    return [good, bad_width, unordered, good[:14], good[:14] + [math.nan]]


def _schema_refuses(type_: str, options: dict) -> bool:
    spec = {"name": "f", "type": type_, "options": options}
    if FILTER_TYPES[type_].base is not None and "params" not in options:
        spec["tune"] = {}
    try:
        FilterSpec.model_validate(spec)
    except ValueError:
        return True
    return False


@pytest.mark.parametrize("type_, option", [(t, o.name) for t in FILTER_TYPES
                                           for o in FILTER_TYPES[t].options])
def test_what_the_constructor_refuses_the_schema_refuses(type_, option):
    """For every option and a spread of values, inside and outside its range: a value the
    filter's constructor refuses is refused when the scenario is read (the table may be
    stricter: true/false only for a flag); a value the schema accepts builds the filter."""
    t = FILTER_TYPES[type_]
    o = t.option(option)
    for value in _probes(o):
        kwargs = {option: tuple(value) if isinstance(value, list) else value}
        if option == "q_inputs" and isinstance(value, list) and len(value) % 2 == 0:
            kwargs[option] = tuple(zip(value[::2], value[1::2], strict=True))
        if t.base is not None:
            kwargs["base"] = make_filter(t.base, {})
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t.constructor(**t.fixed, **kwargs)
            constructor_refuses = False
        except (ValueError, TypeError):
            constructor_refuses = True
        refused = _schema_refuses(type_, {option: value})
        if constructor_refuses:
            assert refused, f"{type_} {option} = {value!r}: the constructor refuses it"
        if not refused:
            spec = FilterSpec.model_validate(
                {"name": "f", "type": type_, "options": {option: value}}
                | ({"tune": {}} if t.base and option != "params" else {}))
            make_filter(type_, spec.options)


@pytest.mark.parametrize("options, words", [
    ({"alpha": "abc"}, ["filters.2.options.alpha = 'abc'", "filter 'UKF' (UKF)",
                        "expected a number > 0", "default 0.5"]),
    ({"alpha": -1.0}, ["filters.2.options.alpha = -1.0", "'UKF'", "expected a number > 0"]),
    ({"kappa": -4.0}, ["filters.2.options.kappa = -4.0", "expected a number > -n = -4",
                       "n = 4"]),
    ({"gamma": 1}, ["filters.2.options.gamma = 1", "has no option gamma",
                    "allowed: alpha, beta, kappa"]),
])
def test_bad_ukf_options_name_the_file_filter_option_value_and_allowed(tmp_path, options,
                                                                       words):
    inline = ", ".join(f"{k} = {v!r}".replace("'", '"') for k, v in options.items())
    text = BO_CV.replace('type = "UKF"\n', f'type = "UKF"\noptions = {{ {inline} }}\n')
    p = write(tmp_path, text)
    with pytest.raises(S.ScenarioError) as err:
        S.load(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}: 1 problem(s)"), msg
    for w in words:
        assert w in msg, (w, msg)


def test_iekf_iterations_must_be_an_integer():
    d = bo_cv()
    d["filters"][1]["options"] = {"iterations": 2.5}
    msg = problem(d)
    assert "filters.1.options.iterations = 2.5" in msg and "an integer >= 1" in msg
    d["filters"][1]["options"] = {"iterations": 3.0}  # a TOML float, as the IEKF says
    assert "filters.1.options.iterations = 3.0" in problem(d)
    d["filters"][1]["options"] = {"iterations": 3}
    assert S.parse(d).filters[1].options == {"iterations": 3}


def test_options_that_depend_on_each_other_are_checked_by_building_the_filter():
    d = copy.deepcopy(S.load("uw-ch3-r").model_dump())
    d["filters"][3]["options"] = {"floor": 10.0, "ceiling": 5.0}
    msg = problem(d)
    assert "filters.3.options" in msg and "ceiling" in msg and "> floor" in msg
    d["filters"][3]["options"] = {"params": [0.0] * 15}
    d["filters"][3]["tune"] = None
    msg = problem(d)
    assert "filters.3.options" in msg and "widths" in msg


def test_a_none_option_is_its_default_where_the_default_is_none():
    d = bo_cv()
    d["filters"][2]["options"] = {"kappa": None}
    assert S.parse(d).filters[2].options == {}
    d["filters"][2]["options"] = {"alpha": None}
    assert "filters.2.options.alpha = None" in problem(d)


# --------------------------------------------------------------------------------------------
# 2. Scenario names are plain file names
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["../../escaped", "/tmp/abs", ".hidden", "a/b", "a b", "",
                                  "x" * 256, "C:\\out"])
def test_names_that_are_not_plain_file_names_are_refused(name):
    d = bo_cv()
    d["name"] = name
    msg = problem(d)
    assert f"\n  name = {repr(name)[:40]}" in msg, msg


@pytest.mark.parametrize("name", ["bo-cv", "my_run.2", "A-1", "-x"])
def test_plain_names_are_accepted(name):
    d = bo_cv()
    d["name"] = name
    assert S.parse(d).name == name


def test_the_message_for_a_bad_name_says_what_is_allowed():
    d = bo_cv()
    d["name"] = "../../escaped"
    msg = problem(d)
    assert "name = '../../escaped': expected a plain file name" in msg
    assert "trackkit-out/NAME" in msg


# --------------------------------------------------------------------------------------------
# 3. Numbers a run cannot carry are refused at load, by field
# --------------------------------------------------------------------------------------------


def _set(d: dict, path: str, value: Any) -> dict:
    *parents, last = path.split(".")
    obj = d
    for part in parents:
        obj = obj[int(part)] if part.isdigit() else obj[part]
    obj[last] = value
    return d


@pytest.mark.parametrize("scenario, path, value, words", [
    ("bo-cv", "target.motion.q", 1e300, ["expected q <= about", "1.8e308"]),
    ("bo-cv", "target.motion.q", 1e20, ["mostly from this process noise"]),
    ("bo-cv", "observers.0.sensor.sigma_deg", 1e-9, ["expected sigma_deg >= 9.56e-06",
                                                     "tighter prior"]),
    ("bo-cv", "observers.0.sensor.sigma_deg", 1e300, ["noise variance of the bearing"]),
    ("bo-cv", "prior.std", [1e200, 1.0, 1.0, 1.0], ["prior variances"]),
    ("bo-cv", "prior.std", [1e-200, 1.0, 1.0, 1.0], ["prior variances"]),
    ("cv-position", "observers.0.sensor.sigma_m", 1e-7, ["expected sigma_m >= "]),
    ("uw-ch5-fixed", "filters.0.r0_diag_si", [1e-30] * 4, ["bearing"]),
    ("uw-ch4-delays", "observers.0.sensor.snr_db", 400.0, ["expected snr_db <= "]),
])
def test_numbers_a_run_cannot_carry_name_the_field(scenario, path, value, words):
    d = copy.deepcopy(S.load(scenario).model_dump())
    for f in d["filters"]:  # the filters believe the true R (uw-ch4's own R0 hides it)
        f["r0_diag_si"] = None
    d = _set(d, path, value)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # and no numpy warning on the way
        msg = problem(d)
    shown = repr(value) if not isinstance(value, list) else repr(value)[:20]
    assert f"{path} = {shown}" in msg, msg
    for w in words:
        assert w in msg, (w, msg)


def test_a_filters_own_motion_is_named_as_the_filters():
    d = bo_cv()
    d["filters"][0]["motion"] = {"model": "ConstantVelocity", "q": 1e300}
    msg = problem(d)
    assert "filters.0.motion.q = 1e+300" in msg and "target.motion" not in msg


def test_sizes_the_built_models_check_are_reported_at_load():
    d = copy.deepcopy(S.load("uw-ch5-fixed").model_dump())
    d["filters"][0]["r0_diag_si"] = [1.0, 1.0, 1.0]
    assert "filters.0.r0_diag_si = [1.0, 1.0, 1.0]: filter 'EKF': r0_diag_si has 3 values; " \
        "expected 4" in problem(d)


def _short_bo_cv(sigma_deg: float) -> dict:
    d = _set(bo_cv(), "observers.0.sensor.sigma_deg", sigma_deg)
    d["time"]["duration_s"] = 300.0
    d["report"]["average_from_s"] = 0.0
    d["observers"][0]["legs"] = [{"start_s": 100.0, "end_s": 190.0, "turn_rate_deg_s": -1.0}]
    return d


def test_the_precision_limit_sits_between_what_runs_and_what_fails():
    """Just inside the limit the run goes through; far beyond it (sigma_deg = 1e-8, where
    the UKF's covariance stops being positive definite) the scenario is refused at load."""
    from trackkit.experiments.montecarlo import run_scenario

    bearing_spread = 0.167  # rad: the first predicted bearing's std in bo-cv
    inside = math.degrees(bearing_spread / math.sqrt(PRECISION_LIMIT)) * 2
    result = run_scenario(S.parse(_short_bo_cv(inside)), runs=4)
    assert set(result.filters) == {"EKF", "IEKF", "UKF", "CKF", "RPEKF", "MPEKF", "PF"}
    assert "observers.0.sensor.sigma_deg" in problem(_short_bo_cv(inside / 4))
    assert "observers.0.sensor.sigma_deg" in problem(_short_bo_cv(1e-8))


def test_the_covariance_limit_keeps_products_finite():
    assert (1e4 * COV_LIMIT) ** 2 < np.finfo(float).max


# --------------------------------------------------------------------------------------------
# 4. load: errors in words
# --------------------------------------------------------------------------------------------


def test_a_file_that_is_not_utf8_is_named(tmp_path):
    p = tmp_path / "latin1.toml"
    p.write_bytes(BO_CV.replace("Classic", "Classic \xb5").encode("latin-1"))
    with pytest.raises(S.ScenarioError) as err:
        S.load(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}: not UTF-8 text (byte 0xb5 on line 4)"), msg


def test_a_directory_is_not_a_missing_file(tmp_path):
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(S.ScenarioError, match="is a directory; expected a scenario .toml"):
        S.load(tmp_path / "dir.toml")
    with pytest.raises(S.ScenarioError, match="is a directory"):
        S.load(tmp_path)
    with pytest.raises(S.ScenarioError, match="no such scenario file"):
        S.load(tmp_path / "missing.toml")


def test_a_utf8_bom_is_read(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + BO_CV.encode())
    assert S.load(p) == S.load("bo-cv")


def test_a_bundled_name_is_a_name_not_a_path():
    with pytest.raises(S.ScenarioError, match="no bundled scenario named '../scenarios/bo-cv'"):
        S.load("../scenarios/bo-cv")


# --------------------------------------------------------------------------------------------
# 5. dumps: TOML that reads back to an equal scenario
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", S.bundled())
def test_dumps_of_every_bundled_scenario_loads_back_equal(name, tmp_path):
    s = S.load(name)
    text = S.dumps(s)
    assert S.load(write(tmp_path, text, f"{name}.toml")) == s
    assert text == S.dumps(S.parse(tomllib.loads(text)))  # a fixed point
    assert "None" not in text and "null" not in text


def test_dumps_writes_the_defaults_and_the_layout_of_a_scenario_file():
    text = S.dumps(S.load("bo-cv"))
    assert text.startswith('name = "bo-cv"\n')
    for line in ["[time]", "[[observers]]", "[[filters]]", "[run]", "block = 250",
                 "[report]", "matching = false", 'options = { iterations = 5 }']:
        assert line in text.splitlines(), line
    assert text.index("notes = [") < text.index("[time]")  # top-level values first


_TEXT = st.text(st.characters(codec="utf-8"), max_size=40)
_FLOAT = st.floats(allow_nan=False, allow_infinity=False)
_POSITIVE = st.floats(min_value=5e-324, allow_infinity=False)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.from_regex(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,20}", fullmatch=True),
       description=_TEXT, notes=st.lists(_TEXT, max_size=3),
       filter_name=_TEXT, course=_FLOAT, x_m=st.floats(-1e6, 1e6),
       c_mps=_POSITIVE, tau=_POSITIVE, q_omega=st.floats(min_value=0.0, allow_infinity=False),
       dom_alpha=_POSITIVE, alpha=st.floats(min_value=1e-3, max_value=10.0),
       sigma_deg=st.floats(min_value=1e-4, max_value=90.0))
def test_dumps_round_trips_strings_and_floats(name, description, notes, filter_name, course,
                                              x_m, c_mps, tau, q_omega, dom_alpha, alpha,
                                              sigma_deg):
    d = bo_cv()
    d.update(name=name, description=description, notes=notes)
    d["filters"][0]["name"] = "EKF " + filter_name  # unique among the filters
    d["filters"][2]["options"] = {"alpha": alpha}
    d["target"]["initial"]["course_deg"] = course
    d["observers"][0]["initial"]["x_m"] = x_m
    d["observers"][0]["sensor"].update(c_mps=c_mps, sigma_deg=sigma_deg)
    d["target"]["motion"].update(tau=tau, q_omega=q_omega)
    d["report"]["dom_alpha"] = dom_alpha
    s = S.parse(d)
    assert S.parse(tomllib.loads(S.dumps(s))) == s


@given(st.text())
def test_strings_are_escaped_as_toml_requires(s):
    assert tomllib.loads(f"k = {_string(s)}\n") == {"k": s}


# --------------------------------------------------------------------------------------------
# 6. The scenario reference
# --------------------------------------------------------------------------------------------


def test_the_scenario_reference_is_current():
    committed = (REPO / "docs" / "scenario-reference.md").read_text(encoding="utf-8")
    assert committed == reference(), f"docs/scenario-reference.md is stale; run: {COMMAND}"


@pytest.mark.parametrize("text", ["FieldInfo", "typing.", "Annotated", "<class", "_Pydantic"])
def test_the_reference_states_types_in_words_not_in_a_library_repr(text):
    committed = (REPO / "docs" / "scenario-reference.md").read_text(encoding="utf-8")
    lines = [line for line in committed.splitlines() if text in line]
    assert not lines, f"{text!r} in docs/scenario-reference.md: {lines[0]}"


def test_type_words_describe_the_annotation_and_its_constraints():
    from typing import Annotated, Literal

    from pydantic import Field

    from trackkit.scenario.reference import type_words

    class Inner(BaseModel):
        """A nested table."""

    nonneg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
    count = Annotated[int, Field(ge=1)]
    cases = {
        list[tuple[nonneg, nonneg]]: "list of pairs of finite numbers >= 0",
        list[tuple[Annotated[int, Field(ge=0)], count]]:
            "list of pairs (integer >= 0, integer >= 1)",
        nonneg | None: "optional finite number",
        Annotated[float, Field(gt=0, le=1)]: "finite number",
        float: "number",
        list[list[nonneg]]: "list of lists of finite numbers",
        tuple[int, int, int]: "triple of integers",
        dict[str, list[nonneg]]: "table mapping names to lists of finite numbers >= 0",
        Literal["a", "b"]: "string",
        list[Literal["a", "b"]]: "list of strings",
        tuple[Literal["a", "b"], bool]: 'pair (one of "a", "b", boolean)',
        Inner | None: "optional table ([Inner](#inner))",
        list[Inner]: "array of tables ([Inner](#inner))",
        dict[str, Any]: "table mapping names to values",
    }
    for tp, words in cases.items():
        assert type_words(tp) == words, tp


def _models(model, seen):
    if model in seen:
        return
    seen.add(model)
    for info in model.model_fields.values():
        for arg in _walk(info.annotation):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                _models(arg, seen)


def _walk(tp):
    yield tp
    for a in getattr(tp, "__args__", ()) or ():
        yield from _walk(a)
    for a in getattr(tp, "__metadata__", ()) or ():
        yield a


def test_every_field_is_described_in_the_reference():
    seen: set = set()
    _models(Scenario, seen)
    assert len(seen) >= 12
    text = reference()
    for model in seen:
        for name, info in model.model_fields.items():
            assert info.description, f"{model.__name__}.{name} has no description"
            assert f"| `{name}` |" in text
    for t in FILTER_TYPES.values():
        for o in t.options:
            assert f"| `{o.name}` | " in text

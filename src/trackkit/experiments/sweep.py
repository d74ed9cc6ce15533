"""Campaigns: a full Monte Carlo comparison at every point of a sweep over scenario fields.

    from trackkit.experiments.sweep import parse_param, plan_campaign, run_campaign
    from trackkit.experiments.checkpoint import CampaignStore
    c = plan_campaign(load("bo-cv"), [parse_param("sensor.sigma_deg=1,2,4"),
                                     parse_param("filters.EKF.motion.q=1e-5,1e-4,1e-3")],
                      runs=200, seed=7, block=50)
    store = CampaignStore("out/")
    store.open(c.identity())
    docs = run_campaign(c, store, workers=4)      # one result document per point, design order

**Parameters.** A swept field is named by its dotted path as ``trackkit show`` prints it, list
items by index (``observers.0.sensor.sigma_deg``; ``observers[0]`` works too) and filters by
name (``filters.EKF.motion.q``). ``sensor.X`` is every observer's sensor. A filter's own
assumptions apart from the truth are its ``motion`` (its process noise ``q``; a filter without
its own motion starts from a copy of the target's), its ``prior`` (from the scenario's) and
``r0_diag_si`` (the R it believes, a list: ``filters.EKF.r0_diag_si=[3e-4],[1.2e-3]``). The
values are TOML values (numbers, ``true``, ``"text"``, ``[lists]``; a bare word is text),
validated by the scenario schema at every point; ``LOW:HIGH`` and ``log:LOW:HIGH`` are ranges
for the seeded random and Latin-hypercube designs (a grid takes ``points`` evenly spaced
values of a range). ``run.*`` is not swept: runs, seed and block belong to the campaign.

**Every item, and factors.** ``*`` in a path stands for every item of a list:
``filters.*.motion.q`` is every filter's q, swept together (one column, one value per point).
A value ``xF`` (or ``*F``), F a finite number > 0, is a factor: the field's value in the
scenario times F, a number multiplied, a list elementwise. So

    --param 'filters.*.motion.q=x0.1,x1,x10,x100' --param 'filters.*.r0_diag_si=x0.1,x1,x10'

mis-specifies every filter's Q0 and R0 together, each relative to its own well-specified
value. Where a filter has no ``r0_diag_si`` (it believes the true R), the base of a factor is
the true R: the diagonal of the point's sensor noise (every observer's channels, in order).
Where it has no ``motion`` or ``prior``, the base is the target's or the scenario's, as
above. The factors of a point apply after its plain values, and the truth's before the
filters', so ``filters.*.r0_diag_si=x0.5`` beside ``sensor.sigma_deg=1,2`` is half of each
point's own true variances. A parameter's values are all factors or all plain values; a
factor is listed, never a range. The point records the factor (``"x10"``, the text of the
table's column), its scenario the values it makes.

**Seeds.** A point's seed is a hash of the campaign seed and the canonical JSON of its
values (``point_seed``), never its position in the design, so adding points leaves the others'
runs unchanged; run ``r`` of a point draws from ``run_rng(point seed, r)`` as in ``trackkit
run``, and all filters at a point see the same truths and measurements. Only the values that
change the simulation enter the hash (not ``filters.*``, factors included): points that
differ only in the filters' assumptions share their truths and measurements (common random
numbers).

**Execution.** Every (point, block) is one task, in this process or on Dask (a local cluster
with ``workers``, or the scheduler at ``scheduler``), with one client for the whole campaign.
Each finished block is stored at once (``trackkit.experiments.checkpoint``); a point is combined
(``combine``) from its stored blocks once they are all there, so a result is the same bits
whether its blocks came from one process, several workers, a worker that died, or a campaign
interrupted and resumed. A block that fails ``attempts`` times stops the campaign with
``BlockFailed`` naming the point, the block and the error; the blocks finished stay stored.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import threading
import tomllib
import uuid
from collections.abc import Callable, Sequence
from copy import deepcopy
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from trackkit.experiments.checkpoint import CampaignStore, code_version
from trackkit.experiments.executors import dask_client
from trackkit.experiments.montecarlo import check_memory, combine, plan_of, run_blocks, with_run
from trackkit.experiments.results import MonteCarloResult
from trackkit.scenario.schema import Scenario, parse_range

__all__ = ["Param", "Point", "Campaign", "BlockFailed", "Listener", "parse_param",
           "params_from_table", "plan_campaign", "point_seed", "point_id", "canonical",
           "run_campaign", "point_document", "truth_values", "factor_of", "DESIGNS",
           "ATTEMPTS"]

#: The campaign designs: the full grid, uniform random points, a Latin hypercube.
DESIGNS = ("grid", "random", "lhs")
#: times a block is tried before the campaign stops
ATTEMPTS = 3
#: fields that belong to the campaign, not to a point
_NOT_SWEPT = {"run": "runs, seed and block belong to the campaign: use --runs, --seed, --block",
              "sweep": "the sweep cannot sweep itself", "name": "the name is the campaign's",
              "description": "not a number of the comparison",
              "notes": "not a number of the comparison"}


# --- parameters ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Param:
    """One swept field: its ``path`` and either ``values`` or a range ``low``..``high``
    (log-uniform with ``log``). ``source`` names it in messages (``--param PATH=...``)."""

    path: str
    values: tuple[Any, ...] | None = None
    low: float | None = None
    high: float | None = None
    log: bool = False
    source: str = ""

    @property
    def is_range(self) -> bool:
        return self.values is None

    @property
    def relative(self) -> bool:
        """Its values are factors of the scenario's value (``x0.1``), not values."""
        return not self.is_range and factor_of(self.values[0]) is not None

    def describe(self) -> str:
        if self.is_range:
            return f"{'log:' if self.log else ''}{self.low:g}:{self.high:g}"
        return ", ".join(_show(v) for v in self.values)


def _show(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, str):
        return v
    return json.dumps(v)


def _split_top(text: str) -> list[str]:
    """Split at commas outside brackets, braces and quotes (a value may be a list)."""
    out, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    out.append("".join(cur))
    return [t.strip() for t in out]


def _value(token: str) -> Any:
    """A value as TOML reads it (numbers, booleans, strings, arrays, inline tables); a
    plain number TOML refuses (``.5``, ``5.``) as a float; anything else as text."""
    try:
        return tomllib.loads(f"v = {token}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    try:
        return float(token)
    except ValueError:
        return token


#: a factor of the scenario's value: ``x0.1``, ``*10``, ``x1e-3``
_FACTOR = re.compile(r"\s*[x*]\s*([-+0-9.eEinfINFaN]+)\s*")


def factor_of(value: Any) -> float | None:
    """The factor F of a value ``"xF"`` (as a point records it), else None."""
    if not isinstance(value, str):
        return None
    m = _FACTOR.fullmatch(value)
    if m is None:
        return None
    try:
        return float(m.group(1))
    except ValueError:
        return None


def _factor_text(f: float) -> str:
    """The one spelling of a factor: ``x`` and the shortest float text, ``x10`` not
    ``x10.0`` (a point's id hashes it)."""
    text = repr(float(f))
    return "x" + (text[:-2] if text.endswith(".0") else text)


def _factors(path: str, values: Sequence[Any], source: str) -> tuple[Any, ...]:
    """``values`` as given, or, when they are factors, in their one spelling; an error names
    a bad factor and a mix of factors and plain values."""
    out, plain = [], []
    for v in values:
        text = v.strip() if isinstance(v, str) else None
        if text is None or not text or text[0] not in "x*":
            plain.append(v)
            out.append(v)
            continue
        f = factor_of(text)
        if f is None or not (math.isfinite(f) and f > 0):
            if text[0] == "x" and f is None and ":" not in text:
                plain.append(v)  # a text value that happens to begin with x
                out.append(v)
                continue
            raise ValueError(f"{source}: value {text!r} of {path}: expected a factor xF or *F "
                             "with F a finite number > 0, listed (e.g. x0.1,x1,x10; a factor "
                             "is never a range)")
        out.append(_factor_text(f))
    factors = [x for x in out if factor_of(x) is not None]
    if factors and plain:
        raise ValueError(f"{source}: {path} mixes factors ({', '.join(factors)}) and plain "
                         f"values ({', '.join(_show(x) for x in plain)}); expected all "
                         "factors (x0.1,x1,x10) or all values")
    return tuple(out)


def _normal_path(path: str) -> str:
    path = re.sub(r"\[(\w+)\]", r".\1", path.strip())
    return path.strip(".")


def parse_param(text: str, source: str | None = None) -> Param:
    """``PATH=V1,V2,...``, ``PATH=LOW:HIGH`` or ``PATH=log:LOW:HIGH`` (``--param``)."""
    source = source or f"--param {text}"
    path, sep, rhs = text.partition("=")
    path = _normal_path(path)
    if not sep or not path or not rhs.strip():
        raise ValueError(f"{source}: expected PATH=V1,V2,... or PATH=LOW:HIGH or "
                         "PATH=log:LOW:HIGH (e.g. --param sensor.sigma_deg=1,2,4)")
    try:
        rng = parse_range(rhs)
    except ValueError as err:
        raise ValueError(f"{source}: {err}") from None
    if rng is not None:
        return Param(path, None, rng[0], rng[1], rng[2], source)
    tokens = _split_top(rhs)
    if any(not t for t in tokens):
        raise ValueError(f"{source}: an empty value in {rhs!r}; expected values separated "
                         "by commas")
    return Param(path, _factors(path, [_value(t) for t in tokens], source), source=source)


def params_from_table(table: Any) -> list[Param]:
    """The parameters of a scenario's ``[sweep]`` table (``SweepSpec``)."""
    out = []
    for path, values in table.params.items():
        source = f"[sweep] params.{json.dumps(path)}"
        if isinstance(values, str):
            low, high, log = parse_range(values)
            out.append(Param(_normal_path(path), None, low, high, log, source))
        else:
            out.append(Param(_normal_path(path), _factors(path, values, source),
                             source=source))
    return out


# --- where a path points in a scenario ----------------------------------------------------


def _locate(data: dict, path: str, source: str) -> list[tuple[Any, ...]]:
    """The concrete locations (keys and list indices from the top) that ``path`` names in
    the scenario ``data`` (a ``model_dump``); ``sensor.X`` names every observer's."""
    parts = path.split(".")
    if parts[0] in _NOT_SWEPT:
        raise ValueError(f"{source}: {parts[0]} is not swept ({_NOT_SWEPT[parts[0]]})")
    if "*" in parts:  # every item of the list before it
        j = parts.index("*")
        head = ".".join(parts[:j])
        if not head:
            raise ValueError(f"{source}: {path} begins with *; expected * after a list, "
                             "e.g. filters.*.motion.q")
        (where,) = _locate(data, head, source)
        items = _get(data, where)
        if not isinstance(items, list):
            raise ValueError(f"{source}: {head} is not a list, so * (every item) cannot "
                             f"follow it; expected a list such as filters or observers")
        return [loc for i in range(len(items))
                for loc in _locate(data, ".".join([head, str(i), *parts[j + 1:]]), source)]
    if parts[0] == "sensor" and "sensor" not in data:
        return [loc for i in range(len(data["observers"]))
                for loc in _locate(data, ".".join(["observers", str(i), *parts]), source)]
    loc: list[Any] = []
    node: Any = data
    for j, part in enumerate(parts):
        here = ".".join(map(str, loc)) or "the scenario"
        last = j == len(parts) - 1
        if isinstance(node, list):
            names = [x.get("name") for x in node if isinstance(x, dict)]
            if part in names:
                k: Any = names.index(part)
            elif part.isdigit() and int(part) < len(node):
                k = int(part)
            else:
                named = f" or a name among {names}" if any(names) else ""
                raise ValueError(f"{source}: {here} has no item {part!r}; expected an index "
                                 f"0 .. {len(node) - 1}{named}")
            loc.append(k)
            node = node[k]
        elif isinstance(node, dict):
            if part not in node and not (loc and loc[-1] == "options"):
                raise ValueError(f"{source}: {here} has no field {part!r}; expected one of "
                                 f"{sorted(node)}")
            loc.append(part)
            node = node.get(part)
            if node is None and not last:
                node = _default_table(data, loc)
        else:
            raise ValueError(f"{source}: {here} is a value ({node!r}), not a table; "
                             f"{'.'.join(parts[j:])} cannot be inside it")
    return [tuple(loc)]


def _canonical_path(data: dict, p: Param, locs: list[tuple[Any, ...]]) -> str:
    """One spelling per field: a filter by its name, a list item by its index (the
    ``sensor.`` shorthand, naming several fields, stays as it is)."""
    if len(locs) != 1 or p.path.split(".")[0] == "sensor" or "*" in p.path.split("."):
        return p.path
    loc = locs[0]
    parts = [str(k) for k in loc]
    if loc[0] == "filters" and len(loc) > 1:
        parts[1] = str(data["filters"][loc[1]]["name"])
    return ".".join(parts)


def _default_table(data: dict, loc: list[Any]) -> dict:
    """What an absent table starts from when a field inside it is swept: a filter's own
    motion from the target's, its prior from the scenario's, anything else empty."""
    if len(loc) == 3 and loc[0] == "filters" and loc[2] == "motion":
        return deepcopy(data["target"]["motion"])
    if len(loc) == 3 and loc[0] == "filters" and loc[2] == "prior":
        # only what a filter's prior holds (the scenario's may say how runs start, too)
        from trackkit.scenario.schema import FilterSpec

        allowed = _model_fields(FilterSpec.model_fields["prior"].annotation)
        return {k: deepcopy(v) for k, v in data["prior"].items()
                if allowed is None or k in allowed}
    return {}


def _model_fields(annotation: Any) -> set[str] | None:
    """The field names of the pydantic model in ``annotation`` (``Model | None``)."""
    import typing

    for tp in (annotation, *typing.get_args(annotation)):
        fields = getattr(tp, "model_fields", None)
        if isinstance(fields, dict):
            return set(fields)
    return None


def _assign(data: dict, loc: tuple[Any, ...], value: Any) -> None:
    node = data
    for j, k in enumerate(loc[:-1]):
        nxt = node[k] if isinstance(node, list) else node.get(k)
        if nxt is None:
            nxt = _default_table(data, list(loc[:j + 1]))
            node[k] = nxt
        node = nxt
    node[loc[-1]] = deepcopy(value)


def _get(data: Any, loc: tuple[Any, ...]) -> Any:
    for k in loc:
        if data is None:
            return None
        data = data[k] if isinstance(data, list) else data.get(k)
    return data


def _named(data: dict, loc: tuple[Any, ...]) -> str:
    """A location as the user calls it: a filter by its name."""
    parts = [str(k) for k in loc]
    if len(loc) > 1 and loc[0] == "filters":
        parts[1] = str(data["filters"][loc[1]]["name"])
    return ".".join(parts)


def _current(data: dict, loc: tuple[Any, ...]) -> Any:
    """The value at ``loc`` as a run would use it: inside an absent table, the value of the
    table it starts from (``_default_table``)."""
    node: Any = data
    for j, k in enumerate(loc):
        if node is None:
            return None
        nxt = node[k] if isinstance(node, list) else node.get(k)
        if nxt is None and j < len(loc) - 1:
            nxt = _default_table(data, list(loc[:j + 1]))
        node = nxt
    return node


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _times(now: Any, f: float, where: str, source: str) -> Any:
    """``now`` times the factor ``f``: a number, or a list of numbers elementwise."""
    if _is_number(now):
        return float(now) * f
    if isinstance(now, list) and now and all(_is_number(x) for x in now):
        return [float(x) * f for x in now]
    shown = "is not set" if now is None else f"= {_show(now)}"
    raise ValueError(f"{source}: {where} {shown}; a factor (x{f:g}) multiplies a number "
                     "or a list of numbers, so give plain values for it")


def _true_r(data: dict, source: str) -> list[float]:
    """The true R's diagonal at the scenario ``data``: the noise variance of every
    observer's channels, in the order of the stacked measurement, as a filter that
    believes the true R uses it."""
    plan = plan_of(_validated(data, source))
    return np.diagonal(np.asarray(plan.sensors[0].noise, dtype=float)).tolist()


def _apply(data: dict, values: dict[str, Any], locations: dict[str, list[tuple[Any, ...]]],
           sources: dict[str, str], true_rs: dict[str, list[float]]) -> None:
    """Set a point's ``values`` in ``data``: plain values first, then the factors of the
    truth, then the filters' factors, each relative to the point as set so far (a filter's
    ``r0_diag_si`` absent: relative to the point's true R, kept in ``true_rs`` by the
    truth's JSON)."""
    def is_factor(item: tuple[str, Any]) -> bool:
        return factor_of(item[1]) is not None

    plain = [kv for kv in values.items() if not is_factor(kv)]
    truth = [kv for kv in values.items() if is_factor(kv) and not kv[0].startswith("filters.")]
    own = [kv for kv in values.items() if is_factor(kv) and kv[0].startswith("filters.")]
    for path, v in plain:
        for loc in locations[path]:
            _assign(data, loc, v)
    true_r: list[float] | None = None
    for k, (path, v) in enumerate([*truth, *own]):
        f = factor_of(v)
        if k == len(truth) and any(loc[-1] == "r0_diag_si" for p, _ in own
                                   for loc in locations[p]):
            # the truth is final and no filter factor is in yet: the point's true R
            key = json.dumps({x: y for x, y in data.items() if x not in ("filters", "run")},
                             sort_keys=True, default=str)
            if key not in true_rs:
                true_rs[key] = _true_r(data, f"{sources[path]}: the point's true R")
            true_r = true_rs[key]
        for loc in locations[path]:
            now = _current(data, loc)
            where = _named(data, loc)
            if now is None and loc[0] == "filters" and loc[2:] == ("r0_diag_si",):
                now = true_r
            _assign(data, loc, _times(now, f, where, sources[path]))


# --- designs ------------------------------------------------------------------------------


def _grid_values(p: Param, points: int | None, integer: bool) -> list[Any]:
    if not p.is_range:
        return list(p.values)
    if points is None:
        raise ValueError(f"{p.source}: {p.path} is a range ({p.describe()}); a grid needs "
                         "--points N, the values per range")
    if points == 1:
        raw = [math.sqrt(p.low * p.high) if p.log else 0.5 * (p.low + p.high)]
    else:
        raw = (np.geomspace if p.log else np.linspace)(p.low, p.high, points).tolist()
    return _from_unit(p, raw, integer)


def _from_unit(p: Param, raw: Sequence[float], integer: bool) -> list[Any]:
    vals = [int(round(v)) if integer else float(v) for v in raw]
    return list(dict.fromkeys(vals)) if integer else vals


def _draw(p: Param, u: np.ndarray, integer: bool) -> list[Any]:
    """Map uniform draws ``u`` in [0, 1) to the parameter: a range (uniform or
    log-uniform), or one of its listed values."""
    if p.is_range:
        if p.log:
            a, b = math.log(p.low), math.log(p.high)
            raw = np.exp(a + u * (b - a))
        else:
            raw = p.low + u * (p.high - p.low)
        return [int(round(v)) if integer else float(v) for v in raw.tolist()]
    k = len(p.values)
    return [p.values[min(int(x * k), k - 1)] for x in u.tolist()]


def _design(params: list[Param], kind: str, points: int | None, seed: int,
            integer: dict[str, bool]) -> list[dict[str, Any]]:
    """The points' raw values, in design order. The random design draws row by row (the
    first N rows of a larger design are the same N points); both draw from the campaign
    seed, so the same command gives the same design."""
    if kind == "grid":
        axes = [_grid_values(p, points, integer[p.path]) for p in params]
        return [dict(zip([p.path for p in params], combo, strict=True))
                for combo in itertools.product(*axes)]
    if points is None:
        raise ValueError(f"a {kind} design needs --points N, the number of points")
    tag = {"random": 0x72616E64, "lhs": 0x6C6873}[kind]
    rng = np.random.default_rng(np.random.SeedSequence([seed, tag]))
    d = len(params)
    if kind == "random":
        u = rng.random((points, d))
    else:  # Latin hypercube: one draw in each of the N strata of every axis
        u = np.empty((points, d))
        for j in range(d):
            u[:, j] = (rng.permutation(points) + rng.random(points)) / points
    cols = [_draw(p, u[:, j], integer[p.path]) for j, p in enumerate(params)]
    return [{p.path: cols[j][i] for j, p in enumerate(params)} for i in range(points)]


# --- points -------------------------------------------------------------------------------


def canonical(values: dict[str, Any]) -> str:
    """The canonical JSON of a point's values (sorted keys, no spaces, shortest floats)."""
    return json.dumps(values, sort_keys=True, separators=(",", ":"), allow_nan=False)


def truth_values(values: dict[str, Any]) -> dict[str, Any]:
    """The values that change what is simulated: all but the filters' own (``filters.*``)."""
    return {k: v for k, v in values.items() if not k.startswith("filters.")}


def point_seed(campaign_seed: int, values: dict[str, Any]) -> int:
    """A point's master seed: the first 63 bits of sha256 of the campaign seed and the
    canonical JSON of the point's ``truth_values``. Its position in the design plays no part,
    so adding points never changes another's seed; points that differ only in the filters'
    own assumptions share their seed, so their filters see the same truths and measurements
    (common random numbers: the differences between them are the filters', not the draws')."""
    text = f"trackkit-sweep-point\0{int(campaign_seed)}\0{canonical(truth_values(values))}"
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "big") >> 1


def point_id(values: dict[str, Any]) -> str:
    """A point's directory name: 12 hex digits of sha256 of its canonical values."""
    return hashlib.sha256(canonical(values).encode()).hexdigest()[:12]


@dataclass(frozen=True)
class Point:
    """One point: its values (path -> value as the validated scenario holds it), id, seed,
    its scenario (runs, seed, block set) and the key its blocks are stored under."""

    index: int
    values: dict[str, Any]
    id: str
    seed: int
    scenario: Scenario
    key: str

    def label(self) -> str:
        return ", ".join(f"{k}={_show(v)}" for k, v in self.values.items())

    def header(self) -> dict:
        return {"id": self.id, "values": self.values, "seed": self.seed, "key": self.key}


@dataclass
class Campaign:
    """A sweep: the base scenario (runs, seed and block set), its parameters, its design and
    its points (in design order)."""

    base: Scenario
    params: list[Param]
    design: str
    n_points: int | None
    seed: int
    runs: int
    block: int
    points: list[Point]
    notes: list[str] = field(default_factory=list)

    @property
    def blocks_per_point(self) -> int:
        return -(-self.runs // self.block)

    def block_runs(self, block: int) -> int:
        return min(self.runs, (block + 1) * self.block) - block * self.block

    def identity(self) -> dict:
        """What the stored blocks depend on (``CampaignStore.open`` compares it). The
        points are not in it (each point is stored under its own values), nor the order of
        the parameters."""
        data = self.base.model_dump(mode="json")
        data.pop("run", None)
        data.pop("sweep", None)
        scenario = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
        return {"scenario": scenario, "parameters": sorted(p.path for p in self.params),
                "seed": self.seed, "runs": self.runs, "block": self.block,
                "code": code_version()}

    def own_value(self, param: Param) -> Any:
        """The value of ``param`` at the base scenario's own setting, as a point records it:
        ``x1`` for factors, else the scenario's value (None where it has none)."""
        if param.relative:
            return _factor_text(1.0)
        data = self.base.model_dump(mode="json")
        data["sweep"] = None
        return _current(data, _locate(data, param.path, param.source)[0])

    def document(self) -> dict:
        """The campaign's design, as ``sweep.json`` records it."""
        return {"scenario": self.base.name, "design": self.design,
                "points_requested": self.n_points, "seed": self.seed, "runs": self.runs,
                "block": self.block,
                "parameters": [{"path": p.path, "values": list(p.values)} if not p.is_range
                               else {"path": p.path, "low": p.low, "high": p.high,
                                     "log": p.log} for p in self.params],
                "points": [p.header() for p in self.points]}


def _problems(err: Exception) -> str:
    text = str(err)
    lines = text.split("\n")
    return "; ".join(x.strip() for x in lines[1:]) if len(lines) > 1 else text


def _validated(data: dict, source: str) -> Scenario:
    from trackkit.scenario import parse

    try:
        return parse(data, source)
    except ValueError as err:
        raise ValueError(f"{source}: {_problems(err)}") from None


def plan_campaign(scenario: Scenario, params: Sequence[Param] | None = None,
                  design: str | None = None, points: int | None = None,
                  runs: int | None = None, seed: int | None = None,
                  block: int | None = None) -> Campaign:
    """The campaign of ``params`` (default: the scenario's ``[sweep]`` table) over
    ``scenario``, every point's scenario validated; ``design``, ``points``, ``runs``,
    ``seed`` and ``block`` default to the ``[sweep]`` table's and the scenario's ``run``.
    Errors (ValueError) name the parameter, the value and what is allowed."""
    table = scenario.sweep
    if not params:
        if table is None:
            raise ValueError("nothing to sweep: give --param PATH=V1,V2,... (or PATH=LOW:HIGH) "
                             "or a [sweep] table in the scenario")
        params = params_from_table(table)
        design = design or table.design
        points = points if points is not None else table.points
    design = design or "grid"
    if design not in DESIGNS:
        raise ValueError(f"design = {design!r}; expected one of {list(DESIGNS)}")
    if points is not None and points < 1:
        raise ValueError(f"points = {points}; expected an integer >= 1")
    for name, v in (("runs", runs), ("block", block)):
        if v is not None and v < 1:
            raise ValueError(f"{name} = {v}; expected an integer >= 1")
    if seed is not None and seed < 0:
        raise ValueError(f"seed = {seed}; expected a non-negative integer")
    s = with_run(scenario, runs, seed)
    if block is not None:
        s = Scenario.model_validate({**s.model_dump(), "run": {**s.run.model_dump(),
                                                              "block": block}})
    untuned = [f.name for f in s.filters if f.tune is not None]
    if untuned:
        raise ValueError(f"filters {untuned} have a tune block; trackkit sweep does not tune "
                         "fuzzy systems: give their options.params (e.g. from a tuned "
                         "trackkit run) to sweep them")
    base = s.model_dump()
    base["sweep"] = None
    params = [replace(p, path=_canonical_path(base, p, _locate(base, p.path, p.source)))
              for p in params]
    seen: dict[str, str] = {}
    for p in params:
        if p.path in seen:
            raise ValueError(f"{p.source}: {p.path} is swept twice (also by {seen[p.path]}); "
                             "give each parameter once")
        seen[p.path] = p.source
    locations = {p.path: _locate(base, p.path, p.source) for p in params}
    owner: dict[tuple[Any, ...], Param] = {}
    for p in params:  # filters.*.motion.q and filters.EKF.motion.q name one field twice
        for loc in locations[p.path]:
            if loc in owner:
                raise ValueError(f"{p.source}: {p.path} sets {_named(base, loc)}, which "
                                 f"{owner[loc].path} ({owner[loc].source}) sets too; expected "
                                 "each field swept by one parameter")
            owner[loc] = p
    sources = {p.path: p.source for p in params}
    true_rs: dict[str, list[float]] = {}
    integer = {}
    for p in params:
        now = _get(base, locations[p.path][0])
        integer[p.path] = isinstance(now, int) and not isinstance(now, bool) and (
            not p.relative)
    # each parameter's values alone first, so that a bad one is named by itself
    for p in params:
        for v in (p.values if not p.is_range else (p.low, p.high)):
            if integer[p.path] and p.is_range:
                v = int(round(v))
            data = deepcopy(base)
            _apply(data, {p.path: v}, locations, sources, true_rs)
            _validated(data, f"{p.source}: value {_show(v)} of {p.path}")
    raw_points = _design(list(params), design, points, s.run.seed, integer)
    campaign = Campaign(base=s, params=list(params), design=design, n_points=points,
                        seed=s.run.seed, runs=s.run.runs, block=s.run.block, points=[])
    code = json.dumps(code_version(), sort_keys=True)
    ids: set[str] = set()
    for raw in raw_points:
        data = deepcopy(base)
        where = ", ".join(f"{k}={_show(v)}" for k, v in raw.items())
        _apply(data, raw, locations, {k: f"the point {where}" for k in raw}, true_rs)
        sc = _validated(data, f"the point {where}")
        dumped = sc.model_dump(mode="json")
        # a factor is recorded as given (its column); a plain value as the scenario holds it
        values = {path: v if factor_of(v) is not None else _get(dumped, locations[path][0])
                  for path, v in raw.items()}
        pid = point_id(values)
        if pid in ids:
            campaign.notes.append(f"the point {where} appears more than once in the "
                                  "design; it is run once")
            continue
        ids.add(pid)
        pseed = point_seed(campaign.seed, values)
        sc = with_run(sc, None, pseed)
        check_memory(sc)
        plan_of(sc)  # compile (so validate the models) before anything runs
        key = hashlib.sha256((sc.model_dump_json() + code).encode()).hexdigest()[:32]
        campaign.points.append(Point(len(campaign.points), values, pid, pseed, sc, key))
    return campaign


# --- results of a point -------------------------------------------------------------------


def _finite(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def point_document(point: Point, result: MonteCarloResult) -> tuple[dict, dict]:
    """A point's result document (deterministic: the same bits for the same blocks) and its
    timings. The document is ``MonteCarloResult.to_json_dict`` without the wall-clock times,
    with the point's id, values and seed, the error groups' units and each filter's RMSE
    over PCRLB (``efficiency``); non-finite numbers are null."""
    doc = result.to_json_dict()
    timings = {"point": point.id, "units": {"seconds_per_step": "s per run and step"},
               "seconds_per_step": {}}
    for name, entry in doc["filters"].items():
        timings["seconds_per_step"][name] = entry.pop("seconds_per_step", None)
        entry["rmse_pcrlb"] = {g: result.efficiency(name, g) for g in result.groups}
    doc = {"point": point.id, "values": point.values, "seed_point": point.seed,
           "units": dict(result.groups), **doc}
    return _finite(doc), _finite(timings)


# --- running a campaign -------------------------------------------------------------------


class BlockFailed(RuntimeError):
    """A block that failed every attempt; the campaign stopped, its finished blocks stored."""

    def __init__(self, point: Point, block: int, runs: tuple[int, int], attempts: int,
                 error: BaseException) -> None:
        self.point, self.block, self.error = point, block, error
        super().__init__(
            f"point {point.id} ({point.label()}), block {block} (runs {runs[0]}-{runs[1] - 1})"
            f" failed {attempts} time{'s' if attempts > 1 else ''}: "
            f"{type(error).__name__}: {error}")


class Listener:
    """What a campaign reports as it goes (the command line draws progress bars from it);
    every method may be left as it is."""

    def start(self, campaign: Campaign, stored_runs: list[int], stored_blocks: list[int],
              finished: list[bool]) -> None:
        """Before any work: each point's runs and blocks already stored, and whether it is
        already combined."""

    def progress(self, i: int, runs_done: float) -> None:
        """Point ``i`` has ``runs_done`` runs done (stored ones included; fractional)."""

    def stored(self, i: int, block: int) -> None:
        """Block ``block`` of point ``i`` is stored."""

    def finished(self, i: int) -> None:
        """Point ``i`` is combined and its result stored."""


def run_campaign(campaign: Campaign, store: CampaignStore, workers: int | None = None,
                 scheduler: str | None = None, listener: Listener | None = None,
                 attempts: int = ATTEMPTS) -> list[dict]:
    """Run every block not yet stored, store each as it finishes, combine each point whose
    blocks are all stored, and return the points' result documents in design order.
    ``store`` must be open (``CampaignStore.open(campaign.identity())``)."""
    listener = listener or Listener()
    nb = campaign.blocks_per_point
    for p in campaign.points:
        store.prepare_point(p.id, p.header())
    stored = [store.stored_blocks(p.id) & set(range(nb)) for p in campaign.points]
    finished = [store.has_result(p.id) for p in campaign.points]
    stored_runs = [sum(campaign.block_runs(b) for b in s) for s in stored]
    listener.start(campaign, stored_runs, [len(x) for x in stored], list(finished))
    lock = threading.Lock()

    def finish(i: int) -> None:
        p = campaign.points[i]
        parts = [store.load_block(p.id, p.key, b) for b in range(nb)]
        doc, timings = point_document(p, combine(p.scenario, parts))
        store.save_result(p.id, doc, timings)
        finished[i] = True
        listener.finished(i)

    def on_block(i: int, b: int, result: Any) -> None:
        p = campaign.points[i]
        store.save_block(p.id, p.key, b, campaign.block_runs(b), result)
        with lock:
            stored[i].add(b)
            stored_runs[i] += campaign.block_runs(b)
        listener.stored(i, b)
        listener.progress(i, stored_runs[i])
        if len(stored[i]) == nb:
            finish(i)

    for i in range(len(campaign.points)):  # all blocks stored, not yet combined
        if not finished[i] and len(stored[i]) == nb:
            finish(i)
    tasks = [(i, b) for i in range(len(campaign.points)) if not finished[i]
             for b in range(nb) if b not in stored[i]]
    if tasks:
        if workers or scheduler:
            _run_dask(campaign, tasks, workers, scheduler, attempts, on_block, listener,
                      stored_runs, lock)
        else:
            _run_here(campaign, tasks, attempts, on_block, listener, stored_runs)
    return [store.load_result(p.id) for p in campaign.points]


def _run_here(campaign: Campaign, tasks: list[tuple[int, int]], attempts: int,
              on_block: Callable, listener: Listener, stored_runs: list[int]) -> None:
    for i, b in tasks:
        p = campaign.points[i]
        n = campaign.block_runs(b)
        base = stored_runs[i]
        for attempt in range(attempts):
            try:
                result = run_blocks(p.scenario, [b],
                                    lambda d, i=i, base=base: listener.progress(i, base + d))[0]
                break
            except Exception as err:  # noqa: BLE001 - any failure of the block counts
                if attempt == attempts - 1:
                    r0 = b * campaign.block
                    raise BlockFailed(p, b, (r0, r0 + n), attempts, err) from err
        on_block(i, b, result)


def _on_worker(scenario: Scenario, block: int, topic: str, key: str) -> Any:
    """One block on a Dask worker; its progress goes to the client as worker events."""
    from dask.distributed import get_worker

    worker = get_worker()

    def report(done: float) -> None:
        worker.log_event(topic, (key, float(done)))

    return run_blocks(scenario, [block], report)[0]


def _run_dask(campaign: Campaign, tasks: list[tuple[int, int]], workers: int | None,
              scheduler: str | None, attempts: int, on_block: Callable, listener: Listener,
              stored_runs: list[int], lock: threading.Lock) -> None:
    with dask_client(workers, scheduler) as client:
        _run_on(client, campaign, tasks, attempts, on_block, listener, stored_runs, lock)


def _run_on(client: Any, campaign: Campaign, tasks: list[tuple[int, int]], attempts: int,
            on_block: Callable, listener: Listener, stored_runs: list[int],
            lock: threading.Lock) -> None:
    from dask.distributed import as_completed

    token = uuid.uuid4().hex[:10]  # keys and events of this campaign alone on a shared cluster
    topic = f"trackkit-sweep-{token}"
    where: dict[str, tuple[int, int]] = {}
    partial: dict[str, float] = {}
    futures: list = []

    def on_event(event: tuple) -> None:
        _, (key, done) = event
        with lock:
            if key not in where:
                return
            i, b = where[key]
            partial[key] = max(partial.get(key, 0.0), done)  # a retried task restarts at 0
            ahead = sum(v for k, v in partial.items() if where[k][0] == i)
            runs = stored_runs[i] + ahead
        listener.progress(i, runs)

    try:
        client.subscribe_topic(topic, on_event)
        for i, b in tasks:
            p = campaign.points[i]
            key = f"trackkit-sweep-{token}-{p.id}-{b}"
            where[key] = (i, b)
            futures.append(client.submit(_on_worker, p.scenario, b, topic, key, key=key,
                                         retries=attempts - 1, pure=False))
        pending = set(futures)
        for fut in as_completed(futures):
            pending.discard(fut)
            i, b = where[fut.key]
            if fut.status != "finished":
                _store_finished(pending, where, on_block, partial, lock)
                p = campaign.points[i]
                r0 = b * campaign.block
                err = fut.exception()
                raise BlockFailed(p, b, (r0, r0 + campaign.block_runs(b)), attempts, err)
            result = fut.result()
            with lock:
                partial.pop(fut.key, None)
            fut.release()
            on_block(i, b, result)
    finally:
        for f in futures:
            f.cancel()
        try:
            client.unsubscribe_topic(topic)
        except Exception:  # noqa: BLE001 - the client may be gone already
            pass


def _store_finished(pending: set, where: dict, on_block: Callable, partial: dict,
                    lock: threading.Lock) -> None:
    """Before stopping: store the blocks that finished meanwhile."""
    for fut in list(pending):
        if fut.status == "finished":
            i, b = where[fut.key]
            try:
                result = fut.result(timeout=10)
            except Exception:  # noqa: BLE001 - lost meanwhile: it will be run again
                continue
            with lock:
                partial.pop(fut.key, None)
            on_block(i, b, result)

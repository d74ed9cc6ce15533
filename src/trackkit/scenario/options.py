"""The filter types of a scenario's ``[[filters]]`` and their ``options``: one table.

:data:`FILTER_TYPES` maps each ``type`` to its constructor in ``trackkit.filters``, the
arguments the type fixes (EKF2's ``order``, a fuzzy filter's base) and the options a user may
set, each with its type, allowed range, default and meaning. The schema validates ``options``
with it when a scenario is read, ``build`` constructs the filters from it and the scenario
reference is generated from it; ``tests/test_scenario_schema.py`` checks it against the
constructors' signatures and checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from trackkit import filters as tkf
from trackkit.filters.adaptive import Q_FORMS
from trackkit.filters.bearings_only import MPEKF, RPEKF, RangePF
from trackkit.filters.fuzzy import DEFAULT_PARAMS, N_PARAMS
from trackkit.filters.jtc import JTC, RECURSIONS, SPEEDS, MultiFilterJTC
from trackkit.models.classes import ALONG, PAPER_CLASSES

__all__ = ["Option", "FilterType", "FILTER_TYPES", "FUZZY_TYPES", "CONSTANT_GAIN_TYPES",
           "IMM_INNER_TYPES", "IMMSettings", "alpha_beta", "alpha_beta_gamma", "check_options",
           "make_filter"]

Kind = Literal["int", "float", "bool", "choice", "floats", "pairs"]


def _num(v: float) -> str:
    return repr(int(v)) if float(v).is_integer() and abs(v) < 1e15 else repr(float(v))


@dataclass(frozen=True)
class Option:
    """One option: ``kind`` is its TOML type ("int", "float", "bool", "choice" of strings,
    "floats" a list of ``size`` numbers, "pairs" a flat list of index pairs); numbers (and the
    elements of a list) lie in ``low``..``high`` (excluded when ``open_low``/``open_high``).
    ``default`` is the constructor's; ``default_text`` shows a default that is not a value."""

    name: str
    kind: Kind
    default: Any
    meaning: str
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple[str, ...] = ()
    size: int | None = None
    default_text: str | None = None
    allowed_text: str | None = None

    def allowed(self) -> str:
        """What the option accepts, in words."""
        if self.allowed_text is not None:
            return self.allowed_text
        if self.kind == "bool":
            return "true or false"
        if self.kind == "choice":
            return "one of " + ", ".join(f'"{c}"' for c in self.choices)
        if self.kind == "pairs":
            return "a list of pairs of indices >= 0, flat: [i1, l1, i2, l2, ...]"
        what = {"int": "an integer", "float": "a number"}.get(self.kind, "")
        if self.kind == "floats":
            what = f"a list of {self.size} numbers" if self.size else "a list of numbers"
            if self.low is not None or self.high is not None:
                what += ", each"
        return what + self._range()

    def _range(self) -> str:
        lo, hi = self.low, self.high
        if lo is not None and hi is not None:
            if self.kind == "int" and hi - lo == 1:
                return f" {_num(lo)} or {_num(hi)}"
            left, right = "(" if self.open_low else "[", ")" if self.open_high else "]"
            return f" in {left}{_num(lo)}, {_num(hi)}{right}"
        if lo is not None:
            return f" {'>' if self.open_low else '>='} {_num(lo)}"
        if hi is not None:
            return f" {'<' if self.open_high else '<='} {_num(hi)}"
        return " (finite)" if self.kind in ("float", "floats") else ""

    def shown_default(self) -> str:
        """The default as a scenario file would write it."""
        if self.default_text is not None:
            return self.default_text
        d = self.default
        if isinstance(d, bool):
            return "true" if d else "false"
        if isinstance(d, str):
            return f'"{d}"'
        if isinstance(d, tuple | list):
            return "[" + ", ".join(repr(float(v)) for v in d) + "]"
        return repr(d)

    def _in_range(self, v: float) -> bool:
        if self.low is not None and (v <= self.low if self.open_low else v < self.low):
            return False
        return not (self.high is not None
                    and (v >= self.high if self.open_high else v > self.high))

    def check(self, value: Any) -> tuple[Any, str | None]:
        """``(normalised value, None)`` or ``(value, what is wrong)``."""
        bad = f"expected {self.allowed()}"
        if self.kind == "bool":
            return (value, None) if isinstance(value, bool) else (value, bad)
        if self.kind == "choice":
            return (value, None) if value in self.choices else (value, bad)
        if self.kind in ("int", "float"):
            if isinstance(value, bool) or not isinstance(value, int | float):
                return value, bad
            if self.kind == "int":
                if isinstance(value, float):  # a TOML integer, as the constructors require
                    return value, bad
            elif not math.isfinite(value):
                return value, bad
            else:
                value = float(value)
            return (value, None) if self._in_range(value) else (value, bad)
        if not isinstance(value, list | tuple) or any(
                isinstance(v, bool) or not isinstance(v, int | float) for v in value):
            return value, bad
        if self.kind == "pairs":
            if len(value) % 2:
                return value, (f"{self.name} has {len(value)} values; expected pairs "
                               "[i1, l1, i2, l2, ...]")
            if any(not isinstance(v, int) or v < 0 for v in value):
                return value, bad
            return list(value), None
        if self.size is not None and len(value) != self.size:
            return value, f"{self.name} has {len(value)} values; {bad}"
        if not all(math.isfinite(v) and self._in_range(v) for v in value):
            return value, bad
        return [float(v) for v in value], None


@dataclass(frozen=True)
class FilterType:
    """A scenario filter ``type``: ``constructor`` called with ``fixed`` and the options;
    ``base`` names the filter type a fuzzy-adaptive filter wraps."""

    constructor: type
    meaning: str
    options: tuple[Option, ...] = ()
    fixed: dict[str, Any] = field(default_factory=dict)
    base: str | None = None

    def option(self, name: str) -> Option:
        return {o.name: o for o in self.options}[name]


_WINDOW = "innovations in the sliding window of the innovation covariance"
_FUZZY_OPTIONS = (
    Option("params", "floats", DEFAULT_PARAMS, "the fuzzy system: 5 input centres "
           "(increasing), 5 widths (> 0), 5 output centres", size=N_PARAMS,
           default_text="none: give params or a tune block"),
    Option("adapt", "choice", "R", "the covariance adapted: R (measurement noise) or Q "
           "(process noise)", choices=("R", "Q")),
    Option("window", "int", 25, _WINDOW + " C", low=1),
    Option("normalise", "choice", "current", "units of the fuzzy system: DOM relative to S "
           "and adjustments relative to R (current), to R0 (initial) or raw (none)",
           choices=("current", "initial", "none")),
    Option("floor", "float", 1e-3, "lowest adapted R(i,i) (Q(j,j)) as a multiple of the "
           "initial R0(i,i) (Q0(j,j))", low=0, open_low=True),
    Option("ceiling", "float", 1e6, "highest adapted R(i,i) (Q(j,j)) as a multiple of "
           "R0(i,i) (Q0(j,j))", allowed_text="a number > floor"),
    Option("warmup", "choice", "wait", "wait: no adaptation until the window is full; "
           "adapt: from the first step", choices=("wait", "adapt")),
    Option("q_inputs", "pairs", None, "with adapt = \"Q\": the DOM entries (i, l) that "
           "drive each Q(j,j)", default_text="DOM(j,j) for each Q(j,j)"),
)

_BOUNDS = "[low, high], 0 < low <= high"

AB_GAINS = ("kohn", "benedict-bordner", "fading-memory", "explicit")
ABG_GAINS = ("benedict-bordner", "fading-memory", "explicit")


def _unused(gains: str, given: dict[str, float | None], needs: tuple[str, ...]) -> None:
    """Refuse a gain option the chosen designer does not use, and a missing one it needs."""
    for name, value in given.items():
        if value is None and name in needs:
            raise ValueError(f"gains = {gains!r} needs {name}; expected "
                             f"{', '.join(needs)} given")
        if value is not None and name not in needs:
            wanted = ", ".join(needs) if needs else "no gain option"
            raise ValueError(f"{name} = {value!r} is not used with gains = {gains!r}; "
                             f"expected {wanted}")


def alpha_beta(gains: str = "kohn", alpha: float | None = None, beta: float | None = None,
               xi: float | None = None, startup: str = "thesis") -> tkf.AlphaBeta:
    """The alpha-beta tracker of a scenario: gains from a designer of
    ``trackkit.filters.alphabeta`` (Kohn's (0.5, 0.167); Benedict-Bordner's
    ``beta = alpha^2 / (2 - alpha)``; fading memory ``(1 - xi^2, (1 - xi)^2)``) or given."""
    from trackkit.filters import alphabeta as ab

    if gains not in AB_GAINS:
        raise ValueError(f"gains = {gains!r}; expected one of {AB_GAINS}")
    needs = {"kohn": (), "benedict-bordner": ("alpha",), "fading-memory": ("xi",),
             "explicit": ("alpha", "beta")}[gains]
    _unused(gains, {"alpha": alpha, "beta": beta, "xi": xi}, needs)
    if gains == "kohn":
        a, b = ab.kohn()
    elif gains == "benedict-bordner":
        a, b = alpha, ab.benedict_bordner(alpha)
    elif gains == "fading-memory":
        a, b = ab.fading_memory(xi)
    else:
        a, b = alpha, beta
    return tkf.AlphaBeta(a, b, startup=startup)


def alpha_beta_gamma(gains: str = "fading-memory", alpha: float | None = None,
                     beta: float | None = None, gamma: float | None = None,
                     xi: float | None = None, startup: str = "thesis") -> tkf.AlphaBetaGamma:
    """The alpha-beta-gamma tracker of a scenario (acceleration gain 2 gamma / T^2): gains
    Benedict-Bordner (gamma from alpha and beta, eq. 2-50), fading memory (xi) or given."""
    from trackkit.filters import alphabeta as ab

    if gains not in ABG_GAINS:
        raise ValueError(f"gains = {gains!r}; expected one of {ABG_GAINS}")
    needs = {"benedict-bordner": ("alpha", "beta"), "fading-memory": ("xi",),
             "explicit": ("alpha", "beta", "gamma")}[gains]
    _unused(gains, {"alpha": alpha, "beta": beta, "gamma": gamma, "xi": xi}, needs)
    if gains == "benedict-bordner":
        a, b, g = alpha, beta, ab.benedict_bordner_gamma(alpha, beta)
    elif gains == "fading-memory":
        a, b, g = ab.fading_memory_abg(xi)
    else:
        a, b, g = alpha, beta, gamma
    return tkf.AlphaBetaGamma(a, b, g, startup=startup)


@dataclass(frozen=True)
class IMMSettings:
    """The options of a scenario's IMM; its models, transition and mu0 are the filter's
    ``imm`` table (``trackkit.scenario.build`` assembles the :class:`~trackkit.filters.IMM`)."""

    fill: str = "others"

    def __post_init__(self) -> None:
        if self.fill not in ("others", "zero"):
            raise ValueError(f"fill = {self.fill!r}; expected 'others' or 'zero'")


_STARTUP = Option("startup", "choice", "thesis", "thesis: the thesis's start-up rules; "
                  "prior: the constant gains from the first scan; simpson: Simpson's "
                  "growing-memory gains until they fall below the constant ones",
                  choices=("thesis", "prior", "simpson"))
_GAIN_ALPHA = Option("alpha", "float", None, "position gain (benedict-bordner, explicit)",
                     low=0, high=2, open_low=True, open_high=True, default_text="none")
_GAIN_XI = Option("xi", "float", None, "the fading-memory discount: every root of the "
                  "characteristic polynomial at xi (fading-memory)", low=0, high=1,
                  open_high=True, default_text="none")

_JTC_OPTIONS = (
    Option("particles_per_class", "int", 5000, "particles per class, N_c (N = 2 N_c in all)",
           low=1),
    Option("sigma", "float", 10.0, "standard deviation of every mode's white acceleration noise "
           "(m/s^2)", low=0),
    Option("diagonal", "float", None, "the mode transition's diagonal (the rest shared equally "
           "off it) for both classes", low=0, high=1, default_text="none: the paper's 0.6"),
    Option("speed", "choice", "estimate", "the speed the class speed likelihood g(v | c) is "
           "evaluated at: the previous estimate's (the paper's), or each particle's own",
           choices=SPEEDS),
    Option("acceleration", "choice", "velocity", "a CA mode's input u: along the velocity, or "
           "on both axes (the paper's literal G u)", choices=ALONG),
)

#: Every filter type of a scenario, in the order the reference lists them.
FILTER_TYPES: dict[str, FilterType] = {
    "KF": FilterType(tkf.KF, "linear Kalman filter (linear motion and sensor models)"),
    "EKF": FilterType(tkf.EKF, "extended Kalman filter", (
        Option("order", "int", 1, "1: first order; 2: with the measurement Hessian terms "
               "(Athans, Wishner and Bertolini)", low=1, high=2),)),
    "EKF2": FilterType(tkf.EKF, "second-order extended Kalman filter (EKF with order = 2)",
                       fixed={"order": 2}),
    "IEKF": FilterType(tkf.IEKF, "iterated EKF (Gauss-Newton on the update's MAP cost)", (
        Option("iterations", "int", 5, "Gauss-Newton iterations per update (1 is the EKF)",
               low=1),
        Option("line_search", "bool", False, "halve each step until the MAP cost does not "
               "increase"),
        Option("max_halvings", "int", 4, "most halvings of a step with line_search", low=0),
    )),
    "UKF": FilterType(tkf.UKF, "unscented Kalman filter (scaled sigma points)", (
        Option("alpha", "float", 0.5, "spread of the sigma points around the mean", low=0,
               open_low=True),
        Option("beta", "float", 2.0, "weight of the centre point in the covariance (2 is "
               "optimal for a Gaussian)"),
        Option("kappa", "float", None, "secondary scaling: lambda = alpha^2 (n + kappa) - n",
               default_text="3 - n (n the state length)",
               allowed_text="a number > -n (n the state length)"),
    )),
    "CKF": FilterType(tkf.CKF, "cubature Kalman filter (third-degree spherical-radial rule)"),
    "RPEKF": FilterType(RPEKF, "range-parameterised EKF: a bank of EKFs over a geometric "
                        "range grid along the first line of sight, weighted by their "
                        "likelihoods (one bearing sensor)", (
        Option("components", "int", 16, "EKFs in the bank (range cells)", low=1),
        Option("n_sigma", "float", 4.0, "the range interval: the prior's range +- n_sigma "
               "of its standard deviation along the line of sight", low=0, open_low=True),
        Option("r_min", "float", None, "lowest range of the interval (m)", low=0,
               open_low=True, default_text="none: the prior's, at least 0.05 of its range"),
        Option("r_max", "float", None, "highest range of the interval (m)", low=0,
               open_low=True, default_text="none: the prior's"),
        Option("prune", "float", 0.0, "components whose weight falls below it are dropped "
               "(weight 0 for good); 0 keeps them all", low=0, high=1, open_high=True,
               allowed_text="a number in [0, 1 / components)"),
    )),
    "MPEKF": FilterType(MPEKF, "modified-polar-coordinates EKF: [bearing, bearing rate, "
                        "range rate / range, 1 / range] relative to the observer (one "
                        "bearing sensor, a ConstantVelocity target)"),
    "PF": FilterType(RangePF, "bootstrap particle filter (regularised with regularise = "
                     "true); its particles drawn from the Gaussian prior or, with prior = "
                     "\"range\", along the first bearing over a range interval", (
        Option("n_particles", "int", 1000, "particles per run", low=1),
        Option("resampler", "choice", "systematic", "the resampling scheme",
               choices=("systematic", "stratified", "residual", "multinomial")),
        Option("ess_threshold", "float", 0.5, "resample when the effective sample size is "
               "below this fraction of n_particles (0 never, 1 at every step)", low=0, high=1),
        Option("regularise", "bool", False, "Gaussian-kernel jitter after resampling (the "
               "regularised PF, Musso et al.)"),
        Option("roughening", "float", 0.0, "Gordon-Salmond-Smith roughening constant K after "
               "resampling (0 off; not with regularise)", low=0),
        Option("prior", "choice", "gaussian", "gaussian: particles drawn from the scenario's "
               "prior; bearing: the same prior conditioned on the first bearing (drawn along "
               "its rays, weighted exactly); range: at the first bearing, along it, "
               "log-uniform in range over [r_min, r_max], velocity from the prior",
               choices=("gaussian", "bearing", "range")),
        Option("r_min", "float", None, "with prior = \"range\": lowest range (m)", low=0,
               open_low=True, default_text="none: the prior's range - 4 sigma along the "
               "bearing, at least 0.05 of it"),
        Option("r_max", "float", None, "with prior = \"range\": highest range (m)", low=0,
               open_low=True, default_text="none: the prior's range + 4 sigma along the "
               "bearing"),
        Option("shrink", "bool", False, "with regularise: pull the resampled particles "
               "towards their mean by sqrt(1 - h^2) before the jitter, so the cloud keeps its "
               "covariance (Liu and West)"),
    )),
    "MCEKF": FilterType(tkf.MCEKF, "modified-covariance EKF (Hashemi and Alfi 2019)", (
        Option("second_order", "bool", False, "H = J_h + 1/2 diag(Hess h) (eqs. 12-13)"),)),
    "AMCEKF": FilterType(tkf.AMCEKF, "adaptive modified-covariance EKF (Hashemi and Alfi 2019)", (
        Option("window", "int", 25, _WINDOW + " C_r (eq. 15)", low=1),
        Option("second_order", "bool", True, "H = J_h + 1/2 diag(Hess h) (eqs. 12-13)"),
        Option("adapt_r", "bool", True, "adapt R by alpha = tr(C_r) / tr(S) (eqs. 18-19)"),
        Option("adapt_q", "bool", True, "adapt Q by lambda (eqs. 20-21)"),
        Option("q_form", "choice", "normalised", "the form of lambda (eq. 21)",
               choices=Q_FORMS),
        Option("warmup", "choice", "partial", "before the window is full: average the "
               "innovations seen (partial) or do not adapt R (wait)",
               choices=("partial", "wait")),
        Option("r_bounds", "floats", (1e-3, 1e3), "clamp of R's scale factor", low=0,
               open_low=True, size=2, allowed_text=_BOUNDS),
        Option("q_bounds", "floats", (1e-2, 1e2), "clamp of Q's scale factor", low=0,
               open_low=True, size=2, allowed_text=_BOUNDS),
        Option("lam_bounds", "floats", None, "clamp of each step's lambda before it "
               "compounds", low=0, open_low=True, size=2, default_text="none",
               allowed_text=_BOUNDS),
    )),
    "AEKF": FilterType(tkf.AEKF, "adaptive EKF: Sage-Husa noise estimator", (
        Option("forgetting", "float", 0.97, "forgetting factor b (a memory of about "
               "1 / (1 - b) steps)", low=0, high=1, open_low=True, open_high=True),
        Option("adapt_q", "bool", False, "estimate Q as well as R"),
    )),
    "AlphaBeta": FilterType(alpha_beta, "alpha-beta tracker, constant gains on [x, y, vx, "
                            "vy] (the missing-measurements thesis; a Position sensor, a "
                            "ConstantVelocity motion)", (
        Option("gains", "choice", "kohn", "the gain designer: kohn (0.5, 0.167), "
               "benedict-bordner (alpha), fading-memory (xi) or explicit (alpha, beta)",
               choices=AB_GAINS),
        _GAIN_ALPHA,
        Option("beta", "float", None, "velocity gain (explicit; with alpha inside the "
               "stability region 0 < beta < 4 - 2 alpha)", low=0, high=4, open_low=True,
               open_high=True, default_text="none"),
        _GAIN_XI,
        _STARTUP,
    )),
    "AlphaBetaGamma": FilterType(alpha_beta_gamma, "alpha-beta-gamma tracker on [x, y, vx, "
                                 "vy, ax, ay], acceleration gain 2 gamma / T^2 (the "
                                 "missing-measurements thesis; a Position sensor, a 3 dim "
                                 "state)", (
        Option("gains", "choice", "fading-memory", "the gain designer: benedict-bordner "
               "(alpha, beta; gamma by eq. 2-50), fading-memory (xi) or explicit (alpha, beta, "
               "gamma)", choices=ABG_GAINS),
        _GAIN_ALPHA,
        Option("beta", "float", None, "velocity gain (benedict-bordner, explicit)", low=0,
               high=4, open_low=True, open_high=True, default_text="none"),
        Option("gamma", "float", None, "acceleration gain (explicit)", low=0, open_low=True,
               default_text="none"),
        _GAIN_XI,
        _STARTUP,
    )),
    "IMM": FilterType(IMMSettings, "interacting multiple model filter: its models, inner "
                      "filters, transition and mu0 in the filter's imm table", (
        Option("fill", "choice", "others", "what a model says about a union component it "
               "lacks (a CV model and omega): others (the carriers' estimate) or zero",
               choices=("others", "zero")),
    )),
    "JTC": FilterType(JTC, "joint tracking and classification: one multiple-model particle "
                      "filter whose particles carry a class label, airliner or fighter (Hosseini, "
                      "Haeri and Khaloozadeh 2019; a 2-D [x, y, vx, vy] state; the classes' "
                      "own motion modes)",
                      _JTC_OPTIONS[:1] + (
        Option("floor", "float", 0.1, "the fraction of particles_per_class every class keeps "
               "(the paper's N_Thr = 0.1 N_c)", low=0, high=1, open_low=True,
               allowed_text="a number in (0, 1] with floor x particles_per_class >= 1"),
    ) + _JTC_OPTIONS[1:3] + (
        Option("recursion", "choice", "bayes", "the class posterior: bayes (the class "
               "likelihood from weights normalised within each class) or paper (Table 1's "
               "sum of globally normalised weights, which counts p(c) twice)",
               choices=RECURSIONS),
    ) + _JTC_OPTIONS[3:], fixed={"classes": PAPER_CLASSES, "class_prior": None}),
    "MultiFilterJTC": FilterType(MultiFilterJTC, "the multi-filter JTC baseline: one "
                                 "multiple-model particle filter per class, combined by Bayes' "
                                 "rule (Hosseini, Haeri and Khaloozadeh 2019; a 2-D [x, y, "
                                 "vx, vy] state)",
                                 _JTC_OPTIONS,
                                 fixed={"classes": PAPER_CLASSES, "class_prior": None}),
    "OFKF": FilterType(tkf.FuzzyAdaptive, "KF with fuzzy-adaptive R or Q (Naseri Solhdar)",
                       _FUZZY_OPTIONS, base="KF"),
    "OFEKF": FilterType(tkf.FuzzyAdaptive, "EKF with fuzzy-adaptive R or Q (Naseri Solhdar)",
                        _FUZZY_OPTIONS, base="EKF"),
    "OFUKF": FilterType(tkf.FuzzyAdaptive, "UKF with fuzzy-adaptive R or Q (Naseri Solhdar)",
                        _FUZZY_OPTIONS, base="UKF"),
}

#: the types that classify as they track (their beliefs carry class probabilities)
CLASS_TYPES = ("JTC", "MultiFilterJTC")

#: constant-gain types -> the number of state blocks (2: [pos, vel], 3: with acceleration)
CONSTANT_GAIN_TYPES = {"AlphaBeta": 2, "AlphaBetaGamma": 3}

#: the filters an IMM model may run
IMM_INNER_TYPES = ("KF", "EKF", "UKF", "CKF")

#: fuzzy-adaptive type -> the type of the filter it wraps
FUZZY_TYPES = {name: t.base for name, t in FILTER_TYPES.items() if t.base is not None}


def check_options(type_: str, options: dict[str, Any]) -> tuple[dict[str, Any],
                                                                list[tuple[str, Any, str]]]:
    """Validate a filter's options against the table: the options with normalised values
    (ints, floats, lists), and the problems as ``(option, value, message)``. A None value
    (no value in TOML) stands for the default, so it is dropped where the default is None
    and refused elsewhere."""
    spec = FILTER_TYPES[type_]
    known = {o.name: o for o in spec.options}
    out: dict[str, Any] = {}
    problems = []
    for name, value in options.items():
        opt = known.get(name)
        if opt is None:
            allowed = ", ".join(known) or "none"
            problems.append((name, value, f"has no option {name}; allowed: {allowed}"))
            continue
        if value is None:
            if opt.default is None:
                continue
            problems.append((name, value, f"no value; expected {opt.allowed()} (omit the "
                             f"option for its default, {opt.shown_default()})"))
            continue
        value, problem = opt.check(value)
        if problem is not None:
            problems.append((name, value, f"{problem} ({name}: {opt.meaning}; default "
                                          f"{opt.shown_default()})"))
        out[name] = value
    return out, problems


def make_filter(type_: str, options: dict[str, Any]) -> Any:
    """The filter of ``type_`` with validated ``options`` (``q_inputs`` given flat)."""
    spec = FILTER_TYPES[type_]
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in options.items()}
    pairs = kwargs.get("q_inputs")
    if pairs is not None:
        kwargs["q_inputs"] = tuple(zip(pairs[::2], pairs[1::2], strict=True))
    if spec.base is not None:
        kwargs["base"] = make_filter(spec.base, {})
    return spec.constructor(**spec.fixed, **kwargs)

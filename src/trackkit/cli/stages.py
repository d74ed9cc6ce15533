"""The stages the commands drive, imported lazily (the tests replace these functions), and
the kind of a loaded scenario."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def bundled() -> dict[str, str]:
    from trackkit.scenario import bundled

    return bundled()


def default_name() -> str:
    from trackkit.scenario import DEFAULT

    return DEFAULT


def load(name_or_path: str) -> Any:
    from trackkit.scenario import load
    from trackkit.scenario.multitarget import is_multitarget, load_multitarget
    from trackkit.scenario.network import is_network, load_network
    from trackkit.scenario.vessel import is_vessel, load_vessel

    if is_network(name_or_path):  # [[agents]]: an agent network (trackkit network)
        return load_network(name_or_path)
    if is_vessel(name_or_path):  # a [vessel] table: a vessel's identification (identify)
        return load_vessel(name_or_path)
    if is_multitarget(name_or_path):  # a [scene] table: the multi-target tracker comparison
        return load_multitarget(name_or_path)
    return load(name_or_path)


def kind_of(scenario: Any) -> str:
    """The kind of a loaded scenario: "comparison" (a single-target Monte Carlo comparison,
    ``trackkit run``'s and ``trackkit sweep``'s), "multitarget", "network" or "vessel"."""
    from trackkit.scenario.multitarget import MultiTargetScenario
    from trackkit.scenario.network import NetworkScenario
    from trackkit.scenario.vessel import VesselScenario

    kinds = {MultiTargetScenario: "multitarget", NetworkScenario: "network",
             VesselScenario: "vessel"}
    return kinds.get(type(scenario), "comparison")


def dumps(scenario: Any) -> str:
    from trackkit.scenario import dumps

    return dumps(scenario)


def run(scenario: Any, **kwargs: Any) -> Any:
    from trackkit.experiments.compare import compare

    return compare(scenario, **kwargs)


def write(result: Any, out: Path) -> dict[str, Path]:
    from trackkit.report.files import write_report

    return write_report(result, out)


def bundled_multitarget() -> dict[str, str]:
    from trackkit.scenario.multitarget import bundled_multitarget

    return bundled_multitarget()


def bundled_vessel() -> dict[str, str]:
    from trackkit.scenario.vessel import bundled_vessel

    return bundled_vessel()


def parse_toml(path: Path) -> None:
    """Raise the reader's error in words (not UTF-8, not valid TOML, with line and column)
    before a file is called the wrong kind of scenario for lacking a table."""
    from trackkit.scenario import read_scenario

    read_scenario(path, None)

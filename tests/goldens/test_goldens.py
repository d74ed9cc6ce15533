"""Every bundled scenario reproduces its checked-in golden numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import trackkit.scenario as S
from tests.goldens.golden import HERE, golden_numbers


def _close(a, b, path=""):
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, float):
        # rtol 1e-7: the numbers differ across BLAS builds only in the last bits
        assert (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-7,
                                                                 abs_tol=1e-12), (path, a, b)
    else:
        assert a == b, (path, a, b)


@pytest.mark.parametrize("name", sorted(S.bundled()))
def test_bundled_scenario_matches_golden(name):
    path = HERE / f"{name}.json"
    assert path.exists(), f"no golden for {name}: run python tests/goldens/golden.py"
    _close(golden_numbers(name), json.loads(path.read_text()))


def test_every_golden_has_a_scenario():
    assert {p.stem for p in Path(HERE).glob("*.json")} <= set(S.bundled())

"""Every bundled scenario reproduces its checked-in golden numbers, on any CPU, each to its
stated relative tolerance (1e-12, or the wider one its golden file gives an ill-conditioned
quantity; tests/goldens/golden.py says how that is measured). Never bitwise: CI also runs
these with numpy's AVX-512 loops and OpenBLAS's AVX-512 kernels disabled."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import trackkit.scenario as S
from tests.goldens.golden import HERE, RTOL, golden_numbers, leaves, relative

pytestmark = pytest.mark.portability


@pytest.mark.parametrize("name", sorted(S.bundled()))
def test_bundled_scenario_matches_golden(name):
    path = HERE / f"{name}.json"
    assert path.exists(), f"no golden for {name}: run python tests/goldens/golden.py"
    golden = json.loads(path.read_text())
    expected = dict(leaves(golden["numbers"]))
    actual = dict(leaves(golden_numbers(name)))
    assert set(actual) == set(expected), (
        f"{name}: quantities added {sorted(set(actual) - set(expected))}, "
        f"missing {sorted(set(expected) - set(actual))}")
    off = []
    for q, want in expected.items():
        got = actual[q]
        if isinstance(want, float):
            tol = golden["tolerance"].get(q, RTOL)
            if not relative(got, want) <= tol:
                off.append(f"{q} = {got!r}, golden {want!r}: relative difference "
                           f"{relative(got, want):.2e} above its tolerance {tol:.1e}")
        elif got != want:
            off.append(f"{q} = {got!r}, golden {want!r} (compared exactly)")
    assert not off, f"{name}: {len(off)} of {len(expected)} numbers off\n" + "\n".join(off)


def test_every_golden_has_a_scenario():
    assert {p.stem for p in Path(HERE).glob("*.json")} <= set(S.bundled())


def test_tolerances_are_stated_and_at_least_the_promise():
    # a golden file may widen the tolerance only for quantities it names, never tighten it
    # below 1e-12, and every named quantity exists
    for path in Path(HERE).glob("*.json"):
        golden = json.loads(path.read_text())
        assert golden["rtol"] == RTOL
        names = dict(leaves(golden["numbers"]))
        for q, tol in golden["tolerance"].items():
            assert q in names and isinstance(names[q], float), (path.name, q)
            assert math.isfinite(tol) and tol > RTOL, (path.name, q, tol)

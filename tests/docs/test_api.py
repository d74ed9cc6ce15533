"""What the API reference documents is there to document: every package the site lists is
reachable from ``import trackkit as tk`` as ``tk.NAME``, and every public name of every
public module (its ``__all__``) has a docstring. The site's build refuses a missing one too
(``tests/docs/test_build_checks.py``); this test names them all at once, without a build."""

from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "docs" / "_ext"))
import trackkit_docs  # noqa: E402  (the site's own list of packages and modules)


def test_every_package_of_the_reference_is_an_attribute_of_trackkit():
    names = [p.split(".", 1)[1] for p in trackkit_docs.PACKAGES if p != "trackkit"]
    code = ("import trackkit as tk\n"
            f"for n in {names!r}:\n"
            "    assert getattr(tk, n).__name__ == 'trackkit.' + n, n\n"
            "assert set(tk.__all__) >= set(" + repr(names) + ")\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, cwd=REPO)
    assert p.returncode == 0, p.stderr


def test_every_public_name_has_a_docstring():
    missing = []
    for package in trackkit_docs.PACKAGES:
        for module in trackkit_docs.public_modules(package):
            mod = importlib.import_module(module)
            for name in trackkit_docs.members(module):
                obj = getattr(mod, name)
                if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                    continue  # constants carry `#:` comments, checked by the build
                own = obj.__dict__.get("__doc__") if inspect.isclass(obj) else obj.__doc__
                if not (own or "").strip():  # a class's own, not one inherited
                    missing.append(f"{module}.{name}")
    assert not missing, f"public names without a docstring: {missing}"

"""Running the real ``trackkit`` command in a subprocess, as a user would, and checking that a
user's mistake is reported in words: the exit code, the names the message must carry, and no
traceback or numpy warning on either stream."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

LEAKS = ("Traceback (most recent call last)", "RuntimeWarning", "Warning:", "numpy/",
         'File "')


@dataclass
class Ran:
    code: int
    out: str
    err: str

    @property
    def text(self) -> str:
        return self.out + self.err


def trackkit(*args: str, cwd: Path | None = None, env: dict[str, str] | None = None,
             timeout: float = 300.0) -> Ran:
    """``trackkit ARGS`` in a fresh interpreter (``python -m trackkit.cli``), wide output so
    that rich does not fold the message."""
    full_env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1", **(env or {})}
    full_env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.run([sys.executable, "-m", "trackkit.cli", *args], cwd=cwd, env=full_env,
                       capture_output=True, text=True, timeout=timeout)
    return Ran(p.returncode, p.stdout, p.stderr)


def assert_user_error(ran: Ran, code: int, *names: str) -> None:
    """Exit ``code``; every one of ``names`` (file, field, value) appears in the message; no
    traceback, source line or numpy warning leaked."""
    assert ran.code == code, f"exit {ran.code}, expected {code}\n{ran.text}"
    for name in names:
        assert name in ran.text, f"the message does not name {name!r}:\n{ran.text}"
    for leak in LEAKS:
        assert leak not in ran.text, f"{leak!r} leaked into the output:\n{ran.text}"

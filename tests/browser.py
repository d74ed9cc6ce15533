"""Pages in a real browser: Debian's headless Chromium, offline, in a fresh profile
(``.ci/run`` installs ``chromium`` when missing). Shared by the report's and the
documentation site's browser tests."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
from pathlib import Path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WIDTH, HEIGHT = 1200, 1400
CONSOLE = re.compile(r":CONSOLE[:(]\d*\)?\]? (.*)")


def open_in_chromium(page: Path | str, tmp: Path, *, width: int = WIDTH, height: int = HEIGHT,
                     wait_ms: int = 0) -> tuple[str, list[str], Path]:
    """Load ``page`` (a file, or a ``file://`` address with a query) headless, offline, in a
    fresh profile: its DOM after the scripts ran, the console messages and a screenshot.
    ``wait_ms`` lets the page's asynchronous work (a search, MathJax) run that long in
    virtual time before the DOM is taken. The browser's whole process group is killed
    afterwards, whatever happened."""
    shot = tmp / "shot.png"
    uri = page.as_uri() if isinstance(page, Path) else page
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={tmp / 'profile'}",
           "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",  # loopback only
           "--enable-logging=stderr", "--v=0", f"--window-size={width},{height}",
           "--hide-scrollbars", f"--screenshot={shot}", "--dump-dom", uri]
    if wait_ms:
        cmd.insert(-1, f"--virtual-time-budget={wait_ms}")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, cwd=tmp)
    try:
        out, err = proc.communicate(timeout=60)  # a guard; it takes 2-5 s
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    assert proc.returncode == 0, err[-2000:]
    return out, [m.group(1) for m in map(CONSOLE.search, err.splitlines()) if m], shot

"""The ``trackkit`` command: list, show and run the bundled (or your own) scenarios, and track
recorded data.

    trackkit list
    trackkit show bo-cv [--format toml|json]
    trackkit run [NAME|FILE] [--runs N] [--seed S] [--out DIR] [--workers K] [--scheduler ADDR]
    trackkit sweep [NAME|FILE] --param PATH=V1,V2,... [--param ...] [--design grid|random|lhs]
                   [--points N] [--runs N] [--seed S] [--block B] [--workers K | --scheduler ADDR]
                   [--out DIR] [--fresh]
    trackkit network NAME|FILE [--runs N] [--seed S] [--out DIR] [--straight]
                     [--agents inprocess|processes]
    trackkit track FILE [--format ais|opensky|detections] [--as-radar] [radar, tracker and
                   input options] [--on-bad skip|stop] [--out DIR]
    trackkit identify LOG --inputs INPUTS.csv [--filter ekf|ukf|ckf|srckf|ls] [--period 1]
                      [--on-bad skip|stop] [--out DIR]
    trackkit identify NAME|FILE [--runs N] [--seed S] [--filter ...] [--out DIR]

Exit codes: 0 done; 1 a system error (disk full, a Dask scheduler that does not answer, an
unexpected failure); 2 bad input (a scenario error, a bad option value, an output directory
that cannot be created or written, or one that another run is writing into); 130
interrupted (Ctrl-C). Every failure is one message in words, no traceback
(``TRACKKIT_DEBUG=1`` keeps the traceback). The output directory is created, proven writable
and locked before anything is computed; report files appear only when complete, listed in its
``manifest.json`` (which command wrote them, with what arguments). A directory holding another
command's output, or files no manifest lists that the command would overwrite, is refused. The
default directory is ``trackkit-out/NAME``: a scenario file's name without ``.toml``, else the
bundled scenario's name.

The package holds one module per command (``scenarios``: list and show; ``run``, ``sweep``,
``network``, ``track``, ``identify``), each parsing its options and calling the library;
``output`` holds what they share (errors in words, the output directory and its lock,
progress bars), ``entry`` the typer app and ``main``.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    # Ctrl-C while the modules below import: nothing has been written and nothing is held, so
    # leave at once; a KeyboardInterrupt here would surface as a traceback from deep inside an
    # import (or as pydantic's "Error calling __set_name__")
    os.write(2, b"interrupted\n")
    os._exit(130)


def _started_as_command() -> bool:
    from multiprocessing import parent_process

    if parent_process() is not None:  # a worker process started by the command: not it
        return False
    argv = list(getattr(sys, "orig_argv", []))
    if "-m" in argv and argv[argv.index("-m") + 1:argv.index("-m") + 2] == ["trackkit.cli"]:
        return True  # python -m trackkit.cli (its __main__ runs after this package)
    return os.path.basename(sys.argv[0] or "").startswith("trackkit")


try:
    _previous_sigint = signal.signal(signal.SIGINT, _interrupted_while_starting)
except ValueError:  # imported outside the main thread: signals are not ours to handle
    _previous_sigint = None

# the commands register in this order, the order of trackkit --help
from trackkit.cli import (  # noqa: E402, F401, I001
    scenarios, run, sweep, network, track, identify,
)
from trackkit.cli.entry import app, finish_commands, main  # noqa: E402
from trackkit.cli.output import LOCK_FILE  # noqa: E402

__all__ = ["app", "main", "LOCK_FILE"]

finish_commands()

if _previous_sigint is not None and not _started_as_command():
    signal.signal(signal.SIGINT, _previous_sigint)  # imported as a library: hand Ctrl-C back

"""The ``trackkit`` typer app and its entry point: the version option, Ctrl-C and SIGTERM,
warnings in one line, and the last word on any error that escapes a command."""

from __future__ import annotations

import os
import signal
import sys
import warnings
from typing import Annotated, Any

import click
import typer
from rich.text import Text

from trackkit.cli.output import describe, is_interrupt, say_interrupted, session, stderr


class _FlagsWithoutType:
    """Help without a ``<bool>`` type beside a flag (``--help``, ``--straight``): a flag
    takes no value."""

    def get_params(self, ctx: click.Context) -> list[Any]:
        params = super().get_params(ctx)  # type: ignore[misc]
        for p in params:
            if getattr(p, "is_bool_flag", False) and p.metavar is None:
                p.metavar = ""
        return params


class _Group(_FlagsWithoutType, typer.core.TyperGroup):
    pass


class _Command(_FlagsWithoutType, typer.core.TyperCommand):
    pass


app = typer.Typer(
    name="trackkit",
    cls=_Group,
    help="Target tracking comparisons: Monte Carlo runs, PCRLB, tables, plots and reports.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("trackkit")
        except PackageNotFoundError:  # run from a source tree without installing
            from trackkit import __version__ as v
        typer.echo(f"trackkit {v}")
        raise typer.Exit(0)


@app.callback()
def _options(version: Annotated[bool, typer.Option(
        "--version", callback=_print_version, is_eager=True,
        help="Print trackkit's version and exit.")] = False) -> None:
    pass


def _paragraphs(doc: str) -> str:
    """A docstring's paragraphs each on one line, so that rich wraps them to the terminal
    (typer's rich help keeps the hard line breaks of the source)."""
    import inspect

    return "\n\n".join(" ".join(p.split()) for p in inspect.cleandoc(doc).split("\n\n"))


def finish_commands() -> None:
    """Once every command is registered: help without a flag's type, docstrings' paragraphs
    each on one line."""
    for info in app.registered_commands:
        if info.cls in (None, typer.core.TyperCommand):  # typer fills in its default
            info.cls = _Command
        info.help = _paragraphs(info.help or info.callback.__doc__ or "")



def _one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                      lineno: int, file: Any = None, line: str | None = None) -> None:
    # a user sees what happened, not numpy's source path and line
    stderr().print(Text(f"warning: {message}", style="yellow"), soft_wrap=True)


def _unraisable(info: Any) -> None:
    # Ctrl-C inside a finaliser is swallowed by Python ("Exception ignored in ..."), and an
    # interrupt raised here again would be swallowed with it: remember it, and the next
    # progress report raises it in the main thread, where main() turns it into one line
    if isinstance(info.exc_value, KeyboardInterrupt):
        session.interrupt = True
    elif os.environ.get("TRACKKIT_DEBUG"):
        sys.__unraisablehook__(info)




def terminate(signum: int, frame: object) -> None:
    # SIGTERM: unwind like Ctrl-C, so that the lock and temporary files are removed
    raise KeyboardInterrupt


def _forget_handled_interrupt() -> None:
    # CPython (3.11) marks a KeyboardInterrupt that escapes any exec() of a string (dataclass,
    # namedtuple and pydantic class construction use them) as "unhandled" in a global flag,
    # even when it is caught later, and then ends the process by SIGINT instead of our exit
    # code; every exec() of a string starts by clearing that flag
    exec("None")


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``trackkit`` command (and ``python -m trackkit.cli``)."""
    session.main, session.announced = True, False
    try:
        _run_main(argv)
    finally:
        _forget_handled_interrupt()


def _run_main(argv: list[str] | None) -> None:
    try:
        try:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            signal.signal(signal.SIGTERM, terminate)
        except ValueError:  # not the main thread
            pass
        sys.unraisablehook = _unraisable
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            app(args=argv, prog_name="trackkit")
    except SystemExit as done:
        if done.code == 130 and not session.announced:
            say_interrupted()
        raise
    except BaseException as err:
        if is_interrupt(err):
            say_interrupted()
            sys.exit(130)
        if os.environ.get("TRACKKIT_DEBUG") or not isinstance(err, Exception):
            raise
        message, code = describe(err)
        stderr().print(Text(f"error: {message}", style="red"), soft_wrap=True)
        sys.exit(code)

"""The ``wncs-lp`` command line. Thin: parse, call the library, print.

Every subcommand takes a scenario file and ``--set KEY=VALUE`` overrides; with ``--json`` it
prints exactly one JSON object on stdout (messages, warnings and progress go to stderr). The
commands that solve share one ``--method`` vocabulary (:mod:`wncs_lp.methods`, default
``auto``); ``--progress/--no-progress`` (default: on a terminal without ``--json``) shows the
phases and the solver's iterations on stderr. Errors from bad
input print one line ``error: ...`` on stderr and exit with status 2 (with ``--json`` also one
object ``{"error", "type", "source", "field"}`` on stdout). Ctrl-C and SIGTERM stop a command
with one line on stderr and status 130 / 143 (with ``--json`` also one object ``{"interrupted": true,
"signal", "exit_status", ...}`` on stdout); what was written so far is complete (atomic writes).
Every JSON object starts with ``schema_version`` and the toolkit's ``version``.

Each module of this package lists its subcommands in ``COMMANDS``; :func:`build_parser` adds
the modules' commands in the order of :data:`MODULES` (the one place a new module is named).
"""
from __future__ import annotations

import argparse
import sys
from typing import Sequence

from ..errors import WncsError
from . import bound, capstudy, export, maps, policy, reproduce, solve, tradeoff, validate, verify
from .common import Command

__all__ = ["main", "build_parser", "COMMANDS"]

#: Command modules, in the order their subcommands appear in ``wncs-lp --help``.
MODULES = (validate, solve, bound, policy, tradeoff, capstudy, reproduce, verify, maps, export)

#: Every subcommand of ``wncs-lp``.
COMMANDS: list[Command] = [cmd for module in MODULES for cmd in module.COMMANDS]


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="wncs-lp",
        description="Exact average-cost scheduling for multi-process WNCS with edge computing.",
    )
    parser.add_argument("--version", action="version", version=f"wncs-lp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        cmd.configure(p)
        p.set_defaults(func=cmd.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    import signal
    import warnings

    from ..errors import ScenarioWarning

    args = build_parser().parse_args(argv)
    terminated: list[int] = []

    def on_sigterm(signum, frame):  # stop like Ctrl-C (files are written atomically), then say so
        terminated.append(signum)
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread: leave SIGTERM alone
        previous = None
    try:
        with warnings.catch_warnings():
            # the commands print a degenerate scenario's warnings themselves, in words (common.load)
            warnings.filterwarnings("ignore", category=ScenarioWarning)
            code = int(args.func(args) or 0)
        if terminated:
            raise KeyboardInterrupt
        sys.stdout.flush()  # a reader that went away (``| head``) is found here, not at exit
        return code
    except BrokenPipeError:
        return _reader_gone()
    except OSError as exc:  # a write that failed mid-run (disk full, folder removed): one line
        text = f"{str(exc.filename) + ': ' if exc.filename else ''}{exc.strerror or exc}"
        print(f"error: {text}", file=sys.stderr)
        if getattr(args, "json", False):
            from .common import emit_json

            emit_json({"error": text, "type": type(exc).__name__})
        return 2
    except WncsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if getattr(args, "json", False):  # --json promises one JSON object on stdout, errors included
            from .common import emit_json

            emit_json({"error": str(exc), "type": type(exc).__name__,
                       **{k: getattr(exc, k) for k in ("source", "field") if hasattr(exc, k)}})
        return 2
    except KeyboardInterrupt:
        name, code = ("SIGTERM", 143) if terminated else ("SIGINT", 130)
        text = f"{'terminated (SIGTERM)' if terminated else 'interrupted'}: results already written are kept"
        print(text, file=sys.stderr)
        if getattr(args, "json", False):  # --json still prints its one object, saying so
            from .common import emit_json

            emit_json({"interrupted": True, "signal": name, "exit_status": code, "error": text,
                       "type": "KeyboardInterrupt", "command": args.command})
        return code
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


#: The exit status when the reader of stdout closed it early: 128 + SIGPIPE, as a shell reports
#: a command ended by that signal.
EXIT_PIPE = 141


def _reader_gone() -> int:
    """stdout's reader closed the pipe (``wncs-lp ... --json | head -c 10``): nothing more can be
    shown, so stop quietly; stdout is pointed at /dev/null so that the interpreter's own flush at
    exit finds no broken pipe either."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout is not a file descriptor (an embedding caller)
        pass
    return EXIT_PIPE

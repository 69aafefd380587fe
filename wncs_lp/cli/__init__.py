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

from ..errors import WncsError, printable
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

    from .. import stopping
    from ..errors import ScenarioWarning

    args = build_parser().parse_args(argv)

    def on_signal(signum, frame):  # stop the whole command (files are written atomically), then say so
        stopping.request(signum)
        if stopping.not_raisable(frame):  # inside numba's compiler it can hang it, in a finalizer it is lost:
            stopping.deliver_later(signum)  # a moment later, or at the next check between steps if that comes first
            return
        raise KeyboardInterrupt

    previous = {}
    for s in stopping.STOP_SIGNALS:
        try:  # a Ctrl-C ignored by the caller (a background job) stays ignored
            if s != signal.SIGINT or signal.getsignal(s) != signal.SIG_IGN:
                previous[s] = signal.signal(s, on_signal)
        except ValueError:  # not the main thread: leave the signals alone
            break
    stopping.clear()
    try:
        with warnings.catch_warnings(), stopping.redeliver_lost():
            # the commands print a degenerate scenario's warnings themselves, in words (common.load)
            warnings.filterwarnings("ignore", category=ScenarioWarning)
            code = int(args.func(args) or 0)
        stopping.check()  # a step returned what it had after a signal: the command stopped, say so
        sys.stdout.flush()  # a reader that went away (``| head``) is found here, not at exit
        return code
    except KeyboardInterrupt:
        for s in previous:  # a second signal while this is said is not a traceback
            signal.signal(s, signal.SIG_IGN)
        term = stopping.requested() == signal.SIGTERM
        stopping.clear()
        name, code = ("SIGTERM", 143) if term else ("SIGINT", 130)
        text = f"{'terminated (SIGTERM)' if term else 'interrupted'}: results already written are kept"
        return _report(args, text, {"interrupted": True, "signal": name, "exit_status": code, "error": text,
                                    "type": "KeyboardInterrupt", "command": args.command}, code)
    except BrokenPipeError:
        return _reader_gone()
    except OSError as exc:  # a write that failed mid-run (disk full, folder removed): one line
        text = f"{str(exc.filename) + ': ' if exc.filename else ''}{exc.strerror or exc}"
        return _report(args, f"error: {text}", {"error": text, "type": type(exc).__name__}, 2)
    except WncsError as exc:  # --json promises one JSON object on stdout, errors included
        return _report(args, f"error: {exc}", {"error": str(exc), "type": type(exc).__name__,
                                               **{k: getattr(exc, k) for k in ("source", "field")
                                                  if hasattr(exc, k)}}, 2)
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        stopping.clear()


def _report(args, line: str, payload: dict, code: int) -> int:
    """``line`` on stderr and, under ``--json``, ``payload`` as the one JSON object; ``code``."""
    try:
        print(printable(line), file=sys.stderr, flush=True)  # one line, whatever a name holds
        if getattr(args, "json", False):
            from .common import emit_json

            emit_json(payload)
            sys.stdout.flush()
    except BrokenPipeError:
        _reader_gone()
    return code


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

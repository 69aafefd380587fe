"""What the subcommands share: scenario arguments, loading, JSON output, the command record."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

from ..methods import CONSTRAINED_METHODS, DEFAULT_METHOD, METHOD_HELP, METHODS, SCENARIO_METHODS

__all__ = ["Command", "whole_option", "real_option", "add_scenario_args", "add_method_arg", "add_progress_arg",
           "add_threads_arg",
           "add_parallel_args", "executor_of", "progress_for", "load", "emit_json", "head", "output_file",
           "output_folder", "write_after_work", "warn", "solution_json", "scenario_file", "JSON_SCHEMA_VERSION", "SOLVE_METHODS",
           "MATRIX_FREE_METHODS"]

#: The methods of a command that takes a scenario beyond :data:`METHODS` (the matrix-free solver),
#: and those of ``solve``: every unconstrained method and every constrained one.
MATRIX_FREE_METHODS = tuple(m for m in SCENARIO_METHODS if m not in METHODS)
SOLVE_METHODS = METHODS + tuple(m for m in CONSTRAINED_METHODS if m not in METHODS) + MATRIX_FREE_METHODS


class Command(NamedTuple):
    """One subcommand: its name, help line, argument setup and handler (returns the exit status)."""

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


#: The version of the ``--json`` layout: 2 since a solver's statistics sit under ``"stats"``.
JSON_SCHEMA_VERSION = 2


def emit_json(payload: dict) -> None:
    """Print one JSON object on stdout (strict JSON: NaN/inf written as null, see :func:`wncs_lp.files.dumps`),
    starting with ``schema_version`` (:data:`JSON_SCHEMA_VERSION`) and the toolkit's ``version``."""
    import wncs_lp

    from ..files import dumps
    from ..stopping import check

    check()  # a command stopped by a signal prints the interrupted object instead, and only that
    print(dumps({"schema_version": JSON_SCHEMA_VERSION, "version": wncs_lp.__version__, **payload}, indent=2))


def solution_json(sol) -> dict:
    """A solution's ``summary()`` for ``--json``: the certificate, ``iterations`` and ``seconds`` at
    the top, the method's own statistics (which differ from method to method) under ``"stats"``."""
    from ..files import scalars

    summary = sol.summary()
    stats = scalars(getattr(sol, "stats", None) or {})
    top = {k: v for k, v in summary.items() if k not in stats or k in _TOP_KEYS}
    return {**top, "stats": {k: v for k, v in stats.items() if k not in _TOP_KEYS}}


#: The keys of a solution that stay at the top of ``--json`` even when its statistics repeat them.
_TOP_KEYS = ("method", "status", "status_code", "message", "gain", "gain_lower", "gain_upper", "certificate_gap",
             "iterations", "seconds", "policy")


def warn(text: str) -> None:
    """One ``warning: ...`` line on stderr (never on stdout, so ``--json`` stays clean)."""
    from ..errors import printable

    print(f"warning: {printable(text)}", file=sys.stderr, flush=True)


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario TOML file, or the name of a shipped one (paper_p12, paper_p123, ...: "
                                    "wncs-lp validate --list; docs/scenarios.md)")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a field: p=0.8, tau_cap=15, process.2.weight=2, server.edge.p_up=0.7, "
             "constraint.1.max=0.3 (repeatable; processes, servers and constraints by 1-based index or name)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--force", action="store_true",
                   help="build even when the size guard estimates more memory than the machine has available")


def add_method_arg(p: argparse.ArgumentParser, what: str = "", extra: tuple[str, ...] = (), extra_help: str = "") -> None:
    """``--method`` with the one vocabulary of :mod:`wncs_lp.methods` (default auto), plus ``extra``
    methods a command takes beyond it (e.g. ``matrix-free``), described by ``extra_help``."""
    p.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS + tuple(extra),
                   help=(f"{what}: " if what else "") + METHOD_HELP + (f"; {extra_help}" if extra_help else ""))


def whole_option(lo: int | None = None, hi: int | None = None, what: str = "whole number") -> Callable[[str], int]:
    """An argparse ``type``: a whole number in ``[lo, hi]`` (the checks of :mod:`wncs_lp.arguments`),
    else the parser's usage error saying what was expected."""
    from ..arguments import whole
    from ..errors import ArgumentError

    def parse(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            value = text
        try:
            return whole(value, what, lo=lo, hi=hi)
        except ArgumentError as exc:
            expected = exc.detail.split(", got ", 1)[0].replace("a whole number", f"a {what}")
            raise argparse.ArgumentTypeError(f"{expected}, got {text!r}") from None

    parse.__name__ = what
    return parse


def real_option(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                hi_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in the range (``lo_open`` / ``hi_open``: the end
    excluded), else the parser's usage error; ``nan`` and ``inf`` are refused."""
    from ..arguments import real
    from ..errors import ArgumentError

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = text
        try:
            return real(value, "number", lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open)
        except ArgumentError as exc:
            raise argparse.ArgumentTypeError(exc.detail.split(", got ", 1)[0] + f", got {text!r}") from None

    parse.__name__ = "number"
    return parse


#: The options every command shares, checked by the parser.
COUNT = whole_option(1)  # replications, workers, steps: at least one
SLOTS = whole_option(1, what="number of slots")
NONNEGATIVE = whole_option(0)
SEED = whole_option(0, what="seed")


def add_threads_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=whole_option(1, what="number of threads"), default=None, metavar="N",
                   help="threads of the solvers' compiled kernels (value iteration, the matrix-free solver; default: "
                        "the machine's cores)")


def add_parallel_args(p: argparse.ArgumentParser, what: str, executor: bool = True) -> None:
    """``--max-workers`` (and ``--executor``) and ``--scheduler``: where a study's points run."""
    p.add_argument("--max-workers", type=COUNT, default=1,
                   help=f"{what} in parallel worker processes (default 1: in order, with warm start)")
    if executor:
        p.add_argument("--executor", default="process", choices=["process", "dask"],
                       help="parallel backend with --max-workers > 1: worker processes, or a Dask cluster of that "
                            "many workers on this machine")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help=f"run the {what} on the Dask cluster whose scheduler is at ADDRESS (e.g. tcp://host:8786; "
                        "docs/dask.md)")


def executor_of(args: argparse.Namespace):
    """The executor a study's arguments name (:mod:`wncs_lp.studies.executors`)."""
    if args.scheduler is not None:
        if "://" not in args.scheduler:
            from ..errors import WncsError

            raise WncsError(f"--scheduler {args.scheduler!r}: expected a Dask scheduler address such as "
                            "tcp://host:8786")
        return args.scheduler
    return getattr(args, "executor", None)


def add_simulation_args(p: argparse.ArgumentParser, what: str) -> None:
    """``--slots``, ``--reps``, ``--seed``, ``--burn-in`` of a Monte Carlo run; ``what`` prefixes their help
    (``"Monte Carlo"``, ``"--untruncated"``)."""
    p.add_argument("--slots", type=SLOTS, default=40_000, help=f"{what}: slots per replication (default 40000)")
    p.add_argument("--reps", type=COUNT, default=20, help=f"{what}: independent replications (default 20)")
    p.add_argument("--seed", type=SEED, default=0, help=f"{what}: random seed, a whole number >= 0 (default 0)")
    p.add_argument("--burn-in", type=NONNEGATIVE, default=1000, help=f"{what}: slots discarded first (default 1000)")


def add_progress_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="show progress on stderr (phases, value-iteration sweeps with the certificate gap, LP "
                        "iterations); default: on when stderr is a terminal and --json is not given")


def progress_for(args: argparse.Namespace):
    """The :class:`~wncs_lp.progress.Progress` of a command (on, off, or by the terminal)."""
    from ..progress import Progress, wanted

    return Progress(wanted(getattr(args, "progress", None), getattr(args, "json", False)))


def scenario_file(text: str) -> str | Path:
    """A scenario argument as a file: the file when it exists, else the shipped scenario of that
    name (``paper_p12`` or ``paper_p12.toml``, :func:`wncs_lp.scenario_path`), else as given (the
    loader then says it cannot be read)."""
    from .. import scenario_path

    path = Path(text)
    if path.exists() or len(path.parts) != 1:
        return text
    try:
        return scenario_path(text)
    except FileNotFoundError:
        return text


def load(args: argparse.Namespace):
    """The scenario of ``args.scenario`` (a file or a shipped scenario's name, :func:`scenario_file`)
    with the ``--set`` overrides applied (degenerate
    scenarios get ``warning:`` lines on stderr)."""
    from ..scenario import load_scenario

    scenario = load_scenario(scenario_file(args.scenario), args.overrides)
    for text in scenario.degenerate_warnings():
        warn(text)
    return scenario


def output_file(path: str, option: str, suffixes: Sequence[str] | None = None) -> Path:
    """Check an output file before any work: its folder exists (nothing is created) and is
    writable, the path is not a folder, and, with ``suffixes``, its extension is one of them.

    Raises
    ------
    WncsError
        One line naming the option, the path and what is wrong.
    """
    from ..errors import WncsError
    from ..files import check_output_file

    out = Path(path)
    if suffixes is not None and out.suffix.lower().lstrip(".") not in suffixes:
        found = f"'{out.suffix}'" if out.suffix else "no extension"
        raise WncsError(f"{option} {path}: expected a file ending in "
                        f"{', '.join('.' + s for s in suffixes)}, found {found}")
    return check_output_file(out, option)


def output_folder(path: str, option: str = "--out") -> Path:
    """Check an output folder before any work: it is a writable folder, or can be created as one
    (nothing is created here).

    Raises
    ------
    WncsError
        One line naming the option, the path and what is wrong.
    """
    from ..files import check_output_folder

    return check_output_folder(path, option)


def write_after_work(write: Callable[[], object], path: str, option: str = "--out") -> tuple[object, str | None]:
    """Run ``write()`` (saving a finished result) and return ``(its value, None)``, or
    ``(None, message)`` when the write fails: the caller still prints the result, then the
    message, and exits non-zero, so a finished computation is never lost to a full disk or a
    folder that became unwritable."""
    from ..errors import WncsError

    try:
        return write(), None
    except (OSError, WncsError) as exc:
        why = f"{exc.strerror} ({exc.filename})" if isinstance(exc, OSError) and exc.strerror else str(exc)
        return None, f"{option} {path}: the result above was computed but could not be written: {why}"


def head(args: argparse.Namespace, scenario, mdp=None) -> dict:
    """The keys every JSON payload starts with: scenario, overrides, kind (and the MDP's size)."""
    out = {"scenario": scenario.source, "overrides": args.overrides, "kind": scenario.model.kind}
    if mdp is not None:
        out.update(states=mdp.n_states, pairs=mdp.n_pairs)
    return out

"""What the subcommands share: scenario arguments, loading, JSON output, the command record."""
from __future__ import annotations

import argparse
from typing import Callable, NamedTuple

__all__ = ["Command", "add_scenario_args", "load", "emit_json", "head"]


class Command(NamedTuple):
    """One subcommand: its name, help line, argument setup and handler (returns the exit status)."""

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def emit_json(payload: dict) -> None:
    """Print one JSON object on stdout (strict JSON: NaN/inf written as null, see :func:`wncs_lp.files.dumps`)."""
    from ..files import dumps

    print(dumps(payload, indent=2))


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario TOML file (see formulations/)")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a field: p=0.8, tau_cap=15, process.2.weight=2, server.edge.p_up=0.7 (repeatable)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--force", action="store_true",
                   help="build even when the size guard estimates more memory than the machine has available")


def load(args: argparse.Namespace):
    """The scenario of ``args.scenario`` with the ``--set`` overrides applied."""
    from ..scenario import load_scenario

    return load_scenario(args.scenario, args.overrides)


def head(args: argparse.Namespace, scenario, mdp=None) -> dict:
    """The keys every JSON payload starts with: scenario, overrides, kind (and the MDP's size)."""
    out = {"scenario": scenario.source, "overrides": args.overrides, "kind": scenario.model.kind}
    if mdp is not None:
        out.update(states=mdp.n_states, pairs=mdp.n_pairs)
    return out

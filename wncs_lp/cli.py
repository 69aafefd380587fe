"""The ``wncs-lp`` command line. Thin: parse, call the library, print.

Every subcommand takes a scenario file and ``--set KEY=VALUE`` overrides; with ``--json`` it
prints exactly one JSON object on stdout (messages and progress go to stderr). Errors from bad
input print one line ``error: ...`` on stderr and exit with status 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any, Callable, Sequence

import numpy as np

from .errors import WncsError

__all__ = ["main", "build_parser"]


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def emit_json(payload: dict) -> None:
    """Print one JSON object on stdout (NaN/inf written as null, so it is strict JSON)."""

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return v

    print(json.dumps(clean(payload), default=_json_default, indent=2))


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


def load(args: argparse.Namespace):
    from .scenario import load_scenario

    return load_scenario(args.scenario, args.overrides)


# ----------------------------------------------------------------------------- solve
def cmd_solve(args: argparse.Namespace) -> int:
    from .models import build
    from .solvers import solve

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build(scenario)
    t_build = time.perf_counter() - t0
    sol = solve(mdp, method=args.method)
    total = time.perf_counter() - t0
    summary = sol.summary()
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "kind": scenario.model.kind,
        "states": mdp.n_states,
        "pairs": mdp.n_pairs,
        "nnz": int(mdp.P.nnz),
        **summary,
        "build_seconds": t_build,
        "solve_seconds": sol.seconds,
        "seconds": total,
    }
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"MDP: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs, built in {t_build:.2f} s")
        print(f"method {sol.method}: status {sol.status}, {sol.iterations} iterations, {sol.seconds:.2f} s")
        print(f"optimal average cost (gain): {sol.gain:.10g}")
        print(f"certificate: {sol.gain_lower:.12g} <= g* <= {sol.gain_upper:.12g} (relative width {sol.gap:.2e})")
        extra = {k: v for k, v in summary.items() if k not in payload or k in ()}
        for k, v in extra.items():
            print(f"  {k}: {v}")
    return 0 if sol.ok else 1


# ----------------------------------------------------------------------------- parser
SUBCOMMANDS: list[tuple[str, str, Callable[[argparse.ArgumentParser], None], Callable]] = []


def subcommand(name: str, help: str, configure: Callable[[argparse.ArgumentParser], None]):
    """Register a subcommand (used by the modules that add commands)."""

    def deco(fn: Callable[[argparse.Namespace], int]):
        SUBCOMMANDS.append((name, help, configure, fn))
        return fn

    return deco


def _configure_solve(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument(
        "--method",
        default="lp",
        choices=["lp", "lp-cvxpy", "rvi", "pi"],
        help="lp: occupation-measure LP on Clarabel (direct); lp-cvxpy: same LP through cvxpy; "
        "rvi: relative value iteration; pi: policy iteration (default: lp)",
    )


subcommand("solve", "build the MDP and solve it to optimality, with a certificate", _configure_solve)(cmd_solve)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wncs-lp",
        description="Exact average-cost scheduling for multi-process WNCS with edge computing.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name, help, configure, fn in SUBCOMMANDS:
        p = sub.add_parser(name, help=help, description=help)
        configure(p)
        p.set_defaults(func=fn)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WncsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: results already written are kept", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

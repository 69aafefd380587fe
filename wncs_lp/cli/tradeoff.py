"""``wncs-lp tradeoff``: the constrained optimum against one constraint's bound (resumable)."""
from __future__ import annotations

import argparse
import math
import sys

from ..methods import CONSTRAINED_METHODS, DEFAULT_METHOD
from .common import (COUNT, Command, add_parallel_args, add_scenario_args, add_threads_arg, emit_json, executor_of, head,
                     load, output_folder)


def cmd_tradeoff(args: argparse.Namespace) -> int:
    from ..errors import WncsError
    from ..solvers.route import build_scenario
    from ..studies import parse_values, tradeoff

    output_folder(args.out)  # before any work
    scenario = load(args)
    n = len(scenario.constraints)
    if not 1 <= args.constraint <= n:
        tables = "no [[constraint]] tables" if n == 0 else f"{n} [[constraint]] table{'s' if n > 1 else ''} (1..{n})"
        raise WncsError(f"{scenario.source}: no constraint number {args.constraint}: the scenario has {tables}")
    values = parse_values(args.values)
    spec = scenario.constraints[args.constraint - 1]
    side = args.side or ("max" if spec.max is not None else "min")
    mdp, _ = build_scenario(scenario, args.method, constrained=True, force=args.force)
    log = None if args.json else (lambda line: print(line, file=sys.stderr, flush=True))
    res = tradeoff(mdp, scenario.constraints, args.constraint - 1, values, side=side, method=args.method,
                   out=args.out, progress=log, plot=not args.no_plot, max_workers=args.max_workers,
                   executor=executor_of(args), threads=args.threads, fallback=args.fallback, warm=not args.cold)
    payload = {**head(args, scenario, mdp), "constraint_number": args.constraint, **res.summary()}
    if args.json:
        emit_json(payload)
    else:
        op = "<=" if side == "max" else ">="
        print(f"trade-off of {res.constraint} {op} b ({res.unit}); MDP {mdp.n_states:,} states, "
              f"{mdp.n_pairs:,} pairs; method {args.method}")
        print(f"{'bound':>10} {'gain':>16} {'certificate [lower, upper]':>34} {'multiplier':>12} {'rand.':>5}  status")
        for p in res.points:
            if p.feasible:
                print(f"{p.bound:>10g} {p.gain:>16.10g} {f'[{p.gain_lower:.10g}, {p.gain_upper:.10g}]':>34} "
                      f"{p.multiplier:>12.6g} {p.randomized_states:>5d}  {p.status}")
            else:
                r = f" (reachable: {p.reachable:.6g})" if math.isfinite(p.reachable) else ""
                print(f"{p.bound:>10g} {'':>16} {'':>34} {'':>12} {'':>5}  {p.status}{r}")
        print(f"without the constraint: gain {res.unconstrained_gain:.10g}; it stops binding at b = "
              f"{res.threshold:.6g}; least reachable value {res.reachable:.6g}")
        print(f"{res.computed} points computed, {res.reused} reused; files: {', '.join(res.files.values())}")
    return 0 if res.ok else 1


def _configure_tradeoff(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--constraint", type=COUNT, required=True, metavar="N",
                   help="the scenario's [[constraint]] table to sweep (1-based)")
    p.add_argument("--values", required=True,
                   help="bounds: START:STOP:STEP (stop included) or a comma list "
                        "(write --values=-0.1:0.4:0.1 for a negative start)")
    p.add_argument("--out", required=True, help="output folder: tradeoff.csv/.json/.png (resumed when it holds points)")
    p.add_argument("--side", choices=["max", "min"], default=None,
                   help="which bound to sweep (default: max if the table has one, else min)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=CONSTRAINED_METHODS,
                   help="constrained solver at every bound (default auto: the LP up to its size, the "
                        "Lagrangian route beyond)")
    p.add_argument("--fallback", default=None, choices=tuple(m for m in CONSTRAINED_METHODS if m != DEFAULT_METHOD),
                   help="solve again with this method the points the first one does not certify as optimal")
    add_parallel_args(p, "bounds", executor=False)
    add_threads_arg(p)
    p.add_argument("--cold", action="store_true",
                   help="solve every LP point from scratch (Clarabel) instead of re-solving it from the previous "
                        "point's basis (HiGHS dual simplex, the default when the LP solves the points)")
    p.add_argument("--no-plot", action="store_true", help="do not write tradeoff.png")


COMMANDS = [
    Command("tradeoff", "sweep one constraint's bound: optimal cost vs bound with multipliers and certificates "
            "(CSV/JSON resumable, figure)", _configure_tradeoff, cmd_tradeoff),
]

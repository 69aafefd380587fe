"""``wncs-lp solve``: build the MDP and solve it with a certificate."""
from __future__ import annotations

import argparse
import time

from .common import Command, add_scenario_args, emit_json, head, load


def cmd_solve(args: argparse.Namespace) -> int:
    from ..models.guard import build_checked
    from ..solvers import solve

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build_checked(scenario, force=args.force)
    t_build = time.perf_counter() - t0
    sol = solve(mdp, method=args.method)
    total = time.perf_counter() - t0
    summary = sol.summary()
    payload = {
        **head(args, scenario, mdp),
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
        used = f"{sol.method} -> {sol.stats['auto_choice']}" if "auto_choice" in sol.stats else sol.method
        print(f"method {used}: status {sol.status}, {sol.iterations} iterations, {sol.seconds:.2f} s")
        print(f"optimal average cost (gain): {sol.gain:.10g}")
        print(f"certificate: {sol.gain_lower:.12g} <= g* <= {sol.gain_upper:.12g} (relative width {sol.gap:.2e})")
        if "auto_choice" in sol.stats:
            st = sol.stats
            print(f"auto: chose {st['auto_choice']} ({st['auto_reason']})")
            if st.get("cross_check_method"):
                verdict = {True: "agrees", False: "DISAGREES", None: "failed"}[st.get("cross_check_agree")]
                extra = f", relative difference {st['cross_check_rel_diff']:.2e}" if "cross_check_rel_diff" in st else ""
                print(f"cross-check with {st['cross_check_method']}: {verdict}{extra}")
    return 0 if sol.ok else 1


def _configure_solve(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument(
        "--method",
        default="auto",
        choices=["auto", "lp", "lp-cvxpy", "rvi", "vi", "pi"],
        help="auto: LP or value iteration by size, cross-checked when both are cheap (says which); "
        "lp: occupation-measure LP on Clarabel (direct); lp-cvxpy: same LP through cvxpy; "
        "rvi: relative value iteration; vi: certified value iteration on the fused kernel; "
        "pi: policy iteration (default: auto)",
    )


COMMANDS = [
    Command("solve", "build the MDP and solve it to optimality, with a certificate", _configure_solve, cmd_solve),
]

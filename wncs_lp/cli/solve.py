"""``wncs-lp solve``: build the MDP and solve it with a certificate (constrained when the scenario has bounds)."""
from __future__ import annotations

import argparse
import time

from .common import Command, add_scenario_args, emit_json, head, load

#: Methods of an unconstrained solve, and of a constrained one (a scenario with [[constraint]] tables).
UNCONSTRAINED_METHODS = ("auto", "lp", "lp-cvxpy", "rvi", "vi", "pi")
CONSTRAINED_METHODS = ("auto", "lp", "lp-cvxpy", "lagrangian")


def cmd_solve(args: argparse.Namespace) -> int:
    from ..errors import SolverError
    from ..models.guard import build_checked

    scenario = load(args)
    constrained = bool(scenario.constraints) and not args.ignore_constraints
    allowed = CONSTRAINED_METHODS if constrained else UNCONSTRAINED_METHODS
    if args.method not in allowed:
        what = "a scenario with [[constraint]] tables" if constrained else "an unconstrained scenario"
        raise SolverError(f"--method {args.method} does not solve {what}; expected one of {', '.join(allowed)}")
    t0 = time.perf_counter()
    mdp = build_checked(scenario, force=args.force, need_lp=constrained and args.method in ("lp", "lp-cvxpy"))
    t_build = time.perf_counter() - t0
    if constrained:
        return _constrained(args, scenario, mdp, t0, t_build)
    from ..solvers import solve

    from ..truncation import policy_cap_mass

    sol = solve(mdp, method=args.method)
    cap = policy_cap_mass(mdp, sol.policy)
    if args.json:
        emit_json(_payload(args, scenario, mdp, sol, cap, t0, t_build))
    else:
        _header(scenario, mdp, t_build)
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
        print(f"truncation: under the optimal policy {cap.message()}")
    return 0 if sol.ok else 1


def _payload(args: argparse.Namespace, scenario, mdp, sol, cap, t0: float, t_build: float, **extra) -> dict:
    """The JSON of a solve: the head, the solution's summary, the mass at the cap, the timings."""
    return {**head(args, scenario, mdp), "nnz": int(mdp.P.nnz), **sol.summary(), **extra, "cap_mass": cap.to_dict(),
            "build_seconds": t_build, "solve_seconds": sol.seconds, "seconds": time.perf_counter() - t0}


def _header(scenario, mdp, t_build: float) -> None:
    print(scenario.describe())
    print(f"MDP: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs, built in {t_build:.2f} s")


def _constrained(args: argparse.Namespace, scenario, mdp, t0: float, t_build: float) -> int:
    from ..constrained import solve_constrained
    from ..truncation import cap_mass

    sol = solve_constrained(mdp, scenario.constraints, args.method)
    cap = cap_mass(mdp, sol.occupation)
    if args.json:
        emit_json(_payload(args, scenario, mdp, sol, cap, t0, t_build, mixes=sol.mixes(mdp)))
        return 0 if sol.ok else 1
    _header(scenario, mdp, t_build)
    print(f"constrained solve ({sol.method}): status {sol.status}, {sol.seconds:.2f} s")
    print(f"optimal average cost under the constraints: {sol.gain:.10g}")
    print(f"certificate: {sol.gain_lower:.12g} <= g*_C <= {sol.gain_upper:.12g} (relative width {sol.gap:.2e}; "
          "lower: Lagrangian bound by certified value iteration, upper: exact cost of the returned policy)")
    for c in sol.constraints:
        state = f"active ({c.side} bound), multiplier {c.multiplier:.6g}" if c.active else "not binding"
        print(f"  {c.label}: value {c.value:.10g} under the returned policy; {state}")
    if sol.n_randomized:
        print(f"the policy randomises in {sol.n_randomized} state(s):")
        for m in sol.mixes(mdp, limit=5):
            mix = ", ".join(f"{a} w.p. {p:.6g}" for a, p in m["mix"].items())
            print(f"  {m['label']}: {mix}")
    else:
        print("the policy is deterministic (no bound forces a mix)")
    print(f"truncation: under the returned policy {cap.message()}")
    return 0 if sol.ok else 1


def _configure_solve(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument(
        "--method",
        default="auto",
        choices=sorted(set(UNCONSTRAINED_METHODS) | set(CONSTRAINED_METHODS)),
        help="auto: LP or value iteration by size, cross-checked when both are cheap (says which); "
        "lp: occupation-measure LP on Clarabel (direct); lp-cvxpy: same LP through cvxpy; "
        "rvi: relative value iteration; vi: certified value iteration on the fused kernel; "
        "pi: policy iteration; lagrangian: (constrained scenarios, one bound) multiplier search with "
        "certified value iteration. A scenario with [[constraint]] tables takes auto, lp, lp-cvxpy or "
        "lagrangian (default: auto)",
    )
    p.add_argument("--ignore-constraints", action="store_true",
                   help="solve the unconstrained problem even if the scenario has [[constraint]] tables")


COMMANDS = [
    Command("solve", "build the MDP and solve it to optimality, with a certificate (constrained when the "
            "scenario has [[constraint]] tables)", _configure_solve, cmd_solve),
]

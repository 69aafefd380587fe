"""``wncs-lp verify``: check the structural theorems on the solved model.

Each check's verdict comes from its numbers by the one rule the reproduction uses too
(:mod:`wncs_lp.verify.verdict`): HOLDS (no violation), FAILS (a violation in recurrent states of
weight, each visited at least 1e-9 of the time, away from the AoI cap), DEPENDS (violations only in
transient states, in states of negligible weight or at the cap). Exit status: 0 when
no check FAILS and the solve is certified, 1 otherwise (2: bad input).
"""
from __future__ import annotations

import argparse
import time

from .common import (NONNEGATIVE, Command, add_method_arg, add_scenario_args, add_threads_arg, emit_json, head, load,
                     real_option)


def cmd_verify(args: argparse.Namespace) -> int:
    from ..workflow import run_scenario
    from ..verify import Tolerance, verify_all
    from ..verify.verdict import FAILS, RULE, combine

    scenario = load(args)
    t0 = time.perf_counter()
    run = run_scenario(scenario, args.method, constrained=False, force=args.force, threads=args.threads,
                         need_mdp=True)
    mdp, sol = run.mdp, run.solution
    reports = verify_all(mdp, sol, tolerance=Tolerance(args.atol, args.rtol), examples=args.examples)
    verdicts = [r.verdict for r in reports]
    payload = {
        **head(args, scenario, mdp),
        "verdict": combine(verdicts),
        "verdict_rule": RULE,
        "method": sol.method,
        "solve_status": sol.status,
        "gain": sol.gain,
        "gain_lower": sol.gain_lower,
        "gain_upper": sol.gain_upper,
        "checks": [r.to_json() for r in reports],
        "seconds": time.perf_counter() - t0,
    }
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"MDP: {mdp.n_states:,} states; {sol.method}: {sol.status}, gain {sol.gain:.10g} "
              f"(certificate width {sol.gap:.1e})")
        print(f"{'check':<13} {'verdict':<7} {'checked':>9} {'violations':>10} {'recurrent':>9} {'at cap':>7} "
              f"{'ties':>6} {'worst':>11}  unit")
        for r in reports:
            w = "" if r.worst is None else f"{r.worst.size:.4g}"
            print(f"{r.name:<13} {r.verdict:<7} {r.checked:>9} {r.violations:>10} {r.recurrent_violations:>9} "
                  f"{r.at_cap_violations:>7} {r.ties:>6} {w:>11}  {r.unit}")
        print(f"tie tolerance: tol = {reports[0].atol:g} + {reports[0].rtol:g} * span(V) = {reports[0].tol:.3g}; "
              f"recurrent = {reports[0].recurrence_rule}")
        print(f"verdicts: {RULE}")
        for r in reports:
            if r.examples:
                e = r.examples[0]
                weight = "" if e.stationary is None else f", weight {min(e.stationary):.3g}"
                far = "" if e.cap_distance is None else f" ({e.cap_distance} from it)"
                print(f"{r.name}: first example ({'recurrent' if e.recurrent else 'transient'}{weight}, "
                      f"{'at' if e.at_cap else 'below'} the cap{far}, size {e.size:.4g}):")
                for lab in e.labels:
                    print(f"    {lab}")
                for step in e.info.get("trajectory", []):
                    print(f"      -> {step['label']}  action {tuple(step['action'])}  p={step['prob']:.3g}"
                          + (f"  [{step['event']}]" if "event" in step else ""))
    if FAILS in verdicts:
        import sys

        print(f"verify: {', '.join(r.name for r in reports if r.verdict == FAILS)} FAILS", file=sys.stderr)
        return 1
    return 0 if sol.ok else 1


def _configure_verify(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    add_method_arg(p)
    p.add_argument("--atol", type=real_option(0.0), default=1e-9,
                   help="absolute part of the tie tolerance (default 1e-9)")
    p.add_argument("--rtol", type=real_option(0.0), default=1e-9,
                   help="part of the tie tolerance relative to span(V) = max V - min V (default 1e-9)")
    p.add_argument("--examples", type=NONNEGATIVE, default=10, help="example violations kept per check (default 10)")
    add_threads_arg(p)


COMMANDS = [
    Command("verify", "check Theorems 1-3 (monotone V, threshold policy, consistency) on the solved model; "
                      "exit 1 when a check FAILS",
            _configure_verify, cmd_verify),
]

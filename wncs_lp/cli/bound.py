"""``wncs-lp bound``: a certified lower bound on g*, and with ``--policy`` the certified optimality
gaps of the bound's policy and of the baselines."""
from __future__ import annotations

import argparse
import time

from ..errors import WncsError
from .common import (COUNT, NONNEGATIVE, Command, add_progress_arg, add_scenario_args, add_simulation_args, add_threads_arg,
                     emit_json, head, load, progress_for, real_option)


def cmd_bound(args: argparse.Namespace) -> int:
    from ..bounds import lower_bound, parse_relaxation, policy_gaps
    from ..bounds.gaps import policy_source
    from ..models.system import System
    from ..policies import parse_policy_names
    from ..solvers.threads import resolve_threads, thread_limit

    relaxation = parse_relaxation(args.relaxation)  # before any work
    compare = parse_policy_names(args.compare) if args.compare else []
    scenario = load(args)
    prog = progress_for(args)
    t0 = time.perf_counter()
    system = System.from_scenario(scenario, explore="auto")  # lazily where the automaton is too large to enumerate
    prog.phase(f"computing the {relaxation} lower bound")
    # the search options are relaxation 2's; relaxation 1's own max_iter counts other steps
    limit = {} if relaxation in ("private-servers", "grouped-private-servers") else {
        k: v for k, v in (("time_limit", args.time_limit), ("max_iter", args.max_steps)) if v is not None}
    if args.groups is not None:
        if relaxation not in ("grouped-private-servers", "joint-pairs"):
            raise WncsError("--groups is an option of --relaxation 3 (grouped private servers) and 4 (pairs)")
        limit["groups"] = _parse_groups(args.groups)
    # --threads caps every kernel of the command (the policies' and evaluations' too); relaxations 2
    # and 4 take their count explicitly (their library default is one thread)
    with thread_limit(args.threads):
        if relaxation in ("joint-configuration", "joint-pairs", "auto"):
            limit["threads"] = resolve_threads(args.threads)
        res = lower_bound(system, relaxation, tol=args.tol, progress=prog, **limit)
        report, source, why = None, res, ""
        if args.policy:
            source, why = policy_source(res, system, seed=args.seed)  # the bound's own tables unless clearly worse
            report = policy_gaps(res, system, ["bound", *compare], exact=None if args.exact_max_states else False,
                                 exact_max_states=args.exact_max_states or 0, slots=args.slots, reps=args.reps,
                                 seed=args.seed, burn_in=args.burn_in, control=not args.no_control_variate,
                                 progress=prog, tables=source)
        interval = _untruncated(args, res, source, system, report, compare, prog)
    if args.json:
        emit_json({**head(args, scenario), "bound": res.summary(), "explored": "lazily" if system.is_lazy else "whole",
                   "policies": None if report is None else {**report.summary(), "tables_note": why},
                   "untruncated": interval.to_dict(),
                   "seconds": time.perf_counter() - t0})
    else:
        _print(scenario, res, report, system.is_lazy, why)
        tail = "" if interval.candidates or interval.note else " (--untruncated simulates the policies without the cap for one)"
        print(interval.message() + tail)
    return 0 if res.certified else 1  # a search stopped at its budget still certifies its bound


def _untruncated(args: argparse.Namespace, res, source, system, report, compare: list[str], prog):
    """The interval for the optimum without the cap: the certified bound below (g*(cap) <= g*_inf),
    and with ``--untruncated`` the policies evaluated (the bound's alone without ``--policy``)
    simulated without the cap, the least upper confidence limit above."""
    from ..bounds.gaps import policy_by_name
    from ..bounds.tuned import TUNE_SEED_OFFSET
    from ..untruncated import untruncated_interval

    lower_from = f"the certified lower bound ({res.relaxation})"
    if not args.untruncated:
        return untruncated_interval(res.lower_bound, lower_from=lower_from)
    names = ["bound", *compare] if report is not None else ["bound"]
    # the tuned policies tuned on the report's seed as there (the same weights, not the default seed's)
    policies = [policy_by_name(n, source, system, tune_seed=args.seed + TUNE_SEED_OFFSET) for n in names]
    prog.phase(f"simulating {', '.join(p.name for p in policies)} without the AoI cap ({args.reps} x {args.slots} "
               f"slots each, seed {args.seed})")
    return untruncated_interval(res.lower_bound, policies, lower_from=lower_from, slots=args.slots, reps=args.reps,
                                seed=args.seed, burn_in=args.burn_in)


def _parse_groups(text: str) -> list[tuple[int, ...]]:
    """``"1,5;2,6;3;4"`` (1-based processes) -> [(0, 4), (1, 5), (2,), (3,)]."""
    try:
        groups = [tuple(int(k) - 1 for k in part.split(",")) for part in text.split(";") if part.strip()]
    except ValueError:
        groups = None
    if not groups or any(k < 0 for g in groups for k in g):
        raise WncsError(f"--groups {text!r}: expected groups of 1-based process numbers, e.g. '1,5;2,6;3,7;4,8'")
    return groups


def _print(scenario, res, report, lazy: bool = False, tables_note: str = "") -> None:
    from ..models.automaton import approx_count

    print(scenario.describe())
    why = f" (auto: {res.stats['auto_reason']})" if res.stats.get("auto_reason") else ""
    print(f"relaxation {res.relaxation}{why}: status {res.status}, {res.iterations} iterations, {res.seconds:.2f} s")
    if lazy:
        print("  the configuration automaton is too large to enumerate: explored lazily (relaxations 1 and 3 only; "
              "the capacity taken as an inequality)")
    print(f"certified lower bound: g* >= {res.lower_bound:.10g}")
    print(f"  certified by: {res.certified_by}")
    if res.relaxation in ("grouped-private-servers", "joint-pairs"):
        print("  groups: " + "; ".join(", ".join(scenario.processes[k].name for k in g) for g in res.tables.groups))
    if res.relaxation in ("private-servers", "grouped-private-servers"):
        names = ", ".join(f"{s.name} {lam:.8g}" for s, lam in zip(scenario.servers, res.multipliers))
        print(f"  multipliers (price of a server slot): {names}; capacity as an {res.stats['capacity']}")
    if res.relaxation_upper < float("inf"):
        print(f"  the relaxation itself is worth at most {res.relaxation_upper:.10g}")
    if report is None:
        return
    if report.how == "exact":
        print(f"policies, evaluated exactly (matrix-free, {approx_count(report.states)} states); upper = certified "
              "upper end:")
    else:
        r0 = report.rows[0].detail
        ctl = f", control variate: {r0['control']}" if r0.get("control") else ""
        print(f"policies, by Monte Carlo ({r0.get('reps')} x {r0.get('slots')} slots, seed {r0.get('seed')}{ctl}); "
              f"upper = one-sided {100 * r0.get('confidence', 0.95):g}% upper confidence limit, Student t over the "
              f"independent replications (the AoI box has {approx_count(report.states)} states, above "
              "--exact-max-states):")
    if tables_note:
        print(f"  {tables_note}")
    w = max(len("policy"), *(len(r.policy) for r in report.rows))
    print(f"  {'policy':<{w}} {'gain':>16} {'upper':>16} {'gap <=':>9}")
    for r in report.rows:
        print(f"  {r.policy:<{w}} {r.gain:>16.10g} {r.gain_upper:>16.10g} {100 * r.gap:>8.3f}%")
    for name, why in report.skipped:
        print(f"  {name}: not evaluated: {why}")
    print("  gap = (upper - lower bound) / lower bound, an upper bound on (g_pi - g*) / g*")
    print(f"  best: {report.best.policy} (the least upper value)")
    from ..intervals import AGREEMENT_LEVEL

    for r in report.rows:
        if r.detail.get("agreement", 1.0) < AGREEMENT_LEVEL:
            print(f"  WARNING: {r.policy}: its replications disagree more than their own batches allow (p = "
                  f"{r.detail['agreement']:.2g}): runs too short, or several recurrent classes; its limit is void")


def _configure(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--relaxation", default="auto", metavar="1|2|3|4|5|auto",
                   help="1 = private servers with averaged capacity (seconds at any number of processes), "
                        "2 = joint configuration with separable value functions (tighter, when installed), "
                        "3 = private servers shared by pairs of processes (relaxation 1 on groups), "
                        "4 = relaxation 2 with pairs of processes' ages kept jointly (tighter than 2, slower), "
                        "5 = every pair's ages kept jointly at once, its LP solved whole (tighter than 4; "
                        "small systems: its size is checked first), "
                        "auto = the largest certified bound of those that apply (default)")
    p.add_argument("--groups", default=None, metavar="1,5;2,6;...",
                   help="--relaxation 3 or 4: the groups of processes (1-based, ';' between groups; default: the "
                        "pairs that interact most at relaxation 1's multipliers (3), interchangeable processes "
                        "paired, else the best pairing at relaxation 2's prices (4))")
    p.add_argument("--tol", type=real_option(0.0, 1.0, lo_open=True, hi_open=True), default=1e-6,
                   help="relative tolerance of the multiplier search (default 1e-6); the bound is certified "
                        "whatever it is")
    p.add_argument("--max-steps", type=COUNT, default=None, metavar="N",
                   help="bundle steps of relaxation 2's search (default: 30 under auto, 1000 for --relaxation 2); "
                        "the bound is certified whatever stops it")
    p.add_argument("--time-limit", type=real_option(0.0), default=None, metavar="SECONDS",
                   help="seconds of relaxation 2's search at most (default: none under auto, whose interior point "
                        "runs only where predicted to fit and stops at a multiple of that prediction in CPU time; "
                        "600 for --relaxation 2); under auto it also replaces relaxation 3's guard (300 s of CPU) "
                        "by that many seconds of wall clock")
    p.add_argument("--policy", action="store_true",
                   help="also evaluate the bound's greedy policy and the --compare policies, with the certified "
                        "optimality gap of each")
    p.add_argument("--compare", default="lookahead,suboptimal,static,greedy", metavar="NAMES",
                   help="policies evaluated with --policy besides the bound's greedy one (default "
                        "lookahead,suboptimal,static,greedy; lookahead: the two-step lookahead on the bound's tables, "
                        "lookahead3: one step deeper; rollout: the bound's greedy policy simulated a few slots ahead "
                        "of each candidate action; index: the Whittle-type index policy of relaxation 1's chains; "
                        "tuned, tuned_lookahead, tuned_rollout: those on the tables reweighted per process type by a "
                        "simulation on --seed + 2; '' for none)")
    p.add_argument("--exact-max-states", type=NONNEGATIVE, default=50_000_000, metavar="N",
                   help="evaluate exactly (certified matrix-free evaluation) when the AoI box has at most N states, "
                        "else by Monte Carlo (default 50000000; 0: always Monte Carlo)")
    p.add_argument("--untruncated", action="store_true",
                   help="also simulate the policies evaluated (the bound's alone without --policy) without the AoI "
                        "cap: the least upper confidence limit is an upper end on the untruncated optimum, the bound its "
                        "lower end (docs/model.md)")
    add_simulation_args(p, "Monte Carlo")
    p.add_argument("--no-control-variate", action="store_true",
                   help="Monte Carlo: the plain time average, without the bound's tables as control variate")
    add_threads_arg(p)
    add_progress_arg(p)


COMMANDS = [
    Command("bound", "a certified lower bound on the optimal cost for any number of processes, and the certified "
            "optimality gap of the bound's policy and of the baselines", _configure, cmd_bound),
]

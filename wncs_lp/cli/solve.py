"""``wncs-lp solve``: build the MDP and solve it with a certificate (constrained when the scenario has bounds)."""
from __future__ import annotations

import argparse
import time

from ..methods import DEFAULT_METHOD, METHOD_HELP
from .common import (SOLVE_METHODS, Command, add_progress_arg, add_scenario_args, add_simulation_args, add_threads_arg,
                     emit_json, head, load, output_file, progress_for, real_option, solution_json,
                     write_after_work)


def _matrix_free(args: argparse.Namespace, scenario, run, t0: float) -> int:
    """A solve without a stored matrix (:mod:`wncs_lp.solvers.matrix_free`): asked for, or auto's fallback."""
    from ..solvers.matrix_free import matrix_free_cap_mass
    from ..truncation import CAP_COUNT_ATOL, CapCount

    sol = run.solution
    prog = progress_for(args)
    prog.phase("measuring the optimal policy's time at the AoI cap (a certified matrix-free evaluation)")
    t_cap = time.perf_counter()
    cap = CapCount.of(matrix_free_cap_mass(sol.system, sol, atol=CAP_COUNT_ATOL, threads=args.threads,
                                             progress=prog), sol.system)
    t_cap = time.perf_counter() - t_cap
    interval = _untruncated(args, sol, None, prog)
    failed = None
    if args.out is not None:  # one byte a state: wncs_lp.solvers.matrix_free.load_solution reads it back
        prog.phase(f"writing the policy to {args.out}")
        _, failed = write_after_work(lambda: sol.save(args.out), args.out)
    payload = {**head(args, scenario), "states": int(sol.stats.get("n_states", sol.bias.size)),
               **solution_json(sol), "cap_mass": cap.to_dict(), "untruncated": interval.to_dict(),
               "matrix_free_reason": run.route, "solve_seconds": sol.seconds, "cap_mass_seconds": t_cap,
               "seconds": time.perf_counter() - t0}
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"method matrix-free ({run.route}): status {sol.status}, {sol.iterations} sweeps, {sol.seconds:.2f} s")
        print(f"optimal average cost (gain): {sol.gain:.10g}")
        print(f"certificate: {sol.gain_lower:.12g} <= g* <= {sol.gain_upper:.12g} (relative width {sol.gap:.2e})")
        print(f"truncation: under the optimal policy {cap.message()} (measured in {t_cap:.2f} s)")
        print(_interval_line(interval))
    return _write_failed(failed) or (0 if sol.ok else 1)


#: The policies simulated without the cap beside the optimal one (``--untruncated``): a policy optimal
#: at a small cap can starve a process past the cap, where its cost stops growing.
UNTRUNCATED_BASELINES = ("greedy", "max_age", "max_weight", "round_robin")


def _untruncated(args: argparse.Namespace, sol, mdp, prog):
    """The interval for the optimum without the cap: the certified lower end always; with
    ``--untruncated`` the optimal policy and the field's baselines simulated without the cap, the
    least upper confidence limit for the upper end."""
    from ..policies import as_policy
    from ..workflow import make_policy
    from ..untruncated import untruncated_interval

    if not args.untruncated:
        return untruncated_interval(sol.gain_lower, lower_from="the certified truncated optimum")
    optimal = as_policy(sol, mdp, name="optimal")
    candidates = [optimal, *(make_policy(n, optimal.system) for n in UNTRUNCATED_BASELINES)]
    prog.phase(f"simulating the optimal policy and {', '.join(UNTRUNCATED_BASELINES)} without the AoI cap ({args.reps} "
               f"x {args.slots} slots each, seed {args.seed})")
    return untruncated_interval(sol.gain_lower, candidates, lower_from="the certified truncated optimum",
                                slots=args.slots, reps=args.reps, seed=args.seed, burn_in=args.burn_in)


def _interval_line(interval) -> str:
    tail = "" if interval.candidates or interval.note else " (--untruncated simulates policies without the cap for one)"
    return interval.message() + tail


def _write_failed(message: str | None) -> int:
    """2 after printing ``error: message`` when writing the finished result failed, else 0."""
    if message is None:
        return 0
    import sys

    print(f"error: {message}", file=sys.stderr)
    return 2


def cmd_solve(args: argparse.Namespace) -> int:
    from ..workflow import run_scenario

    if args.dry_run:  # what wncs-lp validate says: the checks and the size, nothing built
        from .validate import cmd_validate

        args.list = False
        return cmd_validate(args)
    if args.discount is not None:
        return _discounted(args)
    if args.out is not None:
        output_file(args.out, "--out")  # before any work: its folder must exist
    scenario = load(args)
    prog = progress_for(args)
    t0 = time.perf_counter()
    run = run_scenario(scenario, args.method, constrained=False if args.ignore_constraints else None,
                         force=args.force, threads=args.threads, progress=prog)
    if not run.built:
        return _matrix_free(args, scenario, run, t0)
    if run.constrained:
        return _constrained(args, scenario, run, t0, prog)
    return _unconstrained(args, scenario, run, t0, prog)


def _unconstrained(args: argparse.Namespace, scenario, run, t0: float, prog) -> int:
    from ..truncation import policy_cap_mass

    mdp, sol, t_build = run.mdp, run.solution, run.build_seconds
    prog.phase("measuring the optimal policy's time at the AoI cap")
    cap = policy_cap_mass(mdp, sol.policy)
    interval = _untruncated(args, sol, mdp, prog)
    extra, failed = {}, None
    if args.out is not None:
        saved, failed = write_after_work(lambda: _save(args, scenario, mdp, sol, prog), args.out)
        extra = {"out": str(saved)} if failed is None else {"out_error": failed}
    if args.json:
        emit_json(_payload(args, scenario, mdp, sol, cap, t0, t_build, untruncated=interval.to_dict(), **extra))
        return _write_failed(failed) or (0 if sol.ok else 1)
    _header(scenario, mdp, t_build)
    used = f"{sol.method} -> {sol.stats['auto_choice']}" if "auto_choice" in sol.stats else sol.method
    print(f"method {used}: status {sol.status}, {sol.iterations} iterations, {sol.seconds:.2f} s")
    if not sol.ok:
        print(f"  ({sol.message})")
    print(f"optimal average cost (gain): {sol.gain:.10g}")
    print(f"certificate: {sol.gain_lower:.12g} <= g* <= {sol.gain_upper:.12g} (relative width {sol.gap:.2e})")
    if "auto_choice" in sol.stats:
        _print_auto(sol.stats)
    print(f"truncation: under the optimal policy {cap.message()}")
    print(_interval_line(interval))
    if "out" in extra:
        print(f"policy and bias written to {extra['out']} (format: see wncs_lp.io.npz)")
    return _write_failed(failed) or (0 if sol.ok else 1)


def _discounted(args: argparse.Namespace) -> int:
    """``--discount BETA``: the discounted problem through the one route, certified
    (:mod:`wncs_lp.solvers.discounted`; ``--method`` read by :data:`wncs_lp.methods.DISCOUNTED_FOR`)."""
    from ..io import initial_state
    from ..workflow import run_scenario

    scenario = load(args)
    t0 = time.perf_counter()
    run = run_scenario(scenario, args.method, discount=args.discount,
                       constrained=False if args.ignore_constraints else None, force=args.force,
                       progress=progress_for(args))
    mdp, d, t_build = run.mdp, run.solution, run.build_seconds
    s0 = initial_state(mdp)
    payload = {**head(args, scenario, mdp), "criterion": "discounted", "beta": d.beta, "method": d.method,
               "status": d.status, "gap": d.gap, "initial_state": mdp.state_label(s0),
               "value_initial": float(d.value[s0]), "lower_initial": float(d.lower[s0]),
               "value_min": float(d.value.min()), "value_max": float(d.value.max()), "iterations": d.iterations,
               "build_seconds": t_build, "seconds": time.perf_counter() - t0}
    if args.json:
        emit_json(payload)
    else:
        _header(scenario, mdp, t_build)
        print(f"discounted (beta = {d.beta:g}) by {d.method}: status {d.status}, {d.iterations} iterations")
        print(f"value from the initial state {payload['initial_state']}: {d.value[s0]:.10g} "
              f"(certified: {d.lower[s0]:.10g} <= v*, gap in any state {d.gap:.2e})")
        print(f"(1 - beta) v over the states: {(1 - d.beta) * d.value.min():.8g} .. {(1 - d.beta) * d.value.max():.8g} "
              "(-> the average cost g* as beta -> 1)")
    return 0 if d.status == "optimal" else 1


def _print_auto(st: dict) -> None:
    print(f"auto: chose {st['auto_choice']} ({st['auto_reason']})")
    if st.get("cross_check_method"):
        verdict = {True: "agrees", False: "DISAGREES", None: "failed"}[st.get("cross_check_agree")]
        diff = f", relative difference {st['cross_check_rel_diff']:.2e}" if "cross_check_rel_diff" in st else ""
        print(f"cross-check with {st['cross_check_method']}: {verdict}{diff}")


def _save(args: argparse.Namespace, scenario, mdp, sol, prog):
    from ..io import save_solution_npz

    prog.phase(f"writing the policy and the bias to {args.out}")
    return save_solution_npz(args.out, mdp, sol, scenario=scenario)


def _payload(args: argparse.Namespace, scenario, mdp, sol, cap, t0: float, t_build: float, **extra) -> dict:
    """The JSON of a solve: the head, the solution's summary, the mass at the cap, the timings."""
    return {**head(args, scenario, mdp), "nnz": int(mdp.P.nnz), **solution_json(sol), **extra,
            "cap_mass": cap.to_dict(),
            "build_seconds": t_build, "solve_seconds": sol.seconds, "seconds": time.perf_counter() - t0}


def _header(scenario, mdp, t_build: float) -> None:
    print(scenario.describe())
    print(f"MDP: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs, built in {t_build:.2f} s")


def _constrained(args: argparse.Namespace, scenario, run, t0: float, prog) -> int:
    from ..truncation import cap_mass

    mdp, sol, t_build = run.mdp, run.solution, run.build_seconds
    cap = cap_mass(mdp, sol.occupation)
    extra, failed = {}, None
    if args.out is not None:
        saved, failed = write_after_work(lambda: _save(args, scenario, mdp, sol, prog), args.out)
        extra = {"out": str(saved)} if failed is None else {"out_error": failed}
    if args.json:
        emit_json(_payload(args, scenario, mdp, sol, cap, t0, t_build, mixes=sol.mixes(mdp), **extra))
        return _write_failed(failed) or (0 if sol.ok else 1)
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
    if "out" in extra:
        print(f"policy written to {extra['out']} (format: see wncs_lp.io.npz)")
    return _write_failed(failed) or (0 if sol.ok else 1)


def _configure_solve(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        choices=SOLVE_METHODS,
        help=METHOD_HELP + "; matrix-free: certified value iteration without building the MDP (Section II "
        "model; auto switches to it when the stored matrix would not fit in memory); and for a scenario with "
        "[[constraint]] tables: auto, lp, lp-cvxpy or lagrangian (one bound: multiplier search with certified "
        "value iteration)",
    )
    p.add_argument("--dry-run", action="store_true",
                   help="check the scenario and print the size of its MDP and the memory a solve needs, as wncs-lp "
                        "validate does; build and solve nothing")
    p.add_argument("--discount", type=real_option(0.0, 1.0, hi_open=True), default=None, metavar="BETA",
                   help="solve the discounted problem with this discount factor in [0, 1) instead of the average "
                        "cost (--method auto/pi: policy iteration, vi/rvi: value iteration, lp/lp-highs: the LP on "
                        "HiGHS; certified by MacQueen's bounds)")
    p.add_argument("--ignore-constraints", action="store_true",
                   help="solve the unconstrained problem even if the scenario has [[constraint]] tables")
    p.add_argument("--out", default=None, metavar="FILE.npz",
                   help="also write the optimal policy and the bias (and the action per state, the state decoding "
                        "and the certificate) to this .npz file, in an existing folder; numpy.load reads it "
                        "(format: wncs_lp.io.save_solution_npz); with the matrix-free method, its policy (one "
                        "byte a state) and certificate, read back by wncs_lp.solvers.matrix_free.load_solution")
    p.add_argument("--untruncated", action="store_true",
                   help="also simulate the optimal policy and the baselines greedy, max_age, max_weight, round_robin "
                        "without the AoI cap (each sees the capped AoI, the true AoI is charged): the least upper "
                        "confidence limit is an upper end on the untruncated optimum, the certified truncated optimum "
                        "its lower end (docs/model.md)")
    add_simulation_args(p, "--untruncated")
    add_threads_arg(p)
    add_progress_arg(p)


COMMANDS = [
    Command("solve", "build the MDP and solve it to optimality, with a certificate (constrained when the "
            "scenario has [[constraint]] tables)", _configure_solve, cmd_solve),
]

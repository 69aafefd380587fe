"""``wncs-lp evaluate``, ``simulate`` and ``sweep``: policies, exactly, by simulation, over a grid."""
from __future__ import annotations

import argparse
import sys

from .common import (COUNT, NONNEGATIVE, SEED, SLOTS, Command, add_method_arg, add_parallel_args, add_progress_arg,
                     add_scenario_args, add_threads_arg, emit_json, executor_of, head, load, output_folder, progress_for)


def _add_policy_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument(
        "--policy",
        required=required,
        metavar="NAME|FILE.npz",
        help="a policy saved by wncs-lp solve --out FILE.npz (on the same scenario and overrides), or by name: "
        "optimal (solved exactly), suboptimal (the paper's separable policy), static (one fixed server per "
        "process), best_static (the best static assignment, by exact evaluation), greedy (the process of largest "
        "current cost first, to its shortest-loop server), random (uniform over the feasible actions), max_age "
        "(the process of largest AoI first), max_weight (the process whose update removes the most expected cost "
        "first), round_robin (the processes in turn; a policy with memory), relaxation (the greedy policy of the "
        "certified lower bound), lookahead (the two-step lookahead on the bound's tables) or index (the "
        "Whittle-type index policy of relaxation 1's priced chains); docs/policies.md",
    )
    add_method_arg(p, "solver of the optimal policy")
    p.add_argument(
        "--assignment",
        default=None,
        metavar="SERVERS",
        help="static policy: one server per process, by name or 1-based index, e.g. remote,edge "
        "(default: the paper's: the largest process to the server with its shortest loop U + T + D, every "
        "other process to the other server(s); docs/policies.md)",
    )
    add_threads_arg(p)
    add_progress_arg(p)


def _policy(args: argparse.Namespace, scenario, *, need_mdp: bool, prog=False):
    from ..workflow import policy_for

    if args.policy.lower().endswith(".npz"):
        return _policy_file(args, scenario, prog)
    return policy_for(scenario, args.policy, method=args.method, assignment=args.assignment,
                      need_mdp=need_mdp, force=args.force, threads=args.threads, progress=prog)


def _policy_file(args: argparse.Namespace, scenario, prog):
    """A policy saved by ``wncs-lp solve --out FILE.npz``, on the scenario's MDP (built here)."""
    import time

    from ..io import policy_from_file
    from ..policies import PolicySetup
    from ..solvers.route import build_scenario

    t0 = time.perf_counter()
    mdp, _ = build_scenario(scenario, force=args.force, progress=prog)
    prog.phase(f"reading the policy of {args.policy}")
    policy = policy_from_file(args.policy, mdp)
    return PolicySetup(system=policy.system, mdp=mdp, policy=policy, seconds=time.perf_counter() - t0)


def _solve_label(made) -> tuple[dict, str | None]:
    """The status of the solve an ``optimal`` policy comes from, for the payload, and the line
    saying it is not certified (None when it is, or when no solve made the policy): the label
    "optimal" is earned only where the certificate closed, as for ``wncs-lp solve``."""
    status = getattr(made, "status", None)
    if status is None:
        return {}, None
    from ..status import as_status

    st = as_status(status)
    line = None if st.ok else (f"note: the solve of the {made.policy.name} policy is not certified (status {st}: "
                               f"{st.message}); the numbers below are this policy's, not a certified optimum's")
    return {"policy_status": str(st), "policy_certified": bool(st.ok)}, line


# ----------------------------------------------------------------------------- evaluate
def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..errors import PolicyError
    from ..evaluate import MultichainEvaluationError, evaluate
    from ..models.guard import SizeLimitError

    scenario = load(args)
    prog = progress_for(args)
    try:
        made = _policy(args, scenario, need_mdp=True, prog=prog)
    except SizeLimitError as refused:  # as solve's auto: the certified matrix-free evaluation, no matrix stored
        if args.policy.lower().endswith(".npz"):
            raise
        return _evaluate_matrix_free(args, scenario, prog, refused)
    mdp, policy = made.mdp, made.policy
    label, note = _solve_label(made)
    prog.phase(f"evaluating the {policy.name} policy exactly (its chain's stationary law)")
    try:
        ev = evaluate(mdp, policy, multichain="initial" if args.from_initial else "error", method=args.stationary,
                      certify=args.certify)
    except MultichainEvaluationError as exc:
        raise PolicyError(f"{exc.detail} (rerun with --from-initial for the averages from the initial state)") from None
    transient = _transient(args, mdp, policy, prog) if args.horizon is not None else None
    payload = {
        **head(args, scenario, mdp),
        **ev.to_dict(),
        "policy_info": policy.describe(),
        **label,
        "setup_seconds": made.seconds,
    }
    if transient is not None:
        payload["transient"] = {"policy": transient[0].to_dict(), "finite_horizon_optimum": transient[1].to_dict()}
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"MDP: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs")
        if note:
            print(note)
        print(f"policy {ev.policy}: average cost (gain) {ev.gain:.10g}")
        if args.certify:
            print(f"certificate: {ev.gain_lower:.12g} <= g_pi <= {ev.gain_upper:.12g} (certified value iteration of "
                  "the policy's chain)")
        for name, v in zip(ev.process_names, ev.mse):
            print(f"  {name}: average MSE {v:.8g}")
        for name, v in zip(ev.server_names, ev.utilisation):
            print(f"  server {name}: utilisation {v:.4f}")
        if ev.recurrent_classes > 1:
            print(f"  (multichain: {ev.recurrent_classes} recurrent classes; averages from the initial state)")
        if ev.cap_mass is not None:
            print(f"truncation: under the {ev.policy} policy {ev.cap_mass.message()}")
        if "base_gain" in payload["policy_info"]:
            print(f"  base (random) policy gain sum_k g_k = {payload['policy_info']['base_gain']:.10g}")
        if transient is not None:
            tr, best = transient
            print(f"first {tr.horizon} slots from {tr.start}: expected cost {tr.total:.10g} (average "
                  f"{tr.average:.8g} a slot) under {tr.policy}; the finite-horizon optimum {best.total:.10g} (average {best.average:.8g})")
    return 0 if note is None else 1


def _transient(args: argparse.Namespace, mdp, policy, prog):
    """``--horizon T``: the policy's expected cost over the first T slots and the finite-horizon
    optimum's, from ``--start`` (default: every AoI at its cap, servers idle)."""
    from ..errors import WncsError
    from ..transient import transient_cost

    start = None
    if args.start is not None:
        try:
            start = tuple(int(x) for x in args.start.split(","))
        except ValueError:
            raise WncsError(f"--start {args.start!r}: expected one AoI per process, e.g. 1,1") from None
    prog.phase(f"the expected cost over the first {args.horizon} slots (exact recursions)")
    return transient_cost(mdp, policy, args.horizon, start), transient_cost(mdp, "optimal", args.horizon, start)


def _evaluate_matrix_free(args: argparse.Namespace, scenario, prog, refused) -> int:
    """``evaluate`` where the stored matrix would not fit: the certified matrix-free evaluation of
    the policy and of its time at the cap (round robin: exact on its per-process chains)."""
    from ..errors import PolicyError
    from ..solvers.matrix_free import matrix_free_cap_mass, matrix_free_evaluate
    from ..truncation import CAP_COUNT_ATOL, CapCount

    for flag, given in (("--from-initial", args.from_initial), ("--horizon", args.horizon is not None)):
        if given:
            raise PolicyError(f"{flag} needs the enumerated MDP, which would not fit here: {refused}") from None
    why = "the stored matrix would not fit in memory"
    prog.phase(f"{why}: evaluating without it")
    made = _policy(args, scenario, need_mdp=False, prog=prog)
    policy, system = made.policy, made.system
    label, note = _solve_label(made)
    if hasattr(policy, "separable_evaluation"):
        prog.phase(f"evaluating the {policy.name} policy exactly on its per-process chains")
        ev = policy.separable_evaluation()
        out = {"how": "separable", "gain": ev.gain, "gain_lower": ev.gain, "gain_upper": ev.gain, "mse": list(ev.mse),
               "utilisation": list(ev.utilisation), "status": "optimal", "states": ev.n_states}
        cap = None
    else:
        prog.phase(f"evaluating the {policy.name} policy exactly (certified matrix-free evaluation)")
        ev = matrix_free_evaluate(system, policy, threads=args.threads, progress=prog, name=policy.name)
        out = {"how": "matrix-free", "gain": ev.gain, "gain_lower": ev.gain_lower, "gain_upper": ev.gain_upper,
               "status": ev.status, "iterations": ev.iterations, "states": int(ev.stats.get("n_states", ev.bias.size))}
        prog.phase(f"measuring the {policy.name} policy's time at the AoI cap (certified matrix-free evaluation)")
        cap = CapCount.of(matrix_free_cap_mass(system, policy, atol=CAP_COUNT_ATOL, threads=args.threads,
                                                 progress=prog), system)
    payload = {**head(args, scenario), "policy": policy.name, "route": why, **out,
               "cap_mass": None if cap is None else cap.to_dict(), "policy_info": policy.describe(), **label,
               "setup_seconds": made.seconds}
    code = 0 if out["status"] == "optimal" and note is None else 1
    if args.json:
        emit_json(payload)
        return code
    print(scenario.describe())
    print(f"no MDP built ({why}); {out['how']} evaluation over {out['states']:,} states")
    if note:
        print(note)
    print(f"policy {policy.name}: average cost (gain) {out['gain']:.10g}")
    if out["how"] == "separable":
        for name, v in zip([p.name for p in scenario.processes], out["mse"]):
            print(f"  {name}: average MSE {v:.8g}")
        for name, v in zip([s.name for s in scenario.servers], out["utilisation"]):
            print(f"  server {name}: utilisation {v:.4f}")
    else:
        print(f"certificate: {out['gain_lower']:.12g} <= g_pi <= {out['gain_upper']:.12g} (status {out['status']})")
        print(f"truncation: under the {policy.name} policy {cap.message()}")
    return code


def _configure_evaluate(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    _add_policy_args(p)
    p.add_argument(
        "--from-initial",
        action="store_true",
        help="for a multichain policy, report the averages from the initial state instead of failing",
    )
    p.add_argument("--stationary", default="auto", choices=("auto", "lu", "iterative"),
                   help="how the stationary law is solved: a sparse LU, BiCGSTAB (residual checked), or auto: the LU "
                        "for recurrent classes under 1,000 states, BiCGSTAB above (benchmarks/evaluation.py)")
    p.add_argument("--certify", action="store_true",
                   help="also bracket the gain by the certified value iteration of the policy's chain")
    p.add_argument("--horizon", type=COUNT, default=None, metavar="T",
                   help="also the expected cost over the first T slots (the policy's, and the finite-horizon "
                        "optimum's), by exact recursion on the enumerated MDP")
    p.add_argument("--start", default=None, metavar="TAU",
                   help="--horizon: the AoI vector to start from, servers idle (e.g. 1,1; default: every AoI at its "
                        "cap)")


# ----------------------------------------------------------------------------- simulate
def cmd_simulate(args: argparse.Namespace) -> int:
    from ..simulate import simulate

    scenario = load(args)
    prog = progress_for(args)
    made = _policy(args, scenario, need_mdp=False, prog=prog)
    policy = made.policy
    label, note = _solve_label(made)
    control = None
    if args.control_variate:
        from ..bounds import lower_bound

        prog.phase("relaxation 1's value tables, for the control variate")
        control = lower_bound(made.system, 1).tables
    res = simulate(policy, slots=args.slots, reps=args.reps, seed=args.seed, burn_in=args.burn_in, control=control,
                   progress=prog.enabled)
    payload = {
        **head(args, scenario),
        "configs": made.system.n_configs,
        **res.to_dict(),
        "policy_info": policy.describe(),
        **label,
        "setup_seconds": made.seconds,
    }
    if args.json:
        emit_json(payload)
    else:
        _print_simulation(scenario, res, note)
    return 0 if note is None else 1


def _print_simulation(scenario, res, note: str | None = None) -> None:
    from ..intervals import AGREEMENT_LEVEL

    print(scenario.describe())
    if note:
        print(note)
    print(f"policy {res.policy}: {res.reps} replications x {res.slots} slots (burn-in {res.burn_in}, seed {res.seed})")
    two, up = res.interval(0.95, "two-sided"), res.interval(0.95, "upper")  # batch means for one replication
    print(f"average cost {res.mean:.8g} +- {two.stderr:.3g} (standard error, {two.method}), {res.seconds:.2f} s")
    print(f"  95% confidence interval [{two.lower:.8g}, {two.upper:.8g}]; one-sided 95% upper limit "
          f"{up.upper:.8g} (Student t, {up.df} df{'' if two.independent else '; the batches are still correlated: longer runs needed'})")
    if res.control is not None:
        print(f"  control variate: relaxation 1's value tables, beta = {res.control_coef:.4g} (variance / "
              f"{res.variance_reduction:.3g}; the plain average {res.plain_mean:.8g} +- {res.plain_stderr:.3g})")
    if res.agreement < AGREEMENT_LEVEL:
        print(f"  WARNING: the replications disagree more than their own batches allow (p = {res.agreement:.2g}): "
              "runs too short for the chain, or a policy with several recurrent classes; no interval holds")
    aoi = res.aoi
    q = aoi.quantile([0.5, 0.99])
    for k, (name, v) in enumerate(zip([p.name for p in scenario.processes], res.process_means)):
        print(f"  {name}: average MSE {v:.8g}; AoI mean {aoi.mean()[k]:.4g}, median {q[k, 0]}, 99% quantile "
              f"{q[k, 1]}, at the cap ({aoi.caps[k]}) {100 * aoi.at_cap[k]:.2f}% of slots")


def _configure_simulate(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    _add_policy_args(p)
    p.add_argument("--slots", type=SLOTS, default=40_000, help="slots averaged per replication (default 40000)")
    p.add_argument("--reps", type=COUNT, default=20, help="independent replications (default 20)")
    p.add_argument("--seed", type=SEED, default=0, help="random seed, a whole number >= 0 (default 0)")
    p.add_argument("--burn-in", type=NONNEGATIVE, default=1000, help="slots discarded first (default 1000)")
    p.add_argument("--control-variate", action="store_true",
                   help="average the Bellman residual of relaxation 1's value tables instead of the cost: the same "
                        "expectation, usually a far smaller variance (docs/simulation.md)")


# ----------------------------------------------------------------------------- sweep
def cmd_sweep(args: argparse.Namespace) -> int:
    from ..studies import run_sweep

    output_folder(args.out)  # before any work
    scenario = load(args)
    show = args.progress if args.progress is not None else not args.json  # a line per row, [done/total, ETA]
    log = (lambda line: print(line, file=sys.stderr, flush=True)) if show else None
    res = run_sweep(
        scenario,
        args.param,
        args.values,
        args.policies,
        args.out,
        method=args.method,
        force=args.force,
        exact=not args.no_exact,
        simulate_slots=args.simulate_slots,
        reps=args.reps,
        seed=args.seed,
        burn_in=args.burn_in,
        max_workers=args.max_workers,
        executor=executor_of(args),
        threads=args.threads,
        plot=not args.no_plot,
        log=log,
    )
    if res.dropped and log is None:  # else the log said so
        from .common import warn

        warn(f"{res.dropped} row(s) of {args.out}/sweep.csv were not this sweep's (fingerprint): not reused")
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "param": args.param,
        "rows": res.table(),
        "files": res.files,
        "computed": res.computed,
        "reused": res.reused,
        "seconds": res.seconds,
    }
    if args.json:
        emit_json(payload)
    else:
        name = res.rows[0].value_column if res.rows else args.param
        width = max(8, len(name))
        print(f"{name:>{width}} {'policy':<12} {'gain':>14} {'sim mean':>14} {'stderr':>9} {'seconds':>8}  status")
        for r in res.rows:
            g = "" if r.gain != r.gain else f"{r.gain:.8g}"
            m = "" if r.sim_mean != r.sim_mean else f"{r.sim_mean:.8g}"
            e = "" if r.sim_stderr != r.sim_stderr else f"{r.sim_stderr:.3g}"
            print(f"{r.value:>{width}g} {r.policy:<12} {g:>14} {m:>14} {e:>9} {r.seconds:>8.2f}  {r.status}")
        print(f"{res.computed} rows computed, {res.reused} reused; files: {', '.join(res.files.values())}")
    bad = [r for r in res.rows if r.status.startswith("error")]
    return 1 if bad else 0


def _configure_sweep(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--param", default="p", help="override key to sweep (default p)")
    p.add_argument("--values", required=True, help="START:STOP:STEP (stop included) or a comma list")
    p.add_argument("--policies", default="optimal,suboptimal,static,greedy",
                   help="comma list from optimal,suboptimal,static,best_static,greedy,random,relaxation,max_age,"
                        "max_weight,round_robin (docs/policies.md)")
    p.add_argument("--out", required=True, help="output folder (resumed when it holds rows)")
    add_method_arg(p, "solver of the optimal policy at every grid value")
    p.add_argument("--simulate-slots", type=NONNEGATIVE, default=0,
                   help="also simulate each policy for this many slots (default 0: no simulation)")
    p.add_argument("--reps", type=COUNT, default=20, help="replications when simulating (default 20)")
    p.add_argument("--seed", type=SEED, default=0, help="simulation seed, a whole number >= 0 (default 0)")
    p.add_argument("--burn-in", type=NONNEGATIVE, default=1000, help="simulation burn-in (default 1000)")
    p.add_argument("--no-exact", action="store_true", help="no exact evaluation (simulate only; needs --simulate-slots)")
    add_parallel_args(p, "grid values")
    add_threads_arg(p)
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="one line on stderr per finished row, with the rows done, the time elapsed and an ETA "
                        "(default: on without --json)")
    p.add_argument("--no-plot", action="store_true", help="do not write sweep.png / sweep.svg")


COMMANDS = [
    Command("evaluate", "evaluate a policy exactly (stationary distribution of the enumerated MDP; certified "
            "matrix-free evaluation when the stored matrix would not fit)",
            _configure_evaluate, cmd_evaluate),
    Command("simulate", "Monte Carlo simulation of a policy from the configuration automaton",
            _configure_simulate, cmd_simulate),
    Command("sweep", "sweep one parameter for several policies: CSV/JSON table (resumable) and figure",
            _configure_sweep, cmd_sweep),
]

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
    p.add_argument("--force", action="store_true",
                   help="build even when the size guard estimates more memory than the machine has available")


def load(args: argparse.Namespace):
    from .scenario import load_scenario

    return load_scenario(args.scenario, args.overrides)


def build(scenario, args: argparse.Namespace | None = None, need_lp: bool = False):
    """Build the MDP after the size guard (refuses huge builds unless ``--force``)."""
    from .guard import check_size
    from .models import build as _build

    check_size(scenario, force=bool(getattr(args, "force", False)), need_lp=need_lp)
    return _build(scenario)


# ----------------------------------------------------------------------------- solve
def cmd_solve(args: argparse.Namespace) -> int:
    from .solvers import solve

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build(scenario, args)
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
        default="auto",
        choices=["auto", "lp", "lp-cvxpy", "rvi", "vi", "pi"],
        help="auto: LP or value iteration by size, cross-checked when both are cheap (says which); "
        "lp: occupation-measure LP on Clarabel (direct); lp-cvxpy: same LP through cvxpy; "
        "rvi: relative value iteration; vi: certified value iteration on the fused kernel; "
        "pi: policy iteration (default: auto)",
    )


subcommand("solve", "build the MDP and solve it to optimality, with a certificate", _configure_solve)(cmd_solve)


# ----------------------------------------------------------------------------- policies
def _add_policy_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument(
        "--policy",
        required=required,
        metavar="NAME",
        help="optimal, suboptimal, static, best_static, greedy or random",
    )
    p.add_argument(
        "--method",
        default="pi",
        choices=["lp", "lp-cvxpy", "rvi", "pi"],
        help="solver of the optimal policy (default: pi; pi falls back to rvi on a multichain iterate)",
    )
    p.add_argument(
        "--assignment",
        default=None,
        metavar="SERVERS",
        help="static policy: one server per process, by name or 1-based index, e.g. remote,edge "
        "(default: the paper's assignment, see policies.md)",
    )


def _parse_assignment(text: str | None, scenario) -> list[int] | None:
    from .errors import PolicyError

    if text is None:
        return None
    names = [s.name for s in scenario.servers]
    out = []
    for item in (x.strip() for x in text.split(",")):
        if item.isdigit() and 1 <= int(item) <= len(names):
            out.append(int(item) - 1)
        elif item in names:
            out.append(names.index(item))
        else:
            raise PolicyError(f"--assignment: {item!r} is not a server; expected a name from {names} or 1..{len(names)}")
    return out


def _make_cli_policy(args: argparse.Namespace, scenario):
    """Build the system, the MDP when the policy needs it, and the policy. Returns a dict."""
    from .policies import POLICY_NAMES, System, make_policy

    from .errors import PolicyError

    if args.policy not in POLICY_NAMES:
        raise PolicyError(f"unknown policy {args.policy!r}; expected one of {', '.join(POLICY_NAMES)}")
    t0 = time.perf_counter()
    system = System.from_scenario(scenario)
    mdp = None
    if args.policy in ("optimal", "best_static") or getattr(args, "need_mdp", False):
        mdp = build(scenario, args)
    policy = make_policy(args.policy, system, mdp, method=args.method,
                         assignment=_parse_assignment(args.assignment, scenario))
    return {"system": system, "mdp": mdp, "policy": policy, "seconds": time.perf_counter() - t0}


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate

    scenario = load(args)
    args.need_mdp = True
    made = _make_cli_policy(args, scenario)
    mdp, policy = made["mdp"], made["policy"]
    ev = evaluate(mdp, policy, multichain="initial" if args.from_initial else "error")
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "kind": scenario.model.kind,
        "states": mdp.n_states,
        "pairs": mdp.n_pairs,
        **ev.to_dict(),
        "policy_info": policy.describe(),
        "setup_seconds": made["seconds"],
    }
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"MDP: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs")
        print(f"policy {ev.policy}: average cost (gain) {ev.gain:.10g}")
        for name, v in zip(ev.process_names, ev.mse):
            print(f"  {name}: average MSE {v:.8g}")
        for name, v in zip(ev.server_names, ev.utilisation):
            print(f"  server {name}: utilisation {v:.4f}")
        if ev.recurrent_classes > 1:
            print(f"  (multichain: {ev.recurrent_classes} recurrent classes; averages from the initial state)")
        if "base_gain" in payload["policy_info"]:
            print(f"  base (random) policy gain sum_k g_k = {payload['policy_info']['base_gain']:.10g}")
    return 0


def _configure_evaluate(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    _add_policy_args(p)
    p.add_argument(
        "--from-initial",
        action="store_true",
        help="for a multichain policy, report the averages from the initial state instead of failing",
    )


subcommand("evaluate", "evaluate a policy exactly (stationary distribution of the enumerated MDP)",
           _configure_evaluate)(cmd_evaluate)


def cmd_simulate(args: argparse.Namespace) -> int:
    from .simulate import simulate

    scenario = load(args)
    args.need_mdp = False
    made = _make_cli_policy(args, scenario)
    policy = made["policy"]
    progress = False if (args.no_progress or args.json and not sys.stderr.isatty()) else None
    res = simulate(policy, slots=args.slots, reps=args.reps, seed=args.seed, burn_in=args.burn_in, progress=progress)
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "kind": scenario.model.kind,
        "configs": made["system"].n_configs,
        **res.to_dict(),
        "policy_info": policy.describe(),
        "setup_seconds": made["seconds"],
    }
    if args.json:
        emit_json(payload)
    else:
        print(scenario.describe())
        print(f"policy {res.policy}: {res.reps} replications x {res.slots} slots (burn-in {res.burn_in}, seed {res.seed})")
        print(f"average cost {res.mean:.8g} +- {res.stderr:.3g} (standard error), {res.seconds:.2f} s")
        for name, v in zip([p.name for p in scenario.processes], res.process_means):
            print(f"  {name}: average MSE {v:.8g}")
    return 0


def _configure_simulate(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    _add_policy_args(p)
    p.add_argument("--slots", type=int, default=40_000, help="slots averaged per replication (default 40000)")
    p.add_argument("--reps", type=int, default=20, help="independent replications (default 20)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--burn-in", type=int, default=1000, help="slots discarded first (default 1000)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


subcommand("simulate", "Monte Carlo simulation of a policy from the configuration automaton",
           _configure_simulate)(cmd_simulate)


def cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import run_sweep

    scenario = load(args)
    log = None if args.json else (lambda line: print(line, file=sys.stderr, flush=True))
    res = run_sweep(
        scenario,
        args.param,
        args.values,
        args.policies,
        args.out,
        method=args.method,
        exact=not args.no_exact,
        simulate_slots=args.simulate_slots,
        reps=args.reps,
        seed=args.seed,
        burn_in=args.burn_in,
        max_workers=args.max_workers,
        executor=args.executor,
        plot=not args.no_plot,
        log=log,
    )
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
        print(f"{'value':>8} {'policy':<12} {'gain':>14} {'sim mean':>14} {'stderr':>9} {'seconds':>8}  status")
        for r in res.rows:
            g = "" if r.gain != r.gain else f"{r.gain:.8g}"
            m = "" if r.sim_mean != r.sim_mean else f"{r.sim_mean:.8g}"
            e = "" if r.sim_stderr != r.sim_stderr else f"{r.sim_stderr:.3g}"
            print(f"{r.value:>8g} {r.policy:<12} {g:>14} {m:>14} {e:>9} {r.seconds:>8.2f}  {r.status}")
        print(f"{res.computed} rows computed, {res.reused} reused; files: {', '.join(res.files.values())}")
    bad = [r for r in res.rows if r.status.startswith("error")]
    return 1 if bad else 0


def _configure_sweep(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--param", default="p", help="override key to sweep (default p)")
    p.add_argument("--values", required=True, help="START:STOP:STEP (stop included) or a comma list")
    p.add_argument("--policies", default="optimal,suboptimal,static,greedy",
                   help="comma list from optimal,suboptimal,static,best_static,greedy,random")
    p.add_argument("--out", required=True, help="output folder (resumed when it holds rows)")
    p.add_argument("--method", default="pi", choices=["lp", "lp-cvxpy", "rvi", "pi"],
                   help="solver of the optimal policy (default pi)")
    p.add_argument("--simulate-slots", type=int, default=0, help="also simulate each policy for this many slots")
    p.add_argument("--reps", type=int, default=20, help="replications when simulating (default 20)")
    p.add_argument("--seed", type=int, default=0, help="simulation seed (default 0)")
    p.add_argument("--burn-in", type=int, default=1000, help="simulation burn-in (default 1000)")
    p.add_argument("--no-exact", action="store_true", help="no exact evaluation (simulate only; needs --simulate-slots)")
    p.add_argument("--max-workers", type=int, default=1, help="grid values in parallel (default 1, with warm start)")
    p.add_argument("--executor", default="process", choices=["process", "dask"], help="parallel backend")
    p.add_argument("--no-plot", action="store_true", help="do not write sweep.png / sweep.svg")


subcommand("sweep", "sweep one parameter for several policies: CSV/JSON table (resumable) and figure",
           _configure_sweep)(cmd_sweep)


# ----------------------------------------------------------------------------- reproduce
def cmd_reproduce(args: argparse.Namespace) -> int:
    from .reproduce import run_reproduction

    result = run_reproduction(args.out, args.profile, force=args.force,
                              claims=[c.strip().upper() for c in args.claims.split(",")] if args.claims else None,
                              progress=not args.json)
    if args.json:
        emit_json({"files": result["files"], "seconds": result["seconds"],
                   "claims": [{k: c[k] for k in ("id", "verdict", "summary")} for c in result["claims"]]})
    else:
        for c in result["claims"]:
            print(f"{c['id']:>4} {c['verdict']:<8} {c['summary']}")
        print(f"report: {result['files']['md']} and {result['files']['html']} ({result['seconds']:.0f} s)")
    return 0


def _configure_reproduce(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output folder (figures, tables, report.md/.html/.json, cache)")
    p.add_argument("--profile", default="default", choices=["quick", "default"],
                   help="quick: small caps, about a minute; default: caps 12/20/30 where the size allows")
    p.add_argument("--force", action="store_true", help="recompute every step instead of using the cache")
    p.add_argument("--claims", default="", help="only these claims, e.g. C1,C7 (default: all)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


subcommand("reproduce", "reproduce every figure and claim of the paper into a report (cached, resumable)",
           _configure_reproduce)(cmd_reproduce)


# ----------------------------------------------------------------------------- verify / map
def cmd_verify(args: argparse.Namespace) -> int:
    from .solvers import solve
    from .structure import Tolerance, verify_all

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build(scenario, args)
    sol = solve(mdp, method=args.method)
    reports = verify_all(mdp, sol, tolerance=Tolerance(args.atol, args.rtol), examples=args.examples)
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "kind": scenario.model.kind,
        "states": mdp.n_states,
        "pairs": mdp.n_pairs,
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
        for r in reports:
            if r.examples:
                e = r.examples[0]
                print(f"{r.name}: first example ({'recurrent' if e.recurrent else 'transient'}, "
                      f"{'at' if e.at_cap else 'below'} the cap, size {e.size:.4g}):")
                for lab in e.labels:
                    print(f"    {lab}")
                for step in e.info.get("trajectory", []):
                    print(f"      -> {step['label']}  action {tuple(step['action'])}  p={step['prob']:.3g}"
                          + (f"  [{step['event']}]" if "event" in step else ""))
    return 0 if sol.ok else 1


def _configure_verify(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--method", default="pi", choices=["pi", "rvi", "lp"], help="solver (default: pi)")
    p.add_argument("--atol", type=float, default=1e-9, help="absolute part of the tie tolerance (default 1e-9)")
    p.add_argument("--rtol", type=float, default=1e-9,
                   help="part of the tie tolerance relative to span(V) = max V - min V (default 1e-9)")
    p.add_argument("--examples", type=int, default=10, help="example violations kept per check (default 10)")


subcommand("verify", "check Theorems 1-3 (monotone V, threshold policy, consistency) on the solved model",
           _configure_verify)(cmd_verify)


def _parse_fix(items: Sequence[str]) -> dict[int, int]:
    from .errors import ModelError

    out: dict[int, int] = {}
    for item in (x.strip() for chunk in items for x in chunk.split(",") if x.strip()):
        k, sep, v = item.partition("=")
        if not sep or not k.strip().isdigit() or not v.strip().isdigit():
            raise ModelError(f"--fix {item!r}: expected PROCESS=TAU with 1-based integers, e.g. 3=5")
        out[int(k)] = int(v)
    return out


def cmd_map(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .errors import ModelError
    from .maps import parse_config_spec, plot_policy_map, plot_policy_slice, region_stats
    from .solvers import solve

    scenario = load(args)
    try:
        axes = tuple(int(x) for x in args.axes.split(","))
    except ValueError:
        raise ModelError(f"--axes {args.axes!r}: expected comma-separated process indices, e.g. 1,2") from None
    fixed = _parse_fix(args.fix)
    mdp = build(scenario, args)
    config = parse_config_spec(mdp, args.servers)
    sol = solve(mdp, method=args.method)
    if args.slice is not None:
        axes = axes if len(axes) == 3 else (1, 2, 3)
        ax = plot_policy_slice(mdp, sol, config, args.slice, axes=axes, fixed_tau=fixed, scenario=scenario)
        stats = region_stats(mdp, sol, config, axes=axes, fixed_tau=fixed, total=args.slice, scenario=scenario)
    else:
        ax = plot_policy_map(mdp, sol, config, axes=axes, fixed_tau=fixed, scenario=scenario)
        stats = region_stats(mdp, sol, config, axes=axes, fixed_tau=fixed, scenario=scenario)
    ax.figure.savefig(args.out, dpi=args.dpi, bbox_inches="tight")
    plt.close(ax.figure)
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "out": args.out,
        "configuration": mdp.states.describe_config(mdp.states.configs[config]),
        "configuration_id": config,
        "axes": list(axes),
        "slice_total": args.slice,
        "gain": sol.gain,
        "regions": stats,
    }
    if args.json:
        emit_json(payload)
    else:
        print(f"map of [{payload['configuration']}] written to {args.out}")
        for name, r in stats["per_action"].items():
            print(f"  {name}: {r['cells']} cells, {r['components']} region(s), {r['holes']} hole(s)"
                  f"{'' if r['connected'] else '  -- not connected'}")
    return 0


def _configure_map(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--servers", required=True, metavar="SPEC",
                   help="the configuration: 'idle'; '#ID'; its description as in state labels, e.g. "
                        "'edge: job 3 d=3' (servers not named are idle) or 'b=10 | serving 2(d=2,g=2) | down [-]'; "
                        "or a Python literal of the configuration tuple")
    p.add_argument("--out", required=True, help="output image (.png, .svg, .pdf)")
    p.add_argument("--axes", default="1,2", help="processes on the x,y axes, 1-based (default 1,2); with --slice "
                                                 "three of them (default 1,2,3)")
    p.add_argument("--fix", action="append", default=[], metavar="K=TAU",
                   help="AoI of a process not on the axes, e.g. 3=5 (repeatable; default: the value with the "
                        "most reachable states)")
    p.add_argument("--slice", type=int, default=None, metavar="TOTAL",
                   help="draw the plane tau_i + tau_j + tau_k = TOTAL as a triangle (three processes)")
    p.add_argument("--method", default="pi", choices=["pi", "rvi", "lp"], help="solver (default: pi)")
    p.add_argument("--dpi", type=int, default=120, help="resolution of raster output (default 120)")


subcommand("map", "draw the optimal action over two AoIs (or a 3-process slice) for one server configuration",
           _configure_map)(cmd_map)


# ----------------------------------------------------------------------------- export
def cmd_export(args: argparse.Namespace) -> int:
    from .export import save_npz

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build(scenario, args)
    t_build = time.perf_counter() - t0
    path = save_npz(mdp, args.out, scenario=scenario, compress=args.compress)
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "fingerprint": scenario.fingerprint(),
        "out": str(path),
        "states": mdp.n_states,
        "pairs": mdp.n_pairs,
        "nnz": int(mdp.P.nnz),
        "bytes": path.stat().st_size,
        "build_seconds": t_build,
        "seconds": time.perf_counter() - t0,
    }
    if args.json:
        emit_json(payload)
    else:
        print(f"wrote {path}: {mdp.n_states:,} states, {mdp.n_pairs:,} pairs, {mdp.P.nnz:,} transitions "
              f"({payload['bytes'] / 1e6:.1f} MB; format wncs_lp.mdp-npz v1, see wncs_lp.export)")
    return 0


def _configure_export(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--out", required=True, metavar="FILE.npz", help="output file (.npz; format documented in wncs_lp.export)")
    p.add_argument("--compress", action="store_true", help="compress the arrays (smaller, slower)")


subcommand("export", "build the MDP and write it as .npz (pairs, costs, CSR transitions, decoded state labels)",
           _configure_export)(cmd_export)


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

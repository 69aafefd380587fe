"""``wncs-lp map``: draw the optimal action over two AoIs (or a 3-process slice)."""
from __future__ import annotations

import argparse
from typing import Sequence

from .common import (MATRIX_FREE_METHODS, Command, add_method_arg, add_progress_arg, add_scenario_args,
                     add_threads_arg, emit_json, load, output_file, progress_for, whole_option)

#: The largest ``--dpi``: a figure of the default size at 1200 dpi is already 7,680 x 5,760 pixels.
MAX_DPI = 1200


def _parse_axes(text: str) -> tuple[int, ...]:
    from ..errors import ModelError

    try:
        return tuple(int(x) for x in text.split(","))
    except ValueError:
        raise ModelError(f"--axes {text!r}: expected comma-separated process indices, e.g. 1,2") from None


def _parse_fix(items: Sequence[str]) -> dict[int, int]:
    from ..errors import ModelError

    out: dict[int, int] = {}
    for item in (x.strip() for chunk in items for x in chunk.split(",") if x.strip()):
        k, sep, v = item.partition("=")
        if not sep or not k.strip().isdigit() or not v.strip().isdigit():
            raise ModelError(f"--fix {item!r}: expected PROCESS=TAU with 1-based integers, e.g. 3=5")
        out[int(k)] = int(v)
    return out


def _check_route(args: argparse.Namespace, scenario) -> None:
    """What a map without a stored matrix cannot draw, refused before the solve."""
    from ..errors import SolverError
    from ..methods import SCENARIO_INPUT, method

    if method(args.method).takes != SCENARIO_INPUT:
        return
    if args.slice is not None:
        raise SolverError(f"--slice is not available with the {args.method} method; draw a map over two AoIs with "
                          "the others fixed (--axes I,J --fix K=TAU)")
    if scenario.constraints and not args.ignore_constraints:
        raise SolverError(f"the {args.method} method solves unconstrained scenarios only; pass --ignore-constraints "
                          "to map the unconstrained optimum")


def cmd_map(args: argparse.Namespace) -> int:
    from ..policy_grids import parse_config_spec
    from ..spaces import space_of
    from ..workflow import run_scenario
    from ..viz import file_backend, image_formats

    file_backend()
    # before any work: an image format matplotlib writes, in an existing folder
    output_file(args.out, "--out", image_formats())

    scenario = load(args)
    axes = _parse_axes(args.axes)
    if args.slice is None and len(axes) != 2:  # before the solve, for the stored-matrix and matrix-free maps alike
        from ..errors import ModelError

        raise ModelError(f"--axes {args.axes!r}: a map takes two processes (three with --slice)")
    fixed = _parse_fix(args.fix)
    prog = progress_for(args)
    if args.policy is not None:
        return _saved_policy_map(args, scenario, axes, fixed, prog)
    _check_route(args, scenario)
    config = []  # the configuration, read off the MDP before the solve (a bad --servers fails early)
    run = run_scenario(scenario, args.method, constrained=False if args.ignore_constraints else None,
                         force=args.force, threads=args.threads, progress=prog, need_mdp=args.slice is not None,
                         check=lambda mdp: config.append(parse_config_spec(mdp, args.servers)))
    sol = run.solution
    if run.built:  # the MDP's state table
        space, config = space_of(run.mdp), config[0]
        route = {"slice_total": args.slice, "gain": sol.gain, "constrained": run.constrained}
    else:  # no stored matrix: the matrix-free solve's AoI box
        space = space_of(sol)
        config = space.config_id(args.servers)
        route = {"gain": sol.gain, "gain_lower": sol.gain_lower, "gain_upper": sol.gain_upper, "method": run.method,
                 "matrix_free_reason": run.route}
    axes, stats = _draw(args, space, sol, config, axes, fixed, scenario, prog)
    payload = {"scenario": scenario.source, "overrides": args.overrides, "out": args.out,
               "configuration": space.describe(config), "configuration_id": config, "axes": list(axes), **route,
               "regions": stats}
    if args.json:
        emit_json({**payload, "status": str(sol.status)})
    else:
        how = "" if run.built else (f" ({run.method}, {run.route}; g* in [{sol.gain_lower:.10g}, "
                                    f"{sol.gain_upper:.10g}])")
        print(f"map of [{payload['configuration']}] written to {args.out}{how}")
        if not sol.ok:  # the label "optimal" is earned only where the certificate closed
            print(f"note: the solve is not certified (status {sol.status}: {sol.status.message}); the map shows "
                  "its policy, not a certified optimum")
        _print_regions(stats)
    return 0 if sol.ok else 1


def _draw(args: argparse.Namespace, space, policy, config: int, axes, fixed, scenario, prog):
    """Draw the map (or the --slice) of ``policy`` in configuration ``config`` of ``space`` (an MDP's
    state table or a matrix-free AoI box, :mod:`wncs_lp.spaces`), save it to --out; the axes drawn
    and the regions' statistics (with the configuration they are of)."""
    from ..policy_grids import region_stats
    from ..viz import plot_policy_map, plot_policy_slice, save_figure

    prog.phase(f"drawing the map and writing {args.out}")
    total = {} if args.slice is None else {"total": args.slice}
    if args.slice is not None:
        axes = axes if len(axes) == 3 else (1, 2, 3)
        ax = plot_policy_slice(space, policy, config, args.slice, axes=axes, fixed_tau=fixed, scenario=scenario)
    else:
        ax = plot_policy_map(space, policy, config, axes=axes, fixed_tau=fixed, scenario=scenario)
    stats = region_stats(space, policy, config, axes=axes, fixed_tau=fixed, scenario=scenario, **total)
    stats.update(configuration=space.describe(config), configuration_id=int(config))
    save_figure(ax.figure, args.out, dpi=args.dpi, bbox_inches="tight")
    return axes, stats


def _saved_policy_map(args: argparse.Namespace, scenario, axes, fixed, prog) -> int:
    """``--policy FILE.npz``: draw a policy saved by ``wncs-lp solve --out`` on the scenario's MDP,
    as ``evaluate`` and ``simulate`` take it (nothing is solved)."""
    from ..errors import PolicyError
    from ..io import load_policy_npz
    from ..solvers.route import build_scenario
    from ..spaces import space_of

    if not args.policy.lower().endswith(".npz"):
        raise PolicyError(f"--policy {args.policy!r}: map draws a policy saved by wncs-lp solve --out FILE.npz "
                          "(without --policy: the optimal policy, solved here)")
    mdp, _ = build_scenario(scenario, force=args.force, progress=prog)
    space = space_of(mdp)
    config = space.config_id(args.servers)
    prog.phase(f"reading the policy of {args.policy}")
    probs = load_policy_npz(args.policy, mdp)
    axes, stats = _draw(args, space, probs, config, axes, fixed, scenario, prog)
    payload = {"scenario": scenario.source, "overrides": args.overrides, "out": args.out, "policy": args.policy,
               "configuration": space.describe(config), "configuration_id": config,
               "axes": list(axes), "slice_total": args.slice, "regions": stats}
    if args.json:
        emit_json(payload)
    else:
        print(f"map of [{payload['configuration']}] of the policy of {args.policy} written to {args.out}")
        _print_regions(stats)
    return 0


def _print_regions(stats: dict) -> None:
    for name, r in stats["per_action"].items():
        print(f"  {name}: {r['cells']} cells, {r['components']} region(s), {r['holes']} hole(s)"
              f"{'' if r['connected'] else '  -- not connected'}")


def _configure_map(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--servers", required=True, metavar="SPEC",
                   help="the configuration: 'idle'; '#ID' (its 0-based id, as configuration_id in --json "
                        "output); its description as in state labels, e.g. "
                        "'edge: job 3 d=3' (servers not named are idle) or 'b=10 | serving 2(d=2,g=2) | down [-]'; "
                        "or a Python literal of the configuration tuple")
    p.add_argument("--out", required=True, help="output image in an existing folder: .png, .svg, .pdf (or any "
                                                "format matplotlib writes); checked before the solve")
    p.add_argument("--axes", default="1,2", help="processes on the x,y axes, 1-based (default 1,2); with --slice "
                                                 "three of them (default 1,2,3)")
    p.add_argument("--fix", action="append", default=[], metavar="K=TAU",
                   help="AoI of a process not on the axes, e.g. 3=5 (repeatable; default: the value with the "
                        "most reachable states)")
    p.add_argument("--slice", type=whole_option(1, what="total AoI"), default=None, metavar="TOTAL",
                   help="draw the plane tau_i + tau_j + tau_k = TOTAL as a triangle (three processes)")
    add_method_arg(p, "solver of the optimal policy (constrained scenarios: auto, lp or lp-cvxpy)", MATRIX_FREE_METHODS,
                   "matrix-free: certified value iteration without building the MDP, for models too large to "
                   "store (auto switches to it when the stored matrix would not fit; two-AoI maps only, the "
                   "AoIs off the axes default to the lower end of the configuration's box)")
    p.add_argument("--policy", default=None, metavar="FILE.npz",
                   help="draw a policy saved by wncs-lp solve --out FILE.npz (on the same scenario and overrides) "
                        "instead of solving, as evaluate and simulate take it")
    p.add_argument("--ignore-constraints", action="store_true",
                   help="map the unconstrained optimum even if the scenario has [[constraint]] tables (by default "
                        "the constrained optimum is drawn, with its randomised states starred)")
    p.add_argument("--dpi", type=whole_option(10, MAX_DPI, what="resolution"), default=120,
                   help=f"resolution of raster output, 10 to {MAX_DPI} dots per inch (default 120)")
    add_threads_arg(p)
    add_progress_arg(p)


COMMANDS = [
    Command("map", "draw the optimal action over two AoIs (or a 3-process slice) for one server configuration",
            _configure_map, cmd_map),
]

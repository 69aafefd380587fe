"""``wncs-lp capstudy``: solve at increasing AoI caps until the truncation stops mattering."""
from __future__ import annotations

import argparse
import sys

from ..methods import SCENARIO_INPUT, TABLE
from .common import (Command, add_method_arg, add_scenario_args, add_threads_arg, emit_json, head, load,
                     real_option)


def cmd_capstudy(args: argparse.Namespace) -> int:
    from ..studies import cap_study, parse_values

    scenario = load(args)
    values = parse_values(args.caps, "--caps")
    if any(v != int(v) for v in values):
        from ..errors import WncsError

        raise WncsError(f"--caps {args.caps!r}: expected whole numbers, got {', '.join(f'{v:g}' for v in values)}")
    caps = [int(v) for v in values]

    def show(row) -> None:
        if not args.json:
            change = "" if row.rel_change != row.rel_change else f"{row.rel_change:+.3%}"
            on_box = getattr(TABLE.get(row.method), "takes", None) == SCENARIO_INPUT  # on the AoI box, no matrix
            mass = f"{'<=' if on_box else ''}{row.cap_mass:.3%}"  # a certified upper end there
            print(f"{row.cap:>5} {row.states:>10,} {row.gain:>16.10g} {row.gain_upper - row.gain_lower:>10.2e} "
                  f"{mass:>10} {change:>10} {row.first_policy_gain:>16.10g} {row.seconds:>7.1f}"
                  + (f"  {row.method}" if on_box else "")
                  + ("" if row.certified else f"  NOT CERTIFIED: {row.status}"), flush=True)
        elif sys.stderr.isatty():
            print(f"cap {row.cap}: gain {row.gain:.10g}, mass at cap {row.cap_mass:.3%}", file=sys.stderr)

    if not args.json:
        print(scenario.describe())
        print(f"{'cap':>5} {'states':>10} {'optimal gain':>16} {'bracket':>10} {'at cap':>10} {'change':>10} "
              f"{'cap-' + str(caps[0]) + ' policy':>16} {'seconds':>7}")
    study = cap_study(scenario, caps, mass_tol=args.mass_tol, gain_rtol=args.gain_rtol, method=args.method,
                      force=args.force, threads=args.threads, on_row=show)
    if args.json:
        emit_json({**head(args, scenario), "converged": study.converged, "mass_tol": study.mass_tol,
                   "gain_rtol": study.gain_rtol, "rows": study.table()})
    else:
        last = study.rows[-1]
        if study.converged:
            print(f"converged at cap {last.cap}: mass at the cap {last.cap_mass:.3%} <= {args.mass_tol:.2%} and "
                  f"change {abs(last.rel_change):.3%} <= {args.gain_rtol:.2%}; every gain above is a lower bound on the "
                  "untruncated optimum (g*(C) <= g*(C') while the loops fit under C)")
        elif any(not r.certified for r in study.rows[-2:]):
            bad = ", ".join(f"cap {r.cap} ({r.status})" for r in study.rows if not r.certified)
            print(f"not converged: the solves at {bad} are not certified, so their gains prove nothing "
                  "(another --method, or a smaller cap)")
        else:
            print(f"not converged by cap {last.cap}: give larger caps (--caps)")
    return 0 if study.converged else 1


def _configure(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--caps", default="12:40:4", help="caps to try, START:STOP:STEP or a comma list (default 12:40:4)")
    p.add_argument("--mass-tol", type=real_option(0.0, 1.0), default=0.01,
                   help="stop when the optimal policy's mass at the cap is at most this (default 0.01)")
    p.add_argument("--gain-rtol", type=real_option(0.0), default=1e-3,
                   help="... and the relative change of the gain from the previous cap at most this (default 1e-3)")
    add_method_arg(p, "solver of each cap")
    add_threads_arg(p)


COMMANDS = [
    Command("capstudy", "solve at increasing AoI caps until the mass at the cap and the change in gain are small",
            _configure, cmd_capstudy),
]

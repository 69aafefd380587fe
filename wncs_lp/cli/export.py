"""``wncs-lp export``: build the MDP and write it as .npz."""
from __future__ import annotations

import argparse
import time

from .common import Command, add_scenario_args, emit_json, load


def cmd_export(args: argparse.Namespace) -> int:
    from ..export import save_npz
    from ..models.guard import build_checked

    scenario = load(args)
    t0 = time.perf_counter()
    mdp = build_checked(scenario, force=args.force)
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


COMMANDS = [
    Command("export", "build the MDP and write it as .npz (pairs, costs, CSR transitions, decoded state labels)",
            _configure_export, cmd_export),
]

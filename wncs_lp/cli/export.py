"""``wncs-lp export``: build the MDP and write it as .npz (the toolkit's format) or .drn (Storm's)."""
from __future__ import annotations

import argparse
import time

from .common import Command, add_scenario_args, emit_json, load, output_file

#: Output formats: ours (numpy) and Storm's explicit DRN.
FORMATS = ("npz", "drn")


def _format_of(args: argparse.Namespace) -> str:
    if args.format is not None:
        return args.format
    suffix = args.out.rsplit(".", 1)[-1].lower() if "." in args.out.rsplit("/", 1)[-1] else ""
    return suffix if suffix in FORMATS else "npz"


def cmd_export(args: argparse.Namespace) -> int:
    from ..solvers.route import build_scenario

    fmt = _format_of(args)
    output_file(args.out, "--out")  # before any work: the folder must exist (nothing is created)
    if fmt == "drn" and args.compress:
        from ..errors import WncsError

        raise WncsError("--compress applies to --format npz only (a .drn file is plain text)")
    scenario = load(args)
    t0 = time.perf_counter()
    mdp, t_build = build_scenario(scenario, force=args.force)
    if fmt == "drn":
        from ..export import save_drn

        path = save_drn(mdp, args.out, scenario=scenario)
        described = "Storm's explicit DRN; check it with R{\"cost\"}min=? [LRA], see wncs_lp.export"
    else:
        from ..export import save_npz

        path = save_npz(mdp, args.out, scenario=scenario, compress=args.compress)
        described = "wncs_lp.mdp-npz v1, see wncs_lp.export"
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "fingerprint": scenario.fingerprint(),
        "format": fmt,
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
              f"({payload['bytes'] / 1e6:.1f} MB; {described})")
    return 0


def _configure_export(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output file, in an existing folder: FILE.npz (.npz is appended when missing) or FILE.drn")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="npz: arrays with the decoded states (numpy.load reads it; wncs_lp.export.load_npz builds "
                        "the MDP back); drn: Storm's explicit format (storm --explicit-drn, "
                        "stormpy.build_model_from_drn), the cost as the reward model 'cost'. "
                        "Default: from the extension of --out, else npz")
    p.add_argument("--compress", action="store_true", help="compress the arrays (npz only; smaller, slower)")


COMMANDS = [
    Command("export", "build the MDP and write it: .npz (pairs, costs, CSR transitions, decoded states) or "
            "Storm's explicit .drn", _configure_export, cmd_export),
]

"""``wncs-lp export``: build the MDP and write it as .npz (the toolkit's format), .drn (Storm's) or
PRISM's explicit files (.tra, .sta, .lab, .srew, .trew)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from .common import Command, add_scenario_args, emit_json, load, output_file

#: Output formats: ours (numpy), Storm's explicit DRN, PRISM's explicit files.
FORMATS = ("npz", "drn", "prism")
#: Extensions of --out that name a format when --format is not given.
_SUFFIX_FORMAT = {"npz": "npz", "drn": "drn", "tra": "prism", "all": "prism"}


def _format_of(args: argparse.Namespace) -> str:
    if args.format is not None:
        return args.format
    suffix = args.out.rsplit(".", 1)[-1].lower() if "." in args.out.rsplit("/", 1)[-1] else ""
    return _SUFFIX_FORMAT.get(suffix, "npz")


def _write(fmt: str, mdp, scenario, args: argparse.Namespace) -> tuple[Path, list[Path], str]:
    """Write the export; (the path reported, every file written, what the format is)."""
    if fmt == "drn":
        from ..io import save_drn

        path = save_drn(mdp, args.out, scenario=scenario)
        return path, [path], "Storm's explicit DRN; check it with R{\"cost\"}min=? [LRA], see wncs_lp.io.drn"
    if fmt == "prism":
        from ..io import save_prism

        files = list(save_prism(mdp, args.out, scenario=scenario).values())
        prefix = files[0].with_suffix("")
        return prefix, files, f"PRISM's explicit files: prism -importmodel {prefix}.all -mdp; see wncs_lp.io.prism"
    from ..io import save_npz

    path = save_npz(mdp, args.out, scenario=scenario, compress=args.compress)
    return path, [path], "wncs_lp.mdp-npz v1, see wncs_lp.io.npz"


def cmd_export(args: argparse.Namespace) -> int:
    from ..solvers.route import build_scenario

    fmt = _format_of(args)
    output_file(args.out, "--out")  # before any work: the folder must exist (nothing is created)
    if fmt != "npz" and args.compress:
        from ..errors import WncsError

        raise WncsError(f"--compress applies to --format npz only (--format {fmt} writes plain text)")
    scenario = load(args)
    t0 = time.perf_counter()
    mdp, t_build = build_scenario(scenario, force=args.force)
    path, files, described = _write(fmt, mdp, scenario, args)
    size = sum(f.stat().st_size for f in files)
    payload = {
        "scenario": scenario.source,
        "overrides": args.overrides,
        "fingerprint": scenario.fingerprint(),
        "format": fmt,
        "out": str(path),
        "files": [str(f) for f in files],
        "states": mdp.n_states,
        "pairs": mdp.n_pairs,
        "nnz": int(mdp.P.nnz),
        "bytes": size,
        "build_seconds": t_build,
        "seconds": time.perf_counter() - t0,
    }
    if scenario.constraints and fmt != "npz":
        from ..io import constraint_reward_names, multi_objective_property

        payload["reward_models"] = ["cost", *constraint_reward_names(scenario)]
        payload["multi_objective"] = multi_objective_property(scenario)
    if args.json:
        emit_json(payload)
    else:
        what = f"{len(files)} files, " if len(files) > 1 else ""
        print(f"wrote {path}: {mdp.n_states:,} states, {mdp.n_pairs:,} pairs, {mdp.P.nnz:,} transitions "
              f"({what}{size / 1e6:.1f} MB; {described})")
        if "multi_objective" in payload:
            print(f"reward models {', '.join(payload['reward_models'])}; the constrained optimum in Storm: "
                  f"{payload['multi_objective']}")
    return 0


def _configure_export(p: argparse.ArgumentParser) -> None:
    add_scenario_args(p)
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output, in an existing folder: FILE.npz (.npz is appended when missing), FILE.drn, or "
                        "DIR/NAME for --format prism (writes NAME.tra, .sta, .lab, .srew, ...)")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="npz: arrays with the decoded states (numpy.load reads it; wncs_lp.io.load_npz builds "
                        "the MDP back); drn: Storm's explicit format (storm --explicit-drn, "
                        "stormpy.build_model_from_drn), the cost as the reward model 'cost' and each "
                        "[[constraint]]'s quantity as one more; prism: PRISM's explicit files (prism -importmodel "
                        "NAME.all -mdp), the same reward models. Default: from the extension of --out "
                        "(.npz, .drn, .tra or .all for prism), else npz")
    p.add_argument("--compress", action="store_true", help="compress the arrays (npz only; smaller, slower)")


COMMANDS = [
    Command("export", "build the MDP and write it: .npz (pairs, costs, CSR transitions, decoded states), "
            "Storm's explicit .drn or PRISM's explicit files", _configure_export, cmd_export),
]

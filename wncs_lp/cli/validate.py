"""``wncs-lp validate``: check a scenario and print the size of its MDP, without building or solving."""
from __future__ import annotations

import argparse

from .common import Command, emit_json, head, load, scenario_file


def cmd_validate(args: argparse.Namespace) -> int:
    from .. import scenario_names

    if args.list:
        names = [n.removesuffix(".toml") for n in scenario_names()]
        if args.json:
            emit_json({"scenarios": names})
        else:
            print("\n".join(names))
        return 0
    if args.scenario is None:
        from ..errors import WncsError

        raise WncsError("validate needs a scenario file or the name of a shipped scenario (or --list)")
    scenario = load(args)
    est, refusal = _estimate(scenario, args.force)
    from ..models.guard import available_memory, matrix_free_fit

    avail = available_memory()
    payload = {**head(args, scenario), "file": str(scenario_file(args.scenario)), "valid": True,
               "estimate": None if est is None else est.to_dict(), "available_bytes": avail,
               "matrix_free": None if est is None else matrix_free_fit(est, avail),
               "would_build": refusal is None, "refusal": refusal}
    if args.json:
        emit_json(payload)
        return 0
    print(scenario.describe())
    if est is None:  # the automaton outgrew its exploration budget: no size to give
        print(f"valid. A solve would refuse to build it: {refusal}")
        return 0
    bound = "up to " if est.complete else "at least "
    what = "configurations (servers and sensors' ages)" if scenario.has_arrivals else "server configurations"
    print(f"valid. The MDP: {est.configs:,} {what}, {bound}{est.states:,} states, "
          f"{est.pairs:,} state-action pairs, {est.nnz:,} transition nonzeros")
    print(f"memory: build about {_gib(est.build_bytes)}, LP about {_gib(est.lp_bytes)} on Clarabel "
          f"({_gib(est.lp_need('highs'))} on HiGHS); available now {_gib(avail)}")
    print(f"matrix-free solver: {est.matrix_free_states:,} states, {matrix_free_fit(est, avail)}")
    print("a solve would build it" if refusal is None else f"a solve would refuse to build it: {refusal}")
    return 0


def _estimate(scenario, force: bool):
    """``(SizeEstimate, None)``, or ``(the estimate, the size guard's message)`` when a build would
    be refused (the estimate is then a lower bound when the automaton was not explored)."""
    from ..models.guard import SizeLimitError, check_size

    try:
        return check_size(scenario, force=force), None
    except SizeLimitError as exc:
        return exc.estimate, str(exc)


def _gib(b: float) -> str:
    return f"{b / 2**30:.2f} GiB" if b >= 2**30 else f"{b / 2**20:.1f} MiB"


def _configure_validate(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario TOML file, or the name of a shipped one (paper_p12, ...: see --list)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a field, as for solve (repeatable)")
    p.add_argument("--list", action="store_true", help="list the shipped scenarios by name")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--force", action="store_true",
                   help="explore the automaton past its budget to give the full estimate")


COMMANDS = [
    Command("validate", "check a scenario file (every field) and print the size of its MDP and the memory a solve "
            "needs, without building or solving; --list names the shipped scenarios", _configure_validate,
            cmd_validate),
]

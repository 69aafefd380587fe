"""What the DRN and PRISM exports carry beside the chain: the reward models (the cost, and a
constrained scenario's quantities: :func:`reward_models`), Storm's multi-objective query of a
constrained scenario (:func:`multi_objective_property`), the states' labels (``init``:
:func:`initial_state`; ``at_cap``: :func:`state_labels`) and the comments both formats write
in their header (:func:`export_header`, :func:`action_comments`).
"""
from __future__ import annotations

import re
from typing import Any

import numpy as np

from ..errors import ExportError
from ..mdp import MDP

__all__ = ["initial_state", "constraint_reward_names", "reward_models", "multi_objective_property",
           "action_comments", "export_header", "state_labels"]


def initial_state(mdp: MDP) -> int:
    """The state a run of the system starts in: every AoI at its cap in the first initial
    configuration (0 for an MDP without a decoded state space or model)."""
    st = mdp.states
    model = getattr(st, "model", None)
    if st is not None and model is not None and hasattr(st, "find"):
        try:
            s = st.find(tuple(int(c) for c in st.caps), int(model.automaton.initial[0]))
        except (AttributeError, IndexError, TypeError, ValueError):
            s = -1
        if s >= 0:
            return int(s)
    return 0


def action_comments(mdp: MDP, scenario: Any) -> list[str]:
    """Comment lines saying what each action name ``a<k>`` means (the names of the policy maps)."""
    at = mdp.action_table
    if at is None:
        return ["// action a<k>: action index k of the MDP"]
    rows = np.asarray(at, dtype=np.int64).reshape(len(at), -1)
    out = []
    for k, row in enumerate(rows):
        what = str(tuple(int(v) for v in row))
        if mdp.states is not None and getattr(mdp.states, "configs", None) is not None:
            try:
                from ..policy_grids import action_name

                what = f"{action_name(mdp, k, scenario=scenario)} {what}"
            except Exception:  # a name is a courtesy: the decoded tuple always stands
                pass
        out.append(f"// action a{k}: {what}")
    return out


_NAME_CHARS = re.compile(r"[^A-Za-z0-9_]+")


def _reward_name(text: str) -> str:
    """An identifier both Storm's properties and PRISM's reward headers accept ([A-Za-z_][A-Za-z0-9_]*)."""
    name = _NAME_CHARS.sub("_", text).strip("_") or "reward"
    return name if not name[0].isdigit() else f"r_{name}"


def constraint_reward_names(scenario: Any) -> tuple[str, ...]:
    """The reward-model name of each ``[[constraint]]`` table of ``scenario``, in file order.

    A constraint's name is its quantity followed by the server and / or process it is about
    (``send_rate_remote``, ``aoi_process_1``), with every character outside ``[A-Za-z0-9_]``
    replaced by ``_``; a name already taken (``cost``, or an earlier constraint's) gets the
    suffix ``_c<j>`` (j the constraint's 1-based position).
    """
    taken, out = {"cost"}, []
    for j, spec in enumerate(getattr(scenario, "constraints", ()) or (), start=1):
        parts = [spec.quantity]
        if spec.server is not None:
            parts.append(scenario.servers[spec.server].name)
        if spec.process is not None:
            parts.append(scenario.processes[spec.process].name)
        name = _reward_name("_".join(parts))
        if name in taken:
            name = f"{name}_c{j}"
        taken.add(name)
        out.append(name)
    return tuple(out)


def reward_models(mdp: MDP, scenario: Any = None, rewards: dict[str, Any] | None = None) -> dict[str, np.ndarray]:
    """The reward models a DRN or PRISM export carries, each an (L,) per-pair vector.

    ``cost`` (the MDP's one-slot cost) first; then, when ``scenario`` has ``[[constraint]]``
    tables, each constraint's quantity d_l (:func:`wncs_lp.models.quantities.pair_values`, the
    vector whose long-run average the constraint bounds) under the name of
    :func:`constraint_reward_names`; then ``rewards`` (name -> (L,) values) as given.

    Raises
    ------
    ExportError
        A name that is not an identifier or is used twice, or values of the wrong shape, not
        finite or negative (Storm's and PRISM's parsers take non-negative rewards).
    """
    out: dict[str, np.ndarray] = {"cost": np.asarray(mdp.cost, dtype=np.float64)}
    specs = getattr(scenario, "constraints", ()) or ()
    if specs:
        from ..models.quantities import pair_values

        for name, spec in zip(constraint_reward_names(scenario), specs):
            out[name] = np.asarray(pair_values(mdp, spec), dtype=np.float64)
    for name, values in (rewards or {}).items():
        if not isinstance(name, str) or _reward_name(name) != name:
            raise ExportError(f"reward model name {name!r}: expected an identifier ([A-Za-z_][A-Za-z0-9_]*)")
        if name in out:
            raise ExportError(f"reward model {name!r} is given twice (names taken: {', '.join(out)})")
        out[name] = np.asarray(values, dtype=np.float64)
    for name, v in out.items():
        if v.shape != (mdp.n_pairs,):
            raise ExportError(f"reward model {name!r}: expected {mdp.n_pairs} values (one per pair), got shape {v.shape}")
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ExportError(f"reward model {name!r}: values must be finite and >= 0 (pair {int(np.flatnonzero(~(v >= 0) | ~np.isfinite(v))[0])})")
    return out


def multi_objective_property(scenario: Any, *, direction: str = "min") -> str:
    """Storm's multi-objective query of a constrained scenario: the least long-run average cost
    subject to each ``[[constraint]]`` bound on its reward model's long-run average, e.g.
    ``multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2 [LRA])``.

    Its value is the constrained optimum that :func:`wncs_lp.solve` (``constraints=``)
    certifies (Storm's multi-objective engine lets the scheduler randomise, as the constrained
    optimum does).

    Raises
    ------
    ExportError
        The scenario has no ``[[constraint]]`` table.
    """
    specs = getattr(scenario, "constraints", ()) or ()
    if not specs:
        raise ExportError("the scenario has no [[constraint]] table: its optimum is R{\"cost\"}min=? [LRA]")
    terms = [f'R{{"cost"}}{direction}=? [LRA]']
    for name, spec in zip(constraint_reward_names(scenario), specs):
        if spec.max is not None:
            terms.append(f'R{{"{name}"}}<={float(spec.max)!r} [LRA]')
        if spec.min is not None:
            terms.append(f'R{{"{name}"}}>={float(spec.min)!r} [LRA]')
    return f"multi({', '.join(terms)})"


def export_header(mdp: MDP, scenario: Any, fmt: str, names: list[str]) -> list[str]:
    """Comment lines (without the comment marker) shared by the DRN and PRISM exports."""
    source = str(scenario.source) if scenario is not None else str(mdp.meta.get("source", ""))
    fingerprint = scenario.fingerprint() if scenario is not None else str(mdp.meta.get("fingerprint", ""))
    lines = [
        f"Exported by wncs_lp (wncs-lp export --format {fmt}): an average-cost MDP; its optimal average",
        'cost is the minimal long-run average of the reward model "cost": R{"cost"}min=? [LRA] in Storm',
        f"scenario {source} (fingerprint {fingerprint}): {mdp.n_states} states, {mdp.n_pairs} choices, "
        f"{int(mdp.P.nnz)} transitions",
        "states are numbered as in the .npz export (wncs-lp export --format npz): tau[s], config[s]",
        f"reward models: {', '.join(names)}",
    ]
    specs = getattr(scenario, "constraints", ()) or ()
    for name, spec in zip(constraint_reward_names(scenario) if specs else (), specs):
        lines.append(f'reward model "{name}": the quantity of the constraint {spec.label or spec.quantity}')
    if specs:
        lines.append(f"the constrained optimum (Storm): {multi_objective_property(scenario)}")
    return lines


def state_labels(mdp: MDP) -> tuple[int, np.ndarray]:
    """The initial state and the states where some AoI is at its cap (the exports' labels)."""
    st = mdp.states
    if st is not None and hasattr(st, "tau") and len(getattr(st, "caps", ())) > 0:
        at_cap = np.any(np.asarray(st.tau) >= np.asarray(st.caps)[None, :], axis=1)
    else:
        at_cap = np.zeros(mdp.n_states, bool)
    return initial_state(mdp), at_cap

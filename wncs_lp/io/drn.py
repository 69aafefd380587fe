"""An MDP in Storm's explicit DRN format (``wncs-lp export --format drn``).

:func:`save_drn` writes the MDP in Storm's DiRect eNcoding (DRN), which ``storm --explicit-drn
FILE`` and ``stormpy.build_model_from_drn(FILE)`` load. The file holds

* a header: ``@type: MDP``, an empty ``@parameters`` line, ``@reward_models`` with the names of
  the reward models (:func:`reward_models`: ``cost``, then one per ``[[constraint]]`` table of
  the scenario), ``@nr_states`` n and ``@nr_choices`` L; before it, comment lines (``//``)
  naming the scenario, each reward model and what each action name means;
* ``@model``: every state as ``state <s> <labels>`` in the toolkit's numbering (the same as the
  ``.npz`` export's, so ``tau[s]``, ``config[s]`` of that file decode it), then each of its pairs
  as ``action a<k> [<cost>, <reward 2>, ...]`` (``k`` the row of the action table; the one-slot
  cost and the other reward models' values as the choice rewards, in the header's order)
  followed by one line ``<target> : <probability>`` per successor, in increasing target order.

Labels: ``init`` on the initial state (every AoI at its cap in the first initial configuration,
where the paper's chain starts; state 0 for an MDP without decoded states) and ``at_cap`` on the
states where some AoI is at its cap. The optimal average cost is the minimal long-run average
reward ``R{"cost"}min=? [LRA]``: ``storm --explicit-drn model.drn --prop 'R{"cost"}min=? [LRA]'``,
or in Python::

    model = stormpy.build_model_from_drn("model.drn")
    prop = stormpy.parse_properties('R{"cost"}min=? [LRA]')[0]
    g = stormpy.model_checking(model, prop).get_value(model.initial_states[0])

A constrained scenario's optimum is Storm's multi-objective query
(:func:`multi_objective_property`), e.g. ``multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2
[LRA])``. Storm's long-run-average solvers stop at their own precision (1e-6 relative by
default) and give no certificate. Numbers are written as Python's shortest round-trip decimals
(the exact doubles).

The file is written atomically (:func:`wncs_lp.files.atomic_write_bytes`): a reader sees the
old complete file or the new one, never a partial one.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..files import atomic_write_bytes
from ..mdp import MDP
from .rewards import action_comments, export_header, reward_models, state_labels

__all__ = ["save_drn"]


def save_drn(mdp: MDP, path: str | Path, *, scenario: Any = None, rewards: dict[str, Any] | None = None) -> Path:
    """Write ``mdp`` in Storm's explicit DRN format (module docstring), atomically.

    Parameters
    ----------
    mdp : MDP
    path : file name (written as given)
    scenario : Scenario, optional
        Named in the header comments (with its fingerprint); also used to describe the actions.
        Its ``[[constraint]]`` tables become extra reward models (:func:`reward_models`).
    rewards : dict, optional
        More reward models, name -> (L,) non-negative per-pair values.

    Returns
    -------
    Path of the written file.
    """
    path = Path(path)
    models = reward_models(mdp, scenario, rewards)
    P = mdp.P.tocsr()
    if not P.has_sorted_indices:
        P = P.copy()
        P.sort_indices()
    n = mdp.n_states
    init, at_cap = state_labels(mdp)
    labels = np.where(at_cap, " at_cap", "").astype(object)
    labels[init] = " init" + labels[init]
    head = [f"// {line}" for line in export_header(mdp, scenario, "drn", list(models))]
    head += [*action_comments(mdp, scenario), "@type: MDP", "@parameters", "", "@reward_models", " ".join(models),
             "@nr_states", str(n), "@nr_choices", str(mdp.n_pairs), "@model", ""]
    values = np.column_stack(list(models.values())).tolist()
    action = [f"\taction a{a} [{', '.join(repr(x) for x in r)}]\n" for a, r in zip(mdp.a_indices.tolist(), values)]
    rows = [f"\t\t{j} : {x!r}\n" for j, x in zip(P.indices.tolist(), P.data.tolist())]
    indptr = P.indptr.tolist()
    pair_ptr = mdp.pair_ptr.tolist()
    out = ["\n".join(head)]
    push = out.append
    for s in range(n):
        push(f"state {s}{labels[s]}\n")
        for l in range(pair_ptr[s], pair_ptr[s + 1]):
            push(action[l])
            push("".join(rows[indptr[l]:indptr[l + 1]]))
    atomic_write_bytes(path, "".join(out).encode("utf-8"))
    return path

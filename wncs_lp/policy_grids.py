r"""Policy maps as data: the chosen action over the AoI box, as in the paper's Figs. 3-4, 6-9, 11-12.

No drawing here (that is :mod:`wncs_lp.viz.maps`; this module was ``wncs_lp.maps``, a name that
read as either):

* :func:`policy_grid` -- the action over (tau_i, tau_j) for one configuration (server state)
  with the other AoIs fixed;
* :func:`policy_probabilities`, :func:`mixed_states`, :func:`state_mix` -- randomised policies
  (see below);
* :func:`slice_grid` -- three processes on the plane tau_i + tau_j + tau_k = total (Figs. 6-7);
* :func:`region_stats` -- number of connected regions of each action and whether each is
  (simply) connected, on the grid (4-neighbour) or on the triangular lattice of a slice
  (6-neighbour);
* :func:`parse_config_spec` -- a configuration from a short text (used by ``wncs-lp map``);
* :func:`action_name`, :func:`short_action_name`, :func:`map_names` -- readable names, from the
  model (:meth:`wncs_lp.models.base.Model.action_name`).

Process indices (``axes``, ``fixed_tau``) are **1-based** like the paper's tau_1, tau_2, ...

Policies
--------
Every function taking ``policy_or_solution`` accepts a ``Solution`` or an (n,) int array of pair
indices (deterministic), a ``ConstrainedSolution``, a
:class:`~wncs_lp.policies.MixedPolicy` or an (L,) float array of pair probabilities
(randomised), or any :class:`~wncs_lp.policies.Policy` (mapped with ``on_mdp``). A randomised
policy's map shows its *most likely* action in each state (ties: the first pair, i.e. the
action listed first); :func:`mixed_states` gives the states where it mixes and
:func:`state_mix` the mix of one. Its recurrent states are those of its own (randomised) chain.

Configuration specs (``config`` arguments and ``wncs-lp map --servers``)
------------------------------------------------------------------------
* a configuration id (int) or object (as in ``mdp.states.configs``);
* ``"idle"``: every server idle with empty pipelines (Section II);
* ``"#17"``: configuration id 17;
* a Python literal of the configuration tuple: Section II ``((up, job, d, down), ...)`` per
  server, e.g. ``"(((), 0, 0, (0,)), ((), 3, 3, ()))"``; preemption ``(b, job, stack, down)``,
  e.g. ``"((1, 0), (2, 2, 2), (), (None,))"``;
* the configuration's description as printed in state labels, e.g.
  ``"remote: idle; edge: job 3 d=3"`` or ``"b=10 | serving 2(d=2,g=2) | down [-]"``
  (whitespace and case are ignored). For Section II, servers not named are idle, so
  ``"edge: job 3 d=3"`` is enough.
"""
from __future__ import annotations

import ast
import difflib
import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .chain import PROB_SUM_TOL, policy_matrices, recurrent_classes
from .errors import ModelError, PolicyError, WncsError
from .mdp import MDP
from .models import model_type
from .scenario import load_scenario

__all__ = [
    "NEIGHBOURS",
    "parse_config_spec",
    "map_names",
    "action_name",
    "short_action_name",
    "policy_pairs",
    "policy_probabilities",
    "mixed_states",
    "state_mix",
    "recurrent_mask",
    "policy_grid",
    "slice_grid",
    "region_stats",
    "system_names",
    "system_config",
    "matrix_free_grid",
    "matrix_free_region_stats",
]

# ============================================================================ names
def _short_process(name: str, k: int) -> str:
    m = re.fullmatch(r"(?i)process[-_ ]?(\w+)", name.strip())
    return m.group(1) if m else name


def map_names(mdp: MDP, scenario: Any = None) -> dict:
    """Names and parameters for labels: ``processes``, ``servers``, ``p``, ``name``, ``model``.

    From ``scenario`` when given, else from the scenario file the MDP was built from (``p`` only
    when that file without overrides is this very model).
    """
    N = len(mdp.states.caps)
    model = model_type(mdp)
    info = {"processes": [str(k) for k in range(1, N + 1)], "servers": None, "p": None,
            "name": Path(str(mdp.meta.get("source", mdp.name))).stem, "model": model}
    sc = scenario
    if sc is None and mdp.meta.get("source"):
        try:  # names only; p only if the file without overrides is this very model
            sc0 = load_scenario(mdp.meta["source"])
            info["processes"] = [_short_process(p.name, k) for k, p in enumerate(sc0.processes, 1)]
            info["servers"] = [s.name for s in sc0.servers]
            if sc0.fingerprint() == mdp.meta.get("fingerprint"):
                info["p"] = _one_p(sc0)
        except (OSError, WncsError):  # the file moved or changed since the build: default names
            pass
    elif sc is not None:
        info.update(_scenario_names(sc))
    if info["servers"] is None:
        info["servers"] = model.default_servers(mdp.states.configs)
    return info


def _scenario_names(sc: Any) -> dict:
    return {"processes": [_short_process(p.name, k) for k, p in enumerate(sc.processes, 1)],
            "servers": [s.name for s in sc.servers], "p": _one_p(sc), "name": Path(str(sc.source)).stem}


def _one_p(sc: Any) -> float | None:
    """The success probability of every link, or None when the links differ (per server or per
    process: then no single p describes the system)."""
    links = {float(v) for s in sc.servers for v in (*s.p_up, *s.p_down)}
    return links.pop() if len(links) == 1 else None


def system_names(system: Any) -> dict:
    """:func:`map_names` of a :class:`~wncs_lp.models.system.System` (no MDP: matrix-free maps)."""
    return {**_scenario_names(system.scenario), "model": type(system.model)}


def action_name(mdp: MDP, action: int | Sequence[int], config: Any = None, *, scenario: Any = None,
                names: dict | None = None) -> str:
    """A readable name of an action.

    Section II: ``"(1 to remote, 2 to edge)"`` (servers sent nothing are left out; all zero:
    ``"(send nothing)"``). Preemption, given the configuration: ``"keep going (serve 2)"``,
    ``"1 preempts 2"``, ``"restart 2 (cancel)"``, ``"start 1"``, ``"stay idle"``.

    Parameters
    ----------
    mdp : MDP
    action : int or tuple
        An action index (row of ``mdp.action_table``) or a decoded label.
    config : configuration object or id, optional
        Preemption: makes the name specific (which job is preempted).
    """
    names = names or map_names(mdp, scenario)
    if isinstance(action, (int, np.integer)):
        label = tuple(int(x) for x in np.atleast_1d(mdp.action_table[int(action)]))
    else:
        label = tuple(int(x) for x in action)
    conf = mdp.states.configs[int(config)] if isinstance(config, (int, np.integer)) else config
    return names["model"].action_name(label, conf, names)


def short_action_name(mdp: MDP, a: int, names: dict) -> str:
    """A short legend entry of action index ``a`` (``names`` from :func:`map_names`)."""
    label = tuple(int(x) for x in np.atleast_1d(mdp.action_table[int(a)]))
    return names["model"].short_action(label, names)


# ============================================================================ configurations
def _norm(text: str) -> str:
    return re.sub(r"\s+", " ", text.strip().lower())


def _tuplify(x: Any) -> Any:
    if isinstance(x, (list, tuple)):
        return tuple(_tuplify(v) for v in x)
    return x


def parse_config_spec(mdp: MDP, spec: Any) -> int:
    """The configuration id named by ``spec`` (see the module docstring for the syntax).

    Raises
    ------
    ModelError
        When the spec names no reachable configuration; the message lists close matches.
    """
    space = mdp.states
    if space is None or not hasattr(space, "configs"):
        raise ModelError(f"{mdp!r} has no decoded state space; cannot select a configuration")
    return _config_id(space.configs, space.describe_config, model_type(mdp), mdp.name, spec)


def system_config(system: Any, spec: Any) -> int:
    """:func:`parse_config_spec` over a :class:`~wncs_lp.models.system.System`'s configurations."""
    name = Path(str(system.scenario.source)).stem
    return _config_id(list(system.automaton.configs), system.model.describe, type(system.model), name, spec)


def _config_id(configs: list, describe: Any, model: Any, name: str, spec: Any) -> int:
    def lookup(obj: Any) -> int:
        try:
            return configs.index(obj)
        except ValueError:
            return -1

    if isinstance(spec, (int, np.integer)):
        if not 0 <= int(spec) < len(configs):
            raise ModelError(f"configuration id {spec} out of range 0..{len(configs) - 1}")
        return int(spec)
    if not isinstance(spec, str):
        c = lookup(_tuplify(spec))
        if c < 0:
            raise ModelError(f"configuration {spec!r} is not reachable in {name}")
        return c
    text = spec.strip()
    if text.lower() == "idle":
        ids = [i for i, c in enumerate(configs) if model.is_idle(c)]
        if len(ids) == 1:
            return ids[0]
        if not ids:
            raise ModelError(f"{name}: no configuration with every server idle")
        raise ModelError(f"{name}: 'idle' is ambiguous ({len(ids)} configurations); give the description, "
                         f"e.g. {describe(configs[ids[0]])!r}")
    if text.startswith("#") and text[1:].strip().isdigit():
        return _config_id(configs, describe, model, name, int(text[1:]))
    if text[:1] in "([":
        try:
            obj = _tuplify(ast.literal_eval(text))
        except (ValueError, SyntaxError) as exc:
            raise ModelError(f"configuration literal {text!r} is not a valid Python literal: {exc}") from None
        c = lookup(obj)
        if c < 0:
            raise ModelError(f"configuration {obj!r} is not reachable in {name}")
        return c
    descs = [describe(c) for c in configs]
    target = _norm(text)
    normed = [_norm(d) for d in descs]
    if target in normed:
        return normed.index(target)
    # a partial description (Section II: servers not named are idle)
    idle_desc = next((d for c, d in zip(configs, descs) if model.is_idle(c)), None)
    full = model.complete_partial(text, descs, idle_desc)
    if full is not None and _norm(full) in normed:
        return normed.index(_norm(full))
    close = difflib.get_close_matches(target, normed, n=6, cutoff=0.5)
    hint = "; ".join(repr(descs[normed.index(c)]) for c in close) or "none close"
    raise ModelError(f"no reachable configuration matches {text!r} in {name}; close matches: {hint}")


# ============================================================================ grids
def _policy_array(mdp: MDP, policy_or_solution: Any) -> np.ndarray:
    if callable(getattr(policy_or_solution, "on_mdp", None)):  # a Policy
        try:
            return np.asarray(policy_or_solution.on_mdp(mdp))
        except PolicyError as exc:
            raise ModelError(str(exc)) from None
    return np.asarray(getattr(policy_or_solution, "policy", policy_or_solution))


def _is_probs(pol: np.ndarray) -> bool:
    return np.issubdtype(pol.dtype, np.floating)


def policy_probabilities(mdp: MDP, policy_or_solution: Any) -> np.ndarray | None:
    """The (L,) pair probabilities of a randomised policy, checked; None for a deterministic one.

    Randomised: an (L,) float array, or an object with such a ``.policy`` (ConstrainedSolution,
    MixedPolicy), or a Policy whose ``on_mdp`` gives one. Deterministic: a Solution, an (n,) int
    array, a deterministic Policy.

    Raises
    ------
    ModelError
        Malformed probabilities (the message names the first bad state or pair).
    """
    pol = _policy_array(mdp, policy_or_solution)
    if not _is_probs(pol):
        return None
    pol = pol.astype(np.float64)
    ok = pol.shape == (mdp.n_pairs,) and bool(np.all(np.isfinite(pol))) and bool(np.all(pol >= 0)) \
        and bool(np.all(np.abs(np.add.reduceat(pol, mdp.pair_ptr[:-1]) - 1.0) <= PROB_SUM_TOL))
    if not ok:
        try:
            policy_matrices(mdp, pol)  # the one validation of pair probabilities: its message
        except PolicyError as exc:
            raise ModelError(str(exc)) from None
    return pol


def mixed_states(mdp: MDP, policy_or_solution: Any) -> np.ndarray:
    """The states where the policy puts positive probability on two or more actions (sorted;
    empty for a deterministic policy)."""
    probs = policy_probabilities(mdp, policy_or_solution)
    if probs is None:
        return np.zeros(0, np.int64)
    return np.flatnonzero(np.add.reduceat((probs > 0).astype(np.int64), mdp.pair_ptr[:-1]) > 1)


def state_mix(mdp: MDP, probs: np.ndarray, s: int) -> list[tuple[int, float]]:
    """``[(action index, probability), ...]`` of state s, positive probabilities only, most likely
    first (ties: the action listed first). ``probs`` from :func:`policy_probabilities`."""
    out = [(int(mdp.a_indices[l]), float(probs[l])) for l in mdp.pairs_of(int(s)) if probs[l] > 0]
    return sorted(out, key=lambda t: -t[1])


def _most_likely_pairs(mdp: MDP, probs: np.ndarray) -> np.ndarray:
    starts = mdp.pair_ptr[:-1]
    best = np.maximum.reduceat(probs, starts)
    cand = np.where(probs == best[mdp.s_indices], np.arange(mdp.n_pairs), mdp.n_pairs)
    return np.minimum.reduceat(cand, starts).astype(np.int64)


def _chain_policy(mdp: MDP, policy_or_solution: Any) -> np.ndarray:
    """What the policy's chain is built from: the probabilities (randomised) or the pairs."""
    probs = policy_probabilities(mdp, policy_or_solution)
    return probs if probs is not None else policy_pairs(mdp, policy_or_solution)


def policy_pairs(mdp: MDP, policy_or_solution: Any) -> np.ndarray:
    """The (n,) chosen pair per state, checked.

    Deterministic policies (a Solution, a pair-index array): the chosen pair. Randomised ones
    (see the module docstring): the most likely pair of each state (ties: the first).
    """
    pol = _policy_array(mdp, policy_or_solution)
    if _is_probs(pol):
        return _most_likely_pairs(mdp, policy_probabilities(mdp, pol))
    if pol.shape != (mdp.n_states,) or not np.issubdtype(pol.dtype, np.integer):
        raise ModelError(f"policy must be a Solution or an integer array of pair indices of shape ({mdp.n_states},), "
                         f"or a float array of pair probabilities of shape ({mdp.n_pairs},)")
    if pol.min() < 0 or pol.max() >= mdp.n_pairs or np.any(mdp.s_indices[pol] != np.arange(mdp.n_states)):
        raise ModelError("policy holds a pair index that does not belong to its state")
    return pol.astype(np.int64)


def recurrent_mask(mdp: MDP, pol: np.ndarray, stationary: Any = None) -> np.ndarray | None:
    """States with positive stationary probability under the policy.

    ``pol``: (n,) chosen pairs, or (L,) pair probabilities of a randomised policy.

    ``stationary`` False: no shading (None); an (n,) array: ``stationary > 0``; None: the
    exact graph criterion (the states of the closed communicating classes of the policy's chain,
    which are exactly the states with positive stationary probability) -- no linear solve needed.
    """
    if stationary is False:
        return None
    if stationary is not None:
        st = np.asarray(stationary, float)
        if st.shape != (mdp.n_states,):
            raise ModelError(f"stationary must have shape ({mdp.n_states},), got {st.shape}")
        return st > 0
    rec = np.zeros(mdp.n_states, bool)
    pol = np.asarray(pol)
    P = policy_matrices(mdp, pol)[0] if _is_probs(pol) else mdp.P[pol]
    for cl in recurrent_classes(P):
        rec[cl] = True
    return rec


def _check_axes(N: int, axes: Sequence[int], need: int) -> tuple[int, ...]:
    axes = tuple(int(a) for a in axes)
    if len(axes) != need or len(set(axes)) != need or any(not 1 <= a <= N for a in axes):
        raise ModelError(f"axes must be {need} distinct process indices in 1..{N}, got {axes}")
    return axes


def _given_fixed(fixed_tau: Mapping[int, int] | None, caps: Sequence[int], axes: Sequence[int]) -> dict[int, int]:
    """The AoIs given off the axes, checked: 1-based processes not on the axes, values in 1..cap."""
    N = len(caps)
    fixed = {int(k): int(v) for k, v in (fixed_tau or {}).items()}
    for k, v in fixed.items():
        if not 1 <= k <= N or k in axes:
            raise ModelError(f"fixed_tau: process {k} must be in 1..{N} and not on the axes {tuple(axes)}")
        if not 1 <= v <= caps[k - 1]:
            raise ModelError(f"fixed_tau: tau_{k} = {v} outside 1..{caps[k - 1]}")
    return fixed


def _fixed(mdp: MDP, config: int, axes: Sequence[int], fixed_tau: Mapping[int, int] | None,
           weights: np.ndarray | None = None) -> dict[int, int]:
    """Values of the AoIs not on the axes: given, or else the value carrying the most weight
    (e.g. stationary probability, or number of recurrent states) in the configuration, ties and
    weightless configurations broken by the number of reachable cells (then the smaller value)."""
    space = mdp.states
    caps = space.caps
    N = len(caps)
    fixed = _given_fixed(fixed_tau, caps, axes)
    ids = space.lookup_grid(config)
    G = ids >= 0
    W = np.zeros(G.shape) if weights is None else np.where(G, np.asarray(weights, float)[np.maximum(ids, 0)], 0.0)
    for k in range(1, N + 1):
        if k in axes or k in fixed:
            continue
        other = tuple(i for i in range(N) if i != k - 1)
        counts = G.sum(axis=other)
        mass = W.sum(axis=other)
        fixed[k] = int(np.lexsort((-counts, -mass))[0]) + 1
    return fixed


def _weights(mdp: MDP, pol: np.ndarray, stationary: Any) -> np.ndarray | None:
    """Per-state weights for the default fixed AoIs: the stationary distribution if given, else
    the recurrent indicator of the policy's chain (only computed when N > 2)."""
    if len(mdp.states.caps) <= 2 or stationary is False:
        return None
    if stationary is not None:
        return np.asarray(stationary, float)
    return recurrent_mask(mdp, pol, None).astype(float)


def _view(mdp: MDP, policy_or_solution: Any, config: Any, axes: Sequence[int], n_axes: int,
          fixed_tau: Mapping[int, int] | None, stationary: Any) -> tuple[tuple[int, ...], int, np.ndarray, dict[int, int]]:
    """What a map or a slice looks at: ``(axes, configuration id, chosen pair per state, the values of
    the AoIs off the axes)``."""
    N = len(mdp.states.caps)
    axes = _check_axes(N, axes, n_axes)
    c = parse_config_spec(mdp, config)
    chain_pol = _chain_policy(mdp, policy_or_solution)
    pol = policy_pairs(mdp, chain_pol)
    fixed = _fixed(mdp, c, axes, fixed_tau,
                   _weights(mdp, chain_pol, stationary) if len(fixed_tau or {}) < N - n_axes else None)
    return axes, c, pol, fixed


def policy_grid(mdp: MDP, policy_or_solution: Any, config: Any, axes: Sequence[int] = (1, 2),
                fixed_tau: Mapping[int, int] | None = None, stationary: Any = None
                ) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """The chosen action over (tau_i, tau_j) for one configuration (the most likely one for a
    randomised policy).

    The AoIs not on the axes take ``fixed_tau`` or, by default, the value with the most
    stationary probability (``stationary`` given) or the most recurrent states of the policy's
    chain in this configuration (ties: the most reachable cells).

    Returns
    -------
    actions : (cap_i, cap_j) int array
        Action index (row of ``mdp.action_table``) at ``[tau_i - 1, tau_j - 1]``; -1 = unreachable.
    states : (cap_i, cap_j) int array
        State ids (-1 = unreachable).
    fixed : dict
        The values used for the other AoIs (1-based process -> tau).
    """
    space = mdp.states
    N = len(space.caps)
    axes, c, pol, fixed = _view(mdp, policy_or_solution, config, axes, 2, fixed_tau, stationary)
    G = space.lookup_grid(c)
    idx = [slice(None) if k in axes else fixed[k] - 1 for k in range(1, N + 1)]
    S = G[tuple(idx)]
    if axes[0] > axes[1]:
        S = S.T
    A = np.where(S >= 0, mdp.a_indices[pol[np.maximum(S, 0)]], -1)
    return A, S, fixed


def slice_grid(mdp: MDP, policy_or_solution: Any, config: Any, total: int, axes: Sequence[int] = (1, 2, 3),
               fixed_tau: Mapping[int, int] | None = None, stationary: Any = None
               ) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """The chosen action on the plane tau_i + tau_j + tau_k = total.

    Returns
    -------
    actions : (cap_i, cap_j) int array
        Indexed by ``[tau_i - 1, tau_j - 1]`` (tau_k = total - tau_i - tau_j): the action index
        (most likely one for a randomised policy),
        -1 = in the plane but unreachable, -2 = not in the plane (tau_k outside 1..cap_k).
    states : (cap_i, cap_j) int array
        State ids (-1 unreachable or off the plane).
    fixed : dict
        The values of the AoIs not in ``axes``.
    """
    space = mdp.states
    caps = space.caps
    N = len(caps)
    if N < 3:
        raise ModelError(f"a slice tau_i + tau_j + tau_k = total needs 3 processes, this model has {N}")
    axes, c, pol, fixed = _view(mdp, policy_or_solution, config, axes, 3, fixed_tau, stationary)
    i, j, k = axes
    ci, cj, ck = caps[i - 1], caps[j - 1], caps[k - 1]
    if not 3 <= total <= ci + cj + ck:
        raise ModelError(f"total = {total} outside 3..{ci + cj + ck} (the caps are {ci}, {cj}, {ck})")
    G = space.lookup_grid(c)
    A = np.full((ci, cj), -2, dtype=np.int64)
    S = np.full((ci, cj), -1, dtype=np.int64)
    for a in range(1, ci + 1):
        for b in range(1, cj + 1):
            t = total - a - b
            if not 1 <= t <= ck:
                continue
            tau = [0] * N
            for p, v in fixed.items():
                tau[p - 1] = v
            tau[i - 1], tau[j - 1], tau[k - 1] = a, b, t
            s = int(G[tuple(x - 1 for x in tau)])
            S[a - 1, b - 1] = s
            A[a - 1, b - 1] = mdp.a_indices[pol[s]] if s >= 0 else -1
    return A, S, fixed


# ============================================================================ regions
#: Structuring elements of the region counts: 4- and 8-neighbour grids, the triangular lattice.
NEIGHBOURS = {
    "grid4": np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]]),
    "grid8": np.ones((3, 3), int),
    # triangular lattice in (tau_i, tau_j) coordinates: (+-1, 0), (0, +-1), (+1, -1), (-1, +1)
    "tri6": np.array([[0, 1, 1], [1, 1, 1], [1, 1, 0]]),
}
#: The dual connectivity of each, for the holes of a region.
DUAL_NEIGHBOURS = {"grid4": "grid8", "grid8": "grid4", "tri6": "tri6"}


def region_stats(labels_or_mdp: Any, policy_or_solution: Any = None, config: Any = None, *,
                 axes: Sequence[int] | None = None, fixed_tau: Mapping[int, int] | None = None,
                 total: int | None = None, connectivity: str | None = None, scenario: Any = None,
                 stationary: Any = None) -> dict:
    """Number of regions of each action and whether each is connected / simply connected.

    Two ways to call it:

    * ``region_stats(labels, connectivity="grid4")`` on a 2-D integer array of action ids,
      with -1 for an unreachable cell and -2 for a cell outside the domain;
    * ``region_stats(mdp, solution, config, axes=(1, 2), fixed_tau=..., stationary=...)`` for a
      2-D map (the other AoIs chosen as in :func:`policy_grid` unless fixed)
      on the grid (4-neighbour), or ``region_stats(mdp, solution, config, total=T, axes=(1, 2, 3))``
      for a slice (triangular lattice, 6-neighbour: on the plane sum = T the lattice points
      adjacent to (t_i, t_j, t_k) are those moving one unit between two coordinates).

    A *region* of action a is a connected component of the cells choosing a. Unreachable cells
    belong to no region; ``components_bridging_unreachable`` counts the components when
    unreachable cells may join them. A *hole* of a region is a connected component (dual
    connectivity: 8-neighbour for grid4, 6 for tri6) of the cells not choosing a that does not
    touch the domain's border; unreachable cells are counted as the region's own for holes.
    ``simply_connected`` = one component and no hole. ``components_grid8`` is the loosest count
    (8-neighbour in the array's (tau_i, tau_j) indices, so diagonal touching joins), to tell a
    staircase boundary strip apart from truly separate regions.

    Returns
    -------
    dict
        ``connectivity``, ``cells`` (in the domain), ``unreachable``, ``actions_present``,
        ``regions_total`` and ``per_action`` ``{name: {"action": index, "cells", "components",
        "component_sizes", "connected", "holes", "simply_connected",
        "components_bridging_unreachable"}}``.
    """
    from scipy import ndimage

    names: dict[int, str] = {}
    fixed: dict[int, int] | None = None
    if isinstance(labels_or_mdp, MDP):
        mdp = labels_or_mdp
        if policy_or_solution is None or config is None:
            raise ModelError("region_stats(mdp, ...) needs the policy (or solution) and the configuration")
        if total is None:
            lab, _, fixed = policy_grid(mdp, policy_or_solution, config, axes or (1, 2), fixed_tau, stationary)
            connectivity = connectivity or "grid4"
        else:
            lab, _, fixed = slice_grid(mdp, policy_or_solution, config, total, axes or (1, 2, 3), fixed_tau,
                                       stationary)
            connectivity = connectivity or "tri6"
        info = map_names(mdp, scenario)
        cid = parse_config_spec(mdp, config)
        names = {int(a): action_name(mdp, int(a), cid, names=info) for a in np.unique(lab[lab >= 0])}
    else:
        lab = np.asarray(labels_or_mdp)
        connectivity = connectivity or "grid4"
    if lab.ndim != 2 or not np.issubdtype(lab.dtype, np.integer):
        raise ModelError(f"labels must be a 2-D integer array, got shape {lab.shape} and dtype {lab.dtype}")
    if connectivity not in NEIGHBOURS:
        raise ModelError(f"connectivity must be one of {sorted(NEIGHBOURS)}, got {connectivity!r}")
    st, dual = NEIGHBOURS[connectivity], NEIGHBOURS[DUAL_NEIGHBOURS[connectivity]]
    domain = lab != -2
    unreach = lab == -1
    padded_dom = np.pad(domain, 1, constant_values=False)
    out: dict[str, Any] = {
        "connectivity": connectivity,
        "cells": int(domain.sum()),
        "unreachable": int(unreach.sum()),
        "per_action": {},
    }
    if fixed is not None:
        out["fixed_tau"] = {str(k): v for k, v in sorted(fixed.items())}
    total_regions = 0
    for a in np.unique(lab[lab >= 0]):
        mask = lab == a
        comp, ncomp = ndimage.label(mask, structure=st)
        sizes = sorted((int(x) for x in np.bincount(comp.ravel())[1:]), reverse=True)
        _, ndiag = ndimage.label(mask, structure=NEIGHBOURS["grid8"])
        br, nbr = ndimage.label(mask | unreach, structure=st)
        bridged = int(np.unique(br[mask]).size)
        filled = np.pad(mask | unreach, 1, constant_values=False)
        comp_c, nc = ndimage.label(~filled, structure=dual)
        outside_labels = set(np.unique(comp_c[~padded_dom]).tolist()) - {0}
        holes = len(set(range(1, nc + 1)) - outside_labels)
        key = names.get(int(a), str(int(a)))
        out["per_action"][key] = {
            "action": int(a),
            "cells": int(mask.sum()),
            "components": int(ncomp),
            "component_sizes": sizes,
            "connected": ncomp == 1,
            "holes": int(holes),
            "simply_connected": ncomp == 1 and holes == 0,
            "components_bridging_unreachable": bridged,
            "components_grid8": int(ndiag),
        }
        total_regions += int(ncomp)
    out["actions_present"] = len(out["per_action"])
    out["regions_total"] = total_regions
    return out


# ============================================================================ matrix-free policies
def matrix_free_grid(policy: Any, config: Any, axes: Sequence[int] = (1, 2),
                     fixed_tau: Mapping[int, int] | None = None) -> tuple[np.ndarray, list, dict[int, int], int]:
    """The chosen action over (tau_i, tau_j) of a matrix-free policy, for one configuration.

    The policy is a :class:`~wncs_lp.policies.MatrixFreePolicy` (``system``, ``layout``,
    ``table``: one local action index per state of the configuration's AoI box, no MDP). The
    AoIs not on the axes take ``fixed_tau`` or, by default, the *lower end* of the box of this
    configuration (the freshest value it can hold: there is no stationary law to choose by at
    this scale; pass ``fixed_tau`` for another).

    Returns
    -------
    actions : (cap_i, cap_j) int array
        Local action index (into ``labels``) at ``[tau_i - 1, tau_j - 1]``; -1 = outside the
        configuration's box (not reachable with this configuration).
    labels : list of tuples
        The configuration's action labels (``system.automaton.actions[c]``).
    fixed : dict
        The values used for the other AoIs (1-based process -> tau).
    config : int
        The configuration id.
    """
    system, layout, table = policy.system, policy.layout, policy.table
    caps = [int(c) for c in system.caps]
    N = len(caps)
    axes = _check_axes(N, axes, 2)
    c = system_config(system, config)
    lo, dims = layout.lo[c], layout.dims[c]
    fixed = _given_fixed(fixed_tau, caps, axes)
    for k, v in fixed.items():
        if not lo[k - 1] + 1 <= v <= lo[k - 1] + dims[k - 1]:
            raise ModelError(f"fixed_tau: tau_{k} = {v} is not reachable with this configuration "
                             f"(it holds tau_{k} in {lo[k - 1] + 1}..{lo[k - 1] + dims[k - 1]})")
    for k in range(1, N + 1):
        if k not in axes and k not in fixed:
            fixed[k] = int(lo[k - 1]) + 1
    i, j = axes
    ti, tj = np.meshgrid(np.arange(1, caps[i - 1] + 1), np.arange(1, caps[j - 1] + 1), indexing="ij")
    tau = np.empty((ti.size, N), np.int64)
    for k in range(1, N + 1):
        tau[:, k - 1] = ti.ravel() if k == i else (tj.ravel() if k == j else fixed[k])
    idx = layout.index(tau, np.full(ti.size, c, np.int64))
    A = np.where(idx >= 0, table[np.maximum(idx, 0)].astype(np.int64), -1).reshape(ti.shape)
    return A, list(system.automaton.actions[c]), fixed, c


def matrix_free_region_stats(policy: Any, config: Any, axes: Sequence[int] = (1, 2),
                             fixed_tau: Mapping[int, int] | None = None) -> dict:
    """:func:`region_stats` of a matrix-free policy's map (:func:`matrix_free_grid`), with the
    actions named and ``configuration``, ``configuration_id`` and ``fixed_tau`` added."""
    A, labels, fixed, c = matrix_free_grid(policy, config, axes, fixed_tau)
    system = policy.system
    conf = system.automaton.configs[c]
    info = system_names(system)
    out = region_stats(A, connectivity="grid4")
    out["per_action"] = {info["model"].action_name(tuple(int(x) for x in np.atleast_1d(labels[int(k)])), conf, info): v
                         for k, v in out["per_action"].items()}
    out.update(configuration=system.model.describe(conf), configuration_id=int(c),
               fixed_tau={str(k): v for k, v in sorted(fixed.items())})
    return out

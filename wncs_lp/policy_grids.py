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
  model (:meth:`wncs_lp.models.base.Model.action_name`);
* :func:`map_view` -- what a map reads (:class:`MapView`), on either state space.

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

State spaces
------------
Every map reads its states through one interface, :mod:`wncs_lp.spaces`: an MDP's state table
(:class:`~wncs_lp.spaces.EnumeratedSpace`) or a matrix-free solve's AoI box
(:class:`~wncs_lp.spaces.BoxSpace`). :func:`policy_grid` and :func:`region_stats` take either
(an MDP, a space, or a matrix-free solution or policy); :func:`map_view` is what both read.
:func:`matrix_free_grid` and :func:`matrix_free_region_stats` are :func:`policy_grid` and
:func:`region_stats` on the box with the box's own return values. A ``config`` argument is a
configuration spec: its id, object, ``"idle"``, ``"#17"``, a literal or its description (the
syntax: :mod:`wncs_lp.spaces`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .chain import PROB_SUM_TOL, policy_matrices, recurrent_classes
from .errors import ModelError, PolicyError
from .mdp import MDP
from .spaces import BoxSpace, EnumeratedSpace, Space, map_names, space_of, system_config, system_names

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
    "MapView",
    "map_view",
]

# ============================================================================ names
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
def parse_config_spec(mdp: MDP, spec: Any) -> int:
    """The configuration id named by ``spec`` (the syntax: :mod:`wncs_lp.spaces`).

    Raises
    ------
    ModelError
        When the spec names no reachable configuration; the message lists close matches.
    """
    return space_of(mdp).config_id(spec)


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


def _fixed(space: Space, c: int, axes: Sequence[int], fixed_tau: Mapping[int, int] | None,
           weights: np.ndarray | None = None) -> dict[int, int]:
    """Values of the AoIs not on the axes: given (within the configuration's range), or else the value
    carrying the most weight (e.g. stationary probability, or number of recurrent states) in the
    configuration, ties and weightless configurations broken by the number of its states (then the
    smaller value; on an AoI box, whose values all hold as many states, its lower end)."""
    fixed = _given_fixed(fixed_tau, space.caps, axes)
    low, high = space.box(c)
    for k, v in fixed.items():
        if not low[k - 1] <= v <= high[k - 1]:
            raise ModelError(f"fixed_tau: tau_{k} = {v} is not reachable with this configuration "
                             f"(it holds tau_{k} in {low[k - 1]}..{high[k - 1]})")
    if len(fixed) == space.n_processes - len(axes):
        return fixed
    counts, mass = space.value_counts(c, weights)
    for k in range(1, space.n_processes + 1):
        if k not in axes and k not in fixed:
            fixed[k] = int(np.lexsort((-counts[k - 1], -mass[k - 1]))[0]) + 1
    return fixed


def _weights(mdp: MDP, pol: np.ndarray, stationary: Any) -> np.ndarray | None:
    """Per-state weights for the default fixed AoIs: the stationary distribution if given, else
    the recurrent indicator of the policy's chain (only computed when N > 2)."""
    if len(mdp.states.caps) <= 2 or stationary is False:
        return None
    if stationary is not None:
        return np.asarray(stationary, float)
    return recurrent_mask(mdp, pol, None).astype(float)


def _box_table(space: BoxSpace, policy: Any) -> np.ndarray:
    """A matrix-free policy's local action per layout state (a MatrixFreePolicy, a MatrixFreeSolution or
    the array), checked against the layout."""
    table = np.asarray(getattr(policy, "table", getattr(policy, "local_actions", policy)))
    if table.shape != (space.layout.n_states,) or not np.issubdtype(table.dtype, np.integer):
        raise ModelError(f"a matrix-free policy is one local action index per layout state, shape "
                         f"({space.layout.n_states},); got shape {table.shape} and dtype {table.dtype}")
    return table


@dataclass(frozen=True, eq=False)
class MapView:
    """What a policy map looks at, on either state space (:mod:`wncs_lp.spaces`).

    Attributes
    ----------
    space : Space
    config : int
        The configuration id.
    axes : tuple of int
        The 1-based processes on the axes.
    fixed : dict
        The values of the AoIs off the axes (1-based process -> tau).
    policy : array
        The policy in the space's form: the chosen (most likely) pair per state, or the local
        action per layout state.
    probabilities : (L,) array or None
        A randomised policy's pair probabilities (enumerated spaces only).
    chain : array or None
        What the policy's chain is built from (its probabilities or its pairs); None on an AoI box,
        where no chain is formed.
    """

    space: Space
    config: int
    axes: tuple[int, ...]
    fixed: dict
    policy: np.ndarray
    probabilities: np.ndarray | None
    chain: np.ndarray | None

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """``(actions, states)`` over (tau_i, tau_j), ``[tau_i - 1, tau_j - 1]``; -1 where there is no state."""
        S = self.space.slice_states(self.config, self.axes, self.fixed)
        return _actions(self, S), S

    def plane(self, total: int) -> tuple[np.ndarray, np.ndarray]:
        """``(actions, states)`` on the plane tau_i + tau_j + tau_k = total (three axes), indexed
        ``[tau_i - 1, tau_j - 1]``: -1 where the plane holds no state, actions -2 off the plane."""
        caps, N = self.space.caps, self.space.n_processes
        i, j, k = self.axes
        ci, cj, ck = caps[i - 1], caps[j - 1], caps[k - 1]
        if not 3 <= total <= ci + cj + ck:
            raise ModelError(f"total = {total} outside 3..{ci + cj + ck} (the caps are {ci}, {cj}, {ck})")
        ti, tj = np.meshgrid(np.arange(1, ci + 1), np.arange(1, cj + 1), indexing="ij")
        tk = total - ti - tj
        on = (tk >= 1) & (tk <= ck)
        tau = np.empty((int(on.sum()), N), np.int64)
        for p in range(1, N + 1):
            tau[:, p - 1] = ti[on] if p == i else tj[on] if p == j else tk[on] if p == k else self.fixed[p]
        S = np.full((ci, cj), -1, dtype=np.int64)
        S[on] = self.space.lookup(tau, self.config)
        return np.where(on, _actions(self, S), -2), S

    def recurrent(self, stationary: Any = None) -> np.ndarray | None:
        """The states with positive stationary probability (:func:`recurrent_mask`); None on an AoI box
        (no stationary law is known there) or with ``stationary=False``."""
        if self.chain is None:
            return None
        return recurrent_mask(self.space.mdp, self.chain, stationary)


def map_view(mdp_or_space: Any, policy_or_solution: Any, config: Any, axes: Sequence[int] = (1, 2),
             fixed_tau: Mapping[int, int] | None = None, stationary: Any = None, *, plane: bool = False) -> MapView:
    """The configuration, the values off the axes and the policy's form a map or a slice reads.

    ``mdp_or_space``: an MDP, a :class:`~wncs_lp.spaces.Space`, or a matrix-free solution or
    policy (its AoI box). ``axes``: two processes (a map), or three with ``plane=True`` (a slice,
    :meth:`MapView.plane`).
    """
    space = space_of(mdp_or_space)
    N = space.n_processes
    if plane and N < 3:
        raise ModelError(f"a slice tau_i + tau_j + tau_k = total needs 3 processes, this model has {N}")
    axes = _check_axes(N, axes, 3 if plane else 2)
    c = space.config_id(config)
    if isinstance(space, EnumeratedSpace):
        mdp = space.mdp
        chain = _chain_policy(mdp, policy_or_solution)
        probs = chain if _is_probs(chain) else None
        pol = policy_pairs(mdp, chain)
        missing = len(fixed_tau or {}) < space.n_processes - len(axes)
        fixed = _fixed(space, c, axes, fixed_tau, _weights(mdp, chain, stationary) if missing else None)
        return MapView(space, c, axes, fixed, pol, probs, chain)
    table = _box_table(space, policy_or_solution)
    return MapView(space, c, axes, _fixed(space, c, axes, fixed_tau), table, None, None)


def _actions(view: MapView, S: np.ndarray) -> np.ndarray:
    """The policy's action index at state indices S (-1 kept for no state)."""
    return np.where(S >= 0, view.space.actions_at(view.policy, np.maximum(S, 0)), -1)


def policy_grid(mdp: Any, policy_or_solution: Any, config: Any, axes: Sequence[int] = (1, 2),
                fixed_tau: Mapping[int, int] | None = None, stationary: Any = None
                ) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """The chosen action over (tau_i, tau_j) for one configuration (the most likely one for a
    randomised policy).

    ``mdp`` is an MDP or any state space of :mod:`wncs_lp.spaces` (a matrix-free solution or
    policy: its AoI box; then the policy is its local action table). The AoIs not on the axes take
    ``fixed_tau`` or, by default, the value with the most stationary probability (``stationary``
    given) or the most recurrent states of the policy's chain in this configuration (ties: the
    most reachable cells; on an AoI box, where no stationary law is known, the lower end of the
    configuration's box).

    Returns
    -------
    actions : (cap_i, cap_j) int array
        Action index (the space's: a row of ``mdp.action_table``, or a local index into the
        configuration's actions) at ``[tau_i - 1, tau_j - 1]``; -1 = no state (unreachable).
    states : (cap_i, cap_j) int array
        State ids (-1 = unreachable).
    fixed : dict
        The values used for the other AoIs (1-based process -> tau).
    """
    view = map_view(mdp, policy_or_solution, config, axes, fixed_tau, stationary)
    return (*view.grid(), view.fixed)


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
    view = map_view(mdp, policy_or_solution, config, axes, fixed_tau, stationary, plane=True)
    return (*view.plane(total), view.fixed)


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
    if isinstance(labels_or_mdp, (MDP, Space)):
        space = space_of(labels_or_mdp)
        if policy_or_solution is None or config is None:
            raise ModelError("region_stats(mdp, ...) needs the policy (or solution) and the configuration")
        if total is None:
            lab, _, fixed = policy_grid(space, policy_or_solution, config, axes or (1, 2), fixed_tau, stationary)
            connectivity = connectivity or "grid4"
        else:
            lab, _, fixed = slice_grid(space, policy_or_solution, config, total, axes or (1, 2, 3), fixed_tau,
                                       stationary)
            connectivity = connectivity or "tri6"
        info = space.names(scenario)
        cid = space.config_id(config)
        names = {int(a): space.action_name(cid, int(a), info) for a in np.unique(lab[lab >= 0])}
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
    """The chosen action over (tau_i, tau_j) of a matrix-free policy, for one configuration:
    :func:`policy_grid` on the policy's AoI box (:class:`~wncs_lp.spaces.BoxSpace`).

    The policy is a :class:`~wncs_lp.policies.MatrixFreePolicy` or a matrix-free solution (one
    local action index per state of the configuration's AoI box, no MDP). The AoIs not on the
    axes take ``fixed_tau`` or, by default, the *lower end* of the box of this configuration (the
    freshest value it can hold: there is no stationary law to choose by at this scale).

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
    space = space_of(policy)
    A, _, fixed = policy_grid(space, policy, config, axes, fixed_tau)
    c = space.config_id(config)
    return A, list(space.system.automaton.actions[c]), fixed, c


def matrix_free_region_stats(policy: Any, config: Any, axes: Sequence[int] = (1, 2),
                             fixed_tau: Mapping[int, int] | None = None) -> dict:
    """:func:`region_stats` of a matrix-free policy's map on its AoI box, with ``configuration`` and
    ``configuration_id`` added."""
    space = space_of(policy)
    out = region_stats(space, policy, config, axes=axes, fixed_tau=fixed_tau)
    c = space.config_id(config)
    return {**out, "configuration": space.describe(c), "configuration_id": int(c)}

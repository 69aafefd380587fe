r"""Policy maps: the optimal action over the AoI box, as in the paper's Figs. 3-4, 6-9 and 11-12.

* :func:`plot_policy_map` -- the action over (tau_i, tau_j) for one configuration (server state)
  with the other AoIs fixed;
* :func:`plot_policy_slice` -- three processes on the plane tau_i + tau_j + tau_k = total, drawn
  as a triangle in barycentric coordinates (Figs. 6-7);
* :func:`region_stats` -- number of connected regions of each action and whether each is
  (simply) connected, on the grid (4-neighbour) or on the triangular lattice of a slice
  (6-neighbour);
* :func:`parse_config_spec` -- a configuration from a short text (used by ``wncs-lp map``).

Process indices (``axes``, ``fixed_tau``) are **1-based** like the paper's tau_1, tau_2, ...

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

from .errors import ModelError
from .mdp import MDP

__all__ = [
    "ACTION_STYLES",
    "parse_config_spec",
    "action_name",
    "policy_grid",
    "slice_grid",
    "region_stats",
    "plot_policy_map",
    "plot_policy_slice",
]

#: (marker, colour) per action index (row of ``mdp.action_table``), cycled.
ACTION_STYLES: list[tuple[str, str]] = [
    ("x", "tab:blue"),
    ("o", "tab:red"),
    ("s", "tab:green"),
    ("^", "tab:orange"),
    ("D", "tab:purple"),
    ("v", "tab:brown"),
    ("P", "tab:pink"),
    ("*", "tab:olive"),
    ("h", "tab:cyan"),
    ("<", "black"),
]
_FILLED_ALPHA = 0.85
_TRANSIENT_BG = "#dcdcdc"
_UNREACHABLE_BG = "#7f7f7f"


# ============================================================================ names
def _style(a: int) -> tuple[str, str]:
    return ACTION_STYLES[int(a) % len(ACTION_STYLES)]


def _short_process(name: str, k: int) -> str:
    m = re.fullmatch(r"(?i)process[-_ ]?(\w+)", name.strip())
    return m.group(1) if m else name


def _context(mdp: MDP, scenario: Any = None) -> dict:
    """Names and parameters for labels: processes, servers, p, scenario name, kind."""
    N = len(mdp.states.caps)
    kind = mdp.meta.get("kind", "wncs") if isinstance(mdp.meta, dict) else "wncs"
    info = {"processes": [str(k) for k in range(1, N + 1)], "servers": None, "p": None,
            "name": Path(str(mdp.meta.get("source", mdp.name))).stem, "kind": kind}
    sc = scenario
    if sc is None and mdp.meta.get("source"):
        try:  # names only; p only if the file without overrides is this very model
            from .scenario import load_scenario

            sc0 = load_scenario(mdp.meta["source"])
            info["processes"] = [_short_process(p.name, k) for k, p in enumerate(sc0.processes, 1)]
            info["servers"] = [s.name for s in sc0.servers]
            if sc0.fingerprint() == mdp.meta.get("fingerprint"):
                info["p"] = sc0.p
        except Exception:
            pass
    elif sc is not None:
        info["processes"] = [_short_process(p.name, k) for k, p in enumerate(sc.processes, 1)]
        info["servers"] = [s.name for s in sc.servers]
        info["p"] = sc.p
        info["name"] = Path(str(sc.source)).stem
    if info["servers"] is None and kind == "wncs" and mdp.states.configs:
        M = len(mdp.states.configs[0])
        info["servers"] = [f"server {m}" for m in range(1, M + 1)]
    return info


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
    names = names or _context(mdp, scenario)
    if isinstance(action, (int, np.integer)):
        label = tuple(int(x) for x in np.atleast_1d(mdp.action_table[int(action)]))
    else:
        label = tuple(int(x) for x in action)
    procs = names["processes"]
    if names["kind"] == "preemption":
        a = label[0]
        job = None
        if config is not None:
            conf = mdp.states.configs[int(config)] if isinstance(config, (int, np.integer)) else config
            job = conf[1]
        if a == 0:
            if config is None:
                return "keep going (no new job)"
            return "stay idle" if job is None else f"keep going (serve {procs[job[0] - 1]})"
        if job is None:
            return f"start {procs[a - 1]}" if config is not None else f"start {procs[a - 1]} (preempting if busy)"
        if job[0] == a:
            return f"restart {procs[a - 1]} (cancel)"
        return f"{procs[a - 1]} preempts {procs[job[0] - 1]}"
    servers = names["servers"] or [f"server {m}" for m in range(1, len(label) + 1)]
    parts = [f"{procs[k - 1]} to {servers[m]}" for m, k in enumerate(label) if k]
    return "(" + ", ".join(parts) + ")" if parts else "(send nothing)"


def _short_action(mdp: MDP, a: int, names: dict) -> str:
    label = tuple(int(x) for x in np.atleast_1d(mdp.action_table[int(a)]))
    procs = names["processes"]
    if names["kind"] == "preemption":
        return "keep" if label[0] == 0 else f"start {procs[label[0] - 1]}"
    return "(" + ",".join(procs[k - 1] if k else "-" for k in label) + ")"


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
    configs = space.configs
    if isinstance(spec, (int, np.integer)):
        if not 0 <= int(spec) < len(configs):
            raise ModelError(f"configuration id {spec} out of range 0..{len(configs) - 1}")
        return int(spec)
    if not isinstance(spec, str):
        c = space.config_id(_tuplify(spec))
        if c < 0:
            raise ModelError(f"configuration {spec!r} is not reachable in {mdp.name}")
        return c
    text = spec.strip()
    if text.lower() == "idle":
        ids = [i for i, c in enumerate(configs) if _is_idle(c)]
        if len(ids) == 1:
            return ids[0]
        if not ids:
            raise ModelError(f"{mdp.name}: no configuration with every server idle")
        raise ModelError(f"{mdp.name}: 'idle' is ambiguous ({len(ids)} configurations); give the description, "
                         f"e.g. {space.describe_config(configs[ids[0]])!r}")
    if text.startswith("#") and text[1:].strip().isdigit():
        return parse_config_spec(mdp, int(text[1:]))
    if text[:1] in "([":
        try:
            obj = _tuplify(ast.literal_eval(text))
        except (ValueError, SyntaxError) as exc:
            raise ModelError(f"configuration literal {text!r} is not a valid Python literal: {exc}") from None
        c = space.config_id(obj)
        if c < 0:
            raise ModelError(f"configuration {obj!r} is not reachable in {mdp.name}")
        return c
    descs = [space.describe_config(c) for c in configs]
    target = _norm(text)
    normed = [_norm(d) for d in descs]
    if target in normed:
        return normed.index(target)
    # Section II: servers not named are idle
    if configs and isinstance(configs[0], tuple) and all(isinstance(x, tuple) and len(x) == 4 for x in configs[0]):
        idle_desc = next((d for c, d in zip(configs, descs) if _is_idle(c)), None)
        if idle_desc is not None:
            server_names = [p.split(":")[0].strip().lower() for p in idle_desc.split(";")]
            given = {}
            for part in text.split(";"):
                if ":" in part:
                    nm, rest = part.split(":", 1)
                    given[nm.strip().lower()] = rest
            if given and set(given) <= set(server_names):
                full = "; ".join(f"{nm}: {given.get(nm, 'idle')}" for nm in server_names)
                if _norm(full) in normed:
                    return normed.index(_norm(full))
    close = difflib.get_close_matches(target, normed, n=6, cutoff=0.5)
    hint = "; ".join(repr(descs[normed.index(c)]) for c in close) or "none close"
    raise ModelError(f"no reachable configuration matches {text!r} in {mdp.name}; close matches: {hint}")


def _is_idle(c: Any) -> bool:
    if hasattr(c, "_fields"):  # preemption
        return c[1] is None and not c[2] and all(x is None for x in c[3])
    try:
        return all(job == 0 and d == 0 and not any(up) and not any(down) for (up, job, d, down) in c)
    except (TypeError, ValueError):
        return False


# ============================================================================ grids
def _policy_pairs(mdp: MDP, policy_or_solution: Any) -> np.ndarray:
    pol = getattr(policy_or_solution, "policy", policy_or_solution)
    pol = np.asarray(pol)
    if pol.shape != (mdp.n_states,) or not np.issubdtype(pol.dtype, np.integer):
        raise ModelError(f"policy must be a Solution or an integer array of pair indices of shape ({mdp.n_states},)")
    if pol.min() < 0 or pol.max() >= mdp.n_pairs or np.any(mdp.s_indices[pol] != np.arange(mdp.n_states)):
        raise ModelError("policy holds a pair index that does not belong to its state")
    return pol.astype(np.int64)


def _recurrent_mask(mdp: MDP, policy_or_solution: Any, pol: np.ndarray, stationary: Any) -> np.ndarray | None:
    """States with positive stationary probability under the policy.

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
    from .solvers.dp import recurrent_classes

    rec = np.zeros(mdp.n_states, bool)
    for cl in recurrent_classes(mdp.P[pol]):
        rec[cl] = True
    return rec


def _check_axes(N: int, axes: Sequence[int], need: int) -> tuple[int, ...]:
    axes = tuple(int(a) for a in axes)
    if len(axes) != need or len(set(axes)) != need or any(not 1 <= a <= N for a in axes):
        raise ModelError(f"axes must be {need} distinct process indices in 1..{N}, got {axes}")
    return axes


def _fixed(mdp: MDP, config: int, axes: Sequence[int], fixed_tau: Mapping[int, int] | None,
           weights: np.ndarray | None = None) -> dict[int, int]:
    """Values of the AoIs not on the axes: given, or else the value carrying the most weight
    (e.g. stationary probability, or number of recurrent states) in the configuration, ties and
    weightless configurations broken by the number of reachable cells (then the smaller value)."""
    space = mdp.states
    caps = space.caps
    N = len(caps)
    fixed = {int(k): int(v) for k, v in (fixed_tau or {}).items()}
    for k, v in fixed.items():
        if not 1 <= k <= N or k in axes:
            raise ModelError(f"fixed_tau: process {k} must be in 1..{N} and not on the axes {tuple(axes)}")
        if not 1 <= v <= caps[k - 1]:
            raise ModelError(f"fixed_tau: tau_{k} = {v} outside 1..{caps[k - 1]}")
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
    return _recurrent_mask(mdp, pol, pol, None).astype(float)


def policy_grid(mdp: MDP, policy_or_solution: Any, config: Any, axes: Sequence[int] = (1, 2),
                fixed_tau: Mapping[int, int] | None = None, stationary: Any = None
                ) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """The chosen action over (tau_i, tau_j) for one configuration.

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
    axes = _check_axes(N, axes, 2)
    c = parse_config_spec(mdp, config)
    pol = _policy_pairs(mdp, policy_or_solution)
    fixed = _fixed(mdp, c, axes, fixed_tau, _weights(mdp, pol, stationary) if len(fixed_tau or {}) < N - 2 else None)
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
        Indexed by ``[tau_i - 1, tau_j - 1]`` (tau_k = total - tau_i - tau_j): the action index,
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
    axes = _check_axes(N, axes, 3)
    c = parse_config_spec(mdp, config)
    pol = _policy_pairs(mdp, policy_or_solution)
    fixed = _fixed(mdp, c, axes, fixed_tau,
                   _weights(mdp, pol, stationary) if len(fixed_tau or {}) < N - 3 else None)
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
_STRUCT = {
    "grid4": np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]]),
    "grid8": np.ones((3, 3), int),
    # triangular lattice in (tau_i, tau_j) coordinates: (+-1, 0), (0, +-1), (+1, -1), (-1, +1)
    "tri6": np.array([[0, 1, 1], [1, 1, 1], [1, 1, 0]]),
}
_DUAL = {"grid4": "grid8", "grid8": "grid4", "tri6": "tri6"}


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
        info = _context(mdp, scenario)
        cid = parse_config_spec(mdp, config)
        names = {int(a): action_name(mdp, int(a), cid, names=info) for a in np.unique(lab[lab >= 0])}
    else:
        lab = np.asarray(labels_or_mdp)
        connectivity = connectivity or "grid4"
    if lab.ndim != 2 or not np.issubdtype(lab.dtype, np.integer):
        raise ModelError(f"labels must be a 2-D integer array, got shape {lab.shape} and dtype {lab.dtype}")
    if connectivity not in _STRUCT:
        raise ModelError(f"connectivity must be one of {sorted(_STRUCT)}, got {connectivity!r}")
    st, dual = _STRUCT[connectivity], _STRUCT[_DUAL[connectivity]]
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
        _, ndiag = ndimage.label(mask, structure=_STRUCT["grid8"])
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


# ============================================================================ plots
def _tau(k: int, info: dict) -> str:
    """Mathtext tau with the process's short name as subscript when it is short, else its index."""
    nm = info["processes"][k - 1]
    sub = nm if re.fullmatch(r"\w{1,3}", nm) else str(k)
    return rf"$\tau_{{{sub}}}$"


def _title(info: dict, mdp: MDP, config: int, extra: str) -> str:
    desc = mdp.states.describe_config(mdp.states.configs[config])
    caps = mdp.states.caps
    par = [f"cap {caps[0]}" if len(set(caps)) == 1 else "caps " + ",".join(map(str, caps))]
    if info.get("p") is not None:
        par.insert(0, f"p = {info['p']:g}")
    return f"{info['name']}: policy in [{desc}]\n{extra}{', '.join(par)}"


def _ticks(ax, cap_x: int, cap_y: int) -> None:
    step = lambda c: 1 if c <= 15 else (2 if c <= 30 else 5)  # noqa: E731
    ax.set_xticks(range(1, cap_x + 1, step(cap_x)))
    ax.set_yticks(range(1, cap_y + 1, step(cap_y)))


def plot_policy_map(
    mdp: MDP,
    policy_or_solution: Any,
    config: Any,
    axes: Sequence[int] = (1, 2),
    fixed_tau: Mapping[int, int] | None = None,
    ax: Any = None,
    stationary: Any = None,
    *,
    scenario: Any = None,
    title: str | None = None,
    legend: bool = True,
) -> Any:
    r"""Draw the chosen action over (tau_i, tau_j) for one configuration (paper Figs. 3, 4, 8, 9, 11, 12).

    Each reachable cell carries the action's marker (one marker/colour per action, consistent
    across maps of one MDP); the background is white for states with positive stationary
    probability under the policy, light grey for states with zero stationary probability
    (transient), dark grey for unreachable cells.

    Parameters
    ----------
    mdp : MDP
    policy_or_solution : Solution or (n,) int array of pair indices
    config : configuration (id, object or spec string, see :func:`parse_config_spec`)
    axes : (i, j)
        1-based processes on the x and y axes.
    fixed_tau : {k: tau_k}, optional
        The other AoIs (default: the value with the most stationary probability, or the most
        recurrent states, in this configuration; see :func:`policy_grid`).
    ax : matplotlib Axes, optional
    stationary : (n,) array, False or None
        Stationary distribution for the shading (``> 0`` = recurrent); None (default) uses the
        exact graph criterion (closed communicating classes of the policy's chain); False
        disables the shading.
    scenario : Scenario, optional
        For process/server names and p in labels (default: read from ``mdp.meta["source"]``).
    title : str, optional
    legend : bool

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    cid = parse_config_spec(mdp, config)
    pol = _policy_pairs(mdp, policy_or_solution)
    A, S, fixed = policy_grid(mdp, pol, cid, axes, fixed_tau, stationary)
    rec_mask = _recurrent_mask(mdp, policy_or_solution, pol, stationary)
    info = _context(mdp, scenario)
    if ax is None:
        _, ax = plt.subplots(figsize=(8.6, 6.2))
    ci, cj = A.shape
    bg = np.ones((cj, ci, 3))
    reach = S >= 0
    if rec_mask is not None:
        trans = reach & ~rec_mask[np.maximum(S, 0)]
        bg[trans.T] = np.array([0xDC, 0xDC, 0xDC]) / 255
    bg[(~reach).T] = np.array([0x7F, 0x7F, 0x7F]) / 255
    ax.imshow(bg, origin="lower", extent=(0.5, ci + 0.5, 0.5, cj + 0.5), interpolation="nearest", aspect="auto")
    n_cells = max(ci, cj)
    ms = max(3.0, min(9.0, 160.0 / n_cells))
    handles = []
    for a in np.unique(A[A >= 0]):
        xs, ys = np.nonzero(A == a)
        mk, col = _style(a)
        ax.plot(xs + 1, ys + 1, linestyle="none", marker=mk, color=col, markersize=ms,
                markerfacecolor=col if mk not in ("x", "+") else None, alpha=_FILLED_ALPHA,
                markeredgewidth=1.4 if mk in ("x", "+") else 0.6)
        n = int(xs.size)
        handles.append(Line2D([], [], linestyle="none", marker=mk, color=col, markersize=7,
                              label=f"{action_name(mdp, int(a), cid, names=info)}  [{n} cells]"))
    if rec_mask is not None:
        handles.append(Patch(facecolor=_TRANSIENT_BG, edgecolor="0.5", label="zero stationary probability"))
    if (~reach).any():
        handles.append(Patch(facecolor=_UNREACHABLE_BG, edgecolor="0.3", label="unreachable state"))
    i, j = axes
    pn = info["processes"]
    ax.set_xlabel(f"{_tau(i, info)}  (AoI of process {pn[i - 1]})")
    ax.set_ylabel(f"{_tau(j, info)}  (AoI of process {pn[j - 1]})")
    ax.set_xlim(0.5, ci + 0.5)
    ax.set_ylim(0.5, cj + 0.5)
    _ticks(ax, ci, cj)
    extra = ", ".join(f"{_tau(k, info)} = {v}" for k, v in sorted(fixed.items()))
    ax.set_title(title or _title(info, mdp, cid, (extra + ", ") if extra else ""), fontsize=10)
    if legend:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8.5,
                  title="action", title_fontsize=9, frameon=True)
    return ax


def _bary(t_i: np.ndarray, t_j: np.ndarray, t_k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric -> plane: vertex of tau_i at (0, 0), tau_j at (1, 0), tau_k at (1/2, sqrt(3)/2)."""
    tot = t_i + t_j + t_k
    return (t_j + 0.5 * t_k) / tot, (np.sqrt(3) / 2) * t_k / tot


def plot_policy_slice(
    mdp: MDP,
    solution: Any,
    config: Any,
    total: int,
    ax: Any = None,
    *,
    axes: Sequence[int] = (1, 2, 3),
    fixed_tau: Mapping[int, int] | None = None,
    stationary: Any = None,
    scenario: Any = None,
    title: str | None = None,
    legend: bool = True,
) -> Any:
    r"""Draw the policy on the plane tau_i + tau_j + tau_k = total as a triangle (paper Figs. 6-7).

    A lattice point (t_i, t_j, t_k) is drawn at its barycentric position (corner of tau_i = the
    point where tau_i is largest, etc.); markers as in :func:`plot_policy_map`, faded for
    states with zero stationary probability, a small grey dot for unreachable points. Each
    connected region (6-neighbour on the triangular lattice) carries a text label with its
    action.

    Parameters
    ----------
    mdp, solution, config
        As in :func:`plot_policy_map`.
    total : int
        The plane's constant.
    ax : Axes, optional
    axes : (i, j, k)
        The three processes (1-based).
    fixed_tau : dict, optional
        Values of the AoIs not in ``axes`` (N > 3).

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from scipy import ndimage

    cid = parse_config_spec(mdp, config)
    pol = _policy_pairs(mdp, solution)
    A, S, fixed = slice_grid(mdp, pol, cid, total, axes, fixed_tau, stationary)
    rec_mask = _recurrent_mask(mdp, solution, pol, stationary)
    info = _context(mdp, scenario)
    if ax is None:
        _, ax = plt.subplots(figsize=(9.0, 6.8))
    i, j, k = axes
    ci, cj = A.shape
    TI, TJ = np.meshgrid(np.arange(1, ci + 1), np.arange(1, cj + 1), indexing="ij")
    TK = total - TI - TJ
    X, Y = _bary(TI.astype(float), TJ.astype(float), TK.astype(float))
    on = A != -2
    npts = int(on.sum())
    side = max(2.0, np.sqrt(2 * npts))
    ms = max(2.5, min(9.0, 170.0 / side))
    # outline of the plane inside the box (the convex hull of its lattice points)
    px, py = X[on], Y[on]
    ax.plot(px, py, linestyle="none")  # sets the limits
    if npts >= 3:
        try:
            from scipy.spatial import ConvexHull

            hull = ConvexHull(np.c_[px, py])
            v = np.r_[hull.vertices, hull.vertices[:1]]
            ax.plot(px[v], py[v], color="0.6", lw=0.8, zorder=0)
        except Exception:  # degenerate (collinear) slice
            pass
    unr = A == -1
    if unr.any():
        ax.plot(X[unr], Y[unr], linestyle="none", marker=".", color="0.55", markersize=ms * 0.5, zorder=1)
    handles = []
    for a in np.unique(A[A >= 0]):
        mk, col = _style(a)
        m = A == a
        rec = m.copy()
        if rec_mask is not None:
            rec = m & rec_mask[np.maximum(S, 0)]
        for sel, alpha in ((rec, _FILLED_ALPHA), (m & ~rec, 0.35)):
            if sel.any():
                ax.plot(X[sel], Y[sel], linestyle="none", marker=mk, color=col, markersize=ms, alpha=alpha,
                        markerfacecolor=col if mk not in ("x", "+") else None,
                        markeredgewidth=1.2 if mk in ("x", "+") else 0.5, zorder=2)
        handles.append(Line2D([], [], linestyle="none", marker=mk, color=col, markersize=7,
                              label=f"{action_name(mdp, int(a), cid, names=info)}  [{int(m.sum())} points]"))
        comp, ncomp = ndimage.label(m, structure=_STRUCT["tri6"])
        for r in range(1, ncomp + 1):
            sel = comp == r
            if sel.sum() < 3:
                continue
            ax.text(X[sel].mean(), Y[sel].mean(), _short_action(mdp, int(a), info), ha="center", va="center",
                    fontsize=9, fontweight="bold", color=col, zorder=4,
                    bbox=dict(boxstyle="round,pad=0.2", facecolor="white", edgecolor=col, alpha=0.85))
    if rec_mask is not None:
        handles.append(Line2D([], [], linestyle="none", marker="o", color="0.3", alpha=0.35, markersize=7,
                              label="faded: zero stationary probability"))
    if unr.any():
        handles.append(Line2D([], [], linestyle="none", marker=".", color="0.55", markersize=7,
                              label="unreachable state"))
    pn = info["processes"]
    # where each tau is largest: a label just outside the points, away from their centre
    mx, my = px.mean(), py.mean()
    span = max(px.max() - px.min(), py.max() - py.min(), 1e-9)
    for name, T_ in ((i, TI), (j, TJ), (k, TK)):
        vals = np.where(on, T_, -1)
        top = vals == vals.max()
        tx, ty = X[top].mean(), Y[top].mean()
        dx, dy = tx - mx, ty - my
        nrm = max(np.hypot(dx, dy), 1e-9)
        ax.annotate(f"{_tau(name, info)} largest (= {int(vals.max())})\nprocess {pn[name - 1]}",
                    (tx + 0.17 * span * dx / nrm, ty + 0.17 * span * dy / nrm), ha="center", va="center",
                    fontsize=8.5, color="0.25", annotation_clip=False)
    ax.margins(0.2)
    ax.set_aspect("equal")
    ax.set_axis_off()
    extra = ", ".join(f"{_tau(p, info)} = {v}" for p, v in sorted(fixed.items()))
    head = f"plane {_tau(i, info)} + {_tau(j, info)} + {_tau(k, info)} = {total}, " + (extra + ", " if extra else "")
    ax.set_title(title or _title(info, mdp, cid, head), fontsize=10, pad=30)
    if legend:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8.5, title="action",
                  title_fontsize=9)
    return ax

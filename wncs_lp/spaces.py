r"""One interface to the states a policy is read on, for the maps, the tables and the command line.

A state is an AoI vector tau = (tau_1, ..., tau_N) (1-based, tau_k in 1..cap_k) and a
configuration (the servers' state), as in the model. Two kinds of state space hold them:

* :class:`EnumeratedSpace` -- an MDP's state table (:class:`wncs_lp.models.statespace.StateSpace`:
  the reachable states, numbered; a policy is one pair index per state, the action an index into
  ``mdp.action_table``);
* :class:`BoxSpace` -- a matrix-free solve's :class:`~wncs_lp.solvers.matrix_free.BoxLayout`
  (one dense AoI box per configuration, which contains every reachable state and possibly a few
  more; a policy is one *local* action index per layout state, into
  ``system.automaton.actions[c]``).

Both answer the same questions (:class:`Space`): the configurations and their descriptions, a
configuration named by a spec (:meth:`Space.config_id`), the state indices of AoI vectors in a
configuration (:meth:`Space.lookup`), the AoI vectors and configurations of state indices
(:meth:`Space.tau_of`, :meth:`Space.config_of`), the action label and readable name of an action
(:meth:`Space.action_label`, :meth:`Space.action_name`) and a policy's action at states
(:meth:`Space.actions_at`). :func:`space_of` gives the space of an MDP, a matrix-free solution or
policy. The consumers (:mod:`wncs_lp.policy_grids`, :mod:`wncs_lp.viz.maps`,
:mod:`wncs_lp.tables`, ``wncs-lp map``) read either through this one interface.

Action indices are the space's own: global rows of ``mdp.action_table`` (enumerated) or local
indices of the configuration's actions (box). :meth:`Space.action_label` turns either into the
model's label (a tuple), which is what two spaces of one scenario agree on.

Configuration specs (:meth:`Space.config_id`)
---------------------------------------------
* a configuration id (int) or object (as in ``configs``);
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
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import ModelError, PolicyError, WncsError
from .mdp import MDP
from .models import model_type
from .scenario import load_scenario

__all__ = ["Space", "EnumeratedSpace", "BoxSpace", "space_of", "map_names", "system_names", "config_id",
           "system_config"]


# ============================================================================ names
def _short_process(name: str) -> str:
    m = re.fullmatch(r"(?i)process[-_ ]?(\w+)", name.strip())
    return m.group(1) if m else name


def _scenario_names(sc: Any) -> dict:
    return {"processes": [_short_process(p.name) for p in sc.processes],
            "servers": [s.name for s in sc.servers], "p": _one_p(sc), "name": Path(str(sc.source)).stem}


def _one_p(sc: Any) -> float | None:
    """The success probability of every link, or None when the links differ (per server or per
    process: then no single p describes the system)."""
    links = {float(v) for s in sc.servers for v in (*s.p_up, *s.p_down)}
    return links.pop() if len(links) == 1 else None


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
            info["processes"] = [_short_process(p.name) for p in sc0.processes]
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


def system_names(system: Any) -> dict:
    """:func:`map_names` of a :class:`~wncs_lp.models.system.System` (no MDP: matrix-free maps)."""
    return {**_scenario_names(system.scenario), "model": type(system.model)}


# ============================================================================ configurations
def _norm(text: str) -> str:
    return re.sub(r"\s+", " ", text.strip().lower())


def _tuplify(x: Any) -> Any:
    if isinstance(x, (list, tuple)):
        return tuple(_tuplify(v) for v in x)
    return x


def config_id(configs: list, describe: Any, model: Any, name: str, spec: Any) -> int:
    """The id of the configuration ``spec`` names among ``configs`` (the syntax: the module docstring).

    Raises
    ------
    ModelError
        When the spec names no reachable configuration; the message lists close matches.
    """
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
        return config_id(configs, describe, model, name, int(text[1:]))
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


def system_config(system: Any, spec: Any) -> int:
    """:func:`config_id` over a :class:`~wncs_lp.models.system.System`'s configurations."""
    name = Path(str(system.scenario.source)).stem
    return config_id(list(system.automaton.configs), system.model.describe, type(system.model), name, spec)


def _label(x: Any) -> tuple:
    return tuple(int(v) for v in np.atleast_1d(x))


# ============================================================================ the interface
class Space(ABC):
    """The states a policy is read on: configurations x AoI vectors, numbered.

    Attributes
    ----------
    caps : tuple of int
        The AoI caps (tau_k in 1..caps[k-1]).
    configs : list
        The configuration objects, by id.
    outside : str
        What a state index of -1 means on a map (legend text).
    note : str
        Appended to a map's title (how the policy was computed, where it matters).
    """

    caps: tuple[int, ...]
    configs: list
    outside: str = "unreachable state"
    note: str = ""

    @property
    def n_processes(self) -> int:
        return len(self.caps)

    @abstractmethod
    def describe(self, c: int) -> str:
        """The readable description of configuration id ``c``."""

    @abstractmethod
    def names(self, scenario: Any = None) -> dict:
        """Names and parameters for labels (:func:`map_names`)."""

    @abstractmethod
    def config_id(self, spec: Any) -> int:
        """The configuration id ``spec`` names (module docstring)."""

    @abstractmethod
    def lookup(self, tau: np.ndarray, c: int) -> np.ndarray:
        """State indices of R AoI vectors ((R, N), values in 1..cap) in configuration ``c``; -1 where
        the space holds no such state."""

    @abstractmethod
    def tau_of(self, states: np.ndarray) -> np.ndarray:
        """(R, N) AoI vectors (1-based) of state indices."""

    @abstractmethod
    def config_of(self, states: np.ndarray) -> np.ndarray:
        """(R,) configuration ids of state indices."""

    @abstractmethod
    def action_label(self, c: int, a: int) -> tuple:
        """The model's label of action index ``a`` in configuration ``c``."""

    @abstractmethod
    def actions_at(self, policy: np.ndarray, states: np.ndarray) -> np.ndarray:
        """The action index a policy (the space's form, checked) takes at state indices (all >= 0)."""

    def action_name(self, c: int, a: int, names: dict | None = None) -> str:
        """The readable name of action index ``a`` in configuration ``c`` (``names`` from :meth:`names`)."""
        names = names or self.names()
        return names["model"].action_name(self.action_label(c, a), self.configs[int(c)], names)

    def style_key(self, c: int, a: int) -> int:
        """An index that is the same for one action in every configuration (a map's marker)."""
        return int(a)

    def box(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """The AoI range configuration ``c`` can hold: 1-based ``(low, high)`` per process."""
        return np.ones(self.n_processes, np.int64), np.asarray(self.caps, np.int64)

    @abstractmethod
    def value_counts(self, c: int, weights: np.ndarray | None = None) -> tuple[list, list]:
        """Per process k, over tau_k = 1..cap_k: the number of states of configuration ``c`` with
        that value, and the ``weights`` (one per state) they carry (zeros without weights)."""

    def slice_states(self, c: int, axes: Sequence[int], fixed: Mapping[int, int]) -> np.ndarray:
        """State indices over (tau_i, tau_j), ``axes`` = (i, j) 1-based, the other AoIs at ``fixed``:
        a (cap_i, cap_j) array indexed by ``[tau_i - 1, tau_j - 1]``, -1 where there is no state."""
        i, j = axes
        ti, tj = np.meshgrid(np.arange(1, self.caps[i - 1] + 1), np.arange(1, self.caps[j - 1] + 1), indexing="ij")
        tau = np.empty((ti.size, self.n_processes), np.int64)
        for k in range(1, self.n_processes + 1):
            tau[:, k - 1] = ti.ravel() if k == i else (tj.ravel() if k == j else fixed[k])
        return self.lookup(tau, c).reshape(ti.shape)


class EnumeratedSpace(Space):
    """The reachable states of an MDP, as its state table numbers them (a policy: pair indices)."""

    def __init__(self, mdp: MDP):
        st = getattr(mdp, "states", None)
        if st is None or getattr(st, "configs", None) is None:
            raise ModelError(f"{mdp!r} has no decoded state space; cannot select a configuration")
        self.mdp = mdp
        self.caps = tuple(int(x) for x in st.caps)
        self.configs = st.configs

    def describe(self, c: int) -> str:
        return self.mdp.states.describe_config(self.configs[int(c)])

    def names(self, scenario: Any = None) -> dict:
        return map_names(self.mdp, scenario)

    def config_id(self, spec: Any) -> int:
        st = self.mdp.states
        return config_id(st.configs, st.describe_config, model_type(self.mdp), self.mdp.name, spec)

    def lookup(self, tau: np.ndarray, c: int) -> np.ndarray:
        tau = np.asarray(tau, np.int64)
        return self.mdp.states.ids(tau, np.full(tau.shape[0], int(c), np.int64))

    def tau_of(self, states: np.ndarray) -> np.ndarray:
        return np.asarray(self.mdp.states.tau)[states]

    def config_of(self, states: np.ndarray) -> np.ndarray:
        return np.asarray(self.mdp.states.config)[states]

    def action_label(self, c: int, a: int) -> tuple:
        return _label(self.mdp.action_table[int(a)])

    def actions_at(self, policy: np.ndarray, states: np.ndarray) -> np.ndarray:
        return np.asarray(self.mdp.a_indices)[np.asarray(policy)[states]]

    def value_counts(self, c: int, weights: np.ndarray | None = None) -> tuple[list, list]:
        ids = self.mdp.states.lookup_grid(int(c))
        G = ids >= 0
        W = np.zeros(G.shape) if weights is None else np.where(G, np.asarray(weights, float)[np.maximum(ids, 0)], 0.0)
        N = self.n_processes
        other = [tuple(i for i in range(N) if i != k) for k in range(N)]
        return [G.sum(axis=o) for o in other], [W.sum(axis=o) for o in other]


class BoxSpace(Space):
    """The states of a matrix-free solve: one AoI box per configuration (a policy: local action
    indices, one per layout state). No stationary law is known at this scale."""

    outside = "outside this configuration's box"
    note = " (matrix-free)"

    def __init__(self, system: Any, layout: Any):
        self.system, self.layout = system, layout
        self.caps = tuple(int(x) for x in system.caps)
        self.configs = list(system.automaton.configs)
        self._style: dict | None = None  # label -> marker index, made when a map first asks

    def describe(self, c: int) -> str:
        return self.system.model.describe(self.configs[int(c)])

    def names(self, scenario: Any = None) -> dict:
        return system_names(self.system)

    def config_id(self, spec: Any) -> int:
        return system_config(self.system, spec)

    def lookup(self, tau: np.ndarray, c: int) -> np.ndarray:
        tau = np.asarray(tau, np.int64)
        return self.layout.index(tau, np.full(tau.shape[0], int(c), np.int64))

    def tau_of(self, states: np.ndarray) -> np.ndarray:
        return self.layout.tau_of(states)

    def config_of(self, states: np.ndarray) -> np.ndarray:
        return self.layout.config_of(states)

    def action_label(self, c: int, a: int) -> tuple:
        return _label(self.system.automaton.actions[int(c)][int(a)])

    def actions_at(self, policy: np.ndarray, states: np.ndarray) -> np.ndarray:
        return np.asarray(policy)[states].astype(np.int64)

    def style_key(self, c: int, a: int) -> int:
        if self._style is None:  # the sorted labels of every configuration, like the MDP's action rows
            every = sorted({_label(x) for acts in self.system.automaton.actions for x in acts})
            self._style = {lab: k for k, lab in enumerate(every)}
        return self._style[self.action_label(c, a)]

    def box(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        lo = np.asarray(self.layout.lo[int(c)], np.int64)
        return lo + 1, lo + np.asarray(self.layout.dims[int(c)], np.int64)

    def value_counts(self, c: int, weights: np.ndarray | None = None) -> tuple[list, list]:
        low, high = self.box(c)
        dims = high - low + 1
        counts = []
        for k, cap in enumerate(self.caps):
            t = np.arange(1, cap + 1)
            counts.append(np.where((t >= low[k]) & (t <= high[k]), int(np.prod(np.delete(dims, k))), 0))
        return counts, [np.zeros(cap) for cap in self.caps]


def space_of(obj: Any) -> Space:
    """The state space of an MDP, a matrix-free solution or policy (anything with ``system`` and
    ``layout``), or a :class:`Space` itself.

    Raises
    ------
    PolicyError
        For anything else.
    """
    if isinstance(obj, Space):
        return obj
    if isinstance(obj, MDP):
        return EnumeratedSpace(obj)
    if hasattr(obj, "layout") and hasattr(obj, "system"):
        return BoxSpace(obj.system, obj.layout)
    raise PolicyError(f"no state space in {type(obj).__name__}: expected an MDP, a matrix-free solution or policy")

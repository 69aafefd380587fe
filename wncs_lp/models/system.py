"""A scenario's configuration automaton and cost tables: all a policy or a simulator needs.

A :class:`System` never holds the tau box, so it exists for systems far too large to enumerate
(all four paper processes with caps of 30 or more). What it knows of the configurations comes
from the scenario's :class:`~wncs_lp.models.base.Model`.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import ModelError, PolicyError, SizeLimitError
from ..mdp import MDP
from ..scenario import Scenario
from .automaton import ConfigAutomaton, ExplorationLimitError, exploration_limit
from .base import Model
from .cost import cost_tables

__all__ = ["System", "OutcomeTables", "PairTables", "OUTCOME_TABLES_MAX_BYTES"]

#: Largest padded (configuration, action, outcome) table :attr:`System.outcome_tables` builds
#: (its delivery array alone has |C| A_max O_max N entries: 4.6 GB for the paper's four processes
#: four times); past it the pair-indexed :attr:`System.pairs` (one row per feasible action) is
#: the only form, and the message says so.
OUTCOME_TABLES_MAX_BYTES = 1 << 30
#: ``explore="auto"`` explores lazily when the model's bound on the configurations times the actions
#: of the idle configuration exceeds this (the paper's four processes four times: 56,457 x 240 =
#: 13.5 million, enumerated: 652,056 edges; three times on three servers: 762,073 x 1,320, lazy).
LAZY_EDGES = 50_000_000
#: ``explore="auto"`` below :data:`LAZY_EDGES` explores the whole automaton within this many edges
#: (about 1.7 GB of Python objects at the ~870 bytes an edge measured at 20 sensors, and 30-60 s),
#: lazily past it: 16 processes pass (652,056 and 1,071,040 edges), 20 sensors do not (2.6 million).
AUTO_EDGES = 2_000_000


@dataclass(frozen=True, eq=False)
class System:
    """A scenario's configuration automaton and cost tables: all a policy or simulator needs.

    Build it with :meth:`System.from_scenario`; nothing here is proportional to the size of the
    tau box, only to the number of configurations |C| and to sum_k tau_hat_k.

    Attributes
    ----------
    scenario : Scenario
    automaton : ConfigAutomaton
        ``configs``, ``actions[c]`` (labels in the MDP's action order), ``outcomes[c][j]`` =
        ``[(next_config_id, delta, prob), ...]``.
    caps : (N,) int array
        tau_hat_k.
    q : tuple of arrays
        ``q[k][tau - 1] = q_k(tau)``, tau = 1..tau_hat_k.
    n_actions : (|C|,) int array
        Number of feasible actions of each configuration.
    model : Model
        The scenario's model: what the system knows of its configurations comes from it.
    """

    scenario: Scenario
    automaton: ConfigAutomaton
    caps: np.ndarray
    q: tuple
    n_actions: np.ndarray
    model: Model

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_scenario(cls, scenario: Scenario, model: Model | None = None, *, explore: str = "full") -> "System":
        """The scenario's system (through its :class:`Model`).

        Parameters
        ----------
        scenario : Scenario
        model : Model, optional
        explore : {"full", "lazy", "auto"}
            ``"full"`` explores the whole configuration automaton now (within the exploration
            budget of :mod:`wncs_lp.models.automaton`: an :class:`ExplorationLimitError` past it);
            ``"lazy"`` explores nothing but the initial configurations and expands the others as
            they are met (:meth:`expand`: simulations and the policies that support it,
            :attr:`Policy.explores_lazily`); ``"auto"`` is lazy when the model's bounds on the
            automaton (configurations x actions of the idle one, :data:`LAZY_EDGES`) or the
            exploration budget say it is too large to enumerate, full otherwise.
        """
        from . import model_for

        if explore not in ("full", "lazy", "auto"):
            raise ModelError(f"explore must be 'full', 'lazy' or 'auto', got {explore!r}")
        model = model if model is not None else model_for(scenario)
        if explore == "auto":
            b = model.automaton_bounds()
            explore = "lazy" if b.configs is not None and b.configs * b.edges_initial > LAZY_EDGES else "full"
            if explore == "full" and "automaton" not in model.__dict__:
                try:
                    with exploration_limit(-1, AUTO_EDGES):
                        auto = model.automaton
                except ExplorationLimitError:
                    explore = "lazy"
                else:
                    return cls.from_automaton(scenario, auto, model)
        if explore == "lazy":
            return cls._lazy(scenario, model)
        return cls.from_automaton(scenario, model.automaton, model)

    @classmethod
    def _lazy(cls, scenario: Scenario, model: Model) -> "System":
        auto = model.lazy_automaton()
        caps = np.array(scenario.tau_caps, dtype=np.int64)
        q = tuple(np.asarray(t, dtype=float) for t in cost_tables(scenario))
        system = cls(scenario, auto, caps, q, np.zeros(len(auto.configs), np.int64), model)
        object.__setattr__(system, "_store", _PairStore(scenario.n_processes, scenario.n_servers))
        system.expand(auto.initial)
        return system

    @property
    def is_lazy(self) -> bool:
        """Whether the automaton is explored on demand (:meth:`expand`) rather than whole."""
        return "_store" in self.__dict__

    @property
    def n_expanded(self) -> int:
        """Configurations whose actions are known (all of them unless :attr:`is_lazy`)."""
        return int(self.automaton.n_expanded) if self.is_lazy else self.n_configs

    def expand(self, config_ids) -> int:
        """Expand the configurations ``config_ids`` not expanded yet (a lazily explored system; a no-op
        otherwise): their actions and outcomes join :attr:`pairs`, and the configurations their
        outcomes lead to get ids. Returns the number expanded.

        Raises
        ------
        SizeLimitError
            The pairs would outgrow the memory budget (:func:`wncs_lp.models.guard.require_memory`)."""
        store = self.__dict__.get("_store")
        if store is None:
            return 0
        c = np.asarray(config_ids, dtype=np.int64).ravel()
        if store.count.size < len(self.automaton.configs):
            store.reserve(len(self.automaton.configs))
        todo = c[store.count[c] == 0] if c.size else c
        if todo.size == 0:
            return 0
        new = self.automaton.expand(np.unique(todo).tolist())
        store.add(new, self.automaton, self.model)
        object.__setattr__(self, "n_actions", store.count[:store.n_known])
        self.__dict__["pairs"] = store.tables()
        self.__dict__["label_index"] = store.label_index
        self.__dict__["accepts"] = store.accepts[:len(self.automaton.configs)]
        for key in ("max_actions", "action_valid", "busy", "labels", "outcome_tables"):
            self.__dict__.pop(key, None)
        return len(new)

    @classmethod
    def from_automaton(cls, scenario: Scenario, auto: ConfigAutomaton, model: Model | None = None) -> "System":
        if model is None:
            from . import model_for

            model = model_for(scenario)
        caps = np.array(scenario.tau_caps, dtype=np.int64)
        q = tuple(np.asarray(t, dtype=float) for t in cost_tables(scenario))
        n_actions = np.array([len(a) for a in auto.actions], dtype=np.int64)
        return cls(scenario, auto, caps, q, n_actions, model)

    # ---------------------------------------------------------------- basic facts
    @property
    def n_processes(self) -> int:
        return int(self.caps.size)

    @property
    def n_servers(self) -> int:
        return self.scenario.n_servers

    @property
    def n_configs(self) -> int:
        return len(self.automaton.configs)

    @property
    def initial_config(self) -> int:
        """The first initial configuration (all servers idle, empty pipelines)."""
        return int(self.automaton.initial[0])

    def state_cost(self, tau: np.ndarray) -> np.ndarray:
        """c(s) = sum_k q_k(tau_k) for an (R, N) array of AoI vectors."""
        tau = np.asarray(tau)
        out = np.zeros(tau.shape[0])
        for k in range(self.n_processes):
            out += self.q[k][tau[:, k] - 1]
        return out

    def check_mdp(self, mdp: MDP) -> None:
        """Raise :class:`PolicyError` unless ``mdp`` was built from this system's automaton.

        The engine numbers the MDP's configurations in automaton order, so the check is that
        the configuration lists and the caps agree.
        """
        states = getattr(mdp, "states", None)
        if states is None or not hasattr(states, "configs") or not hasattr(states, "tau"):
            raise PolicyError(f"{mdp!r} has no decoded (tau, configuration) states; build it with wncs_lp.models.build")
        if tuple(states.caps) != tuple(int(c) for c in self.caps):
            raise PolicyError(f"MDP caps {tuple(states.caps)} differ from the scenario's {tuple(self.caps)}")
        if len(states.configs) != self.n_configs or any(
            a != b for a, b in zip(states.configs, self.automaton.configs)
        ):
            raise PolicyError(
                "the MDP's configurations differ from this scenario's automaton "
                "(was it built from another scenario or another parameter value?)"
            )

    # ---------------------------------------------------------------- padded tables
    @cached_property
    def max_actions(self) -> int:
        return int(self.n_actions.max())

    @cached_property
    def labels(self) -> np.ndarray:
        """(|C|, A_max, M) int array of action labels (padding: -1)."""
        pt = self.pairs
        out = np.full((self.n_configs, self.max_actions, pt.labels.shape[1]), -1, dtype=np.int64)
        out[pt.config_of, np.arange(pt.n_pairs) - pt.first[pt.config_of]] = pt.labels
        return out

    @cached_property
    def label_index(self) -> list[dict[tuple, int]]:
        """Per configuration: action label -> local index."""
        return [{tuple(a): j for j, a in enumerate(acts)} for acts in self.automaton.actions]

    @cached_property
    def action_valid(self) -> np.ndarray:
        """(|C|, A_max) bool: local index j is a feasible action of configuration c."""
        return np.arange(self.max_actions)[None, :] < self.n_actions[:, None]

    @cached_property
    def pairs(self) -> "PairTables":
        """The automaton's feasible (configuration, action) pairs and their outcomes, one row per
        pair (see :class:`PairTables`): what simulations and lookahead policies read."""
        return PairTables.from_automaton(self.automaton, self.n_processes, self.model)

    @cached_property
    def outcome_tables(self) -> "OutcomeTables":
        """Padded per-(configuration, action) outcome tables (see :class:`OutcomeTables`).

        Raises
        ------
        SizeLimitError
            The padded tables would take more than :data:`OUTCOME_TABLES_MAX_BYTES` (most of it
            padding once many configurations have few actions): use :attr:`pairs`.
        """
        pt = self.pairs
        nC, A, N, O = self.n_configs, self.max_actions, self.n_processes, pt.n_outcomes
        need = nC * A * O * (3 * 8 + 8 * N)
        if need > OUTCOME_TABLES_MAX_BYTES:
            raise SizeLimitError(
                f"the padded outcome tables of {self.scenario.source} would take {need / 2**30:.1f} GiB "
                f"({nC:,} configurations x {A:,} actions x {O} outcomes x {N} processes' delivery ages), over "
                f"{OUTCOME_TABLES_MAX_BYTES / 2**30:.1f} GiB; read the pair-indexed System.pairs instead "
                f"({pt.n_pairs:,} feasible pairs, {pt.nbytes / 2**20:.1f} MiB)")
        c = pt.config_of
        j = np.arange(pt.n_pairs) - pt.first[c]
        nxt = np.zeros((nC, A, O), dtype=np.int64)
        delta = np.zeros((nC, A, O, N), dtype=np.int64)
        prob = np.zeros((nC, A, O))
        cum = np.full((nC, A, O), np.inf)
        nxt[c, j] = pt.nxt
        delta[c, j] = pt.deltas[pt.delta]
        prob[c, j] = pt.prob
        cum[c, j] = pt.cum
        return OutcomeTables(nxt=nxt, delta=delta, prob=prob, cum=cum)

    @cached_property
    def accepts(self) -> np.ndarray:
        """(|C|, M) bool: server m accepts a new update in configuration c (:meth:`Model.accepts`)."""
        return np.array([self.model.accepts(cfg) for cfg in self.automaton.configs], dtype=bool)

    @cached_property
    def busy(self) -> np.ndarray:
        """(|C|, A_max, M): probability that server m performs a service step in the slot
        (:meth:`Model.busy`; 0 on padding)."""
        pt = self.pairs
        out = np.zeros((self.n_configs, self.max_actions, self.n_servers))
        out[pt.config_of, np.arange(pt.n_pairs) - pt.first[pt.config_of]] = pt.busy
        return out

    def next_tau(self, tau: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """tau'_k = min(tau_k + 1, delta_k if delta_k > 0, tau_hat_k), elementwise (broadcasts)."""
        t = np.minimum(tau + 1, self.caps)
        return np.where(delta > 0, np.minimum(t, delta), t)


class _LabelIndex:
    """Per configuration of a lazily explored automaton, action label -> local index, each dict made
    when first asked for (the bound's policy never asks: at a dozen processes on three servers the
    dicts of every configuration met would take about as much as the pairs themselves)."""

    def __init__(self):
        self.actions: list = []
        self._made: dict[int, dict[tuple, int]] = {}

    def __len__(self) -> int:
        return len(self.actions)

    def __getitem__(self, c: int) -> dict[tuple, int]:
        c = int(c)
        got = self._made.get(c)
        if got is None:
            got = {lab: j for j, lab in enumerate(self.actions[c])}
            if got:  # an unexpanded configuration has no actions yet: nothing to keep
                self._made[c] = got
        return got


class _PairStore:
    """The growing arrays of a lazily explored system (capacity doubling: amortised O(1) a pair)."""

    def __init__(self, n_processes: int, n_servers: int):
        self.N, self.M = n_processes, n_servers
        self.n_pairs = 0
        self.O = 1
        self.first = np.full(0, -1, np.int64)
        self.count = np.zeros(0, np.int64)
        self.accepts = np.zeros((0, n_servers), bool)
        self.label_index = _LabelIndex()
        self.n_known = 0
        self.deltas = np.zeros((0, n_processes), np.int64)
        self.cols = {"config_of": np.zeros(0, np.int64), "labels": np.zeros((0, n_servers), np.int64),
                     "nxt": np.zeros((0, 1), np.int64), "delta": np.zeros((0, 1), np.int32),
                     "prob": np.zeros((0, 1)), "cum": np.zeros((0, 1)), "busy": np.zeros((0, n_servers))}

    def reserve(self, n_configs: int) -> None:
        self._room(n_configs, self.n_pairs, self.O)

    def _room(self, n_configs: int, n_pairs: int, width: int) -> None:
        from .guard import require_memory

        if n_configs > self.count.size:
            cap = max(n_configs, 2 * self.count.size, 1024)
            self.first = np.r_[self.first, np.full(cap - self.first.size, -1, np.int64)]
            self.count = np.r_[self.count, np.zeros(cap - self.count.size, np.int64)]
            self.accepts = np.r_[self.accepts, np.zeros((cap - self.accepts.shape[0], self.M), bool)]
        rows = self.cols["prob"].shape[0]
        if n_pairs > rows or width > self.O:
            cap = max(n_pairs, 2 * rows if n_pairs > rows else rows, 4096)
            O = max(width, self.O)
            require_memory(cap * (O * 28 + self.M * 16 + 8), f"the pairs of the {n_configs:,} configurations met so "
                           f"far ({n_pairs:,} pairs of up to {O} outcomes)",
                           ["fewer processes or servers", "a shorter simulation (--slots, --reps)"])
            out = {}
            for key, a in self.cols.items():
                shape = (cap,) + a.shape[1:]
                if key in ("nxt", "delta", "prob", "cum"):
                    shape = (cap, O)
                b = np.zeros(shape, a.dtype)
                if a.ndim == 2:
                    b[:self.n_pairs, :a.shape[1]] = a[:self.n_pairs]
                    if key in ("nxt", "delta") and O > a.shape[1]:  # padding repeats the first outcome
                        b[:self.n_pairs, a.shape[1]:] = a[:self.n_pairs, :1]
                    if key == "cum" and O > a.shape[1]:
                        b[:self.n_pairs, a.shape[1]:] = np.inf
                else:
                    b[:self.n_pairs] = a[:self.n_pairs]
                out[key] = b
            self.cols, self.O = out, O

    def add(self, new: list, auto, model: Model) -> None:
        """Append the pairs of newly expanded configurations (:meth:`LazyAutomaton.expand`)."""
        n_configs = len(auto.configs)
        n_new = sum(len(labels) for _, labels, _ in new)
        width = max((len(o) for _, _, outs in new for o in outs), default=1)
        self._room(n_configs, self.n_pairs + n_new, width)
        for c in range(self.n_known, n_configs):  # configurations met for the first time
            self.accepts[c] = model.accepts(auto.configs[c])
        self.n_known = n_configs
        self.label_index.actions = auto.actions
        if len(auto.deltas) > self.deltas.shape[0]:
            d = np.zeros((len(auto.deltas), self.N), np.int64)
            for vec, i in auto.deltas.items():
                d[i] = vec
            self.deltas = d
        cols, p = self.cols, self.n_pairs
        for c, labels, outs in new:
            n = len(labels)
            self.first[c], self.count[c] = p, n
            lab = np.array(labels, dtype=np.int64).reshape(n, self.M)
            cols["config_of"][p:p + n] = c
            cols["labels"][p:p + n] = lab
            cols["busy"][p:p + n] = model.busy(auto.configs[c], lab)
            for j, o in enumerate(outs):
                arr = np.array(o, dtype=float)  # (outcomes, 3): next id, delivery id, probability
                cols["nxt"][p + j] = arr[0, 0]
                cols["delta"][p + j] = arr[0, 1]
                cols["nxt"][p + j, :len(o)] = arr[:, 0]
                cols["delta"][p + j, :len(o)] = arr[:, 1]
                cols["prob"][p + j, :len(o)] = arr[:, 2]
                cum = np.cumsum(arr[:, 2])
                cum[-1] = np.inf  # u < 1 always lands on a real outcome, whatever the round-off
                cols["cum"][p + j] = np.inf
                cols["cum"][p + j, :len(o)] = cum
            p += n
        self.n_pairs = p

    def tables(self) -> "PairTables":
        n, c = self.n_pairs, self.cols
        nc = self.n_known
        return PairTables(first=self.first[:nc], count=self.count[:nc], config_of=c["config_of"][:n],
                          labels=c["labels"][:n], nxt=c["nxt"][:n], delta=c["delta"][:n], deltas=self.deltas,
                          prob=c["prob"][:n], cum=c["cum"][:n], busy=c["busy"][:n])


@dataclass(frozen=True, eq=False)
class PairTables:
    """The feasible (configuration, action) pairs of a :class:`System`, one row each, and their
    outcomes padded to the most outcomes of any pair (a few: two or three per server).

    Pair ``p = first[c] + j`` is local action j of configuration c (the automaton's action
    order), j < ``count[c]``: a configuration's pairs are contiguous. Unlike the padded
    :class:`OutcomeTables` nothing is stored for the actions a configuration lacks: the paper's
    four processes four times have 137,288 pairs against 19,845 x 240 padded slots.

    Attributes
    ----------
    first : (|C|,) int array
        The first pair of each configuration (-1 for one not expanded yet: :meth:`System.expand`).
    count : (|C|,) int array
        Its number of feasible actions (0 when not expanded yet).
    config_of : (P,) int array
        The configuration of each pair.
    labels : (P, M) int array
        Action label of each pair.
    nxt : (P, O) int array
        Next configuration of each outcome (padding: the first outcome's).
    delta : (P, O) int array
        Row of ``deltas`` of each outcome's delivery vector (padding: the first outcome's).
    deltas : (D, N) int array
        The distinct delivery vectors (delivery ages per process, 0 = none).
    prob : (P, O) float array
        Outcome probabilities (0 on padding).
    cum : (P, O) float array
        Cumulative probabilities, the last real entry and the padding +inf: the outcome a
        uniform u in [0, 1) draws is ``sum(u >= cum[p])``.
    busy : (P, M) float array
        Probability that server m performs a service step in the slot (:meth:`Model.busy`).
    """

    first: np.ndarray
    count: np.ndarray
    config_of: np.ndarray
    labels: np.ndarray
    nxt: np.ndarray
    delta: np.ndarray
    deltas: np.ndarray
    prob: np.ndarray
    cum: np.ndarray
    busy: np.ndarray

    @property
    def n_pairs(self) -> int:
        return int(self.prob.shape[0])

    @property
    def n_outcomes(self) -> int:
        """The most outcomes of any pair (the padded width O)."""
        return int(self.prob.shape[1])

    @property
    def nbytes(self) -> int:
        return sum(int(a.nbytes) for a in (self.first, self.count, self.config_of, self.labels, self.nxt, self.delta, self.deltas, self.prob,
                                           self.cum, self.busy))

    def of(self, config_ids: np.ndarray, local: np.ndarray) -> np.ndarray:
        """Pair indices of local actions ``local`` in configurations ``config_ids`` (broadcasting)."""
        return self.first[np.asarray(config_ids, dtype=np.int64)] + np.asarray(local, dtype=np.int64)

    def padded(self, config_ids: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
        """(R, width) pair indices of local actions 0..width-1 in each configuration (clipped to its
        last pair where it has fewer) and the (R, width) mask of the real ones."""
        c = np.asarray(config_ids, dtype=np.int64)
        lo, n = self.first[c][:, None], self.count[c][:, None]
        j = np.arange(width)[None, :]
        valid = j < n
        return lo + np.minimum(j, n - 1), valid

    def delivery(self, k: int) -> np.ndarray:
        """(P, O) delivery ages of process k (0 = none) of every outcome."""
        return self.deltas[:, k][self.delta]

    @classmethod
    def from_automaton(cls, auto, n_processes: int, model: Model) -> "PairTables":
        """From a :class:`ConfigAutomaton` (its flat edge arrays, :meth:`ConfigAutomaton.flat`)."""
        flat = auto.flat(n_processes)
        start = np.asarray(flat.act_ptr, dtype=np.int64)
        count = np.diff(start)
        n_out = np.diff(flat.out_ptr)
        P, O = int(n_out.size), int(n_out.max(initial=1))
        pair_of = np.repeat(np.arange(P), n_out)
        slot = np.arange(flat.n_edges) - flat.out_ptr[pair_of]
        first = flat.out_ptr[:-1]
        nxt = np.repeat(flat.out_nxt[first][:, None], O, axis=1)
        delta = np.repeat(flat.out_delta[first][:, None], O, axis=1).astype(np.int32)
        prob = np.zeros((P, O))
        nxt[pair_of, slot] = flat.out_nxt
        delta[pair_of, slot] = flat.out_delta
        prob[pair_of, slot] = flat.out_prob
        cum = np.cumsum(prob, axis=1)
        cum[np.arange(P), n_out - 1] = np.inf  # u < 1 always lands on a real outcome, whatever the round-off
        cum[np.arange(O)[None, :] >= n_out[:, None]] = np.inf
        labels = np.array([a for acts in auto.actions for a in acts], dtype=np.int64).reshape(P, -1)
        busy = np.zeros(labels.shape)
        for c, cfg in enumerate(auto.configs):
            if start[c + 1] > start[c]:
                busy[start[c]:start[c + 1]] = model.busy(cfg, labels[start[c]:start[c + 1]])
        return cls(first=start[:-1].copy(), count=count, config_of=np.repeat(np.arange(count.size), count),
                   labels=labels, nxt=nxt, delta=delta, deltas=np.asarray(flat.deltas, np.int64),
                   prob=prob, cum=cum, busy=busy)


@dataclass(frozen=True, eq=False)
class OutcomeTables:
    """Padded outcome tables of a :class:`System`, indexed ``[c, j, o]``.

    Attributes
    ----------
    nxt : (|C|, A, O) int array
        Next configuration id of outcome o of action j in configuration c.
    delta : (|C|, A, O, N) int array
        Delivery ages (0 = none).
    prob : (|C|, A, O) float array
        Outcome probabilities (0 on padding).
    cum : (|C|, A, O) float array
        Cumulative probabilities with the last real entry and the padding set to +inf: the
        outcome drawn by a uniform u in [0, 1) is ``sum(u >= cum[c, j])``.
    """

    nxt: np.ndarray
    delta: np.ndarray
    prob: np.ndarray
    cum: np.ndarray

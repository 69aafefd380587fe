r"""The greedy policy of a private-servers bound, read through projections: memory linear in N.

Relaxations 1 and 3 give value tables over a member's *private* configuration: process k's (or
group G's) own jobs, :math:`h_G(\tau_G, C_G)` with :math:`C_G` the projection of the joint
configuration C (:meth:`~wncs_lp.models.base.Model.project_group`). The greedy policy of the bound
(:mod:`wncs_lp.bounds.policy`) needs, for every action a of every joint configuration C,

.. math:: W_G(C, a, \tau_G) = \sum_o P(o \mid C, a)\, h_G(\tau'_G, C'_{G,o}).

By the argument that makes the relaxation valid, the AoI and own jobs of the processes of G move
under the joint system exactly as in G's private system under the projected action
:math:`a_G` (:meth:`~wncs_lp.models.base.Model.project_group_labels`), so the sum is the same
one over G's private outcomes:

.. math:: W_G(C, a, \tau_G) = W^{priv}_G(C_G, a_G, \tau_G),

a table over G's private pairs (a few hundred for one process, a few thousand for a pair),
whatever N. The joint tables had |C| A_max sum_k tau_hat_k entries: 24 GB for the paper's four
processes four times at cap 40 (19,845 configurations x 240 actions), ~N^4 in N; these have a few
MB. (The tests check the equality against the joint tables and a brute-force lookahead, on two
and three servers.)

A joint action sends to at most M processes; every member none of whose processes is sent
takes its private "send nothing" action (feasible: the private systems may idle). So

.. math:: \sum_G W_G(C, a, \tau_G) = \underbrace{\sum_G W^{priv}_G(C_G, 0, \tau_G)}_{\text{base}(\tau, C)}
          + \sum_{G \text{ sent to by } a} \bigl[W^{priv}_G(C_G, a_G, \tau_G) - W^{priv}_G(C_G, 0, \tau_G)\bigr],

N lookups a state for the base and at most M a pair: a slot of 20 replications at 32 processes
(992 actions) costs ~40,000 lookups instead of ~640,000. The sums differ from the joint tables'
by rounding only (1e-12 relative), which can only change the choice between actions whose values
tie to that precision.
"""
from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np

from ..errors import PolicyError
from ..models.guard import require_memory
from ..models.system import System
from ..policies.base import Policy
from ..policies.suboptimal import separable_table
from .private import chain_key
from .result import BoundResult, GroupTables

__all__ = ["ProjectedLookahead", "ProjectedBoundPolicy", "ProjectedValue", "lookahead_table", "projected_tables",
           "PROJECTED"]

#: The relaxations whose tables are read on private configurations (their greedy policy is projected).
PROJECTED = ("private-servers", "grouped-private-servers")
#: Entries (group AoI vectors x outcomes x members) of one block of :func:`lookahead_table`.
BLOCK_ENTRIES = 2_000_000
#: Relative width within which two actions' values tie (the first is taken).
TIE = 1e-12
#: Joint configurations whose projections are checked against the bound's own column maps.
CHECK_CONFIGS = 64


def lookahead_table(system: System, group: Sequence[int], h: np.ndarray, column: np.ndarray | None = None) -> np.ndarray:
    """W[p, t] = sum_o P(o | pair p) h(column(C'_o), tau'_G) for every feasible pair p of ``system``
    (:attr:`System.pairs`) and every AoI vector of the processes ``group`` (t the flat C-order index
    of tau_G - 1), tau'_k = min(tau_k + 1, delta_k if > 0, tau_hat_k).

    ``h`` has shape (n_cols, tau_hat of each member); ``column`` maps the system's configurations
    to rows of ``h`` (default the identity). The memory is the table, 8 P prod tau_hat_G bytes.
    """
    group = tuple(int(k) for k in group)
    col = np.arange(system.n_configs) if column is None else np.asarray(column, np.int64)
    if len(group) == 1:
        return separable_table(system, group[0], np.asarray(h, float), col)
    pt = system.pairs
    caps = tuple(int(system.caps[k]) for k in group)
    n_t = math.prod(caps)
    grid = np.stack(np.unravel_index(np.arange(n_t), caps), axis=1) + 1  # (T, |G|) AoI vectors
    step = np.minimum(grid + 1, np.asarray(caps))
    W = np.zeros((pt.n_pairs, n_t))
    block = max(1, BLOCK_ENTRIES // (n_t * len(group)))
    for o in range(pt.n_outcomes):
        prob = pt.prob[:, o]
        real = np.flatnonzero(prob > 0)
        for b in range(0, real.size, block):
            idx = real[b:b + block]
            d = pt.deltas[pt.delta[idx, o]][:, list(group)][:, None, :]  # (E, 1, |G|)
            tn = np.where(d > 0, np.minimum(step[None], d), step[None])  # (E, T, |G|)
            nxt = col[pt.nxt[idx, o]][:, None]
            W[idx] += prob[idx, None] * h[(nxt,) + tuple(tn[..., i] - 1 for i in range(len(group)))]
    return W


def projected_tables(result: BoundResult) -> tuple[tuple, tuple, tuple] | None:
    """(groups, h, column) of a bound whose tables are read on private configurations, else None."""
    if result.relaxation not in PROJECTED:
        return None
    t = result.tables
    if isinstance(t, GroupTables):
        return tuple(tuple(g) for g in t.groups), tuple(t.h), tuple(t.column)
    return tuple((k,) for k in range(len(t.h))), tuple(t.h), tuple(t.column)


def project_configs(system: System, group: Sequence[int], index: dict, configs: np.ndarray) -> np.ndarray:
    """The private configuration ids (``index``: the group's private automaton's) of the joint
    configurations ``configs`` of ``system``, projected on ``group``."""
    model, joint = system.model, system.automaton.configs
    try:
        return np.array([index[model.project_group(joint[c], group)] for c in np.asarray(configs).tolist()],
                        np.int64)
    except KeyError as exc:  # the projection argument says this cannot happen
        raise PolicyError(f"internal error: the projection {exc} of a joint configuration on the group "
                          f"{tuple(k + 1 for k in group)} is not a configuration of its private system") from None


def _grown(a: np.ndarray, size: int, axis: int) -> np.ndarray:
    """``a`` with room for ``size`` entries along ``axis`` (at least twice its length on a lazily
    explored system; exactly ``size`` the first time), its content kept."""
    n = a.shape[axis]
    shape = list(a.shape)
    shape[axis] = size if n == 0 else max(size, 2 * n)
    out = np.zeros(shape, a.dtype)
    out[(slice(None),) * axis + (slice(0, n),)] = a
    return out


class ProjectedLookahead:
    """The lookahead sum_G W_G(C, a, tau_G) of value tables over private configurations, read
    through projections (module docstring).

    Parameters
    ----------
    system : System
        The joint system.
    groups : sequence of sequences of int
        A partition of the processes (0-based); singletons for relaxation 1.
    h : sequence of arrays
        ``h[i]`` of shape (n_cols_i, tau_hat of each member of group i): rows numbered like the
        configurations of group i's private system (:meth:`Model.group_scenario`, explored by
        :meth:`System.from_scenario`), as the bounds number them.
    column : sequence of (|C|,) int arrays, optional
        The bound's own column maps, checked against the projections on a sample of joint
        configurations (a mismatch is a :class:`~wncs_lp.errors.PolicyError`: the tables are not
        numbered like the private systems).

    Attributes
    ----------
    groups : tuple of tuples
    private : tuple of System
        Each group's private system (identical groups share one).
    nbytes : int
        Memory of the member tables and the per-pair maps.
    """

    def __init__(self, system: System, groups: Sequence[Sequence[int]], h: Sequence[np.ndarray],
                 column: Sequence[np.ndarray] | None = None):
        self.system = system
        model = system.model
        N, M = system.n_processes, system.n_servers
        self.groups = tuple(tuple(int(k) for k in g) for g in groups)
        if sorted(k for g in self.groups for k in g) != list(range(N)) or len(h) != len(self.groups):
            raise PolicyError(f"expected a partition of the {N} processes and one value table per group, found "
                              f"groups {[list(g) for g in self.groups]} and {len(h)} tables")
        by_key: dict[str, System] = {}
        private = []
        for g in self.groups:
            sc = model.group_scenario(g)
            key = chain_key(sc)
            if key not in by_key:
                by_key[key] = System.from_scenario(sc)
            private.append(by_key[key])
        self.private = tuple(private)
        for i, (g, hi, ps) in enumerate(zip(self.groups, h, self.private)):
            want = (ps.n_configs,) + tuple(int(system.caps[k]) for k in g)
            if np.shape(hi) != want or not np.all(np.isfinite(hi)):
                raise PolicyError(f"group {tuple(k + 1 for k in g)}: value table of shape {np.shape(hi)}, expected "
                                  f"{want} finite values (private configurations, tau_hat of each member)")
        # member tables, shared by members with the same private system and the same values
        self._T = np.array([math.prod(int(system.caps[k]) for k in g) for g in self.groups], np.int64)
        distinct: list[tuple[System, np.ndarray]] = []
        which = []
        for ps, hi in zip(self.private, h):
            j = next((j for j, (q, hq) in enumerate(distinct) if q is ps and np.array_equal(hq, hi)), None)
            if j is None:
                distinct.append((ps, np.asarray(hi, float)))
                j = len(distinct) - 1
            which.append(j)
        need = sum(8 * q.pairs.n_pairs * hq[0].size for q, hq in distinct)
        require_memory(need, f"the projected lookahead tables of {len(distinct)} distinct private systems",
                       ["relaxation 1 (--relaxation 1: one process per private system, smallest tables)"])
        tables = [lookahead_table(q, tuple(range(hq.ndim - 1)), hq) for q, hq in distinct]
        offs = np.cumsum([0] + [t.size for t in tables])
        self._W = np.concatenate([t.ravel() for t in tables]) if tables else np.zeros(0)
        self._off = np.array([offs[j] for j in which], np.int64)
        # private action codes: server m's entry is the member's rank (1-based) of the process sent there
        self._member_of = np.empty(N, np.int64)
        self._rank = np.empty(N, np.int64)
        for i, g in enumerate(self.groups):
            self._member_of[list(g)] = i
            self._rank[list(g)] = np.arange(1, len(g) + 1)
        self._strides = np.zeros((N, len(self.groups)), np.int64)  # C order within each group
        for i, g in enumerate(self.groups):
            for j, k in enumerate(g):
                self._strides[k, i] = math.prod(int(system.caps[kk]) for kk in g[j + 1:])
        self._base = max(len(g) for g in self.groups) + 1
        self._codes = self._base ** M
        order = list({id(ps): ps for ps in self.private}.values())  # the distinct private systems
        luts = [self._lut(ps) for ps in order]
        starts = np.cumsum([0] + [lut.size for lut in luts])
        self._lut_flat = np.concatenate([lut.ravel() for lut in luts])
        self._lut_off = np.array([starts[next(j for j, q in enumerate(order) if q is ps)] for ps in self.private],
                                 np.int64)
        # per joint configuration and per pair: filled by prepare() (capacity doubling on a lazy system)
        self._n_configs = self._n_pairs = 0
        self._col = np.zeros((len(self.groups), 0), np.int64)
        self._idle = np.zeros((len(self.groups), 0), np.int64)
        self._touch = np.zeros((0, M), np.int64)
        self._tpair = np.zeros((0, M), np.int64)
        self._column = None if column is None else tuple(np.asarray(c, np.int64) for c in column)
        if column is not None:
            self._check_columns(column)
        self.prepare()

    def kernel_arrays(self) -> tuple[np.ndarray, ...]:
        """The lookahead's arrays as a kernel reads them, for the configurations and pairs known
        (:meth:`prepare`): ``(W, off, width, idle, touch, tpair)`` with member i's value at private
        pair r and AoI index t in ``W[off[i] + r * width[i] + t]``, ``idle[i, c]`` its "send
        nothing" pair in joint configuration c, and ``touch[p, m]`` / ``tpair[p, m]`` the member
        server m's entry of joint pair p sends to (-1: none or listed already) and its private pair
        (:mod:`wncs_lp.bounds.lookahead_kernels`)."""
        self.prepare()
        n, p = self._n_configs, self._n_pairs
        return (self._W, self._off, self._T, np.ascontiguousarray(self._idle[:, :n]),
                np.ascontiguousarray(self._touch[:p]), np.ascontiguousarray(self._tpair[:p]))

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self._W, self._lut_flat, self._col, self._idle, self._touch, self._tpair)))

    def _lut(self, ps: System) -> np.ndarray:
        """(private configurations, codes) -> the private pair of that action label there (-1: none)."""
        pt = ps.pairs
        lut = np.full((ps.n_configs, self._codes), -1, np.int64)
        code = (pt.labels * (self._base ** np.arange(pt.labels.shape[1]))[None, :]).sum(axis=1)
        lut[pt.config_of, code] = np.arange(pt.n_pairs)
        if np.any(lut[:, 0] < 0):
            raise PolicyError("a private system without the 'send nothing' action in some configuration; the "
                              "projected lookahead needs it (private systems may idle)")
        return lut

    def _project(self, i: int, configs: np.ndarray) -> np.ndarray:
        """Group i's private configuration id of joint configurations ``configs``."""
        return project_configs(self.system, self.groups[i], self.private[i].automaton.index, configs)

    def _check_columns(self, column: Sequence[np.ndarray]) -> None:
        # the column maps cover the configurations known when the bound was computed: on a lazily
        # explored system a simulation may have met more since (those are projected, prepare())
        n = self.system.n_configs
        for i in range(len(self.groups)):
            col = np.asarray(column[i])
            m = col.shape[0] if col.ndim == 1 else -1
            sample = np.unique(np.linspace(0, m - 1, min(max(m, 1), CHECK_CONFIGS)).astype(np.int64))
            if not 0 < m <= n or not np.array_equal(col[sample], self._project(i, sample)):
                raise PolicyError(f"group {tuple(k + 1 for k in self.groups[i])}: the tables' column map is not the "
                                  "projection on its private system (tables numbered otherwise)")

    def prepare(self) -> None:
        """Compute the projections of the configurations and pairs the system knows and this
        lookahead does not yet (all of them for an enumerated system; the new ones after
        :meth:`System.expand` on a lazily explored one)."""
        s = self.system
        n_old, n_new = self._n_configs, s.n_configs
        if n_new > n_old:
            new = np.arange(n_old, n_new)
            col = np.empty((len(self.groups), new.size), np.int64)
            for i in range(len(self.groups)):
                known = self._column[i] if self._column is not None else np.zeros(0, np.int64)
                inside = new < known.shape[0]  # read from the tables' map; configurations met since projected
                col[i, inside] = known[new[inside]]
                if not inside.all():
                    col[i, ~inside] = self._project(i, new[~inside])
            if n_new > self._col.shape[1]:
                self._col, self._idle = (_grown(a, n_new, axis=1) for a in (self._col, self._idle))
            self._col[:, n_old:n_new] = col
            self._idle[:, n_old:n_new] = self._lut_flat[self._lut_off[:, None] + col * self._codes]
            self._n_configs = n_new
        pt = s.pairs
        p_old = self._n_pairs
        if pt.n_pairs > p_old:
            if pt.n_pairs > self._touch.shape[0]:
                self._touch, self._tpair = (_grown(a, pt.n_pairs, axis=0) for a in (self._touch, self._tpair))
            self._touch[p_old:pt.n_pairs], self._tpair[p_old:pt.n_pairs] = self._pair_maps(pt, p_old)
            self._n_pairs = pt.n_pairs

    def _pair_maps(self, pt, p0: int) -> tuple[np.ndarray, np.ndarray]:
        """For pairs p0.. of the joint system: the member each server's entry sends to (-1: none, or
        a member already listed) and that member's private pair."""
        labels = pt.labels[p0:]
        c = pt.config_of[p0:]
        M = labels.shape[1]
        k = labels - 1
        mem = np.where(k >= 0, self._member_of[np.maximum(k, 0)], -1)  # (P, M)
        rank = np.where(k >= 0, self._rank[np.maximum(k, 0)], 0)
        powers = self._base ** np.arange(M)
        touch = mem.copy()
        tpair = np.zeros_like(mem)
        for m in range(M):
            dup = np.zeros(mem.shape[0], bool)
            for m2 in range(m):
                dup |= mem[:, m2] == mem[:, m]
            touch[dup, m] = -1
            i = np.maximum(mem[:, m], 0)
            code = ((mem == mem[:, m][:, None]) * rank * powers[None, :]).sum(axis=1)
            tpair[:, m] = self._lut_flat[self._lut_off[i] + self._col[i, c] * self._codes + code]
        if np.any(tpair[touch >= 0] < 0):
            raise PolicyError("internal error: a projected action is not feasible in its private system")
        return touch, tpair

    def _tau_index(self, tau: np.ndarray) -> np.ndarray:
        """(R, members) flat C-order index of each member's AoI vector: (tau - 1) @ strides."""
        return (tau - 1) @ self._strides

    def values(self, tau: np.ndarray, c: np.ndarray, *, base: bool = True) -> np.ndarray:
        """(R, A_max) sum_G W_G(C, a, tau_G) over the local actions of each state (+inf on actions a
        configuration lacks); ``base=False`` leaves out the part common to every action of a state."""
        self.system.expand(c)
        self.prepare()
        s = self.system
        t = self._tau_index(tau)
        r = np.arange(c.size)[:, None]
        idle_at = self._off[None, :] + self._idle[:, c].T * self._T[None, :] + t  # (R, members)
        p, valid = s.pairs.padded(c, int(s.pairs.count[c].max(initial=1)))
        v = np.zeros(p.shape)
        for m in range(self._touch.shape[1]):
            i = self._touch[p, m]
            on = i >= 0
            i0 = np.maximum(i, 0)
            ti = t[r, i0]
            gain = self._W[self._off[i0] + self._tpair[p, m] * self._T[i0] + ti] - self._W[idle_at[r, i0]]
            v += np.where(on, gain, 0.0)
        if base:
            v += self._W[idle_at].sum(axis=1)[:, None]
        out = np.full((c.size, s.max_actions), np.inf)
        out[:, :v.shape[1]] = np.where(valid, v, np.inf)
        return out


class ProjectedBoundPolicy(Policy):
    """The greedy policy of a relaxation-1 or relaxation-3 bound, its lookahead read through the
    projections on the private systems (:class:`ProjectedLookahead`): the actions of
    :class:`~wncs_lp.bounds.BoundPolicy` / :class:`~wncs_lp.bounds.GroupBoundPolicy` (up to ties
    at rounding level), in memory linear in the number of processes. Ties go to the first action.

    Parameters
    ----------
    result : BoundResult
        Of relaxation 1 or 3 (:data:`PROJECTED`).
    system : System
        The system the bound was computed on.

    Attributes
    ----------
    result : BoundResult
    lookahead : ProjectedLookahead
    build_seconds : float
    """

    name = "bound"
    explores_lazily = True

    def __init__(self, result: BoundResult, system: System):
        super().__init__(system)
        t0 = time.perf_counter()
        parts = projected_tables(result)
        if parts is None:
            raise PolicyError(f"the {result.relaxation} bound's tables are not over private configurations; "
                              "use bound_policy")
        groups, h, column = parts
        if sum(len(g) for g in groups) != system.n_processes or (not system.is_lazy and any(
                np.shape(col) != (system.n_configs,) for col in column)):
            raise PolicyError(f"the {result.relaxation} bound's tables belong to another system "
                              f"({sum(len(g) for g in groups)} processes; this system has {system.n_processes} "
                              f"processes and {system.n_configs} configurations)")
        self.result = result
        self.name = f"bound[{result.relaxation}]"
        self.lookahead = ProjectedLookahead(system, groups, h, column)
        self.build_seconds = time.perf_counter() - t0

    def values(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A_max) lookahead values (+inf on infeasible actions)."""
        tau, c = self._check_inputs(tau, config_ids)
        return self.lookahead.values(tau, c)

    def act(self, tau, config_ids, rng=None):
        """The first action whose value is within :data:`TIE` (relative) of the least: the sums are
        formed in another order than the joint tables', so exact ties there are ties to rounding here."""
        tau, c = self._check_inputs(tau, config_ids)
        v = self.lookahead.values(tau, c)
        best = v.min(axis=1, keepdims=True)
        return np.argmax(v <= best + TIE * np.abs(best), axis=1).astype(np.int64)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "relaxation": self.result.relaxation, "lower_bound": self.result.lower_bound,
                "lookahead": "projected", "lookahead_bytes": self.lookahead.nbytes,
                "build_seconds": self.build_seconds}


class ProjectedValue:
    """h(tau, C) = sum_G h_G(tau_G, column_G(C)) of a bound over private configurations, on a
    system that may be explored lazily: the column of a joint configuration met after the bound
    was computed is its projection on the group's private system, found when first asked for
    (the bound's own column maps cover the configurations known then). The simulator's control
    variate (:func:`wncs_lp.bounds.policy_gaps`) reads a bound's tables through it.
    """

    def __init__(self, result: BoundResult, system: System):
        parts = projected_tables(result)
        if parts is None:
            raise PolicyError(f"the {result.relaxation} bound's tables are not over private configurations")
        groups, h, column = parts
        self.system = system
        self.groups = groups
        self.h = tuple(np.asarray(x, float) for x in h)
        by_key: dict[str, Any] = {}
        self._index = []
        for g in groups:
            sc = system.model.group_scenario(g)
            by_key.setdefault(chain_key(sc), System.from_scenario(sc).automaton.index)
            self._index.append(by_key[chain_key(sc)])
        self._col = [np.asarray(c, np.int64) for c in column]

    def _grow(self, n: int) -> None:
        for i, g in enumerate(self.groups):
            have = self._col[i].size
            if have < n:
                new = project_configs(self.system, g, self._index[i], np.arange(have, n))
                self._col[i] = np.concatenate([self._col[i], new])

    def __call__(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        tau = np.asarray(tau, np.int64)
        c = np.asarray(config_ids, np.int64)
        if c.size:
            self._grow(int(c.max()) + 1)
        out = np.zeros(tau.shape[0])
        for i, (g, hg) in enumerate(zip(self.groups, self.h)):
            out += hg[(self._col[i][c], *(tau[:, k] - 1 for k in g))]
        return out

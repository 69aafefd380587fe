r"""Relaxation 4: relaxation 2 with the processes' ages kept jointly in pairs -- a tighter
certified lower bound on g*.

The relaxation
--------------
Relaxation 2 (:mod:`wncs_lp.bounds.joint`) keeps the joint server configuration C and one value
table per process, h(s) = sum_k h_k(tau_k, C). Relaxation 4 takes a partition of the processes
into **groups** G of one or two processes and one table per group on the group's ages jointly,

.. math::  h(\tau, C) = \sum_G h_G(\tau_G, C),

in the average-cost approximate LP

.. math::

    \max_{g, h}\; g \quad\text{s.t.}\quad g + \sum_G h_G(\tau_G, C)
    \le \sum_k q_k(\tau_k) + \sum_o P(o|C,a) \sum_G h_G(\tau'_G, C'_o) \quad \forall (\tau, C, a).

Any feasible (g, h) has g <= g* (sum the constraint over the stationary law of an optimal
policy: a Bellman sub-solution). For fixed (C, a) the constraint is a sum over groups of terms in
tau_G alone (q_G = sum_{k in G} q_k), so it holds for every tau iff sum_G u_G(C, a) <= -g with

.. math::

    u_G(C, a) = \max_{\tau_G} \Big[h_G(\tau_G, C) - q_G(\tau_G)
                - \sum_o P(o|C,a)\, h_G(\tau'_G(o), C'_o)\Big].

Hence for **any** tables, g(h) = -max_(C,a) sum_G u_G(C, a) <= g*
(:func:`certify_group_tables`, the only thing the bound rests on). Tables h_G = sum_{k in G} h_k
give exactly relaxation 2's constraints, so relaxation 4's optimum is never below relaxation 2's,
and the search below starts from relaxation 2's tables.

Its Lagrangian
--------------
Dualising the shared (C, a) marginal with prices mu_G(C, a) summing to zero over the groups gives
L(mu) = sum_G g_G(mu_G), g_G the optimal gain of group G's **priced chain** on (tau_G, C) with
pair cost q_G(tau_G) + mu_G(C, a): an MDP of prod_{k in G} tau_hat_k |C| states, solved by
relative value iteration (:func:`solve_group_chain`). Its bias tables certify at least the sum of
the chains' lower Bellman brackets: with lower_G = min (T h_G - h_G), u_G(p) <= mu_G(p) - lower_G,
so g(h) >= sum_G lower_G.

At relaxation 2's prices summed over each group's members, mu_G = sum_{k in G} mu_k, the group's
chain is worth at least the sum of its members' chains (one controller choosing (C, a) for both
instead of each its own; the sum of the members' sub-solutions is a sub-solution of the group's
chain), so relaxation 4 starts at relaxation 2's bound or above, and the proximal bundle of
:mod:`~wncs_lp.bounds.joint_bundle` (groups in place of processes) raises L from there.

Where interchangeable processes are paired with each other, L is invariant under the permutations
of process names that map every group onto itself; L being concave, its maximum is reached at
prices invariant under them, and at such prices each group's chain lumps by the permutations that
fix its members (:class:`GroupLumps`): the search runs on the lumped chains and on prices per orbit
of pairs, and its tables, spread back, are certified on the whole system. A pair of two
interchangeable processes is moreover symmetric under its own swap (:class:`PairSwap`): its sweeps
and cuts are computed on one state of each orbit of that swap and mirrored.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import SolverError
from ..models.system import System
from ..progress import as_progress
from ..solvers.threads import run_twins
from ..status import INTERRUPTED, MAX_ITER, OPTIMAL
from .inputs import bound_system
from .joint import joint_bound
from .joint_bundle import PriceBundle
from .joint_chains import ChainSolution, JointData, TableCertificate, certificate_of, damped_rvi, lazy_power
from .joint_symmetry import ProcessSymmetry, orbit_labels, process_symmetry
from .result import BoundResult, GroupTables, ValueTables

__all__ = ["pairs_bound", "pairs_size", "GroupChains", "GroupLumps", "PairSwap", "certify_group_tables", "solve_group_chain", "group_cut",
           "candidate_partitions",
           "pair_partition"]

def _mod():
    """The numba kernels (relaxation 4's chains and check have no numpy path: without numba they
    would be hundreds of times slower)."""
    try:
        from . import pairs_kernels
    except ImportError as exc:
        raise SolverError(f"relaxation 4 needs numba (pip install 'wncs_lp[fast]'): {exc}") from None
    return pairs_kernels


@dataclass(frozen=True, eq=False)
class GroupChains:
    """The groups of a partition and the arrays their chains run on.

    Attributes
    ----------
    data : JointData
    groups : tuple of tuples
        The partition (0-based; groups of one or two processes, members increasing).
    c1, c2 : tuple of int
        Per group the caps of its first and second member (c2 = 1 for a group of one).
    s1, s2 : tuple of (E,) int arrays
        Per group the saturation columns (:attr:`JointData.sat`) of its members (zeros for a
        missing second member).
    q : tuple of (c1 * c2,) arrays
        q_G(T) = q_{k1}(t1) + q_{k2}(t2) at the flat index T = t1 * c2 + t2.
    swaps : tuple of PairSwap or None
        Per group its own swap where its chain is symmetric under it (:class:`PairSwap`: the
        sweeps and the cuts computed on one state of each orbit); empty: none.
    """

    data: JointData
    groups: tuple
    c1: tuple
    c2: tuple
    s1: tuple
    s2: tuple
    q: tuple
    swaps: tuple = ()

    @classmethod
    def build(cls, data: JointData, groups) -> "GroupChains":
        groups = _checked_groups(data.n_processes, groups)
        c1, c2, s1, s2, q = [], [], [], [], []
        zero = np.zeros(data.n_outcomes, dtype=np.int64)
        for g in groups:
            a = g[0]
            c1.append(int(data.caps[a]))
            s1.append(data.sat_of(a))
            if len(g) == 2:
                b = g[1]
                c2.append(int(data.caps[b]))
                s2.append(data.sat_of(b))
                q.append((data.q[a][:, None] + data.q[b][None, :]).ravel())
            else:
                c2.append(1)
                s2.append(zero)
                q.append(np.asarray(data.q[a], float).copy())
        return cls(data, groups, tuple(c1), tuple(c2), tuple(s1), tuple(s2), tuple(q))

    @property
    def n_groups(self) -> int:
        return len(self.groups)

    def shape(self, i: int) -> tuple[int, int]:
        """(|C|, c1 * c2): group i's table, flat over its ages."""
        return self.data.n_configs, self.c1[i] * self.c2[i]

    def swap(self, i: int) -> "PairSwap | None":
        return self.swaps[i] if self.swaps else None

    def args(self, i: int) -> tuple:
        d = self.data
        return (self.c1[i], self.c2[i], d.act_ptr, d.out_ptr, d.out_nxt, d.out_prob, self.s1[i], self.s2[i])

    def from_separable(self, tables) -> list[np.ndarray]:
        """Group tables h_G(t1, t2, C) = h_{k1}(t1, C) + h_{k2}(t2, C) of per-process tables."""
        out = []
        for g in self.groups:
            h = np.asarray(tables[g[0]], float)
            if len(g) == 2:
                h = (h[:, :, None] + np.asarray(tables[g[1]], float)[:, None, :]).reshape(h.shape[0], -1)
            out.append(np.ascontiguousarray(h))
        return out

    def as_grids(self, tables) -> tuple:
        """Flat tables (|C|, c1 * c2) as (|C|, tau_hat_{k1}[, tau_hat_{k2}]) arrays (GroupTables' layout)."""
        return tuple(np.asarray(h).reshape((self.data.n_configs,) + ((c1,) if len(g) == 1 else (c1, c2)))
                     for h, g, c1, c2 in zip(tables, self.groups, self.c1, self.c2))


def _checked_groups(n: int, groups) -> tuple:
    try:
        gs = tuple(tuple(sorted(int(k) for k in g)) for g in groups)
    except (TypeError, ValueError):
        raise SolverError(f"groups must be a partition of the processes 0..{n - 1} into groups of one or two, "
                          f"got {groups!r}") from None
    flat = sorted(k for g in gs for k in g)
    if flat != list(range(n)) or any(len(g) not in (1, 2) for g in gs):
        raise SolverError(f"groups must be a partition of the processes 0..{n - 1} into groups of one or two, "
                          f"got {[list(g) for g in gs]}")
    return gs


def pair_partition(order) -> tuple:
    """The partition pairing consecutive processes of ``order`` ((a b) (c d) ...; a last one alone)."""
    order = [int(k) for k in order]
    return tuple(tuple(sorted(order[i:i + 2])) for i in range(0, len(order), 2))


# ---------------------------------------------------------------------------- the symmetry reduction
def _swap_maps(sym: ProcessSymmetry, x: int, y: int) -> tuple[np.ndarray, np.ndarray]:
    """(configuration map, pair map) of the transposition (x y) of one class: stored, or
    (r x)(r y)(r x) from the stored transpositions with the class's representative r."""
    if (min(x, y), max(x, y)) in sym.config_maps:
        return sym.transposition(x, y)
    r = sym.class_of(x)[0]
    (cx, px), (cy, py) = sym.transposition(r, x), sym.transposition(r, y)
    return cx[cy[cx]], px[py[px]]


@dataclass(frozen=True, eq=False)
class PairSwap:
    r"""A pair's chain lumped by its own swap: sigma (t1, t2, C) = (t2, t1, sigma C).

    Where the group's two members are interchangeable (the same costs, caps and links) and its
    prices are sigma-invariant (the search's are: sigma is in Gamma, :class:`GroupLumps`), sigma
    maps the chain onto itself: the state (t1, t2, C) under pair p = (C, a) and (t2, t1, sigma C)
    under sigma p have the same cost and the same price, and their outcomes correspond (sigma o
    delivers to the members in the other order). So T h is sigma-invariant when h is, the
    relative value iteration from a sigma-invariant start stays on sigma-invariant tables (its
    fixed point and brackets are the whole chain's), a greedy policy may be taken sigma-equivariant,
    and its stationary law from a sigma-invariant start is sigma-invariant. Each sweep and push is
    then computed on one state of each sigma-orbit and mirrored (``pairs_kernels.bellman_sym_ser``,
    ``push_sym``); the tables still live on every state, and are certified on the whole system.

    Attributes
    ----------
    kind : (|C|,) int8 array
        0: configuration computed whole (its image is larger); 1: sigma C = C, only t2 >= t1
        computed; 2: the image of a smaller configuration (not computed).
    config : (|C|,) int array
        sigma on the chain's configurations.
    pair : (|C x A|,) int array
        sigma on the chain's pairs.
    todo : int array
        The configurations of kind 0 or 1.
    """

    kind: np.ndarray
    config: np.ndarray
    pair: np.ndarray
    todo: np.ndarray

    @classmethod
    def of(cls, config: np.ndarray, pair: np.ndarray) -> "PairSwap":
        n = config.size
        kind = np.where(config > np.arange(n), 0, np.where(config == np.arange(n), 1, 2)).astype(np.int8)
        return cls(kind, np.ascontiguousarray(config, dtype=np.int64), np.ascontiguousarray(pair, dtype=np.int64),
                   np.flatnonzero(kind != 2).astype(np.int64))

    def symmetrised(self, table: np.ndarray, c2: int) -> np.ndarray:
        """(table + table o sigma) / 2 for a table over (C, t1 * c2 + t2) of a square pair: the
        sigma-invariant start of the chains' iteration and of the cuts' power iteration."""
        t = np.arange(table.shape[1])
        return 0.5 * (table + table[self.config][:, (t % c2) * c2 + t // c2])

    @property
    def share(self) -> float:
        """The fraction of a whole sweep computed (states, weighed alike)."""
        return float(np.mean(np.where(self.kind == 0, 1.0, np.where(self.kind == 1, 0.5, 0.0))))


@dataclass(frozen=True, eq=False)
class GroupLumps:
    r"""Each group's priced chain lumped by the symmetry of interchangeable processes.

    Let Gamma be the permutations of process names generated by the transpositions (x y) of
    interchangeable processes (:func:`~wncs_lp.bounds.joint_symmetry.process_symmetry`) that map
    every group of the partition onto itself (no group holds exactly one of x, y: the paper's four
    types twice, paired by type, keeps all four). Gamma acts on configurations and pairs, and
    maps each group's priced chain at prices mu_G onto the same chain at mu_G o sigma^{-1} (its
    states (tau_G, C) to (tau_G, sigma C), the members' ages swapped when sigma swaps them).
    So L(sigma mu) = L(mu) with the zero-sum coupling kept, and L being concave, averaging any
    prices over Gamma does not lower L: the maximum of L is reached at **Gamma-invariant prices**,
    one per group and Gamma-orbit Q of pairs. At such prices, group G's chain is lumpable by
    H_G, the permutations of Gamma generated by the transpositions disjoint from G (they fix its
    members, hence their deliveries, and the outcome probabilities): the lumped chain on
    (tau_G, H_G-orbit of configurations) has the same gain, its bias read on the orbits is the
    whole chain's, and a policy's stationary law on it sums the whole chain's over orbits. The
    tables are certified on the whole system after all (:func:`certify_group_tables` on the
    tables spread back), so a wrong symmetry could only loosen the bound, never invalidate it.

    Attributes
    ----------
    chains : tuple of GroupChains
        Group i's lumped chain: a one-group :class:`GroupChains` on a JointData of the group's
        members over the H_G-orbits of configurations (each orbit of pairs represented by its
        first pair's outcomes, next configurations read as their orbits).
    config_orbit : tuple of (|C|,) int arrays
        Each whole configuration's orbit in group i's lumped chain (tables spread by it).
    price_of : tuple of int arrays
        The Gamma-orbit Q of each lumped pair of group i (its price is mu_G(Q)).
    pair_orbit : (|C x A|,) int array
        The Gamma-orbit of each whole pair.
    n_prices : int
        The number of Gamma-orbits of pairs (prices per group).
    """

    chains: tuple
    config_orbit: tuple
    price_of: tuple
    pair_orbit: np.ndarray
    n_prices: int

    @classmethod
    def build(cls, data: JointData, groups: tuple, sym: ProcessSymmetry | None,
              own_swap: bool = True) -> "GroupLumps":
        swaps = []
        for cl in (sym.classes if sym is not None else ()):
            for i, x in enumerate(cl):
                for y in cl[i + 1:]:
                    if all((x in g) == (y in g) for g in groups):
                        swaps.append((x, y))
        maps = {s: _swap_maps(sym, *s) for s in swaps}
        n_q, qorb = orbit_labels([maps[s][1] for s in swaps], data.n_pairs)
        lens = np.diff(data.out_ptr)
        chains, corbs, price_of = [], [], []
        for g in groups:
            mine = [maps[s] for s in swaps if not set(s) & set(g)]
            n_k, corb = orbit_labels([m[0] for m in mine], data.n_configs)
            n_o, porb = orbit_labels([m[1] for m in mine], data.n_pairs)
            first = np.full(n_o, -1, dtype=np.int64)
            first[porb[::-1]] = np.arange(data.n_pairs)[::-1]  # each orbit's smallest pair
            conf = corb[data.pair_c[first]]
            first = first[np.argsort(conf, kind="stable")]  # grouped by orbit of configurations
            counts = np.bincount(conf, minlength=n_k)
            n_out = lens[first]
            idx = np.repeat(data.out_ptr[first] - np.cumsum(n_out) + n_out, n_out) + np.arange(int(n_out.sum()))
            lumped = JointData(caps=data.caps[list(g)].copy(), q=tuple(data.q[k] for k in g),
                               act_ptr=np.r_[0, np.cumsum(counts)].astype(np.int64),
                               pair_c=np.repeat(np.arange(n_k), counts).astype(np.int64),
                               out_ptr=np.r_[0, np.cumsum(n_out)].astype(np.int64),
                               out_nxt=np.ascontiguousarray(corb[data.out_nxt[idx]]),
                               out_prob=np.ascontiguousarray(data.out_prob[idx]),
                               out_delta=np.ascontiguousarray(data.out_delta[idx][:, list(g)]))
            chain = GroupChains.build(lumped, [tuple(range(len(g)))])
            if own_swap and g in maps:
                chain = replace(chain, swaps=(_own_swap(data, g, maps[g], corb, n_k, porb, first, lumped),))
            chains.append(chain)
            corbs.append(corb)
            price_of.append(qorb[first])
        return cls(tuple(chains), tuple(corbs), tuple(price_of), qorb, n_q)

    def prices_of(self, mu: np.ndarray) -> np.ndarray:
        """Whole-system prices (groups, |C x A|) averaged over each Gamma-orbit: (groups, n_prices)."""
        size = np.bincount(self.pair_orbit, minlength=self.n_prices)
        return np.array([np.bincount(self.pair_orbit, weights=m, minlength=self.n_prices) / size for m in mu])

    def spread(self, i: int, h: np.ndarray) -> np.ndarray:
        """Group i's lumped table (orbits, ages) on every whole configuration."""
        return np.ascontiguousarray(h[self.config_orbit[i]])

    def lumped(self, i: int, h: np.ndarray) -> np.ndarray:
        """A whole table of group i read at the first configuration of each orbit (a warm start)."""
        first = np.full(self.chains[i].data.n_configs, -1, dtype=np.int64)
        first[self.config_orbit[i][::-1]] = np.arange(self.config_orbit[i].size)[::-1]
        return np.ascontiguousarray(h[first])


def _own_swap(data: JointData, g: tuple, maps: tuple, corb: np.ndarray, n_k: int, porb: np.ndarray,
              first: np.ndarray, lumped: JointData) -> "PairSwap | None":
    """Group g's own swap on its chain lumped by H_G (sigma commutes with H_G, so it acts on the
    orbits), or None where the chain is not symmetric under it (caps or costs differ)."""
    a, b = g
    if data.caps[a] != data.caps[b] or not np.array_equal(data.q[a], data.q[b]):
        return None
    cmap, pmap = maps
    firstc = np.full(n_k, -1, dtype=np.int64)
    firstc[corb[::-1]] = np.arange(corb.size)[::-1]
    config = corb[cmap[firstc]]
    inv = np.empty(first.size, dtype=np.int64)
    inv[porb[first]] = np.arange(first.size)
    pair = inv[porb[pmap[first]]]
    if not np.array_equal(lumped.pair_c[pair], config[lumped.pair_c]) or not np.array_equal(config[config],
                                                                                            np.arange(n_k)):
        return None
    return PairSwap.of(config, pair)


# ---------------------------------------------------------------------------- the certificate
def certify_group_tables(chains: GroupChains, tables) -> TableCertificate:
    r"""The certified lower bound g(h) of group tables ``tables[i]`` of shape (|C|, c1 * c2).

    Valid for *any* tables (module docstring): u_G(p) = max over the group's ages of
    h_G - q_G - E h_G, g(h) = -max_p sum_G u_G(p), minus a bound on the round-off (Higham's gamma
    bounds on the sums and the outcome tables' defect from stochastic times max |h|). Each
    table is first shifted by a constant, which changes no constraint beyond that defect.
    """
    d = chains.data
    n_g = chains.n_groups
    if len(tables) != n_g:
        raise SolverError(f"relaxation 4's certificate needs {n_g} group tables, got {len(tables)}")
    hs = []
    for i, h in enumerate(tables):
        h = np.asarray(h, dtype=float)
        if h.shape != chains.shape(i):
            raise SolverError(f"group table {i} (processes {[k + 1 for k in chains.groups[i]]}) has shape {h.shape}; "
                              f"expected {chains.shape(i)} (configurations x ages of the group)")
        hs.append(h)
    def residual_max(i: int, h: np.ndarray) -> np.ndarray:
        u = np.empty(d.n_pairs)
        _mod().residuals(np.ascontiguousarray(h), chains.q[i], *chains.args(i), u)
        return u

    return certificate_of(d, hs, chains.q, residual_max)


# ---------------------------------------------------------------------------- a group's priced chain
def solve_group_chain(chains: GroupChains, i: int, price: np.ndarray, h0: np.ndarray | None, *, tol: float,
                      max_sweeps: int = 100_000, relax: float = 0.9, threads: int = 1,
                      stop=None) -> ChainSolution:
    """Relative value iteration on group i's priced chain until upper - lower <= tol * max(|lower|, 1)
    (damped: h <- h + relax (T h - h), recentred)."""
    mod = _mod()
    shape = chains.shape(i)
    h = np.zeros(shape) if h0 is None else np.array(h0, dtype=float, copy=True)
    th = np.empty(shape)
    pol = np.empty(shape, dtype=np.int64)
    price = np.ascontiguousarray(price, dtype=float)
    sw = chains.swap(i)
    if sw is None:
        kernels, args = (mod.bellman_par, mod.bellman_ser), (chains.q[i], price, *chains.args(i), th, pol)
    else:  # one state of each orbit of the pair's own swap, then the rest mirrored (PairSwap)
        h = sw.symmetrised(h, chains.c2[i])  # a sigma-invariant start
        kernels = (mod.bellman_sym_par, mod.bellman_sym_ser)
        args = (chains.q[i], price, *chains.args(i), sw.kind, sw.config, sw.pair, sw.todo, th, pol)

    def bellman(x):  # on threads the configurations split, each writing its own rows: the same numbers
        run_twins(*kernels, threads, x, *args)
    lo, hi, sweeps = damped_rvi(bellman, h, th, tol=tol, max_sweeps=max_sweeps, relax=relax, stop=stop,
                                fused=(mod.bracket, mod.relax_update))
    return ChainSolution(h=h, lower=lo, upper=hi, policy=pol, sweeps=sweeps)


#: The lazy weight of the cuts' power iteration (:func:`~wncs_lp.bounds.joint_chains.lazy_power`):
#: 0.25 took 2/3 to 3/4 of the sweeps of 0.5 on the eight-process pair chains (docs/bounds.md).
CUT_LAZY = 0.25


def group_cut(chains: GroupChains, i: int, policy: np.ndarray, y0: np.ndarray | None = None, *,
              tol: float = 1e-9, max_sweeps: int = 20_000) -> tuple[float, np.ndarray, np.ndarray]:
    """The cut of group i's deterministic policy: (a, x, y), y a stationary law (lazy power
    iteration from ``y0``), a = <y, q_G>, x its (C, a) marginal: the policy's average priced cost
    is a + <x, mu_G> for every price mu_G."""
    mod = _mod()
    d = chains.data
    shape = chains.shape(i)
    y = np.full(shape, 1.0 / (shape[0] * shape[1])) if y0 is None else np.array(y0, dtype=float, copy=True)
    c1, c2, _, out_ptr, out_nxt, out_prob, s1, s2 = chains.args(i)
    sw = chains.swap(i)
    if sw is None:
        def push(x, out):
            mod.push(x, policy, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, out)
    else:  # solve_group_chain's policy, sigma-equivariant off the fixed states (PairSwap), there mixed
        y = sw.symmetrised(y, c2)

        def push(x, out):
            mod.push_sym(x, policy, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, sw.kind, sw.config, out)
    y, _, _ = lazy_power(push, y, tol=tol, max_sweeps=max_sweeps, lazy=CUT_LAZY, mix=mod.lazy_mix)
    x = np.bincount(policy.ravel(), weights=y.ravel(), minlength=d.n_pairs)
    if sw is not None:  # at a fixed state the law is pushed half by p, half by sigma p
        x = 0.5 * (x + np.bincount(sw.pair[policy.ravel()], weights=y.ravel(), minlength=d.n_pairs))
    return float((y * chains.q[i][None, :]).sum()), x, y


# ---------------------------------------------------------------------------- the search
#: ``pairs_bound``'s candidates when ``groups="auto"``: at most this many processes pair every way.
ALL_PAIRINGS_MAX = 4


def candidate_partitions(n: int, classes=()) -> list[tuple]:
    """``groups="auto"``'s candidates: interchangeable processes paired with each other first (the
    paper's four types twice: same-type pairs gave 9045.39 at relaxation 2's prices against
    9003.55 for the pairing best at processes 1-4, ``docs/bounds.md``); what is left paired every way
    when at most :data:`ALL_PAIRINGS_MAX` processes are left, else consecutively."""
    fixed, rest = [], []
    for cl in (classes or [(k,) for k in range(n)]):
        cl = list(cl)
        while len(cl) >= 2:
            fixed.append((cl.pop(0), cl.pop(0)))
        rest += cl
    rest.sort()
    if len(rest) > ALL_PAIRINGS_MAX:
        return [tuple(fixed) + pair_partition(rest)]
    return [tuple(sorted(fixed + list(p))) for p in _pairings(rest)]


def _pairings(items: list) -> list[tuple]:
    """Every partition of ``items`` into pairs (and one single when their number is odd)."""
    if len(items) <= 1:
        return [tuple((k,) for k in items)]
    out = []
    if len(items) % 2 == 1:  # the single: each item in turn
        for i, k in enumerate(items):
            out += [((k,),) + p for p in _pairings(items[:i] + items[i + 1:])]
        return out
    a = items[0]
    for i in range(1, len(items)):
        out += [((a, items[i]),) + p for p in _pairings(items[1:i] + items[i + 1:])]
    return out


#: The bundle stops when its model predicts less than STOP_PREDICTED tol |L| more. At eight
#: processes a test at tol |L| stopped the search after 13-15 steps (its prox parameter halved by
#: null steps, not L at its maximum) where 10 more steps raised the bound by 1.9 (docs/bounds.md).
STOP_PREDICTED = 1e-2


@dataclass
class _Search:
    chains: GroupChains
    lumps: GroupLumps
    tol: float
    threads: int
    deadline: float
    h: list
    laws: list
    best_bound: float = -np.inf
    best_tables: list | None = None
    best_prices: np.ndarray | None = None
    best_gains: np.ndarray | None = None
    found_at: str = ""
    evaluations: int = 0
    sweeps: int = 0
    cut_seconds: dict = field(default_factory=dict)

    def out_of_time(self) -> bool:
        return time.monotonic() >= self.deadline

    def offer(self, tables, prices, gains, where: str) -> float:
        cert = certify_group_tables(self.chains, tables)
        if cert.lower_bound > self.best_bound:
            self.best_bound, self.best_tables, self.found_at = cert.lower_bound, list(tables), where
            self.best_prices, self.best_gains = prices, gains
        return cert.lower_bound

    def evaluate(self, prices: np.ndarray, where: str) -> tuple[float, list]:
        """Every group's lumped priced chain at the Gamma-invariant ``prices`` (groups, n_prices),
        warm-started; their tables spread to the whole system, certified and offered:
        (L(prices) = sum of the chains' lower brackets, the cuts of their greedy policies, on the
        price orbits)."""
        lp = self.lumps
        sols = [solve_group_chain(lp.chains[i], 0, prices[i][lp.price_of[i]], self.h[i],
                                  tol=max(1e-11, 0.02 * self.tol), threads=self.threads, stop=self.out_of_time)
                for i in range(self.chains.n_groups)]
        self.h = [s.h for s in sols]
        self.evaluations += 1
        self.sweeps += sum(s.sweeps for s in sols)
        gains = np.array([s.lower for s in sols])
        self.offer([lp.spread(i, h) for i, h in enumerate(self.h)], prices.copy(), gains, where)
        # the cuts' power iterations (a scatter, serial inside) are independent: one group per thread,
        # the longest first (the last step's time: the order changes no number, only the makespan)
        def cut(i):
            t = time.perf_counter()
            out = group_cut(lp.chains[i], 0, sols[i].policy, self.laws[i])
            self.cut_seconds[i] = time.perf_counter() - t
            return out

        order = sorted(range(len(sols)), key=lambda i: -self.cut_seconds.get(i, 0.0))
        with ThreadPoolExecutor(max_workers=max(1, min(self.threads, len(sols)))) as pool:
            futures = {i: pool.submit(cut, i) for i in order}
            found = [futures[i].result() for i in range(len(sols))]
        cuts = []
        for i, (a, x, y) in enumerate(found):
            self.laws[i] = y
            cuts.append((i, a, np.bincount(lp.price_of[i], weights=x, minlength=lp.n_prices)))
        return float(gains.sum()), cuts


def pairs_size(system: System, groups="auto", *, symmetric: bool = True) -> dict:
    """What relaxation 4 would build, before it is built: ``sweep_work``, the outcomes x ages of
    one Bellman sweep over every candidate partition's (lumped) group chains -- the unit of its CPU
    time -- and ``memory_bytes``, its largest arrays (each candidate's whole tables, certified on
    the whole system, four copies: the tables, the best so far, their spread and the check's)."""
    system = bound_system(system)
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    cands = candidate_partitions(data.n_processes, sym.classes) if groups == "auto" else [groups]
    work = mem = 0
    for cand in cands:
        gs = _checked_groups(data.n_processes, cand)
        lumps = GroupLumps.build(data, gs, sym if symmetric else None)
        work += sum(lc.data.n_outcomes * lc.c1[0] * lc.c2[0] for lc in lumps.chains)
        mem = max(mem, 4 * 8 * data.n_configs * sum(int(np.prod(data.caps[list(g)])) for g in gs))
    return {"sweep_work": int(work), "memory_bytes": int(mem), "candidates": len(cands)}


def pairs_bound(system: System, *, groups="auto", start=None, tol: float = 1e-4, max_iter: int = 30,
                time_limit: float | None = 600.0, threads: int = 1, symmetric: bool = True, own_swap: bool = True,
                min_gain: float = 0.0, progress=None, **joint_options):
    """A certified lower bound on g* from relaxation 4 (relaxation 2 with pairs of processes' ages
    kept jointly; module docstring).

    Parameters
    ----------
    system : System
    groups : "auto" or sequence of groups
        A partition of the processes (0-based) into groups of one or two; ``"auto"``: each
        candidate of :func:`candidate_partitions` evaluated at relaxation 2's prices, the best
        certified kept for the search.
    start : BoundResult, optional
        Relaxation 2's result on this system (its tables over the joint configuration and its
        prices); default: ``joint_bound(system, **joint_options)``.
    tol : float
        The chains' relative accuracy is ``0.02 tol``; the bundle stops when its model predicts
        less than ``STOP_PREDICTED tol |L|`` more.
    max_iter : int
        Bundle steps after the start (each: every group's chain solved, warm-started, and the
        certificate); 0: the start only.
    time_limit : float or None
        Seconds of wall clock for the search after the start (None: none); the bound is
        certified whatever stops it, and Ctrl-C returns the best so far.
    threads : int
        numba threads of the chains' Bellman sweeps.
    symmetric : bool
        Search over prices invariant under the permutations of interchangeable processes that map
        every group onto itself, each group's chain lumped by them (:class:`GroupLumps`: the same
        maximum of L, smaller chains); False: every pair priced on its own, the whole chains.
    own_swap : bool
        With ``symmetric``, each pair of interchangeable processes' chain also lumped by its own
        swap (:class:`PairSwap`: the same chain, each sweep and cut computed on one state of each
        orbit); False: only by the permutations that fix its members.
    min_gain : float
        The bundle runs only when the start raised relaxation 2's bound by more than
        ``min_gain |bound|`` (``"auto"``'s test of whether the pairs pay); 0: always.
    progress : bool or Progress, optional
    **joint_options
        Relaxation 2's options (:func:`~wncs_lp.bounds.joint.joint_bound`) when ``start`` is not given.

    Returns
    -------
    BoundResult
        ``relaxation="joint-pairs"``; ``lower_bound`` the group check of ``tables`` (a
        :class:`GroupTables` over the joint configuration, column the identity), never below
        relaxation 2's own (its tables, summed per group, are offered first);
        ``multipliers`` the prices (groups, |C x A|); ``process_gains`` each group's chain's lower
        bracket there.
    """
    t0 = time.monotonic()
    prog = as_progress(progress)
    system = bound_system(system)
    if start is None:
        start = joint_bound(system, tol=tol, progress=prog, **joint_options)
    if not isinstance(start.tables, ValueTables) or start.relaxation != "joint-configuration":
        raise SolverError("relaxation 4 starts from relaxation 2's result (joint-configuration), "
                          f"got {start.relaxation}")
    data = JointData.from_system(system)
    sym = process_symmetry(system, data) if symmetric else None
    mu1 = np.asarray(start.multipliers, float)
    if mu1.shape != (data.n_processes, data.n_pairs):
        raise SolverError(f"relaxation 2's prices have shape {mu1.shape}; expected {(data.n_processes, data.n_pairs)}")
    sep = [np.asarray(h, float) for h in start.tables.h]
    if groups == "auto":
        cands = candidate_partitions(data.n_processes, (sym or process_symmetry(system, data)).classes)
    else:
        cands = [groups]
    deadline = np.inf if time_limit is None else time.monotonic() + float(time_limit)
    stats: dict = {"relaxation_2_bound": float(start.lower_bound), "candidates": {}}
    status, it, found = MAX_ITER, 0, []  # found: the best start so far, which an interrupt keeps
    try:
        _best_start(data, sym, own_swap, cands, sep, mu1, tol, threads, deadline, prog, stats, found)
        s = found[0][0]
        pays = s.best_bound - start.lower_bound > min_gain * abs(start.lower_bound)
        stats["start_pays"] = bool(pays)
        if max_iter > 0 and pays and not s.out_of_time():
            status, it = _bundle_steps(s, *found[0][1:], tol, max_iter, prog, stats)
    except KeyboardInterrupt:
        status = INTERRUPTED
        if not found:
            raise
        s = found[0][0]
    ch = s.chains
    cert = certify_group_tables(ch, s.best_tables)
    stats.update(evaluations=s.evaluations, chain_sweeps=s.sweeps, bundle_steps=stats.get("bundle_steps", it),
                 found_in=s.found_at,
                 roundoff=cert.roundoff, raw_bound=cert.raw, binding_pair=cert.binding_pair,
                 groups=[list(g) for g in ch.groups], certified=bool(np.isfinite(cert.lower_bound)))
    n_c = data.n_configs
    tables = GroupTables(groups=ch.groups, h=ch.as_grids(s.best_tables),
                         column=tuple(np.arange(n_c) for _ in ch.groups))
    how = ("group check of the tables h_G(tau_G, C) over all sum_G prod tau_hat_G |C x A| = "
           f"{sum(c1 * c2 for c1, c2 in zip(ch.c1, ch.c2)) * data.n_pairs:,} constraints: g(h) = -max_(C,a) sum_G "
           f"max_tau_G [h_G - q_G - E h_G] = {cert.raw:.12g}, minus a round-off bound {cert.roundoff:.2g}; the tables "
           f"came from {s.found_at}; how they were found does not enter the bound")
    gains = s.best_gains if s.best_gains is not None else np.full(ch.n_groups, np.nan)
    prices = (s.best_prices[:, s.lumps.pair_orbit] if s.best_prices is not None
              else np.zeros((ch.n_groups, data.n_pairs)))
    prog.done(f"relaxation 4: certified lower bound {cert.lower_bound:.10g} ({status})")
    return BoundResult(relaxation="joint-pairs", lower_bound=float(cert.lower_bound), relaxation_upper=float("inf"),
                       status=status, certified_by=how, multipliers=prices, process_gains=gains, tables=tables,
                       seconds=time.monotonic() - t0, iterations=int(s.evaluations), stats=stats)


def _best_start(data: JointData, sym: ProcessSymmetry | None, own_swap: bool, cands: list, sep: list, mu1: np.ndarray,
                tol: float, threads: int, deadline: float, prog, stats: dict, found: list) -> None:
    """Phase 1: each candidate partition's chains at relaxation 2's prices summed per group (its
    tables summed per group offered first); the best certified so far kept in ``found`` as
    ``[(search, L, cuts, prices)]``."""
    for cand in cands:
        ch = GroupChains.build(data, cand)
        lumps = GroupLumps.build(data, ch.groups, sym, own_swap)
        summed = ch.from_separable(sep)
        s = _Search(ch, lumps, float(tol), int(threads), deadline, [lumps.lumped(i, h) for i, h in enumerate(summed)],
                    [None] * ch.n_groups)
        s.offer(summed, None, None, "relaxation 2's tables")
        prices = lumps.prices_of(np.array([mu1[list(g)].sum(axis=0) for g in ch.groups]))
        prog.phase(f"relaxation 4: groups {[[k + 1 for k in g] for g in ch.groups]} at relaxation 2's prices")
        value, cuts = s.evaluate(prices, "the group chains at relaxation 2's prices")
        stats["candidates"][str([[k + 1 for k in g] for g in ch.groups])] = s.best_bound
        if not found or s.best_bound > found[0][0].best_bound:
            found[:] = [(s, value, cuts, prices)]
    prog.tick(f"relaxation 4: groups {[[k + 1 for k in g] for g in found[0][0].chains.groups]}, "
              f"certified {found[0][0].best_bound:.10g}")


def _bundle_steps(s: "_Search", value: float, cuts: list, prices: np.ndarray, tol: float, max_iter: int,
                  prog, stats: dict) -> tuple[str, int]:
    """Phase 2: the proximal bundle on the group prices from the start, until its stopping test,
    ``max_iter`` steps or the deadline: (status, steps)."""
    status, it = MAX_ITER, 0
    X = np.array([x for _, _, x in cuts])
    spread = float(((X - X.mean(axis=0)) ** 2).sum())
    bundle = PriceBundle(prices, value, t=1e-2 * max(abs(value), 1.0) / max(spread, 1e-12))
    for c in cuts:
        bundle.add_cut(*c)
    try:
        while it < max_iter and not s.out_of_time():
            mu = bundle.candidate()
            if bundle.converged(tol) or bundle.predicted <= STOP_PREDICTED * tol * max(abs(bundle.value), 1.0):
                status = OPTIMAL
                break
            value, cuts = s.evaluate(mu, "the bundle")
            it += 1
            for c in cuts:
                bundle.add_cut(*c)
            bundle.report(mu, value)
            prog.tick(f"relaxation 4: bundle {it}: certified {s.best_bound:.10g}, L(centre) {bundle.value:.10g}")
    finally:
        stats.update(bundle_serious=bundle.serious_steps, bundle_null=bundle.null_steps,
                     bundle_predicted=bundle.predicted, bundle_steps=it)
    return status, it

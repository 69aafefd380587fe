r"""Relaxation 2's LP reduced by the symmetry of interchangeable processes.

Two processes are **interchangeable** when swapping their names maps the joint automaton onto
itself: every configuration to a configuration, every action to an action of the image, every
outcome to an outcome of the image with the same probability and the two processes' deliveries
swapped, and their cost tables and caps are equal (the paper's four process types twice:
``bounds_p1234_twice``). The classes of interchangeable processes generate a group G (a product
of symmetric groups), and relaxation 2's LP (:mod:`wncs_lp.bounds.joint_lp`)

.. math::

    \min \sum_k \langle q_k, y_k\rangle \;\text{s.t.}\; y_k \text{ balanced on } (\tau, C),\;
    \sum_\tau y_k(\tau, p) = x(p),\; \sum_p x(p) = 1,\; y, x \ge 0

is invariant under G acting on process names, configurations and pairs together. Averaging an
optimal solution over G gives an optimal solution with y_{sigma k}(tau, sigma p) = y_k(tau, p)
and x(sigma p) = x(p), so the LP may be restricted to such solutions without changing its
optimum. Then

* one **representative** r per class carries the class: y_k for k = sigma r is y_r moved by
  sigma, and the constraints of k are images of those of r;
* y_r is invariant under the stabiliser H_r of r (the permutations of the other processes of
  every class), so it lives on the H_r-orbits of pairs: the lumped variable
  Y_r(tau, O) = sum_{p in O} y_r(tau, p) is balanced on the H_r-orbits of configurations under
  the lumped kernel (H_r fixes r, so r's delivery and the outcome probabilities are the same for
  every pair of an orbit);
* x is G-invariant: X(Q) = sum_{p in Q} x(p) on the G-orbits of pairs, and the coupling of r
  on an H_r-orbit O inside the G-orbit Q reads sum_tau Y_r(tau, O) = |O| / |Q| X(Q);
* the objective counts every representative |class| times.

At eight processes (four classes of two, cap 20) this is 1.97M columns -> ~0.3M and 12.5M
nonzeros -> ~1.9M: within the interior point's reach.

The reduction only finds tables. Its balance duals h_r(tau, orbit) are spread back to every
process (h_k(tau, C) = h_r(tau, orbit of sigma C) for k = sigma r, sigma the transposition
(r k)) and certified by :func:`~wncs_lp.bounds.joint_chains.certify_tables` on the whole
system, like any other tables: were the symmetry wrong, the bound would be looser, never
invalid. The symmetry is checked, not assumed: a pair of processes enters a class only if the
transposition maps every configuration, pair and outcome as above.

Dropped rows (their dual fixed at 0: the flat directions of the LP, as in
the LP of :mod:`~wncs_lp.bounds.joint_lp`). Summed over tau, a representative's balance rows on
an H_r-orbit K of configurations are, through its coupling rows, the balance of x on K:
bal(1_K) = sum_p x(p) [1_K(C_p) - sum_o P(o|p) 1_K(C'_o)]. For a G-invariant x,
bal(f o sigma) = bal(f), so bal(1_K) = |K| / |M| bal(1_M), M the G-orbit holding K: all these
sums are multiples of the balances on the G-orbits, which sum to 0. So the rows (tau = 1) of
every representative after the first are dropped, and of the first all but one per G-orbit of
configurations, less the one of configuration 0's G-orbit (without symmetry: process 0's row
(tau = 1, C_0) and the rows (tau = 1, C) of every other process, the LP's own dropped rows).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..models.system import System
from .joint_chains import ChainSolution, JointData, Kernels, solve_chain

__all__ = ["ProcessSymmetry", "process_symmetry", "symmetric_lp", "symmetric_lp_shape", "spread_tables",
           "orbit_tables", "spread_orbit_tables", "orbit_labels", "LumpedChains", "lumped_chains", "coupling_prices"]


@dataclass(frozen=True, eq=False)
class ProcessSymmetry:
    """The classes of interchangeable processes of a system and the maps of their transpositions.

    Attributes
    ----------
    classes : tuple of tuples
        The classes (0-based, increasing; singletons included), in order of their first member;
        the first member is the class's representative.
    config_maps : dict
        ``{(i, j): (|C|,) int array}``: the configuration index of each configuration with
        processes i and j swapped (i < j in one class).
    pair_maps : dict
        The same for pairs (configuration-major, the automaton's action order).
    """

    classes: tuple
    config_maps: dict
    pair_maps: dict

    @classmethod
    def none(cls, n_processes: int) -> "ProcessSymmetry":
        """No two processes interchangeable: the reduced LP is relaxation 2's LP itself."""
        return cls(classes=tuple((k,) for k in range(n_processes)), config_maps={}, pair_maps={})

    @property
    def trivial(self) -> bool:
        """True when no two processes are interchangeable (the reduction is the LP itself)."""
        return all(len(c) == 1 for c in self.classes)

    @property
    def representatives(self) -> tuple:
        return tuple(c[0] for c in self.classes)

    def class_of(self, k: int) -> tuple:
        return next(c for c in self.classes if k in c)

    def generators(self, fixed: int | None = None) -> list[tuple[int, int]]:
        """Adjacent transpositions generating the product of the classes' symmetric groups, or its
        stabiliser of process ``fixed`` (the transpositions among the class's other members)."""
        out = []
        for c in self.classes:
            members = [k for k in c if k != fixed]
            out += list(zip(members[:-1], members[1:]))
        return out

    def transposition(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(configuration map, pair map) of swapping i and j (one class)."""
        key = (min(i, j), max(i, j))
        return self.config_maps[key], self.pair_maps[key]


def _relabel_maps(system: System, data: JointData, i: int, j: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The configuration and pair maps of swapping processes i and j, or None when the swap is not
    an automorphism of the automaton (checked on every configuration, pair and outcome)."""
    auto, model, n = system.automaton, system.model, system.n_processes
    order = list(range(n))
    order[i], order[j] = j, i
    new_id = np.arange(n + 1)
    new_id[i + 1], new_id[j + 1] = j + 1, i + 1
    index = {cfg: c for c, cfg in enumerate(auto.configs)}
    cmap = np.empty(len(auto.configs), dtype=np.int64)
    pmap = np.empty(data.n_pairs, dtype=np.int64)
    try:
        for c, cfg in enumerate(auto.configs):
            # the projection on the group of all processes listed in ``order`` renames process
            # order[m] to m + 1: the configuration with i and j swapped
            cmap[c] = index[model.project_group(cfg, order)]
    except (KeyError, TypeError, IndexError, ValueError):
        return None
    for c, acts in enumerate(auto.actions):
        target = {tuple(a): t for t, a in enumerate(auto.actions[cmap[c]])}
        for t, a in enumerate(acts):
            image = target.get(tuple(int(new_id[x]) if 0 <= x <= n else -1 for x in a))
            if image is None:
                return None
            pmap[data.act_ptr[c] + t] = data.act_ptr[cmap[c]] + image
    if not _outcomes_map(data, cmap, pmap, i, j):
        return None
    return cmap, pmap


def _outcomes_map(data: JointData, cmap: np.ndarray, pmap: np.ndarray, i: int, j: int) -> bool:
    """Whether every pair's outcomes, relabelled, are its image's outcomes (as multisets)."""
    lens = np.diff(data.out_ptr)
    if not np.array_equal(lens[pmap], lens):
        return False
    pair_of = np.repeat(np.arange(data.n_pairs), lens)
    delta = data.out_delta.copy()
    delta[:, [i, j]] = delta[:, [j, i]]
    # outcomes of p relabelled, against the outcomes of pmap[p]: both sorted within the pair
    mine = np.column_stack([pmap[pair_of], cmap[data.out_nxt], delta])
    theirs = np.column_stack([pair_of, data.out_nxt, data.out_delta])
    o1 = np.lexsort(np.column_stack([np.round(data.out_prob, 12), mine[:, ::-1]]).T)
    o2 = np.lexsort(np.column_stack([np.round(data.out_prob, 12), theirs[:, ::-1]]).T)
    return bool(np.array_equal(mine[o1], theirs[o2]) and np.allclose(data.out_prob[o1], data.out_prob[o2],
                                                                        rtol=0, atol=1e-12))


def process_symmetry(system: System, data: JointData | None = None) -> ProcessSymmetry:
    """The classes of interchangeable processes of ``system`` (checked on its automaton).

    Candidates are processes with equal caps and cost tables; a candidate joins a class when its
    transposition with the class's representative is an automorphism of the automaton
    (:func:`_relabel_maps`), and the adjacent transpositions of every class are kept.
    """
    data = data if data is not None else JointData.from_system(system)
    n = system.n_processes
    classes: list[list[int]] = []
    maps: dict = {}
    for k in range(n):
        for cl in classes:
            r = cl[0]
            if data.caps[r] != data.caps[k] or not np.array_equal(data.q[r], data.q[k]):
                continue
            m = _relabel_maps(system, data, r, k)
            if m is not None:
                maps[(r, k)] = m
                cl.append(k)
                break
        else:
            classes.append([k])
    for cl in classes:
        r = cl[0]
        for a, b in zip(cl[1:-1], cl[2:]):  # (a b) = (r a)(r b)(r a): an automorphism, no check needed
            ra, rb = maps[(r, a)], maps[(r, b)]
            maps[(a, b)] = (ra[0][rb[0][ra[0]]], ra[1][rb[1][ra[1]]])
    return ProcessSymmetry(classes=tuple(tuple(c) for c in classes),
                           config_maps={key: v[0] for key, v in maps.items()},
                           pair_maps={key: v[1] for key, v in maps.items()})


def orbit_labels(maps: list[np.ndarray], size: int) -> tuple[int, np.ndarray]:
    """(number of orbits, orbit label of each element) of the group generated by the permutations
    ``maps`` of ``range(size)``; orbits numbered in the order of their first element."""
    if not maps:
        return size, np.arange(size, dtype=np.int64)
    src = np.concatenate([np.arange(size)] * len(maps))
    dst = np.concatenate(maps)
    g = sp.csr_matrix((np.ones(src.size), (src, dst)), shape=(size, size))
    n, lab = connected_components(g, directed=True, connection="weak")
    _, first = np.unique(lab, return_index=True)  # label -> its first element
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(n)
    return int(n), rank[lab]


@dataclass(frozen=True, eq=False)
class _Orbits:
    """The H_r-orbits of configurations and pairs of one representative r."""

    rep: int
    weight: int            # the size of r's class: how many processes it stands for
    n_configs: int
    config_orbit: np.ndarray
    n_pairs: int
    pair_orbit: np.ndarray
    pair_first: np.ndarray  # a member pair of each orbit
    pair_size: np.ndarray   # |O|


def _rep_orbits(sym: ProcessSymmetry, data: JointData, cl: tuple) -> _Orbits:
    r = cl[0]
    gens = sym.generators(fixed=r)
    nc, corb = orbit_labels([sym.config_maps[g] for g in gens], data.n_configs)
    npo, porb = orbit_labels([sym.pair_maps[g] for g in gens], data.n_pairs)
    first = np.full(npo, -1, dtype=np.int64)
    first[porb[::-1]] = np.arange(data.n_pairs)[::-1]  # the smallest member of each orbit
    return _Orbits(r, len(cl), nc, corb, npo, porb, first, np.bincount(porb, minlength=npo))


def symmetric_lp_shape(sym: ProcessSymmetry, data: JointData) -> dict:
    """Rows, columns and nonzeros of :func:`symmetric_lp` without building it (the outcome count of
    the orbits' first pairs, before merging outcomes into the same orbit)."""
    lens = np.diff(data.out_ptr)
    rows = cols = nnz = 0
    for cl in sym.classes:
        o = _rep_orbits(sym, data, cl)
        cap = int(data.caps[cl[0]])
        rows += cap * o.n_configs + o.n_pairs
        cols += cap * o.n_pairs
        nnz += cap * (2 * o.n_pairs + int(lens[o.pair_first].sum())) + o.n_pairs
    n_q, _ = orbit_labels([sym.pair_maps[g] for g in sym.generators()], data.n_pairs)
    return {"rows": rows + 1, "cols": cols + n_q, "nnz": nnz + n_q}


@dataclass(frozen=True, eq=False)
class SymmetricLP:
    """The reduced LP ``min c^T z s.t. A z = b, z >= 0`` and how to read tables off its duals.

    Attributes
    ----------
    A, b, c
        The LP (CSC, dropped rows removed).
    keep : (rows,) bool array
        The full rows kept.
    table_rows : list of slices
        Per representative (in ``orbits`` order), its balance rows in the full row vector,
        (H_r-orbit of configurations) x tau.
    orbits : list of _Orbits
    coupling_rows : list of slices
        Per representative, its coupling rows in the full row vector (one per H_r-orbit of pairs):
        their duals are the prices of :class:`LumpedChains`.
    """

    A: sp.csc_matrix
    b: np.ndarray
    c: np.ndarray
    keep: np.ndarray
    table_rows: list
    orbits: list
    coupling_rows: list


def symmetric_lp(sym: ProcessSymmetry, data: JointData) -> SymmetricLP:
    """Relaxation 2's LP restricted to G-invariant solutions, lumped on orbits (module docstring)."""
    n_q, qorb = orbit_labels([sym.pair_maps[g] for g in sym.generators()], data.n_pairs)
    q_size = np.bincount(qorb, minlength=n_q)
    orbs = [_rep_orbits(sym, data, cl) for cl in sym.classes]
    # row offsets: per representative its balance rows (orbit-major, tau minor), then its coupling rows
    b_off, c_off, pos = [], [], 0
    for o in orbs:
        b_off.append(pos)
        pos += o.n_configs * int(data.caps[o.rep])
    for o in orbs:
        c_off.append(pos)
        pos += o.n_pairs
    n_rows = pos + 1
    y_off, pos = [], 0
    for o in orbs:
        y_off.append(pos)
        pos += o.n_pairs * int(data.caps[o.rep])
    x_off, n_cols = pos, pos + n_q
    rows, cols, vals, cost = [], [], [], np.zeros(n_cols)
    lens = np.diff(data.out_ptr)
    for i, o in enumerate(orbs):
        r, cap = o.rep, int(data.caps[o.rep])
        P = o.n_pairs
        p_rep = o.pair_first
        t = np.tile(np.arange(cap), P)
        op = np.repeat(np.arange(P), cap)
        col = y_off[i] + op * cap + t
        cost[col] = o.weight * data.q[r][t]
        conf = o.config_orbit[data.pair_c[p_rep]]
        rows += [b_off[i] + conf[op] * cap + t, np.full(col.size, c_off[i]) + op]
        cols += [col, col]
        vals += [np.ones(col.size), np.ones(col.size)]
        # outcomes of each orbit's first pair: -P(o) at (next tau, orbit of the next configuration)
        L = lens[p_rep]
        starts = data.out_ptr[p_rep]
        o_idx = np.repeat(starts - np.cumsum(L) + L, L) + np.arange(int(L.sum()))
        o_pair = np.repeat(np.arange(P), L)
        # every tau of the pair
        o_idx_t = np.repeat(o_idx, cap)
        o_pair_t = np.repeat(o_pair, cap)
        t_o = np.tile(np.arange(cap), o_idx.size)
        nt = np.minimum(t_o + 1, data.sat[o_idx_t, r])
        rows.append(b_off[i] + o.config_orbit[data.out_nxt[o_idx_t]] * cap + nt)
        cols.append(y_off[i] + o_pair_t * cap + t_o)
        vals.append(-data.out_prob[o_idx_t])
        # coupling: sum_tau Y_r(tau, O) - |O| / |Q| X(Q) = 0
        q_of = qorb[p_rep]
        rows.append(c_off[i] + np.arange(P))
        cols.append(x_off + q_of)
        vals.append(-o.pair_size / q_size[q_of])
    rows.append(np.full(n_q, n_rows - 1))
    cols.append(x_off + np.arange(n_q))
    vals.append(np.ones(n_q))
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_rows, n_cols))
    A.sum_duplicates()
    keep = _kept_rows(sym, data, orbs, b_off)
    b = np.zeros(n_rows)
    b[-1] = 1.0
    table_rows = [slice(b_off[i], b_off[i] + o.n_configs * int(data.caps[o.rep])) for i, o in enumerate(orbs)]
    coupling_rows = [slice(c_off[i], c_off[i] + o.n_pairs) for i, o in enumerate(orbs)]
    return SymmetricLP(A=A[keep].tocsc(), b=b[keep], c=cost, keep=keep, table_rows=table_rows, orbits=orbs,
                       coupling_rows=coupling_rows)


def _kept_rows(sym: ProcessSymmetry, data: JointData, orbs: list, b_off: list) -> np.ndarray:
    """All rows but those whose duals can be taken 0 (module docstring): the rows (tau = 1) of
    every representative after the first, and of the first every row (tau = 1) but one per
    G-orbit of configurations, and that one too for the G-orbit of configuration 0."""
    n_rows = b_off[0] + sum(o.n_configs * int(data.caps[o.rep]) + o.n_pairs for o in orbs) + 1
    keep = np.ones(n_rows, dtype=bool)
    for i, o in enumerate(orbs):
        keep[b_off[i]:b_off[i] + o.n_configs * int(data.caps[o.rep]):int(data.caps[o.rep])] = False
    _, gorb = orbit_labels([sym.config_maps[g] for g in sym.generators()], data.n_configs)
    first = np.full(int(gorb.max()) + 1, -1, dtype=np.int64)
    first[gorb[::-1]] = np.arange(data.n_configs)[::-1]  # the smallest configuration of each G-orbit
    o = orbs[0]
    keep[b_off[0] + o.config_orbit[first] * int(data.caps[o.rep])] = True
    keep[b_off[0] + o.config_orbit[0] * int(data.caps[o.rep])] = False
    return keep


def spread_tables(sym: ProcessSymmetry, data: JointData, lp: SymmetricLP, lam: np.ndarray) -> list[np.ndarray]:
    """Every process's table h_k(tau, C) from the reduced LP's balance duals ``lam`` (full rows, 0 on
    the dropped ones): the representative's on its orbits, moved by the transposition (r k) for
    the other members of its class."""
    # the representative's column costs weight * q_r: its duals are weight times one process's table
    per_orbit = [lam[sl].reshape(o.n_configs, -1) / o.weight for sl, o in zip(lp.table_rows, lp.orbits)]
    return spread_orbit_tables(sym, data, per_orbit)


def spread_orbit_tables(sym: ProcessSymmetry, data: JointData, per_orbit: list) -> list[np.ndarray]:
    """Every process's table from its class representative's table on the representative's orbits
    of configurations (one (orbits, tau_hat) array per class, in ``sym.classes`` order): the
    inverse of :func:`orbit_tables`."""
    tables: list = [None] * data.n_processes
    for h_orb, cl in zip(per_orbit, sym.classes):
        o = _rep_orbits(sym, data, cl)
        h_r = np.asarray(h_orb, dtype=float)[o.config_orbit]
        tables[cl[0]] = np.ascontiguousarray(h_r)
        for k in cl[1:]:
            cmap, _ = sym.transposition(cl[0], k)  # stored for every member: it joined the class by it
            tables[k] = np.ascontiguousarray(h_r[cmap])
    return tables


def orbit_tables(sym: ProcessSymmetry, data: JointData, tables) -> list[np.ndarray]:
    """Each class representative's table averaged on its orbits of configurations: a compact form of
    symmetric tables (the twins' are the representative's moved by the swaps), read back by
    :func:`spread_orbit_tables`. Tables that are not symmetric lose their asymmetry."""
    out = []
    for cl in sym.classes:
        o = _rep_orbits(sym, data, cl)
        h = np.asarray(tables[cl[0]], dtype=float)
        m = np.zeros((o.n_configs, h.shape[1]))
        np.add.at(m, o.config_orbit, h)
        out.append(m / np.bincount(o.config_orbit, minlength=o.n_configs)[:, None])
    return out


# ---------------------------------------------------------------------------- the reduced Lagrangian
@dataclass(frozen=True, eq=False)
class LumpedChains:
    r"""The priced chains of the class representatives on their orbits: the reduced LP's Lagrangian.

    Dualising the coupling rows of :func:`symmetric_lp` with prices nu_r(O) (one per H_r-orbit O
    of pairs of representative r) leaves, per representative, the lumped chain of r on
    (tau, H_r-orbit of configurations) with pair cost q_r(tau) - nu_r(O) / w_r (w_r = |class|),
    and the marginal X alone on the G-orbits Q of pairs:

    .. math::

        L(\nu) = \sum_r w_r\, g_r(q_r - \nu_r / w_r)
                 + \min_Q \sum_r \sum_{O \subseteq Q} \frac{|O|}{|Q|} \nu_r(O) \le \text{the LP's optimum},

    g_r the optimal gain of the lumped chain (weak duality: the chains' biases, times w_r, are
    balance duals, nu_r(O) + w_r g_r the coupling duals, and the H_r-orbits inside Q cover Q).
    The lumped chain is exact: for H_r-invariant prices the whole chain of process r on
    (tau, C) has the same gain and its bias is the lumped one read on the orbits (H_r fixes r's
    deliveries and the outcome probabilities). Spread to every process
    (:func:`spread_orbit_tables`), the biases are tables whose certificate
    (:func:`~wncs_lp.bounds.joint_chains.certify_tables`) is at least L(nu) less the chains'
    bracket widths: for a pair p of G-orbit Q, the members k of r's class see r's prices on the
    H_r-orbits of the images of p, which average to the weights |O| / |Q|. At the LP's optimal
    coupling duals L(nu) is the optimum.

    These chains are as small as the reduced LP's blocks (the paper's four process types four
    times at cap 40: 1,009-1,348 orbits of configurations x 40 AoI values each, against 19,845 x
    40 for one whole chain), so every evaluation of L costs far less than the N whole chains.

    Attributes
    ----------
    chains : tuple of JointData
        One per class (``sym.classes`` order): a one-process automaton on r's orbits, its pairs
        grouped by orbit of configurations (each orbit's first pair's outcomes, configurations
        read as their orbits, r's deliveries).
    order : tuple of int arrays
        Pair i of chain c is the LP's orbit ``order[c][i]`` (the order of ``lp.orbits[c]``).
    q_orbit, share : tuple of arrays
        The G-orbit Q of each chain pair and |O| / |Q|.
    weights : tuple of int
        w_r, the size of each class.
    n_q : int
        The number of G-orbits of pairs.
    reps : tuple of int
        Each class's representative r.
    pair : tuple of int arrays
        A pair of the whole automaton in each orbit (chain order).
    """

    chains: tuple
    order: tuple
    q_orbit: tuple
    share: tuple
    weights: tuple
    n_q: int
    reps: tuple
    pair: tuple

    def prices_from(self, mu: np.ndarray) -> list[np.ndarray]:
        """The prices nu (LP order, as :meth:`lagrangian` takes them) of whole-system prices ``mu`` (N,
        |C x A|), each process's chain priced q_k + mu_k, read at each orbit's pair: nu_r = -w_r mu_r.
        For symmetric zero-sum prices (relaxation 1's, :func:`~wncs_lp.bounds.joint.relaxation1_start`)
        every G-orbit's weighted sum is zero, and L(nu) is the whole Lagrangian at mu."""
        out = []
        for c, w in enumerate(self.weights):
            nu = np.empty(self.order[c].size)
            nu[self.order[c]] = -w * np.asarray(mu[self.reps[c]], dtype=float)[self.pair[c]]
            out.append(nu)
        return out

    def lagrangian(self, prices, kern: Kernels, *, tol: float, h0=None, stop=None) -> tuple[float, list[ChainSolution]]:
        """(L(nu) from the chains' lower brackets, each chain's solution) at prices ``prices[c]``
        (one array per class, on the LP's orbits as :func:`coupling_prices` gives them)."""
        value = 0.0
        marginal = np.zeros(self.n_q)
        sols = []
        for c, (ld, w) in enumerate(zip(self.chains, self.weights)):
            nu = np.asarray(prices[c], dtype=float)[self.order[c]]
            sol = solve_chain(ld, 0, -nu / w, None if h0 is None else h0[c], kern, tol=tol, stop=stop)
            sols.append(sol)
            value += w * sol.lower
            np.add.at(marginal, self.q_orbit[c], self.share[c] * nu)
        return float(value + marginal.min()), sols


def lumped_chains(sym: ProcessSymmetry, data: JointData) -> LumpedChains:
    """The lumped priced chains of ``sym``'s class representatives (:class:`LumpedChains`)."""
    n_q, qorb = orbit_labels([sym.pair_maps[g] for g in sym.generators()], data.n_pairs)
    q_size = np.bincount(qorb, minlength=n_q)
    lens = np.diff(data.out_ptr)
    chains, orders, q_of, shares, pairs = [], [], [], [], []
    for cl in sym.classes:
        o = _rep_orbits(sym, data, cl)
        r = cl[0]
        conf = o.config_orbit[data.pair_c[o.pair_first]]
        order = np.argsort(conf, kind="stable")  # pairs grouped by orbit of configurations
        counts = np.bincount(conf, minlength=o.n_configs)
        first = o.pair_first[order]
        n_out = lens[first]
        idx = np.repeat(data.out_ptr[first] - np.cumsum(n_out) + n_out, n_out) + np.arange(int(n_out.sum()))
        chains.append(JointData(caps=data.caps[[r]].copy(), q=(data.q[r],),
                                act_ptr=np.r_[0, np.cumsum(counts)].astype(np.int64),
                                pair_c=np.repeat(np.arange(o.n_configs), counts).astype(np.int64),
                                out_ptr=np.r_[0, np.cumsum(n_out)].astype(np.int64),
                                out_nxt=np.ascontiguousarray(o.config_orbit[data.out_nxt[idx]]),
                                out_prob=np.ascontiguousarray(data.out_prob[idx]),
                                out_delta=np.ascontiguousarray(data.out_delta[idx, r][:, None])))
        orders.append(order)
        pairs.append(first)
        q_of.append(qorb[first])
        shares.append(o.pair_size[order] / q_size[qorb[first]])
    return LumpedChains(chains=tuple(chains), order=tuple(orders), q_orbit=tuple(q_of), share=tuple(shares),
                        weights=tuple(len(cl) for cl in sym.classes), n_q=int(n_q),
                        reps=tuple(cl[0] for cl in sym.classes), pair=tuple(pairs))


def coupling_prices(lp: SymmetricLP, lam: np.ndarray) -> list[np.ndarray]:
    """The coupling rows' duals of each representative (``lam`` on the full rows, as
    :func:`spread_tables` takes it): the prices of :meth:`LumpedChains.lagrangian`."""
    return [np.asarray(lam[sl], dtype=float).copy() for sl in lp.coupling_rows]

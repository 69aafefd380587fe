r"""The level-2 relaxation: every pair of processes' ages kept jointly with the joint configuration.

Relaxation 4 keeps one occupation measure per group of a *partition* into pairs. This relaxation
keeps one for **every** pair {k, l}, y_kl(tau_k, tau_l, C, a), each balanced on
(tau_k, tau_l, C), and makes them consistent: for each process k the marginal of y_kl on
(tau_k, C, a) is the same measure z_k(tau_k, C, a) for every partner l, and the z_k share the
(C, a) marginal x. The objective is sum_k <q_k, z_k>.

**Lumped ages** (``lump``). A pair's measure may keep process k's ages 1 .. c_k - 1 apart and lump
the ages >= c_k into one class (index c_k - 1, c_k <= tau_hat_k). Under an outcome the AoI index
t (tau - 1) of k moves to min(t + 1, s), s = :attr:`~wncs_lp.bounds.joint_chains.JointData.sat`
(the cap, or the delivered age). From any t >= c_k - 1 that is in the class again when s >= c_k - 1
and s itself when s < c_k - 1: the class moves as one state, to min(t + 1, s, c_k - 1) -- the chain
of cap c_k with its saturation clipped. So the true law's projection onto the lumped ages is
balanced under the clipped transitions, and the pair measure stays a valid constraint. The cost
q_k(tau) still needs k's ages apart: z_k keeps them all and gets its own balance on (tau_k, C)
(implied by the pairs when no age is lumped, explicit when some is), and the consistency holds on
the lumped ages, z_k summed over the class.

**Why the LP is at most g***. Take any stationary policy of the joint MDP and a stationary law
nu of it on (tau, C, a) (of the recurrent class of least gain if there are several). Its
projection onto (class_k(tau_k), class_l(tau_l), C, a) is balanced for the pair's chain (the pair's
lumped ages and the configuration move by the outcome of (C, a) alone), its projections onto
(tau_k, C, a) are one measure z_k for every partner (each the marginal of nu) and balanced, and
they share nu's (C, a) marginal; its cost is the policy's gain. So the optimal policy's law is
feasible and the LP's optimum is at most g*. With no lumping its constraints contain relaxation 4's
with any partition into pairs, so it is at least as tight.

**The certificate** (:func:`certify_level2`), of size of the LP, not of the AoI box. Let
h_kl(T_kl, C) be tables on a pair's lumped ages, h_k(tau_k, C) tables on a process's ages (zero
where no age of k is lumped), and lambda_{kl->k}(t, C, a) prices on the pair's lumped ages of k.
For each (C, a) let

.. math::

    U(C,a) = \sum_{kl} \max_{T} \Big[h_{kl}(T, C) - \sum_o P(o|C,a)\, h_{kl}(T'_o, C'_o)
              - \lambda_{kl\to k}(t_k, C, a) - \lambda_{kl\to l}(t_l, C, a)\Big]
           + \sum_k \max_{\tau} \Big[h_k(\tau, C) - \sum_o P(o|C,a)\, h_k(\tau'_o, C'_o) - q_k(\tau)
              + \sum_{l \ne k} \lambda_{kl\to k}(\mathrm{class}_k(\tau), C, a)\Big],

g = -max_{(C, a)} U(C, a). At any state-action (tau, C, a) of the box evaluate every bracket at
the state's own (lumped) ages: each price appears once with each sign and cancels, and the sum is
at most U(C, a) <= -g, i.e.

.. math:: g + V(\tau, C) \le \sum_k q_k(\tau_k) + \sum_o P(o|C,a)\, V(\tau'_o, C'_o),
          \quad V = \sum_{kl} h_{kl}(\mathrm{class}(\tau_{kl}), C) + \sum_k h_k(\tau_k, C),

since the lumped successor of the class is the class of the successor. This is the approximate-LP
inequality for the value function V: averaged over the optimal policy's stationary law the V terms
cancel and g <= g*. It holds for **any** tables and prices. At the LP's duals (the balance rows'
as h, the consistency rows' negated as lambda; the (C, a) marginal rows' prices mu_k(C, a) with
g <= sum_k mu_k(C, a) are eliminated by the maxima) every bracket is <= 0 resp. <= -mu_k by dual
feasibility, so U <= -g_LP and the certificate returns the LP's value up to the solver's dual
residual. Its cost is the LP's pair columns times their outcomes (a numba kernel), not the box's
prod_k tau_hat_k |C| states. Each pair and process table is first shifted to mid-range (which
changes the inequality only by the outcome tables' defect from stochastic, accounted for), and a
bound on the round-off (Higham's gamma, :func:`wncs_lp.solvers.iteration.gamma`) is subtracted.

The LP (:func:`level2_lp`, :class:`Level2Layout`) is solved whole by HiGHS (:func:`level2_bound`;
IPX without crossover, Clarabel or PDLP), for small and medium instances; ``lower_bound(x, 5)``
(:mod:`~wncs_lp.bounds.all_pairs`) packs it as relaxation 5, with its tables for the policies.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import ArgumentError, SolverError
from ..models.system import System
from ..solvers.highs import solve_highs
from ..solvers.iteration import gamma
from .joint_chains import JointData

__all__ = ["Level2Layout", "Level2Tables", "Level2Certificate", "Level2Result", "level2_layout", "level2_shape",
           "level2_lp",
           "level2_tables", "independent_rows", "certify_level2", "level2_bound", "LEVEL2_SOLVERS"]

#: HiGHS's ``presolve_rule_off`` bit of its dependent-equations rule (HiGHS 1.16's rule 10), off as
#: for relaxation 2's interior point (:mod:`wncs_lp.bounds.joint_ipm`): each pair's balance rows sum to
#: zero, a dependence the solvers handle without it.
_NO_DEPENDENT_EQUATIONS = 1 << 10
#: The solvers :func:`level2_bound` runs: HiGHS's IPX (interior point with an iterative, basis-
#: preconditioned linear algebra; no crossover), Clarabel (interior point, direct sparse LDL of the
#: KKT system) and HiGHS's PDLP (first order).
LEVEL2_SOLVERS = ("ipx", "clarabel", "pdlp")


@dataclass(frozen=True)
class Level2Layout:
    """Where the level-2 LP's pieces sit.

    Columns: pair i = (k, l) of ``pairs`` has y(T, p) at ``y[i] + T * P + p``, T = t_k * c_l + t_l
    on the lumped ages (c = ``lumps``); z_k(t, p) at ``z[k] + t * P + p`` on all of k's ages; x(p) at
    ``x + p``. Rows: pair i's balance rows (T, C) at ``balance[i] + T * |C| + C``, then its two
    consistency blocks (t, p) at ``consistency[i][0] + t_k * P + p`` and ``consistency[i][1] +
    t_l * P + p``; process k's own balance rows (t, C) at ``single[k] + t * |C| + C`` (-1: none, no age
    of k lumped); the (C, a) marginal rows of z_k at ``marginal + k * P + p``; the normalisation last.

    Attributes
    ----------
    pairs : tuple of (k, l), k < l
    caps, lumps : tuple of int
        tau_hat_k and c_k <= tau_hat_k (the pair measures' ages of k: c_k - 1 apart, one class).
    n_configs, n_pairs_ca : int
        |C| and P = |C x A|.
    nnz : int
        The matrix's entries before duplicates merge (an upper bound on its nonzeros).
    """

    pairs: tuple
    caps: tuple
    lumps: tuple
    n_configs: int
    n_pairs_ca: int
    y: tuple
    z: tuple
    x: int
    cols: int
    balance: tuple
    consistency: tuple
    single: tuple
    marginal: int
    rows: int
    nnz: int

    def lumped(self, k: int) -> bool:
        return self.lumps[k] < self.caps[k]


def _lumps(caps, lump) -> tuple:
    n = len(caps)
    if lump is None:
        return tuple(int(c) for c in caps)
    if np.isscalar(lump):
        lump = [lump] * n
    lump = list(lump)
    if len(lump) != n:
        raise ArgumentError("lump", f"expected one threshold per process ({n}), got {len(lump)}")
    out = []
    for k, (c, v) in enumerate(zip(caps, lump)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < 1:
            raise ArgumentError("lump", f"process {k + 1}: a lumping threshold is an integer >= 1, got {v!r}")
        out.append(min(int(v), int(c)))
    return tuple(out)


def level2_layout(data: JointData, lump=None) -> Level2Layout:
    """The layout of the level-2 LP of ``data`` (sizes without building anything).

    Parameters
    ----------
    lump : None, int or sequence of int
        The pair measures keep process k's AoI indices below c_k - 1 apart and lump the rest,
        c_k = min(lump_k, tau_hat_k) (module docstring); None: no lumping.
    """
    return level2_shape(data.caps, data.n_configs, int(data.act_ptr[-1]), data.n_outcomes, lump)


def level2_shape(caps, n_configs: int, n_pairs_ca: int, n_outcomes: int, lump=None) -> Level2Layout:
    """:func:`level2_layout` from the counts alone: the caps tau_hat_k, |C|, |C x A| and the
    automaton's outcomes (what a size check needs, without the joint data's arrays)."""
    caps = tuple(int(c) for c in caps)
    N, P, nC, E = len(caps), int(n_pairs_ca), int(n_configs), int(n_outcomes)
    lumps = _lumps(caps, lump)
    pairs = tuple(itertools.combinations(range(N), 2))
    y, bal, cons = [], [], []
    cols = row = nnz = 0
    for k, l in pairs:
        a, b = lumps[k], lumps[l]
        y.append(cols)
        bal.append(row)
        cols += a * b * P
        row += a * b * nC
        cons.append((row, row + a * P))
        row += (a + b) * P
        nnz += a * b * (P + E) + 2 * a * b * P + caps[k] * P + caps[l] * P
    z = []
    for k in range(N):
        z.append(cols)
        cols += caps[k] * P
    single = []
    for k in range(N):
        if lumps[k] < caps[k]:
            single.append(row)
            row += caps[k] * nC
            nnz += caps[k] * (P + E)
        else:
            single.append(-1)
    marginal = row
    row += N * P + 1
    nnz += sum(caps) * P + N * P + P
    return Level2Layout(pairs=pairs, caps=caps, lumps=lumps, n_configs=nC, n_pairs_ca=P, y=tuple(y), z=tuple(z),
                        x=cols, cols=cols + P, balance=tuple(bal), consistency=tuple(cons), single=tuple(single),
                        marginal=marginal, rows=row, nnz=nnz)


def _clipped_sat(data: JointData, k: int, c: int) -> np.ndarray:
    """Process k's successor bounds on ages lumped at c: t -> min(t + 1, s), s clipped to c - 1."""
    return np.ascontiguousarray(np.minimum(data.sat_of(k), c - 1))


def _chain_entries(data: JointData, c1: int, c2: int, s1: np.ndarray, s2: np.ndarray, row0: int, col0: int):
    """The balance entries of a chain on (T, C), T = t1 * c2 + t2, columns (T, p) at col0 + T P + p:
    +1 where the column leaves (T, C_p), -P(o|p) where it enters (T'_o, C'_o)."""
    P, nC = int(data.act_ptr[-1]), data.n_configs
    T = np.arange(c1 * c2)
    t1, t2 = T // c2, T % c2
    p_of = np.repeat(np.arange(P), np.diff(data.out_ptr))
    r_out = (row0 + T[:, None] * nC + data.pair_c[None, :]).ravel()
    c_out = (col0 + T[:, None] * P + np.arange(P)[None, :]).ravel()
    n1 = np.minimum(t1[:, None] + 1, s1[None, :])
    n2 = np.minimum(t2[:, None] + 1, s2[None, :])
    r_in = (row0 + (n1 * c2 + n2) * nC + data.out_nxt[None, :]).ravel()
    c_in = (col0 + T[:, None] * P + p_of[None, :]).ravel()
    v_in = np.broadcast_to(-data.out_prob[None, :], n1.shape).ravel()
    return (np.concatenate([r_out, r_in]), np.concatenate([c_out, c_in]),
            np.concatenate([np.ones(r_out.size), v_in]))


def level2_lp(data: JointData, lay: Level2Layout | None = None):
    """``(A, b, c)`` of the level-2 LP, min c v s.t. A v = b, v >= 0, in the layout ``lay``
    (:func:`level2_layout`; default: no lumping). A is CSR with duplicate entries summed."""
    lay = lay if lay is not None else level2_layout(data)
    N, P = data.n_processes, lay.n_pairs_ca
    R, C, V = [], [], []
    zero = np.zeros(data.n_outcomes, dtype=np.int64)
    for i, (k, l) in enumerate(lay.pairs):
        a, b = lay.lumps[k], lay.lumps[l]
        r, c, v = _chain_entries(data, a, b, _clipped_sat(data, k, a), _clipped_sat(data, l, b), lay.balance[i], lay.y[i])
        R.append(r); C.append(c); V.append(v)
        T = np.arange(a * b)
        for side, (who, t, cw) in enumerate(((k, T // b, a), (l, T % b, b))):
            row0 = lay.consistency[i][side]
            R.append((row0 + t[:, None] * P + np.arange(P)[None, :]).ravel())
            C.append((lay.y[i] + T[:, None] * P + np.arange(P)[None, :]).ravel())
            V.append(np.ones(a * b * P))
            tt = np.minimum(np.arange(lay.caps[who]), cw - 1)  # z_who's ages summed over each class
            R.append((row0 + tt[:, None] * P + np.arange(P)[None, :]).ravel())
            C.append((lay.z[who] + np.arange(lay.caps[who])[:, None] * P + np.arange(P)[None, :]).ravel())
            V.append(-np.ones(lay.caps[who] * P))
    for k in range(N):
        if lay.single[k] >= 0:
            r, c, v = _chain_entries(data, lay.caps[k], 1, data.sat_of(k), zero, lay.single[k], lay.z[k])
            R.append(r); C.append(c); V.append(v)
        ck = lay.caps[k]
        R.append(np.tile(lay.marginal + k * P + np.arange(P), ck))
        C.append(lay.z[k] + np.arange(ck * P))
        V.append(np.ones(ck * P))
        R.append(lay.marginal + k * P + np.arange(P))
        C.append(lay.x + np.arange(P))
        V.append(-np.ones(P))
    R.append(np.full(P, lay.rows - 1)); C.append(lay.x + np.arange(P)); V.append(np.ones(P))
    A = sp.coo_matrix((np.concatenate(V), (np.concatenate(R), np.concatenate(C))), shape=(lay.rows, lay.cols)).tocsr()
    A.sum_duplicates()
    b = np.zeros(lay.rows)
    b[-1] = 1.0
    cost = np.zeros(lay.cols)
    for k in range(N):
        cost[lay.z[k]:lay.z[k] + lay.caps[k] * P] = np.repeat(np.asarray(data.q[k], float), P)
    return A, b, cost


def independent_rows(lay: Level2Layout) -> np.ndarray:
    """(rows,) bool: the rows of :func:`level2_lp` kept for the solver, the others implied by them.

    The LP's equations are dependent, and an interior point pays for it (IPX builds its
    preconditioning basis around the deficiency: minutes of factorizations at 60k rows). The
    relations, each of whose last-named row is dropped:

    * **a pair's k-side consistency** summed over t_k plus z_k's (C, a) marginal row equals the
      l-side's summed plus z_l's, for each (C, a): the l-side row t_l = 0 is dropped;
    * **a pair's marginal balance**: pair (k, l)'s balance rows at (t_k, ., C) summed over t_l are,
      through the k-side consistency rows, the balance of z_k on (class t_k, C) -- the same form as
      for k's first partner (the lowest other index), or z_k's own balance rows summed over the
      class when k has them: for every pair but k's first (and for every pair when k is lumped)
      the rows (t_k, c_l - 1, C) are dropped; likewise the rows (c_k - 1, t_l, C) for l;
    * **a pair's balance rows sum to zero** (each column leaves one state and enters with
      probability one): for a pair that is both members' first partner (no family dropped) the row
      (c_k - 1, c_l - 1, C_0) is dropped;
    * **z_k's balance rows** (lumped k) sum to zero: row (tau_hat_k - 1, C_0) of the first lumped
      process is dropped; for the other lumped processes the rows (tau_hat_k - 1, C) for every C
      (their configuration balance is the first one's through the consistency and marginal rows).

    The tests check on small instances that the kept rows have full rank and the dropped ones are
    in their span (the LP's optimum unchanged). Nothing here enters the bound: the certificate
    takes any duals (a dropped row's dual is 0), so a row dropped wrongly could only loosen it.
    """
    keep = np.ones(lay.rows, dtype=bool)
    nC, P, N = lay.n_configs, lay.n_pairs_ca, len(lay.caps)
    first = [1 if k == 0 else 0 for k in range(N)]
    C = np.arange(nC)
    for i, (k, l) in enumerate(lay.pairs):
        a, b = lay.lumps[k], lay.lumps[l]
        base = lay.balance[i]
        k_family = first[k] != l or lay.lumped(k)
        l_family = first[l] != k or lay.lumped(l)
        if k_family:
            keep[(base + (np.arange(a)[:, None] * b + b - 1) * nC + C[None, :]).ravel()] = False
        if l_family:
            keep[(base + ((a - 1) * b + np.arange(b)[:, None]) * nC + C[None, :]).ravel()] = False
        if not (k_family or l_family):
            keep[base + ((a - 1) * b + b - 1) * nC] = False
        keep[lay.consistency[i][1] + np.arange(P)] = False
    lumped = [k for k in range(N) if lay.single[k] >= 0]
    for j, k in enumerate(lumped):
        last = lay.single[k] + (lay.caps[k] - 1) * nC
        keep[last if j == 0 else last + C] = False
    return keep


@dataclass(frozen=True, eq=False)
class Level2Tables:
    """Tables and prices for :func:`certify_level2` (any values give a valid bound).

    Attributes
    ----------
    pair : tuple of (|C|, c_k * c_l) arrays
        h_kl(C, T) per pair of the layout, T = t_k * c_l + t_l on the lumped ages.
    price : tuple of ((P, c_k), (P, c_l)) arrays
        lambda_{kl->k}(p, t_k) and lambda_{kl->l}(p, t_l) per pair, on the lumped ages.
    single : tuple of (|C|, tau_hat_k) arrays or None
        h_k(C, t) per process (None: zero).
    """

    pair: tuple
    price: tuple
    single: tuple


def level2_tables(lay: Level2Layout, row_duals: np.ndarray) -> Level2Tables:
    """The tables and prices of the LP's row duals (HiGHS's sign: reduced costs c - A^T y >= 0): the
    balance rows' duals are the tables, the consistency rows' duals negated the prices."""
    y = np.asarray(row_duals, float)
    if y.shape != (lay.rows,):
        raise SolverError(f"level-2 duals: expected {lay.rows} row duals, got shape {y.shape}")
    nC, P = lay.n_configs, lay.n_pairs_ca
    pair, price = [], []
    for i, (k, l) in enumerate(lay.pairs):
        a, b = lay.lumps[k], lay.lumps[l]
        pair.append(np.ascontiguousarray(y[lay.balance[i]:lay.balance[i] + a * b * nC].reshape(a * b, nC).T))
        sides = []
        for side, cw in enumerate((a, b)):
            r0 = lay.consistency[i][side]
            sides.append(np.ascontiguousarray(-y[r0:r0 + cw * P].reshape(cw, P).T))
        price.append(tuple(sides))
    single = tuple(None if lay.single[k] < 0 else
                   np.ascontiguousarray(y[lay.single[k]:lay.single[k] + lay.caps[k] * nC].reshape(lay.caps[k], nC).T)
                   for k in range(len(lay.caps)))
    return Level2Tables(pair=tuple(pair), price=tuple(price), single=single)


@dataclass(frozen=True, eq=False)
class Level2Certificate:
    """A certified lower bound from level-2 tables (:func:`certify_level2`).

    Attributes
    ----------
    lower_bound : float
        ``raw - roundoff``: a lower bound on g* in exact arithmetic.
    raw : float
        -max_p U(p) as computed.
    roundoff : float
        The bound on its floating-point error.
    u : (|C x A|,) array
        U(p).
    binding_pair : int
        A (C, a) pair where U is largest.
    """

    lower_bound: float
    raw: float
    roundoff: float
    u: np.ndarray
    binding_pair: int


def _kernel():
    try:
        from . import level2_kernels
    except ImportError as exc:
        raise SolverError(f"the level-2 certificate needs numba (pip install 'wncs_lp[fast]'): {exc}") from None
    return level2_kernels.residuals


def certify_level2(data: JointData, lay: Level2Layout, tables: Level2Tables) -> Level2Certificate:
    """The certified lower bound g = -max_{(C, a)} U(C, a) of any level-2 tables and prices (module
    docstring), less a bound on its round-off. Non-finite entries certify nothing (-inf)."""
    residuals = _kernel()
    nC, P, N = lay.n_configs, lay.n_pairs_ca, len(lay.caps)
    if len(tables.pair) != len(lay.pairs) or len(tables.price) != len(lay.pairs) or len(tables.single) != N:
        raise SolverError("level-2 tables: one table and two price arrays per pair, one (or None) table per process")
    args = (data.act_ptr, data.out_ptr, data.out_nxt, data.out_prob)
    m = data.max_outcomes
    u = np.zeros(P)
    parts = []  # per part: max |u_part|
    err = 0.0
    lam_sum = [np.zeros((P, c)) for c in lay.caps]
    lam_max = np.zeros(N)
    for i, (k, l) in enumerate(lay.pairs):
        a, b = lay.lumps[k], lay.lumps[l]
        h = np.asarray(tables.pair[i], float)
        l1, l2 = (np.asarray(x, float) for x in tables.price[i])
        if h.shape != (nC, a * b) or l1.shape != (P, a) or l2.shape != (P, b):
            raise SolverError(f"level-2 tables of pair ({k + 1}, {l + 1}): shapes {h.shape}, {l1.shape}, {l2.shape}; "
                              f"expected {(nC, a * b)}, {(P, a)}, {(P, b)}")
        if not (np.isfinite(h).all() and np.isfinite(l1).all() and np.isfinite(l2).all()):
            return Level2Certificate(-np.inf, -np.inf, np.inf, np.full(P, np.inf), -1)
        h = np.ascontiguousarray(h - 0.5 * (h.max() + h.min()))
        hk = float(np.abs(h).max())
        ui = np.empty(P)
        residuals(h, np.ascontiguousarray(l1), np.ascontiguousarray(l2), a, b, *args,
                  _clipped_sat(data, k, a), _clipped_sat(data, l, b), ui)
        u += ui
        parts.append(float(np.abs(ui).max()))
        m1, m2 = float(np.abs(l1).max()), float(np.abs(l2).max())
        err += gamma(m + 3) * (2.0 * hk + m1 + m2) + data.prob_defect * hk
        lam_sum[k] += l1[:, np.minimum(np.arange(lay.caps[k]), a - 1)]
        lam_sum[l] += l2[:, np.minimum(np.arange(lay.caps[l]), b - 1)]
        lam_max[k] += m1
        lam_max[l] += m2
    zero_s = np.zeros(data.n_outcomes, dtype=np.int64)
    zero_l = np.zeros((P, 1))
    for k in range(N):
        ck = lay.caps[k]
        h = tables.single[k]
        h = np.zeros((nC, ck)) if h is None else np.asarray(h, float)
        if h.shape != (nC, ck):
            raise SolverError(f"level-2 table of process {k + 1}: shape {h.shape}; expected {(nC, ck)}")
        if not np.isfinite(h).all():
            return Level2Certificate(-np.inf, -np.inf, np.inf, np.full(P, np.inf), -1)
        h = np.ascontiguousarray(h - 0.5 * (h.max() + h.min()))
        hk = float(np.abs(h).max())
        qk = np.asarray(data.q[k], float)
        ui = np.empty(P)
        residuals(h, np.ascontiguousarray(qk[None, :] - lam_sum[k]), zero_l, ck, 1, *args, data.sat_of(k), zero_s, ui)
        u += ui
        parts.append(float(np.abs(ui).max()))
        err += gamma(m + N + 2) * (2.0 * hk + float(np.abs(qk).max()) + lam_max[k]) + data.prob_defect * hk
    err += gamma(len(parts)) * sum(parts)
    p = int(np.argmax(u))
    raw = -float(u[p])
    return Level2Certificate(lower_bound=raw - err, raw=raw, roundoff=err, u=u, binding_pair=p)


@dataclass(frozen=True, eq=False)
class Level2Result:
    """What :func:`level2_bound` found.

    Attributes
    ----------
    lower_bound : float
        The certified bound (:func:`certify_level2` on the solver's duals; -inf when it held none).
    lp_value : float
        The solver's objective (not a bound).
    status : str
        The solver's status name (a report, not a certificate).
    certificate : Level2Certificate or None
    tables : Level2Tables or None
    layout : Level2Layout
    rows, cols, nnz : int
        The LP handed over (:func:`independent_rows` only; nonzeros after duplicates merge).
    build_cpu, solve_cpu, certify_cpu : float
        CPU seconds of this process.
    iterations : int
        The solver's iterations.
    stats : dict
        :func:`~wncs_lp.solvers.highs.solve_highs`'s statistics.
    """

    lower_bound: float
    lp_value: float
    status: str
    certificate: Level2Certificate | None
    tables: Level2Tables | None
    layout: Level2Layout
    rows: int
    cols: int
    nnz: int
    build_cpu: float
    solve_cpu: float
    certify_cpu: float
    iterations: int
    stats: dict = field(default_factory=dict)


def _solve_clarabel(A, b, c, tol: float, verbose: bool, time_limit: float | None):
    """min c v s.t. A v = b, v >= 0 by Clarabel: ``(z, stats)`` with z = -row duals (HiGHS's
    :func:`~wncs_lp.solvers.highs.solve_highs` sign), NaN when it returned none."""
    import clarabel

    from ..solvers.lp import clarabel_settings, clarabel_solve

    m, n = A.shape
    K = sp.vstack([sp.csc_matrix(A), -sp.identity(n, format="csc")], format="csc")
    extra = {} if time_limit is None else {"time_limit": float(time_limit)}
    solver = clarabel.DefaultSolver(sp.csc_matrix((n, n)), np.asarray(c, float), K, np.concatenate([b, np.zeros(n)]),
                                    [clarabel.ZeroConeT(m), clarabel.NonnegativeConeT(n)],
                                    clarabel_settings(tol, 200, verbose, extra))
    sol = clarabel_solve(solver)
    z = np.asarray(sol.z, float)[:m] if len(sol.z) == m + n else np.full(m, np.nan)
    stats = {"solver_status": str(sol.status), "obj_scaled": float(sol.obj_val), "solver_iterations": int(sol.iterations)}
    return z, stats


def level2_bound(system: System | JointData, *, lump=None, solver: str = "ipx", tol: float = 1e-8,
                 time_limit: float | None = None, cpu_limit: float | None = None,
                 verbose: bool = False) -> Level2Result:
    """The level-2 relaxation's certified lower bound on g*: its LP solved whole, its duals certified.

    Parameters
    ----------
    system : System or JointData
    lump : None, int or sequence of int
        Lumping thresholds of the pair measures (:func:`level2_layout`); None: none.
    solver : {"ipx", "clarabel", "pdlp"}
        HiGHS's interior point IPX (no crossover; the default), Clarabel's or HiGHS's first-order
        PDLP (:data:`LEVEL2_SOLVERS`). Any duals are certified, so a loose solve gives a valid,
        looser bound.
    tol : float
        The solver's optimality / feasibility tolerance.
    time_limit : float, optional
        Wall-clock seconds for the solver. HiGHS 1.16 holds no duals after its time limit (IPX and
        PDLP alike, measured): such a run certifies nothing (``lower_bound`` = -inf).
    cpu_limit : float, optional
        CPU seconds of this process for IPX (HiGHS's interrupt callback; an interrupted run holds no
        duals and certifies nothing); not used by Clarabel or PDLP.
    verbose : bool
        HiGHS's log on stdout.

    Returns
    -------
    Level2Result
    """
    if solver not in LEVEL2_SOLVERS:
        raise ArgumentError("solver", f"expected one of {', '.join(LEVEL2_SOLVERS)}, got {solver!r}")
    if not (isinstance(tol, (int, float)) and np.isfinite(tol) and tol > 0):
        raise ArgumentError("tol", f"a positive number, got {tol!r}")
    c0 = time.process_time()
    data = system if isinstance(system, JointData) else JointData.from_system(system)
    lay = level2_layout(data, lump)
    A, b, c = level2_lp(data, lay)
    keep = independent_rows(lay)
    A, b = A[keep], b[keep]
    build = time.process_time() - c0
    c0 = time.process_time()
    if solver == "clarabel":
        z, stats = _solve_clarabel(A, b, c, float(tol), verbose, time_limit)
    else:
        settings = {"variant": "ipx", "run_crossover": "off", "presolve_rule_off": _NO_DEPENDENT_EQUATIONS}
        if solver == "pdlp":
            settings = {"variant": "ipx", "solver": "pdlp", "pdlp_optimality_tolerance": float(tol)}
        if time_limit is not None:
            settings["time_limit"] = float(time_limit)
        stop = None if cpu_limit is None else (lambda: time.process_time() - c0 > cpu_limit)
        _, _, z, stats = solve_highs(A.tocsc(), b, c, tol=float(tol), max_iter=2**31 - 1, verbose=verbose,
                                     settings=settings, interrupt=stop)
    solve = time.process_time() - c0
    c0 = time.process_time()
    tables = cert = None
    bound = -np.inf
    if np.isfinite(z).all():
        duals = np.zeros(lay.rows)
        duals[keep] = -z  # solve_highs returns z = -row_dual; a dropped row's dual is 0
        tables = level2_tables(lay, duals)
        cert = certify_level2(data, lay, tables)
        bound = cert.lower_bound
    return Level2Result(lower_bound=bound, lp_value=float(stats["obj_scaled"]), status=str(stats["solver_status"]),
                        certificate=cert, tables=tables, layout=lay, rows=int(A.shape[0]), cols=int(A.shape[1]),
                        nnz=int(A.nnz), build_cpu=build, solve_cpu=solve, certify_cpu=time.process_time() - c0,
                        iterations=int(stats["solver_iterations"]), stats=stats)

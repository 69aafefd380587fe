"""Matrix-free certified value iteration and exact policy evaluation over the AoI box.

Every model of the toolkit has states s = (c, tau): a configuration c of a small automaton
(:mod:`wncs_lp.models.automaton`) and the AoI vector tau, which moves by arithmetic,

    tau'_k = min(tau_k + 1, delta_k if delivered, tau_hat_k),

for each outcome (c', delta, p) of (c, action). So the Bellman operator needs no stored
transition matrix: a sweep walks, per configuration, a dense box of AoI vectors and computes
the successor indices (:mod:`wncs_lp.solvers._matrix_free_kernels`). Memory is one float64
value vector and one byte of policy per state, plus a second vector when it fits (for the
extrapolation and warm start below, or a Jacobi iteration): the paper's four processes at cap
30 (2.5e8 states) need 2.3 GB (4.3 GB with the second vector), where the stored matrix would
need about 30 GB.

State space (:class:`BoxLayout`)
--------------------------------
For configuration c and process k let [lo_k(c), hi_k(c)] be the smallest interval containing
every tau_k reachable with c (the per-axis fixed point of the size guard, taken as intervals).
The layout holds the product of these intervals for every c, configuration-major, C order of
the box within a configuration (the last process contiguous). This set S is *closed* (every
successor of a state of S is in S) and contains the reachable set R that
:func:`wncs_lp.models.build` enumerates (a few percent more states: 1,073,595 against
1,045,479 for the paper's four processes at cap 10).

Why the certificate over S is valid for the MDP over R: R is closed, so (T h)(s) for s in R
reads h on R only; hence min_R (T h - h) >= min_S (T h - h) and max_R <= max_S, and the
bracket lo_S <= g* <= hi_S holds for R's optimal gain. It *closes* (lo, hi -> g*) when the
states of S \\ R are transient under every policy. That holds when from every configuration,
whatever the actions, an initial configuration (whose whole tau box is in R) is reachable with
positive probability -- in the Section II model because any uplink can lose its update
(p_up < 1), in the preemption model because arrivals can fail. This is checked on the
automaton (:func:`drains_to_initial`); when it fails (e.g. p = 1), ``domain="auto"`` computes
the exact reachable set R as a byte mask over S (a fixed point of marking passes) and the
bracket is taken over R only. ``domain="reachable"`` forces that.

Both model kinds have this structure, so the preemption model is solved the same way (its
automaton carries the job ages; its configurations grow with the cap, the box per
configuration does not).

Policies
--------
:attr:`MatrixFreeSolution.policy` is **not** pair indices (there is no MDP): it is one
``uint8`` per layout state, the *local* action index j (``system.automaton.actions[c][j]``,
the MDP's action order for that configuration) of the greedy policy of the certified bias.
:meth:`MatrixFreeSolution.on_mdp` converts a solution to the ordinary pair-index form on an
enumerated MDP of the same scenario; :class:`wncs_lp.policies.MatrixFreePolicy` is a
:class:`~wncs_lp.policies.Policy` (``act``, ``on_mdp``) usable by the simulator and the
evaluators; :meth:`MatrixFreeSolution.save` / :func:`load_solution` store it.

Exact evaluation of a given policy (:func:`matrix_free_evaluate`) iterates the fixed-policy
operator T_pi to the bracket min_S (T_pi h - h) <= g_pi <= max_S (T_pi h - h).
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import PolicyError, SolverError
from ..models.system import System
from ..scenario import Scenario
from .certify import width_closed
from .dp import VI_TOL, initial_bias
from .result import Solution

__all__ = [
    "BoxLayout",
    "MatrixFreeSolution",
    "MatrixFreeEvaluation",
    "matrix_free_value_iteration",
    "matrix_free_evaluate",
    "policy_table",
    "drains_to_initial",
    "reachable_mask",
    "load_solution",
    "cap_cost",
    "matrix_free_cap_mass",
    "matrix_free_cap_masses",
    "solve_scenario",
    "matrix_free_bytes",
    "DOMAINS",
    "SCHEMES",
]

#: ``domain`` values of the solvers (see the module docstring).
DOMAINS = ("auto", "hull", "reachable")
#: ``scheme`` values of :func:`matrix_free_value_iteration`.
SCHEMES = ("auto", "mpi", "gs", "jacobi")

#: Below this many layout states the solvers use one thread whatever ``threads`` says.
PARALLEL_MIN_STATES = 1_000_000

#: Bytes per state of a solve: one float64 value vector and the uint8 policy (a Jacobi
#: iteration, or the stall fallback, adds a second vector: 17 bytes).
BYTES_PER_STATE = 9


def matrix_free_bytes(n_states: int, *, vectors: int = 1, mask: bool = False) -> int:
    """Memory of a matrix-free solve over ``n_states`` layout states (value vectors, policy,
    optional reachability mask)."""
    return int(n_states) * (8 * int(vectors) + 1 + (1 if mask else 0))


def _kernels():
    if os.environ.get("WNCS_LP_NO_NUMBA"):
        raise SolverError("the matrix-free solver needs numba, disabled here by WNCS_LP_NO_NUMBA")
    try:
        from . import _matrix_free_kernels as K
    except ImportError as exc:  # pragma: no cover - numba is installed in the test environment
        raise SolverError(
            f"the matrix-free solver needs numba (pip install 'wncs_lp[fast]'): {exc}"
        ) from None
    return K


def _as_system(obj: Any) -> System:
    if isinstance(obj, System):
        return obj
    if isinstance(obj, Scenario):
        return System.from_scenario(obj)
    raise SolverError(f"expected a Scenario or a System, got {type(obj).__name__}")


# ============================================================================ layout
def drains_to_initial(system: System) -> bool:
    """Whether every configuration reaches an initial one with positive probability under
    every action choice (a fixed point on the automaton; see the module docstring).

    When true, every state of the hull outside the reachable set is transient under every
    policy, so the hull's certificate closes on the reachable MDP's gain.
    """
    flat = system.automaton.flat(system.n_processes)
    nC = system.n_configs
    good = np.zeros(nC, dtype=bool)
    good[list(system.automaton.initial)] = True
    a_start = flat.act_ptr[:-1]
    o_start = flat.out_ptr[:-1]
    while True:
        ok_out = good[flat.out_nxt]
        ok_act = np.logical_or.reduceat(ok_out, o_start) if ok_out.size else np.zeros(0, bool)
        ok_cfg = np.logical_and.reduceat(ok_act, a_start) if ok_act.size else np.zeros(0, bool)
        new = good | ok_cfg
        if np.array_equal(new, good):
            return bool(good.all())
        good = new


@dataclass(frozen=True, eq=False)
class BoxLayout:
    """The states of a matrix-free solve: one dense AoI sub-box per configuration.

    Attributes
    ----------
    caps : (N,) int array
    lo, dims : (|C|, N) int arrays
        Configuration c covers the 0-based AoI indices ``lo[c, k] .. lo[c, k] + dims[c, k] - 1``
        (tau_k = index + 1).
    strides : (|C|, N) int array
        C-order strides of each sub-box (the last axis contiguous).
    off : (|C| + 1,) int array
        The states of configuration c are ``off[c]:off[c+1]``.
    domain : str
        ``"hull"`` (per-axis interval hull, the default) or ``"box"`` (the whole box).
    """

    caps: np.ndarray
    lo: np.ndarray
    dims: np.ndarray
    strides: np.ndarray
    off: np.ndarray
    domain: str = "hull"

    @property
    def n_states(self) -> int:
        return int(self.off[-1])

    @property
    def n_configs(self) -> int:
        return int(self.lo.shape[0])

    @property
    def n_processes(self) -> int:
        return int(self.caps.size)

    @classmethod
    def from_system(cls, system: System, domain: str = "hull") -> "BoxLayout":
        """The per-axis interval hull of the reachable set (``domain="hull"``) or the full box."""
        caps = np.asarray(system.caps, dtype=np.int64)
        N, nC = caps.size, system.n_configs
        if domain == "box":
            lo = np.zeros((nC, N), np.int64)
            hi = np.tile(caps - 1, (nC, 1))
        elif domain == "hull":
            lo, hi = _interval_hull(system)
        else:
            raise SolverError(f"unknown layout domain {domain!r}; expected 'hull' or 'box'")
        dims = hi - lo + 1
        strides = np.ones((nC, N), np.int64)
        for k in range(N - 2, -1, -1):
            strides[:, k] = strides[:, k + 1] * dims[:, k + 1]
        sizes = np.prod(dims, axis=1)
        off = np.r_[0, np.cumsum(sizes)].astype(np.int64)
        return cls(caps, lo, dims, strides, off, domain)

    def index(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """Layout indices of R states ((R, N) AoI values 1..tau_hat, (R,) configuration ids); -1
        for a state outside the layout."""
        t = np.asarray(tau, dtype=np.int64) - 1
        c = np.asarray(config_ids, dtype=np.int64)
        if t.ndim != 2 or t.shape[1] != self.n_processes or c.shape != (t.shape[0],):
            raise PolicyError(f"expected tau of shape (R, {self.n_processes}) and config_ids of shape (R,)")
        rel = t - self.lo[c]
        inside = np.all((rel >= 0) & (rel < self.dims[c]), axis=1)
        idx = self.off[c] + np.einsum("rk,rk->r", np.where(rel >= 0, rel, 0), self.strides[c])
        return np.where(inside, idx, -1)

    def config_taus(self, c: int) -> np.ndarray:
        """(n_c, N) AoI vectors (1-based) of configuration c, in layout order."""
        grids = np.indices(tuple(int(d) for d in self.dims[c]), dtype=np.int64).reshape(self.n_processes, -1).T
        return grids + self.lo[c][None, :] + 1

    def config_of(self, s: np.ndarray) -> np.ndarray:
        """Configuration id of layout states."""
        return np.searchsorted(self.off, np.asarray(s, dtype=np.int64), side="right") - 1

    def tau_of(self, s: np.ndarray) -> np.ndarray:
        """(R, N) AoI vectors (1-based) of layout states."""
        s = np.asarray(s, dtype=np.int64)
        c = self.config_of(s)
        rem = s - self.off[c]
        out = np.empty((s.size, self.n_processes), np.int64)
        for k in range(self.n_processes):
            out[:, k] = rem // self.strides[c, k]
            rem = rem - out[:, k] * self.strides[c, k]
        return out + self.lo[c] + 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {"caps": self.caps, "lo": self.lo, "dims": self.dims}


def _interval_hull(system: System) -> tuple[np.ndarray, np.ndarray]:
    """Per configuration and process, the smallest interval [lo, hi] (0-based) of reachable
    tau_k: the fixed point of the interval images f([a, b]) = [f(a), f(b)],
    f(t) = min(t + 1, delta - 1, cap - 1), over every edge, from the initial configurations'
    full boxes. (The product of these intervals is closed under every transition.)"""
    caps = np.asarray(system.caps, dtype=np.int64)
    N, nC = caps.size, system.n_configs
    flat = system.automaton.flat(N)
    src = np.repeat(np.arange(nC, dtype=np.int64), np.diff(flat.out_ptr[flat.act_ptr]))
    nxt = flat.out_nxt.astype(np.int64)
    m = _saturation(flat.deltas, caps)[flat.out_delta] if flat.deltas.shape[0] else np.tile(caps - 1, (nxt.size, 1))
    big = np.iinfo(np.int64).max
    lo = np.full((nC, N), big, np.int64)
    hi = np.full((nC, N), -1, np.int64)
    init = np.asarray(sorted(set(int(i) for i in system.automaton.initial)), dtype=np.int64)
    lo[init] = 0
    hi[init] = caps - 1
    while True:
        live = hi[src, 0] >= 0
        s, n_, mm = src[live], nxt[live], m[live]
        new_lo = np.minimum(lo[s] + 1, mm)
        new_hi = np.minimum(hi[s] + 1, mm)
        lo2, hi2 = lo.copy(), hi.copy()
        np.minimum.at(lo2, n_, new_lo)
        np.maximum.at(hi2, n_, new_hi)
        if np.array_equal(lo2, lo) and np.array_equal(hi2, hi):
            break
        lo, hi = lo2, hi2
    if np.any(hi < 0):  # pragma: no cover - explore_configs only keeps reachable configurations
        raise SolverError("internal error: a configuration of the automaton is not reachable")
    return lo, hi


def _saturation(deltas: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """(nD, N) 0-based saturation index of each delivery vector: min(cap - 1, delta - 1 if > 0)."""
    d = np.asarray(deltas, dtype=np.int64)
    return np.where(d > 0, np.minimum(d - 1, caps[None, :] - 1), caps[None, :] - 1)


@dataclass(frozen=True, eq=False)
class _Operator:
    """The flat arrays the kernels read (see :mod:`._matrix_free_kernels`)."""

    N: int
    caps: np.ndarray
    lo: np.ndarray
    dims: np.ndarray
    off: np.ndarray
    act_ptr: np.ndarray
    out_ptr: np.ndarray
    e_prob: np.ndarray
    e_m: np.ndarray
    e_base: np.ndarray
    e_stride: np.ndarray
    q: np.ndarray
    strides: np.ndarray
    tile_tc: np.ndarray
    tile_ptr: np.ndarray
    tile_cfg: np.ndarray
    max_out: int
    max_row: int
    cost_scale: float

    @classmethod
    def build(cls, system: System, layout: BoxLayout) -> "_Operator":
        N = layout.n_processes
        caps = layout.caps
        flat = system.automaton.flat(N)
        nxt = flat.out_nxt.astype(np.int64)
        if flat.deltas.shape[0]:
            e_m = _saturation(flat.deltas, caps)[flat.out_delta]
        else:
            e_m = np.tile(caps - 1, (nxt.size, 1))
        e_stride = layout.strides[nxt]
        e_base = layout.off[nxt] - np.einsum("ek,ek->e", e_stride, layout.lo[nxt])
        qmax = int(caps.max())
        q = np.zeros((N, qmax))
        for k in range(N):
            q[k, : caps[k]] = system.q[k]
        scale = float(sum(float(np.max(np.abs(system.q[k]))) for k in range(N)))
        tile_tc, tile_ptr, tile_cfg = _tiles(layout)
        n_out = np.diff(flat.out_ptr[flat.act_ptr])
        return cls(
            N=N,
            caps=np.ascontiguousarray(caps, np.int64),
            lo=np.ascontiguousarray(layout.lo, np.int64),
            dims=np.ascontiguousarray(layout.dims, np.int64),
            off=np.ascontiguousarray(layout.off, np.int64),
            act_ptr=np.ascontiguousarray(flat.act_ptr, np.int64),
            out_ptr=np.ascontiguousarray(flat.out_ptr, np.int64),
            e_prob=np.ascontiguousarray(flat.out_prob, float),
            e_m=np.ascontiguousarray(e_m, np.int64),
            e_base=np.ascontiguousarray(e_base, np.int64),
            e_stride=np.ascontiguousarray(e_stride, np.int64),
            q=q,
            strides=np.ascontiguousarray(layout.strides, np.int64),
            tile_tc=tile_tc,
            tile_ptr=tile_ptr,
            tile_cfg=tile_cfg,
            max_out=int(n_out.max()),
            max_row=int(layout.dims[:, N - 1].max()),
            cost_scale=scale,
        )


def _tiles(layout: BoxLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tiles of a sweep: every vector of absolute AoI indices of the first N - 2 axes (C
    order), with the configurations whose box contains it (one tile, every configuration,
    when N <= 2)."""
    N, nC = layout.n_processes, layout.n_configs
    K = max(N - 2, 0)
    if K == 0:
        return np.zeros((1, 1), np.int64), np.array([0, nC], np.int64), np.arange(nC, dtype=np.int64)
    caps = layout.caps[:K]
    grid = np.indices(tuple(int(x) for x in caps), dtype=np.int64).reshape(K, -1).T  # (nT, K)
    lo = layout.lo[:, :K]
    hi = lo + layout.dims[:, :K] - 1
    inside = np.all((grid[:, None, :] >= lo[None]) & (grid[:, None, :] <= hi[None]), axis=2)  # (nT, nC)
    counts = inside.sum(axis=1)
    tile_ptr = np.r_[0, np.cumsum(counts)].astype(np.int64)
    tile_cfg = np.nonzero(inside)[1].astype(np.int64)
    return np.ascontiguousarray(grid), tile_ptr, tile_cfg


def _work_items(op: _Operator, nchunk: int, reverse: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The work of a sweep as items (tile, x0, x1) -- the planes of configurations
    ``tile_cfg[x0:x1]`` in that tile -- in sweep order; ``ip``: chunk ci does
    ``items[ip[ci]:ip[ci + 1]]``; and the ``tile_cfg`` the items index.

    With several chunks, each is a contiguous range of tiles of about equal work (states x
    outcomes), so every thread sweeps its part of the box in the serial order. With fewer than
    4 tiles per chunk (N <= 3 processes at small caps), each tile's configurations are split
    between the chunks instead (largest work first to the lightest chunk)."""
    nT = op.tile_ptr.size - 1
    tiles = np.arange(nT, dtype=np.int64)[::-1] if reverse else np.arange(nT, dtype=np.int64)
    whole = np.ascontiguousarray(np.stack([tiles, op.tile_ptr[tiles], op.tile_ptr[tiles + 1]], axis=1))
    if nchunk == 1:
        return whole, np.array([0, nT], np.int64), op.tile_cfg
    work = np.diff(op.off).astype(float) * np.diff(op.out_ptr[op.act_ptr])  # a configuration's whole box
    if nT >= 4 * nchunk:
        plane = work / np.prod(op.dims[:, : max(op.N - 2, 0)], axis=1)  # one of its planes
        tile_work = np.add.reduceat(plane[op.tile_cfg], op.tile_ptr[:-1])
        cum = np.cumsum(tile_work[tiles])
        cuts = np.searchsorted(cum, cum[-1] * np.arange(1, nchunk) / nchunk)
        return whole, np.r_[0, cuts, nT].astype(np.int64), op.tile_cfg
    nC = op.off.size - 1
    chunk_of = np.zeros(nC, np.int64)
    load = np.zeros(nchunk)
    for c in np.argsort(-work, kind="stable"):
        i = int(np.argmin(load))
        chunk_of[c] = i
        load[i] += work[c]
    tile_of = np.repeat(np.arange(nT, dtype=np.int64), np.diff(op.tile_ptr))
    key = tile_of * nchunk + chunk_of[op.tile_cfg]
    order = np.argsort(key, kind="stable")
    counts = np.bincount(key, minlength=nT * nchunk).reshape(nT, nchunk)
    cptr = np.zeros((nT, nchunk + 1), np.int64)
    cptr[:, 1:] = np.cumsum(counts, axis=1)
    cptr += op.tile_ptr[:-1, None]
    items, ip = [], [0]
    for ci in range(nchunk):
        items += [(t, cptr[t, ci], cptr[t, ci + 1]) for t in tiles if cptr[t, ci + 1] > cptr[t, ci]]
        ip.append(len(items))
    return (np.asarray(items, np.int64).reshape(-1, 3), np.asarray(ip, np.int64),
            np.ascontiguousarray(op.tile_cfg[order]))


class _Sweeper:
    """Calls the kernels with the right driver (serial or numba threads) and reductions."""

    def __init__(self, op: _Operator, threads: int | None, mask: np.ndarray | None, reverse: bool = False):
        self.K = _kernels()
        import numba

        self.numba = numba
        self.op = op
        self.threads = max(1, min(int(threads or 1), numba.config.NUMBA_NUM_THREADS))
        if op.off[-1] < PARALLEL_MIN_STATES:
            # a parallel region per sweep costs ~5 ms on a loaded machine (both threads must be
            # scheduled): below this size one thread is faster
            self.threads = 1
        self.nchunk = self.threads
        self.items, self.ip, self.tile_cfg = _work_items(op, self.nchunk, reverse)
        self.los = np.empty(self.nchunk)
        self.his = np.empty(self.nchunk)
        self.mask = mask if mask is not None else np.zeros(1, np.uint8)
        self.use_mask = mask is not None
        self._dummy_h = np.zeros(1)
        self._dummy_W = np.zeros((1, 1))

    def _run(self, fn_par, fn_ser, *args):
        if self.threads > 1:
            nb = self.numba
            old = nb.get_num_threads()
            nb.set_num_threads(self.threads)
            try:
                with nb.parallel_chunksize(1):
                    fn_par(*args)
            finally:
                nb.set_num_threads(old)
        else:
            fn_ser(*args)
        return float(self.los.min()), float(self.his.max())

    def all_actions(self, h, h_out, pol, W, mode, write, write_pol, relax, shift):
        o = self.op
        return self._run(
            self.K.all_actions_par, self.K.all_actions_ser,
            self.items, self.ip, o.tile_tc, self.tile_cfg, o.N, o.lo, o.dims, o.strides, o.off,
            o.act_ptr, o.out_ptr, o.e_prob, o.e_m, o.e_base, o.e_stride, o.q, h,
            self._dummy_h if h_out is None else h_out, pol, self._dummy_W if W is None else W, int(mode),
            int(write), bool(write_pol), float(relax), float(shift), self.mask, self.use_mask, o.max_out,
            o.max_row, self.los, self.his,
        )

    def fixed(self, h, h_out, pol, write, relax, shift):
        o = self.op
        return self._run(
            self.K.fixed_policy_par, self.K.fixed_policy_ser,
            self.items, self.ip, o.tile_tc, self.tile_cfg, o.N, o.lo, o.dims, o.strides, o.off,
            o.act_ptr, o.out_ptr, o.e_prob, o.e_m, o.e_base, o.e_stride, o.q, h,
            self._dummy_h if h_out is None else h_out, pol, int(write), float(relax), float(shift), self.mask,
            self.use_mask, o.max_out, o.max_row, self.los, self.his,
        )


def reachable_mask(system: System, layout: BoxLayout, max_passes: int = 100_000) -> np.ndarray:
    """(n,) uint8 mask of the layout states reachable from the initial configurations' boxes
    (the state set of :func:`wncs_lp.models.build`), by marking passes to a fixed point."""
    K = _kernels()
    op = _Operator.build(system, layout)
    mask = np.zeros(layout.n_states, np.uint8)
    for c in set(int(i) for i in system.automaton.initial):
        mask[layout.off[c]:layout.off[c + 1]] = 1
    passes = K.reach_all(op.N, op.lo, op.dims, op.off, op.act_ptr, op.out_ptr, op.e_m, op.e_base, op.e_stride, mask,
                         op.max_out, int(max_passes))
    if passes > max_passes:  # pragma: no cover - monotone marking settles in finitely many passes
        raise SolverError("reachability marking did not settle")
    return mask


def _resolve_domain(system: System, domain: str) -> tuple[bool, bool]:
    """(use an exact reachability mask, the hull's bracket closes)."""
    if domain not in DOMAINS:
        raise SolverError(f"unknown domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    drains = drains_to_initial(system)
    if domain == "reachable":
        return True, drains
    if domain == "hull":
        return False, drains
    return (not drains), drains


# ============================================================================ results
@dataclass(frozen=True, eq=False)
class MatrixFreeSolution(Solution):
    """A :class:`Solution` of the matrix-free solver, over a :class:`BoxLayout`.

    Differences from the stored-matrix solvers' ``Solution`` (everything else is the same:
    ``gain`` is the midpoint of the certificate ``gain_lower <= g* <= gain_upper``):

    * ``bias`` is h over the *layout* states (normalised so that the first state, tau = 1 in
      the first initial configuration, is 0);
    * ``policy`` is one ``uint8`` per layout state: the **local action index** j of the greedy
      policy of ``bias`` (first minimiser), i.e. ``system.automaton.actions[c][j]``;
    * ``layout`` and ``system`` say what the states are; ``mask`` is the exact reachable set
      when the solve used one (``domain="reachable"``), else None.

    :meth:`on_mdp` gives the ordinary pair-index ``Solution`` on an enumerated MDP;
    :class:`wncs_lp.policies.MatrixFreePolicy` wraps it as a policy.
    """

    layout: BoxLayout | None = None
    system: System | None = None
    mask: np.ndarray | None = None

    def act(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """Local action indices at R states ((R, N) AoI values, (R,) configuration ids)."""
        idx = self.layout.index(tau, config_ids)
        if np.any(idx < 0):
            r = int(np.flatnonzero(idx < 0)[0])
            raise PolicyError(f"state tau={np.asarray(tau)[r].tolist()}, configuration {int(np.asarray(config_ids)[r])} "
                              "is outside the solved layout")
        return self.policy[idx].astype(np.int64)


    def layout_index_of(self, mdp) -> np.ndarray:
        """Layout index of every state of an enumerated MDP of the same scenario."""
        self.system.check_mdp(mdp)
        idx = self.layout.index(np.asarray(mdp.states.tau, np.int64), np.asarray(mdp.states.config, np.int64))
        if np.any(idx < 0):  # pragma: no cover - the layout contains the reachable set
            raise SolverError("internal error: a state of the MDP is outside the matrix-free layout")
        return idx

    def on_mdp(self, mdp) -> Solution:
        """The same solution on an enumerated MDP: ``policy`` as pair indices, ``bias`` on its
        states (h[0] = 0), the certificate unchanged (it holds for the MDP's reachable set)."""
        idx = self.layout_index_of(mdp)
        pol = mdp.pair_ptr[:-1] + self.policy[idx].astype(np.int64)
        h = self.bias[idx]
        return Solution(method=self.method, status=self.status, gain=self.gain, gain_lower=self.gain_lower,
                        gain_upper=self.gain_upper, bias=h - h[0], policy=pol, occupation=None,
                        iterations=self.iterations, seconds=self.seconds, stats=dict(self.stats))

    def actions(self, mdp) -> np.ndarray:
        return self.on_mdp(mdp).actions(mdp)

    def save(self, path, *, bias: bool = False) -> None:
        """Store the policy (and the bias with ``bias=True``: 8 bytes a state) as ``.npz``,
        atomically, readable by others (the umask's mode); :func:`load_solution` reads it back."""
        arrays = dict(policy=self.policy, lo=self.layout.lo, dims=self.layout.dims, caps=self.layout.caps)
        if bias:
            arrays["bias"] = self.bias
        meta = dict(method=self.method, status=self.status, gain=self.gain, gain_lower=self.gain_lower,
                    gain_upper=self.gain_upper, iterations=self.iterations, seconds=self.seconds,
                    domain=self.layout.domain, fingerprint=self.system.scenario.fingerprint())
        import io

        from ..files import atomic_write_bytes

        buf = io.BytesIO()  # written whole or not at all (an interrupt leaves no half file)
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        atomic_write_bytes(path, buf.getvalue())


def load_solution(path, system_or_scenario: System | Scenario) -> MatrixFreeSolution:
    """Read a :meth:`MatrixFreeSolution.save` file back (checked against the scenario)."""
    system = _as_system(system_or_scenario)
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        if meta["fingerprint"] != system.scenario.fingerprint():
            raise PolicyError(f"{path}: saved for another scenario (fingerprint {meta['fingerprint']})")
        layout = BoxLayout.from_system(system, meta["domain"])
        if not (np.array_equal(layout.lo, z["lo"]) and np.array_equal(layout.dims, z["dims"])):
            raise PolicyError(f"{path}: the saved layout differs from this scenario's")
        bias = z["bias"] if "bias" in z.files else np.zeros(0)
        policy = z["policy"]
    return MatrixFreeSolution(method=meta["method"], status=meta["status"], gain=meta["gain"],
                              gain_lower=meta["gain_lower"], gain_upper=meta["gain_upper"], bias=bias,
                              policy=policy, iterations=meta["iterations"], seconds=meta["seconds"],
                              stats={"loaded_from": str(path)}, layout=layout, system=system)


@dataclass(frozen=True, eq=False)
class MatrixFreeEvaluation:
    """Exact (certified) average cost of a fixed policy, from :func:`matrix_free_evaluate`.

    ``gain_lower <= g_pi <= gain_upper`` for the long-run average cost g_pi of the policy from
    every state (the bracket min / max of T_pi h - h over the layout); ``gain`` is the midpoint.
    """

    policy: str
    status: str
    gain: float
    gain_lower: float
    gain_upper: float
    bias: np.ndarray
    iterations: int
    seconds: float
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def gap(self) -> float:
        return (self.gain_upper - self.gain_lower) / max(abs(self.gain), 1e-300)

    def summary(self) -> dict[str, Any]:
        out = {"policy": self.policy, "status": self.status, "gain": float(self.gain),
               "gain_lower": float(self.gain_lower), "gain_upper": float(self.gain_upper),
               "certificate_gap": float(self.gap), "iterations": int(self.iterations),
               "seconds": float(self.seconds)}
        for k, v in self.stats.items():
            if isinstance(v, (int, float, str, bool, np.integer, np.floating)) or v is None:
                out[k] = v.item() if isinstance(v, np.generic) else v
        return out


# ============================================================================ helpers
def _with_cost(op: _Operator, cost: Any) -> _Operator:
    """The operator with another separable cost table (checked: shape, finite)."""
    c = np.asarray(cost, dtype=float)
    if c.ndim != 2 or c.shape[0] != op.N or c.shape[1] < int(op.caps.max()):
        raise SolverError(f"cost must be an (N, max cap) = ({op.N}, {int(op.caps.max())}) table of per-process "
                          f"costs by AoI; got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise SolverError("cost holds a non-finite entry")
    q = np.zeros_like(op.q)
    for k in range(op.N):
        q[k, : op.caps[k]] = c[k, : op.caps[k]]
    scale = float(sum(float(np.max(np.abs(q[k]))) for k in range(op.N)))
    return replace(op, q=q, cost_scale=max(scale, 1e-300))


def cap_cost(scenario_or_system: Scenario | System) -> np.ndarray:
    """The (N, max cap) cost table sum_k [tau_k = cap_k]: its average is the expected number of
    processes at their cap, E[#{k : tau_k = cap_k}] = sum_k m_k (:mod:`wncs_lp.truncation`)."""
    caps = np.asarray(_as_system(scenario_or_system).caps, dtype=np.int64)
    c = np.zeros((caps.size, int(caps.max())))
    c[np.arange(caps.size), caps - 1] = 1.0
    return c


def matrix_free_cap_mass(scenario_or_system: Scenario | System, policy: Any, *, atol: float = 1e-7,
                         **kw: Any) -> "MatrixFreeEvaluation":
    r"""How much a policy leans on the AoI cap, certified, without a transition matrix.

    The long-run average of :math:`\sum_k [\tau_k = \hat\tau_k]`, i.e. the expected number of
    processes at their cap :math:`\sum_k m_k`, by :func:`matrix_free_evaluate` with
    :func:`cap_cost`. It brackets the mass with *some* process at its cap (the quantity of
    :func:`wncs_lp.truncation.cap_mass`, which needs the stationary law):
    :math:`\frac1N \sum_k m_k \le m \le \sum_k m_k`, so the result is an upper bound on m.
    ``atol`` is the absolute width at which the bracket counts as closed (a share of time, so
    1e-7 is ample); ``tol`` (relative, default 1e-8 here) also closes it.
    """
    kw.setdefault("tol", 1e-8)
    kw.setdefault("name", f"{getattr(policy, 'name', 'policy')}: processes at the cap")
    return matrix_free_evaluate(scenario_or_system, policy, cost=cap_cost(scenario_or_system), atol=atol, **kw)


def matrix_free_cap_masses(scenario_or_system: Scenario | System, policy: Any, *, atol: float = 1e-6,
                           **kw: Any) -> list["MatrixFreeEvaluation"]:
    r"""The time each process spends at its cap under a policy, certified: one evaluation per
    process k with the cost :math:`[\tau_k = \hat\tau_k]` (so N times the work of
    :func:`matrix_free_cap_mass`). Entry k brackets :math:`m_k`; the share of time with some
    process at its cap lies in :math:`[\max_k m_k, \min(1, \sum_k m_k)]`. ``atol`` is the
    absolute width at which each bracket counts as closed.
    """
    system = _as_system(scenario_or_system)
    base = cap_cost(system)
    kw.setdefault("tol", 1e-8)
    out = []
    for k in range(base.shape[0]):
        cost = np.zeros_like(base)
        cost[k] = base[k]
        name = f"{getattr(policy, 'name', 'policy')}: process {k + 1} at its cap"
        out.append(matrix_free_evaluate(system, policy, cost=cost, atol=atol, name=name, **kw))
    return out


def _initial_h(h0: Any, n: int) -> np.ndarray:
    """A warm start: a bias array or a matrix-free result's bias (checked by :func:`~wncs_lp.solvers.dp.initial_bias`)."""
    if isinstance(h0, (MatrixFreeSolution, MatrixFreeEvaluation)):
        h0 = h0.bias
    return initial_bias(h0, n, 0)


class _Extrapolator:
    """One-mode (Lyusternik / Aitken) extrapolation of a geometrically converging iteration.

    Near convergence the bracket width of these iterations shrinks by a steady factor lambda per
    iteration (one slow mode of the chain: e.g. 0.968 a sweep for the greedy policy of processes
    1-4 at cap 12), i.e. h_k ~ h* + a lambda^k v. Once ``runs`` successive rates agree within
    ``agree`` (relative), lambda is their value and h is moved to
    h + f (h - h_prev), f = lambda / (1 - lambda), which removes that mode; h_prev is h one
    iteration before (a second value vector, copied in the cycle that may end in an
    extrapolation). The certificate is computed on the new h at once; if its width is not below
    the one before, h is restored ((h + f h_prev) / (1 + f)) and extrapolation is switched off
    for the run. So a poor extrapolation costs one pass, never validity.
    """

    def __init__(self, n: int, enabled: bool, agree: float = 0.02, runs: int = 3, max_undo: int = 3):
        self.prev = np.empty(n) if enabled else None
        self.max_undo = max_undo
        self.agree = agree
        self.runs = runs
        self.records: list[tuple[int, float]] = []
        self.count = 0
        self.reverted = 0
        self.saved_at = -1
        self.pending: tuple[float, float] | None = None  # (f, width before) of an unchecked step

    @property
    def enabled(self) -> bool:
        return self.prev is not None

    def _rates(self, pts) -> list[float] | None:
        rates = []
        for (i0, w0), (i1, w1) in zip(pts, pts[1:]):
            if not (w1 < w0) or i1 <= i0:
                return None
            rates.append(np.log(w1 / w0) / (i1 - i0))
        return rates

    def _steady(self, rates) -> bool:
        r = rates[-1]
        return max(abs(x - r) for x in rates) <= self.agree * abs(r)

    def want_save(self) -> bool:
        """Whether the coming check may extrapolate (the rates so far are steady), so h must be
        copied before the last iteration of this cycle."""
        if not self.enabled or self.pending is not None or len(self.records) < self.runs:
            return False
        rates = self._rates(self.records[-self.runs:])
        return rates is not None and (len(rates) == 0 or self._steady(rates))

    def save(self, h: np.ndarray, iters: int) -> None:
        np.copyto(self.prev, h)
        self.saved_at = iters

    def _axpy(self, h: np.ndarray, f: float, undo: bool) -> None:
        step = 1 << 20
        for a in range(0, h.size, step):
            hb = h[a:a + step]
            pb = self.prev[a:a + step]
            if undo:  # h_k = (h + f h_prev) / (1 + f)
                hb += f * pb
                hb /= 1.0 + f
            else:  # h + f (h - h_prev)
                hb *= 1.0 + f
                hb -= f * pb

    def settle(self, h: np.ndarray) -> None:
        """At the end of a run: undo an extrapolation that no pass has certified yet, so that h
        is the iterate of the last certificate."""
        if self.pending is not None:
            self._axpy(h, self.pending[0], undo=True)
            self.pending = None
        self.prev = None

    def step(self, h: np.ndarray, iters: int, width: float) -> str | None:
        """Record the width after ``iters`` iterations; check a pending extrapolation or make
        one. Returns a message for the progress line, or None."""
        if not self.enabled or not np.isfinite(width) or width <= 0:
            return None
        if self.pending is not None:
            f, before = self.pending
            self.pending = None
            if width < before:
                self.records = [(iters, width)]
                return f"extrapolation kept (width {before:.3g} -> {width:.3g})"
            self._axpy(h, f, undo=True)
            self.reverted += 1
            self.records = []
            if self.reverted >= self.max_undo:
                self.prev = None
                return f"extrapolation undone (width {before:.3g} -> {width:.3g}); no more for this run"
            self.runs *= 2  # wait for a longer steady stretch before the next try
            return f"extrapolation undone (width {before:.3g} -> {width:.3g})"
        self.records.append((iters, width))
        if len(self.records) < self.runs + 1 or self.saved_at != iters - 1:
            return None
        rates = self._rates(self.records[-(self.runs + 1):])
        if rates is None or not self._steady(rates):
            return None
        lam = float(np.exp(rates[-1]))
        if not (0.0 < lam < 0.9999):
            return None
        f = lam / (1.0 - lam)
        self._axpy(h, f, undo=False)
        self.pending = (f, width)
        self.count += 1
        return f"extrapolated (rate {lam:.4f} an iteration)"


def _second_vector_fits(n: int) -> bool:
    """Whether a second value vector (the Jacobi fallback's) fits in the memory available now."""
    from ..models.guard import available_memory

    return 8 * n * 1.25 <= available_memory()


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, file=sys.stderr, flush=True)


def _mb(nbytes: float) -> str:
    return f"{nbytes / 2**20:,.0f} MiB"


# ============================================================================ the solver
def matrix_free_value_iteration(
    scenario_or_system: Scenario | System,
    *,
    tol: float = VI_TOL,
    atol: float = 0.0,
    max_iter: int = 100_000,
    scheme: str = "auto",
    relax: float = 0.8,
    eval_sweeps: int = 1,
    check_every: int = 5,
    h0: Any = None,
    threads: int | None = None,
    domain: str = "auto",
    stall_checks: int = 40,
    progress: bool = False,
    on_interrupt: str = "return",
    tile_order: str = "forward",
    extrapolate: bool = True,
    warm_start: bool = False,
    warm_rel: float = 0.05,
    warm_max: int = 100,
    force: bool = False,
) -> MatrixFreeSolution:
    """Certified average-cost value iteration without a transition matrix.

    The iteration is that of :func:`wncs_lp.solvers.dp.value_iteration` (modified policy
    iteration: relaxed Gauss-Seidel improvement sweeps, ``eval_sweeps`` sweeps of the policy
    they found, and every ``check_every`` improvement sweeps a certificate pass), on the
    matrix-free kernels. The certificate pass computes d = T h - h over **every** state of the
    layout (or of the exact reachable set, see ``domain``) on one fixed h and stops when
    ``hi - lo <= tol |(lo + hi)/2|`` (or ``<= atol``). It writes nothing but the greedy policy
    of that h, so the returned ``bias`` is exactly the h of the certificate and the returned
    policy its greedy policy (whose gain is <= ``gain_upper``).

    Parameters
    ----------
    scenario_or_system : Scenario or System
    tol, atol : float
        Relative (default 1e-9) and absolute certificate widths.
    max_iter : int
        Budget of improvement + certificate sweeps (evaluation sweeps not counted).
    scheme : {"auto", "mpi", "gs", "jacobi"}
        ``"auto"`` = ``"mpi"``; ``"jacobi"`` is relative value iteration with the aperiodicity
        transform (tau = 0.5), which needs a second value vector.
    relax : float
        Relaxation of the in-place sweeps, in (0, 1].
    eval_sweeps, check_every : int
    h0 : array or MatrixFreeSolution, optional
        Warm start, one value per layout state.
    threads : int, optional
        numba threads (default 1: numba's OpenMP layer does not survive a fork). With 2 or
        more, configurations are swept in parallel; the in-place sweeps are then asynchronous
        (iterates depend on timing; the certificate does not).
    domain : {"auto", "hull", "reachable"}
        Over which states the certificate is taken (module docstring): the interval hull
        (valid always, closes when :func:`drains_to_initial`), or the exact reachable set
        (a byte mask; ``"auto"`` uses it only when the hull's bracket might not close).
    stall_checks : int
        Switch to the Jacobi scheme when the width has not halved in this many checks.
    progress : bool
        One line on stderr per certificate pass (sweeps, bracket, relative width, time).
    on_interrupt : {"return", "raise"}
        On KeyboardInterrupt: certify the current h with one more pass and return it with
        status ``"interrupted"`` (default), or re-raise.
    tile_order : {"forward", "reverse"}
        Order of the in-place sweeps over the AoI tiles (forward, the default, needed 1.5x
        fewer sweeps than reverse on processes 1-4).
    extrapolate : bool
        One-mode extrapolation of the bias when the bracket shrinks at a steady rate
        (:class:`_Extrapolator`; needs a second value vector, used only if it fits in memory).
    force : bool
        Skip the size guard (:func:`wncs_lp.models.guard.check_size` with
        ``method="matrix-free"``, which refuses a layout whose vectors would not fit).

    Returns
    -------
    MatrixFreeSolution
        ``method = "matrix-free"``; ``stats``: ``scheme``, ``threads``, ``domain``,
        ``n_states`` (layout), ``n_reachable`` (with a mask), ``sweeps``, ``eval_sweeps``,
        ``checks``, ``rel_gap``, ``bytes`` (the solve's arrays), ``seconds_setup``,
        ``fallback``, ``hull_closes`` and ``history``: one ``(sweeps, eval_sweeps, seconds, lo, hi)``
        per certificate pass.
    """
    t0 = time.perf_counter()
    if scheme not in SCHEMES:
        raise SolverError(f"unknown matrix-free scheme {scheme!r}; expected one of {', '.join(SCHEMES)}")
    if not (0.0 < relax <= 1.0):
        raise SolverError(f"relax must be in (0, 1], got {relax}")
    if max_iter < 1 or check_every < 1 or eval_sweeps < 0:
        raise SolverError("max_iter and check_every must be >= 1 and eval_sweeps >= 0")
    if on_interrupt not in ("return", "raise"):
        raise SolverError(f"on_interrupt must be 'return' or 'raise', got {on_interrupt!r}")
    _kernels()
    system = _as_system(scenario_or_system)
    if not force:
        from ..models.guard import check_size

        check_size(system.scenario, method="matrix-free", model=system.model)
    use_mask, closes = _resolve_domain(system, domain)
    layout = BoxLayout.from_system(system, "hull")
    op = _Operator.build(system, layout)
    n = layout.n_states
    mask = reachable_mask(system, layout) if use_mask else None
    sw = _Sweeper(op, threads, mask, reverse=tile_order == "reverse")
    h = _initial_h(h0, n)
    pol = np.zeros(n, np.uint8)
    if int(system.n_actions.max()) > 255:  # pragma: no cover - the paper's models have <= 12
        raise SolverError("more than 255 actions in a configuration: the uint8 policy cannot hold them")
    if scheme == "auto":
        scheme = "mpi"
    cur = scheme
    h_out = np.empty(n) if cur == "jacobi" else None
    n_eval = eval_sweeps if scheme == "mpi" else 0
    t_setup = time.perf_counter() - t0
    _say(progress, f"[matrix-free] {n:,} states over {layout.n_configs} configurations"
         + (f" ({int(mask.sum()):,} reachable)" if mask is not None else "")
         + f", {_mb(matrix_free_bytes(n, vectors=2 if h_out is not None else 1, mask=mask is not None))}, "
         f"{sw.threads} thread(s), setup {t_setup:.2f}s")
    used = evals = checks = iters = 0
    shift = 0.0
    lo = hi = np.nan
    converged = False
    fallback = None
    interrupted = False
    history: list[tuple] = []
    ex = _Extrapolator(n, extrapolate and scheme != "jacobi" and _second_vector_fits(n))
    vectors = 1 + (h_out is not None) + ex.enabled
    _say(progress, f"[matrix-free] {_mb(matrix_free_bytes(n, vectors=vectors, mask=mask is not None))} "
         f"with {vectors} value vector(s)")
    best_w, best_at = np.inf, 0
    tau_j = 0.5
    first = True
    warm = warm_start and ex.enabled
    try:
        while used < max_iter:
            if warm:
                # Jacobi sweeps until the bracket is within warm_rel (see matrix_free_evaluate)
                lo, hi = sw.all_actions(h, ex.prev, pol, None, 0, 2, True, tau_j, shift)
                used += 1
                checks += 1
                ex.prev -= ex.prev[0]
                h, ex.prev = ex.prev, h
                width, mid = hi - lo, 0.5 * (lo + hi)
                history.append((used, evals, time.perf_counter() - t0, lo, hi))
                shift = mid
                if width <= warm_rel * abs(mid) or used >= warm_max or used >= max_iter - 1:
                    warm = False
                    first = True
                    _say(progress, f"[matrix-free:jacobi] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                         f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s (warm start)")
                continue
            if cur != "jacobi" and not first:
                todo = min(check_every, max(max_iter - used - 1, 0))
                for i in range(todo):
                    if i == todo - 1 and ex.want_save():
                        ex.save(h, iters)
                    sw.all_actions(h, None, pol, None, 0, 1, n_eval > 0, relax, shift)
                    used += 1
                    iters += 1
                    for _ in range(n_eval):
                        sw.fixed(h, None, pol, 1, relax, shift)
                        evals += 1
            first = False
            if cur == "jacobi":
                lo, hi = sw.all_actions(h, h_out, pol, None, 0, 2, True, tau_j, shift)
            else:
                lo, hi = sw.all_actions(h, None, pol, None, 0, 0, True, relax, shift)
            used += 1
            checks += 1
            width = hi - lo
            mid = 0.5 * (lo + hi)
            history.append((used, evals, time.perf_counter() - t0, lo, hi))
            _say(progress, f"[matrix-free:{cur}] sweeps={used} evals={evals} lo={lo:.12g} hi={hi:.12g} "
                 f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s")
            if width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale):
                converged = True
                break
            if cur != "jacobi":
                note = ex.step(h, iters, width)
                if note is not None:
                    _say(progress, f"[matrix-free] {note}")
                if ex.pending is not None or (note is not None and "undone" in note):
                    first = True  # certify the moved h before sweeping on
                    continue
            if width < 0.5 * best_w:
                best_w, best_at = width, checks
            elif cur != "jacobi" and checks - best_at >= stall_checks:
                fallback = f"{cur} stalled at relative width {width / max(abs(mid), 1e-300):.3g} after {used} sweeps"
                best_at = checks
                if _second_vector_fits(n):
                    cur = "jacobi"
                    h_out = np.empty(n)
                    vectors += 1
                    continue
                fallback += " (no memory for the Jacobi fallback's second vector: continuing)"
            shift = mid
            if cur == "jacobi" and used < max_iter:  # the budget's last pass keeps its (certified) h
                h_out -= h_out[0]
                h, h_out = h_out, h
    except KeyboardInterrupt:
        if on_interrupt == "raise":
            raise
        interrupted = True
        _say(progress, "[matrix-free] interrupted: certifying the current iterate")
        ex.pending = None
        lo, hi = sw.all_actions(h, None, pol, None, 0, 0, True, relax, shift)
        checks += 1
        converged = width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale)
    ex.settle(h)
    h -= h[0]
    gain = 0.5 * (lo + hi)
    status = "optimal" if converged else ("interrupted" if interrupted else "max_iter")
    stats = {
        "scheme": scheme,
        "final_scheme": cur,
        "threads": sw.threads,
        "domain": "reachable" if mask is not None else "hull",
        "hull_closes": closes,
        "n_states": n,
        "n_reachable": int(mask.sum()) if mask is not None else None,
        "n_configs": layout.n_configs,
        "sweeps": used,
        "eval_sweeps": evals,
        "checks": checks,
        "relax": relax,
        "tol": tol,
        "span": hi - lo,
        "rel_gap": (hi - lo) / max(abs(gain), 1e-300),
        "converged": converged,
        "bytes": matrix_free_bytes(n, vectors=vectors, mask=mask is not None),
        "value_vectors": vectors,
        "seconds_setup": t_setup,
        "fallback": fallback,
        "history": history,
        "extrapolations": ex.count,
        "extrapolations_undone": ex.reverted,
    }
    return MatrixFreeSolution(method="matrix-free", status=status, gain=gain, gain_lower=lo, gain_upper=hi,
                              bias=h, policy=pol, occupation=None, iterations=used,
                              seconds=time.perf_counter() - t0, stats=stats, layout=layout, system=system,
                              mask=mask)


# ============================================================================ evaluation
def policy_table(system: System, layout: BoxLayout, policy: Any, *, batch: int = 1 << 21) -> np.ndarray:
    """(n,) uint8 local action of a deterministic ``policy`` at every layout state (``policy.act``
    called on batches of whole configurations)."""
    n = layout.n_states
    out = np.empty(n, np.uint8)
    nact = system.n_actions
    rng = np.random.default_rng(0)
    c = 0
    nC = layout.n_configs
    while c < nC:
        c1 = c + 1
        while c1 < nC and layout.off[c1 + 1] - layout.off[c] <= batch:
            c1 += 1
        taus = np.concatenate([layout.config_taus(i) for i in range(c, c1)])
        cfg = np.repeat(np.arange(c, c1, dtype=np.int64), np.diff(layout.off[c:c1 + 1]))
        j = np.asarray(policy.act(taus, cfg, rng), dtype=np.int64)
        if j.shape != cfg.shape or np.any(j < 0) or np.any(j >= nact[cfg]):
            raise PolicyError(f"policy {getattr(policy, 'name', policy)!r}: a local action index is out of range")
        out[layout.off[c]:layout.off[c1]] = j
        c = c1
    return out


def matrix_free_evaluate(
    scenario_or_system: Scenario | System,
    policy: Any,
    *,
    tol: float = VI_TOL,
    atol: float = 0.0,
    max_iter: int = 100_000,
    relax: float = 0.8,
    check_every: int = 5,
    h0: Any = None,
    threads: int | None = None,
    domain: str = "auto",
    stall_checks: int = 40,
    progress: bool = False,
    on_interrupt: str = "return",
    name: str | None = None,
    extrapolate: bool = True,
    warm_start: bool = True,
    warm_rel: float = 0.05,
    warm_max: int = 100,
    cost: Any = None,
) -> MatrixFreeEvaluation:
    """Exact average cost of a stationary policy, certified, without a transition matrix.

    Relaxed Gauss-Seidel sweeps of the fixed-policy operator
    (T_pi h)(s) = c(s) + sum_{s'} P_pi(s' | s) h(s'), and every ``check_every`` sweeps a pass
    computing ``lo = min (T_pi h - h) <= g_pi <= max (T_pi h - h) = hi`` on one fixed h over
    every layout state (or the exact reachable set, as in :func:`matrix_free_value_iteration`).
    If the width stalls, Jacobi sweeps with the aperiodicity transform take over.

    Parameters
    ----------
    policy : Policy, MatrixFreeSolution or array
        A deterministic :class:`~wncs_lp.policies.Policy` (``act`` is called once on every
        layout state), a tau-independent randomised one (anything with a ``probs`` table of
        action probabilities per configuration, e.g. the random policy: evaluated with those
        weights), a :class:`MatrixFreeSolution` (its policy), or an (n,) array of local
        action indices over the layout.
    cost : array, optional
        A separable per-slot cost c(s) = sum_k cost[k, tau_k - 1] instead of the MSE: an
        (N, max cap) table (entries past a process's cap are ignored). With
        :func:`cap_cost` it measures the time spent at the cap (:func:`matrix_free_cap_mass`).
    Other parameters as in :func:`matrix_free_value_iteration`.

    Returns
    -------
    MatrixFreeEvaluation
    """
    t0 = time.perf_counter()
    if not (0.0 < relax <= 1.0):
        raise SolverError(f"relax must be in (0, 1], got {relax}")
    if on_interrupt not in ("return", "raise"):
        raise SolverError(f"on_interrupt must be 'return' or 'raise', got {on_interrupt!r}")
    _kernels()
    system = getattr(policy, "system", None)
    if not isinstance(system, System):
        system = _as_system(scenario_or_system)
    use_mask, closes = _resolve_domain(system, domain)
    layout = BoxLayout.from_system(system, "hull")
    n = layout.n_states
    W = None
    table = None
    if isinstance(policy, MatrixFreeSolution):
        table = policy.policy
        pname = name or "optimal"
    elif hasattr(policy, "table") and hasattr(policy, "layout"):  # a wncs_lp.policies.MatrixFreePolicy
        table = policy.table
        pname = name or policy.name
    elif hasattr(policy, "act"):  # any wncs_lp.policies.Policy (duck-typed: solvers sit below policies)
        pname = name or policy.name
        probs = getattr(policy, "probs", None)
        if probs is not None:
            W = np.ascontiguousarray(probs, dtype=float)
        elif policy.randomised:
            raise PolicyError(f"policy {pname}: matrix-free evaluation takes a deterministic policy or a "
                              "tau-independent randomised one (a probs table)")
        else:
            table = policy_table(system, layout, policy)
    else:
        pname = name or "array"
        table = np.asarray(policy)
        if table.shape != (n,) or not np.issubdtype(table.dtype, np.integer):
            raise PolicyError(f"a policy array must hold one local action index per layout state ({n})")
        cfg = np.repeat(np.arange(layout.n_configs), np.diff(layout.off))
        if np.any(table < 0) or np.any(table >= system.n_actions[cfg]):
            raise PolicyError("a local action index is out of range")
        table = table.astype(np.uint8)
    if table is not None and table.shape != (n,):
        raise PolicyError(f"the policy's table has {table.shape[0]} states, the layout {n}")
    op = _Operator.build(system, layout)
    if cost is not None:
        op = _with_cost(op, cost)
    mask = reachable_mask(system, layout) if use_mask else None
    sw = _Sweeper(op, threads, mask)
    h = _initial_h(h0, n)
    t_setup = time.perf_counter() - t0
    _say(progress, f"[matrix-free eval {pname}] {n:,} states, setup (policy table) {t_setup:.2f}s")

    def sweep(h_, h_out_, write, rx, shift_):
        if table is None:
            return sw.all_actions(h_, h_out_, np.zeros(1, np.uint8), W, 1, write, False, rx, shift_)
        return sw.fixed(h_, h_out_, table, write, rx, shift_)

    used = checks = iters = 0
    shift = 0.0
    lo = hi = np.nan
    converged = interrupted = False
    history: list[tuple] = []
    ex = _Extrapolator(n, extrapolate and _second_vector_fits(n))
    cur = "gs"
    fallback = None
    h_out = None
    best_w, best_at = np.inf, 0
    first = True
    warm = warm_start and ex.enabled
    try:
        while used < max_iter:
            if warm:
                # Jacobi sweeps (tau = 0.5) until the bracket is within warm_rel: their bounds
                # are monotone and a wrong shift only adds a constant, whereas in-place sweeps
                # started with the wide first bracket's midpoint as the gain distort h for
                # hundreds of sweeps (suboptimal policy, cap 12: 212 -> 173 sweeps)
                lo, hi = sweep(h, ex.prev, 2, 0.5, shift)
                used += 1
                checks += 1
                ex.prev -= ex.prev[0]
                h, ex.prev = ex.prev, h
                width, mid = hi - lo, 0.5 * (lo + hi)
                history.append((used, 0, time.perf_counter() - t0, lo, hi))
                shift = mid
                if width <= warm_rel * abs(mid) or used >= warm_max or used >= max_iter - 1:
                    warm = False
                    first = True
                    _say(progress, f"[matrix-free eval {pname}:jacobi] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                         f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s (warm start)")
                continue
            if cur == "gs" and not first:
                todo = min(check_every, max(max_iter - used - 1, 0))
                for i in range(todo):
                    if i == todo - 1 and ex.want_save():
                        ex.save(h, iters)
                    sweep(h, None, 1, relax, shift)
                    used += 1
                    iters += 1
            first = False
            if cur == "jacobi":
                lo, hi = sweep(h, h_out, 2, 0.5, shift)
            else:
                lo, hi = sweep(h, None, 0, relax, shift)
            used += 1
            checks += 1
            width = hi - lo
            mid = 0.5 * (lo + hi)
            history.append((used, 0, time.perf_counter() - t0, lo, hi))
            _say(progress, f"[matrix-free eval {pname}:{cur}] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                 f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s")
            if width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale):
                converged = True
                break
            if cur == "gs":
                note = ex.step(h, iters, width)
                if note is not None:
                    _say(progress, f"[matrix-free eval {pname}] {note}")
                if ex.pending is not None:
                    first = True  # certify the extrapolated h before sweeping on
                    continue
                if note is not None and "undone" in note:
                    first = True
                    continue
            if width < 0.5 * best_w:
                best_w, best_at = width, checks
            elif cur == "gs" and checks - best_at >= stall_checks:
                fallback = f"gs stalled at relative width {width / max(abs(mid), 1e-300):.3g} after {used} sweeps"
                best_at = checks
                if _second_vector_fits(n):
                    cur = "jacobi"
                    h_out = np.empty(n)
                    continue
                fallback += " (no memory for the Jacobi fallback's second vector: continuing)"
            shift = mid
            if cur == "jacobi" and used < max_iter:  # the budget's last pass keeps its (certified) h
                h_out -= h_out[0]
                h, h_out = h_out, h
    except KeyboardInterrupt:
        if on_interrupt == "raise":
            raise
        interrupted = True
        ex.pending = None
        lo, hi = sweep(h, None, 0, relax, shift)
        converged = width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale)
    ex.settle(h)
    h -= h[0]
    gain = 0.5 * (lo + hi)
    stats = {"threads": sw.threads, "domain": "reachable" if mask is not None else "hull", "hull_closes": closes,
             "n_states": n, "checks": checks, "relax": relax, "tol": tol, "rel_gap": (hi - lo) / max(abs(gain), 1e-300),
             "converged": converged, "seconds_setup": t_setup, "fallback": fallback,
             "randomised": W is not None, "history": history, "extrapolations": ex.count,
             "extrapolations_undone": ex.reverted}
    return MatrixFreeEvaluation(policy=pname,
                                status="optimal" if converged else ("interrupted" if interrupted else "max_iter"),
                                gain=gain, gain_lower=lo, gain_upper=hi, bias=h, iterations=used,
                                seconds=time.perf_counter() - t0, stats=stats)


# ============================================================================ entry points
def solve_scenario(scenario: Scenario, method: str = "matrix-free", *, force: bool = False, **kw: Any) -> Solution:
    """Solve a scenario by name of method: ``"matrix-free"`` runs
    :func:`matrix_free_value_iteration` (no MDP is built); any other method builds the MDP
    after the size guard and calls :func:`wncs_lp.solvers.solve`."""
    if method == "matrix-free":
        return matrix_free_value_iteration(scenario, **kw)
    from ..models.guard import build_checked
    from . import solve

    return solve(build_checked(scenario, force=force), method, **kw)


def solve_mdp(mdp, **kw: Any) -> Solution:
    """``solve(mdp, "matrix-free")``: the matrix-free solve of the MDP's scenario, returned on
    the MDP (pair-index policy, bias on its states; :meth:`MatrixFreeSolution.on_mdp`)."""
    model = getattr(getattr(mdp, "states", None), "model", None)
    scenario = getattr(model, "scenario", None)
    if scenario is None:
        raise SolverError("method 'matrix-free' needs an MDP built from a scenario (mdp.states.model.scenario); "
                          "this one has none")
    system = System.from_automaton(scenario, model.automaton, model)
    sol = matrix_free_value_iteration(system, **kw)
    out = sol.on_mdp(mdp)
    return replace(out, stats={**out.stats, "n_mdp_states": mdp.n_states})

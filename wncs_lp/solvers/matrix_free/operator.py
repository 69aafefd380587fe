"""The operator tables a matrix-free sweep reads: per outcome of the configuration automaton,
its probability, the saturation of each AoI axis and the base / strides of its successor's
sub-box (:class:`Operator`); the tiles a sweep visits and their split into work items for the
threads (:func:`work_items`)."""
from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Any

import numpy as np

from ...errors import SolverError
from ...models.system import System
from .layout import BoxLayout, saturation

__all__ = ["Operator", "Reduce", "Write", "tiles", "work_items", "with_cost", "check_costs"]


class Reduce(IntEnum):
    """How a kernel combines the actions of a state (its ``mode``)."""

    #: the minimum over actions (the Bellman operator T), its first minimiser kept
    MIN = 0
    #: the sum weighted by the per-configuration action probabilities ``W[c, j]`` (a
    #: tau-independent randomised policy)
    WEIGHTED = 1


class Write(IntEnum):
    """What a kernel pass writes (its ``write``)."""

    #: nothing: only min / max of (T h - h), a certificate on a fixed h
    NONE = 0
    #: h in place, Gauss-Seidel: ``h += relax (T h - h - shift)``
    IN_PLACE = 1
    #: the next iterate into ``h_out`` (Jacobi): ``h_out = h + relax (T h - h - shift)``
    OUT = 2


@dataclass(frozen=True, eq=False)
class Operator:
    """The flat arrays the kernels read (see :mod:`.kernels`)."""

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
    def build(cls, system: System, layout: BoxLayout) -> "Operator":
        N = layout.n_processes
        caps = layout.caps
        flat = system.automaton.flat(N)
        nxt = flat.out_nxt.astype(np.int64)
        if flat.deltas.shape[0]:
            e_m = saturation(flat.deltas, caps)[flat.out_delta]
        else:
            e_m = np.tile(caps - 1, (nxt.size, 1))
        e_stride = layout.strides[nxt]
        e_base = layout.off[nxt] - np.einsum("ek,ek->e", e_stride, layout.lo[nxt])
        qmax = int(caps.max())
        q = np.zeros((N, qmax))
        for k in range(N):
            q[k, : caps[k]] = system.q[k]
        scale = check_costs(q, caps, [p.name for p in system.scenario.processes])
        tile_tc, tile_ptr, tile_cfg = tiles(layout)
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

    @property
    def roundoff_terms(self) -> int:
        """The most floating-point operations behind one (T h - h)(s) after its first term: the
        outcomes of a configuration (every action's, for a weighted sum), the N cost terms and the
        final subtraction (the m of Higham's gamma_m, :class:`wncs_lp.solvers.dp.RoundoffBound`)."""
        return self.max_out + self.N + 2


def tiles(layout: BoxLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def work_items(op: Operator, nchunk: int, reverse: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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



def with_cost(op: Operator, cost: Any) -> Operator:
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
    scale = check_costs(q, op.caps, [f"row {k}" for k in range(op.N)])
    return replace(op, q=q, cost_scale=max(scale, 1e-300))


def check_costs(q: np.ndarray, caps: np.ndarray, names: list[str]) -> float:
    """The cost scale sum_k max_tau |q_k(tau)| (the largest cost of a slot), after checking that every
    cost and that sum are finite: a SolverError naming the process and the AoI where a cost overflows."""
    for k, name in enumerate(names):
        row = q[k, : int(caps[k])]
        bad = np.flatnonzero(~np.isfinite(row))
        if bad.size:
            raise SolverError(f"process {name!r}: its cost q(tau) overflows float64 from tau = {int(bad[0]) + 1} on "
                              f"(tau_cap {int(caps[k])}); lower the cap or rescale the process (A, weight)")
    scale = float(sum(float(np.max(np.abs(q[k, : int(caps[k])]))) for k in range(len(names))))
    if not np.isfinite(scale):
        raise SolverError(f"the largest cost of a slot, sum_k max q_k = {scale}, overflows float64; lower the caps "
                          "or rescale the processes")
    return scale


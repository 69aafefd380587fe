"""Calls of the numba kernels (:mod:`.kernels`): the serial or threaded driver, its reductions, and
the reachability marking (:func:`reachable_mask`)."""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from ...errors import SolverError
from ...models.system import System
from ..threads import resolve_threads, run_twins
from .layout import BoxLayout
from .operator import Operator, Reduce, Write, work_items

__all__ = ["Sweeper", "load_kernels", "reachable_mask"]


def load_kernels() -> Any:
    """The numba kernels (:mod:`.kernels`); a SolverError when numba is missing or disabled."""
    if os.environ.get("WNCS_LP_NO_NUMBA"):
        raise SolverError("the matrix-free solver needs numba, disabled here by WNCS_LP_NO_NUMBA")
    try:
        from . import kernels as K
    except ImportError as exc:  # pragma: no cover - numba is a core dependency
        raise SolverError(
            f"the matrix-free solver needs numba, a dependency of wncs_lp that did not import here "
            f"(pip install 'numba>=0.58'): {exc}"
        ) from None
    return K


class Sweeper:
    """One kind of pass over the layout, on the serial or the threaded kernel.

    ``threads`` as :func:`wncs_lp.solvers.threads.resolve_threads` (default: the usable cores
    from :data:`~wncs_lp.solvers.threads.PARALLEL_MIN_STATES` states on, else one; explicit
    counts are kept). The chunks of a threaded pass are contiguous ranges of tiles
    (:func:`.operator.work_items`).
    """

    def __init__(self, op: Operator, threads: int | None, mask: np.ndarray | None, reverse: bool = False):
        self.K = load_kernels()
        self.op = op
        self.threads = resolve_threads(threads, int(op.off[-1]))
        self.nchunk = self.threads
        self.items, self.ip, self.tile_cfg = work_items(op, self.nchunk, reverse)
        self.los = np.empty(self.nchunk)
        self.his = np.empty(self.nchunk)
        self.mask = mask if mask is not None else np.zeros(1, np.uint8)
        self.use_mask = mask is not None
        self._dummy_h = np.zeros(1)
        self._dummy_W = np.zeros((1, 1))
        self._no_cand = np.zeros(1, np.uint64)
        N = op.N
        #: global index of each configuration's first row (a row: the last AoI axis of its box)
        self.row_off = np.r_[0, np.cumsum(np.diff(op.off) // op.dims[:, N - 1])].astype(np.int64)

    def _run(self, fn_par, fn_ser, *args) -> tuple[float, float]:
        run_twins(fn_par, fn_ser, self.threads, *args, chunksize=1)
        return float(self.los.min()), float(self.his.max())

    def value_range(self, h: np.ndarray) -> tuple[float, float]:
        """(min, max) of ``h`` (NaN if an entry is), in one pass on the sweeps' threads."""
        return self._run(self.K.value_range, self.K.value_range_serial, h, self.nchunk, self.los, self.his)

    def all_actions(self, h: np.ndarray, h_out: np.ndarray | None, pol: np.ndarray, W: np.ndarray | None,
                    reduce: Reduce, write: Write, write_pol: bool, relax: float, shift: float,
                    cand: np.ndarray | None = None, cand_rows: bool = False, near: float = -1.0,
                    nbits: np.ndarray | None = None) -> tuple[float, float]:
        """A pass of every action: the Bellman operator (``Reduce.MIN``, its minimiser into ``pol``
        with ``write_pol``) or the weights ``W`` (``Reduce.WEIGHTED``); returns min / max of T h - h
        (``(inf, -inf)`` for an in-place pass, which computes no bracket). With ``cand`` (one uint64
        bit set of actions per configuration, :meth:`used_actions`; with ``cand_rows`` one per row,
        :meth:`row_actions`) only those actions are tried: for in-place improvement sweeps only,
        never for a pass whose bracket is a certificate."""
        if cand is not None and write != Write.IN_PLACE:
            raise SolverError("candidate actions are for in-place improvement sweeps only (a certificate tries all)")
        K = self.K
        use = K.CAND_NONE if cand is None else K.CAND_ROW if cand_rows else K.CAND_CONFIG
        if near >= 0 and (write == Write.IN_PLACE or reduce != Reduce.MIN or nbits is None
                          or nbits.size != self.n_rows):
            raise SolverError("near-minimal actions: a certificate pass of the minimum, one bit set a row")
        if cand is not None and cand.size != (self.n_rows if cand_rows else self.op.off.size - 1):
            raise SolverError("candidate bit sets: one per row (cand_rows) or one per configuration")
        o = self.op
        return self._run(
            self.K.all_actions, self.K.all_actions_serial,
            self.items, self.ip, o.tile_tc, self.tile_cfg, o.N, o.lo, o.dims, o.strides, o.off,
            o.act_ptr, o.out_ptr, o.e_prob, o.e_m, o.e_base, o.e_stride, o.q, h,
            self._dummy_h if h_out is None else h_out, pol, self._dummy_W if W is None else W, int(reduce),
            int(write), bool(write_pol), float(relax), float(shift), self.mask, self.use_mask,
            self._no_cand if cand is None else cand, use, self.row_off, float(near),
            self._no_cand if nbits is None else nbits, o.max_out, o.max_row, self.los, self.his,
        )

    def used_actions(self, pol: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """Into ``cand`` (uint64, one per configuration): the bit set of the actions ``pol`` takes
        somewhere in the configuration's box (actions past 63 as bit 63)."""
        run_twins(self.K.used_actions, self.K.used_actions_serial, self.threads, pol, self.op.off, cand)
        return cand

    @property
    def n_rows(self) -> int:
        """Rows of the layout (the last AoI axis of each configuration's box)."""
        return int(self.row_off[-1])

    def row_actions(self, pol: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """Into ``cand`` (uint64, one per row, :attr:`n_rows`): the bit set of the actions ``pol``
        takes on the row (actions past 63 as bit 63)."""
        o = self.op
        run_twins(self.K.row_actions, self.K.row_actions_serial, self.threads, pol, o.off, o.dims, self.row_off, cand)
        return cand

    def fixed(self, h: np.ndarray, h_out: np.ndarray | None, pol: np.ndarray, write: Write, relax: float,
              shift: float) -> tuple[float, float]:
        """A pass of the fixed policy ``pol`` (one local action per state); min / max of T_pol h - h
        (``(inf, -inf)`` in place)."""
        o = self.op
        return self._run(
            self.K.fixed_policy, self.K.fixed_policy_serial,
            self.items, self.ip, o.tile_tc, self.tile_cfg, o.N, o.lo, o.dims, o.strides, o.off,
            o.act_ptr, o.out_ptr, o.e_prob, o.e_m, o.e_base, o.e_stride, o.q, h,
            self._dummy_h if h_out is None else h_out, pol, int(write), float(relax), float(shift), self.mask,
            self.use_mask, o.max_out, o.max_row, self.los, self.his,
        )


def reachable_mask(system: System, layout: BoxLayout, max_passes: int = 100_000) -> np.ndarray:
    """(n,) uint8 mask of the layout states reachable from the initial configurations' boxes
    (the state set of :func:`wncs_lp.models.build`), by marking passes to a fixed point."""
    K = load_kernels()
    op = Operator.build(system, layout)
    mask = np.zeros(layout.n_states, np.uint8)
    for c in set(int(i) for i in system.automaton.initial):
        mask[layout.off[c]:layout.off[c + 1]] = 1
    passes = K.reach_all(op.N, op.lo, op.dims, op.off, op.act_ptr, op.out_ptr, op.e_m, op.e_base, op.e_stride, mask,
                         op.max_out, int(max_passes))
    if passes > max_passes:  # pragma: no cover - monotone marking settles in finitely many passes
        raise SolverError("reachability marking did not settle")
    return mask

"""Calls of the numba kernels (:mod:`.kernels`): the serial or threaded driver, its reductions, and
the reachability marking (:func:`reachable_mask`)."""
from __future__ import annotations

import os

import numpy as np

from ...errors import SolverError
from ...models.system import System
from .layout import BoxLayout
from .operator import Operator, work_items

__all__ = ["Sweeper", "load_kernels", "reachable_mask", "PARALLEL_MIN_STATES"]

#: Below this many layout states the solvers use one thread whatever ``threads`` says.
PARALLEL_MIN_STATES = 1_000_000


def load_kernels():
    if os.environ.get("WNCS_LP_NO_NUMBA"):
        raise SolverError("the matrix-free solver needs numba, disabled here by WNCS_LP_NO_NUMBA")
    try:
        from . import kernels as K
    except ImportError as exc:  # pragma: no cover - numba is installed in the test environment
        raise SolverError(
            f"the matrix-free solver needs numba (pip install 'wncs_lp[fast]'): {exc}"
        ) from None
    return K



class Sweeper:
    """Calls the kernels with the right driver (serial or numba threads) and reductions."""

    def __init__(self, op: Operator, threads: int | None, mask: np.ndarray | None, reverse: bool = False):
        self.K = load_kernels()
        import numba

        self.numba = numba
        self.op = op
        self.threads = max(1, min(int(threads or 1), numba.config.NUMBA_NUM_THREADS))
        if op.off[-1] < PARALLEL_MIN_STATES:
            # a parallel region per sweep costs ~5 ms on a loaded machine (both threads must be
            # scheduled): below this size one thread is faster
            self.threads = 1
        self.nchunk = self.threads
        self.items, self.ip, self.tile_cfg = work_items(op, self.nchunk, reverse)
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


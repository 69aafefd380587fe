r"""Coarse correction of the bias by aggregation over the configurations (:class:`Aggregator`;
after Bertsekas & Castañon, "Adaptive aggregation methods for infinite horizon dynamic
programming", IEEE Trans. Automatic Control 34(6), 1989).

For a policy mu with costs c and transition matrix P, the bias h_mu and gain g_mu satisfy
h_mu + g_mu = c + P h_mu. With the residual r = c + P h - h of any h, the error e = h_mu - h
satisfies

    e + g_mu 1 = r + P e.

Aggregation looks for e in the span of the indicator vectors of a few groups of states,
e ~ W y (W: states x groups, a single 1 a row), and averages the equation over each group
(Q = diag(1 / |group|) W^T, so Q W = I):

    y + g 1 = Q r + (Q P W) y,

an average-cost evaluation on the groups (Q P W is a stochastic matrix: the transition mass
between groups, averaged over each group's states). h + W y is the corrected bias.

The groups here are the **configurations** of the automaton. The error the sweeps leave is
almost constant on each configuration's AoI box (it is the slow exchange of value between
configurations that Gauss-Seidel sweeps over the AoI boxes carry slowly), and the successor's
group of an outcome is its next configuration, known without looking at the state. So one
pass over the states gives everything: per configuration, how many of its states take each
action (which fixes Q P W through the automaton's outcome probabilities) and the sum of the
residual. (Grouping by the residual's value, Bertsekas & Castañon's adaptive choice, was
measured and did not pay here: docs/matrix-free.md.)

The certificate is untouched: a correction only changes h, and every bracket is still computed
on the h it is reported for (a correction not yet certified when the run stops is undone).
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as sparse_linalg

from ...models.system import System
from ..threads import run_twins
from .operator import Operator

__all__ = ["Aggregator", "config_chunks"]


def config_chunks(op: Operator, nchunk: int) -> np.ndarray:
    """Contiguous ranges of configurations of about equal numbers of states (chunk i is
    ``cp[i]:cp[i + 1]``)."""
    cum = op.off[1:].astype(float)
    cuts = np.searchsorted(cum, cum[-1] * np.arange(1, nchunk) / nchunk)
    return np.unique(np.r_[0, cuts, op.off.size - 1]).astype(np.int64)


class Aggregator:
    """The coarse correction h <- h + W y of the module docstring, one group per configuration.

    Parameters
    ----------
    system : System
    op : Operator
        The solve's operator tables (its costs: the MSE or an evaluation's own).
    threads : int
    """

    def __init__(self, system: System, op: Operator, threads: int):
        from .sweeper import load_kernels

        self.K = load_kernels()
        self.op, self.threads = op, threads
        flat = system.automaton.flat(op.N)
        nC = op.off.size - 1
        n_act = np.diff(op.act_ptr)
        # per outcome: its configuration, its local action and its next configuration
        act_cfg = np.repeat(np.arange(nC), n_act)
        act_local = np.arange(op.act_ptr[-1]) - op.act_ptr[act_cfg]
        n_out = np.diff(op.out_ptr)
        self.e_cfg = np.repeat(act_cfg, n_out)
        self.e_local = np.repeat(act_local, n_out)
        self.e_nxt = np.asarray(flat.out_nxt, np.int64)
        self.size = np.diff(op.off).astype(float)
        self.cp = config_chunks(op, 4 * threads if threads > 1 else 1)
        self.counts = np.zeros((nC, int(n_act.max())), np.int64)
        self.rsum = np.zeros(nC)
        self.y: np.ndarray | None = None  # the last correction (for undo)
        self.count = 0
        self.last_gain = np.nan

    def correct(self, h: np.ndarray, pol: np.ndarray, weight: float = 1.0) -> bool:
        """Add the aggregated correction of policy ``pol`` (one local action per state) to h in
        place; False (h unchanged) when the groups' equation has no finite solution."""
        o = self.op
        run_twins(self.K.agg_config, self.K.agg_config_serial, self.threads, self.cp, o.N, o.lo, o.dims, o.off, o.act_ptr, o.out_ptr, o.e_prob, o.e_m, o.e_base,
                   o.e_stride, o.q, h, pol, self.counts, self.rsum, o.max_out)
        nC = self.size.size
        share = self.counts[self.e_cfg, self.e_local] / self.size[self.e_cfg]  # of its configuration's states
        rbar = self.rsum / self.size
        # y + g 1 = rbar + M y, with the states' mean of y fixed at 0 (a constant is no correction):
        # sparse (a configuration has a few successors), solved by SuperLU on one thread (a dense
        # solve on the BLAS threads cost more CPU than the whole pass beside the numba threads)
        w = self.size / self.size.sum()
        rows = np.r_[self.e_cfg, np.arange(nC), np.arange(nC), np.full(nC, nC)]
        cols = np.r_[self.e_nxt, np.arange(nC), np.full(nC, nC), np.arange(nC)]
        vals = np.r_[-share * o.e_prob, np.ones(nC), np.ones(nC), w]
        K = sparse.csc_matrix((vals, (rows, cols)), shape=(nC + 1, nC + 1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sparse_linalg.MatrixRankWarning)
            sol = sparse_linalg.spsolve(K, np.r_[rbar, 0.0])
        if not np.all(np.isfinite(sol)):
            return False
        self.y = weight * sol[:nC]
        self.last_gain = float(sol[nC])
        run_twins(self.K.agg_apply, self.K.agg_apply_serial, self.threads, o.off, h, self.y)
        self.count += 1
        return True

    def undo(self, h: np.ndarray) -> None:
        """Take the last correction back out of h."""
        if self.y is not None:
            run_twins(self.K.agg_apply, self.K.agg_apply_serial, self.threads, self.op.off, h, -self.y)
            self.y = None

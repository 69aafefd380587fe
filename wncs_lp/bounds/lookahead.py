r"""The two-step lookahead policy: one step of value iteration on a separable value function,
then greedy.

With separable value tables h(s) ~ sum_k h_k(tau_k, column_k(C)) (a bound's, or the paper's
suboptimal policy's), the greedy policy (:class:`~wncs_lp.policies.suboptimal.SeparableGreedyPolicy`)
minimises E[h(s')]. The lookahead policy minimises instead

.. math:: Q_2(s, a) = \sum_o P(o \mid C, a) \Bigl[c(s'_o) + \min_{a'} \sum_{o'} P(o' \mid C'_o, a')
          h(s''_{o,o'})\Bigr] = \sum_o P(o \mid C, a)\, (T h)(s'_o),

the greedy policy on T h, one Bellman step of h (equivalently: the rollout of the greedy policy
for one step, with h as terminal value). Where h is exact (h = h*) both are optimal; where h
is a relaxation's approximation, T h is closer to the optimal bias in the sup-norm span
(contraction over the step), at A x O times the greedy's work per state. The inner minimum is
the greedy's value at s'_o, read from the same precomputed tables W_k[C', a', tau'_k]
(:func:`~wncs_lp.policies.suboptimal.separable_table`): per state the policy makes
sum_{a, o} A(C'_o) N lookups, in a numba kernel (:mod:`~wncs_lp.bounds.lookahead_kernels`).
Ties go to the first action.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..errors import PolicyError
from ..models.system import System
from ..policies.base import Policy
from ..policies.rollout import ROLLOUT_CANDIDATES, ROLLOUT_HORIZON, ROLLOUT_SAMPLES, check_rollout, rollout_uniforms
from ..policies.suboptimal import SeparableGreedyPolicy
from .policy import TABLE_MAX_BYTES, GroupBoundPolicy
from .projected import ProjectedBoundPolicy

__all__ = ["LookaheadPolicy", "TableRolloutPolicy", "lookahead_policy", "auto_candidates", "AUTO_CANDIDATES",
           "AUTO_CANDIDATES_FROM", "rollout_candidates", "ROLLOUT_CANDIDATES_LARGE"]

#: States per call of the kernel from which it runs threaded (:func:`wncs_lp.solvers.threads.resolve_threads`).
PARALLEL_MIN_STATES = 20_000
#: The lookahead by name (the gap reports, the policy factory) evaluates only this many actions of
#: least greedy value a state ...
AUTO_CANDIDATES = 16
#: ... on systems with more than this many actions in some configuration (sixteen processes on two
#: servers: 240), where the restriction cuts at least three quarters of the work. Measured
#: (``python benchmarks/bounds.py --candidates bounds_lab16:4000``: 4,000 states of a simulation
#: of relaxation 1's greedy policy, 16 sensors of the lab shape) the 16 best greedy candidates
#: held the full lookahead's action in 99.95% of the states at 16% of its CPU time (32: every
#: state, 22%; 8: 99.75%, 8%); on the paper's four types four times every count from 2 up agreed
#: on 2,000 states. At eight processes and below (56 actions or fewer) the lookahead stays exact.
AUTO_CANDIDATES_FROM = 64


def auto_candidates(system: System) -> int | None:
    """The candidate count of the lookahead by name on ``system``: :data:`AUTO_CANDIDATES` where some
    configuration has more than :data:`AUTO_CANDIDATES_FROM` actions, else None (every action)."""
    return AUTO_CANDIDATES if int(system.max_actions) > AUTO_CANDIDATES_FROM else None


def _kernels() -> Any:
    try:
        from . import lookahead_kernels
    except ImportError as exc:  # numba missing
        raise PolicyError(f"the lookahead policy needs numba ({exc})") from None
    return lookahead_kernels


class LookaheadPolicy(Policy):
    """The greedy policy on T h for the value function of a greedy policy on tables (module docstring).

    Parameters
    ----------
    base : SeparableGreedyPolicy or GroupBoundPolicy
        A greedy policy on separable tables (a bound's :class:`~wncs_lp.bounds.BoundPolicy`, the
        paper's :class:`~wncs_lp.policies.suboptimal.SuboptimalPolicy`, ...) or on a grouped
        bound's group tables (:class:`~wncs_lp.bounds.GroupBoundPolicy`, every group's lookahead
        table precomputed). Its tables are copied into one flat array, each configuration's
        entries AoI-major (the values of its actions at one AoI vector contiguous). The greedy
        policy of relaxations 1 and 3 (:class:`~wncs_lp.bounds.projected.ProjectedBoundPolicy`)
        is read as it is, through its tables over the members' private pairs.
    candidates : int, optional
        Evaluate the lookahead value only for the ``candidates`` actions of least greedy value in
        each state (ties: the first); default every action (the exact two-step lookahead).
    depth : {2, 3}
        2 (default): the greedy policy on T h. 3: one step further, the greedy policy on T' T h with
        T' the Bellman step restricted to the ``middle`` actions of least greedy value at the
        intermediate state (about ``middle`` times the work of depth 2 a state).
    middle : int
        Actions tried at the intermediate state of depth 3 (default 3).
    threads : int, optional
        Kernel threads (default: every usable core from :data:`PARALLEL_MIN_STATES` states a call,
        one below).

    Attributes
    ----------
    base : Policy
    candidates : int or None
    build_seconds : float
    """

    def __init__(self, base: SeparableGreedyPolicy | GroupBoundPolicy, candidates: int | None = None,
                 threads: int | None = None, *, depth: int = 2, middle: int = 3):
        if not isinstance(base, (SeparableGreedyPolicy, GroupBoundPolicy, ProjectedBoundPolicy)):
            raise PolicyError(f"the lookahead policy works on a greedy policy of separable or group tables "
                              f"(SeparableGreedyPolicy, GroupBoundPolicy, ProjectedBoundPolicy), got {type(base).__name__}")
        if candidates is not None and not (isinstance(candidates, (int, np.integer)) and candidates >= 1):
            raise PolicyError(f"candidates must be a whole number >= 1 (or None: every action), got {candidates!r}")
        if depth not in (2, 3) or not (isinstance(middle, (int, np.integer)) and middle >= 1):
            raise PolicyError(f"depth must be 2 or 3 and middle a whole number >= 1, got {depth!r} and {middle!r}")
        if base.system.is_lazy:  # its arrays are the pairs known when built; a simulation meets more
            raise PolicyError("the lookahead policy needs the outcomes of every configuration one step ahead, and "
                              "this system's configuration automaton is explored lazily (too large to enumerate); "
                              "the bound's greedy policy runs on it")
        super().__init__(base.system)
        t0 = time.perf_counter()
        self.kernels = _kernels()
        s = self.system
        self.base = base
        self.candidates = None if candidates is None else int(candidates)
        self.depth, self.middle = int(depth), int(middle)
        label = "lookahead" + ("" if depth == 2 else f"3-m{int(middle)}")
        self.name = f"{label}[{base.name}]" if candidates is None else f"{label}-k{int(candidates)}[{base.name}]"
        self.threads = threads
        caps = np.asarray(s.caps, np.int64)
        valid = s.action_valid
        c_of, j_of = np.nonzero(valid)  # the feasible pairs, configuration-major: p = first[c] + j
        count = np.asarray(s.n_actions, np.int64)
        first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        projected = _NONE
        if isinstance(base, ProjectedBoundPolicy):  # tables over the members' private pairs, as they are
            blocks = [tuple(g) for g in base.lookahead.groups]
            W, off, width, *arrays = base.lookahead.kernel_arrays()
            projected = tuple(np.asarray(a, np.int64) for a in arrays)
        elif isinstance(base, SeparableGreedyPolicy):
            if base.tables is None:
                raise PolicyError("the lookahead policy needs the greedy policy's tables, which did not fit the "
                                  "memory budget (it computes its lookahead state by state)")
            blocks = [(k,) for k in range(s.n_processes)]
            rows = list(base.tables)  # (P, tau_hat_k), one row per feasible pair, configuration-major
        else:
            blocks = [tuple(g) for g in base.tables.groups]
            if any(t is None for t in base.lookahead):
                raise PolicyError("the lookahead policy needs every group's lookahead table; a group of this bound "
                                  f"is too large for one (over {TABLE_MAX_BYTES:,} bytes)")
            rows = [t[base.pair_row[c_of, j_of]] for t in base.lookahead]  # (P, prod tau_hat_G)
        if projected is _NONE:
            width = np.array([math.prod(int(caps[k]) for k in g) for g in blocks], np.int64)
            off = np.concatenate([[0], np.cumsum(width * c_of.size)[:-1]]).astype(np.int64)
            W = np.empty(int(np.sum(width)) * c_of.size)
            for b, (r, w) in enumerate(zip(rows, width)):  # AoI-major within each configuration
                dst = (off[b] + (first[c_of] * w)[:, None] + np.arange(w)[None, :] * count[c_of][:, None]
                       + j_of[:, None])
                W[dst] = r
        members = np.array([k for g in blocks for k in g], np.int64)
        mptr = np.concatenate([[0], np.cumsum([len(g) for g in blocks])]).astype(np.int64)
        stride = np.array([math.prod(int(caps[k]) for k in g[i + 1:]) for g in blocks for i in range(len(g))],
                          np.int64)
        pt = s.pairs  # one row per feasible pair, configuration-major (the rows c_of, j_of above)
        q = np.zeros((s.n_processes, int(caps.max())))
        for k, qk in enumerate(s.q):
            q[k, : qk.size] = qk
        self._caps = caps
        self._args = (first, count, np.ascontiguousarray(pt.nxt, dtype=np.int64),
                      np.ascontiguousarray(pt.delta, dtype=np.int64), np.ascontiguousarray(pt.deltas, dtype=np.int64),
                      np.ascontiguousarray(pt.prob), caps, q, W, off, width, mptr, members, stride,
                      *projected, -1 if self.candidates is None else self.candidates, self.depth, self.middle,
                      int(s.max_actions))
        self.build_seconds = time.perf_counter() - t0 + getattr(base, "build_seconds", 0.0)

    def act(self, tau, config_ids, rng=None):
        from ..solvers.threads import resolve_threads, run_twins

        tau, c = self._check_inputs(tau, config_ids)
        if tau.shape[1] != self._caps.size or np.any(tau < 1) or np.any(tau > self._caps):
            raise PolicyError(f"policy {self.name}: tau must have {self._caps.size} columns in 1..tau_hat = "
                              f"{self._caps.tolist()}")
        out = np.empty(c.size, dtype=np.int64)
        args = (np.ascontiguousarray(tau), np.ascontiguousarray(c), *self._args, out)
        threads = resolve_threads(self.threads, None if c.size >= PARALLEL_MIN_STATES else 0)
        run_twins(self.kernels.lookahead, self.kernels.lookahead_serial, threads, *args)
        return out

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "base": self.base.describe(), "candidates": self.candidates,
                "depth": self.depth, "middle": self.middle, "build_seconds": self.build_seconds}


#: The rollout by name where some configuration has more than :data:`AUTO_CANDIDATES_FROM` actions
#: (:data:`~wncs_lp.policies.rollout.ROLLOUT_CANDIDATES` below; the horizon and the paths are the rule's
#: own defaults, :data:`~wncs_lp.policies.rollout.ROLLOUT_HORIZON` and ``ROLLOUT_SAMPLES``). Measured
#: (docs/bounds.md, "Rollout"): at eight processes 8 candidates chose as 4 did; at sixteen (240
#: actions) 8 cut the upper limit by a further 0.31% and 16 no more than 8.
ROLLOUT_CANDIDATES_LARGE = 8


def rollout_candidates(system: System) -> int:
    """The candidate count of the rollout by name on ``system`` (:data:`ROLLOUT_CANDIDATES`, or
    :data:`ROLLOUT_CANDIDATES_LARGE` where some configuration has more than :data:`AUTO_CANDIDATES_FROM`
    actions)."""
    return ROLLOUT_CANDIDATES_LARGE if int(system.max_actions) > AUTO_CANDIDATES_FROM else ROLLOUT_CANDIDATES


class TableRolloutPolicy(LookaheadPolicy):
    r"""The rollout policy (:class:`~wncs_lp.policies.rollout.RolloutPolicy`) of a bound's greedy policy
    in a numba kernel: each of the ``candidates`` actions of least greedy value (the greedy's own
    choice first) is scored by

    .. math:: \mathrm{E}[h(s_1) \mid s, a] + \frac{1}{S} \sum_{i=1}^{S} \sum_{t=1}^{H-1}
              \bigl(c(s^i_t) + \min_{a'} \mathrm{E}[h(s^i_{t+1}) \mid s^i_t, a'] - h(s^i_t)\bigr),

    the paths s^i driven by a fixed (S, H - 1) array of uniforms drawn from ``seed`` (common random
    numbers across candidates and states: a deterministic stationary policy), the greedy policy
    followed after the first slot, h the bound's tables; ties go to the greedy's choice. The same
    decisions as :class:`~wncs_lp.policies.rollout.RolloutPolicy` on the same tables and uniforms (up
    to the order of floating-point sums), at candidates x S x (H - 1) greedy decisions a state,
    each A x (blocks) table reads.

    Parameters
    ----------
    base : BoundPolicy, GroupBoundPolicy or ProjectedBoundPolicy
        A bound's greedy policy (its ``result.tables`` are h).
    candidates, horizon, samples : int
        Default :func:`rollout_candidates` of the system, :data:`ROLLOUT_HORIZON`, :data:`ROLLOUT_SAMPLES`.
    seed : int
    threads : int, optional
    """

    def __init__(self, base: SeparableGreedyPolicy | GroupBoundPolicy | ProjectedBoundPolicy,
                 candidates: int | None = None, horizon: int = ROLLOUT_HORIZON,
                 samples: int = ROLLOUT_SAMPLES, seed: int = 0, threads: int | None = None):
        result = getattr(base, "result", None)
        if result is None:
            raise PolicyError("the table rollout needs a bound's greedy policy (BoundPolicy, GroupBoundPolicy, "
                              f"ProjectedBoundPolicy: its tables are the terminal value); got {type(base).__name__}")
        if candidates is None:
            candidates = rollout_candidates(base.system)
        check_rollout(candidates, horizon, samples, seed)
        super().__init__(base, int(candidates), threads)
        t0 = time.perf_counter()
        s = self.system
        tables = result.tables
        groups = [tuple(g) for g in getattr(tables, "groups", [(k,) for k in range(s.n_processes)])]
        members = self._args[12]
        mptr = self._args[11]
        blocks = [tuple(int(k) for k in members[mptr[b]:mptr[b + 1]]) for b in range(mptr.size - 1)]
        if sorted(blocks) != sorted(groups):
            raise PolicyError(f"the bound's tables have groups {groups}, its greedy policy reads {blocks}")
        where = {g: i for i, g in enumerate(groups)}
        hs = [np.ascontiguousarray(tables.h[where[g]], dtype=float).reshape(np.shape(tables.h[where[g]])[0], -1)
              for g in blocks]
        self._hwidth = np.array([h.shape[1] for h in hs], np.int64)
        self._hoff = np.concatenate([[0], np.cumsum([h.size for h in hs])[:-1]]).astype(np.int64)
        self._hflat = np.concatenate([h.ravel() for h in hs])
        self._hcol = np.stack([np.asarray(tables.column[where[g]], np.int64) for g in blocks])
        self.horizon, self.samples, self.seed = int(horizon), int(samples), int(seed)
        self.uniforms = rollout_uniforms(self.samples, self.horizon, self.seed)
        self.name = f"rollout-k{self.candidates}-h{self.horizon}-s{self.samples}[{base.name}]"
        self.build_seconds += time.perf_counter() - t0

    def act(self, tau, config_ids, rng=None):
        from ..solvers.threads import resolve_threads, run_twins

        tau, c = self._check_inputs(tau, config_ids)
        if tau.shape[1] != self._caps.size or np.any(tau < 1) or np.any(tau > self._caps):
            raise PolicyError(f"policy {self.name}: tau must have {self._caps.size} columns in 1..tau_hat = "
                              f"{self._caps.tolist()}")
        (first, count, nxt, delta, deltas, _prob, caps, q, W, off, width, mptr, members, stride,
         idle, touch, tpair) = self._args[:17]
        out = np.empty(c.size, dtype=np.int64)
        args = (np.ascontiguousarray(tau), np.ascontiguousarray(c), first, count, nxt, delta, deltas,
                np.ascontiguousarray(self.system.pairs.cum), caps, q, W, off, width, mptr, members, stride, idle,
                touch, tpair, self._hflat, self._hoff, self._hwidth, self._hcol, self.uniforms, self.candidates,
                np.ascontiguousarray(self.base.act(tau, c), dtype=np.int64), int(self.system.max_actions), out)
        work = c.size * self.candidates * self.samples * (self.horizon - 1)
        threads = resolve_threads(self.threads, None if work >= PARALLEL_MIN_STATES else 0)
        run_twins(self.kernels.rollout, self.kernels.rollout_serial, threads, *args)
        return out

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "horizon": self.horizon, "samples": self.samples, "seed": self.seed}


#: The stand-ins for the arrays of tables read through projections (the kernel tells joint tables by
#: an empty ``idle``).
_NONE = (np.zeros((0, 0), np.int64), np.zeros((0, 1), np.int64), np.zeros((0, 1), np.int64))


def lookahead_policy(base: SeparableGreedyPolicy | GroupBoundPolicy, candidates: int | None = None,
                     threads: int | None = None, *, depth: int = 2, middle: int = 3) -> LookaheadPolicy:
    """The lookahead policy on a greedy policy's tables."""
    return LookaheadPolicy(base, candidates, threads, depth=depth, middle=middle)

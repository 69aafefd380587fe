"""Theorem 3 (claim C10): a started job is not preempted or cancelled before it completes."""
from __future__ import annotations

import time

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..models import model_type
from ..solvers.result import Solution
from .context import DEFAULT_EXAMPLES, PolicyContext, make_report, require_space, use_context, witness_flags
from .report import CheckReport, Tolerance, Violation, pick_examples
from .verdict import witness_rank

__all__ = ["check_consistency"]


def check_consistency(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    ctx: PolicyContext | None = None,
    starts: str = "preempting",
) -> CheckReport:
    r"""Theorem 3 (claim C10, preemption model): a job started by preempting is not preempted before it completes.

    *Starts.* A state s starts a job when ``pi(s) = (k,)`` with ``k != 0``: process k's fresh update
    enters service as ``(k, T_k, U)`` (on an idle server, preempting another process's job, or
    cancelling k's own job in service -- sub-counted).

    *Tree.* While the started job is in service, the next state is random (arrivals, downlink
    outcome). From each start the check follows **every** positive-probability successor
    under the policy (the rows of ``P``: equal next states of different channel outcomes are one
    branch). At a state x reached with the job still in service:

    * if ``pi(x) = (0,)`` (keep going) the job gets one more slot; if it had ``d = 1`` slot
      left it completes there (the path ends, consistent); otherwise every successor is followed;
    * if ``pi(x) = (j,)`` with ``j != 0`` the job is preempted (``j != k``) or cancelled
      (``j = k``) before completing: the path ends in a **violation** -- unless keeping going is
      optimal within tol, ``|Q(x, 0) - Q(x, pi(x))| <= tol``, which counts as a tie and the
      keep-going branch is followed instead.

    The job's identity is the job of process k in service (at most one job per process exists),
    so the exploration is memoised on the state x alone; each tree has depth <= T_k - 1.

    Counts: ``checked`` = start states of the kind ``starts`` names -- by default the theorem's
    own wording, jobs started *by preempting* another process's job; ``"all"``: every start --;
    ``violations`` = those whose tree contains a violating path; ``details["by_start_type"]``
    splits every start by its kind (on an idle server, preempting another process's job,
    restarting its own process; and whether another process's update was also available, i.e.
    the start was a choice), with one counterexample per kind; ``details`` adds the number of paths and of violating paths (over all trees),
    the probability that a start is later preempted/cancelled (max, and the long-run frequency
    ``sum_s pi(s) P(violation | start at s)``), and the starts by type. A violating start is
    recurrent when the start state is; it is *at cap* when every violating path from it passes
    through a state with some tau at its cap. The worst violation is the start with the largest
    violation probability; ``details["counterexample"]`` is one violating path in full (recurrent
    and below the cap when one exists).

    Parameters
    ----------
    starts : {"preempting", "all"}
        Which starts decide ``holds`` and the headline counts (default: the theorem's, preempting).

    Raises
    ------
    ModelError
        If ``starts`` is neither, or the model has no consistency check (``"consistency"`` not in its
        :attr:`~wncs_lp.models.base.Model.checks`: only the preemption model has one).
    """
    t0 = time.perf_counter()
    if starts not in ("preempting", "all"):
        raise ModelError(f"starts must be 'preempting' or 'all', got {starts!r}")
    require_space(mdp)
    model = model_type(mdp)
    if "consistency" not in model.checks:
        raise ModelError(f"{mdp.name}: the consistency check (Theorem 3) applies to the preemption model only")
    ctx = use_context(mdp, solution, tolerance, stationary_tol, ctx)
    trees = _JobTrees(mdp, solution, ctx, model)
    st = trees.explore_starts()
    in_scope = st["type"] == 1 if starts == "preempting" else np.ones(st["states"].size, bool)
    vidx = np.flatnonzero(st["violating"] & in_scope)  # the headline's violations (indices into the starts)
    rec, cap, size = st["recurrent"][vidx], st["at_cap"][vidx], st["probability"][vidx]
    W = st["states"][vidx, None]
    obs, dist = witness_flags(ctx, W, rec)
    ex = [trees.violation(st, int(vidx[i])) for i in pick_examples(rec, cap, size, examples, obs, dist)]
    worst = trees.violation(st, int(vidx[np.argmax(size)])) if size.size else None
    details = _details(trees, st, starts, ex)
    return make_report(
        "consistency", "Theorem 3 (C10): a job started by preempting is not preempted or cancelled before it "
                       "completes" if starts == "preempting" else
                       "Theorem 3 (C10), every start: a started job is not preempted or cancelled before it completes",
        ctx, holds=vidx.size == 0, checked=int(np.count_nonzero(in_scope)), violations=int(vidx.size), rec=rec,
        cap=cap, ties=details["tie_nodes"],
        unit="preempting start states" if starts == "preempting" else "start states", worst=worst, examples=ex,
        details=details, notes=_notes(starts), t0=t0, witnesses=W, obs=obs,
    )


#: The kinds of start (the code in ``starts["type"]``).
START_TYPES = {0: "idle_server", 1: "preempting", 2: "restarting_own"}


class _JobTrees:
    """The trees of a started job: every positive-probability successor while the job is in service.

    The exploration is memoised on the state alone (the job in service is the job of process
    ``job_k[config]``, at most one per process): per state, the number of paths, of violating
    paths, of violating paths that avoid the cap, and the probability of a violation.
    """

    def __init__(self, mdp: MDP, solution: Solution, ctx: PolicyContext, model) -> None:
        space = mdp.states
        self.mdp, self.ctx, self.model = mdp, ctx, model
        a_lab = np.asarray(mdp.action_table[:, 0], dtype=np.int64)  # action index -> process started (0 = keep going)
        self.cfg = np.asarray(space.config)
        nC = len(space.configs)
        self.job_k = np.zeros(nC, np.int64)
        self.job_d = np.zeros(nC, np.int64)
        for c, conf in enumerate(space.configs):
            job = model.job_in_service(conf)
            if job is not None:
                self.job_k[c], self.job_d[c] = job
        zero_idx = np.flatnonzero(a_lab == 0)
        if zero_idx.size != 1:
            raise ModelError("the preemption model must have exactly one keep-going action (0,)")
        n = mdp.n_states
        self.P = mdp.P
        self.pol = np.asarray(solution.policy, dtype=np.int64)
        self.started = a_lab[ctx.act]  # process started in each state (0 = none)
        self.pair0 = mdp.pair_ptr[:-1] + ctx.offsets[self.cfg, int(zero_idx[0])]
        self.q0 = ctx.q[self.pair0]
        self.tie_at = (self.started != 0) & (np.abs(self.q0 - ctx.q_pi) <= ctx.tol)
        self.paths = np.full(n, -1, dtype=np.int64)
        self.bad = np.zeros(n, np.int64)
        self.bad_free = np.zeros(n, np.int64)
        self.pviol = np.zeros(n)
        self.ties_seen = np.zeros(n, bool)
        self.kind_of = np.zeros(n, np.int8)  # at a violating node: 1 preempt, 2 cancel

    def succ(self, pair: int) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.P.indptr[pair], self.P.indptr[pair + 1]
        return self.P.indices[lo:hi], self.P.data[lo:hi]

    def subtree(self, pair: int) -> tuple[int, int, int, float]:
        """(paths, violating paths, violating paths below the cap, violation probability) summed
        over the successors of ``pair``, each explored first."""
        tp = tb = tbf = 0
        pv = 0.0
        for y, p in zip(*self.succ(pair)):
            y = int(y)
            self.node(y)
            tp += self.paths[y]
            tb += self.bad[y]
            tbf += self.bad_free[y]
            pv += p * self.pviol[y]
        return tp, tb, tbf, pv

    def node(self, x: int) -> None:
        """Explore state x, reached with the started job still in service."""
        if self.paths[x] >= 0:
            return
        c = self.cfg[x]
        k = self.job_k[c]
        if k == 0:
            raise ModelError(f"internal error: no job in service at {self.ctx.label(x)} while following a started job")
        j = self.started[x]
        if j != 0 and not self.tie_at[x]:
            self.paths[x], self.bad[x], self.pviol[x] = 1, 1, 1.0
            self.bad_free[x] = 0 if self.ctx.at_cap[x] else 1
            self.kind_of[x] = 2 if j == k else 1
            return
        if self.tie_at[x]:
            self.ties_seen[x] = True
        pair = int(self.pol[x]) if j == 0 else int(self.pair0[x])
        if self.job_d[c] <= 1:  # completes in this slot
            self.paths[x], self.bad[x], self.bad_free[x], self.pviol[x] = 1, 0, 0, 0.0
            return
        tp, tb, tbf, pv = self.subtree(pair)
        self.paths[x], self.bad[x], self.pviol[x] = tp, tb, pv
        self.bad_free[x] = 0 if self.ctx.at_cap[x] else tbf

    def explore_starts(self) -> dict[str, np.ndarray]:
        """The tree of every start state: its paths, violating paths (and those below the cap), the
        probability of a violation, the kind of start (:data:`START_TYPES`), recurrence and cap."""
        ctx = self.ctx
        states = np.flatnonzero(self.started != 0)
        m = states.size
        out = {"states": states, "paths": np.zeros(m, np.int64), "bad": np.zeros(m, np.int64),
               "bad_free": np.zeros(m, np.int64), "probability": np.zeros(m), "type": np.zeros(m, np.int8)}
        for i, s in enumerate(states):
            s = int(s)
            k = int(self.started[s])
            cur = self.job_k[self.cfg[s]]
            out["type"][i] = 0 if cur == 0 else (2 if cur == k else 1)
            cols, _ = self.succ(int(self.pol[s]))
            if cols.size and self.job_k[self.cfg[int(cols[0])]] != k:
                tp, tb, tbf, pv = 1, 0, 0, 0.0  # T_k = 1: the job completes within the start slot
            else:
                tp, tb, tbf, pv = self.subtree(int(self.pol[s]))
            out["paths"][i], out["bad"][i], out["probability"][i] = tp, tb, pv
            out["bad_free"][i] = 0 if ctx.at_cap[s] else tbf
        out["violating"] = out["bad"] > 0  # every kind of start
        out["recurrent"] = ctx.recurrent[states]
        out["at_cap"] = out["bad_free"] == 0  # every violating path from the start passes the cap
        return out

    def trajectory(self, s: int) -> list[dict]:
        """One violating path from start s: prefer cap-free branches, then the likeliest."""
        ctx = self.ctx

        def step(y: int, p: float) -> dict:
            return {"state": y, "label": ctx.label(y), "action": list(ctx.action(ctx.act[y])), "prob": p,
                    "at_cap": bool(ctx.at_cap[y]), "recurrent": bool(ctx.recurrent[y])}

        steps = [step(s, 1.0)]
        pair = int(self.pol[s])
        k = int(self.started[s])
        while True:
            best, key = None, None
            for y, p in zip(*self.succ(pair)):
                y = int(y)
                if self.job_k[self.cfg[y]] != k or self.paths[y] < 0 or self.bad[y] == 0:
                    continue
                kk = (self.bad_free[y] > 0, p)
                if key is None or kk > key:
                    best, key = (y, float(p)), kk
            if best is None:
                raise ModelError("internal error: lost the violating branch while rebuilding a trajectory")
            y, p = best
            j = int(self.started[y])
            here = step(y, p)
            if j != 0 and not self.tie_at[y]:
                here["event"] = "preempts the started job" if j != k else "cancels (restarts) the started job"
                here["Q_keep_going_minus_Q_chosen"] = float(self.q0[y] - ctx.q_pi[y])
                steps.append(here)
                return steps
            if self.tie_at[y]:
                here["note"] = "preempting ties with keeping going; followed keep-going"
            steps.append(here)
            pair = int(self.pol[y]) if j == 0 else int(self.pair0[y])

    def violation(self, st: dict[str, np.ndarray], j: int) -> Violation:
        """The violation of the j-th start (a violating one)."""
        s = int(st["states"][j])
        traj = self.trajectory(s)
        last = traj[-1]
        return self.ctx.violation(
            "preempt" if "preempts" in last.get("event", "") else "cancel",
            st["probability"][j], (s, last["state"]), st["recurrent"][j], st["at_cap"][j],
            {"start_type": START_TYPES[int(st["type"][j])], "violation_probability": float(st["probability"][j]),
             "violating_paths": int(st["bad"][j]), "paths": int(st["paths"][j]),
             "cap_free_violating_paths": int(st["bad_free"][j]), "steps": len(traj) - 1, "trajectory": traj},
        )


def _by_start_type(trees: _JobTrees, st: dict[str, np.ndarray]) -> dict[str, dict]:
    """The starts split by kind (and by whether another process's update was also available, i.e.
    the start was a choice), with the counts of the verdict and one counterexample per kind."""
    space, model = trees.mdp.states, trees.model
    states, viol = st["states"], st["violating"]
    other = np.array([any(x for j, x in enumerate(model.arrived(space.configs[trees.cfg[s]]), 1)
                          if j != trees.started[s]) for s in states], dtype=bool) if states.size else np.zeros(0, bool)
    selections = {name: st["type"] == t for t, name in START_TYPES.items()}
    selections["other_update_available"] = other
    selections["preempting_with_other_available"] = (st["type"] == 1) & other
    selections["all"] = np.ones(states.size, bool)
    obs = st["recurrent"] & trees.ctx.observable[states]
    dist = trees.ctx.cap_distance[states]
    out = {}
    for name, sel in selections.items():
        v = sel & viol
        out[name] = {"checked": int(np.count_nonzero(sel)), "violations": int(np.count_nonzero(v)),
                     "recurrent_violations": int(np.count_nonzero(v & st["recurrent"])),
                     "at_cap_violations": int(np.count_nonzero(v & st["at_cap"])),
                     "recurrent_below_cap": int(np.count_nonzero(v & st["recurrent"] & ~st["at_cap"])),
                     "observable_below_cap": int(np.count_nonzero(v & obs & ~st["at_cap"]))}
    for name, sel in selections.items():  # one counterexample per kind of start: the best witness, far from the cap
        cand = np.flatnonzero(sel & viol)
        if cand.size:
            rank = witness_rank(st["recurrent"][cand], st["at_cap"][cand], obs[cand])
            best = cand[np.lexsort((-st["probability"][cand], -dist[cand], rank))[0]]
            out[name]["counterexample"] = trees.violation(st, int(best)).to_json()
    return out


def _details(trees: _JobTrees, st: dict[str, np.ndarray], starts: str, examples: list[Violation]) -> dict:
    """The report's details: starts by kind, path counts, long-run frequencies, a counterexample."""
    ctx = trees.ctx
    states, pv = st["states"], st["probability"]
    stationary = ctx.stationary
    has = stationary is not None and states.size
    vnodes = np.flatnonzero(trees.kind_of > 0)
    return {
        "starts_by_type": {name: int(np.count_nonzero(st["type"] == t)) for t, name in START_TYPES.items()},
        "violating_starts_by_type": {name: int(np.count_nonzero(st["type"][st["violating"]] == t))
                                     for t, name in START_TYPES.items()},
        "scope": starts,
        "by_start_type": _by_start_type(trees, st),
        "paths": int(st["paths"].sum()),
        "violating_paths": int(st["bad"].sum()),
        "cap_free_violating_paths": int(st["bad_free"].sum()),
        "violating_nodes": {"preempt": int(np.count_nonzero(trees.kind_of == 1)),
                            "cancel": int(np.count_nonzero(trees.kind_of == 2)),
                            "recurrent": int(np.count_nonzero(ctx.recurrent[vnodes]))},
        "max_violation_probability": float(pv.max()) if pv.size else 0.0,
        "long_run_start_frequency": float(stationary[states].sum()) if has else None,
        "long_run_violation_frequency": float(np.dot(stationary[states], pv)) if has else None,
        "tie_nodes": int(np.count_nonzero(trees.ties_seen)),
        "counterexample": examples[0].info["trajectory"] if examples else None,
    }


def _notes(starts: str) -> str:
    return ("One case = one state where the policy starts a job "
            + ("by preempting another process's job (Theorem 3's wording; every other kind of start is in "
               "details.by_start_type)" if starts == "preempting" else "(any kind)")
            + "; a violation = a start whose tree of every "
            "positive-probability successor (until the job completes) contains a state where the policy preempts "
            "or cancels that job; a path = a root-to-leaf branch of that tree. Ties (keeping going optimal within "
            "tol) are followed as keep-going and counted in 'ties' (tie states visited).")

"""Theorem 3 (claim C10): a started job is not preempted or cancelled before it completes."""
from __future__ import annotations

import time

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..models import model_type
from ..solvers.result import Solution
from .context import DEFAULT_EXAMPLES, PolicyContext, make_report, require_space, use_context
from .report import CheckReport, Tolerance, Violation, pick_examples

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
    space = mdp.states
    nC = len(space.configs)
    table = mdp.action_table
    a_lab = np.asarray(table[:, 0], dtype=np.int64)  # action index -> process started (0 = keep going)
    cfg = np.asarray(space.config)
    job_k = np.zeros(nC, np.int64)
    job_d = np.zeros(nC, np.int64)
    for c, conf in enumerate(space.configs):
        job = model.job_in_service(conf)
        if job is not None:
            job_k[c], job_d[c] = job
    zero_idx = np.flatnonzero(a_lab == 0)
    if zero_idx.size != 1:
        raise ModelError("the preemption model must have exactly one keep-going action (0,)")
    a0 = int(zero_idx[0])
    n = mdp.n_states
    P = mdp.P
    pol = np.asarray(solution.policy, dtype=np.int64)
    started = a_lab[ctx.act]  # process started in each state (0 = none)
    pair0 = mdp.pair_ptr[:-1] + ctx.offsets[cfg, a0]
    q0 = ctx.q[pair0]
    tie_at = (started != 0) & (np.abs(q0 - ctx.q_pi) <= ctx.tol)

    # memo over states "our job (the job of process job_k in service) in service at x"
    paths = np.full(n, -1, dtype=np.int64)
    bad = np.zeros(n, np.int64)
    bad_free = np.zeros(n, np.int64)
    pviol = np.zeros(n)
    ties_seen = np.zeros(n, bool)
    kind_of = np.zeros(n, np.int8)  # at a violating node: 1 preempt, 2 cancel

    def succ(pair: int) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = P.indptr[pair], P.indptr[pair + 1]
        return P.indices[lo:hi], P.data[lo:hi]

    def subtree(pair: int) -> tuple[int, int, int, float]:
        """(paths, violating paths, violating paths below the cap, violation probability) summed
        over the successors of ``pair``, each explored first."""
        cols, probs = succ(pair)
        tp = tb = tbf = 0
        pv = 0.0
        for y, p in zip(cols, probs):
            y = int(y)
            node(y)
            tp += paths[y]
            tb += bad[y]
            tbf += bad_free[y]
            pv += p * pviol[y]
        return tp, tb, tbf, pv

    def node(x: int) -> None:
        if paths[x] >= 0:
            return
        c = cfg[x]
        k = job_k[c]
        if k == 0:
            raise ModelError(f"internal error: no job in service at {ctx.label(x)} while following a started job")
        j = started[x]
        if j != 0 and not tie_at[x]:
            paths[x], bad[x], pviol[x] = 1, 1, 1.0
            bad_free[x] = 0 if ctx.at_cap[x] else 1
            kind_of[x] = 2 if j == k else 1
            return
        if tie_at[x]:
            ties_seen[x] = True
        pair = int(pol[x]) if j == 0 else int(pair0[x])
        if job_d[c] <= 1:  # completes in this slot
            paths[x], bad[x], bad_free[x], pviol[x] = 1, 0, 0, 0.0
            return
        tp, tb, tbf, pv = subtree(pair)
        paths[x], bad[x], pviol[x] = tp, tb, pv
        bad_free[x] = 0 if ctx.at_cap[x] else tbf

    start_states = np.flatnonzero(started != 0)
    s_paths = np.zeros(start_states.size, np.int64)
    s_bad = np.zeros(start_states.size, np.int64)
    s_bad_free = np.zeros(start_states.size, np.int64)
    s_pv = np.zeros(start_states.size)
    start_type = np.zeros(start_states.size, np.int8)  # 0 idle, 1 preempting, 2 restart own
    for i, s in enumerate(start_states):
        s = int(s)
        k = int(started[s])
        cur = job_k[cfg[s]]
        start_type[i] = 0 if cur == 0 else (2 if cur == k else 1)
        cols, _ = succ(int(pol[s]))
        if cols.size and job_k[cfg[int(cols[0])]] != k:
            tp, tb, tbf, pv = 1, 0, 0, 0.0  # T_k = 1: the job completes within the start slot
        else:
            tp, tb, tbf, pv = subtree(int(pol[s]))
        s_paths[i], s_bad[i], s_pv[i] = tp, tb, pv
        s_bad_free[i] = 0 if ctx.at_cap[s] else tbf
    types = {0: "idle_server", 1: "preempting", 2: "restarting_own"}
    viol_all = s_bad > 0  # every kind of start
    in_scope = start_type == 1 if starts == "preempting" else np.ones(start_states.size, bool)
    rec_all = ctx.recurrent[start_states]
    cap_all = s_bad_free == 0  # every violating path from the start passes the cap
    vidx = np.flatnonzero(viol_all & in_scope)  # the headline's violations (indices into start_states)
    rec = rec_all[vidx]
    cap = cap_all[vidx]
    size = s_pv[vidx]

    def trajectory(s: int) -> list[dict]:
        """One violating path from start s: prefer cap-free branches, then the likeliest."""
        steps = [{"state": s, "label": ctx.label(s), "action": list(ctx.action(ctx.act[s])), "prob": 1.0,
                  "at_cap": bool(ctx.at_cap[s]), "recurrent": bool(ctx.recurrent[s])}]
        pair = int(pol[s])
        k = int(started[s])
        while True:
            cols, probs = succ(pair)
            best, key = None, None
            for y, p in zip(cols, probs):
                y = int(y)
                if job_k[cfg[y]] != k or paths[y] < 0 or bad[y] == 0:
                    continue
                kk = (bad_free[y] > 0, p)
                if key is None or kk > key:
                    best, key = (y, float(p)), kk
            if best is None:
                raise ModelError("internal error: lost the violating branch while rebuilding a trajectory")
            y, p = best
            j = int(started[y])
            step = {"state": y, "label": ctx.label(y), "action": list(ctx.action(ctx.act[y])), "prob": p,
                    "at_cap": bool(ctx.at_cap[y]), "recurrent": bool(ctx.recurrent[y])}
            if j != 0 and not tie_at[y]:
                step["event"] = "preempts the started job" if j != k else "cancels (restarts) the started job"
                step["Q_keep_going_minus_Q_chosen"] = float(q0[y] - ctx.q_pi[y])
                steps.append(step)
                return steps
            if tie_at[y]:
                step["note"] = "preempting ties with keeping going; followed keep-going"
            steps.append(step)
            pair = int(pol[y]) if j == 0 else int(pair0[y])

    def make(j: int) -> Violation:
        """The violation of start_states[j] (a violating start)."""
        s = int(start_states[j])
        traj = trajectory(s)
        last = traj[-1]
        return ctx.violation(
            "preempt" if "preempts" in last.get("event", "") else "cancel",
            s_pv[j], (s, last["state"]), rec_all[j], cap_all[j],
            {"start_type": types[int(start_type[j])], "violation_probability": float(s_pv[j]),
             "violating_paths": int(s_bad[j]), "paths": int(s_paths[j]), "cap_free_violating_paths": int(s_bad_free[j]),
             "steps": len(traj) - 1, "trajectory": traj},
        )

    ex = [make(int(vidx[i])) for i in pick_examples(rec, cap, size, examples)]
    worst = make(int(vidx[np.argmax(size)])) if size.size else None
    counterexample = ex[0].info["trajectory"] if ex else None
    stationary = ctx.stationary
    freq = float(np.dot(stationary[start_states], s_pv)) if stationary is not None and start_states.size else None
    start_freq = float(stationary[start_states].sum()) if stationary is not None and start_states.size else None
    vnodes = np.flatnonzero(kind_of > 0)
    # was another process's update available at the start (the start was a choice between two)?
    other = np.array([any(x for j, x in enumerate(model.arrived(space.configs[cfg[s]]), 1) if j != started[s])
                      for s in start_states], dtype=bool) if start_states.size else np.zeros(0, bool)

    def breakdown(sel: np.ndarray) -> dict[str, int]:
        v = sel & viol_all
        return {"checked": int(np.count_nonzero(sel)), "violations": int(np.count_nonzero(v)),
                "recurrent_violations": int(np.count_nonzero(v & rec_all)),
                "at_cap_violations": int(np.count_nonzero(v & cap_all)),
                "recurrent_below_cap": int(np.count_nonzero(v & rec_all & ~cap_all))}

    selections = {types[t]: start_type == t for t in types}
    selections["other_update_available"] = other
    selections["preempting_with_other_available"] = (start_type == 1) & other
    selections["all"] = np.ones(start_states.size, bool)
    by_type = {name: breakdown(sel) for name, sel in selections.items()}
    for name, sel in selections.items():  # one counterexample per kind of start
        cand = np.flatnonzero(sel & viol_all)
        if cand.size:
            best = cand[np.lexsort((-s_pv[cand], cap_all[cand], ~rec_all[cand]))[0]]
            by_type[name]["counterexample"] = make(int(best)).to_json()
    details = {
        "starts_by_type": {types[t]: int(np.count_nonzero(start_type == t)) for t in types},
        "violating_starts_by_type": {types[t]: int(np.count_nonzero(start_type[viol_all] == t)) for t in types},
        "scope": starts,
        "by_start_type": by_type,
        "paths": int(s_paths.sum()),
        "violating_paths": int(s_bad.sum()),
        "cap_free_violating_paths": int(s_bad_free.sum()),
        "violating_nodes": {"preempt": int(np.count_nonzero(kind_of == 1)), "cancel": int(np.count_nonzero(kind_of == 2)),
                            "recurrent": int(np.count_nonzero(ctx.recurrent[vnodes]))},
        "max_violation_probability": float(s_pv.max()) if s_pv.size else 0.0,
        "long_run_start_frequency": start_freq,
        "long_run_violation_frequency": freq,
        "tie_nodes": int(np.count_nonzero(ties_seen)),
        "counterexample": counterexample,
    }
    notes = ("One case = one state where the policy starts a job "
             + ("by preempting another process's job (Theorem 3's wording; every other kind of start is in "
                "details.by_start_type)" if starts == "preempting" else "(any kind)")
             + "; a violation = a start whose tree of every "
             "positive-probability successor (until the job completes) contains a state where the policy preempts "
             "or cancels that job; a path = a root-to-leaf branch of that tree. Ties (keeping going optimal within "
             "tol) are followed as keep-going and counted in 'ties' (tie states visited).")
    return make_report(
        "consistency", "Theorem 3 (C10): a job started by preempting is not preempted or cancelled before it "
                       "completes" if starts == "preempting" else
                       "Theorem 3 (C10), every start: a started job is not preempted or cancelled before it completes",
        ctx, holds=vidx.size == 0, checked=int(np.count_nonzero(in_scope)), violations=int(vidx.size), rec=rec,
        cap=cap, ties=int(np.count_nonzero(ties_seen)),
        unit="preempting start states" if starts == "preempting" else "start states", worst=worst, examples=ex,
        details=details, notes=notes, t0=t0,
    )

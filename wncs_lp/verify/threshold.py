"""Theorem 2 (claim C8) and the switching-curve form of claim C9: the threshold check."""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..models import model_type
from ..solvers.result import Solution
from .context import (DEFAULT_EXAMPLES, PolicyContext, idle_configs, make_report, use_context, violation_weight,
                      witness_flags)
from .lines import (box_lines, gap_violation, gap_violations, line_structure, order_violation, order_violations,
                    states_on_lines, switching_orders, theorem2_direction)
from .report import CheckReport, Tolerance, Violation, pick_examples, split_counts

__all__ = ["check_threshold", "SITUATIONS", "situations"]


def check_threshold(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    configs: str | Sequence[int] | None = None,
    ctx: PolicyContext | None = None,
) -> CheckReport:
    r"""Theorem 2 (claim C8) for the Section II model; the switching-curve form for preemption.

    The model's :attr:`~wncs_lp.models.base.Model.threshold_form` says which reading applies.

    **Theorem 2's rays** (``threshold_form = "rays"``: the Section II model), in the idle-server
    configuration(s): for every
    reachable idle state s with ``pi(s) = a`` sending distinct processes ``k1 != k2`` (in general
    the set K of the processes a sends, |K| >= 2), and every ``z >= 1`` with
    ``s' = s + z * sum_{k in K} e_k`` reachable in the box, the claim is ``pi(s') = a``.
    If ``pi(s') != a`` the case is a *tie* when ``|Q(s', a) - Q(s', pi(s'))| <= tol`` (``a`` is
    optimal at s' within tol) and a *violation* otherwise; its size is
    ``Q(s', a) - Q(s', pi(s'))``. One case = one (s, z). A violation is recurrent when s and s'
    both are (``details["target_recurrent"]`` counts those with s' recurrent), at the cap when s
    or s' has some tau at its cap; ``details["violating_target_stationary_mass"]`` is the
    stationary probability of the distinct states s' where the claim fails.

    Sub-counts (``details["lines"]``, not part of the verdict for this model): whether each
    action's region is an *interval* on every line parallel to a tau axis and to every
    diagonal ``e_i + e_j`` -- a line has a gap for action a when two states choosing a enclose a
    reachable state that strictly prefers another action (beyond tol).

    **Switching curve** (``threshold_form = "intervals"``: the preemption model): Theorem 2 does
    not apply; claim C9 ("the preemption policy is of threshold type", Figs. 11-12: a monotone
    switching curve, an up-set in one AoI and a down-set in the other) is checked along each
    axis, in every configuration with at least two feasible actions:

    * *gaps* -- each action's region is an interval on every axis-parallel line (one case = one
      (line, action) pair where the action occurs);
    * *order reversals* -- on all parallel lines of one axis the policy switches between two
      actions in the same order (one case = one line on which both actions occur in order; a
      violation = a line of the minority order, see :func:`~wncs_lp.verify.lines.switching_orders`).

    The configurations are split by the decision they pose (:data:`SITUATIONS`): the figures'
    own, a job of process j in service and another process's update arrived but not j's (keep
    going or preempt, Figs. 11-12), decides ``holds`` and the counts; the configurations where
    j's own update arrived too (cancelling the job is an option) and those with a free server
    (which job to start) are checked the same way and reported apart in
    ``details["by_situation"]``, outside the verdict. A monotone switching curve may cross a
    diagonal line several times, so gaps along the diagonals e_i + e_j (every configuration) are
    counted in ``details["diagonal_gaps"]`` only, outside the verdict.

    Parameters
    ----------
    mdp, solution, tolerance, examples, stationary_tol, ctx
        As in :func:`check_monotonicity`.
    configs : "idle", "all" or sequence of configuration ids, optional
        Where to look ("all": every configuration with >= 2 feasible actions). Default: the
        model's :attr:`~wncs_lp.models.base.Model.threshold_configs` -- the idle configuration
        (Section II), "all" (preemption).

    Returns
    -------
    CheckReport
    """
    t0 = time.perf_counter()
    ctx = use_context(mdp, solution, tolerance, stationary_tol, ctx)
    model = model_type(mdp)
    form = model.threshold_form
    if form not in ("rays", "intervals"):
        raise ModelError(f"{mdp.name}: unknown threshold form {form!r} of {model.__name__}")
    cfg_ids = _configurations(mdp, ctx, model.threshold_configs if configs is None else configs)
    N = len(mdp.states.caps)
    axes_d: list[tuple[int, ...]] = [tuple(int(i == k) for i in range(N)) for k in range(N)]
    diagonals = [tuple(int(i in (a, b)) for i in range(N)) for a in range(N) for b in range(a + 1, N)]
    if form == "intervals":
        return _switching_curve(ctx, model, cfg_ids, axes_d, diagonals, examples, t0)
    return _rays(ctx, cfg_ids, axes_d + diagonals, examples, t0)


def _configurations(mdp: MDP, ctx: PolicyContext, configs: str | Sequence[int]) -> list[int]:
    """The configuration ids named by ``configs`` ("idle", "all" with >= 2 feasible actions, or ids)."""
    n_configs = len(mdp.states.configs)
    if not isinstance(configs, str):
        cfg_ids = [int(c) for c in configs]
        for c in cfg_ids:
            if not 0 <= c < n_configs:
                raise ModelError(f"configuration id {c} out of range 0..{n_configs - 1}")
        return cfg_ids
    if configs == "idle":
        cfg_ids = idle_configs(mdp)
        if not cfg_ids:
            raise ModelError(f"{mdp.name}: no idle-server configuration (is this a Section II model?)")
        return cfg_ids
    if configs == "all":
        nfeas = np.count_nonzero(ctx.offsets >= 0, axis=1)
        return [c for c in range(n_configs) if nfeas[c] >= 2]
    raise ModelError(f"configs must be 'idle', 'all' or a list of configuration ids, got {configs!r}")


#: The decisions of the preemption model's configurations (:func:`situations`); the first is the
#: figures' (Figs. 11-12) and decides the switching-curve check.
SITUATIONS = {
    "preemption": "a job in service, another process's update arrived (keep going or preempt: Figs. 11-12)",
    "cancel_option": "a job in service and its own process's update arrived (cancelling it is an option)",
    "server_free": "no job in service (which update to start)",
}


def situations(model, space, cfg_ids: Sequence[int]) -> dict[str, list[int]]:
    """The configuration ids split by the decision they pose (:data:`SITUATIONS`)."""
    out: dict[str, list[int]] = {k: [] for k in SITUATIONS}
    for c in cfg_ids:
        conf = space.configs[c]
        job = model.job_in_service(conf)
        if job is None:
            out["server_free"].append(c)
        elif model.arrived(conf)[job[0] - 1]:
            out["cancel_option"].append(c)
        else:
            out["preemption"].append(c)
    return out


def _switching_curve(ctx: PolicyContext, model, cfg_ids: list[int], axes_d: list[tuple[int, ...]],
                     diagonals: list[tuple[int, ...]], examples: int, t0: float) -> CheckReport:
    """The C9 reading (preemption model): every action region an interval on every axis-parallel
    line (one switch per pair of actions), and the switches in one order on all parallel lines (a
    monotone curve), decided on the figures' situation (preemption decisions); the other
    situations apart; diagonal gaps are a described statistic only."""
    by = {name: _curve_in(ctx, ids, axes_d, examples) for name, ids in situations(model, ctx.mdp.states, cfg_ids).items()}
    head = by["preemption"]
    diag_summary, dgaps = line_structure(ctx, cfg_ids, diagonals)
    drec, dcap, _ = gap_violations(ctx, dgaps)
    details = {
        "axis_lines": head["axis_lines"],
        "axis_orders": head["axis_orders"],
        "gaps": head["gaps"],
        "reversals": head["reversals"],
        "by_situation": {name: {"meaning": SITUATIONS[name], **{k: v for k, v in r.items()
                                                               if k not in ("rec", "cap", "obs", "witnesses",
                                                                            "examples_v", "worst_v")},
                                "examples": [v.to_json() for v in r["examples_v"][:3]]}
                         for name, r in by.items()},
        "diagonal_gaps": {"count": len(dgaps), "split": split_counts(drec, dcap), "lines": diag_summary,
                          "note": "not violations: a monotone switching curve may cross a diagonal "
                                  "tau_i + tau_j = const several times"},
        "configurations": len(cfg_ids),
        "configurations_in_scope": head["configurations"],
    }
    notes = ("Preemption model: Theorem 2 is stated for the Section II model; here the C9 reading is checked, the "
             "switching-curve (threshold) property along each axis, decided in the figures' situation (a job in "
             "service and another process's update arrived, not its own: keep going or preempt): each action's region "
             "is an interval on every axis-parallel line ('line-gap' violations, one case per (line, action) pair), "
             "and the policy switches between two actions in the same order on all parallel lines ('order-reversal' "
             "violations, one case per line ordering a pair of actions). Tie-robust. The configurations where the "
             "job's own process arrived too (cancelling is an option) and those with a free server are checked the "
             "same way and reported in details.by_situation, outside the verdict; gaps along the diagonals in "
             "details.diagonal_gaps.")
    return make_report("threshold", "C9 (Figs. 11-12): preemption policy of threshold (switching-curve) type", ctx,
                       holds=head["violations"] == 0, checked=head["checked"], violations=head["violations"],
                       rec=head["rec"], cap=head["cap"], ties=0,
                       unit="(line, action) pairs and ordered (line, action pair)s", worst=head["worst_v"],
                       examples=head["examples_v"], details=details, notes=notes, t0=t0,
                       witnesses=head["witnesses"], obs=head["obs"])


def _curve_in(ctx: PolicyContext, cfg_ids: list[int], axes_d: list[tuple[int, ...]], examples: int) -> dict:
    """The switching-curve check along the axes in some configurations: the counts, the split, the
    per-violation flags and witnesses, the examples (best witness class first, farthest from the cap)."""
    axis_summary, gaps = line_structure(ctx, cfg_ids, axes_d)
    order_summary, revs = switching_orders(ctx, cfg_ids, axes_d)
    grec, gcap, gsize = gap_violations(ctx, gaps)
    orec, ocap, osize = order_violations(ctx, revs)
    rec = np.concatenate([grec, orec])
    cap = np.concatenate([gcap, ocap])
    size = np.concatenate([gsize, osize])
    witnesses = [g[3:6] for g in gaps] + [r[4] for r in revs]
    obs, dist = witness_flags(ctx, witnesses, rec)

    def make(i: int) -> Violation:
        if i < len(gaps):
            return gap_violation(ctx, gaps[i], grec[i], gcap[i])
        j = i - len(gaps)
        return order_violation(ctx, revs[j], orec[j], ocap[j])

    gobs, oobs = obs[:len(gaps)], obs[len(gaps):]
    return {
        "configurations": len(cfg_ids),
        "checked": (sum(v["checked"] for v in axis_summary.values())
                    + sum(v["ordered_line_pairs"] for v in order_summary.values())),
        "violations": len(gaps) + len(revs),
        "split": split_counts(rec, cap, obs),
        "weight": violation_weight(ctx, witnesses, rec, cap, obs),
        "gaps": {"count": len(gaps), "split": split_counts(grec, gcap, gobs)},
        "reversals": {"count": len(revs), "split": split_counts(orec, ocap, oobs)},
        "axis_lines": axis_summary,
        "axis_orders": order_summary,
        "rec": rec, "cap": cap, "obs": obs, "witnesses": witnesses,
        "examples_v": [make(int(i)) for i in pick_examples(rec, cap, size, examples, obs, dist)],
        "worst_v": make(int(np.argmax(np.abs(size)))) if size.size else None,
    }


def _rays(ctx: PolicyContext, cfg_ids: list[int], directions: list[tuple[int, ...]], examples: int,
          t0: float) -> CheckReport:
    """Theorem 2 (Section II model): along every ray ``s + z sum_{k in K} e_k`` of an idle state s
    whose action sends the processes K, the same action; the line structure beside it."""
    space = ctx.mdp.states
    line_summary, gaps = line_structure(ctx, cfg_ids, directions)
    grec, gcap, gsize = gap_violations(ctx, gaps)
    found = _ray_cases(ctx, cfg_ids)
    R, size = found["rows"], found["size"]
    rec = (ctx.recurrent[R[:, 0]] & ctx.recurrent[R[:, 1]]) if R.size else np.zeros(0, bool)
    cap = (ctx.at_cap[R[:, 0]] | ctx.at_cap[R[:, 1]]) if R.size else np.zeros(0, bool)

    def make(i: int) -> Violation:
        s, t, z, a = (int(x) for x in R[i])
        return ctx.violation(
            "ray", size[i], (s, t), rec[i], cap[i],
            {"z": z, "action_at_s": list(ctx.action(a)), "action_at_s_prime": list(ctx.action(ctx.act[t])),
             "Q_claimed": float(ctx.q_of(np.array([t]), np.array([a]))[0]), "Q_chosen": float(ctx.q_pi[t]),
             "recurrent_each": [bool(ctx.recurrent[s]), bool(ctx.recurrent[t])],
             "meaning": "pi(s) = action_at_s but at s' = s + z(e_k1 + e_k2) the claimed action is worse by size"},
        )

    obs, dist = witness_flags(ctx, R[:, :2], rec)
    ex = [make(int(i)) for i in pick_examples(rec, cap, size, examples, obs, dist)]
    worst = make(int(np.argmax(np.abs(size)))) if size.size else None
    targets = np.unique(R[:, 1]) if R.size else np.zeros(0, np.int64)
    details = {
        "configurations": [space.describe_config(space.configs[c]) for c in cfg_ids],
        "source_states": found["sources"],
        "violating_source_states": int(np.unique(R[:, 0]).size) if R.size else 0,
        "violating_target_states": int(targets.size),
        "target_recurrent": int(np.count_nonzero(ctx.recurrent[R[:, 1]])) if R.size else 0,
        "violating_target_stationary_mass": (None if ctx.stationary is None
                                             else float(ctx.stationary[targets].sum())),
        "per_action": found["per_action"],
        "lines": line_summary,
        "line_gaps": {"count": len(gaps), "split": split_counts(grec, gcap),
                      "examples": [gap_violation(ctx, gaps[int(i)], grec[i], gcap[i]).to_json()
                                   for i in pick_examples(grec, gcap, gsize, examples,
                                                          *witness_flags(ctx, [g[3:6] for g in gaps], grec))]},
    }
    notes = ("Theorem 2 in the idle-server configuration: one case per (s, z); ties (claimed action optimal at s' "
             "within tol) are not violations. 'details.lines' reports, separately and outside the verdict, whether "
             "every action region is an interval along each tau axis and each diagonal e_i + e_j.")
    return make_report(
        "threshold", "Theorem 2 (C8): pi(s) = (k1, k2) => pi(s + z(e_k1 + e_k2)) = (k1, k2) in idle states",
        ctx, holds=(R.shape[0] == 0), checked=found["checked"], violations=R.shape[0], rec=rec, cap=cap,
        ties=found["ties"], unit="(state, z) pairs", worst=worst, examples=ex, details=details, notes=notes, t0=t0,
        witnesses=R[:, :2], obs=obs,
    )


def _ray_cases(ctx: PolicyContext, cfg_ids: list[int]) -> dict:
    """Every case (s, z) of Theorem 2: the violations as rows (s, s', z, action at s) with their
    sizes ``Q(s', a) - Q(s', pi(s'))``, and the counts (cases, ties, sources, per action)."""
    mdp = ctx.mdp
    space = mdp.states
    caps = tuple(int(c) for c in space.caps)
    table = mdp.action_table
    dir_of = {a: theorem2_direction(tuple(int(x) for x in np.atleast_1d(table[a])), len(caps))
              for a in range(table.shape[0])}
    out = {"checked": 0, "ties": 0, "sources": 0, "per_action": {}}
    rows: list[np.ndarray] = []  # columns: s, s', z, a
    sizes: list[np.ndarray] = []
    for d in sorted({d for d in dir_of.values() if d is not None}):
        lines = box_lines(caps, d)
        L = lines.shape[1]
        if L < 2:
            continue
        iu, ju = np.triu_indices(L, 1)
        acts_d = np.array([a for a, dd in dir_of.items() if dd == d], dtype=np.int64)
        for c in cfg_ids:
            S, _ = states_on_lines(space, lines, c)
            src, tgt = S[:, iu], S[:, ju]
            zz = np.broadcast_to(ju - iu, src.shape)
            ok = (src >= 0) & (tgt >= 0)
            ok[ok] &= np.isin(ctx.act[src[ok]], acts_d)
            s, t, z = src[ok], tgt[ok], zz[ok]
            a = ctx.act[s]
            out["checked"] += s.size
            out["sources"] += int(np.count_nonzero(np.isin(ctx.act[S[(S >= 0)]], acts_d)))
            diff_act = ctx.act[t] != a
            gap = ctx.q_of(t, a) - ctx.q_pi[t]
            tie = diff_act & (np.abs(gap) <= ctx.tol)
            bad = diff_act & ~tie
            out["ties"] += int(np.count_nonzero(tie))
            for aa in np.unique(a):
                e = out["per_action"].setdefault(str(ctx.action(aa)), {"checked": 0, "violations": 0, "ties": 0})
                m = a == aa
                e["checked"] += int(np.count_nonzero(m))
                e["violations"] += int(np.count_nonzero(bad & m))
                e["ties"] += int(np.count_nonzero(tie & m))
            rows.append(np.stack([s[bad], t[bad], z[bad], a[bad]], axis=1))
            sizes.append(gap[bad])
    out["rows"] = np.concatenate(rows) if rows else np.zeros((0, 4), np.int64)
    out["size"] = np.concatenate(sizes) if sizes else np.zeros(0)
    return out

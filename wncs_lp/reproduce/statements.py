"""Statements of the paper with no figure of their own: C14 (case 1 is the static policy), C15 (only
the upper-left corner of Fig. 4 differs from static), C16 (preemption and the server's idle time).

Each reuses the solves of the figures' claims (C1, C2 and C3, C11: read from the run's cache, never
solved twice) and is decided like them: at the least truncated cap computed, a more truncated cap
only adding a caveat (:func:`wncs_lp.verify.verdict.subclaims_verdict`, :func:`cap_basis`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..models.system import System
from ..policies import StaticPolicy, default_assignment
from ..solvers.certify import q_values
from ..verify import Tolerance, idle_configs
from ..verify.verdict import EQ_RTOL, SIGNIFICANT, structural_verdict, subclaims_verdict
from .context import ClaimResult, Context, Solved, Step, Table, assignment_label, cap_basis, evidence
from .performance import subclaim_table, subclaims_json, caveat_words
from .structural import state_split, mass_words, pct, shown_words

__all__ = ["claim_c14", "claim_c15", "claim_c16", "static_disagreement", "idle_share", "UNCAPPED"]

#: The caps at which C14 evaluates the static policy on each process's own chain, to read its
#: uncapped value (the static policy sends each process to its own server, so the processes do
#: not interact and the two chains are exact; equal values at both caps: converged).
UNCAPPED = (100, 200)
#: An idle share at most this is no idle time (the round-off of ``1 - sum pi busy``).
IDLE_TOL = 1e-12


def static_disagreement(solved: Solved, assignment) -> dict[str, Any]:
    """Where the static policy's action is strictly worse than the optimal one.

    A state *differs* when the static rule's action at s is worse than the optimal action by more
    than the verifiers' tie tolerance in the optimal solution's pair values,
    ``Q(s, static(s)) - Q(s, pi*(s)) > tol`` (so ties never count). Returns the mask of those
    states, the idle-server mask, and the Q-gap (for the largest one).
    """
    mdp = solved.mdp
    q = q_values(mdp, solved.bias)
    tol = Tolerance().resolve(float(np.ptp(solved.bias)) if mdp.n_states else 0.0)  # the verifiers' tie tolerance
    static = StaticPolicy(System.from_scenario(solved.scenario), assignment).on_mdp(mdp)
    gap = q[static] - q[solved.policy]
    differ = gap > tol
    idle = np.isin(np.asarray(mdp.states.config), idle_configs(mdp))
    return {"differ": differ, "idle": idle, "gap": gap, "tol": tol}


# ============================================================================ C14
def _uncapped_static(sc, assignment) -> dict[str, Any]:
    """The static policy's uncapped average cost: the sum over processes of each one's own chain
    (its server alone; the static policy gives each process its own server here) at the caps of
    :data:`UNCAPPED`."""
    from ..evaluate import evaluate
    from ..models import build
    from ..scenario import load_scenario

    out = {}
    for cap in UNCAPPED:
        big = load_scenario(sc.source, [f"tau_cap={cap}", f"p={sc.p}"])
        model = System.from_scenario(big).model
        total = 0.0
        for k in range(big.n_processes):
            own = model.private_scenario(k)
            system = System.from_scenario(own)
            total += evaluate(build(own), StaticPolicy(system, [assignment[k]]), system, multichain="initial").gain
        out[cap] = total
    return out


def claim_c14(ctx: Context) -> ClaimResult:
    """Sec. V: "the optimal policy in case 1 is entirely equal to the static policy"."""
    prof = ctx.profile
    rows, ev = [], []
    sub: dict[str, dict[int, bool | None]] = {"same average cost as static": {},
                                             "static's action optimal in every recurrent state of weight": {}}
    for cap in prof.caps_2p:
        sc = ctx.scenario("paper_p14.toml", [f"tau_cap={cap}"])
        solved = ctx.solve(sc)
        a = default_assignment(sc)
        g_static = ctx.evaluate(sc, "static", a)["gain"]
        gap = (g_static - solved.gain) / solved.gain
        d = static_disagreement(solved, a)
        split = state_split(solved, np.flatnonzero(d["differ"]))
        sub["same average cost as static"][cap] = bool(abs(gap) <= EQ_RTOL)
        sub["static's action optimal in every recurrent state of weight"][cap] = split["observable_below_cap"] == 0
        v = "HOLDS" if all(sub[k][cap] for k in sub) else "FAILS"
        rows.append({"cap": cap, "optimal": solved.gain, "optimal_lower": solved.gain_lower,
                     "optimal_upper": solved.gain_upper, "static": g_static, "static_assignment": assignment_label(sc, a),
                     "gap_static": gap, "states": solved.mdp.n_states, "differing_states": split["total"],
                     "differing_recurrent": split["recurrent"], "differing_observable_below_cap":
                     split["observable_below_cap"], "differing_idle": int(np.count_nonzero(d["differ"] & d["idle"])),
                     "differing_stationary_mass": split["stationary_mass"], "shown": shown_words(split),
                     "verdict": v, "cap_mass": solved.cap_mass.total})
        ev.append(solved.evidence(f"processes 1, 4 at cap {cap}", v))
    sc = ctx.scenario("paper_p14.toml", [f"tau_cap={prof.caps_2p[-1]}"])
    a = default_assignment(sc)
    unc, _ = ctx.cache.get_or_compute("c14-uncapped", {"fingerprint": sc.fingerprint(), "assignment": list(a)},
                                      lambda: ({str(k): v for k, v in _uncapped_static(sc, a).items()}, None))
    uncapped = {int(k): v for k, v in unc.items()}
    verdict = subclaims_verdict(sub)
    dec = rows[-1]
    g_inf = uncapped[UNCAPPED[-1]]
    converged = abs(uncapped[UNCAPPED[0]] - g_inf) <= 1e-12 * g_inf
    steps = "; ".join(f"{rows[i]['optimal'] - rows[i - 1]['optimal']:+.4g} from cap {rows[i - 1]['cap']} to "
                      f"{rows[i]['cap']}" for i in range(1, len(rows)))
    summary = (f"At cap {dec['cap']}, the least truncated ({pct(dec['cap_mass'], 3)} of the time at the cap), which "
               f"decides, static ({dec['static_assignment']}) costs {dec['static']:.6g} against the optimal "
               f"{dec['optimal']:.6g}: {pct(dec['gap_static'])} more, and its action is strictly worse in "
               f"{dec['differing_states']:,} states, {dec['differing_observable_below_cap']:,} of them recurrent, of "
               f"weight and below the cap (stationary mass {mass_words(dec['differing_stationary_mass'])}); uncapped, "
               f"static costs {g_inf:.6g} ({pct((g_inf - dec['optimal']) / dec['optimal'])} above the cap-"
               f"{dec['cap']} optimum, which moves by {steps})" + caveat_words(sub) + ".")
    shown = [subclaim_table(sub, prof.caps_2p, "Each sub-claim at each cap; the largest cap decides."),
             Table("Processes 1, 4 at p = 0.9: the optimal average MSE (its certified bracket) against the static "
                   "policy, and the states where the static rule's action is strictly worse than the optimal one "
                   "(beyond the tie tolerance); shown: the one farthest from the cap, with its weight.",
                   ["cap", "optimal", "static", "assignment", "static above optimal", "states", "static worse in",
                    "recurrent", "of weight, below the cap", "idle-server states", "their stationary mass", "shown",
                    "mass at the cap"],
                   [[r["cap"], r["optimal"], r["static"], r["static_assignment"], pct(r["gap_static"], 3), r["states"],
                     r["differing_states"], r["differing_recurrent"], r["differing_observable_below_cap"],
                     r["differing_idle"], mass_words(r["differing_stationary_mass"]), r["shown"], pct(r["cap_mass"])]
                    for r in rows]),
             Table("The uncapped trend: the static policy without a cap (each process on its own server, evaluated "
                   "exactly on its own chain at a cap where its AoI never reaches it), and the optimal average MSE as "
                   "the cap grows (nondecreasing: each cap's optimum is a lower bound on the uncapped one).",
                   ["quantity", "value"],
                   [[f"static, uncapped (own chains at cap {c})", v] for c, v in uncapped.items()]
                   + [[f"optimal at cap {r['cap']}", r["optimal"]] for r in rows])]
    tab = ctx.save_table(rows, "c14_case1_static")
    details = ("The paper: \"Since the optimal policy in case 1 is entirely equal to the static policy, performance "
               "simulation is only performed for case 2.\" Checked on the cost (equal within the relative tolerance "
               f"{EQ_RTOL:g}) and state by state: the static rule's action against the optimal one in the optimal "
               "solution's pair values, ties not counted. C1 checks the idle-server states only, C12 the perfect "
               "channel. The static policy's uncapped value "
               + ("converged" if converged else "did NOT converge") + f" ({', '.join(f'{v:.10g} at cap {c}' for c, v in uncapped.items())}).")
    return ClaimResult("C14", "Sec. V", "", verdict, summary,
                       {"rows": rows, "subclaims": subclaims_json(sub),
                        "static_uncapped": {str(k): v for k, v in uncapped.items()}, "static_uncapped_converged": converged},
                       [], [tab], details, basis=cap_basis(ev, verdict), shown=shown)


# ============================================================================ C15
def claim_c15(ctx: Context) -> ClaimResult:
    """Sec. V: "in Fig. 4, only the upper left corner is different from the static policy", and "the
    lower the transmission success probability, the easier it is to reach these different states"."""
    prof = ctx.profile
    rows, ev = [], []
    for cap in prof.caps_2p:
        sc = ctx.scenario("paper_p12.toml", [f"tau_cap={cap}"])
        solved = ctx.solve(sc)
        d = static_disagreement(solved, default_assignment(sc))
        tau = solved.mdp.states.tau
        corner = d["differ"] & d["idle"] & (tau[:, 1] > tau[:, 0])
        outside = d["differ"] & ~corner
        s_out = state_split(solved, np.flatnonzero(outside))
        s_all = state_split(solved, np.flatnonzero(d["differ"]))
        s_corner = state_split(solved, np.flatnonzero(corner))
        v = structural_verdict(s_out["total"] == 0, s_out["recurrent_below_cap"], s_out["observable_below_cap"])
        rows.append({"cap": cap, "states": solved.mdp.n_states, "differing": s_all["total"],
                     "differing_recurrent": s_all["recurrent"], "differing_mass": s_all["stationary_mass"],
                     "corner": s_corner["total"], "corner_mass": s_corner["stationary_mass"],
                     "outside": s_out["total"], "outside_recurrent": s_out["recurrent"],
                     "outside_observable_below_cap": s_out["observable_below_cap"],
                     "outside_idle": int(np.count_nonzero(outside & d["idle"])),
                     "outside_mass": s_out["stationary_mass"], "shown": shown_words(s_out), "verdict": v,
                     "cap_mass": solved.cap_mass.total})
        ev.append(solved.evidence(f"processes 1, 2 at cap {cap}", v))
    basis = cap_basis(ev)
    verdict = basis["verdict"]
    # "the lower p, the easier to reach these states": their stationary mass over p at the largest cap (C3's solves)
    cap = prof.caps_2p[-1]
    steps = [Step(ctx.scenario("paper_p12.toml", [f"tau_cap={cap}", f"p={p}"])) for p in prof.p_grid]
    ctx.prefetch(steps)
    by_p = []
    for st in steps:
        solved = ctx.solve(st.scenario)
        d = static_disagreement(solved, default_assignment(st.scenario))
        by_p.append({"p": st.scenario.p, "differing": int(np.count_nonzero(d["differ"])),
                     "differing_mass": float(np.asarray(solved.stationary)[d["differ"]].sum())})
    masses = [r["differing_mass"] for r in by_p]
    falls = all(b <= a + 1e-15 for a, b in zip(masses, masses[1:]))
    dec = rows[-1]
    weights = ", ".join(f"{mass_words(r['differing_mass'])} at p = {r['p']:g}" for r in by_p)
    summary = (f"At cap {dec['cap']}, the least truncated ({pct(dec['cap_mass'], 3)} of the time at the cap), which "
               f"decides, the static rule's action is strictly worse in {dec['differing']:,} states ({dec['corner']:,} "
               f"in the upper-left corner of the idle-server map, stationary mass {mass_words(dec['corner_mass'])}), "
               f"{dec['outside']:,} of them outside it ({dec['outside_idle']:,} idle-server states, the others with a "
               f"server busy), {dec['outside_observable_below_cap']:,} of those recurrent, of weight and below the cap "
               f"(stationary mass {mass_words(dec['outside_mass'])}; shown: {dec['shown'] or 'none'}); the states where "
               f"they differ weigh {weights} ({'falling' if falls else 'not falling'} as p grows)"
               + "".join(f"; {'caveat, at a more truncated cap: ' if r['verdict'] != dec['verdict'] else ''}cap "
                         f"{r['cap']}: {r['outside']:,} outside the corner, {r['outside_observable_below_cap']:,} of "
                         f"weight below the cap" for r in rows[:-1]) + ".")
    shown = [Table("Processes 1, 2 at p = 0.9: the states where the static rule's action (1 to remote, 2 to edge) is "
                   "strictly worse than the optimal one (beyond the tie tolerance), in the upper-left corner of the "
                   "idle-server map (tau_2 > tau_1) and outside it; the structural rule on those outside; the largest "
                   "cap decides.",
                   ["cap", "states", "static worse in", "recurrent", "their mass", "in the corner", "corner mass",
                    "outside", "outside, idle-server", "outside, recurrent", "outside, of weight below the cap",
                    "outside mass", "shown", "verdict", "mass at the cap"],
                   [[r["cap"], r["states"], r["differing"], r["differing_recurrent"], mass_words(r["differing_mass"]),
                     r["corner"], mass_words(r["corner_mass"]), r["outside"], r["outside_idle"], r["outside_recurrent"],
                     r["outside_observable_below_cap"], mass_words(r["outside_mass"]), r["shown"], r["verdict"],
                     pct(r["cap_mass"])] for r in rows]),
             Table(f"At cap {cap}: the states where static is strictly worse, and their stationary probability under "
                   "the optimal policy, over p (the paper: the lower p, the easier they are reached; at p = 1 never).",
                   ["p", "static worse in", "stationary mass"],
                   [[r["p"], r["differing"], mass_words(r["differing_mass"])] for r in by_p])]
    tab = ctx.save_table(rows, "c15_where_static_differs")
    details = ("The paper (Sec. V, on Fig. 5): \"This is because the optimal policy in Fig. 4, only the upper left "
               "corner is different from the static policy, and the lower the transmission success probability, the "
               "easier it is to reach these different states. When the transmission success probability is 1, these "
               "states will not be reached at all.\" Checked over every state (every configuration, not only the "
               "idle-server map of Fig. 4): the static rule's action against the optimal one in the optimal solution's "
               "pair values, ties not counted; the states outside the corner are judged by the structural rule (FAILS: "
               "some recurrent, of weight and below the cap). The weight over p is reported beside, outside the verdict.")
    return ClaimResult("C15", "Sec. V", "", verdict, summary, {"rows": rows, "by_p": by_p, "mass_falls_with_p": falls},
                       [], [tab], details, basis=basis, shown=shown)


# ============================================================================ C16
def idle_share(solved: Solved) -> float:
    """The long-run share of slots in which the one server performs no service step under the
    optimal policy: ``1 - sum_s pi(s) busy(C(s), a(s))`` (:attr:`Solved.utilisation`, stored with
    the solve: a job in service at the start of the slot, or one started by the action)."""
    return float(1.0 - solved.utilisation[0])


def claim_c16(ctx: Context) -> ClaimResult:
    """Sec. IV: "Work with the preemption mechanism, it can significantly reduce the idle time of the
    server without reducing the system performance." """
    prof = ctx.profile
    ps, caps = list(prof.p_grid), list(prof.caps_pre)

    def scenarios(cap: int, p: float):
        over = [f"tau_cap={cap}", f"p={p}"]
        return (ctx.scenario("paper_preemption_p12.toml", over),
                ctx.scenario("paper_preemption_p12.toml", over + ["model.preemptive=false"]))

    ctx.prefetch([Step(sc) for cap in sorted(caps, reverse=True) for p in ps for sc in scenarios(cap, p)])
    rows = []
    for cap in caps:
        for p in ps:
            pre, non = (ctx.solve(sc) for sc in scenarios(cap, p))
            i_pre, i_non = idle_share(pre), idle_share(non)
            rows.append({"cap": cap, "p": p, "idle_preemptive": i_pre, "idle_non_preemptive": i_non,
                         "idle_reduction_rel": (i_non - i_pre) / i_non if i_non > IDLE_TOL else 0.0,
                         "performance_not_reduced": bool(pre.gain <= non.gain * (1 + EQ_RTOL)),
                         "cap_mass": max(pre.cap_mass.total, non.cap_mass.total)})
    red = {c: np.array([r["idle_reduction_rel"] for r in rows if r["cap"] == c]) for c in caps}
    idles = {c: np.array([r["idle_non_preemptive"] > IDLE_TOL for r in rows if r["cap"] == c]) for c in caps}
    trunc = {c: (np.abs(red[c] - red[caps[i - 1]]) if i else np.zeros_like(red[c])) for i, c in enumerate(caps)}
    lower, significant = ("idle time lower with preemption wherever the server idles",
                          f"reduced by at least {SIGNIFICANT:.0%} (significantly) wherever the server idles")
    sub: dict[str, dict[int, bool | None]] = {lower: {}, significant: {}, "performance not reduced": {}}
    for c in caps:
        m = idles[c]  # a p where the server never idles without preemption has no idle time to reduce
        sub[lower][c] = bool(np.all(red[c][m] > 0)) if m.any() else None
        if not m.any():
            sig: bool | None = None
        elif np.all(red[c][m] - trunc[c][m] >= SIGNIFICANT):
            sig = True
        elif np.any(red[c][m] + trunc[c][m] < SIGNIFICANT):
            sig = False
        else:
            sig = None  # on the bar within the truncation effect
        sub[significant][c] = sig
        sub["performance not reduced"][c] = all(r["performance_not_reduced"] for r in rows if r["cap"] == c)
    verdict = subclaims_verdict(sub)
    ev = []
    for c in caps:
        at = [r for r in rows if r["cap"] == c]
        top = max(at, key=lambda r: r["cap_mass"])
        ok = all(sub[k][c] is not False for k in sub)
        ev.append(evidence(f"preemption and no preemption, processes 1, 2 at cap {c} (largest mass over p and the "
                           f"two models, at p = {top['p']:g})", c, top["cap_mass"], "HOLDS" if ok else "FAILS",
                           "paper_preemption_p12", top["p"]))
    c = caps[-1]
    at = [r for r in rows if r["cap"] == c]
    summary = (f"At cap {c}, the least truncated ({pct(max(r['cap_mass'] for r in at))} of the time at the cap at "
               f"worst), which decides, the server is idle {span_words_pct([r['idle_non_preemptive'] for r in at])} of "
               f"the time without preemption and {span_words_pct([r['idle_preemptive'] for r in at])} with it "
               f"(p = {ps[0]:g} to {ps[-1]:g}): preemption changes its idle time by "
               + ", ".join((f"{-100 * r['idle_reduction_rel']:+.2f}%" if r["idle_non_preemptive"] > IDLE_TOL else
                            "nothing (no idle time without it)") + f" at p = {r['p']:g}" for r in at)
               + (f" (the truncation effect, its change from cap {caps[-2]}: up to {pct(trunc[c].max())})"
                  if len(caps) > 1 else "")
               + f"; the optimal average MSE is {'never' if sub['performance not reduced'][c] else 'sometimes'} "
                 "higher with preemption" + caveat_words(sub) + ".")
    shown = [subclaim_table(sub, caps, "Each sub-claim at each cap (n/a: not decided, within the truncation "
                                        "effect); the largest cap decides."),
             Table("The server's idle share (long-run fraction of slots without a service step) under each optimal "
                   "policy, with and without preemption, per cap and p; reduction relative to no preemption.",
                   ["cap", "p", "idle, no preemption", "idle, preemption", "reduction", "MSE not higher",
                    "mass at the cap (larger of the two)"],
                   [[r["cap"], r["p"], pct(r["idle_non_preemptive"], 3), pct(r["idle_preemptive"], 3),
                     pct(r["idle_reduction_rel"], 2), r["performance_not_reduced"], pct(r["cap_mass"])] for r in rows])]
    tab = ctx.save_table(rows, "c16_idle_time")
    details = ("The paper (Sec. IV): \"The controller may be idle if only one status is allowed to send the state to "
               "controller at a slot. Moreover, the worse the channel, the longer the controller will be idle. [...] "
               "Work with the preemption mechanism, it can significantly reduce the idle time of the server without "
               "reducing the system performance.\" The idle share is read from the model's busy table (a job in "
               "service, or one started by the action), weighted by each optimal policy's stationary law; "
               f"\"significantly\" with the report's bar of significance ({SIGNIFICANT:.0%} relative), decided only "
               "beyond the truncation effect (the change from the previous cap). The solves are C11's.")
    return ClaimResult("C16", "Sec. IV", "", verdict, summary, {"rows": rows, "subclaims": subclaims_json(sub)},
                       [], [tab], details, basis=cap_basis(ev, verdict), shown=shown)


def span_words_pct(values: list[float]) -> str:
    """"a% to b%" (two decimals), or one percentage when equal."""
    lo, hi = pct(min(values)), pct(max(values))
    return lo if lo == hi else f"{lo} to {hi}"

"""Claims about the optimal policy's structure: C1, C2, C4, C5 (maps), C7-C10 (theorems).

Every claim is judged at every cap the profile solves, and says which caps its verdict rests on
(:func:`~wncs_lp.reproduce.context.cap_basis`). Structural findings are decided by the one rule
of :mod:`wncs_lp.verify.verdict`, shared with ``wncs-lp verify``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..policy_grids import NEIGHBOURS, action_name, region_stats, slice_grid
from ..verify import check_consistency, check_monotonicity, check_threshold, policy_context
from ..verify.verdict import NEGLIGIBLE, across, cap_distance, combine, structural_verdict, verdict_of, witness_rank
from ..viz import plot_policy_map, plot_policy_slice, subplots
from .context import ClaimResult, Context, Solved, Step, Table, cap_basis

CONFIGURATION_NOTE = ("Recurrent: the state lies in a closed class of the optimal policy's chain (positive stationary "
                      "probability); at the cap: some AoI equals its cap.")


def pct(x: float | None, digits: int = 2) -> str:
    """A share as a percentage; "n/a" for None; never "-0.00%" (round-off below the last digit shows as 0)."""
    if x is None:
        return "n/a"
    y = round(100 * float(x), digits)
    return f"{y + 0.0:.{digits}f}%"


def _idle_ids(solved: Solved) -> np.ndarray:
    """State ids over the tau box in the idle-server configuration."""
    mdp = solved.mdp
    grid = mdp.states.lookup_grid(mdp.states.model.initial_config())
    return grid[grid >= 0]


def state_split(solved: Solved, states: np.ndarray) -> dict[str, Any]:
    """The states where a map claim fails: how many, recurrent / transient, at the cap, observable
    (recurrent, visited at least NEGLIGIBLE of the time) and below the cap, their stationary
    probability under the optimal policy (the weight of the counterexample), and the witness shown
    (``shown``: the best by the verifiers' order -- observable and below the cap first -- then the
    farthest from the cap, with its weight)."""
    states = np.asarray(states, np.int64)
    rec = solved.recurrent[states]
    caps = np.asarray(solved.mdp.states.caps)
    tau = solved.mdp.states.tau[states]
    at_cap = np.any(tau == caps, axis=1)
    law = np.asarray(solved.stationary)[states]
    obs = rec & (law >= NEGLIGIBLE)
    out = {
        "total": int(states.size),
        "recurrent": int(rec.sum()),
        "transient": int((~rec).sum()),
        "at_cap": int(at_cap.sum()),
        "recurrent_below_cap": int((rec & ~at_cap).sum()),
        "observable_below_cap": int((obs & ~at_cap).sum()),
        "stationary_mass": float(law.sum()),
    }
    if states.size:
        dist = cap_distance(tau, caps)
        i = int(np.lexsort((-law, -dist, witness_rank(rec, at_cap, obs)))[0])
        out["shown"] = {"state": int(states[i]), "tau": [int(x) for x in tau[i]], "cap_distance": int(dist[i]),
                        "stationary": float(law[i]), "recurrent": bool(rec[i])}
    return out


def _map_verdict(split: dict[str, Any]) -> str:
    """The structural rule on the states where a map claim fails."""
    return structural_verdict(split["total"] == 0, split["recurrent_below_cap"], split["observable_below_cap"])


def shown_words(split: dict[str, Any]) -> str:
    """The witness shown of a map claim's states, e.g. "tau = (6, 15), 14 from the cap, weight 2.1e-06"."""
    w = split.get("shown")
    if not w:
        return ""
    return (f"tau = ({', '.join(map(str, w['tau']))}), {w['cap_distance']} from the cap, "
            f"{'weight ' + mass_words(w['stationary']) if w['recurrent'] else 'transient'}")


def span_words(values: Sequence[float], digits: int = 2) -> str:
    """``"a% to b%"``, or one percentage when all are equal at the shown digits."""
    lo, hi = pct(min(values), digits), pct(max(values), digits)
    return lo if lo == hi else f"{lo} to {hi}"


def _mass_at_most(m: float | None) -> str:
    """"stationary mass 0" or "stationary mass at most m"."""
    return "stationary mass 0" if m == 0 else f"stationary mass at most {mass_words(m)}"


def mass_words(m: float | None) -> str:
    """A stationary probability for the text: "0" when exactly none, else three significant digits."""
    if m is None:
        return "n/a"
    return "0" if m == 0 else f"{m:.3g}"


def tidy_ticks(ax, cap_x: int, cap_y: int) -> None:
    """Readable integer ticks on a policy map (1, 5, 10, ... above cap 15, so labels never collide)."""
    def ticks(c: int) -> list[int]:
        if c <= 15:
            return list(range(1, c + 1))
        step = 5 if c <= 40 else 10
        return [1] + list(range(step, c + 1, step))

    ax.set_xticks(ticks(cap_x))
    ax.set_yticks(ticks(cap_y))


def _maps_figure(ctx: Context, panels: list[tuple[Solved, Any, dict]], stem: str, suptitle: str) -> list[str]:
    n = len(panels)
    fig, axes = subplots(1, n, figsize=(6.6 * n, 5.8), squeeze=False)
    for ax, (solved, config, kw) in zip(axes[0], panels):
        plot_policy_map(solved.mdp, solved.as_solution(), config, ax=ax, stationary=solved.stationary,
                        scenario=solved.scenario, **kw)
        caps = solved.mdp.states.caps
        i, j = kw.get("axes", (1, 2))
        tidy_ticks(ax, caps[i - 1], caps[j - 1])
    fig.suptitle(suptitle)
    fig.tight_layout()
    return ctx.save_figure(fig, stem)


def _idle_maps(ctx: Context, solves: list[Solved], stem: str, title: str) -> list[str]:
    """The idle-server maps over (tau_1, tau_2) at the smallest and the largest cap."""
    panels = [(s, "idle", {"axes": (1, 2)}) for s in (solves[:1] + solves[-1:] if len(solves) > 1 else solves)]
    return _maps_figure(ctx, panels, stem, f"{title}, caps " + " and ".join(
        str(s.scenario.tau_caps[0]) for s, _, _ in panels))


def _act(solved: Solved, label: Sequence[int], config: Any = None) -> str:
    return action_name(solved.mdp, tuple(int(x) for x in label), config, scenario=solved.scenario)


def _mass_cell(solved: Solved) -> str:
    return pct(solved.cap_mass.total)


# ============================================================================ C1, C2: two processes
def claim_c1(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, solves, ev = [], [], []
    for cap in prof.caps_2p:
        solved = ctx.solve(ctx.scenario("paper_p14.toml", [f"tau_cap={cap}"]))
        ids = _idle_ids(solved)
        acts = [solved.action_tuple(s) for s in ids]
        other = ids[np.array([a != (1, 2) for a in acts], dtype=bool)]
        split = state_split(solved, other)
        v = _map_verdict(split)
        others = sorted({a for a in acts if a != (1, 2)})
        per_cap.append({"cap": cap, "idle_states": int(ids.size), "other_actions": [_act(solved, a) for a in others],
                        "other_action_states": split, "gain": solved.gain, "verdict": v,
                        "cap_mass": solved.cap_mass.to_dict()})
        solves.append(solved)
        ev.append(solved.evidence(f"processes 1, 4 at cap {cap}", v))
    basis = cap_basis(ev)
    verdict = basis["verdict"]
    figs = _idle_maps(ctx, solves, "c1_fig3_policy_p14", "Processes 1 and 4, idle servers (Fig. 3)")
    tab = ctx.save_table([{"cap": r["cap"], "idle_states": r["idle_states"], "verdict": r["verdict"],
                           "cap_mass": r["cap_mass"]["total"],
                           **{f"other_{k}": v for k, v in r["other_action_states"].items() if k != "shown"}}
                          for r in per_cap], "c1_fig3_counts")
    shown = [Table("Idle-server states that do not choose (1 to remote, 4 to edge), per cap, with their stationary "
                   "probability under the optimal policy; the largest cap decides.",
                   ["cap", "idle states", "other action", "recurrent", "transient", "at the cap",
                    "recurrent below the cap", "of weight", "stationary mass", "verdict at this cap", "mass at the cap"],
                   [[r["cap"], r["idle_states"], r["other_action_states"]["total"],
                     r["other_action_states"]["recurrent"], r["other_action_states"]["transient"],
                     r["other_action_states"]["at_cap"], r["other_action_states"]["recurrent_below_cap"],
                     r["other_action_states"]["observable_below_cap"],
                     mass_words(r["other_action_states"]["stationary_mass"]), r["verdict"],
                     pct(r["cap_mass"]["total"])] for r in per_cap])]
    dec, rest = per_cap[-1], per_cap[:-1]

    def at(r: dict) -> str:
        s = r["other_action_states"]
        if not s["total"]:
            return f"every idle-server state chooses (1 to remote, 4 to edge) at cap {r['cap']}"
        return (f"at cap {r['cap']} ({pct(r['cap_mass']['total'], 1)} of the time at the cap), {s['total']} of "
                f"{r['idle_states']} idle-server states choose {', '.join(r['other_actions'])}, "
                f"{s['observable_below_cap'] or 'none'} of them recurrent, of weight and below the cap (stationary mass "
                f"{mass_words(s['stationary_mass'])}; shown: {shown_words(s)})")

    clean = [r["cap"] for r in rest if not r["other_action_states"]["total"]]
    if not dec["other_action_states"]["total"] and clean:
        first = (f"every idle-server state chooses (1 to remote, 4 to edge) at cap {dec['cap']}, the least truncated "
                 f"({pct(dec['cap_mass']['total'], 3)} of the time at the cap), which decides, and at cap "
                 + ", ".join(map(str, clean)))
        rest = [r for r in rest if r["cap"] not in clean]
    else:
        first = at(dec) + ": the least truncated cap, which decides"
    parts = [first] + [("caveat, at a more truncated cap: " if r["verdict"] != dec["verdict"] else "") + at(r)
                       for r in rest]
    summary = "; ".join(parts)
    summary = summary[0].upper() + summary[1:]
    return ClaimResult("C1", "Fig. 3", "", verdict, summary + ".", {"per_cap": per_cap}, figs, [tab],
                       details="Action (1, 2) here means paper process 1 to the remote server and paper process 4 "
                               "(our process 2 of this scenario) to the edge. Whether the optimal policy of this case "
                               "is the static policy in every state, not only in the idle-server states, is claim "
                               "C14. " + CONFIGURATION_NOTE,
                       basis=basis, shown=shown,
                       captions={figs[0]: "The optimal action in the idle-server states over (tau_1, tau_4) at the "
                                          "smallest and the largest cap; grey background: transient states."})


def claim_c2(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, solves, ev = [], [], []
    for cap in prof.caps_2p:
        solved = ctx.solve(ctx.scenario("paper_p12.toml", [f"tau_cap={cap}"]))
        ids = _idle_ids(solved)
        acts = np.array([solved.action_tuple(s) for s in ids])
        is21 = np.all(acts == (2, 1), axis=1)
        is12 = np.all(acts == (1, 2), axis=1)
        tau = solved.mdp.states.tau[ids]
        s21, t21 = ids[is21], tau[is21]
        upper_left = bool(np.all(t21[:, 1] > t21[:, 0])) if s21.size else False
        share = float(is12.mean())
        if share > 0.5 and s21.size and upper_left:
            v = "HOLDS"
        elif share <= 0.5 or not s21.size:
            v = "FAILS"
        else:
            v = "DEPENDS"
        rec = {
            "cap": cap,
            "idle_states": int(ids.size),
            "share_12": share,
            "count_21": int(is21.sum()),
            "split_21": state_split(solved, s21),
            "tau1_range_21": [int(t21[:, 0].min()), int(t21[:, 0].max())] if s21.size else [],
            "tau2_range_21": [int(t21[:, 1].min()), int(t21[:, 1].max())] if s21.size else [],
            "all_upper_left_21": upper_left,
            "outside_upper_left_21": state_split(solved, s21[t21[:, 1] <= t21[:, 0]]),
            "gain": solved.gain,
            "verdict": v,
            "cap_mass": solved.cap_mass.to_dict(),
        }
        per_cap.append(rec)
        solves.append(solved)
        ev.append(solved.evidence(f"processes 1, 2 at cap {cap}", v))
    basis = cap_basis(ev, how="descriptive")
    verdict = basis["verdict"]
    figs = _idle_maps(ctx, solves, "c2_fig4_policy_p12", "Processes 1 and 2, idle servers (Fig. 4)")

    def rng(x: list[int]) -> str:
        return f"{x[0]}-{x[1]}" if x else "none"

    tab = ctx.save_table([{"cap": r["cap"], "idle_states": r["idle_states"], "share_12": r["share_12"],
                           "count_21": r["count_21"], "recurrent_21": r["split_21"]["recurrent"],
                           "stationary_mass_21": r["split_21"]["stationary_mass"],
                           "outside_upper_left_21": r["outside_upper_left_21"]["total"],
                           "tau1_range_21": rng(r["tau1_range_21"]), "tau2_range_21": rng(r["tau2_range_21"]),
                           "all_upper_left_21": r["all_upper_left_21"], "verdict": r["verdict"],
                           "cap_mass": r["cap_mass"]["total"]} for r in per_cap], "c2_fig4_counts")
    shown = [Table("The (2 to remote, 1 to edge) region of the idle-server map, per cap: where it lies, how much of "
                   "it is recurrent, its stationary probability under the optimal policy, and its states outside the "
                   "upper-left corner (tau_2 <= tau_1).",
                   ["cap", "share of (1,2)", "(2,1) states", "tau_1 range", "tau_2 range", "all tau_2 > tau_1",
                    "recurrent", "stationary mass", "outside the corner", "verdict at this cap", "mass at the cap"],
                   [[r["cap"], pct(r["share_12"], 1), r["count_21"], rng(r["tau1_range_21"]), rng(r["tau2_range_21"]),
                     r["all_upper_left_21"] if r["count_21"] else "n/a", r["split_21"]["recurrent"],
                     mass_words(r["split_21"]["stationary_mass"]), r["outside_upper_left_21"]["total"], r["verdict"],
                     pct(r["cap_mass"]["total"])] for r in per_cap])]
    def at(r: dict) -> str:
        if not r["count_21"]:
            return f"no (2,1) state at cap {r['cap']}"
        return (f"(2,1) in {r['count_21']} of {r['idle_states']} idle states at cap {r['cap']} (tau_1 "
                f"{rng(r['tau1_range_21'])}, tau_2 {rng(r['tau2_range_21'])}, "
                f"{'all' if r['all_upper_left_21'] else 'not all'} with tau_2 > tau_1; {r['split_21']['recurrent']} "
                f"recurrent, stationary mass {mass_words(r['split_21']['stationary_mass'])})")

    dec, rest = per_cap[-1], per_cap[:-1]
    summary = (f"Mostly (1,2) ({pct(dec['share_12'], 0)} of the idle states) with " + at(dec)
               + f", the least truncated cap ({pct(dec['cap_mass']['total'], 3)} of the time at the cap), which "
               "decides" + "".join(("; caveat, at a more truncated cap: " if r["verdict"] != dec["verdict"] else "; ")
                                   + at(r) + f" ({pct(r['cap_mass']['total'], 1)} of the time at the cap)"
                                   for r in rest) + ".")
    return ClaimResult("C2", "Fig. 4", "", verdict, summary, {"per_cap": per_cap}, figs, [tab],
                       details="Per cap: HOLDS when (1,2) is the majority and a (2,1) region exists with every state "
                               "above the diagonal (tau_2 > tau_1); FAILS when no (2,1) state exists or (1,2) is not "
                               "the majority. The largest cap decides; a smaller cap that disagrees is a caveat. "
                               + ", ".join(f"{r['verdict']} at cap {r['cap']}" for r in per_cap) + ". Whether the "
                               "corner is the only place where the optimal policy differs from the static one is "
                               "claim C15. " + CONFIGURATION_NOTE,
                       basis=basis, shown=shown,
                       captions={figs[0]: "The optimal action in the idle-server states over (tau_1, tau_2) at the "
                                          "smallest and the largest cap; grey background: transient states."})


# ============================================================================ C4, C5: three processes
def _planes(prof, cap: int) -> list[int]:
    return [t for t in prof.c4_planes if 3 <= t <= 2.25 * cap]


def _c4_slice(solved: Solved, total: int) -> dict[str, Any]:
    """One plane tau_1 + tau_2 + tau_3 = total of the idle-server policy: its regions, and what keeps
    it from four simply connected regions (a fifth action; an action in several pieces or with a
    hole), with the offending cells split recurrent / transient and weighed by the stationary law."""
    from scipy import ndimage

    sol = solved.as_solution()
    stats = region_stats(solved.mdp, sol, "idle", total=total, axes=(1, 2, 3), scenario=solved.scenario)
    A, S, _ = slice_grid(solved.mdp, sol, "idle", total, (1, 2, 3))
    at_cap = np.zeros(S.shape, bool)
    ok = S >= 0
    at_cap[ok] = np.any(solved.mdp.states.tau[S[ok]] == np.asarray(solved.mdp.states.caps), axis=1)
    regions = {name: {"cells": v["cells"], "components": v["components"], "holes": v["holes"],
                      "simply_connected": v["simply_connected"],
                      "cells_at_cap": int(np.count_nonzero((A == v["action"]) & at_cap))}
               for name, v in stats["per_action"].items()}
    # offending cells: every action beyond the four largest, and every piece but the largest of an action
    by_size = sorted(stats["per_action"].values(), key=lambda v: -v["cells"])
    extra = np.isin(A, [v["action"] for v in by_size[4:]])
    for v in by_size[:4]:
        comp, n = ndimage.label(A == v["action"], structure=NEIGHBOURS["tri6"])
        if n > 1:
            sizes = np.bincount(comp.ravel())[1:]
            extra |= (comp > 0) & (comp != 1 + int(np.argmax(sizes)))
    good = stats["regions_total"] == 4 and all(r["simply_connected"] for r in regions.values())
    return {"cap": max(solved.scenario.tau_caps), "plane_total": total, "cells": stats["cells"],
            "unreachable": stats["unreachable"], "actions_present": stats["actions_present"],
            "regions_total": stats["regions_total"], "fifth_action": stats["actions_present"] > 4,
            "split_actions": [k for k, v in regions.items() if v["components"] > 1],
            "holed_actions": [k for k, v in regions.items() if v["holes"] > 0],
            "offending_cells": state_split(solved, S[extra & ok]), "regions": regions,
            "verdict": "HOLDS" if good else "FAILS", "cap_mass": solved.cap_mass.total}


def claim_c4(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    rows, ev, by_cap = [], [], {}
    ctx.prefetch([Step(ctx.scenario("paper_p123.toml", [f"tau_cap={c}"])) for c in sorted(prof.caps_3p, reverse=True)])
    for cap in prof.caps_3p:
        solved = ctx.solve(ctx.scenario("paper_p123.toml", [f"tau_cap={cap}"]))
        by_cap[cap] = solved
        for total in _planes(prof, cap):
            rows.append(_c4_slice(solved, total))
            ev.append(solved.evidence(f"processes 1, 2, 3 at cap {cap}, plane {total}", rows[-1]["verdict"],
                                      group=f"plane {total}"))
    basis = cap_basis(ev, how="descriptive")
    verdict = basis["verdict"]
    figs, captions = _c4_figures(ctx, by_cap)
    tab = ctx.save_table([{"cap": r["cap"], "plane_total": r["plane_total"], "action": name, **v}
                          for r in rows for name, v in r["regions"].items()], "c4_fig7_regions")
    shown = [
        Table("Per cap and plane: the actions present, the number of regions (connected components of one action, "
              "6-neighbour on the plane), whether each is simply connected, and the offending cells (of an action "
              "beyond the four largest, or of a piece but the largest of an action) split recurrent / transient with "
              "their stationary probability.",
              ["cap", "plane sum", "cells", "actions", "regions", "all simply connected", "offending cells",
               "recurrent", "transient", "stationary mass", "verdict", "mass at the cap"],
              [[r["cap"], r["plane_total"], r["cells"], r["actions_present"], r["regions_total"],
                all(v["simply_connected"] for v in r["regions"].values()), r["offending_cells"]["total"],
                r["offending_cells"]["recurrent"], r["offending_cells"]["transient"],
                mass_words(r["offending_cells"]["stationary_mass"]), r["verdict"], pct(r["cap_mass"])]
               for r in rows]),
        Table("Each region: cells, components, holes and how many of its cells touch the cap (some tau_k = cap).",
              ["cap", "plane sum", "action", "cells", "components", "holes", "simply connected", "cells at the cap"],
              [[r["cap"], r["plane_total"], name, v["cells"], v["components"], v["holes"], v["simply_connected"],
                v["cells_at_cap"]] for r in rows for name, v in r["regions"].items()]),
    ]
    return ClaimResult("C4", "Figs. 6-7", "", verdict, _c4_summary(rows), {"slices": rows}, figs, [tab],
                       details="Per slice: HOLDS when exactly four regions, each simply connected. Each plane is "
                               "decided at the largest cap where it fits (a smaller cap that disagrees is a caveat); "
                               "across planes: DEPENDS when they disagree. Planes up to 2.25 x cap are used (beyond, "
                               "most of the plane touches the cap). Slices that fail: " + "; ".join(
                                   f"plane {r['plane_total']} at cap {r['cap']}: {r['actions_present']} actions, "
                                   f"{r['regions_total']} regions"
                                   + (f", in several pieces: {', '.join(r['split_actions'])}" if r["split_actions"] else "")
                                   + (f", with a hole: {', '.join(r['holed_actions'])}" if r["holed_actions"] else "")
                                   for r in rows if r["verdict"] != "HOLDS") + ".",
                       basis=basis, shown=shown, captions=captions)


def _c4_summary(rows: list[dict]) -> str:
    """One sentence: on how many planes of the deciding cap (each plane's largest) the four simply
    connected regions show, why the others do not, and the smaller caps' slices that disagree."""
    last = {}
    for r in rows:
        if r["plane_total"] not in last or r["cap"] > last[r["plane_total"]]["cap"]:
            last[r["plane_total"]] = r
    deciding = list(last.values())
    good = [r for r in deciding if r["verdict"] == "HOLDS"]

    def name(r: dict) -> str:
        return f"{r['plane_total']}@{r['cap']}"

    text = (f"{len(good)} of {len(deciding)} planes, each at the largest cap where it fits, show four simply connected "
            "regions" + (f" ({', '.join(map(name, good))})" if good else ""))
    bad = [r for r in deciding if r["verdict"] != "HOLDS"]
    if bad:
        text += "; not " + "; ".join(
            f"{name(r)}: {r['regions_total']} regions" + (", a fifth action" if r["fifth_action"] else "")
            + (f", in several pieces: {', '.join(r['split_actions'])}" if r["split_actions"] else "")
            + (f", with a hole: {', '.join(r['holed_actions'])}" if r["holed_actions"] else "")
            + f" (offending cells {r['offending_cells']['recurrent']} recurrent, {r['offending_cells']['transient']} "
              f"transient, stationary mass {mass_words(r['offending_cells']['stationary_mass'])})" for r in bad)
    caveats = [r for r in rows if r is not last[r["plane_total"]] and r["verdict"] != last[r["plane_total"]]["verdict"]]
    if caveats:
        text += ("; caveat, at smaller caps: " + ", ".join(name(r) for r in caveats) + " "
                 + ("disagree" if len(caveats) > 1 else "disagrees") + " with the same plane at the larger cap")
    return text + "."


def _c4_figures(ctx: Context, by_cap: dict[int, Solved]) -> tuple[list[str], dict[str, str]]:
    """One plane at every cap (the cap's effect) and every plane at the largest cap (the plane's)."""
    prof = ctx.profile
    figs: list[str] = []
    captions = {}
    common = [t for t in prof.c4_planes if all(t in _planes(prof, c) for c in prof.caps_3p)]
    if len(prof.caps_3p) > 1 and common:
        t = common[-1]
        fig, axes = subplots(1, len(prof.caps_3p), figsize=(6.6 * len(prof.caps_3p), 6.2), squeeze=False)
        for ax, cap in zip(axes[0], prof.caps_3p):
            s = by_cap[cap]
            plot_policy_slice(s.mdp, s.as_solution(), "idle", t, ax=ax, stationary=s.stationary, scenario=s.scenario,
                              title=f"cap {cap}: plane tau_1 + tau_2 + tau_3 = {t}")
        fig.suptitle(f"Processes 1, 2, 3, idle servers (Figs. 6-7): the plane {t} at caps "
                     + ", ".join(map(str, prof.caps_3p)))
        _shared_legend(fig, axes.ravel())
        f = ctx.save_figure(fig, f"c4_fig7_plane{t}_by_cap")
        figs += f
        captions[f[0]] = (f"The same plane tau_1 + tau_2 + tau_3 = {t} at every cap: how the regions move as the "
                          "truncation is lifted.")
    cap = prof.caps_3p[-1]
    planes = _planes(prof, cap)
    s = by_cap[cap]
    ncol = min(len(planes), 3)
    nrow = -(-len(planes) // ncol)
    fig, axes = subplots(nrow, ncol, figsize=(6.6 * ncol, 6.2 * nrow), squeeze=False)
    for k, ax in enumerate(axes.ravel()):
        if k >= len(planes):
            ax.set_visible(False)
            continue
        plot_policy_slice(s.mdp, s.as_solution(), "idle", planes[k], ax=ax, stationary=s.stationary,
                          scenario=s.scenario, title=f"cap {cap}: plane tau_1 + tau_2 + tau_3 = {planes[k]}")
    fig.suptitle(f"Processes 1, 2, 3, idle servers (Figs. 6-7): every plane at cap {cap}")
    _shared_legend(fig, axes.ravel())
    f = ctx.save_figure(fig, f"c4_fig7_planes_cap{cap}")
    figs += f
    captions[f[0]] = (f"Several planes at the same cap {cap}, so the plane's effect is not confounded with the "
                      "cap's; faded markers: transient states.")
    return figs, captions


def _shared_legend(fig, axes) -> None:
    """One legend for a figure of several slices, under the panels: each panel's own legend would sit
    inside a grid's panels, over the triangle's corners and its points."""
    import re

    handles: dict[str, Any] = {}
    for ax in axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        for h, t in zip(leg.legend_handles, leg.get_texts()):  # one entry per action: the panels' counts dropped
            handles.setdefault(re.sub(r"\s*\[\d[\d,]* points?\]$", "", t.get_text()), h)
        leg.remove()
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(4, len(handles)),
                   fontsize=9, frameon=False, title="action (each panel)", title_fontsize=9)


def claim_c5(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, ev = [], []
    last = None
    for cap in prof.caps_3p:
        sc = ctx.scenario("paper_p123.toml", [f"tau_cap={cap}"])
        solved = ctx.solve(sc)
        mdp = solved.mdp
        remote, edge = sc.servers
        # Fig. 8: edge serving process 3 with 3 slots left, remote idle; Fig. 9: remote serving 1 with 4 left
        remote_idle = ((0,) * max(remote.uplink_delay - 1, 0), 0, 0, (0,) * remote.downlink_delay)
        edge_idle = ((0,) * max(edge.uplink_delay - 1, 0), 0, 0, (0,) * edge.downlink_delay)
        cases = {
            "Fig. 8: edge busy with process 3": (((remote_idle, (edge_idle[0], 3, 3, edge_idle[3])), 0, 3)),
            "Fig. 9: remote busy with process 1": (((remote_idle[0], 1, 4, remote_idle[3]), edge_idle), 1, 1),
        }
        cfgs, splits = {}, []
        for name, (cfg, free_server, busy_proc) in cases.items():
            c = mdp.states.config_id(cfg)
            if c < 0:
                cfgs[name] = {"reachable": False}
                continue
            grid = mdp.states.lookup_grid(c)
            ids = grid[grid >= 0]
            acts = np.array([solved.action_tuple(s) for s in ids])
            same = ids[acts[:, free_server] == busy_proc]
            split = state_split(solved, same)
            splits.append(split)
            counts: dict[str, int] = {}
            for a in map(tuple, acts):
                key = _act(solved, a, c)
                counts[key] = counts.get(key, 0) + 1
            cfgs[name] = {"reachable": True, "config": c, "states": int(ids.size), "action_counts": counts,
                          "busy_process_also_sent": split, "verdict": _map_verdict(split)}
        v = combine([_map_verdict(s) for s in splits]) if splits else "ERROR"
        per_cap.append({"cap": cap, "cases": cfgs, "verdict": v, "cap_mass": solved.cap_mass.total})
        ev.append(solved.evidence(f"processes 1, 2, 3 at cap {cap}", v))
        last = (solved, cfgs)
    basis = cap_basis(ev)
    verdict = basis["verdict"]
    solved, cfgs = last
    cap = prof.caps_3p[-1]
    panels = [(solved, v["config"], {"axes": (1, 2)}) for v in cfgs.values() if v.get("reachable")]
    figs = _maps_figure(ctx, panels, "c5_figs8_9_busy_server_p123",
                        f"Processes 1, 2, 3 at cap {cap}: one server busy (Figs. 8-9)")
    rows = []
    for r in per_cap:
        for name, v in r["cases"].items():
            if not v.get("reachable"):
                rows.append([r["cap"], name, "unreachable", "", "", "", "", "", "", pct(r["cap_mass"])])
                continue
            s = v["busy_process_also_sent"]
            rows.append([r["cap"], name, v["states"], s["total"], s["recurrent"], s["at_cap"], s["recurrent_below_cap"],
                         mass_words(s["stationary_mass"]), v["verdict"], pct(r["cap_mass"])])
    shown = [Table("States of each configuration where the free server is also sent the busy process (the paper: it "
                   "serves the other processes), per cap, with their stationary probability; the verdict of each "
                   "configuration by the structural rule.",
                   ["cap", "configuration", "states", "busy process also sent", "recurrent", "at the cap",
                    "recurrent below the cap", "stationary mass", "verdict", "mass at the cap"], rows)]
    actions = [Table(f"The free server's actions at cap {cap} (states per action).", ["configuration", "action", "states"],
                     [[name, a, n] for name, v in cfgs.items() if v.get("reachable")
                      for a, n in sorted(v["action_counts"].items(), key=lambda kv: -kv[1])])]
    return ClaimResult("C5", "Figs. 8-9", "", verdict, _c5_summary(per_cap), {"per_cap": per_cap}, figs, [],
                       details="The paper's remark (end of Sec. II): while one server holds process k, the other "
                               "serves processes other than k. Counted over every reachable AoI vector of each "
                               "configuration; the verdict follows the structural rule. " + "; ".join(
                                   f"cap {r['cap']}: " + ", ".join(
                                       f"{name.split(':')[0]} {v['busy_process_also_sent']['total']} of {v['states']} "
                                       "states" if v.get("reachable") else f"{name.split(':')[0]} unreachable"
                                       for name, v in r["cases"].items()) for r in per_cap) + ". " + CONFIGURATION_NOTE,
                       basis=basis, shown=shown + actions,
                       captions={figs[0]: f"The optimal action of the free server over (tau_1, tau_2) at cap {cap}, "
                                          "with tau_3 at its most frequent value."})


def _c5_summary(per_cap: list[dict]) -> str:
    """One sentence: at the deciding (largest) cap, in how many states (and of what weight) the free
    server is also sent the busy process in each configuration; the smaller caps beside."""
    dec = per_cap[-1]
    parts = []
    for name, v in dec["cases"].items():
        fig, what = name.split(": ", 1)
        if not v.get("reachable"):
            parts.append(f"{fig}'s configuration ({what}) is not reachable")
            continue
        c = v["busy_process_also_sent"]
        if not c["total"]:
            parts.append(f"never in {fig}'s configuration ({what})")
        else:
            parts.append(f"in {c['total']} of {v['states']} states of {fig}'s ({what}), {c['observable_below_cap'] or 'none'} "
                         f"of them recurrent, of weight and below the cap (stationary mass "
                         f"{mass_words(c['stationary_mass'])}; shown: {shown_words(c)})")
    text = (f"At cap {dec['cap']}, the least truncated ({pct(dec['cap_mass'], 2)} of the time at the cap), which "
            "decides, the free server is also sent the busy process " + "; ".join(parts))
    rest = []
    for r in per_cap[:-1]:
        counts = [f"{v['busy_process_also_sent']['total']} ({name.split(':')[0]})" for name, v in r["cases"].items()
                  if v.get("reachable")]
        rest.append(f"cap {r['cap']}: {', '.join(counts)} states, {r['verdict']}"
                    + (" (a caveat: it disagrees with the deciding cap)" if r["verdict"] != dec["verdict"] else ""))
    return text + (("; " + "; ".join(rest)) if rest else "") + "."


# ============================================================================ C7-C10: theorems
def _check_instances(ctx: Context, cid: str, check, instances: list[tuple[str, list[str]]], **kw
                     ) -> tuple[list[dict], list[dict], list[Solved]]:
    """Run one structural check on each instance (cached); return the reports, the table rows
    and the solves."""
    rows, reports, solves = [], [], []
    ctx.prefetch([Step(ctx.scenario(file, overrides)) for file, overrides in instances])
    for file, overrides in instances:
        sc = ctx.scenario(file, overrides)
        solved = ctx.solve(sc)

        def compute(solved=solved):
            sol = solved.as_solution()
            pctx = policy_context(solved.mdp, sol, stationary=solved.stationary)
            rep = check(solved.mdp, sol, ctx=pctx, **kw)
            return rep.to_json(), None

        rep, _ = ctx.cache.get_or_compute(f"check-{cid}", {"fingerprint": sc.fingerprint(), **kw}, compute)
        reports.append(rep)
        solves.append(solved)
        worst = rep.get("worst") or {}
        weight = rep.get("weight") or {}
        rows.append({
            "scenario": Path(file).stem,
            "cap": max(sc.tau_caps),
            "verdict": verdict_of(rep),
            "checked": rep["checked"],
            "violations": rep["violations"],
            "recurrent_violations": rep["recurrent_violations"],
            "at_cap_violations": rep["at_cap_violations"],
            "recurrent_below_cap": rep["split"].get("recurrent_below_cap", 0),
            "observable_below_cap": rep["split"].get("observable_below_cap", rep["split"].get("recurrent_below_cap", 0)),
            "ties": rep.get("ties", 0),
            "worst_size": worst.get("size") if rep["violations"] else None,  # empty, never "nan", without a violation
            "violating_mass": weight.get("mass"),
            "violating_mass_recurrent_below_cap": weight.get("mass_recurrent_below_cap"),
            "violating_mass_observable_below_cap": weight.get("mass_observable_below_cap"),
            "cap_mass": solved.cap_mass.total,
        })
    return reports, rows, solves


NAMES = {"paper_p12": "processes 1, 2", "paper_p14": "processes 1, 4", "paper_p123": "processes 1, 2, 3",
         "paper_preemption_p12": "preemption, processes 1, 2"}


def _counterexample(example: dict | None) -> str:
    if not example:
        return ""
    stat = example.get("stationary")
    info = example.get("info", {})
    kind = example.get("kind", "") + (f" along the {info['direction']}" if info.get("direction") else "")
    far = example.get("cap_distance")
    text = (f"Counterexample ({kind}): " + " vs ".join(f"`{lab}`" for lab in example["labels"])
            + f" (size {example['size']:.4g}, {'recurrent' if example['recurrent'] else 'transient'}, "
            f"{'at' if example['at_cap'] else 'below'} the cap" + (f", {far} from it" if far else "")
            + (f"; stationary probability of its states {' / '.join(mass_words(x) for x in stat)}" if stat else "")
            + ")" + (f"; that is, {info['meaning']}" if info.get("meaning") else "") + ".")
    traj = example.get("info", {}).get("trajectory")
    if traj:
        text += "\n\nTrajectory:\n\n" + "\n".join(
            f"{i}. `{step['label']}`, action {tuple(step['action'])}, probability {step['prob']:.3g}"
            + (f" -- **{step['event']}**" if step.get("event") else "") for i, step in enumerate(traj, 1))
    return text


def best_example(examples: list[dict]) -> dict | None:
    """The witness to show: observable (or recurrent) and below the cap first, then the farthest
    from the cap, then the heaviest (the smallest stationary probability of its states)."""
    def key(e: dict):
        rec, cap = bool(e["recurrent"]), bool(e["at_cap"])
        obs = e.get("observable")
        obs = rec if obs is None else bool(obs)
        rank = int(witness_rank(np.array([rec]), np.array([cap]), np.array([obs]))[0])
        stat = e.get("stationary") or [0.0]
        return rank, -(e.get("cap_distance") or 0), -min(stat)

    return min(examples, key=key) if examples else None


def _theorem(ctx: Context, cid: str, paper: str, check, instances: list[tuple[str, list[str]]],
             unit_note: str = "", **kw) -> tuple[ClaimResult, list[dict], list[Solved]]:
    """The claim of one structural check over several instances, with the reports and solves: the
    largest cap of each scenario decides (:func:`~wncs_lp.reproduce.context.cap_basis`)."""
    reports, rows, solves = _check_instances(ctx, cid, check, instances, **kw)
    ev = [s.evidence(f"{NAMES.get(r['scenario'], r['scenario'])} at cap {r['cap']}", r["verdict"])
          for r, s in zip(rows, solves)]
    basis = cap_basis(ev)
    verdict = basis["verdict"]
    deciding = _deciding_rows(rows)
    for r in rows:
        r["decides"] = r in deciding
    tab = ctx.save_table(rows, f"{cid.lower()}_verifier")
    shown = [Table(f"The check per scenario and cap{unit_note}; the largest cap of each scenario decides. Of weight: "
                   f"the violations recurrent and below the cap whose witness states are each visited at least "
                   f"{NEGLIGIBLE:g} of the time (these decide FAILS); stationary mass: the stationary probability of the "
                   "states of the violations' witnesses (all of them / those recurrent and below the cap).",
                   ["scenario", "cap", "checked", "violations", "recurrent", "at the cap", "recurrent below the cap",
                    "of weight", "worst size", "stationary mass", "verdict", "decides", "mass at the cap"],
                   [[NAMES.get(r["scenario"], r["scenario"]), r["cap"], r["checked"], r["violations"],
                     r["recurrent_violations"], r["at_cap_violations"], r["recurrent_below_cap"],
                     r["observable_below_cap"], r["worst_size"] if r["violations"] else "",
                     f"{mass_words(r['violating_mass'])} / {mass_words(r['violating_mass_recurrent_below_cap'])}"
                     if r["violations"] else "", r["verdict"], "yes" if r["decides"] else "", pct(r["cap_mass"])]
                    for r in rows])]
    summary = _theorem_summary(rows)
    # the counterexample: from the deciding instances, the best witness (observable, below and far from the cap)
    pool = [(e, r) for rep, r in zip(reports, rows) if r["decides"] for e in rep.get("examples", [])]
    example = best_example([e for e, _ in pool])
    where = next(r for e, r in pool if e is example) if example else None
    numbers = {"instances": rows,
               "tolerance": {k: reports[0].get(k) for k in ("atol", "rtol")} if reports else {},
               "notes": reports[0].get("notes") if reports else ""}
    details = (f"In {NAMES.get(where['scenario'], where['scenario'])} at cap {where['cap']}: "
               + _counterexample(example)) if example else ""
    res = ClaimResult(cid, paper, "", verdict, summary, numbers, [], [tab], details=details, basis=basis, shown=shown)
    return res, reports, solves


def _deciding_rows(rows: list[dict]) -> list[dict]:
    """The row of the largest cap of each scenario."""
    best: dict[str, dict] = {}
    for r in rows:
        if r["scenario"] not in best or r["cap"] > best[r["scenario"]]["cap"]:
            best[r["scenario"]] = r
    return list(best.values())


def _theorem_summary(rows: list[dict]) -> str:
    """One sentence: the deciding instances (the largest cap of each scenario) with their counts and
    the weight of their counterexamples, then the more truncated instances that disagree (caveats)."""
    def name(r: dict) -> str:
        return f"{NAMES.get(r['scenario'], r['scenario'])} at cap {r['cap']}"

    total = sum(r["violations"] for r in rows)
    cases = f"{sum(r['checked'] for r in rows):,} cases over {len(rows)} instances"
    if not total:
        return f"No violation in {cases}."
    deciding = _deciding_rows(rows)
    parts = []
    for r in deciding:
        if r["verdict"] == "FAILS":
            parts.append(f"{name(r)}: {r['observable_below_cap']:,} violation(s) recurrent, of weight and below the cap "
                         f"(of {r['violations']:,}; stationary mass of their states "
                         f"{mass_words(r['violating_mass_observable_below_cap'])}; {pct(r['cap_mass'], 3)} of the time "
                         "at the cap)")
        elif r["violations"]:
            light = r["recurrent_below_cap"] - r["observable_below_cap"]
            parts.append(f"{name(r)}: {r['violations']:,} violation(s), none recurrent, of weight and below the cap "
                         f"({r['at_cap_violations']:,} at the cap" + (f", {light:,} of negligible weight (stationary "
                         f"mass {mass_words(r['violating_mass_recurrent_below_cap'])})" if light else "")
                         + ", the others transient)")
        else:
            parts.append(f"{name(r)}: no violation")
    text = "Deciding (the largest cap of each scenario): " + "; ".join(parts)
    caveats = [r for r in rows if r not in deciding
               and r["verdict"] != next(d for d in deciding if d["scenario"] == r["scenario"])["verdict"]]
    if caveats:
        text += "; caveat, at more truncated caps: " + "; ".join(
            f"{name(r)} {r['verdict']} ({r['observable_below_cap']:,} of weight below the cap of {r['violations']:,})"
            for r in caveats)
    return text + f"; {total:,} violation(s) in all in {cases}."


def _two_and_three(ctx: Context) -> list[tuple[str, list[str]]]:
    prof = ctx.profile
    inst = [(f, [f"tau_cap={c}"]) for f in ("paper_p12.toml", "paper_p14.toml") for c in prof.caps_2p]
    inst += [("paper_p123.toml", [f"tau_cap={c}"]) for c in prof.caps_3p]
    return inst


def _preemption(ctx: Context) -> list[tuple[str, list[str]]]:
    return [("paper_preemption_p12.toml", [f"tau_cap={c}"]) for c in ctx.profile.caps_pre]


def claim_c7(ctx: Context) -> ClaimResult:
    return _theorem(ctx, "C7", "Theorem 1", check_monotonicity, _two_and_three(ctx) + _preemption(ctx),
                    " (one case = a pair (s, s + e_k) in one configuration)")[0]


def claim_c8(ctx: Context) -> ClaimResult:
    return _theorem(ctx, "C8", "Theorem 2", check_threshold, _two_and_three(ctx),
                    " (one case = an idle state s and a step z along the ray s + z(e_k1 + e_k2))")[0]


START_TYPES = {"preempting": "by preempting another process's job", "idle_server": "on an idle server",
               "restarting_own": "restarting its own process (cancelling its job)"}


def claim_c10(ctx: Context) -> ClaimResult:
    """Theorem 3 on its own wording: jobs started by preempting; the other starts are reported beside."""
    res, reports, _ = _theorem(ctx, "C10", "Theorem 3", check_consistency, _preemption(ctx),
                               " (one case = a state where the optimal policy starts a job by preempting)")
    rows = []
    split_json = []
    for rep, inst in zip(reports, res.numbers["instances"]):
        by = rep["details"]["by_start_type"]
        for start, words in START_TYPES.items():
            b = by.get(start, {})
            obc = b.get("observable_below_cap", b.get("recurrent_below_cap", 0))
            v = structural_verdict(b.get("violations", 0) == 0, b.get("recurrent_below_cap", 0), obc)
            rows.append([inst["cap"], words, b.get("checked", 0), b.get("violations", 0),
                         b.get("recurrent_violations", 0), b.get("at_cap_violations", 0),
                         b.get("recurrent_below_cap", 0), obc, v + (" (the claim)" if start == "preempting" else "")])
            split_json.append({"cap": inst["cap"], "start": start, **{k: b.get(k, 0) for k in (
                "checked", "violations", "recurrent_violations", "at_cap_violations", "recurrent_below_cap")},
                "observable_below_cap": obc})
    res.shown.append(Table("Every start of a job, split by how it starts: Theorem 3 speaks of jobs started by "
                           "preempting; the other kinds are shown for comparison and do not enter the verdict.",
                           ["cap", "job started", "starts", "later preempted or cancelled", "recurrent", "at the cap",
                            "recurrent below the cap", "of weight", "by the structural rule"], rows))
    res.numbers["by_start_type"] = split_json
    res.tables.append(ctx.save_table(split_json, "c10_by_start_type"))
    # the counterexample: a preempting start at the deciding cap, observable, below and far from the cap
    dec = max(zip(reports, res.numbers["instances"]), key=lambda t: t[1]["cap"]) if reports else None
    best = best_example(dec[0].get("examples", [])) if dec else None
    if best:
        res.details = (f"At cap {dec[1]['cap']}, a job started by preempting is itself preempted or cancelled before "
                       "it completes. " + _counterexample(best))
    idle = [r for r in split_json if r["start"] == "idle_server"]
    res.details += ("\n\n" if res.details else "") + ("Jobs started on an idle server (not the theorem's case): "
                    + ", ".join(f"{r['observable_below_cap']} recurrent, of weight and below the cap at cap {r['cap']}"
                                for r in idle) + ".")
    return res


def claim_c9(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    res, reports, solves = _theorem(ctx, "C9", "Figs. 11-12", check_threshold, _preemption(ctx),
                                    " (the switching-curve property along each axis: one case = an axis-parallel "
                                    "line and an action, or a line ordering two actions)")
    rows, apart = [], []
    for rep, inst in zip(reports, res.numbers["instances"]):
        d = rep["details"]
        for name, b in d.get("by_situation", {}).items():
            sp = b.get("split", {})
            w = b.get("weight", {})
            rows.append([inst["cap"], SITUATION_WORDS.get(name, name), b.get("configurations", 0), b.get("checked", 0),
                         b.get("gaps", {}).get("count", 0), b.get("reversals", {}).get("count", 0),
                         sp.get("recurrent_below_cap", 0), sp.get("observable_below_cap", 0),
                         mass_words(w.get("mass_recurrent_below_cap")) if b.get("violations") else "",
                         "yes" if name == "preemption" else "no"])
            if name != "preemption" and inst is res.numbers["instances"][-1] and b.get("violations"):
                ex = best_example(b.get("examples", []))
                apart.append(f"{SITUATION_WORDS.get(name, name)}: {b['violations']} violation(s) at cap {inst['cap']}, "
                             f"{sp.get('recurrent_below_cap', 0)} recurrent below the cap, "
                             f"{sp.get('observable_below_cap', 0)} of them of weight (stationary mass of their states "
                             f"{mass_words(w.get('mass_recurrent_below_cap'))})" + (". " + _counterexample(ex) if ex else ""))
        rows.append([inst["cap"], "diagonal lines, every configuration (described, not violations)", "", "",
                     d.get("diagonal_gaps", {}).get("count", 0), "", "", "", "", "no"])
    res.shown.append(Table("The violations by situation: the figures' own (a job in service, another process's update "
                           "arrived and not its own: keep going or preempt) decides; the configurations where the "
                           "job's own process arrived too (cancelling it is an option) and those with a free server "
                           "are checked the same way and reported apart. Gaps: an action's region not an interval "
                           "along an axis; order reversals: two lines of one axis switching between two actions in "
                           "opposite orders.",
                           ["cap", "situation", "configurations", "cases", "axis gaps", "order reversals",
                            "recurrent below the cap", "of weight", "their stationary mass", "in the verdict"], rows))
    res.numbers["apart"] = apart
    # the maps of Figs. 11 (process 2 in service, process 1 arrived) and 12 (the converse), at the largest cap
    solved = solves[-1]
    cap = prof.caps_pre[-1]
    model = solved.mdp.states.model
    panels, regions = [], {}
    for name, b, k in (("Fig. 11: serving process 2, process 1 arrived", (1, 0), 2),
                       ("Fig. 12: serving process 1, process 2 arrived", (0, 1), 1)):
        c = solved.mdp.states.config_id(model.serving_config(k, b))  # the job one slot into service
        if c < 0:
            continue
        st = region_stats(solved.mdp, solved.as_solution(), c, axes=(1, 2), scenario=solved.scenario)
        regions[name] = {a: {kk: v[kk] for kk in ("cells", "components", "holes", "simply_connected")}
                         for a, v in st["per_action"].items()}
        panels.append((solved, c, {"axes": (1, 2)}))
    res.figures = _maps_figure(ctx, panels, "c9_figs11_12_preemption_maps",
                               f"Preemption, processes 1 and 2 at cap {cap}: Figs. 11-12")
    res.captions = {res.figures[0]: f"The optimal preemption decision over (tau_1, tau_2) at cap {cap}, one slot into "
                                    "the job's service: a monotone switching curve separates keeping going from "
                                    "preempting."}
    res.numbers["maps"] = regions
    res.shown.append(Table(f"The maps of the figure (cap {cap}): regions of each action.",
                           ["map", "action", "cells", "components", "holes", "simply connected"],
                           [[m, a, v["cells"], v["components"], v["holes"], v["simply_connected"]]
                            for m, acts in regions.items() for a, v in acts.items()]))
    diag = sum(rep["details"].get("diagonal_gaps", {}).get("count", 0) for rep in reports)
    res.details += ("\n\n" if res.details else "") + (
        "Reported apart, outside the verdict (the figures show the decision to keep going or preempt by the other "
        "process): " + ("; ".join(apart) if apart else "no violation").rstrip(".") + ".\n\n"
        f"Along the diagonal direction e_1 + e_2 (tau_1 - tau_2 = const) the regions are not intervals in {diag} "
        "line(s) in all; a monotone switching curve may do that, so they are described, not counted. A line-gap is "
        "judged by its witnesses (two states choosing the action around one that strictly prefers another): it is at "
        "the cap only when every witness touches the cap.")
    return res


#: The situations of the switching-curve check (:data:`wncs_lp.verify.threshold.SITUATIONS`) in the report's words.
SITUATION_WORDS = {"preemption": "keep going or preempt (Figs. 11-12)", "cancel_option": "own process arrived too (cancel option)",
                   "server_free": "server free (which job to start)"}

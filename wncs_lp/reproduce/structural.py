"""Claims about the optimal policy's structure: C1, C2, C4, C5 (maps), C7-C10 (theorems)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..maps import region_stats
from ..verify import check_consistency, check_monotonicity, check_threshold, policy_context
from ..viz import plot_policy_map, plot_policy_slice, subplots
from .context import ClaimResult, Context, Solved


def _idle_grid(solved: Solved) -> tuple[np.ndarray, np.ndarray]:
    """State ids over the tau box in the idle-server configuration, and the chosen actions."""
    mdp = solved.mdp
    grid = mdp.states.lookup_grid(mdp.states.model.initial_config())
    ids = grid[grid >= 0]
    return grid, ids


def _split(solved: Solved, states: np.ndarray) -> dict[str, int]:
    rec = solved.recurrent[states]
    caps = np.asarray(solved.mdp.states.caps)
    at_cap = np.any(solved.mdp.states.tau[states] == caps, axis=1)
    return {
        "total": int(states.size),
        "recurrent": int(rec.sum()),
        "transient": int((~rec).sum()),
        "at_cap": int(at_cap.sum()),
        "recurrent_below_cap": int((rec & ~at_cap).sum()),
    }


def _maps_figure(ctx: Context, panels: list[tuple[Solved, Any, dict]], stem: str, suptitle: str) -> list[str]:
    n = len(panels)
    fig, axes = subplots(1, n, figsize=(6.2 * n, 5.6), squeeze=False)
    for ax, (solved, config, kw) in zip(axes[0], panels):
        plot_policy_map(solved.mdp, solved.as_solution(), config, ax=ax, stationary=solved.stationary,
                        scenario=solved.scenario, **kw)
    fig.suptitle(suptitle)
    fig.tight_layout()
    return ctx.save_figure(fig, stem)


def _verdict_from_split(splits: list[dict[str, int]]) -> str:
    if all(s["total"] == 0 for s in splits):
        return "HOLDS"
    if all(s["recurrent_below_cap"] == 0 for s in splits):
        return "DEPENDS"
    return "FAILS"


# ============================================================================ C1, C2: two processes
def claim_c1(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, panels = [], []
    for cap in prof.caps_2p:
        solved = ctx.solve(ctx.scenario("paper_p14.toml", [f"tau_cap={cap}"]))
        _, ids = _idle_grid(solved)
        acts = [solved.action_tuple(s) for s in ids]
        other = ids[np.array([a != (1, 2) for a in acts], dtype=bool)]
        split = _split(solved, other)
        labels = sorted({a for a in acts})
        per_cap.append({"cap": cap, "idle_states": int(ids.size), "actions_seen": [list(a) for a in labels],
                        "other_action_states": split, "gain": solved.gain})
        panels.append((solved, "idle", {"axes": (1, 2)}))
    verdict = _verdict_from_split([r["other_action_states"] for r in per_cap])
    figs = _maps_figure(ctx, panels[-1:], "c1_fig3_policy_p14", "Processes 1 and 4, idle servers (Fig. 3)")
    tab = ctx.save_table([{"cap": r["cap"], "idle_states": r["idle_states"],
                           **{f"other_{k}": v for k, v in r["other_action_states"].items()}} for r in per_cap],
                         "c1_fig3_counts")
    parts = [f"cap {r['cap']}: {r['other_action_states']['total']} of {r['idle_states']} idle states choose another "
             f"action ({r['other_action_states']['recurrent']} recurrent)" for r in per_cap]
    return ClaimResult("C1", "Fig. 3", "", verdict, "; ".join(parts) + ".", {"per_cap": per_cap}, figs, [tab],
                       details="Action (1, 2) here means paper process 1 to the remote server and paper process 4 "
                               "(our process 2 of this scenario) to the edge.")


def claim_c2(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, panels = [], []
    for cap in prof.caps_2p:
        solved = ctx.solve(ctx.scenario("paper_p12.toml", [f"tau_cap={cap}"]))
        _, ids = _idle_grid(solved)
        acts = np.array([solved.action_tuple(s) for s in ids])
        is21 = np.all(acts == (2, 1), axis=1)
        is12 = np.all(acts == (1, 2), axis=1)
        tau = solved.mdp.states.tau[ids]
        s21 = ids[is21]
        t21 = tau[is21]
        rec = {
            "cap": cap,
            "idle_states": int(ids.size),
            "share_(1,2)": float(is12.mean()),
            "count_(2,1)": int(is21.sum()),
            "(2,1)_split": _split(solved, s21),
            "(2,1)_tau1_range": [int(t21[:, 0].min()), int(t21[:, 0].max())] if s21.size else None,
            "(2,1)_tau2_range": [int(t21[:, 1].min()), int(t21[:, 1].max())] if s21.size else None,
            "(2,1)_all_upper_left": bool(np.all(t21[:, 1] > t21[:, 0])) if s21.size else None,
            "gain": solved.gain,
        }
        per_cap.append(rec)
        panels.append((solved, "idle", {"axes": (1, 2)}))
    shape = all(r["share_(1,2)"] > 0.5 and r["count_(2,1)"] > 0 and r["(2,1)_all_upper_left"] for r in per_cap)
    any_rec = any(r["(2,1)_split"]["recurrent"] > 0 for r in per_cap)
    verdict = "HOLDS" if shape else ("DEPENDS" if any(r["count_(2,1)"] > 0 for r in per_cap) else "FAILS")
    figs = _maps_figure(ctx, panels[:1] + panels[-1:] if len(panels) > 1 else panels,
                        "c2_fig4_policy_p12", "Processes 1 and 2, idle servers (Fig. 4)")
    tab = ctx.save_table([{k: (v if not isinstance(v, dict) else str(v)) for k, v in r.items()} for r in per_cap],
                         "c2_fig4_counts")
    parts = [f"cap {r['cap']}: (1,2) in {r['share_(1,2)']:.0%} of idle states, (2,1) in {r['count_(2,1)']} "
             f"(tau_1 in {r['(2,1)_tau1_range']}, tau_2 in {r['(2,1)_tau2_range']}; "
             f"{r['(2,1)_split']['recurrent']} recurrent)" for r in per_cap]
    any_21 = any(r["count_(2,1)"] > 0 for r in per_cap)
    summary = "; ".join(parts) + "."
    if any_21 and not any_rec:
        summary += (" The (2,1) states are never visited in the long run under the optimal policy, so they do not "
                    "change its average cost.")
    elif not any_21:
        summary += " No idle state chooses (2,1) at these caps."
    return ClaimResult("C2", "Fig. 4", "", verdict, summary, {"per_cap": per_cap}, figs, [tab])


# ============================================================================ C4, C5: three processes
def claim_c4(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    per_cap, figs = [], []
    for cap, total in zip(prof.caps_3p, prof.slice_total_3p):
        solved = ctx.solve(ctx.scenario("paper_p123.toml", [f"tau_cap={cap}"]))
        sol = solved.as_solution()
        stats = region_stats(solved.mdp, sol, "idle", total=total, axes=(1, 2, 3), scenario=solved.scenario)
        per = stats["per_action"]
        per_cap.append({
            "cap": cap,
            "plane_total": total,
            "cells": stats["cells"],
            "unreachable": stats["unreachable"],
            "actions_present": stats["actions_present"],
            "regions_total": stats["regions_total"],
            "regions": {name: {k: v[k] for k in ("cells", "components", "holes", "simply_connected")}
                        for name, v in per.items()},
        })
        fig, ax = subplots(figsize=(7.5, 6.8))
        plot_policy_slice(solved.mdp, sol, "idle", total, ax=ax, stationary=solved.stationary,
                          scenario=solved.scenario)
        figs += ctx.save_figure(fig, f"c4_fig7_slice_p123_cap{cap}_sum{total}")
    def ok(r):
        return r["regions_total"] == 4 and all(v["simply_connected"] for v in r["regions"].values())

    simply = [all(v["simply_connected"] for v in r["regions"].values()) for r in per_cap]
    if all(ok(r) for r in per_cap):
        verdict = "HOLDS"
    elif any(simply):
        verdict = "DEPENDS"
    else:
        verdict = "FAILS"
    parts = [f"cap {r['cap']}, plane sum {r['plane_total']}: {r['regions_total']} regions of "
             f"{r['actions_present']} actions, "
             + ("each simply connected" if s else "not all simply connected") for r, s in zip(per_cap, simply)]
    tab = ctx.save_table([{"cap": r["cap"], "plane_total": r["plane_total"], "action": name, **v}
                          for r in per_cap for name, v in r["regions"].items()], "c4_fig7_regions")
    return ClaimResult("C4", "Figs. 6-7", "", verdict, "; ".join(parts) + ".", {"per_cap": per_cap}, figs, [tab])


def claim_c5(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    cap = prof.caps_3p[0]
    sc = ctx.scenario("paper_p123.toml", [f"tau_cap={cap}"])
    solved = ctx.solve(sc)
    mdp = solved.mdp
    remote, edge = sc.servers
    # Fig. 8: edge serving process 3 with 3 slots left, remote idle; Fig. 9: remote serving 1 with 4 left
    remote_idle = ((0,) * max(remote.uplink_delay - 1, 0), 0, 0, (0,) * remote.downlink_delay)
    edge_idle = ((0,) * max(edge.uplink_delay - 1, 0), 0, 0, (0,) * edge.downlink_delay)
    edge_busy3 = (edge_idle[0], 3, 3, edge_idle[3])
    remote_busy1 = (remote_idle[0], 1, 4, remote_idle[3])
    cases = {
        "fig8: edge busy with process 3": ((remote_idle, edge_busy3), 0, 3),
        "fig9: remote busy with process 1": ((remote_busy1, edge_idle), 1, 1),
    }
    numbers, panels = {}, []
    splits = []
    for name, (cfg, free_server, busy_proc) in cases.items():
        c = mdp.states.config_id(cfg)
        if c < 0:
            numbers[name] = {"reachable": False}
            continue
        grid = mdp.states.lookup_grid(c)
        ids = grid[grid >= 0]
        acts = np.array([solved.action_tuple(s) for s in ids])
        same = ids[acts[:, free_server] == busy_proc]
        split = _split(solved, same)
        splits.append(split)
        counts: dict[str, int] = {}
        for a in map(tuple, acts):
            counts[str(a)] = counts.get(str(a), 0) + 1
        numbers[name] = {"reachable": True, "states": int(ids.size), "action_counts": counts,
                         f"free server also sent process {busy_proc}": split}
        panels.append((solved, c, {"axes": (1, 2)}))
    figs = _maps_figure(ctx, panels, "c5_figs8_9_busy_server_p123",
                        f"Processes 1, 2, 3 (cap {cap}): one server busy (Figs. 8-9)")
    verdict = _verdict_from_split(splits) if splits else "FAILS"
    parts = []
    for name, v in numbers.items():
        if not v.get("reachable"):
            parts.append(f"{name}: configuration unreachable")
            continue
        key = next(k for k in v if k.startswith("free server"))
        parts.append(f"{name}: the free server is also sent the busy process in {v[key]['total']} of {v['states']} "
                     f"states ({v[key]['recurrent']} recurrent)")
    return ClaimResult("C5", "Figs. 8-9", "", verdict, "; ".join(parts) + ".", {"cap": cap, **numbers}, figs, [],
                       details="The paper's remark (end of Sec. II): while one server holds process k, the other "
                               "serves processes other than k. Counted over every reachable AoI vector of each "
                               "configuration.")


# ============================================================================ C7-C10: theorems
def _theorem(ctx: Context, cid: str, paper: str, check, instances: list[tuple[str, list[str]]]) -> ClaimResult:
    rows, reports = [], []
    for file, overrides in instances:
        sc = ctx.scenario(file, overrides)

        def compute(sc=sc):
            solved = ctx.solve(sc)
            sol = solved.as_solution()
            pctx = policy_context(solved.mdp, sol, stationary=solved.stationary)
            rep = check(solved.mdp, sol, ctx=pctx)
            return rep.to_json(), None

        rep, _ = ctx.cache.get_or_compute(f"check-{cid}", {"fingerprint": sc.fingerprint()}, compute)
        reports.append(rep)
        worst = rep.get("worst") or {}
        rows.append({
            "scenario": file,
            "overrides": " ".join(overrides),
            "holds": rep["holds"],
            "checked": rep["checked"],
            "violations": rep["violations"],
            "recurrent_violations": rep["recurrent_violations"],
            "at_cap_violations": rep["at_cap_violations"],
            "recurrent_below_cap": rep["split"].get("recurrent_below_cap", 0),
            "ties": rep.get("ties", 0),
            "worst_size": worst.get("size"),
            "worst_states": " / ".join(worst.get("labels", [])),
        })
    if all(r["holds"] for r in rows):
        verdict = "HOLDS"
    elif any(r["recurrent_below_cap"] > 0 for r in rows):
        verdict = "FAILS"  # violated where the chain lives, away from the truncation
    else:
        verdict = "DEPENDS"  # only in states never visited in the long run, or touching the cap
    tab = ctx.save_table(rows, f"{cid.lower()}_verifier")
    parts = [f"{r['scenario'].replace('.toml', '')} {r['overrides']}: {r['violations']}/{r['checked']} violations "
             f"({r['recurrent_violations']} recurrent, {r['at_cap_violations']} at cap, "
             f"{r['recurrent_below_cap']} recurrent below the cap)" for r in rows]
    example = next((e for rep in reports for e in rep.get("examples", []) if e["recurrent"] and not e["at_cap"]), None)
    example = example or next((e for rep in reports for e in rep.get("examples", [])), None)
    details = ""
    if example:
        details = ("Counterexample: " + " vs ".join(f"`{lab}`" for lab in example["labels"])
                   + f" (size {example['size']:.4g}, {'recurrent' if example['recurrent'] else 'transient'}, "
                   f"{'at' if example['at_cap'] else 'below'} the cap)")
        if example.get("info", {}).get("trajectory"):
            details += "\n\nTrajectory:\n\n" + "\n".join(f"{i}. `{step}`" for i, step in
                                                        enumerate(example["info"]["trajectory"], 1))
    numbers = {"instances": rows,
               "tolerance": {k: reports[0].get(k) for k in ("atol", "rtol")} if reports else {},
               "notes": reports[0].get("notes") if reports else ""}
    return ClaimResult(cid, paper, "", verdict, "; ".join(parts) + ".", numbers, [], [tab], details=details)


def _two_and_three(ctx: Context) -> list[tuple[str, list[str]]]:
    prof = ctx.profile
    inst = [(f, [f"tau_cap={c}"]) for f in ("paper_p12.toml", "paper_p14.toml") for c in prof.caps_2p]
    inst += [("paper_p123.toml", [f"tau_cap={c}"]) for c in prof.caps_3p]
    return inst


def _preemption(ctx: Context) -> list[tuple[str, list[str]]]:
    return [("paper_preemption_p12.toml", [f"tau_cap={c}"]) for c in ctx.profile.caps_pre]


def claim_c7(ctx: Context) -> ClaimResult:
    return _theorem(ctx, "C7", "Theorem 1", check_monotonicity, _two_and_three(ctx) + _preemption(ctx))


def claim_c8(ctx: Context) -> ClaimResult:
    return _theorem(ctx, "C8", "Theorem 2", check_threshold, _two_and_three(ctx))


def claim_c10(ctx: Context) -> ClaimResult:
    return _theorem(ctx, "C10", "Theorem 3", check_consistency, _preemption(ctx))


def claim_c9(ctx: Context) -> ClaimResult:
    prof = ctx.profile
    res = _theorem(ctx, "C9", "Figs. 11-12", check_threshold, _preemption(ctx))
    # the maps of Figs. 11 (process 2 in service, process 1 arrived) and 12 (the converse)
    cap = prof.caps_pre[0]
    solved = ctx.solve(ctx.scenario("paper_preemption_p12.toml", [f"tau_cap={cap}"]))
    sc = solved.scenario
    model = solved.mdp.states.model
    panels, regions = [], {}
    for name, b, k in (("fig11: serving process 2, process 1 arrived", (1, 0), 2),
                       ("fig12: serving process 1, process 2 arrived", (0, 1), 1)):
        # the job one slot into service: d = T_k - 1, age U + 1
        c = solved.mdp.states.config_id(model.serving_config(k, b))
        if c < 0:
            regions[name] = "configuration unreachable"
            continue
        st = region_stats(solved.mdp, solved.as_solution(), c, axes=(1, 2), scenario=sc)
        regions[name] = {a: {kk: v[kk] for kk in ("cells", "components", "holes", "simply_connected")}
                         for a, v in st["per_action"].items()}
        panels.append((solved, c, {"axes": (1, 2)}))
    res.figures = _maps_figure(ctx, panels, "c9_figs11_12_preemption_maps",
                               f"Preemption, processes 1 and 2 (cap {cap}): Figs. 11-12")
    res.numbers["maps"] = regions
    return res

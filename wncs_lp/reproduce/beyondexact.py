"""Beyond the paper, B3: certified lower bounds and the bound's policy, up to eight processes, with
a calibration against exact optima past four processes.

The paper stops at four processes because the optimum cannot be computed beyond; the lower
bounds of :mod:`wncs_lp.bounds` need no enumerated MDP, so every instance gets

* every relaxation's certified lower bound (1: private servers; 2: joint configuration, by its
  interior point where that is predicted to fit, on the LP reduced by interchangeable processes;
  3: pairs sharing their private servers, from three processes on) with its time, and ``auto``'s
  choice among them (:func:`~wncs_lp.bounds.lower_bound`), the ``LB`` of the gaps;
* each relaxation's greedy policy, the two-step lookahead on ``auto``'s tables and the paper's
  baselines, each with its average cost and its **certified optimality gap**
  (g_pi_upper - LB) / LB >= (g_pi - g*) / g*
  (:func:`~wncs_lp.bounds.policy_gaps`): g_pi_upper is the upper end of the certified
  matrix-free evaluation on the instances with an exact column, else the one-sided 95% upper
  confidence limit of a seeded Monte Carlo run;
* where g* is known -- processes 1-4 (B2's cached step) and the **calibration instances** past
  four processes (the 5-process shape at cap 10, the 6-process mix at cap 10) -- every gap split
  into the **bound's looseness** (g* - LB) / g* and the **policy's loss** (g_pi - g*) / g*.

Two things take longer than the default profile can give (it must stay under 8 minutes in all):
the exact optima of the calibration instances (the matrix-free solver on 13M and 156M states: 10
and 37 minutes here) and relaxation 2's interior point at six processes cap 10 and at eight
processes cap 20 (minutes each). Both are **shipped as data** (``data/b3_reference.json`` and its
tables), each with the command that reproduces it, and the report says which numbers came from
there: the optima are certified brackets of those commands; the tables certify their bound in
every run by the separable check of :func:`~wncs_lp.bounds.joint_chains.certify_tables` (the check
is the certificate, wherever the tables came from). The profile ``full`` recomputes both.

No verdict: an extra result. Caching: one step per instance (bounds and policies together).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from .context import Context, ExtraResult, Profile
from .fullscale import exact_optimum

__all__ = ["TITLE", "BeyondExactSettings", "Instance", "SETTINGS", "settings_for", "section_b3", "reference"]

TITLE = "Beyond exact: certified lower bounds and near-optimal policies up to 8 processes, calibrated at 5 and 6"

#: The baselines evaluated against each bound beside the relaxations' own policies.
BASELINES = ("suboptimal", "static")
#: The policies of auto's bound: its greedy policy and the two-step lookahead on its tables (the
#: best at eight processes); the other relaxations get their greedy policy only, and the index
#: policy (minutes of priced solves at cap 20) is left to ``wncs-lp bound --policy --compare index``.
OWN = ("bound", "lookahead")
FOUR = "paper_p1234.toml"
#: The reference data shipped with the report (optima and relaxation 2's tables).
REFERENCE_FILE = "b3_reference.json"


@dataclass(frozen=True)
class Instance:
    """One B3 instance: a shipped scenario at one cap, its policies evaluated exactly or not;
    ``calibration``: g* is known (shipped reference data, recomputed by the profile ``full``)."""

    scenario: str
    cap: int
    exact: bool
    calibration: bool = False


@dataclass(frozen=True)
class BeyondExactSettings:
    """How much B3 computes: the instances, the Monte Carlo run of each inexact one, and whether the
    shipped reference data are recomputed (``recompute``: the optima by the matrix-free solver,
    relaxation 2's tables by its interior point)."""

    instances: tuple[Instance, ...]
    slots: int = 20_000
    reps: int = 10
    seed: int = 0
    burn_in: int = 1_000
    p: float = 0.9
    #: bundle steps of relaxation 2's search per instance where it takes the bundle (beyond its
    #: interior point's predicted reach); a count, so the report is the same on every machine, and
    #: the bound is certified whatever stops it.
    steps: int = 10
    recompute: bool = False


#: quick: processes 1-4 at cap 6 (exact) and eight processes at cap 6. default: processes 1-4 at
#: cap 12 (exact, g* from B2), the two calibration instances (g* shipped; policies by Monte Carlo)
#: and eight processes at cap 20 (relaxation 2's tables shipped). full: processes 1-4 at caps 12,
#: 20 (exact) and 30, the calibration instances (the 5-process shape evaluated exactly), the
#: 6-process mix and eight processes at cap 20, everything recomputed.
SETTINGS: dict[str, BeyondExactSettings] = {
    "quick": BeyondExactSettings((Instance(FOUR, 6, True), Instance("bounds_p1234_twice.toml", 6, False)),
                                 slots=5_000, reps=6, steps=3),
    "default": BeyondExactSettings((Instance(FOUR, 12, True), Instance("bounds_mix5.toml", 10, False, True),
                                    Instance("bounds_mix6.toml", 10, False, True),
                                    Instance("bounds_p1234_twice.toml", 20, False)), steps=3),
    "full": BeyondExactSettings((Instance(FOUR, 12, True), Instance(FOUR, 20, True), Instance(FOUR, 30, False),
                                 Instance("bounds_mix5.toml", 10, True, True), Instance("bounds_mix6.toml", 10, False, True),
                                 Instance("bounds_mix6.toml", 20, False), Instance("bounds_p1234_twice.toml", 20, False)),
                                slots=40_000, reps=20, steps=200, recompute=True),
}


def settings_for(profile: Profile) -> BeyondExactSettings:
    return SETTINGS.get(profile.name, SETTINGS["quick"])


# ----------------------------------------------------------------------------- reference data
@lru_cache(maxsize=None)
def _reference() -> dict[str, Any]:
    return json.loads(resources.files(__package__).joinpath("data", REFERENCE_FILE).read_text())


def reference(kind: str, scenario: str, cap: int) -> dict[str, Any] | None:
    """The shipped entry of ``kind`` (``"optima"`` or ``"tables"``) for a scenario at a cap, or None."""
    for entry in _reference()[kind]:
        if entry["scenario"] == scenario and int(entry["cap"]) == int(cap):
            return entry
    return None


def _shipped_tables(entry: dict[str, Any], system) -> list[np.ndarray]:
    """Relaxation 2's shipped tables of every process: stored as each class representative's table
    on its orbits of configurations (:func:`~wncs_lp.bounds.joint_symmetry.orbit_tables`), spread
    back by the swaps of interchangeable processes."""
    from ..bounds.joint_chains import JointData
    from ..bounds.joint_symmetry import process_symmetry, spread_orbit_tables

    with resources.files(__package__).joinpath("data", entry["file"]).open("rb") as fh:
        z = np.load(fh)
        classes = json.loads(str(z["classes"]))
        per_orbit = [np.asarray(z[f"h{i}"], dtype=float) for i in range(len(classes))]
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    if [list(c) for c in sym.classes] != classes:
        raise ValueError(f"{entry['file']}: tables of classes {classes}, the system has {sym.classes}")
    return spread_orbit_tables(sym, data, per_orbit)


# ----------------------------------------------------------------------------- one instance
def _scenario(ctx: Context, inst: Instance, st: BeyondExactSettings):
    # processes 1-4 at B2's p, so g* is B2's; the larger scenarios as shipped
    return ctx.scenario(inst.scenario, [f"tau_cap={inst.cap}"] + ([f"p={st.p!r}"] if inst.scenario == FOUR else []))


def _bound_entry(res, origin: str = "computed") -> dict[str, Any]:
    return {"relaxation": res.relaxation, "lower_bound": float(res.lower_bound), "status": res.status,
            "certified_by": res.certified_by, "seconds": float(res.seconds), "iterations": int(res.iterations),
            "origin": origin}


def _relaxation_2(system, inst: Instance, st: BeyondExactSettings) -> tuple[Any, str, bool]:
    """(relaxation 2's result or None beyond its reach, where its tables came from, whether auto
    solves it by the interior point): the shipped tables where there are some (unless
    recomputing), else auto's search."""
    from ..bounds.joint import ipm_plan, joint_bound, joint_bound_from_tables, joint_reach
    from ..bounds.joint_chains import JointData
    from ..bounds.joint_symmetry import process_symmetry

    if joint_reach(system) is not None:
        return None, "beyond reach", False
    entry = None if st.recompute else reference("tables", inst.scenario, inst.cap)
    if entry is not None:
        data = JointData.from_system(system)
        fits = ipm_plan(data, process_symmetry(system, data))["fits"]
        res = joint_bound_from_tables(system, _shipped_tables(entry, system), chains=False,
                                      source=f"the tables shipped with the report ({entry['command']})")
        return res, "shipped tables, certified in this run", fits
    res = joint_bound(system, max_iter=st.steps, time_limit=None)
    return res, "computed", res.stats.get("ipm_tables") is True


def _compute(ctx: Context, sc, inst: Instance, st: BeyondExactSettings) -> dict[str, Any]:
    """Bounds and gaps at one instance (no g*: that is B2's step or the reference's)."""
    from ..bounds import bound_policy, grouped_bound, lower_bound, policy_gaps
    from ..bounds.lower import AUTO_GROUPED_TIME_LIMIT, auto_pick
    from ..models.system import System

    t0 = time.perf_counter()
    system = System.from_scenario(sc)
    first = lower_bound(system, 1)
    found, origin = [], {}
    res2, origin["joint-configuration"], by_ipm = _relaxation_2(system, inst, st)
    if res2 is not None:
        found.append(res2)
    res3 = None
    # relaxation 3 where auto runs it, and on the calibration instances (every relaxation against g*)
    if system.n_processes >= 3 and (inst.calibration or not by_ipm):
        res3 = grouped_bound(system, relaxation_1=first, cpu_limit=AUTO_GROUPED_TIME_LIMIT)
        if not by_ipm:
            found.append(res3)
    best = auto_pick(found + [first])
    shown = [best] + [r for r in (res2, res3, first) if r is not None and r.relaxation != best.relaxation]
    bounds = [_bound_entry(r, origin.get(r.relaxation, "computed")) for r in shown]
    policies: list = list(OWN) + [bound_policy(r, system) for r in shown[1:]] + list(BASELINES)
    report = policy_gaps(best, system, policies, exact=inst.exact, slots=st.slots, reps=st.reps, seed=st.seed,
                         burn_in=st.burn_in)
    ctx.log(f"B3 {inst.scenario} cap {inst.cap}: LB = {best.lower_bound:.10g} ({best.relaxation}); "
            + ", ".join(f"{r.policy} gap <= {100 * r.gap:.2f}%" for r in report.rows))
    return {"scenario": inst.scenario, "cap": inst.cap, "processes": system.n_processes,
            "servers": len(sc.servers), "states": int(report.states), "how": report.how,
            "bounds": bounds, "policies": [r.summary() for r in report.rows], "seconds": time.perf_counter() - t0}


def _params(sc, inst: Instance, st: BeyondExactSettings) -> dict[str, Any]:
    return {"fingerprint": sc.fingerprint(), "exact": inst.exact, "slots": st.slots, "reps": st.reps,
            "seed": st.seed, "burn_in": st.burn_in, "baselines": list(BASELINES), "own": list(OWN), "steps": st.steps,
            "recompute": st.recompute, "every_relaxation": True,
            "tables": None if st.recompute else reference("tables", inst.scenario, inst.cap),
            "auto": "relaxations 1, 2 (interior point by predicted time, symmetry-reduced), 3",
            "monte_carlo": "the bound's tables as control variate"}  # a cache of plain averages is not reused


def _calibration_optimum(ctx: Context, sc, inst: Instance, st: BeyondExactSettings) -> dict[str, Any]:
    """g* of a calibration instance: the shipped reference, or (``recompute``) the matrix-free
    solver's certified optimum, a cached step, with the reference beside it."""
    ref = reference("optima", inst.scenario, inst.cap)
    if not st.recompute:
        if ref is None:
            raise KeyError(f"no reference optimum shipped for {inst.scenario} at cap {inst.cap}")
        return {**ref, "origin": f"shipped reference ({ref['command']})"}

    def solve():
        from ..models.system import System
        from ..solvers.matrix_free import matrix_free_value_iteration

        t0 = time.perf_counter()
        sol = matrix_free_value_iteration(System.from_scenario(sc), tol=1e-9, on_interrupt="raise")
        return {"gain": float(sol.gain), "gain_lower": float(sol.gain_lower), "gain_upper": float(sol.gain_upper),
                "status": sol.status, "states": int(sol.stats.get("n_states", 0)), "sweeps": int(sol.iterations),
                "seconds": time.perf_counter() - t0}, None

    out, _ = ctx.cache.get_or_compute("b3_optimum", {"fingerprint": sc.fingerprint(), "tol": 1e-9}, solve)
    agrees = ref is None or (out["gain_lower"] <= ref["gain_upper"] and ref["gain_lower"] <= out["gain_upper"])
    return {**out, "origin": "computed in this run (matrix-free value iteration)", "reference": ref,
            "agrees_with_reference": bool(agrees)}


def _instance(ctx: Context, inst: Instance, st: BeyondExactSettings) -> dict[str, Any]:
    sc = _scenario(ctx, inst, st)
    out, _ = ctx.cache.get_or_compute("b3_instance", _params(sc, inst, st),
                                      lambda: (_compute(ctx, sc, inst, st), None))
    out = dict(out)
    if inst.scenario == FOUR:  # g* is B2's cached step (solved there, or here first)
        out["optimum"] = {**exact_optimum(ctx, inst.cap, st.p, per_process=False), "origin": "B2's certified optimum"}
    elif inst.calibration:
        out["optimum"] = _calibration_optimum(ctx, sc, inst, st)
    return out


# ----------------------------------------------------------------------------- the words
def _pct(x: float) -> str:
    return f"{100 * x:.2f}%" if abs(x) >= 5e-5 else f"{100 * x:.1e}%"


def _signed_pct(x: float) -> str:
    # a distance below 0.005% keeps its digits instead of printing as "-0.00%"
    return f"{100 * x:+.2f}%" if abs(x) >= 5e-5 else f"{100 * x:+.1e}%"


def _rows(instances: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for i in instances:
        opt = i.get("optimum")
        g = opt["gain"] if opt else None
        head = {"scenario": i["scenario"], "processes": i["processes"], "servers": i["servers"], "cap": i["cap"],
                "states": i["states"], "g_star": g}
        for b in i["bounds"]:
            rows.append({**head, "row": f"LB {b['relaxation']}", "value": b["lower_bound"], "value_upper": None,
                         "certified_gap": None,
                         # the bound's looseness (g* - LB) / g*, as a signed distance LB / g* - 1
                         "distance_to_g_star": b["lower_bound"] / g - 1 if opt else None,
                         "how": f"{b['origin']}: {b['certified_by']}", "status": b["status"], "seconds": b["seconds"]})
        for r in i["policies"]:
            rows.append({**head, "row": r["policy"], "value": r["gain"], "value_upper": r["gain_upper"],
                         # the policy's loss (g_pi - g*) / g*
                         "certified_gap": r["gap"], "distance_to_g_star": r["gain"] / g - 1 if opt else None,
                         "how": r["how"], "status": r.get("status", "-"), "seconds": r["seconds"]})
    return rows


def _table_md(rows: list[dict[str, Any]]) -> str:
    md = ["| scenario | N | cap | states | row | value | upper (certified / 95% UCL) | certified gap | vs g* | "
          "how | status | seconds |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        up = "-" if r["value_upper"] is None else f"{r['value_upper']:.8g}"
        gap = "-" if r["certified_gap"] is None else f"<= {_pct(r['certified_gap'])}"
        vs = "-" if r["distance_to_g_star"] is None else _signed_pct(r["distance_to_g_star"])
        how = r["how"] if len(r["how"]) <= 90 else r["how"][:87] + "..."
        md.append(f"| {r['scenario'].removesuffix('.toml')} | {r['processes']} | {r['cap']} | {r['states']:,} | "
                  f"{r['row']} | {r['value']:.8g} | {up} | {gap} | {vs} | {how} | {r['status']} | "
                  f"{r['seconds']:.1f} |")
    return "\n".join(md)


def _calibration_md(instances: list[dict[str, Any]]) -> str:
    """Where g* is known: every gap split into the bound's looseness and the policy's loss."""
    md = ["| scenario | N | cap | g* (from) | relaxation | LB | looseness (g* - LB)/g* | best policy | "
          "its gain | loss (g_pi - g*)/g* |", "|---|---|---|---|---|---|---|---|---|---|"]
    for i in instances:
        opt = i.get("optimum")
        if not opt:
            continue
        g = opt["gain"]
        best = min(i["policies"], key=lambda r: r["gain"])
        origin = "shipped" if str(opt.get("origin", "")).startswith("shipped") else "run"
        for n, b in enumerate(i["bounds"]):
            pol = (f"{best['policy']} | {best['gain']:.8g} ({best['how']}) | {_signed_pct(best['gain'] / g - 1)}"
                   if n == 0 else "| | ")
            md.append(f"| {i['scenario'].removesuffix('.toml')} | {i['processes']} | {i['cap']} | {g:.10g} ({origin}) | "
                      f"{b['relaxation']}{' (auto)' if n == 0 else ''} | {b['lower_bound']:.10g} | "
                      f"{_pct(1 - b['lower_bound'] / g)} | {pol} |")
    return "\n".join(md)


def _sentence(i: dict[str, Any]) -> str:
    best = i["bounds"][0]
    pol = {r["policy"].split("[")[0]: r for r in i["policies"] if not r["policy"].startswith("bound")}
    b = min((r for r in i["policies"] if r["policy"].startswith(("bound", "lookahead"))), key=lambda r: r["gap"])
    s = (f"{i['processes']} processes ({i['scenario'].removesuffix('.toml')}, cap {i['cap']}, {i['states']:,} "
         f"states): LB = {best['lower_bound']:.8g} ({best['relaxation']})")
    opt = i.get("optimum")
    if opt:
        s += f", {_pct(1 - best['lower_bound'] / opt['gain'])} below g* = {opt['gain']:.8g}"
    s += (f"; the best bound's policy ({b['policy']}) is within {_pct(b['gap'])} of g* (certified"
          f"{'' if i['how'] == 'exact' else ', 95% upper confidence limit'}")
    if opt:
        s += f"; {_signed_pct(b['gain'] / opt['gain'] - 1)} from g*"
    s += ")"
    if "suboptimal" in pol:
        s += f", the paper's suboptimal policy within {_pct(pol['suboptimal']['gap'])}"
    return s + "."


def _provenance(instances: list[dict[str, Any]], st: BeyondExactSettings) -> str:
    """Which numbers came from the shipped reference data, said in words."""
    shipped_opt = [f"{i['scenario'].removesuffix('.toml')} cap {i['cap']}" for i in instances
                   if str(i.get("optimum", {}).get("origin", "")).startswith("shipped")]
    shipped_tab = [f"{i['scenario'].removesuffix('.toml')} cap {i['cap']}" for i in instances
                   if any(b["origin"].startswith("shipped") for b in i["bounds"])]
    out = []
    if shipped_opt:
        out.append(f"The optima g* of {', '.join(shipped_opt)} are shipped reference data (certified brackets of the "
                   "matrix-free solver, 10-40 minutes each here; the command of each is in the table's data file "
                   "wncs_lp/reproduce/data/b3_reference.json), not computed in this run.")
    if shipped_tab:
        out.append(f"Relaxation 2's value tables of {', '.join(shipped_tab)} are shipped too (its interior point takes "
                   "minutes there); their bound is certified in this run by the separable check, which holds for any "
                   "tables.")
    mismatch = [f"{i['scenario']} cap {i['cap']}" for i in instances
                if i.get("optimum", {}).get("agrees_with_reference") is False]
    if mismatch:
        out.append(f"The recomputed optimum does NOT match the shipped reference at {', '.join(mismatch)}.")
    if out:
        out.append("`wncs-lp reproduce --profile full` recomputes all of it.")
    elif st.recompute:
        out.append("Every optimum and every relaxation was computed in this run.")
    return " ".join(out)


def section_b3(ctx: Context) -> ExtraResult:
    """B3: beyond exact (see the module docstring)."""
    st = settings_for(ctx.profile)
    # the instances are independent and mostly single-threaded (interior point, Monte Carlo): side by
    # side in the run's worker processes first, then read here from the cache
    # the longest first: exact rows (matrix-free evaluations) before Monte Carlo ones
    todo = [((inst.exact, len(sc.processes) * inst.cap), inst) for inst in st.instances
            if ctx.cache.load("b3_instance", _params(sc := _scenario(ctx, inst, st), inst, st)) is None]
    ctx.prefetch_calls(_instance, [(inst, st) for _, inst in sorted(todo, key=lambda t: t[0], reverse=True)])
    instances = [_instance(ctx, inst, st) for inst in st.instances]
    rows = _rows(instances)
    tab = ctx.save_table(rows, "b3_beyond_exact")
    summary = " ".join(_sentence(i) for i in instances)
    open_rows = [f"{r['scenario'].removesuffix('.toml')} cap {r['cap']} {r['row']} ({r['status']})" for r in rows
                 if not r["row"].startswith("LB ") and r["status"] not in ("optimal", "-")]
    if open_rows:  # an exact evaluation that did not close is said, never hidden in the table
        summary += " NOT every evaluation closed its certificate: " + "; ".join(open_rows) + "."
    stopped = sorted({r["status"] for r in rows if r["row"].startswith("LB ") and r["status"] != "optimal"})
    if stopped:  # a bound is certified whatever stopped its search; the status says what did
        summary += (f" Some relaxations stopped before their own tolerance ({', '.join(stopped)}); their "
                    "bounds are certified all the same.")
    provenance = _provenance(instances, st)
    if provenance:
        summary += " " + provenance
    calibration = _calibration_md(instances)
    details = (
        "Every lower bound is certified without the enumerated MDP (relaxation 1: each process alone with "
        "private servers whose capacity is shared on average, certified by the priced chains' policy-iteration "
        "bounds; relaxation 2: separable value tables over (AoI, configuration), certified by one pass over every "
        "(configuration, action) pair, found by the interior point where it is predicted to fit (on the LP reduced "
        "by interchangeable processes), else by bundle steps; relaxation 3: relaxation 1 with pairs of processes "
        "sharing their private servers). The first LB row of an instance is auto's choice, the LB of its gaps. A "
        "certified gap (upper - LB) / LB bounds the policy's distance to the unknown g* from above; 'upper' is the "
        "certified end of the matrix-free evaluation on exact rows, the one-sided 95% upper confidence limit of "
        f"{st.reps} x {st.slots:,} slots (seed {st.seed}, burn-in {st.burn_in:,}) on Monte Carlo rows. 'vs g*' "
        f"uses B2's certified optimum of processes 1-4 (p = {st.p:g}) and the calibration optima: for an LB row "
        "it is minus the bound's looseness (g* - LB) / g*, for a policy its loss (g_pi - g*) / g*. Relaxation 2's "
        f"search takes at most {st.steps} bundle steps where it takes the bundle; its bound is certified whatever "
        "stops it. `wncs-lp bound SCENARIO --set tau_cap=C` gives any row again. This is an extra result, not a "
        "claim of the paper: there is no verdict.\n\n"
        + (f"Calibration (g* known): the gap split into the bound's looseness and the best policy's loss.\n\n"
           f"{calibration}\n\n" if calibration.count("\n") > 1 else "")
        + _table_md(rows))
    numbers = {"instances": instances, "slots": st.slots, "reps": st.reps, "seed": st.seed, "p": st.p,
               "steps": st.steps, "recompute": st.recompute}
    return ExtraResult("B3", TITLE, summary, numbers, [], [tab], details)

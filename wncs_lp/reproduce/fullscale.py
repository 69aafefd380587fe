"""Beyond the paper, B2: the paper's four processes solved exactly (no verdict).

The paper proposes its separable suboptimal policy because the optimum of its four-process
system (``paper_p1234.toml``) could not be computed. The matrix-free certified value iteration
(:mod:`wncs_lp.solvers.matrix_free`) computes it, and :func:`~wncs_lp.solvers.matrix_free.matrix_free_evaluate`
gives the exact (certified) average cost of each baseline at the same scale, so every gap below
is a ratio of two certified numbers, not a Monte Carlo estimate:

* at p = 0.9, one instance per cap of the profile: optimal, suboptimal, static (the
  specification's default assignment) and greedy;
* a Fig. 10-style sweep over the success probability p at one cap (the largest the profile
  affords): the same four policies.

Every instance also gets the certified long-run expected number of processes at their cap
(:func:`~wncs_lp.solvers.matrix_free.matrix_free_cap_mass`) of the optimal policy (and of the
baselines on the smaller instances): an upper bound on the share of time with some process at
its cap, the measure of how much a number leans on the truncation (:mod:`wncs_lp.truncation`).
At p each process's own share is given too (one evaluation per process,
:func:`~wncs_lp.solvers.matrix_free.matrix_free_cap_masses`); the sweep's instances get the sum
only (one evaluation).

p = 1 is not in the sweep: there a static assignment's chain has several recurrent classes
(a process never loses an update, so the class depends on the initial state) and one certified
gain over every state does not exist; the claims' C6 covers p = 1 on the enumerated models.

Caching: one step of the reproduction cache per (instance, policy), so an interrupted run
resumes solve by solve.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..truncation import CAP_MASS_WARN
from ..viz import subplots
from .context import Context, ExtraResult, Profile, assignment_label

__all__ = ["TITLE", "FullScaleSettings", "SETTINGS", "POLICIES", "settings_for", "section_b2", "exact_optimum",
           "warm_kernels",
           "fullscale_findings", "summary_text"]

SCENARIO = "paper_p1234.toml"
#: The baselines, in the order of the paper's Fig. 10.
POLICIES = ("suboptimal", "static", "greedy")
#: The section's title (kept when it cannot be computed).
TITLE = "The paper's four processes solved exactly: how far the suboptimal policy is"
LABELS = {"optimal": "optimal (certified)", "suboptimal": "suboptimal (paper, Sec. III)", "static": "static",
          "greedy": "greedy"}


@dataclass(frozen=True)
class FullScaleSettings:
    """How much B2 computes.

    ``caps``: the caps of the instances at ``p``; ``sweep_cap`` / ``p_grid``: the sweep over p;
    ``tol``: the relative width of every certificate; ``mass_max_states``: the baselines' time
    at the cap is computed up to this many states (the optimal policy's always);
    ``per_process``: at p, each process's share of the optimal policy's time at the cap too.
    """

    caps: tuple[int, ...]
    sweep_cap: int
    p_grid: tuple[float, ...]
    p: float = 0.9
    tol: float = 1e-7
    mass_max_states: int = 5_000_000
    #: each process's own time at the cap (N evaluations of the optimal policy) at p, not only the sum
    per_process: bool = True
    #: the baselines simulated without the AoI cap at the largest cap (the untruncated interval's upper end)
    untruncated_slots: int = 1_000
    untruncated_reps: int = 5


#: Per profile, chosen by measurement on 2 cores: processes 1-4 at cap 6 (48k states) take under
#: a second per solve or evaluation, at cap 8 (293k) 2-3 s, at cap 12 (2.9M) 5-25 s, at cap 20
#: (38.0M) 40-120 s, at cap 25 (108M) 2-4 min and at cap 30 (247M) 3-6 min. The default profile
#: keeps this section near a minute, so cap 20, the sweep at cap 20 and each process's own time at
#: the cap (four more evaluations of the optimal policy: 30 s at cap 12) are in ``full``; the
#: default's sweep runs at cap 8.
SETTINGS: dict[str, FullScaleSettings] = {
    "quick": FullScaleSettings(caps=(6,), sweep_cap=6, p_grid=(0.8, 0.9)),
    "default": FullScaleSettings(caps=(12,), sweep_cap=8, p_grid=(0.8, 0.85, 0.9, 0.95), mass_max_states=1_000_000,
                                 per_process=False, untruncated_slots=5_000, untruncated_reps=10),
    "full": FullScaleSettings(caps=(12, 20, 25, 30), sweep_cap=20, p_grid=(0.8, 0.85, 0.9, 0.95),
                              untruncated_slots=40_000, untruncated_reps=20),
}


def settings_for(profile: Profile) -> FullScaleSettings:
    return SETTINGS.get(profile.name, SETTINGS["quick"])


def warm_kernels(ctx: Context) -> None:
    """Compile the matrix-free kernels, serial and threaded, into numba's on-disk cache on a small
    instance (processes 1-4 at cap 6). The run starts this in a worker process
    (:meth:`Context.start_in_worker`) while it computes the claims, so that B2 and B3 load the
    kernels instead of compiling them cold (about 20 s on 2 cores)."""
    import warnings

    from ..models.system import System
    from ..policies import GreedyPolicy
    from ..solvers.matrix_free import matrix_free_evaluate, matrix_free_value_iteration

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        system = System.from_scenario(ctx.scenario(SCENARIO, ["tau_cap=6"]))
        for threads in (1, 2):
            matrix_free_value_iteration(system, threads=threads, progress=False)
            matrix_free_evaluate(system, GreedyPolicy(system), threads=threads, progress=False)


# ----------------------------------------------------------------------------- one instance
def exact_optimum(ctx: Context, cap: int, p: float, tol: float = 1e-7, per_process: bool = True) -> dict[str, Any]:
    """The certified optimum of processes 1-4 at (cap, p), one cached step shared by B2 and B3.

    Returns ``gain``, ``gain_lower``, ``gain_upper``, ``status``, ``states``, ``sweeps``,
    ``seconds`` and the optimal policy's time at the cap: ``at_cap`` (the expected number of
    processes at their cap, certified) and, with ``per_process``, each process's share
    ``at_cap_per_process`` (N evaluations instead of one). A request without ``per_process``
    takes the per-process step when the cache has it.
    """
    from ..models.system import System
    from ..policies import MatrixFreePolicy
    from ..solvers.matrix_free import matrix_free_value_iteration

    sc = ctx.scenario(SCENARIO, [f"tau_cap={cap}", f"p={p!r}"])
    system = System.from_scenario(sc)

    def optimal():
        t0 = time.perf_counter()
        sol = matrix_free_value_iteration(system, tol=tol, on_interrupt="raise")
        n = int(sol.stats.get("n_states", sol.local_actions.size))
        ctx.log(f"processes 1-4 cap {cap} p={p:g}: optimal g* = {sol.gain:.10g} ({n:,} states, "
                f"{time.perf_counter() - t0:.1f} s)")
        res = {"gain": float(sol.gain), "gain_lower": float(sol.gain_lower), "gain_upper": float(sol.gain_upper),
               "status": sol.status, "states": n, "sweeps": int(sol.iterations),
               "seconds": time.perf_counter() - t0}
        res.update(_optimal_mass(system, MatrixFreePolicy.from_solution(sol), per_process))
        res["q_at_cap"] = [float(system.q[k][int(system.caps[k]) - 1]) for k in range(system.n_processes)]
        res["seconds_total"] = time.perf_counter() - t0
        return res, None

    full = {"fingerprint": sc.fingerprint(), "tol": tol}
    if not per_process:
        hit = ctx.cache.load("b2_optimal", full)
        if hit is not None:
            return hit[0]
    res, _ = ctx.cache.get_or_compute("b2_optimal", full if per_process else {**full, "masses": "total"}, optimal)
    return res


def _optimal_mass(system, policy, per_process: bool) -> dict[str, Any]:
    """The optimal policy's certified time at the cap: the sum, and each process's share if asked."""
    from ..solvers.matrix_free import matrix_free_cap_mass, matrix_free_cap_masses

    if not per_process:
        ev = matrix_free_cap_mass(system, policy, on_interrupt="raise")
        return {"at_cap": float(ev.gain), "at_cap_lower": float(ev.gain_lower), "at_cap_upper": float(ev.gain_upper),
                "at_cap_status": ev.status}
    per = matrix_free_cap_masses(system, policy, on_interrupt="raise")
    return {"at_cap": float(sum(e.gain for e in per)), "at_cap_lower": float(sum(e.gain_lower for e in per)),
            "at_cap_upper": float(sum(e.gain_upper for e in per)),
            "at_cap_status": "optimal" if all(e.status == "optimal" for e in per) else per[0].status,
            "at_cap_per_process": [float(e.gain) for e in per]}


def _instance(ctx: Context, cap: int, p: float, st: FullScaleSettings, per_process: bool) -> dict[str, Any]:
    """Optimal gain and every baseline's exact gain at one (cap, p); each a cached step."""
    from ..models.system import System
    from ..policies import GreedyPolicy, StaticPolicy, SuboptimalPolicy, default_assignment
    from ..solvers.matrix_free import matrix_free_cap_mass, matrix_free_evaluate

    sc = ctx.scenario(SCENARIO, [f"tau_cap={cap}", f"p={p!r}"])
    fp = sc.fingerprint()
    system = System.from_scenario(sc)
    assignment = [int(a) for a in default_assignment(sc)]
    where = f"B2 cap {cap} p={p:g}"

    def mass_of(policy) -> dict[str, Any]:
        ev = matrix_free_cap_mass(system, policy, on_interrupt="raise")
        return {"at_cap": float(ev.gain), "at_cap_lower": float(ev.gain_lower),
                "at_cap_upper": float(ev.gain_upper), "at_cap_status": ev.status}

    out = {"cap": cap, "p": p, "assignment": assignment, "assignment_label": assignment_label(sc, assignment)}
    out["optimal"] = exact_optimum(ctx, cap, p, st.tol, per_process)
    n = out["optimal"]["states"]
    with_mass = n <= st.mass_max_states
    for name in POLICIES:
        def evaluate(name=name):
            t0 = time.perf_counter()
            pol = {"suboptimal": lambda: SuboptimalPolicy(system), "static": lambda: StaticPolicy(system, assignment),
                   "greedy": lambda: GreedyPolicy(system)}[name]()
            ev = matrix_free_evaluate(system, pol, tol=st.tol, on_interrupt="raise", name=name)
            ctx.log(f"{where}: {name} g = {ev.gain:.10g} ({time.perf_counter() - t0:.1f} s)")
            res = {"gain": float(ev.gain), "gain_lower": float(ev.gain_lower), "gain_upper": float(ev.gain_upper),
                   "status": ev.status, "sweeps": int(ev.iterations), "seconds": time.perf_counter() - t0}
            if with_mass:
                res.update(mass_of(pol))
            res["seconds_total"] = time.perf_counter() - t0
            return res, None

        params = {"fingerprint": fp, "tol": st.tol, "policy": name, "mass": with_mass,
                  "assignment": assignment if name == "static" else None}
        out[name], _ = ctx.cache.get_or_compute("b2_evaluate", params, evaluate)
    return out


def untruncated(ctx: Context, cap: int, p: float, lower: float, st: FullScaleSettings) -> dict[str, Any]:
    """The interval for the optimum without the AoI cap at (cap, p), a cached step: the certified
    optimum's lower end below (g*(cap) <= g*_inf, docs/model.md), the baselines simulated without
    the cap above (:func:`wncs_lp.untruncated.untruncated_interval`)."""
    from ..models.system import System
    from ..policies import GreedyPolicy, StaticPolicy, SuboptimalPolicy, default_assignment
    from ..untruncated import untruncated_interval

    sc = ctx.scenario(SCENARIO, [f"tau_cap={cap}", f"p={p!r}"])

    def compute():
        system = System.from_scenario(sc)
        pols = [SuboptimalPolicy(system), StaticPolicy(system, default_assignment(sc)), GreedyPolicy(system)]
        iv = untruncated_interval(lower, pols, lower_from=f"the certified optimum at cap {cap}",
                                  slots=st.untruncated_slots, reps=st.untruncated_reps, seed=0)
        ctx.log(f"B2 cap {cap} p={p:g}: without the cap {iv.lower:.10g} <= g*_inf <= {iv.upper:.10g}")
        return iv.to_dict(), None

    params = {"fingerprint": sc.fingerprint(), "lower": lower, "slots": st.untruncated_slots,
              "reps": st.untruncated_reps}
    return ctx.cache.get_or_compute("b2_untruncated", params, compute)[0]


def untruncated_text(iv: dict[str, Any]) -> str:
    """The interval without the cap in one sentence."""
    cands = iv["candidates"]
    starved = [c["policy"] for c in cands if c["note"]]
    tail = (f" ({', '.join(starved)} unbounded without the cap: a process starves)" if starved else "")
    if iv["upper"] is None or not math.isfinite(iv["upper"]):
        return f"Without the AoI cap the optimum is at least {iv['lower']:.10g} ({iv['lower_from']}){tail}."
    return (f"Without the AoI cap, {iv['lower']:.10g} <= g*_inf <= {iv['upper']:.10g}: below, {iv['lower_from']} "
            f"(the truncated optimum is a lower bound, docs/model.md); above, the least one-sided 95% upper "
            f"confidence limit of the {', '.join(c['policy'] for c in cands)} policies simulated without the cap "
            f"({iv['reps']} x {iv['slots']} slots each; {iv['policy']}: {iv['mean']:.8g} +- {iv['stderr']:.3g}){tail}.")


# ----------------------------------------------------------------------------- the findings
def _gap(res: dict[str, Any], opt: dict[str, Any]) -> tuple[float, float, float]:
    """(gap, lower, upper) of g_pi / g* - 1, the interval from both certificates."""
    return (res["gain"] / opt["gain"] - 1.0, res["gain_lower"] / opt["gain_upper"] - 1.0,
            res["gain_upper"] / opt["gain_lower"] - 1.0)


def fullscale_findings(instances: list[dict[str, Any]]) -> dict[str, Any]:
    """The numbers the text quotes, computed from the instances.

    Returns ``gaps`` ({policy: [(cap, p, gap, lower, upper), ...]}), ``ordered`` (optimal <=
    suboptimal <= static <= greedy at every instance, each comparison decided by the
    certificates: a pair whose intervals overlap counts as not violating), ``violations`` (the
    instances where a certified order is reversed), ``all_certified`` (every status optimal)
    and ``mass`` ({(cap, p): processes at the cap of the optimal policy}).
    """
    gaps: dict[str, list] = {name: [] for name in POLICIES}
    violations: list[str] = []
    order = ("optimal",) + POLICIES
    certified = True
    for inst in instances:
        opt = inst["optimal"]
        for name in order:
            certified &= inst[name]["status"] == "optimal"
            certified &= inst[name].get("at_cap_status", "optimal") == "optimal"
        for name in POLICIES:
            gaps[name].append((inst["cap"], inst["p"], *_gap(inst[name], opt)))
        for a, b in zip(order, order[1:]):
            if inst[a]["gain_lower"] > inst[b]["gain_upper"]:  # certified: a is worse than b
                violations.append(f"{a} > {b} at cap {inst['cap']}, p = {inst['p']:g}")
    return {"gaps": gaps, "ordered": not violations, "violations": violations, "all_certified": bool(certified),
            "mass": {(i["cap"], i["p"]): i["optimal"]["at_cap"] for i in instances}}


def _pct(x: float) -> str:
    return f"{100 * x:+.2f}%"


def _above(x: tuple) -> str:
    """Words for one (cap, p, gap, lower, upper) entry: a gap whose interval holds 0 is no gap."""
    if x[3] <= 0.0 <= x[4]:
        return f"equal to the optimum within the certificates at cap {x[0]}"
    return f"{_pct(x[2])} above the optimum at cap {x[0]}"


def _trend(values: list[float]) -> str:
    d = np.diff(values)
    if d.size == 0:
        return ""
    if np.all(d > 0):
        return "grows with the cap"
    if np.all(d < 0):
        return "shrinks with the cap"
    return "is not monotone in the cap"


def cap_text(at_p: list[dict[str, Any]]) -> str:
    """What the optimal policy's time at the cap says, per process (``at_cap_per_process``)."""
    bits, last = [], None
    for i in at_p:
        o = i["optimal"]
        per = o.get("at_cap_per_process")
        if not per:
            bits.append(f"cap {i['cap']}: {o['at_cap']:.3g} processes at their cap on average")
            continue
        bits.append(f"cap {i['cap']}: " + ", ".join(f"{100 * m:.1f}%" for m in per))
        last = (i["cap"], per, o)
    head = ("Share of the time each process spends at its cap under the optimal policy (processes 1-4): "
            if last is not None else "Time at the cap under the optimal policy: ")
    s = head + "; ".join(bits) + "."
    if last is not None:
        cap, per, o = last
        q = o.get("q_at_cap", [math.nan] * len(per))
        most = [k for k, m in enumerate(per) if m > 0.5]
        some = [k for k, m in enumerate(per) if CAP_MASS_WARN < m <= 0.5]
        if most:
            s += (f" Even at cap {cap} the results lean on the truncation through process"
                  f"{'es' if len(most) > 1 else ''} {', '.join(str(k + 1) for k in most)}: "
                  + ", ".join(f"q_{k + 1}(cap) = {q[k]:.4g} ({100 * q[k] / o['gain']:.2g}% of g*)" for k in most)
                  + "; the optimal policy leaves such a process at its cap most of the time, which an unbounded "
                  "AoI would not allow forever (its MSE would keep growing).")
        if some:
            s += (f" At cap {cap} process{'es' if len(some) > 1 else ''} {', '.join(str(k + 1) for k in some)} "
                  f"still spend{'s' if len(some) == 1 else ''} more than {100 * CAP_MASS_WARN:g}% of the time "
                  "at the cap.")
    return s


def summary_text(at_p: list[dict[str, Any]], sweep: list[dict[str, Any]], found: dict[str, Any],
          st: FullScaleSettings, later: FullScaleSettings | None) -> str:
    caps = [i["cap"] for i in at_p]
    p = st.p
    parts = [f"Processes 1-4 at p = {p:g}, solved exactly without a stored matrix: "
             + "; ".join(f"cap {i['cap']} ({i['optimal']['states']:,} states) g* = {i['optimal']['gain']:.10g} "
                         f"(certified to [{i['optimal']['gain_lower']:.10g}, {i['optimal']['gain_upper']:.10g}])"
                         for i in at_p) + "."]
    for name in POLICIES:
        g = [x for x in found["gaps"][name] if x[1] == p and x[0] in caps]
        label = name if name != "static" else f"the static policy ({at_p[0]['assignment_label']})"
        if name == "suboptimal":
            label = "The paper's suboptimal policy"
        s = f"{label[0].upper() + label[1:]} is " + ", ".join(_above(x) for x in g)
        if len(g) > 1:
            s += f" (the gap {_trend([x[2] for x in g])})"
        parts.append(s + ".")
    parts.append(cap_text(at_p))
    if sweep:
        sc = sweep[0]["cap"]
        ps = [i["p"] for i in sweep]
        rng = {name: [x for x in found["gaps"][name] if x[0] == sc and x[1] in ps] for name in POLICIES}

        def span(xs: list) -> str:
            lo, hi = min(xs, key=lambda x: x[2]), max(xs, key=lambda x: x[2])
            if hi[3] <= 0.0 <= hi[4]:
                return "equal to the optimum within the certificates at every p"
            low = f"equal (at p = {lo[1]:g})" if lo[3] <= 0.0 <= lo[4] else _pct(lo[2])
            return f"{low} to {_pct(hi[2])} (at p = {hi[1]:g})"

        at = [i["optimal"].get("at_cap", math.nan) for i in sweep]
        lean = ""
        if any(m > CAP_MASS_WARN for m in at if m == m):
            lo, hi = min(at), max(at)
            lean = (f" These gaps lean on the truncation: at cap {sc} the optimal policy keeps "
                    + (f"{lo:.2g}" if f"{lo:.2g}" == f"{hi:.2g}" else f"{lo:.2g} to {hi:.2g}")
                    + " processes at their cap on average, so the states where the policies differ most are cut off.")
        parts.append(f"Over p = {', '.join(f'{q:g}' for q in ps)} at cap {sc}, above the optimum: the suboptimal "
                     f"policy {span(rng['suboptimal'])}, static {span(rng['static'])}, greedy {span(rng['greedy'])}."
                     + lean)
    parts.append("Optimal <= suboptimal <= static <= greedy at every instance (by the certificates)."
                 if found["ordered"] else "The order optimal <= suboptimal <= static <= greedy is reversed, "
                 "certified: " + "; ".join(found["violations"]) + ".")
    if not found["all_certified"]:
        parts.append("NOT every number closed its certificate: see the status column.")
    if later is not None:
        more = [c for c in later.caps if c not in caps]
        if more or later.sweep_cap != st.sweep_cap:
            parts.append(f"`wncs-lp reproduce --profile full` adds cap{'s' if len(more) > 1 else ''} "
                         f"{', '.join(map(str, more))} and the sweep over p at cap {later.sweep_cap}.")
    return " ".join(parts)


def _rows(instances: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for inst in instances:
        opt = inst["optimal"]
        for name in ("optimal",) + POLICIES:
            r = inst[name]
            gap = _gap(r, opt) if name != "optimal" else (0.0, 0.0, 0.0)
            rows.append({"cap": inst["cap"], "p": inst["p"], "states": opt["states"],
                         "policy": name if name != "static" else f"static ({inst['assignment_label']})",
                         "gain": r["gain"], "gain_lower": r["gain_lower"], "gain_upper": r["gain_upper"],
                         "gap_to_optimum": gap[0], "gap_lower": gap[1], "gap_upper": gap[2],
                         "processes_at_cap": r.get("at_cap", math.nan),
                         "at_cap_per_process": " ".join(f"{m:.4g}" for m in r.get("at_cap_per_process", ())),
                         "seconds": r.get("seconds_total", r["seconds"]),
                         "status": r["status"]})
    return rows


def _table_md(rows: list[dict[str, Any]]) -> str:
    md = ["| cap | p | states (box) | policy | average MSE | certificate [lower, upper] | gap to optimum | "
          "processes at the cap (per process) | seconds | status |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        gap = "-" if r["policy"] == "optimal" else (
            "0 (within the certificates)" if r["gap_lower"] <= 0.0 <= r["gap_upper"] else _pct(r["gap_to_optimum"]))
        mass = "-" if math.isnan(r["processes_at_cap"]) else f"{r['processes_at_cap']:.4g}"
        if r["at_cap_per_process"]:
            mass += f" ({r['at_cap_per_process'].replace(' ', ', ')})"
        md.append(f"| {r['cap']} | {r['p']:g} | {r['states']:,} | {r['policy']} | {r['gain']:.10g} | "
                  f"[{r['gain_lower']:.10g}, {r['gain_upper']:.10g}] | {gap} | {mass} | {r['seconds']:.1f} | "
                  f"{r['status']} |")
    return "\n".join(md)


def _figure(ctx: Context, at_p: list[dict[str, Any]], sweep: list[dict[str, Any]], st: FullScaleSettings) -> list[str]:
    fig, axes = subplots(1, 2, figsize=(12.5, 4.6))
    ax = axes[0]
    caps = [i["cap"] for i in at_p]
    for j, name in enumerate(("optimal",) + POLICIES):
        label = LABELS[name] if name != "static" else f"static ({at_p[0]['assignment_label']})"
        ax.plot(caps, [i[name]["gain"] for i in at_p], "o-", color=f"C{j}", label=label)
    for i in at_p:
        g = _gap(i["suboptimal"], i["optimal"])[0]
        ax.annotate(_pct(g), (i["cap"], i["suboptimal"]["gain"]), textcoords="offset points", xytext=(4, 6),
                    fontsize=8, color="C1")
    ax.set(xlabel="AoI cap", ylabel="long-run average MSE", xticks=caps)
    ax.set_title(f"Processes 1-4, p = {st.p:g}: exact gains by cap", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(frameon=False, fontsize=8)
    ax = axes[1]
    if sweep:
        ps = [i["p"] for i in sweep]
        for j, name in enumerate(("optimal",) + POLICIES):
            label = LABELS[name] if name != "static" else f"static ({sweep[0]['assignment_label']})"
            ax.plot(ps, [i[name]["gain"] for i in sweep], "o-", color=f"C{j}", label=label)
        ax.set(xlabel="success probability p", ylabel="long-run average MSE", xticks=ps)
        ax.set_title(f"Processes 1-4, cap {sweep[0]['cap']}: exact gains vs p (cf. paper Fig. 10)", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    return ctx.save_figure(fig, "b2_four_processes_exact")


def section_b2(ctx: Context) -> ExtraResult:
    """B2: the paper's four processes, exact optimum vs the baselines (see the module docstring)."""
    st = settings_for(ctx.profile)
    done: dict[tuple[int, float], dict[str, Any]] = {}

    def instance(cap: int, p: float) -> dict[str, Any]:
        if (cap, p) not in done:  # each process's time at the cap where the text quotes it: at p
            done[cap, p] = _instance(ctx, cap, p, st, per_process=st.per_process and p == st.p)
        return done[cap, p]

    at_p = [instance(cap, st.p) for cap in st.caps]
    sweep = [instance(st.sweep_cap, p) for p in st.p_grid]
    instances = list(done.values())
    found = fullscale_findings(instances)
    later = SETTINGS["full"] if ctx.profile.name != "full" else None
    summary = summary_text(at_p, sweep, found, st, later)
    top = at_p[-1]
    unt = untruncated(ctx, top["cap"], st.p, top["optimal"]["gain_lower"], st)
    summary += " " + untruncated_text(unt)
    figs = _figure(ctx, at_p, sweep, st)
    rows = _rows(instances)
    tab = ctx.save_table(rows, "b2_four_processes_exact")
    details = (
        f"Setup: `{SCENARIO}` (the paper's processes 1-4 on the remote and the edge server), p = {st.p:g} at caps "
        f"{', '.join(map(str, st.caps))}, and p = {', '.join(f'{q:g}' for q in st.p_grid)} at cap {st.sweep_cap}. "
        "The optimum is `matrix_free_value_iteration` (certified value iteration without a stored matrix: the "
        "Bellman bracket min (Th - h) <= g* <= max (Th - h) over every state); each baseline's average MSE is "
        "`matrix_free_evaluate` (the same bracket for the fixed policy), so a gap is a ratio of two certified "
        f"numbers (relative certificate width {st.tol:g}; the gap's interval from both brackets is in the CSV). "
        "'states (box)' counts the solver's state box, every AoI vector of the box with every configuration, a "
        "superset of the states reachable from the idle start that an enumerated model holds. "
        "'processes at the cap' is the policy's long-run expected number of processes whose AoI is at its cap, "
        "sum_k m_k, an upper bound on the share of time with some process at its cap (for the optimal policy "
        + (f"at p = {st.p:g} from one certified evaluation per process, `matrix_free_cap_masses`, to 1e-6, with "
           "m_k in parentheses; elsewhere " if st.per_process else "")
        + "from one evaluation of the sum, `matrix_free_cap_mass`, to 1e-7; "
        f"for the baselines `matrix_free_cap_mass`, to 1e-7, up to {st.mass_max_states:,} states). p = 1 is left out: a static "
        "assignment's chain is then multichain and has no single gain (claim C6 covers p = 1 on the enumerated "
        "models). This is an extra result, not a claim of the paper: there is no verdict.\n\n" + _table_md(rows))
    numbers = {"caps": list(st.caps), "p": st.p, "sweep_cap": st.sweep_cap, "p_grid": list(st.p_grid),
               "tol": st.tol, "ordered": found["ordered"], "violations": found["violations"],
               "all_certified": found["all_certified"], "instances": instances, "untruncated": unt,
               "gaps": {k: [list(x) for x in v] for k, v in found["gaps"].items()}}
    return ExtraResult("B2", TITLE, summary, numbers, figs, [tab], details)

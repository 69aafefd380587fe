"""Beyond the paper: results the paper does not state, computed with the same care (no verdict).

B2 -- the paper's four processes solved exactly (:mod:`~wncs_lp.reproduce.fullscale`).
B3 -- beyond exact: certified lower bounds and the bound's policy up to eight processes
(:mod:`~wncs_lp.reproduce.beyondexact`).

B1 -- what it costs to use the cloud less. Processes 1 and 2 (``paper_p12.toml``) with
``model.allow_idle = true`` (a server may be left unused), total average MSE against a bound b
on the remote server's send rate (the fraction of slots in which it is sent an update,
``docs/constraints.md``), one trade-off curve (:func:`wncs_lp.constrained.tradeoff.tradeoff`)
per cap. Every point is a certified constrained optimum; the text is computed from the numbers.

Caching: each curve is one step of the reproduction cache (keyed by the scenario fingerprint,
the grid, the method and the code), and while it is computed its points are written to a
resumable trade-off folder under ``cache/tradeoff/``, so an interrupted run resumes point by
point and a second run reads the whole section from the cache without building an MDP.
"""
from __future__ import annotations

import math
import shutil
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from ..studies.tradeoff import TradeoffResult, tradeoff
from ..scenario import ConstraintSpec
from ..viz import plot_tradeoff, subplots
from .context import Context, ExtraResult, Profile
from .beyondexact import TITLE as TITLE_B3
from .beyondexact import section_b3
from .fullscale import TITLE as TITLE_B2
from .fullscale import section_b2

__all__ = ["BEYOND", "TITLES", "BeyondSettings", "SETTINGS", "ExtraResult", "run_beyond", "section_b1", "settings_for",
           "tradeoff_findings"]

#: The sections of "beyond the paper", in report order.
BEYOND = ("B1", "B2", "B3")
#: Their titles (kept when a section cannot be computed).
TITLES = {"B1": "What it costs to use the cloud less (processes 1, 2; remote send rate)", "B2": TITLE_B2,
          "B3": TITLE_B3}

SCENARIO = "paper_p12.toml"
SERVER = "remote"
#: Relative tolerance of the convexity / monotonicity / multiplier checks on the numbers.
CHECK_RTOL = 1e-6
#: The constrained method that re-solves a point the first method does not certify (the LP).
FALLBACK = "lp"


def _grid(a: float, b: float, step: float) -> tuple[float, ...]:
    n = int(math.floor((b - a) / step + 1e-9)) + 1
    return tuple(round(a + i * step, 12) for i in range(n))


@dataclass(frozen=True)
class BeyondSettings:
    """How much B1 computes: the caps (the first is the paper's default) and the bounds."""

    caps: tuple[int, ...]
    values: tuple[float, ...]
    method: str = "auto"
    #: :data:`FALLBACK` (the LP) re-solves a point the first method does not certify, up to this many pairs.
    fallback_max_pairs: int = 25_000


#: Per profile. The larger cap of the default profile is chosen by measurement: the Lagrangian
#: route solves a point at cap 30 (96k pairs) in about 5 s on 2 cores; the LP would need minutes
#: per point at that size. The default's grid has step 0.05 (7 bounds and the halving point: the
#: 13 bounds of step 0.025 took 75-90 s of the default's 9 min 40 s); ``full`` keeps 0.025.
SETTINGS: dict[str, BeyondSettings] = {
    "quick": BeyondSettings(caps=(8, 12), values=_grid(0.0, 0.3, 0.05)),
    "default": BeyondSettings(caps=(12, 30), values=_grid(0.0, 0.3, 0.05)),
    "full": BeyondSettings(caps=(12, 30), values=_grid(0.0, 0.3, 0.025)),
}


def settings_for(profile: Profile) -> BeyondSettings:
    if profile.name in SETTINGS:
        return SETTINGS[profile.name]
    caps = tuple(sorted({profile.caps_2p[0], profile.caps_2p[-1]}))
    return BeyondSettings(caps=caps, values=_grid(0.0, 0.3, 0.05))


# ----------------------------------------------------------------------------- one curve
def _lp_warm_route(mdp, spec: ConstraintSpec, method: str) -> bool:
    """Whether ``method`` solves this curve's points by the LP that one warm HiGHS model re-solves
    point after point (the registry row, or the row ``auto`` picks): then the points run in order."""
    from ..constrained import constraints_for
    from ..constrained.registry import row_that_runs
    from ..methods import BASIS

    return row_that_runs(method, mdp, constraints_for(mdp, [spec])).warm_start == BASIS


def _curve(ctx: Context, cap: int, st: BeyondSettings) -> tuple[TradeoffResult, dict[str, Any]]:
    sc = ctx.scenario(SCENARIO, ["model.allow_idle=true", f"tau_cap={cap}"])
    server = [s.name for s in sc.servers].index(SERVER)
    spec = ConstraintSpec("send_rate", server=server, max=max(st.values), label=f"send_rate[{SERVER}]")
    params = {"fingerprint": sc.fingerprint(), "quantity": "send_rate", "server": SERVER, "side": "max",
              "values": list(st.values), "method": st.method, "fallback_max_pairs": st.fallback_max_pairs,
              "halving_point": True}

    def compute():
        t0 = time.perf_counter()
        mdp = ctx.mdp(sc)
        folder = ctx.cache.root / "tradeoff" / ctx.cache.key("tradeoff", params)
        if ctx.cache.force:
            shutil.rmtree(folder, ignore_errors=True)
        fallback = FALLBACK if st.method != FALLBACK and mdp.n_pairs <= st.fallback_max_pairs else None
        ctx.log(f"trade-off: cap {cap}, {mdp.n_states:,} states, {len(st.values)} bounds ({st.method})")
        # the bounds side by side in the run's worker processes: each point of the Lagrangian route is an
        # independent certified solve (the LP route's warm basis is the only thing carried between points)
        workers = 1 if _lp_warm_route(mdp, spec, st.method) else ctx.workers
        kw = dict(method=st.method, out=folder, plot=False, fallback=fallback, max_workers=workers,
                  progress=lambda line: ctx.log(f"  cap {cap}: {line}"))
        res = tradeoff(mdp, [spec], 0, list(st.values), **kw)
        half = res.threshold / 2
        if math.isfinite(half):  # the cost of halving the send rate, solved exactly (one more point)
            res = tradeoff(mdp, [spec], 0, [*st.values, half], **kw)
        return {"summary": res.summary(), "half": half, "states": int(mdp.n_states), "pairs": int(mdp.n_pairs),
                "p": float(sc.p), "fallback": fallback, "seconds": time.perf_counter() - t0}, None

    doc, _ = ctx.cache.get_or_compute("tradeoff", params, compute)
    return TradeoffResult.from_summary(doc["summary"]), doc


# ----------------------------------------------------------------------------- the findings
def tradeoff_findings(res: TradeoffResult, half: float | None = None) -> dict[str, Any]:
    """The numbers the text of B1 quotes, computed from one curve.

    Returns a dict: unconstrained gain ``g0`` and threshold ``r0``; ``g_zero`` (bound 0) and its
    ratio to g0; ``g_half`` at ``half`` (default r0 / 2, when it is a point of the curve) and the
    relative increase; the multiplier just below the threshold and at the smallest positive
    bound; the number of linear pieces; the largest number of randomised states; and three
    checks on the numbers (non-increasing, convex, each finite-difference slope between the
    multipliers of its two ends).
    """
    pts = [p for p in res.feasible_points]
    b = np.array([p.bound for p in pts])
    g = np.array([p.gain for p in pts])
    lam = np.array([p.multiplier for p in pts])
    g0, r0 = res.unconstrained_gain, res.threshold
    scale = max(1.0, float(np.max(np.abs(g)))) if g.size else 1.0
    tol = CHECK_RTOL * scale
    slopes = np.diff(g) / np.diff(b) if b.size > 1 else np.zeros(0)
    # convex: slopes nondecreasing; a slope between consecutive points lies in [-lam_left, -lam_right]
    convex = bool(np.all(np.diff(slopes) >= -tol / max(float(np.min(np.diff(b))), 1e-12))) if slopes.size > 1 else True
    sandwich = [max(0.0, -s - lam[i], lam[i + 1] + s) / max(1.0, lam[i]) for i, s in enumerate(slopes)]
    out: dict[str, Any] = {
        "g0": g0, "r0": r0, "points": len(pts),
        "nonincreasing": bool(np.all(np.diff(g) <= tol)),
        "convex": convex,
        "slope_between_multipliers_max_rel_violation": float(max(sandwich, default=0.0)),
        "max_randomized_states": int(max((p.randomized_states for p in pts), default=0)),
        "all_optimal": all(p.ok for p in res.points),
    }
    if b.size and b[0] == 0.0:
        out["g_zero"] = float(g[0])
        out["g_zero_over_g0"] = float(g[0] / g0)
    h = r0 / 2 if half is None else half
    match = [p for p in pts if abs(p.bound - h) <= 1e-9]
    if match:
        out["half"] = float(h)
        out["g_half"] = float(match[0].gain)
        out["half_increase_rel"] = float(match[0].gain / g0 - 1.0)
    below = [p for p in pts if p.bound < r0 - 1e-9 and p.multiplier > 0]
    if below:
        out["lambda_below_threshold"] = float(below[-1].multiplier)
        out["lambda_below_threshold_at"] = float(below[-1].bound)
    pos = [p for p in pts if p.bound > 0 and p.multiplier > 0]
    if pos:
        out["lambda_low"] = float(pos[0].multiplier)
        out["lambda_low_at"] = float(pos[0].bound)
    inner = [p.multiplier for p in pts if 0 < p.bound < r0 - 1e-9]
    out["distinct_multipliers_inside"] = sum(
        1 for i, v in enumerate(inner) if i == 0 or abs(v - inner[i - 1]) > 1e-6 * max(1.0, abs(inner[i - 1])))
    return out


def _fmt_pct(x: float) -> str:
    return f"{100 * x:.0f}%" if abs(x) >= 0.095 else f"{100 * x:.1f}%"


def _text(curves: dict[int, TradeoffResult], found: dict[int, dict[str, Any]]) -> str:
    caps = sorted(curves)
    c0, c1 = caps[0], caps[-1]
    f0, f1 = found[c0], found[c1]
    parts = [
        f"Without a bound the optimal policy sends an update to the remote server in {f0['r0']:.4f} of the slots "
        f"at cap {c0} (optimal average MSE {f0['g0']:.6g})"
        + (f" and {f1['r0']:.4f} at cap {c1} ({f1['g0']:.6g})" if c1 != c0 else "") + "."
    ]
    if "half_increase_rel" in f0:
        s = (f"Halving that rate costs {_fmt_pct(f0['half_increase_rel'])} more MSE at cap {c0} "
             f"(b = {f0['half']:.4f}: {f0['g_half']:.6g})")
        if c1 != c0 and "half_increase_rel" in f1:
            s += f" and {_fmt_pct(f1['half_increase_rel'])} at cap {c1} (b = {f1['half']:.4f}: {f1['g_half']:.6g})"
        parts.append(s + ".")
    if "lambda_below_threshold" in f0:
        s = (f"Just below the rate where the bound stops binding, each 0.01 of send rate given up costs "
             f"{f0['lambda_below_threshold'] / 100:.4g} MSE at cap {c0}")
        if c1 != c0 and "lambda_below_threshold" in f1:
            s += f" and {f1['lambda_below_threshold'] / 100:.4g} at cap {c1}"
        s += " (the multiplier / 100)"
        shapes = []
        for c, f in ((c0, f0), (c1, f1)) if c1 != c0 else ((c0, f0),):
            if "lambda_low" not in f or "lambda_below_threshold" not in f:
                continue
            ratio = f["lambda_low"] / f["lambda_below_threshold"]
            if ratio > 1 + 1e-6:
                shapes.append(f"at cap {c} it is {f['lambda_low'] / 100:.4g} near b = {f['lambda_low_at']:g}, "
                              f"{ratio:.3g} times steeper (the multiplier takes {f['distinct_multipliers_inside']} "
                              "values on the grid below the threshold)")
            else:
                shapes.append(f"at cap {c} the multiplier is the same at every bound of the grid below the "
                              "threshold: a straight line")
        parts.append(s + ("; " + "; ".join(shapes) if shapes else "") + ".")
    if "g_zero" in f0:
        s = f"Leaving the cloud unused (b = 0) multiplies the optimal MSE by {f0['g_zero_over_g0']:.3g} at cap {c0}"
        if c1 != c0 and "g_zero" in f1:
            s += f" and by {f1['g_zero_over_g0']:.3g} at cap {c1}"
        parts.append(s + ".")
    if c1 != c0:
        r1, r0 = curves[c1], curves[c0]
        common = sorted({round(p.bound, 12) for p in r0.feasible_points}
                        & {round(p.bound, 12) for p in r1.feasible_points})
        ratios = {bb: r1.point(bb).gain / r0.point(bb).gain for bb in common}
        if ratios:
            lo_b, hi_b = min(common), max(common)
            worst = max(ratios, key=lambda bb: abs(math.log(ratios[bb])))
            s = (f"Cap {c1} against cap {c0}: {ratios[lo_b]:.3g} times the MSE at b = {lo_b:g}, "
                 f"{ratios[hi_b]:.3g} times at b = {hi_b:g}")
            if worst == lo_b and abs(math.log(ratios[lo_b])) > abs(math.log(ratios[hi_b])) * 1.5:
                s += (": the caps differ most where the cloud is used least, so the low-rate end of the curve "
                      "measures the truncation more than the model")
            parts.append(s + ".")
    checks = all(found[c]["nonincreasing"] and found[c]["convex"] for c in caps)
    parts.append(f"Checked on the numbers at every cap: non-increasing and convex "
                 f"{'(yes)' if checks else '(NO: see the numbers)'}, at most "
                 f"{max(found[c]['max_randomized_states'] for c in caps)} randomised state per point "
                 "(theory: at most one for one active bound).")
    if not all(found[c]["all_optimal"] for c in caps):
        parts.append("NOT every point closed its certificate: see the status column.")
    return " ".join(parts)


def _table_md(curves: dict[int, TradeoffResult]) -> tuple[str, list[dict[str, Any]]]:
    rows, md = [], ["| cap | bound b | optimal MSE g* | certificate [lower, upper] | multiplier | randomised states | "
                    "solved by | status |", "|---|---|---|---|---|---|---|---|"]
    for cap in sorted(curves):
        for p in curves[cap].points:
            rows.append({"cap": cap, **p.to_dict()})
            if p.feasible:
                md.append(f"| {cap} | {p.bound:.4g} | {p.gain:.10g} | [{p.gain_lower:.10g}, {p.gain_upper:.10g}] | "
                          f"{p.multiplier:.6g} | {p.randomized_states} | {p.method} | {p.status} |")
            else:
                md.append(f"| {cap} | {p.bound:.4g} | - | - | - | - | {p.method} | {p.status} |")
    return "\n".join(md), rows


def section_b1(ctx: Context) -> ExtraResult:
    st = settings_for(ctx.profile)
    curves: dict[int, TradeoffResult] = {}
    docs: dict[int, dict[str, Any]] = {}
    for cap in st.caps:
        curves[cap], docs[cap] = _curve(ctx, cap, st)
    found = {cap: tradeoff_findings(curves[cap], docs[cap].get("half")) for cap in st.caps}
    summary = _text(curves, found)
    fig, axes = subplots(1, 2, figsize=(12.5, 4.6))
    for i, cap in enumerate(st.caps):
        plot_tradeoff(curves[cap], ax=axes[0], label=f"cap {cap}: constrained optimum", color=f"C{i}")
    axes[0].set_title("Processes 1, 2 (idle allowed): optimal MSE vs remote send rate", fontsize=10)
    for i, cap in enumerate(st.caps):
        res = curves[cap]
        mids, slopes = res.slopes()
        pts = res.feasible_points
        steps = [(k, -s) for k, s in enumerate(slopes) if -s > 0]  # -slope between consecutive bounds
        for j, (k, v) in enumerate(steps):
            axes[1].hlines(v, pts[k].bound, pts[k + 1].bound, color=f"C{i}", linewidth=1.5,
                           label=f"cap {cap}: -slope between bounds" if j == 0 else None)
        inner = [p for p in pts if 0 < p.bound < res.threshold]  # b = 0 and the threshold are kinks
        axes[1].plot([p.bound for p in inner], [p.multiplier for p in inner], "o", color=f"C{i}", markersize=4,
                     markerfacecolor="none", label=f"cap {cap}: multiplier \u03bb at the bound")
    axes[1].set_yscale("log")
    axes[1].set(xlabel="bound b on the remote send rate (updates per slot)",
                ylabel="\u03bb (MSE per unit of send rate)")
    axes[1].set_title("Shadow price of the bound (the curve's slope is -\u03bb)", fontsize=10)
    axes[1].grid(True, alpha=0.3)
    axes[1].legend(frameon=False, fontsize=8)
    fig.tight_layout()
    figs = ctx.save_figure(fig, "b1_tradeoff_remote_send_rate")
    table, rows = _table_md(curves)
    tab = ctx.save_table(rows, "b1_tradeoff_remote_send_rate")
    sizes = "; ".join(f"cap {c}: {docs[c].get('states', 0):,} states, {docs[c].get('pairs', 0):,} pairs"
                      for c in st.caps)
    details = (
        f"Setup: `{SCENARIO}` with `model.allow_idle = true`, p = {docs[st.caps[0]].get('p', float('nan')):g}, "
        f"objective the total average MSE; one `[[constraint]]` with `quantity = \"send_rate\"`, "
        f"`server = \"{SERVER}\"`, `max = b`, swept over b = {st.values[0]:g}..{st.values[-1]:g} "
        f"(step {st.values[1] - st.values[0]:g}) plus b = r0 / 2 (r0: the send rate of the unconstrained optimum) "
        f"at each cap ({sizes}). Each point is `wncs_lp.solve(mdp, \"{st.method}\", constraints=[send_rate <= b])` "
        "(the occupation-measure LP up to its size, the Lagrangian route of certified value iteration beyond; a "
        f"point the first route does not certify is solved again by the LP up to {st.fallback_max_pairs:,} pairs: "
        "column 'solved by'), certified by [Lagrangian bound, exact cost of the returned randomised policy]. The "
        "multiplier is the shadow price of the bound: the curve's slope is -multiplier between kinks. This is an "
        "extra result, not a claim of the paper: there is no verdict.\n\n" + table)
    numbers = {"caps": list(st.caps), "values": list(st.values), "method": st.method,
               "findings": {str(c): found[c] for c in st.caps},
               "curves": {str(c): {**curves[c].summary(), "states": docs[c].get("states"),
                                   "pairs": docs[c].get("pairs"), "fallback": docs[c].get("fallback"),
                                   "seconds_cold": docs[c].get("seconds")} for c in st.caps}}
    return ExtraResult("B1", TITLES["B1"], summary, numbers, figs, [tab], details)


_SECTIONS: dict[str, Callable[[Context], ExtraResult]] = {"B1": section_b1, "B2": section_b2, "B3": section_b3}


def run_beyond(ctx: Context, ids: Sequence[str] = BEYOND, say: Callable[[str], None] | None = None) -> list[dict]:
    """Compute the "beyond the paper" sections; a section that fails is reported, never dropped."""
    out = []
    for sid in ids:
        t0 = time.perf_counter()
        try:
            res = _SECTIONS[sid](ctx)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - reported in the section
            res = ExtraResult(sid, TITLES.get(sid, sid), f"could not be computed: {type(exc).__name__}: {exc}",
                              {"error": traceback.format_exc()}, status="ERROR")
            if say is not None:
                say(f"{sid}: error: {exc}")
        res.seconds = time.perf_counter() - t0
        ctx.timings[sid] = res.seconds
        if say is not None:
            say(f"{sid} (beyond the paper): {res.seconds:.1f} s")
        out.append(res.to_dict())
    return out

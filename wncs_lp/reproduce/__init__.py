"""Reproduce every figure and claim of the paper (claims C1-C16, ``docs/reproduction.md``).

:func:`run_reproduction` computes each claim step by step, caching every step on disk (keyed by
scenario fingerprint and parameters) so an interrupted run resumes and a second run is fast, and
writes ``report.md``, a self-contained ``report.html``, ``report.json``, figures (PNG and SVG) and
the tables behind them (CSV) into the output folder. A claim or section that cannot be computed is
an ERROR (never a finding), listed first in the report; a solve that did not close its certificate
is named, with its status, in the section that used it. The estimate of the run is printed before
the first section and one line after each (:mod:`~wncs_lp.reproduce.plan`).
"""
from __future__ import annotations

import platform
import sys
import time
import traceback
from pathlib import Path
from typing import Callable, Sequence

from ..errors import WncsError
from ..solvers.threads import usable_cores
from .beyond import BEYOND
from .context import PROFILES, ClaimResult, Context, Profile
from .fullscale import warm_kernels
from .plan import Plan
from .report import write_report

__all__ = ["run_reproduction", "PROFILES", "Profile", "CLAIMS"]


def _claims() -> dict[str, Callable[[Context], ClaimResult]]:
    from . import performance, statements, structural

    return {
        "C1": structural.claim_c1,
        "C2": structural.claim_c2,
        "C3": performance.claim_c3,
        "C4": structural.claim_c4,
        "C5": structural.claim_c5,
        "C6": performance.claim_c6,
        "C7": structural.claim_c7,
        "C8": structural.claim_c8,
        "C9": structural.claim_c9,
        "C10": structural.claim_c10,
        "C11": performance.claim_c11,
        "C12": performance.claim_c12,
        "C13": performance.claim_c13,
        "C14": statements.claim_c14,
        "C15": statements.claim_c15,
        "C16": statements.claim_c16,
    }


CLAIMS = tuple(f"C{i}" for i in range(1, 17))
PAPER = {"C1": "Fig. 3", "C2": "Fig. 4", "C3": "Fig. 5", "C4": "Figs. 6-7", "C5": "Figs. 8-9", "C6": "Fig. 10",
         "C7": "Theorem 1", "C8": "Theorem 2", "C9": "Figs. 11-12", "C10": "Theorem 3", "C11": "Fig. 13",
         "C12": "Sec. V end", "C13": "Sec. III", "C14": "Sec. V", "C15": "Sec. V", "C16": "Sec. IV"}


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for mod in ("numpy", "scipy", "clarabel", "cvxpy", "matplotlib", "numba"):
        try:
            out[mod] = __import__(mod).__version__
        except Exception:  # noqa: BLE001 - optional packages
            out[mod] = "not installed"
    from .. import __version__

    out["wncs_lp"] = __version__
    return out


def _commit() -> str:
    """The git commit of the package's source tree (``+ uncommitted changes`` when dirty), or why unknown."""
    import subprocess

    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return "unknown (not run from a git checkout)"
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return head.stdout.strip()[:12] + (" + uncommitted changes" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown (git not available)"


def _merge_previous(path: Path, results: list[ClaimResult]) -> list[ClaimResult]:
    import json

    fresh = {r.id: r for r in results}
    try:
        old = json.loads(path.read_text())["claims"]
    except (OSError, ValueError, KeyError):
        return results
    merged = dict(fresh)
    for c in old:
        if c.get("id") in CLAIMS and c["id"] not in fresh:
            merged[c["id"]] = ClaimResult.from_dict(c)
    return [merged[i] for i in CLAIMS if i in merged]


def _merge_previous_extras(path: Path, extras: list[dict], ids: Sequence[str]) -> list[dict]:
    import json

    fresh = {e["id"]: e for e in extras}
    try:
        old = {e["id"]: e for e in json.loads(path.read_text()).get("beyond", []) if e.get("id") in ids}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        old = {}
    for e in old.values():  # a report written before sections had a status: its errors are errors
        if "status" not in e and str(e.get("summary", "")).startswith("could not be computed"):
            from .beyond import TITLES

            e.update(status="ERROR", title=TITLES.get(e["id"], e.get("title", "")))
    merged = {**old, **fresh}
    return [merged[i] for i in ids if i in merged]


def run_reproduction(
    out: str | Path,
    profile: str | Profile = "default",
    *,
    force: bool = False,
    claims: Sequence[str] | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    threads: int | None = None,
) -> dict:
    """Compute the paper's claims and write the report into ``out``.

    Parameters
    ----------
    out : path
        Output folder (created). Its ``cache/`` makes a second run fast and an interrupted run
        resumable.
    profile : {"quick", "default", "full"} or Profile
        ``quick`` (small caps and grids), ``default`` (the caps of claims.md: 12, 20, 30 where
        the size allows, and the paper's four processes at caps 12 and 20) or ``full``
        (``default`` plus the four processes at caps 25 and 30 and their sweep over p at cap 20).
        Every verdict says which caps it rests on and whether its deciding cap leans on the
        truncation (``basis``). The estimate of each (:mod:`~wncs_lp.reproduce.plan`) is printed
        before the first section.
    force : bool
        Recompute every step, ignoring the cache.
    claims : sequence of str, optional
        Only these claims (default all, C1-C16, and the "beyond the paper" sections, B1, B2 and
        B3; name one of them here to compute it in a partial run).
    progress : bool
        The estimate up front and one line per section (its time, the time elapsed and left) on
        stderr, with the sections' own lines between.
    log : callable, optional
        Receives those lines instead of stderr.
    threads : int, optional
        The most threads any solve uses (:func:`wncs_lp.solvers.threads.thread_limit`); default:
        the machine's cores.

    Returns
    -------
    dict
        ``{"files": {...}, "claims": [ClaimResult.to_dict(), ...], "beyond": [...], "seconds": float,
        "errors": [ids]}`` (``beyond``: the extra results of :mod:`~wncs_lp.reproduce.beyond`,
        without verdicts, each with its ``status``; ``errors``: every claim and section that could
        not be computed).
    """
    from ..solvers.threads import thread_limit

    prof, todo, extra_ids = _arguments(profile, claims)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = log or (lambda m: print(m, file=sys.stderr, flush=True))
    ctx = Context(out, prof, force=force, log=(lambda m: say(f"  {m}")) if progress else (lambda m: None))
    plan = Plan(prof.name, [*todo, *extra_ids])
    if progress:
        say(plan.opening(_threads_used(threads), usable_cores(), 0 if force else _cached_steps(out)))
    t_all = time.perf_counter()
    try:
        if {"B2", "B3"} & set(extra_ids) and todo:  # their kernels compile in a worker while the claims run
            ctx.start_in_worker(warm_kernels)
        with thread_limit(threads):
            results = [_run_claim(ctx, cid, plan, say if progress else None, t_all) for cid in todo]
            extras = [_run_section(ctx, sid, plan, say if progress else None, t_all) for sid in extra_ids]
    finally:
        ctx.close()  # the worker processes of Context.prefetch, also on Ctrl-C
    provenance = _provenance(ctx, prof, _threads_used(threads), time.perf_counter() - t_all)
    if claims is not None:  # a partial run keeps the other claims of an earlier report in this folder
        results = _merge_previous(out / "report.json", results)
        extras = _merge_previous_extras(out / "report.json", extras, BEYOND)
    files = write_report(out, results, provenance, extras)
    errors = [r.id for r in results if r.verdict == "ERROR"] + [e["id"] for e in extras if e.get("status") == "ERROR"]
    return {"files": files, "claims": [r.to_dict() for r in results], "beyond": extras,
            "seconds": provenance["total_seconds"], "errors": errors}


def _arguments(profile: str | Profile, claims: Sequence[str] | None) -> tuple[Profile, list[str], list[str]]:
    """The profile, the claims and the sections to run; checked before anything is created."""
    unknown = [c for c in (claims or ()) if c not in CLAIMS and c not in BEYOND]
    if unknown:
        raise WncsError(f"unknown claim(s) {', '.join(unknown)}: expected some of {', '.join(CLAIMS + tuple(BEYOND))}")
    if isinstance(profile, str) and profile not in PROFILES:
        raise WncsError(f"unknown profile {profile!r}: expected one of {', '.join(PROFILES)}")
    prof = PROFILES[profile] if isinstance(profile, str) else profile
    todo = [c for c in (claims or CLAIMS) if c not in BEYOND]
    extra_ids = list(BEYOND) if claims is None else [c for c in claims if c in BEYOND]
    return prof, todo, extra_ids


def _threads_used(threads: int | None) -> int:
    return usable_cores() if threads is None else int(threads)


def _cached_steps(out: Path) -> int:
    """Steps already in the output folder's cache (a resumed or repeated run)."""
    try:
        return sum(1 for f in (out / "cache").rglob("*.json"))
    except OSError:
        return 0


def _run_claim(ctx: Context, cid: str, plan: Plan, say: Callable[[str], None] | None, t_all: float) -> ClaimResult:
    """One claim: its result, an ERROR (never a finding) when it raises, the solves it used that
    did not close their certificate."""
    t0 = time.perf_counter()
    notes_before = len(ctx.status_notes)
    try:
        res = _claims()[cid](ctx)
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # a claim that cannot be computed is reported as an ERROR, never as a finding
        res = ClaimResult(cid, PAPER[cid], "", "ERROR", f"could not be computed: {type(exc).__name__}: {exc}",
                          {"error": traceback.format_exc()})
        if say is not None:
            say(f"  {cid}: error: {exc}")
    res.paper = res.paper or PAPER[cid]
    res.seconds = time.perf_counter() - t0
    res.solver_notes = list(dict.fromkeys([*res.solver_notes, *ctx.status_notes[notes_before:]]))
    ctx.timings[cid] = res.seconds
    if say is not None:
        outcome = res.verdict + (f" ({len(res.solver_notes)} solve(s) not optimal)" if res.solver_notes else "")
        say(plan.finished(cid, outcome, res.seconds, time.perf_counter() - t_all))
    return res


def _run_section(ctx: Context, sid: str, plan: Plan, say: Callable[[str], None] | None, t_all: float) -> dict:
    """One "beyond the paper" section (:func:`~wncs_lp.reproduce.beyond.run_beyond`)."""
    from .beyond import run_beyond

    (res,) = run_beyond(ctx, [sid], None)
    if say is not None:
        if res.get("status") == "ERROR":
            say(f"  {sid}: error: {res['summary']}")
        outcome = "ERROR" if res.get("status") == "ERROR" else "done (beyond the paper, no verdict)"
        say(plan.finished(sid, outcome, res["seconds"], time.perf_counter() - t_all))
    return res


def _provenance(ctx: Context, prof: Profile, threads: int, seconds: float) -> dict:
    from datetime import datetime, timezone

    return {
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _commit(),
        "profile": prof.name,
        "caps": {"two processes": list(prof.caps_2p), "three processes": list(prof.caps_3p),
                 "preemption": list(prof.caps_pre), "Monte Carlo (2p, 3p)": [prof.sweep_cap_2p, prof.sweep_cap_3p]},
        "p_grid": list(prof.p_grid),
        "monte_carlo": {"slots": prof.mc_slots, "reps": prof.mc_reps, "slots_3p": prof.mc_slots_3p,
                        "reps_3p": prof.mc_reps_3p, "seed": prof.seed},
        "scenario_files": sorted(ctx.scenario_files),
        "versions": _versions(),
        "solver": "policy iteration (exact evaluation, Bellman certificate) up to 60,000 states, "
                  "relative value iteration above; LP results in the solver benchmarks",
        "threads": {"at most": threads, "cores": usable_cores()},
        "timings_seconds": ctx.timings,
        "total_seconds": seconds,
        "cache": {"hits": ctx.cache.hits, "misses": ctx.cache.misses},
        "platform": platform.platform(),
    }

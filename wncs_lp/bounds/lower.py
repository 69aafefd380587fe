"""The entry point of the bounds room: :func:`lower_bound`, the relaxation asked for or the best
certified one (``"auto"``).

It lives apart from the package's ``__init__`` so that the policy factory can offer the bound's
policy by name without importing :mod:`~wncs_lp.bounds.gaps`, which takes its comparators from
that factory.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from ..arguments import keywords, real, shown, whole
from ..errors import ArgumentError, WncsError
from ..models.guard import require_memory
from ..models.system import System
from ..scenario import Scenario
from .all_pairs import all_pairs_bound, all_pairs_size
from .grouped import grouped_bound
from .inputs import bound_system
from .joint import ipm_plan, joint_bound, joint_reach, joint_size
from .joint_chains import JointData
from .joint_symmetry import process_symmetry
from .pairs import pairs_bound, pairs_size
from .private import private_bound
from .result import BoundResult

__all__ = ["RELAXATIONS", "AUTO_SEARCH", "AUTO_GROUPED_TIME_LIMIT", "AUTO_ASCENT_STEPS",
           "AUTO_ASCENT_MAX_BYTES", "AUTO_PAIRS_STEPS", "AUTO_PAIRS_BUDGET", "AUTO_PAIRS_CPU_PER_WORK",
           "AUTO_PAIRS_MAX_BYTES", "AUTO_PAIRS_MIN_GAIN", "AUTO_PAIRS_IPM_TOL", "AUTO_PAIRS_IPM_FROM",
           "AUTO_ALL_PAIRS_BUDGET", "AUTO_ALL_PAIRS_GUARD", "AUTO_ALL_PAIRS_MAX_BYTES", "AUTO_ALL_PAIRS_MIN_LUMP",
           "lower_bound", "parse_relaxation", "auto_pick", "runs_grouped", "all_pairs_plan"]

#: The relaxations :func:`lower_bound` knows, and their short names (the command line's 1 / 2).
RELAXATIONS = ("auto", "private-servers", "joint-configuration", "grouped-private-servers", "joint-pairs",
               "joint-all-pairs")
_SHORT = {"1": "private-servers", "2": "joint-configuration", "3": "grouped-private-servers", "4": "joint-pairs",
          "5": "joint-all-pairs"}


#: Relaxation 2's search under ``"auto"`` unless given: ``max_iter`` bundle steps (a count, so the
#: bound and its policy are the same on every machine) and no wall-clock limit. Relaxation 2 takes
#: its interior point only where that is predicted to fit (``joint.IPM_BUDGET`` seconds of CPU, a
#: measured model), guarded by a multiple of the prediction in CPU time (``joint.IPM_GUARD``), so a
#: loaded machine does not cut a solve that would finish (a wall-clock guard had cut one on a
#: loaded machine: docs/bounds.md, "How the tables are found"). Its bound is certified
#: whatever stops the search, and it starts at relaxation 1's (``lower_bound(x, 2)`` keeps its own
#: defaults, 1000 steps and 10 minutes).
AUTO_SEARCH = {"max_iter": 30, "time_limit": None}
#: Relaxation 3's guard under ``"auto"`` unless ``time_limit`` is given: seconds of CPU time (its
#: ``cpu_limit``) after which no more candidate pairs are measured and the multiplier search stops
#: (its bound is certified whatever stops it). CPU time, not wall clock, so that the bound ``auto``
#: returns is the same on a loaded machine as on a quiet one (a 300 s wall-clock limit had cut the
#: pair search of the 16-process instances under load 7-11).
AUTO_GROUPED_TIME_LIMIT = 300.0


#: Beyond relaxation 2's reach (its whole LP), ``"auto"`` still evaluates relaxation 2's Lagrangian on
#: the lumped chains (:func:`~wncs_lp.bounds.joint.joint_bound` with ``method="ascent"``) this many
#: steps from relaxation 1's prices: one, the start, never below relaxation 1. Where measured at
#: sixteen processes the start was the best point of 100 supergradient steps, and the smoothed
#: ascent (``method="smooth"``) in a comparable budget gained 0.05% at ``bounds_lab16`` and nothing at
#: ``bounds_p1234_x4`` while taking the command past ten minutes of CPU (docs/bounds.md, "Relaxation
#: 2 and the lookahead at sixteen processes").
AUTO_ASCENT_STEPS = 1
#: ... where its arrays are estimated to fit this many bytes.
AUTO_ASCENT_MAX_BYTES = 3 * 2**30

#: Relaxation 4 (pairs) under ``"auto"``: only where relaxation 2 was solved by its interior point
#: (its tables at its optimum: pairs are the way further), from three processes on, and where its
#: start plus :data:`AUTO_PAIRS_STEPS` bundle steps are predicted to take at most
#: :data:`AUTO_PAIRS_BUDGET` seconds of CPU (``pairs_size``'s sweep work times
#: :data:`AUTO_PAIRS_CPU_PER_WORK`, measured: docs/bounds.md, "Relaxation 4") and its tables to fit
#: :data:`AUTO_PAIRS_MAX_BYTES`. It pays only where relaxation 2 leaves a gap the pairs see, which
#: the start measures: the bundle runs, and the result competes with the others, only when the
#: start raised relaxation 2's bound by more than :data:`AUTO_PAIRS_MIN_GAIN` (relative).
#: A count of steps, no wall clock: the same bound on every machine.
AUTO_PAIRS_STEPS = 50
AUTO_PAIRS_BUDGET = 480.0
AUTO_PAIRS_CPU_PER_WORK = 3.7e-7
AUTO_PAIRS_MAX_BYTES = 2**30
AUTO_PAIRS_MIN_GAIN = 1e-4
#: Where relaxation 4 follows (its rule above) and relaxation 2's interior point is predicted to take
#: at least :data:`AUTO_PAIRS_IPM_FROM` seconds of CPU, IPX stops at this tolerance instead of
#: ``tol``: the pairs start from the coupling duals repaired by the chains, and at eight processes,
#: cap 20 the looser duals gave the pairs a *higher* start (9048.16 against 9045.38 from the duals at
#: 1e-6) at about 60% of IPX's CPU (36 iterations against 58), relaxation 2's own bound 0.037% lower (docs/bounds.md,
#: "Relaxation 4"). Where IPX is quicker (processes 1-4: 23-87 s) ``tol`` stays.
AUTO_PAIRS_IPM_TOL = 1e-2
AUTO_PAIRS_IPM_FROM = 200.0

#: Relaxation 5 (every pair's ages at once, its LP solved whole by IPX) under ``"auto"``: from two
#: processes on, where its LP is predicted to take at most :data:`AUTO_ALL_PAIRS_BUDGET` seconds of
#: CPU (:func:`~wncs_lp.bounds.all_pairs.all_pairs_size`'s count and
#: :data:`~wncs_lp.bounds.all_pairs.ALL_PAIRS_TIME_MODEL`, measured: docs/bounds.md, "Relaxation 5")
#: and its memory estimate is at most :data:`AUTO_ALL_PAIRS_MAX_BYTES`; where the whole LP does not
#: fit, with the ages lumped at the largest threshold that does, but not below
#: :data:`AUTO_ALL_PAIRS_MIN_LUMP` of the largest cap (lumped at 0.3-0.4 of the cap it still
#: halved relaxation 4's looseness on the cloud and both servers; at half of cap 12 on the edge it
#: gave no more than relaxation 2, whose LP the lumped one contains: docs/bounds.md, "The lumping
#: trade-off"). IPX is stopped at
#: :data:`AUTO_ALL_PAIRS_GUARD` (``factor`` times the prediction plus ``slack`` seconds of CPU), so a
#: solve far beyond its prediction costs a bounded time and certifies nothing (said in
#: ``auto_reason``). Counted, never built, where it is skipped: milliseconds at sixteen processes.
#: Where relaxation 2 was solved by its interior point and relaxation 4's start runs, that start is
#: the probe: relaxation 5 runs only where it raised relaxation 2's bound (the pairs see a gap).
AUTO_ALL_PAIRS_BUDGET = 120.0
AUTO_ALL_PAIRS_GUARD = {"factor": 3.0, "slack": 30.0}
AUTO_ALL_PAIRS_MAX_BYTES = 3 * 2**30
AUTO_ALL_PAIRS_MIN_LUMP = 1 / 3

#: Why relaxation 2 does not run on a lazily explored system.
LAZY_NOTE = ("the system's configuration automaton is explored lazily (too large to enumerate), and relaxation 2's "
             "tables live on every joint configuration; relaxations 1 and 3 need only the private ones")


def parse_relaxation(name: str | int) -> str:
    """``1`` / ``"1"`` / ``"private-servers"`` -> ``"private-servers"`` (likewise 2, 3 and auto).

    Raises
    ------
    WncsError
        An unknown name (the message lists the allowed ones).
    """
    text = _SHORT.get(str(name).strip(), str(name).strip())
    if text not in RELAXATIONS:
        raise WncsError(f"unknown relaxation {name!r}; expected one of 1, 2, 3, 4, 5, {', '.join(RELAXATIONS)}")
    return text


def lower_bound(scenario_or_system: Scenario | System, relaxation: str | int = "auto", **options: Any) -> BoundResult:
    """A certified lower bound on the optimal gain g* of a Section II scenario.

    Parameters
    ----------
    scenario_or_system : Scenario or System
    relaxation : {"auto", "private-servers", "joint-configuration", "grouped-private-servers", "joint-pairs", \
"joint-all-pairs"}
        or 1 / 2 / 3 / 4 / 5.
        ``"joint-all-pairs"`` (relaxation 5, :mod:`~wncs_lp.bounds.all_pairs`): every pair's ages
        kept jointly with the joint configuration, all pairs at once (the level-2 LP of
        :mod:`~wncs_lp.bounds.level2`, solved whole, its duals certified); at least as tight as
        relaxation 4 with any pairing and as relaxation 2's LP; its LP's size is checked against
        the memory before it is built; run by ``"auto"`` where its LP is predicted to fit
        :data:`AUTO_ALL_PAIRS_BUDGET` (whole, else with lumped ages).
        ``"joint-pairs"`` (relaxation 4, :mod:`~wncs_lp.bounds.pairs`): relaxation 2 solved, then
        its tables and prices carried to pairs of processes whose ages are kept jointly; never
        looser than relaxation 2; run by ``"auto"`` after relaxation 2's interior point where
        predicted to fit and where its start pays (:data:`AUTO_PAIRS_STEPS`).
        ``"auto"``: the largest certified bound of relaxation 1, relaxation 2 when the instance is
        within its reach (beyond it, on an enumerated system, its Lagrangian at relaxation 1's
        prices on the lumped chains: :data:`AUTO_ASCENT_STEPS`), and relaxation 3 (pairs, :mod:`~wncs_lp.bounds.grouped`)
        when there are at least three processes and relaxation 2 was not solved by its interior
        point (where it was, it was the tighter: processes 1-4, cap 20, 1547.6 against 1441.2);
        relaxation 4 (pairs) after relaxation 2's interior point where it fits and its start pays
        (:data:`AUTO_PAIRS_STEPS`; the interior point then stops at :data:`AUTO_PAIRS_IPM_TOL`
        where it is slow, :data:`AUTO_PAIRS_IPM_FROM`), its start alone where relaxation 5 runs
        whole (whose LP contains relaxation 4's); relaxation 5 where its LP, whole or lumped, is
        predicted to fit (:func:`all_pairs_plan`, :data:`AUTO_ALL_PAIRS_BUDGET`), unless relaxation
        4's start, run, saw no gap beyond relaxation 2 (a heuristic: the pairs at relaxation 2's
        prices add nothing); on a tie the first of 5, 2, 4, 3, 1. ``stats["auto_choice"]``, ``stats["auto_reason"]`` and
        ``stats["auto_bounds"]`` say which was taken, why, and what each gave. Relaxation 2's
        search then stops as :data:`AUTO_SEARCH` says unless ``max_iter`` / ``time_limit`` are given.
    **options
        Keyword arguments of the relaxation's function (e.g. ``tol``, ``progress``). Under
        ``"auto"`` relaxations 1 and 3 take only ``tol`` and ``progress`` (and relaxation 3 the
        ``time_limit`` given, else :data:`AUTO_GROUPED_TIME_LIMIT` seconds of CPU); the others go to
        relaxation 2.

    Returns
    -------
    BoundResult

    Raises
    ------
    WncsError
        An unknown relaxation, or a model without the
        relaxation (the preemption model), refused before any work with the reason.
    """
    name = parse_relaxation(relaxation)
    if not isinstance(scenario_or_system, (Scenario, System)):
        raise ArgumentError("scenario_or_system", f"expected a Scenario or a System, got {shown(scenario_or_system)}")
    _check_options(name, options)
    if name == "private-servers":
        return private_bound(scenario_or_system, **options)
    if name == "grouped-private-servers":
        return grouped_bound(scenario_or_system, **options)
    if name == "joint-all-pairs":
        system = _as_system(scenario_or_system)
        if system.is_lazy:
            raise WncsError(f"relaxation {name} asked for, but {LAZY_NOTE}")
        return all_pairs_bound(system, **options)  # its LP's size checked against the memory first
    if name in ("joint-configuration", "joint-pairs"):
        system = _as_system(scenario_or_system)
        if system.is_lazy:
            raise WncsError(f"relaxation {name} asked for, but {LAZY_NOTE}")
        size = joint_size(system)  # estimate first: refuse, with the cheaper routes, what would not fit
        require_memory(_joint_bytes(system, size, options) if name == "joint-configuration" else size["memory_bytes"],
                       f"relaxation 2 on {system.n_processes} processes ({size['lp_nnz']:,} "
                       f"LP nonzeros, {size['configurations']:,} joint configurations)",
                       ["relaxation 3 (--relaxation 3: pairs sharing private servers)",
                        "relaxation 1 (--relaxation 1: seconds at any size)"])
        return joint_bound(system, **options) if name == "joint-configuration" else pairs_bound(system, **options)
    return _auto(_as_system(scenario_or_system), {**AUTO_SEARCH, **options})


def _auto(system: System, options: dict) -> BoundResult:
    """``"auto"``: every relaxation that applies, the largest certified bound returned."""
    found: list[BoundResult] = []
    notes: list[str] = []
    plan5 = all_pairs_plan(system)
    res2, note = _try_joint(system, {**({} if plan5["whole"] else _pairs_ipm_tol(system)), **options})
    if res2 is not None:
        found.append(res2)
    if note:
        notes.append(note)
    # relaxation 4's start (relaxation 2's tables carried to pairs) is the probe of a gap the pairs see;
    # where relaxation 5 runs whole its LP contains relaxation 4's, so the start alone is taken
    res4, note, probe = _try_pairs(system, res2, options, steps=0 if plan5["whole"] else AUTO_PAIRS_STEPS)
    if res4 is not None:
        found.append(res4)
    if note:
        notes.append(note)
    if plan5["runs"] and probe in ("no gap", "failed"):
        why = "saw no gap beyond relaxation 2" if probe == "no gap" else "could not run"
        notes.append(f"relaxation 5 not run: relaxation 4's start {why} ({plan5['rule']})")
    else:
        res5, note = _try_all_pairs(system, plan5, options)
        if res5 is not None:
            found.insert(0, res5)
        if note:
            notes.append(note)
    res1 = _try(private_bound, system, _private_options(options))
    if res1 is not None and runs_grouped(system, res2):
        limit = options.get("time_limit")
        res3 = _try(grouped_bound, system, {**_private_options(options), "relaxation_1": res1,
                                            **({"cpu_limit": AUTO_GROUPED_TIME_LIMIT} if limit is None
                                               else {"time_limit": limit})})
        if res3 is not None:
            found.append(res3)
    if res1 is not None:
        found.append(res1)
    if not found:
        return private_bound(system, **_private_options(options))  # raises the model's reason
    return auto_pick(found, notes)


def runs_grouped(system: System, joint_result: BoundResult | None) -> bool:
    """``"auto"``'s rule for relaxation 3: from three processes on, where relaxation 2 was not
    solved by its interior point (where it was, it was the tighter)."""
    return system.n_processes >= 3 and (joint_result is None or joint_result.stats.get("ipm_tables") is not True)


def auto_pick(found: list[BoundResult], notes: list[str] = ()) -> BoundResult:
    """``"auto"``'s choice among certified bounds listed in the order 5, 2, 4, 3, 1: the largest (the
    first of equals), with ``stats["auto_choice"]``, ``"auto_reason"`` and ``"auto_bounds"``, and the
    others as ``alternatives`` (their tables may make the better policy: :func:`~wncs_lp.bounds.gaps.policy_source`)."""
    best = max(found, key=lambda r: r.lower_bound)  # max keeps the first of equals: 5, 2, 4, 3, 1
    bounds = {r.relaxation: r.lower_bound for r in found}
    reason = "; ".join([f"the largest certified bound of {', '.join(f'{k} {v:.10g}' for k, v in bounds.items())}"]
                       + list(notes))
    return replace(best, stats={**best.stats, "auto_choice": best.relaxation, "auto_reason": reason,
                                "auto_bounds": bounds},
                   alternatives=tuple(r for r in found if r is not best))  # their tables, for the policies


def _check_options(name: str, options: dict) -> None:
    """Refuse, naming it, a keyword the relaxation does not take (under ``"auto"``, one relaxation 2
    does not take: auto hands its options to relaxation 2 and only ``tol`` and ``progress`` to
    relaxations 1 and 3, so their own options, e.g. ``groups``, are refused there), and a ``tol``,
    ``time_limit`` or ``max_iter`` out of range, before any work."""
    fns = {"private-servers": [private_bound], "grouped-private-servers": [grouped_bound],
           "joint-configuration": [joint_bound], "joint-pairs": [pairs_bound, joint_bound],
           "joint-all-pairs": [all_pairs_bound],
           "auto": [joint_bound]}[name]
    import inspect

    takes = {p for fn in fns for p, v in inspect.signature(fn).parameters.items() if v.kind is v.KEYWORD_ONLY
             or (v.kind is v.POSITIONAL_OR_KEYWORD and p != "scenario_or_system" and p != "system")}
    keywords(options, sorted(takes), f"lower_bound(relaxation={name!r})")
    if "tol" in options:
        real(options["tol"], "tol", lo=0.0, lo_open=True, hi=1.0, hi_open=True)
    if options.get("time_limit") is not None:
        real(options["time_limit"], "time_limit", lo=0.0)
    if "max_iter" in options:
        whole(options["max_iter"], "max_iter", lo=1)


def _private_options(options: dict) -> dict:
    """What relaxation 1 takes of auto's options: the tolerance and the progress (the search
    options, ``max_iter`` and ``time_limit``, are relaxation 2's under auto)."""
    return {k: v for k, v in options.items() if k in ("tol", "progress")}


def _try(relaxation: Any, system: System, options: dict) -> BoundResult | None:
    """Relaxation 1 or 3 for comparison (None where the model has no private servers)."""
    try:
        return relaxation(system, **options)
    except WncsError:
        return None


def _try_joint(system: System, options: dict) -> tuple[BoundResult | None, str]:
    """Relaxation 2 when the instance is within its reach: (its result, "") or (None, why not)."""
    if system.is_lazy:
        return None, f"beyond relaxation 2's reach: {LAZY_NOTE}"
    why_not = joint_reach(system)
    if why_not is not None:
        return _try_lumped(system, options, why_not)
    try:
        res = joint_bound(system, **options)
    except WncsError as exc:
        return None, f"relaxation 2 could not run: {exc}"
    return res, ""


def _lumped_bytes(system: System, size: dict) -> int:
    """Peak bytes of relaxation 2 on the lumped chains: the automaton's outcome arrays, the
    certificate's (outcomes x cap) temporaries, the tables."""
    cap = int(max(system.caps))
    return 8 * size["outcomes"] * (system.n_processes + 4 * cap) + 16 * size["configurations"] * cap * system.n_processes


def _joint_bytes(system: System, size: dict, options: dict) -> int:
    """Peak bytes of relaxation 2 by the route asked: with ``method="ipm"``, ``"ascent"`` or
    ``"smooth"`` on interchangeable processes, the reduced LP (:func:`ipm_plan`) or the lumped
    chains and the certificate, never the whole LP (595M nonzeros at the paper's four types four
    times, 4.25M reduced); otherwise :func:`joint_size`'s estimate of the whole LP."""
    method = options.get("method", "auto")
    if method not in ("ipm", "ascent", "smooth") or options.get("symmetry") is False:
        return size["memory_bytes"]
    need = _lumped_bytes(system, size)
    if method == "ipm":
        data = JointData.from_system(system)
        need += ipm_plan(data, process_symmetry(system, data))["memory_bytes"]
    return need


def _try_lumped(system: System, options: dict, why_not: str) -> tuple[BoundResult | None, str]:
    """Beyond the whole LP's reach: relaxation 2's Lagrangian at relaxation 1's prices on the lumped
    chains (:data:`AUTO_ASCENT_STEPS`), where its arrays fit :data:`AUTO_ASCENT_MAX_BYTES`."""
    need = _lumped_bytes(system, joint_size(system))
    if need > AUTO_ASCENT_MAX_BYTES:
        return None, f"beyond relaxation 2's reach: {why_not}; its lumped chains need ~{need / 2**30:.1f} GiB"
    keep = {k: v for k, v in options.items() if k in ("tol", "progress")}
    try:
        res = joint_bound(system, method="ascent", max_iter=AUTO_ASCENT_STEPS, time_limit=None, **keep)
    except WncsError as exc:
        return None, f"beyond relaxation 2's reach: {why_not}; its lumped chains could not run: {exc}"
    return res, f"relaxation 2's whole LP is out of reach ({why_not}): its Lagrangian at relaxation 1's prices instead"


def _pairs_prediction(system: System) -> tuple[float, dict]:
    """(predicted CPU seconds of relaxation 4's start and :data:`AUTO_PAIRS_STEPS` steps, ``pairs_size``)."""
    size = pairs_size(system)
    return AUTO_PAIRS_CPU_PER_WORK * size["sweep_work"] * (1 + AUTO_PAIRS_STEPS / size["candidates"]), size


def _pairs_fit(predicted: float, size: dict) -> bool:
    return predicted <= AUTO_PAIRS_BUDGET and size["memory_bytes"] <= AUTO_PAIRS_MAX_BYTES


def _pairs_ipm_tol(system: System) -> dict:
    """``{"ipm_tol": AUTO_PAIRS_IPM_TOL}`` where relaxation 4 is predicted to follow relaxation 2's
    interior point and that is predicted to take at least :data:`AUTO_PAIRS_IPM_FROM` seconds of
    CPU; else nothing (IPX at ``tol``)."""
    if system.is_lazy or system.n_processes < 3 or joint_reach(system) is not None:
        return {}
    data = JointData.from_system(system)
    plan = ipm_plan(data, process_symmetry(system, data))
    if not plan["fits"] or plan["predicted_seconds"] < AUTO_PAIRS_IPM_FROM or not _pairs_fit(*_pairs_prediction(system)):
        return {}
    return {"ipm_tol": AUTO_PAIRS_IPM_TOL}


def _try_pairs(system: System, res2: BoundResult | None, options: dict,
               steps: int = AUTO_PAIRS_STEPS) -> tuple[BoundResult | None, str, str]:
    """Relaxation 4 from relaxation 2's result where :data:`AUTO_PAIRS_STEPS`' rule takes it, its
    start and ``steps`` bundle steps: (its result, why, the probe) or (None, why not; "" where it
    does not apply, the probe). The probe -- what its start, run, says of a gap beyond relaxation 2
    (relaxation 5's rule) -- is ``"gap"``, ``"no gap"``, ``"failed"``, or ``""`` where it was not run."""
    if res2 is None or res2.stats.get("ipm_tables") is not True or system.n_processes < 3:
        return None, "", ""
    predicted, size = _pairs_prediction(system)
    if not _pairs_fit(predicted, size):
        return None, (f"relaxation 4 not run: predicted {predicted:.0f} s of CPU (budget {AUTO_PAIRS_BUDGET:.0f}), "
                      f"{size['memory_bytes'] / 2**30:.2f} GiB (at most {AUTO_PAIRS_MAX_BYTES / 2**30:.0f})"), ""
    keep = {k: v for k, v in options.items() if k in ("tol", "progress", "threads")}
    try:
        res = pairs_bound(system, start=res2, max_iter=steps, time_limit=None, min_gain=AUTO_PAIRS_MIN_GAIN, **keep)
    except WncsError as exc:
        return None, f"relaxation 4 could not run: {exc}", "failed"
    if not res.stats.get("start_pays"):
        return None, (f"relaxation 4's start {res.lower_bound:.10g} raised relaxation 2's bound by at most "
                      f"{AUTO_PAIRS_MIN_GAIN:g} of it: not kept"), "no gap"
    if steps == 0:
        return res, "relaxation 4's start only (relaxation 5's whole LP, which contains its constraints, follows)", "gap"
    return res, (f"relaxation 4 from relaxation 2's optimum: {steps} bundle steps (predicted {predicted:.0f} s "
                 "of CPU)"), "gap"


def all_pairs_plan(system: System) -> dict:
    """``"auto"``'s rule for relaxation 5 (:data:`AUTO_ALL_PAIRS_BUDGET`), counted, nothing built.

    Returns
    -------
    dict
        ``runs`` (bool), ``lump`` (None: the whole LP; else the threshold), ``whole`` (runs
        without lumping), ``size`` (:func:`~wncs_lp.bounds.all_pairs.all_pairs_size` of the LP
        that runs, or of the whole LP where nothing does), ``predicted`` (its CPU seconds) and
        ``rule`` (the rule in words, with the prediction).
    """
    def words(z: dict) -> str:
        return (f"{z['cols']:,} columns, {z['nnz']:,} nonzeros, |C x A| = {z['pairs_ca']:,}, chains of "
                f"{z['mean_lump']:.3g} ages: predicted {z['predicted_seconds']:.3g} s of CPU, "
                f"{z['memory_bytes'] / 2**30:.2f} GiB")

    def fits(z: dict) -> bool:
        return z["predicted_seconds"] <= AUTO_ALL_PAIRS_BUDGET and z["memory_bytes"] <= AUTO_ALL_PAIRS_MAX_BYTES

    limits = f"(budget {AUTO_ALL_PAIRS_BUDGET:.0f} s, {AUTO_ALL_PAIRS_MAX_BYTES / 2**30:.0f} GiB)"
    if system.is_lazy or system.n_processes < 2:
        why = LAZY_NOTE if system.is_lazy else "one process: relaxation 1 is exact"
        return {"runs": False, "lump": None, "whole": False, "size": None, "predicted": float("inf"),
                "rule": f"relaxation 5 not run: {why}"}
    whole = all_pairs_size(system)
    if fits(whole):
        return {"runs": True, "lump": None, "whole": True, "size": whole, "predicted": whole["predicted_seconds"],
                "rule": f"relaxation 5, its whole LP: {words(whole)} {limits}"}
    top = int(max(system.caps))
    floor = max(4, int(-(-AUTO_ALL_PAIRS_MIN_LUMP * top // 1)))  # fewer ages apart keep next to nothing
    for c in range(top - 1, floor - 1, -1):  # sizes only grow with c: the first that fits is the largest
        z = all_pairs_size(system, c)
        if fits(z):
            return {"runs": True, "lump": c, "whole": False, "size": z, "predicted": z["predicted_seconds"],
                    "rule": (f"relaxation 5 with ages lumped from {c} on: {words(z)} {limits}; its whole LP "
                             f"{words(whole)}")}
    return {"runs": False, "lump": None, "whole": False, "size": whole, "predicted": whole["predicted_seconds"],
            "rule": (f"relaxation 5 not run: its whole LP {words(whole)} {limits}, and with its ages lumped at "
                     f"any threshold down to {floor} it does not fit either")}


def _try_all_pairs(system: System, plan: dict, options: dict) -> tuple[BoundResult | None, str]:
    """Relaxation 5 where :func:`all_pairs_plan` takes it: (its result, why) or (None, why not)."""
    if not plan["runs"]:
        return None, plan["rule"] if plan["size"] is not None else ""
    g = AUTO_ALL_PAIRS_GUARD
    guard = g["factor"] * plan["predicted"] + g["slack"]
    keep = {k: v for k, v in options.items() if k in ("progress",)}
    try:
        res = all_pairs_bound(system, lump=plan["lump"], cpu_limit=guard, **keep)
    except WncsError as exc:
        return None, f"{plan['rule']}: it could not run ({exc})"
    return res, f"{plan['rule']}; it took {res.stats['solve_cpu']:.3g} s of CPU"


def _as_system(obj: Scenario | System) -> System:
    return bound_system(obj)  # a System checked, its own cost tables honoured

"""Shared machinery of the reproduction: profiles, cached solves, figure and table writers."""
from __future__ import annotations

import csv
import io
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..chain import PolicyChain, recurrent_classes, stationary_law
from ..files import atomic_write_text
from ..formulations import scenario_path
from ..mdp import MDP
from ..models import build
from ..scenario import Scenario, load_scenario
from ..methods import EXACT_METHOD_MAX_STATES, exact_method
from ..solvers.result import Solution
from ..workflow import run_scenario
from ..truncation import CAP_MASS_WARN, CapMass, cap_mass
from ..verify.verdict import decide, subclaims_verdict  # the rules of the verdicts live together
from ..viz import save_figure
from .cache import StepCache, code_version

__all__ = ["Profile", "PROFILES", "Context", "ClaimResult", "Solved", "Step", "Table", "PI_MAX_STATES", "WORKERS",
           "assignment_label", "short_name"]

#: The reproduction solves by policy iteration up to this many states, by relative value
#: iteration above (:func:`wncs_lp.methods.exact_method`; policy iteration's own multichain
#: fallback is the only fallback).
PI_MAX_STATES = EXACT_METHOD_MAX_STATES


@dataclass(frozen=True)
class Profile:
    """How much to compute. Caps are truncations of the paper's unbounded AoI, so every
    cap-sensitive claim is judged at each cap listed here. Every cap lies above the longest loop
    U + T + D of the paper's processes (6 on the remote server for process 1, 8 on the edge): at
    or below it an update never arrives fresher than the cap and the model degenerates.

    ``sweep_cap_2p`` / ``sweep_cap_3p``: the cap of the Monte Carlo runs beside the exact values
    (Figs. 5 and 10; exact values are computed at every cap). ``c4_planes``: the planes
    tau_1 + tau_2 + tau_3 = const of claim C4, each used at every cap of ``caps_3p`` up to 2.25 x cap.
    """

    name: str
    caps_2p: tuple[int, ...]
    caps_3p: tuple[int, ...]
    caps_pre: tuple[int, ...]
    p_grid: tuple[float, ...]
    sweep_cap_2p: int
    sweep_cap_3p: int
    mc_slots: int
    mc_reps: int
    mc_slots_3p: int
    mc_reps_3p: int
    c4_planes: tuple[int, ...]
    c13_caps: tuple[int, ...]
    c13_big_cap: int
    seed: int = 20221


PROFILES: dict[str, Profile] = {
    "quick": Profile(
        name="quick",
        caps_2p=(8, 12),
        caps_3p=(8,),
        caps_pre=(8, 10),
        p_grid=(0.8, 0.9, 1.0),
        sweep_cap_2p=12,
        sweep_cap_3p=8,
        mc_slots=2_000,
        mc_reps=4,
        mc_slots_3p=1_000,
        mc_reps_3p=4,
        c4_planes=(12, 18),
        c13_caps=(7, 8),
        c13_big_cap=12,
    ),
    "default": Profile(
        name="default",
        caps_2p=(12, 20, 30),
        caps_3p=(12, 16, 20),
        caps_pre=(12, 20, 25),
        p_grid=(0.8, 0.85, 0.9, 0.95, 1.0),
        sweep_cap_2p=30,
        sweep_cap_3p=20,
        mc_slots=40_000,
        mc_reps=20,
        mc_slots_3p=10_000,
        mc_reps_3p=10,
        c4_planes=(18, 24, 30, 36, 45),
        c13_caps=(7, 8, 10, 12),
        c13_big_cap=30,
    ),
}
#: ``full``: the claims as in ``default``; "beyond the paper" B2 adds the four processes at caps 25 and 30
#: and its sweep over p at cap 20 (about 45 more minutes on 2 cores).
PROFILES["full"] = replace(PROFILES["default"], name="full")


@dataclass
class Table:
    """A table shown in the report (Markdown and HTML), with its caption."""

    caption: str
    header: list[str]
    rows: list[list[Any]]

    def to_dict(self) -> dict[str, Any]:
        return {"caption": self.caption, "header": list(self.header), "rows": [list(r) for r in self.rows]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Table":
        return cls(d.get("caption", ""), list(d.get("header", [])), [list(r) for r in d.get("rows", [])])


@dataclass
class ClaimResult:
    """One claim of ``claims.md`` with its verdict and the numbers that decide it.

    ``basis`` says where the verdict is decided: every instance used (scenario, cap, p) with the
    stationary mass the optimal policy spends with some AoI at its cap, the deciding (least
    truncated) instances, whether their mass exceeds :data:`~wncs_lp.truncation.CAP_MASS_WARN`
    (``flag``) and the more truncated instances that disagree (``caveats``); see :func:`cap_basis`. ``shown`` are the tables of the report, ``captions`` the figures' captions
    (keyed by the PNG's path).
    """

    id: str
    paper: str
    statement: str
    verdict: str  # HOLDS | FAILS | DEPENDS | ERROR
    summary: str
    numbers: dict[str, Any] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    details: str = ""  # markdown
    seconds: float = 0.0
    basis: dict[str, Any] = field(default_factory=dict)
    shown: list[Table] = field(default_factory=list)
    captions: dict[str, str] = field(default_factory=dict)
    #: The solves this claim used that did not close their certificate (status in words); shown
    #: at the head of its section and beside its verdict.
    solver_notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "paper": self.paper,
            "statement": self.statement,
            "verdict": self.verdict,
            "summary": self.summary,
            "basis": self.basis,
            "numbers": self.numbers,
            "figures": self.figures,
            "captions": self.captions,
            "tables": self.tables,
            "shown": [t.to_dict() for t in self.shown],
            "details": self.details,
            "seconds": self.seconds,
            "solver_notes": list(self.solver_notes),
        }

    @classmethod
    def from_dict(cls, c: dict[str, Any]) -> "ClaimResult":
        return cls(c["id"], c.get("paper", ""), c.get("statement", ""), c["verdict"], c["summary"],
                   c.get("numbers", {}), c.get("figures", []), c.get("tables", []), c.get("details", ""),
                   c.get("seconds", 0.0), c.get("basis", {}), [Table.from_dict(t) for t in c.get("shown", [])],
                   c.get("captions", {}), list(c.get("solver_notes", [])))


@dataclass
class ExtraResult:
    """One section of "beyond the paper": like a claim, but an extra result without a verdict."""

    id: str
    title: str
    summary: str
    numbers: dict[str, Any] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    details: str = ""  # markdown
    seconds: float = 0.0
    status: str = "ok"  # ok | ERROR (could not be computed: the summary says why)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "title": self.title, "summary": self.summary, "numbers": self.numbers,
                "figures": self.figures, "tables": self.tables, "details": self.details, "seconds": self.seconds,
                "status": self.status}


def evidence(label: str, cap: int, mass: float, verdict: str, scenario: str = "", p: float | None = None,
             per_process: Sequence[float] = (), group: str | None = None) -> dict[str, Any]:
    """One instance a verdict rests on (see :func:`cap_basis`). ``group``: what the instance is of
    apart from its cap (default: its scenario; e.g. a scenario and a plane), so that the largest cap
    of each group decides."""
    def share(x: float) -> float:  # a probability, round-off of a summed law clipped to [0, 1]
        return float(min(1.0, max(0.0, x)))

    return {"label": label, "scenario": scenario, "cap": int(cap), "p": p, "mass": share(mass),
            "per_process": [share(m) for m in per_process], "verdict": verdict,
            "group": scenario if group is None else group}


def cap_basis(entries: Sequence[dict[str, Any]], verdict: str | None = None, note: str = "", decides: bool = True,
              how: str = "structural") -> dict[str, Any]:
    """Where a verdict is decided, and whether its deciding instances lean on the truncation.

    ``entries`` come from :func:`evidence`, one per instance (scenario, cap, p or p-grid, ...) with
    its own verdict and the stationary mass of the optimal policy at the cap (for a p-grid: the
    largest over p). The *least truncated* instance of each group (the largest cap of each
    scenario, or scenario and plane) decides (:func:`wncs_lp.verify.verdict.decide`: the deciding
    instances combined structurally -- any FAILS decides -- or, ``how="descriptive"``, DEPENDS when
    they differ); a more truncated instance whose verdict differs from its group's deciding one is
    a *caveat* (``caveats``, printed beside the verdict), never the verdict. ``verdict``: the claim's
    verdict when the claim decides it itself (sub-claims, :func:`subclaims_verdict`, by the same
    rule); default: the one of :func:`~wncs_lp.verify.verdict.decide`. The verdict is *flagged*
    when a deciding instance has more than CAP_MASS_WARN of its long-run time with some AoI at its
    cap (``deciding_mass``: the largest of them; for a FAILS decided here by the structural rule,
    where one counterexample decides, the smallest among the failing deciding instances: such a
    FAILS leans on the truncation only when every counterexample does; a verdict given by the
    claim, from sub-claims that read every deciding instance together, takes the largest). ``decides=False`` (a claim the truncation cannot change,
    said in ``note``): nothing is flagged and the verdict is the one given.
    """
    entries = list(entries)
    out: dict[str, Any] = {"instances": entries, "caps": sorted({e["cap"] for e in entries}),
                           "threshold": CAP_MASS_WARN, "note": note}
    if not entries or not decides:
        return {**out, "verdict": verdict, "deciding": [], "deciding_mass": None, "flag": False, "caveats": []}
    d = decide([(e.get("group", e["scenario"]), e["cap"], e["verdict"]) for e in entries], how)
    deciding = [entries[i] for i in d.deciding]
    failing = [e for e in deciding if e["verdict"] == "FAILS"]
    if verdict is None and d.verdict == "FAILS" and how == "structural" and failing:
        worst = min(e["mass"] for e in failing)  # one counterexample decides: its own truncation
    else:
        worst = max(e["mass"] for e in deciding)
    verdict = d.verdict if verdict is None else verdict
    return {**out, "verdict": verdict, "deciding": [e["label"] for e in deciding],
            "deciding_caps": sorted({e["cap"] for e in deciding}), "deciding_mass": worst,
            "flag": bool(worst > CAP_MASS_WARN),
            "caveats": [{"label": entries[i]["label"], "verdict": entries[i]["verdict"], "cap": entries[i]["cap"],
                         "mass": entries[i]["mass"]} for i in d.caveats]}


def short_name(name: str) -> str:
    """``process-4`` -> ``4``; other names unchanged."""
    import re

    m = re.fullmatch(r"(?i)process[-_ ]?(\w+)", name.strip())
    return m.group(1) if m else name


def assignment_label(scenario: Scenario, assignment: Sequence[int]) -> str:
    """A static assignment in words: ``1->remote, 2->edge, 3->edge`` (paper process names)."""
    return ", ".join(f"{short_name(p.name)}\u2192{scenario.servers[m].name}"
                     for p, m in zip(scenario.processes, assignment))


@dataclass(frozen=True, eq=False)
class Solved:
    """An optimal solution (cached on disk) with the stationary law of its policy.

    ``built`` is the MDP, or a function that builds it: a solve read from the cache builds its MDP
    only when something asks for :attr:`mdp` (a claim that needs only the gains, the mass at the
    cap and the number of recurrent classes, stored with the solve, builds none).
    """

    scenario: Scenario
    built: MDP | Callable[[], MDP]
    gain: float
    gain_lower: float
    gain_upper: float
    policy: np.ndarray  # chosen pair per state
    bias: np.ndarray
    stationary: np.ndarray
    method: str
    seconds: float
    status: str = "optimal"  # the solver's; anything else is said in the claim's section
    #: The mass at the cap, the number of recurrent classes and of states, when the solve stored them.
    stored_cap_mass: CapMass | None = None
    stored_classes: int | None = None
    stored_states: int | None = None
    stored_utilisation: tuple[float, ...] | None = None

    @cached_property
    def utilisation(self) -> tuple[float, ...]:
        """Each server's long-run share of slots with a service step under the optimal policy
        (:func:`utilisation`)."""
        if self.stored_utilisation is not None:
            return self.stored_utilisation
        return utilisation(self.mdp, self.policy, self.stationary)

    @cached_property
    def mdp(self) -> MDP:
        return self.built if isinstance(self.built, MDP) else self.built()

    @cached_property
    def recurrent(self) -> np.ndarray:
        """(n,) bool: the state lies in a closed class of the policy's chain (:mod:`wncs_lp.chain`)."""
        return PolicyChain(self.mdp, self.policy).recurrent

    @property
    def n_states(self) -> int:
        """The number of states of the MDP."""
        return self.stored_states if self.stored_states is not None else self.mdp.n_states

    @property
    def n_classes(self) -> int:
        """The number of recurrent classes of the policy's chain."""
        if self.stored_classes is not None:
            return self.stored_classes
        return len(PolicyChain(self.mdp, self.policy).recurrent_classes)

    @cached_property
    def cap_mass(self) -> CapMass:
        """The stationary mass of the optimal policy with some AoI at its cap (:mod:`wncs_lp.truncation`)."""
        return self.stored_cap_mass if self.stored_cap_mass is not None else cap_mass(self.mdp, self.stationary)

    def evidence(self, label: str, verdict: str, group: str | None = None) -> dict[str, Any]:
        """This solve as one instance a verdict rests on (:func:`cap_basis`; ``group`` as in :func:`evidence`)."""
        m = self.cap_mass
        return evidence(label, max(self.scenario.tau_caps), m.total, verdict, Path(str(self.scenario.source)).stem,
                        self.scenario.p, m.per_process, group)

    @property
    def actions(self) -> np.ndarray:
        """The action label row (into ``mdp.action_table``) of the chosen pair of each state."""
        return self.mdp.a_indices[self.policy]

    def action_tuple(self, s: int) -> tuple[int, ...]:
        return tuple(int(x) for x in self.mdp.action_table[self.mdp.a_indices[self.policy[s]]])

    def as_solution(self) -> Solution:
        return Solution(
            method=self.method,
            status=self.status,
            gain=self.gain,
            gain_lower=self.gain_lower,
            gain_upper=self.gain_upper,
            bias=self.bias,
            policy=self.policy,
        )


#: Worker processes of :meth:`Context.prefetch` (independent instances computed side by side).
WORKERS = 2
#: The policies :meth:`Context.simulate` runs as a table of their actions on the enumerated MDP.
TABLE_FORM = ("static", "greedy")


@dataclass(frozen=True)
class Step:
    """The work on one instance that :meth:`Context.prefetch` hands to a worker process: its
    optimal solve, the baselines' exact evaluations (``evaluate``, by name; ``static``: every
    static assignment, :meth:`Context.static_search`) and Monte Carlo runs (``simulate``:
    ``(policy, slots, reps, seed, burn_in)`` tuples)."""

    scenario: Scenario
    evaluate: tuple[str, ...] = ()
    static: bool = False
    simulate: tuple[tuple[str, int, int, int, int], ...] = ()


def utilisation(mdp: MDP, policy: np.ndarray, stationary: np.ndarray) -> list[float]:
    """Each server's long-run share of slots in which it performs a service step under a
    deterministic policy: ``sum_s pi(s) busy_m(C(s), a(s))`` with the model's busy table
    (:attr:`wncs_lp.models.system.System.busy`: a job in service, or one the action starts)."""
    from ..models.system import System

    system = System.from_scenario(mdp.states.model.scenario)
    local = np.asarray(policy, np.int64) - mdp.pair_ptr[:-1]
    busy = system.busy[np.asarray(mdp.states.config, np.int64), local]  # (n, M)
    return [float(x) for x in np.asarray(stationary) @ busy]


def _solved_law(sol: Solution, P_pi, n_pairs: int) -> np.ndarray | None:
    """The stationary law a unichain solution carries already (e.g. policy iteration's occupation
    of its last policy), when it is one of ``P_pi`` to the stationary tolerance; else None."""
    from ..chain import STATIONARY_TOL

    occ = sol.occupation
    if occ is None or np.shape(occ) != (n_pairs,):
        return None
    pi = np.asarray(occ)[sol.policy]
    ok = abs(pi.sum() - 1.0) <= STATIONARY_TOL and float(np.max(np.abs(P_pi.T @ pi - pi))) <= STATIONARY_TOL
    return pi if ok else None


def _compute_step(ctx: "Context", step: Step) -> None:
    """The work of one :class:`Step`, into ``ctx``'s cache."""
    ctx.solve(step.scenario)
    if step.static:
        ctx.static_search(step.scenario)
    for pol in step.evaluate:
        ctx.evaluate(step.scenario, pol)
    for sim in step.simulate:
        ctx.simulate(step.scenario, *sim)


def _run_call(out: Path, profile: "Profile", fn: Callable[..., Any], args: tuple, code: str) -> bool:
    """``fn(ctx, *args)`` in a worker process, through a Context on the same folder (its cache).
    Returns False, computing nothing, when the package's source is not the parent's ``code``
    (edited since the run started: the parent would not find the results under its keys)."""
    if code_version() != code:
        return False
    ctx = Context(out, profile)
    ctx.workers = 1
    fn(ctx, *args)
    return True


def _run_step(out: Path, profile: "Profile", step: Step, code: str) -> bool:
    """One :class:`Step` in a worker process (:meth:`Context.prefetch`), as :func:`_run_call`."""
    return _run_call(out, profile, _compute_step, (step,), code)


class Context:
    """State shared by the claim computations of one reproduction run."""

    def __init__(self, out: Path, profile: Profile, force: bool = False, log: Callable[[str], None] | None = None):
        self.out = Path(out)
        self.profile = profile
        self.cache = StepCache(self.out / "cache", force=force)
        self.fig_dir = self.out / "figures"
        self.tab_dir = self.out / "tables"
        self.fig_dir.mkdir(parents=True, exist_ok=True)
        self.tab_dir.mkdir(parents=True, exist_ok=True)
        self.log = log or (lambda msg: None)
        self._mdps: dict[str, MDP] = {}
        self._solved: dict[str, Solved] = {}
        self.timings: dict[str, float] = {}
        self.scenario_files: set[str] = set()
        #: Every solve of this run that did not close its certificate, in words (:meth:`note_status`).
        self.status_notes: list[str] = []
        self.workers = WORKERS
        self._pool: Any = None

    def note_status(self, what: str, status: str) -> None:
        """Record a solve whose status is not optimal: the section that used it says so."""
        line = f"{what}: {status}"
        if line not in self.status_notes:
            self.status_notes.append(line)

    # ------------------------------------------------------------------ steps in worker processes
    def prefetch(self, tasks: Sequence[Step]) -> None:
        """Compute independent steps in ``self.workers`` worker processes, into the disk cache.

        Each :class:`Step` (an instance with the solve, evaluations and simulations asked of it)
        runs in a fresh process (spawned: numba's OpenMP layer does not survive a fork) through a
        :class:`Context` on the same folder, exactly as :meth:`solve`, :meth:`evaluate`,
        :meth:`static_search` and :meth:`simulate` compute it here, so the numbers are the same;
        the caller then reads them from the cache. A step that fails in a worker is left to the
        caller, which computes it again and reports the error where it belongs. Nothing runs in
        workers with ``force`` (a forced run ignores the cache) or with fewer than two workers.
        """
        todo = [t for t in tasks if not self._cached(t)]
        self._in_workers(_run_step, [(t,) for t in todo], "instance(s)")

    def prefetch_calls(self, fn: Callable[..., Any], calls: Sequence[tuple]) -> None:
        """Run ``fn(ctx, *args)`` for each ``args`` of ``calls`` in ``self.workers`` worker processes,
        each through a :class:`Context` on the same folder, for the cached steps ``fn`` computes (the
        caller then computes the same calls here, reading the cache). ``fn`` must be a module-level
        function and ``args`` picklable; the rules of :meth:`prefetch` apply (no workers with
        ``force``, with fewer than two workers or for fewer than two calls; a failed call is left to
        the caller)."""
        self._in_workers(_run_call, [(fn, args) for args in calls], "step(s)")

    def start_in_worker(self, fn: Callable[..., Any], *args: Any) -> None:
        """Start ``fn(ctx, *args)`` in a worker process and return at once; its result and errors
        are not read. For work whose effect is outside the run's cache, e.g. compiling kernels
        into numba's on-disk cache while this process computes other sections."""
        if self.workers >= 2:
            self._worker_pool().submit(_run_call, self.out, self.profile, fn, args, code_version())

    def _in_workers(self, job: Callable[..., bool], items: list[tuple], what: str) -> None:
        """``job(out, profile, *item, code)`` for each item in the worker pool; waits for all."""
        if self.workers < 2 or self.cache.force or len(items) < 2:
            return
        from concurrent.futures import wait

        pool = self._worker_pool()
        t0 = time.perf_counter()
        try:
            pending = [pool.submit(job, self.out, self.profile, *item, code_version()) for item in items]
            wait(pending)
        except BaseException:  # Ctrl-C: stop the workers now (the cache keeps what they finished)
            self.close()
            raise
        failed = sum(1 for f in pending if f.exception() is not None)  # a dead worker too: computed here
        if failed:
            self.close()  # a broken pool is not reused
        elif not all(f.result() for f in pending):  # the source changed under the run: no workers from now on
            self.close()
            self.workers = 1
            self.log("the package's source changed since this run started: no more worker processes")
        self.log(f"{len(items)} {what} in {self.workers} worker processes, {time.perf_counter() - t0:.1f} s"
                 + (f" ({failed} failed there, computed here)" if failed else ""))

    def _cached(self, task: Step) -> bool:
        """Every result of the step is in the cache already (a second run starts no worker)."""
        from ..policies import default_assignment
        from ..policies.rules import static_assignments

        sc, fp = task.scenario, task.scenario.fingerprint()
        keys = [] if fp in self._solved else [("solve", {"fingerprint": fp})]  # solved in this run: not read again
        keys += [("evaluate", {"fingerprint": fp, "policy": p, "assignment": None}) for p in task.evaluate]
        if task.static:
            keys += [("evaluate", {"fingerprint": fp, "policy": "static", "assignment": [int(x) for x in a]})
                     for a in [default_assignment(sc), *static_assignments(sc)]]
        keys += [("simulate", {"fingerprint": fp, "policy": p, "slots": int(n), "reps": int(r), "seed": seed,
                               "burn_in": int(b)}) for p, n, r, seed, b in task.simulate]
        return all(self.cache.load(step, params) is not None for step, params in keys)

    def _worker_pool(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"))
        return self._pool

    def close(self) -> None:
        """Stop the worker processes of :meth:`prefetch` (at once: their finished steps are cached)."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:  # the running steps too, not only the queued ones
            if proc.is_alive():
                proc.terminate()

    # ------------------------------------------------------------------ scenarios and solves
    def scenario(self, name: str, overrides: Sequence[str] = ()) -> Scenario:
        path = scenario_path(name)
        self.scenario_files.add(name)
        return load_scenario(path, list(overrides))

    def mdp(self, scenario: Scenario) -> MDP:
        key = scenario.fingerprint()
        if key not in self._mdps:
            self._mdps[key] = build(scenario)
        return self._mdps[key]

    def solve(self, scenario: Scenario) -> Solved:
        """Optimal solution of a scenario: cached on disk (policy, bias, stationary law)."""
        key = scenario.fingerprint()
        if key not in self._solved:
            self._solved[key] = self._solve(scenario, key)
        solved = self._solved[key]
        if solved.status != "optimal":
            self.note_status(f"{Path(str(scenario.source)).name} caps {scenario.tau_caps} p={scenario.p:g} "
                             f"({solved.method}, certificate [{solved.gain_lower:.10g}, {solved.gain_upper:.10g}])",
                             solved.status)
        return solved

    def _solve(self, scenario: Scenario, key: str) -> Solved:
        def compute():
            mdp = self.mdp(scenario)
            self.log(f"solving {Path(scenario.source).name} caps {scenario.tau_caps} p={scenario.p:g} "
                     f"({mdp.n_states:,} states)")
            t0 = time.perf_counter()
            sol = run_scenario(scenario, exact_method(mdp.n_states), constrained=False, mdp=mdp).solution
            P_pi = mdp.P[sol.policy]
            classes = recurrent_classes(P_pi)
            unichain = len(classes) == 1
            stationary = _solved_law(sol, P_pi, mdp.n_pairs) if unichain else None
            if stationary is None:
                stationary, _ = stationary_law(P_pi, classes)  # equal weights on several classes
            res = {
                "gain": float(sol.gain),
                "gain_lower": float(sol.gain_lower),
                "gain_upper": float(sol.gain_upper),
                "method": sol.method,
                "status": sol.status,
                "states": mdp.n_states,
                "pairs": mdp.n_pairs,
                "unichain": unichain,
                "recurrent_classes": len(classes),
                "seconds": time.perf_counter() - t0,
            }
            m = cap_mass(mdp, stationary)  # stored, so a claim reading the solve needs no MDP for it
            res["cap_mass"] = {"total": m.total, "per_process": list(m.per_process), "caps": list(m.caps),
                               "process_names": list(m.process_names)}
            res["utilisation"] = utilisation(mdp, sol.policy, stationary)
            return res, {"policy": sol.policy, "bias": sol.bias, "stationary": stationary}

        res, arr = self.cache.get_or_compute("solve", {"fingerprint": key}, compute)
        m = res.get("cap_mass")
        stored = None if m is None else CapMass(float(m["total"]), tuple(float(x) for x in m["per_process"]),
                                                tuple(int(c) for c in m["caps"]), tuple(m["process_names"]))
        solved = Solved(
            scenario,
            lambda: self.mdp(scenario),
            res["gain"],
            res["gain_lower"],
            res["gain_upper"],
            arr["policy"],
            arr["bias"],
            arr["stationary"],
            res["method"],
            res["seconds"],
            res.get("status", "optimal"),
            stored,
            res.get("recurrent_classes"),
            res.get("states"),
            None if res.get("utilisation") is None else tuple(float(x) for x in res["utilisation"]),
        )
        return solved

    def evaluate(self, scenario: Scenario, policy: str, assignment: Sequence[int] | None = None) -> dict[str, Any]:
        """Exact long-run average cost of a baseline policy (cached on disk).

        ``policy``: ``static`` (the spec's default assignment, or ``assignment``), ``greedy``,
        ``suboptimal`` or ``random``. A multichain chain (e.g. a static policy at p = 1) is
        averaged from the initial state (:func:`wncs_lp.evaluate.evaluate`, ``multichain="initial"``).
        Returns ``{"gain", "name", "label", "assignment", "recurrent_classes"}``.
        """
        from ..evaluate import evaluate
        from ..models.system import System
        from ..policies import GreedyPolicy, RandomPolicy, StaticPolicy, SuboptimalPolicy, default_assignment

        if policy == "static" and assignment is None:
            assignment = default_assignment(scenario)
        a = None if assignment is None else [int(x) for x in assignment]

        def compute():
            system = System.from_scenario(scenario)
            pol = {"static": lambda: StaticPolicy(system, a), "greedy": lambda: GreedyPolicy(system),
                   "suboptimal": lambda: SuboptimalPolicy(system), "random": lambda: RandomPolicy(system)}[policy]()
            ev = evaluate(self.mdp(scenario), pol, system, multichain="initial")
            return {"gain": float(ev.gain), "name": pol.name, "recurrent_classes": int(ev.recurrent_classes)}, None

        res, _ = self.cache.get_or_compute("evaluate", {"fingerprint": scenario.fingerprint(), "policy": policy,
                                                        "assignment": a}, compute)
        label = policy if a is None else f"{policy} ({assignment_label(scenario, a)})"
        return {**res, "assignment": a, "label": label}

    def simulate(self, scenario: Scenario, policy: str, slots: int, reps: int, seed: int, burn_in: int
                 ) -> dict[str, Any]:
        """Monte Carlo of a policy by name (:func:`wncs_lp.simulate.simulate`; cached on disk).

        ``optimal`` simulates the policy of :meth:`solve` (the instance is solved once per run,
        whichever claim asks first); the others are built as a sweep builds them
        (:func:`wncs_lp.workflow.make_policy`, the static one on the spec's default assignment); the
        rule-based ones of :data:`TABLE_FORM` are simulated through their action in each state of the
        enumerated MDP (a deterministic rule draws no random numbers, so the sample paths are the
        same, and a table lookup is cheaper than the rule: about 40% less time per slot).
        Returns ``{"mean", "stderr"}``.
        """
        from ..models.system import System
        from ..policies import TablePolicy
        from ..workflow import make_policy
        from ..simulate import simulate

        def compute():
            system = System.from_scenario(scenario)
            if policy == "optimal":
                solved = self.solve(scenario)
                pol = make_policy(policy, system, solved.mdp, solution=solved.as_solution())
            else:
                pol = make_policy(policy, system)
                if policy in TABLE_FORM:  # the same actions looked up per state: the same paths, faster
                    mdp = self.mdp(scenario)
                    pol = TablePolicy(system, mdp, pol.on_mdp(mdp), name=pol.name)
            res = simulate(pol, slots=slots, reps=reps, seed=seed, burn_in=burn_in, progress=False)
            return {"mean": float(res.mean), "stderr": float(res.stderr)}, None

        params = {"fingerprint": scenario.fingerprint(), "policy": policy, "slots": int(slots), "reps": int(reps),
                  "seed": seed, "burn_in": int(burn_in)}
        res, _ = self.cache.get_or_compute("simulate", params, compute)
        return res

    def static_search(self, scenario: Scenario) -> dict[str, Any]:
        """The default static assignment and ``best_static``: every assignment that gives each
        server a process (:func:`wncs_lp.policies.static_assignments`), evaluated exactly.

        Returns ``{"default": {...}, "best": {...}, "all": [{...}, ...]}`` (entries as
        :meth:`evaluate`; ``best`` is the one of least gain, ties: the first).
        """
        from ..policies import default_assignment
        from ..policies.rules import static_assignments

        default = self.evaluate(scenario, "static", default_assignment(scenario))
        every = [self.evaluate(scenario, "static", a) for a in static_assignments(scenario)]
        best = min(every, key=lambda e: e["gain"])
        return {"default": default, "best": best, "all": every}

    # ------------------------------------------------------------------ outputs
    def save_figure(self, fig, stem: str) -> list[str]:
        """Write a matplotlib figure as PNG and SVG (atomically); return the relative paths."""
        save_figure(fig, self.fig_dir / stem, ("png", "svg"), dpi=130, bbox_inches="tight")
        return [f"figures/{stem}.{ext}" for ext in ("png", "svg")]

    def save_table(self, rows: list[dict[str, Any]], stem: str) -> str:
        """Write rows (dicts with the same keys) as CSV; return the relative path."""
        buf = io.StringIO()
        if rows:
            cols = list(rows[0].keys())
            for r in rows[1:]:
                cols += [k for k in r if k not in cols]
            w = csv.DictWriter(buf, fieldnames=cols)
            w.writeheader()
            for r in rows:
                w.writerow({k: _fmt(v) for k, v in r.items()})
        atomic_write_text(self.tab_dir / f"{stem}.csv", buf.getvalue())
        return f"tables/{stem}.csv"


def _fmt(v: Any) -> Any:
    """A CSV cell: numbers as plain numbers (numpy scalars too: never ``np.float64(...)`` text), lists
    space-separated."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return " ".join(str(_fmt(x)) for x in v)
    return v

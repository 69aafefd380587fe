"""Shared machinery of the reproduction: profiles, cached solves, figure and table writers."""
from __future__ import annotations

import csv
import io
import time
from dataclasses import dataclass, field
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
from ..solvers import solve
from ..solvers.result import Solution
from ..viz import save_figure
from .cache import StepCache

__all__ = ["Profile", "PROFILES", "Context", "ClaimResult", "Solved", "PI_MAX_STATES"]

#: The reproduction solves by policy iteration up to this many states, by relative value
#: iteration above (policy iteration's own multichain fallback is the only fallback).
PI_MAX_STATES = 60_000


@dataclass(frozen=True)
class Profile:
    """How much to compute. Caps are truncations of the paper's unbounded AoI, so every
    cap-sensitive claim is reported at each cap listed here."""

    name: str
    caps_2p: tuple[int, ...]
    caps_3p: tuple[int, ...]
    caps_pre: tuple[int, ...]
    p_grid: tuple[float, ...]
    sweep_cap_2p: int
    sweep_cap_3p: int
    sweep_cap_pre: int
    mc_slots: int
    mc_reps: int
    mc_slots_3p: int
    mc_reps_3p: int
    slice_total_3p: tuple[int, ...]  # the tau_1 + tau_2 + tau_3 plane, one per cap in caps_3p (the paper's 45 at cap 20)
    c13_caps: tuple[int, ...]
    c13_big_cap: int
    seed: int = 20221


PROFILES: dict[str, Profile] = {
    "quick": Profile(
        name="quick",
        caps_2p=(8, 12),
        caps_3p=(6,),
        caps_pre=(8,),
        p_grid=(0.8, 0.9, 1.0),
        sweep_cap_2p=8,
        sweep_cap_3p=5,
        sweep_cap_pre=6,
        mc_slots=2_000,
        mc_reps=4,
        mc_slots_3p=1_000,
        mc_reps_3p=4,
        slice_total_3p=(9,),
        c13_caps=(6, 8),
        c13_big_cap=12,
    ),
    "default": Profile(
        name="default",
        caps_2p=(12, 20, 30),
        caps_3p=(12, 16, 20),
        caps_pre=(12, 20, 25),
        p_grid=(0.8, 0.85, 0.9, 0.95, 1.0),
        sweep_cap_2p=12,
        sweep_cap_3p=12,
        sweep_cap_pre=12,
        mc_slots=40_000,
        mc_reps=20,
        mc_slots_3p=10_000,
        mc_reps_3p=10,
        slice_total_3p=(18, 24, 45),
        c13_caps=(6, 8, 10, 12),
        c13_big_cap=30,
    ),
}


@dataclass
class ClaimResult:
    """One claim of ``claims.md`` with its verdict and the numbers that decide it."""

    id: str
    paper: str
    statement: str
    verdict: str  # HOLDS | FAILS | DEPENDS
    summary: str
    numbers: dict[str, Any] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    details: str = ""  # markdown
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "paper": self.paper,
            "statement": self.statement,
            "verdict": self.verdict,
            "summary": self.summary,
            "numbers": self.numbers,
            "figures": self.figures,
            "tables": self.tables,
            "details": self.details,
            "seconds": self.seconds,
        }


@dataclass(frozen=True, eq=False)
class Solved:
    """An optimal solution (cached on disk) with the stationary law of its policy."""

    scenario: Scenario
    mdp: MDP
    gain: float
    gain_lower: float
    gain_upper: float
    policy: np.ndarray  # chosen pair per state
    bias: np.ndarray
    stationary: np.ndarray
    method: str
    seconds: float

    @cached_property
    def recurrent(self) -> np.ndarray:
        """(n,) bool: the state lies in a closed class of the policy's chain (:mod:`wncs_lp.chain`)."""
        return PolicyChain(self.mdp, self.policy).recurrent

    @property
    def actions(self) -> np.ndarray:
        """The action label row (into ``mdp.action_table``) of the chosen pair of each state."""
        return self.mdp.a_indices[self.policy]

    def action_tuple(self, s: int) -> tuple[int, ...]:
        return tuple(int(x) for x in self.mdp.action_table[self.mdp.a_indices[self.policy[s]]])

    def as_solution(self) -> Solution:
        return Solution(
            method=self.method,
            status="optimal",
            gain=self.gain,
            gain_lower=self.gain_lower,
            gain_upper=self.gain_upper,
            bias=self.bias,
            policy=self.policy,
        )


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
        if key in self._solved:
            return self._solved[key]
        mdp = self.mdp(scenario)

        def compute():
            t0 = time.perf_counter()
            sol = solve(mdp, method="pi" if mdp.n_states <= PI_MAX_STATES else "rvi")
            P_pi = mdp.P[sol.policy]
            classes = recurrent_classes(P_pi)
            stationary, _ = stationary_law(P_pi, classes)  # equal weights on several classes
            unichain = len(classes) == 1
            res = {
                "gain": float(sol.gain),
                "gain_lower": float(sol.gain_lower),
                "gain_upper": float(sol.gain_upper),
                "method": sol.method,
                "status": sol.status,
                "states": mdp.n_states,
                "pairs": mdp.n_pairs,
                "unichain": unichain,
                "seconds": time.perf_counter() - t0,
            }
            return res, {"policy": sol.policy, "bias": sol.bias, "stationary": stationary}

        def logged():
            self.log(f"solving {Path(scenario.source).name} caps {scenario.tau_caps} p={scenario.p:g} "
                     f"({mdp.n_states:,} states)")
            return compute()

        res, arr = self.cache.get_or_compute("solve", {"fingerprint": key}, logged)
        solved = Solved(
            scenario,
            mdp,
            res["gain"],
            res["gain_lower"],
            res["gain_upper"],
            arr["policy"],
            arr["bias"],
            arr["stationary"],
            res["method"],
            res["seconds"],
        )
        self._solved[key] = solved
        return solved

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
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return " ".join(str(x) for x in v)
    return v

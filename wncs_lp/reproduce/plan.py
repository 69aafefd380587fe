"""What a reproduction run will do and how long it takes: the estimate printed before the first
section, and the line printed after each section (its time, the time elapsed, the time left).

The estimate of a section is its measured time with a cold cache (:data:`ESTIMATE_SECONDS`, per
profile); the time left rescales the estimates of the sections still to run by how the finished
sections compared with theirs, so a loaded or a faster machine corrects the figure as the run
goes. A section read from the cache takes seconds, so a resumed run ends sooner than estimated.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

__all__ = ["ESTIMATE_SECONDS", "ESTIMATE_WHERE", "Plan", "duration"]

#: Seconds of each section with a cold cache, per profile: ``default`` from one run of
#: ``wncs-lp reproduce`` on a fresh clone (commit 180c2f6, 2 cores, 2 threads, quiet, numba's caches
#: cold: 5 min 04 s in all; the per-section lines it printed); ``quick`` from one run of
#: ``wncs-lp reproduce --profile quick`` on the same machine (55 s). ``full`` adds B2's caps 20, 25
#: and 30 and its sweep at cap 20, and B3's processes 1-4 at caps 20 and 30, estimated from the
#: matrix-free and bounds benchmarks (not one measured run). C14-C16 (issue 37) reuse the solves of
#: C1, C2, C3 and C11 (a fraction of a second each).
ESTIMATE_SECONDS: dict[str, dict[str, float]] = {
    "quick": {"C1": 2.3, "C2": 1.6, "C3": 2.8, "C4": 1.4, "C5": 1.0, "C6": 3.7, "C7": 0.8, "C8": 0.1,
              "C9": 1.6, "C10": 0.1, "C11": 1.4, "C12": 1.1, "C13": 5.7, "C14": 0.3, "C15": 0.3, "C16": 0.3,
              "B1": 7.6, "B2": 4.5, "B3": 19.5},
    "default": {"C1": 5.0, "C2": 8.0, "C3": 28.0, "C4": 17.0, "C5": 1.0, "C6": 76.0, "C7": 6.0, "C8": 1.0,
                "C9": 3.0, "C10": 2.0, "C11": 10.0, "C12": 4.0, "C13": 3.0, "C14": 0.1, "C15": 0.2, "C16": 0.1,
                "B1": 26.0, "B2": 43.0, "B3": 70.0},
}
ESTIMATE_SECONDS["full"] = {**ESTIMATE_SECONDS["default"], "B1": 80.0, "B2": 43.0 + 75 * 60.0, "B3": 65.0 + 15 * 60.0}
#: Where the estimates come from, in the line that prints them.
ESTIMATE_WHERE = "measured on a 2-core machine with a cold cache"


def duration(seconds: float) -> str:
    """``41 s``, ``2 min 05 s``, ``1 h 02 min``."""
    s = int(round(max(0.0, seconds)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


@dataclass
class Plan:
    """The sections of one run in order, their estimates, and what has finished.

    Parameters
    ----------
    profile : str
        A profile name (unknown names take the quick profile's estimates).
    sections : sequence of str
        Claim and section ids in the order they run.
    """

    profile: str
    sections: Sequence[str]
    done: dict[str, float] = field(default_factory=dict)

    def estimate(self, sid: str) -> float:
        table = ESTIMATE_SECONDS.get(self.profile, ESTIMATE_SECONDS["quick"])
        return float(table.get(sid, 0.0))

    def total(self) -> float:
        """The estimate of the whole run, cold."""
        return sum(self.estimate(s) for s in self.sections)

    def opening(self, threads: int, cores: int, cached_steps: int) -> str:
        """The line printed before the first section."""
        ids = ", ".join(self.sections)
        text = (f"reproduce: profile {self.profile}, {len(self.sections)} section(s) ({ids}), solves on up to "
                f"{threads} thread(s) of {cores} core(s); estimate about {duration(self.total())} ({ESTIMATE_WHERE})")
        if cached_steps:
            text += f"; {cached_steps} step(s) already in the cache are read, not recomputed: it will take less"
        return text

    def left(self) -> float:
        """The estimate of the sections still to run, rescaled by how the finished ones compared."""
        todo = sum(self.estimate(s) for s in self.sections if s not in self.done)
        est_done = sum(self.estimate(s) for s in self.done)
        took = sum(self.done.values())
        ratio = took / est_done if est_done > 0 and took > 0 else 1.0
        return todo * min(4.0, max(0.25, ratio))

    def finished(self, sid: str, outcome: str, seconds: float, elapsed: float) -> str:
        """Record a finished section; the line to print."""
        self.done[sid] = seconds
        n, i = len(self.sections), len(self.done)
        width = len(str(n))
        line = (f"[{i:>{width}}/{n}] {sid} {outcome} in {duration(seconds)}; elapsed {duration(elapsed)}")
        if i < n:
            line += f", about {duration(self.left())} left"
        return line

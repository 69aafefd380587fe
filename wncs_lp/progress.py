"""Progress on stderr for long work: phases, and ticks that rewrite one line on a terminal.

The solvers take ``progress=True`` (or a :class:`Progress` to share one line between several
steps) and report through it: value iteration its sweeps and the certificate gap shrinking,
policy iteration its improvements, the LP its interior-point iterations. Nothing goes to stdout,
so ``--json`` output stays one clean object.

On a terminal a tick rewrites the current line at most every 0.2 s; elsewhere (a log file, a
pipe, when ``--progress`` forces it) each tick is its own line, at most one every 2 s. The
command line shows progress by default only when stderr is a terminal and ``--json`` is not
given (:func:`wanted`).
"""
from __future__ import annotations

import math
import sys
import time
from typing import Any, Sequence, TextIO

from .stopping import check as check_stop

__all__ = ["Progress", "as_progress", "wanted", "eta", "duration", "convergence_eta"]


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def wanted(flag: bool | None, json: bool = False, stream: Any = None) -> bool:
    """Whether to show progress: ``flag`` when given (``--progress`` / ``--no-progress``), else
    only on a terminal (stderr) and not under ``--json``."""
    if flag is not None:
        return bool(flag)
    return not json and _isatty(sys.stderr if stream is None else stream)


def duration(seconds: float) -> str:
    """``"42 s"``, ``"3 min 20 s"``, ``"2 h 05 min"``: a duration as a person reads it."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


def eta(done: int, total: int, elapsed: float) -> str:
    """``"3/40, 12 s elapsed, ETA 2 min 28 s"``: how far a job of ``total`` equal steps is, and
    the time left if the remaining steps take as long as the average of the ``done`` ones."""
    text = f"{done}/{total}, {duration(elapsed)} elapsed"
    if 0 < done < total:
        text += f", ETA {duration(elapsed * (total - done) / done)}"
    return text


def convergence_eta(points: Sequence[tuple[float, float]], target: float) -> str:
    """``", ETA 40 s"`` for a width shrinking geometrically towards ``target`` (a certificate gap),
    from ``(seconds, width)`` points: the rate is that of the recent half of the run, so a solver
    that speeds up or slows down is followed. Empty while the width is not shrinking, already at
    the target, or measured only once."""
    if len(points) < 2:
        return ""
    t_now, w_now = points[-1]
    half = next((p for p in points if p[0] >= 0.5 * t_now), points[0])
    if half is points[-1]:
        half = points[-2]
    t_then, w_then = half
    if not (target > 0 and w_now > target and w_then > w_now > 0 and t_now > t_then):
        return ""
    rate = (math.log(w_then) - math.log(w_now)) / (t_now - t_then)
    return f", ETA {duration(math.log(w_now / target) / rate)}"


class Progress:
    """Phase lines and rate-limited ticks on a stream (default: ``sys.stderr`` at creation).

    Parameters
    ----------
    enabled : bool
        When False every call does nothing (so code can report unconditionally).
    stream : text stream, optional
    every : float, optional
        Least seconds between two ticks (default 0.2 on a terminal, 2 elsewhere).
    """

    def __init__(self, enabled: bool = True, stream: TextIO | None = None, every: float | None = None):
        self.enabled = bool(enabled)
        self.stream = sys.stderr if stream is None else stream
        self.tty = _isatty(self.stream)
        self.every = (0.2 if self.tty else 2.0) if every is None else float(every)
        self._last = -float("inf")
        self._open = False

    def __bool__(self) -> bool:
        return self.enabled

    def _close_line(self) -> None:
        if self._open:
            self.stream.write("\n")
            self._open = False

    def phase(self, text: str) -> None:
        """A new phase (always shown, on its own line). A stop requested by a signal
        (:func:`wncs_lp.stopping.check`) raises ``KeyboardInterrupt`` here: a new phase is not
        started after Ctrl-C / SIGTERM."""
        check_stop()
        if not self.enabled:
            return
        self._close_line()
        self.stream.write(text + "\n")
        self.stream.flush()
        self._last = -float("inf")

    def due(self) -> bool:
        """Whether a :meth:`tick` would be shown now (to skip formatting a line that would not be)."""
        return self.enabled and time.monotonic() - self._last >= self.every

    def tick(self, text: str, force: bool = False) -> None:
        """A step within a phase: shown when ``every`` seconds passed since the last one (or ``force``);
        raises ``KeyboardInterrupt`` after a stop request, as :meth:`phase`."""
        check_stop()
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < self.every:
            return
        self._last = now
        if self.tty:
            self.stream.write("\r\x1b[K" + text)
            self._open = True
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def done(self, text: str | None = None) -> None:
        """End the current line (and show ``text`` as its last state)."""
        if not self.enabled:
            return
        if text is not None:
            self.tick(text, force=True)
        self._close_line()
        self.stream.flush()


_OFF = None


def as_progress(progress: bool | Progress | None) -> Progress:
    """A :class:`Progress` from a solver's ``progress`` argument (True, False/None or one to share)."""
    if isinstance(progress, Progress):
        return progress
    if progress:
        return Progress(True)
    global _OFF
    if _OFF is None:
        _OFF = Progress(False)
    return _OFF

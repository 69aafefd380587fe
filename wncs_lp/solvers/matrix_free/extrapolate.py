"""One-mode extrapolation of the bias of a geometrically converging iteration (:class:`Extrapolator`)."""
from __future__ import annotations

import numpy as np

__all__ = ["Extrapolator"]


class Extrapolator:
    """One-mode (Lyusternik / Aitken) extrapolation of a geometrically converging iteration.

    Near convergence the bracket width of these iterations shrinks by a steady factor lambda per
    iteration (one slow mode of the chain: e.g. 0.86 an improvement sweep for processes 1-4 at
    cap 12), i.e. h_k ~ h* + a lambda^k v. lambda is the mean rate of the last ``runs`` widths'
    ratios once each of them is within ``agree`` (relative) of it, and only once the bracket is
    within ``max_rel`` of the gain (the asymptotic regime: steps on early stretches of steady
    ratios, relative widths 2e-4 to 1e-2 on processes 1-3 and 1-4, did not pay). (The
    asynchronous in-place sweeps of two threads make successive ratios alternate between ~0.25
    and ~0.7 a certificate; a looser rule that stepped on their mean rate was measured to lose
    there: processes 1-4 at cap 20, both steps missed. So the threaded solves seldom step.)
    Then h is moved to h + f (h - h_prev), f = lambda / (1 - lambda), which removes that mode;
    h_prev is h one iteration before (a second value vector, copied in the cycle that may end in an
    extrapolation).

    The step also multiplies the faster modes still in h (a mode mu by 1 - f (1/mu - 1), large
    for a small mu), and the iteration damps those within a few sweeps. So the step is judged
    at the next regular certificate, a cycle of sweeps later, not at once (judged at once, the
    first steps on processes 1-4 were undone for a width 6x larger that the next sweeps would
    have removed): it paid if the width is below the one the steady rate predicted without it.
    If it did not, the next step waits for a window twice as long; after ``max_misses`` misses
    extrapolation is off for the run. A step is never undone by the sweeps: every certificate
    bounds g* whatever h is, so a poor step costs sweeps, never validity. (:meth:`settle`
    undoes a step no certificate has seen, so that a run's h is the one of its last
    certificate.)
    """

    def __init__(self, n: int, enabled: bool, agree: float = 0.02, runs: int = 3, max_misses: int = 3,
                 max_rel: float = 1e-4):
        self.prev = np.empty(n) if enabled else None
        self.max_misses = max_misses
        self.agree = agree
        self.max_rel = max_rel
        self.runs = runs
        self.records: list[tuple[int, float]] = []
        self.count = 0
        self.missed = 0
        self.saved_at = -1
        # (f, the width the steady rate predicts a cycle later without the step, its iteration)
        self.pending: tuple[float, float, int] | None = None

    @property
    def enabled(self) -> bool:
        return self.prev is not None

    def _rates(self, pts) -> list[float] | None:
        rates = []
        for (i0, w0), (i1, w1) in zip(pts, pts[1:]):
            if not (w1 < w0) or i1 <= i0:
                return None
            rates.append(np.log(w1 / w0) / (i1 - i0))
        return rates

    def _steady(self, rates) -> bool:
        r = float(np.mean(rates))
        return max(abs(x - r) for x in rates) <= self.agree * abs(r)

    def want_save(self) -> bool:
        """Whether the coming check may extrapolate (the rates so far are steady), so h must be
        copied before the last iteration of this cycle."""
        if not self.enabled or self.pending is not None or len(self.records) < self.runs:
            return False
        rates = self._rates(self.records[-self.runs:])
        return rates is not None and (len(rates) == 0 or self._steady(rates))

    def save(self, h: np.ndarray, iters: int) -> None:
        np.copyto(self.prev, h)
        self.saved_at = iters

    def _axpy(self, h: np.ndarray, f: float, undo: bool) -> None:
        """h += f (h - h_prev), or undo it: h -= f / (1 + f) (h - h_prev), by blocks (a block-sized
        temporary). Written as a correction of h, never as (1 + f) h, which overflows before the
        result does when h is near float64's limit."""
        step = 1 << 20
        k = -f / (1.0 + f) if undo else f
        for a in range(0, h.size, step):
            hb = h[a:a + step]
            d = hb - self.prev[a:a + step]
            d *= k
            hb += d

    def settle(self, h: np.ndarray, iters: int) -> None:
        """At the end of a run (after ``iters`` iterations): undo a step made after the last
        certificate, so that h is the iterate of that certificate."""
        if self.pending is not None and self.pending[2] == iters:
            self._axpy(h, self.pending[0], undo=True)
        self.pending = None
        self.prev = None

    def step(self, h: np.ndarray, iters: int, width: float, rel: float) -> str | None:
        """Record the width after ``iters`` iterations (``rel``: relative to the gain); check a
        pending extrapolation or make one. Returns a message for the progress line, or None."""
        if not self.enabled or not np.isfinite(width) or width <= 0:
            return None
        if self.pending is not None:
            f, rate, at, before = self.pending
            self.pending = None
            forecast = before * float(np.exp(rate * (iters - at)))
            if width < forecast:
                self.records = [(iters, width)]
                return f"extrapolation paid (width {width:.3g}, {forecast:.3g} forecast without it)"
            self.missed += 1
            self.records = [(iters, width)]
            if self.missed >= self.max_misses:
                self.prev = None
                return f"extrapolation did not pay (width {width:.3g}, {forecast:.3g} forecast); no more for this run"
            self.runs *= 2  # wait for a longer steady stretch before the next try
            return f"extrapolation did not pay (width {width:.3g}, {forecast:.3g} forecast without it)"
        self.records.append((iters, width))
        if len(self.records) < self.runs + 1 or self.saved_at != iters - 1:
            return None
        rates = self._rates(self.records[-(self.runs + 1):])
        if rel > self.max_rel or rates is None or not self._steady(rates):
            return None
        rate = float(np.mean(rates))
        lam = float(np.exp(rate))
        if not (0.0 < lam < 0.9999):
            return None
        f = lam / (1.0 - lam)
        self._axpy(h, f, undo=False)
        self.pending = (f, rate, iters, width)
        self.count += 1
        return f"extrapolated (rate {lam:.4f} an iteration)"

"""One-mode extrapolation of the bias of a geometrically converging iteration (:class:`Extrapolator`)."""
from __future__ import annotations

import numpy as np

__all__ = ["Extrapolator"]


class Extrapolator:
    """One-mode (Lyusternik / Aitken) extrapolation of a geometrically converging iteration.

    Near convergence the bracket width of these iterations shrinks by a steady factor lambda per
    iteration (one slow mode of the chain: e.g. 0.86 an improvement sweep for processes 1-4 at
    cap 12, one thread), i.e. h_k ~ h* + a lambda^k v. Once ``runs`` successive rates agree
    within ``agree`` (relative), lambda is their value and h is moved to
    h + f (h - h_prev), f = lambda^m / (1 - lambda^m), which removes that mode; h_prev is h m
    iterations before: a second value vector, copied at the start of the cycle of sweeps that
    may end in an extrapolation, so m is the whole cycle. (A difference over one iteration, as
    before, has f = lambda / (1 - lambda) ~ 6 and multiplies by it whatever else changed in
    that iteration; over the cycle f ~ 0.4: docs/matrix-free.md has the sweeps saved.) The certificate is
    computed on the new h at once; if its width is not below the one before, h is restored
    ((h + f h_prev) / (1 + f)) and extrapolation is switched off for the run after
    ``max_undo`` such undos. So a poor extrapolation costs one pass, never validity.

    With two threads the in-place sweeps are asynchronous, successive ratios alternate between
    ~0.25 and ~0.7 a certificate, and the rates seldom agree: threaded solves seldom step
    (looser rules that did step there were measured not to pay).
    """

    def __init__(self, n: int, enabled: bool, agree: float = 0.02, runs: int = 3, max_undo: int = 3):
        self.prev = np.empty(n) if enabled else None
        self.max_undo = max_undo
        self.agree = agree
        self.runs = runs
        self.records: list[tuple[int, float]] = []
        self.count = 0
        self.reverted = 0
        self.saved_at = -1
        self.pending: tuple[float, float] | None = None  # (f, width before) of an unchecked step
        self.seen = False  # whether a certificate was computed on the h of the pending step

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
        r = rates[-1]
        return max(abs(x - r) for x in rates) <= self.agree * abs(r)

    def want_save(self) -> bool:
        """Whether the coming check may extrapolate (the rates so far are steady), so h must be
        copied at the start of this cycle."""
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

    def certified(self) -> None:
        """A certificate was just computed on the current h (a pending step's h, if any)."""
        self.seen = self.pending is not None

    def settle(self, h: np.ndarray) -> None:
        """At the end of a run: undo an extrapolation that no pass has certified yet, so that h
        is the iterate of the last certificate (a step whose certificate closed the run stays)."""
        if self.pending is not None and not self.seen:
            self._axpy(h, self.pending[0], undo=True)
            self.pending = None
        self.prev = None

    def step(self, h: np.ndarray, iters: int, width: float) -> str | None:
        """Record the width after ``iters`` iterations; check a pending extrapolation or make
        one. Returns a message for the progress line, or None."""
        if not self.enabled or not np.isfinite(width) or width <= 0:
            return None
        if self.pending is not None:
            f, before = self.pending
            self.pending = None
            if width < before:
                self.records = [(iters, width)]
                return f"extrapolation kept (width {before:.3g} -> {width:.3g})"
            self._axpy(h, f, undo=True)
            self.reverted += 1
            self.records = []
            if self.reverted >= self.max_undo:
                self.prev = None
                return f"extrapolation undone (width {before:.3g} -> {width:.3g}); no more for this run"
            self.runs *= 2  # wait for a longer steady stretch before the next try
            return f"extrapolation undone (width {before:.3g} -> {width:.3g})"
        self.records.append((iters, width))
        m = iters - self.saved_at  # iterations since h_prev (the cycle it was saved in)
        if len(self.records) < self.runs + 1 or self.saved_at < 0 or m < 1 or self.saved_at < self.records[-2][0]:
            return None
        rates = self._rates(self.records[-(self.runs + 1):])
        if rates is None or not self._steady(rates):
            return None
        lam = float(np.exp(rates[-1]))
        if not (0.0 < lam < 0.9999):
            return None
        f = lam ** m / (1.0 - lam ** m)
        self._axpy(h, f, undo=False)
        self.pending = (f, width)
        self.seen = False
        self.count += 1
        return f"extrapolated (rate {lam:.4f} an iteration)"

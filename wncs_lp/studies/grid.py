"""The grid of a study: values from ``START:STOP:STEP`` or a comma list, bounded and finite."""
from __future__ import annotations

import math
from typing import Sequence

from ..errors import WncsError

__all__ = ["parse_values", "value_key", "MAX_GRID_VALUES"]

#: The most values a grid may hold (a finer grid is almost surely a typo in STEP, and would hang
#: before the first point: 0:1:1e-12 is 10^12 values).
MAX_GRID_VALUES = 10_000


def value_key(v: float) -> str:
    """A grid value as the key of its rows (12 significant digits: 0.8 + 4 * 0.05 is 1.0)."""
    return format(round(float(v), 12), ".12g")


def _range(text: str, option: str) -> list[float]:
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        a, b, s = (float(x) for x in parts)
    except ValueError:
        raise WncsError(f"{option} {text!r}: expected START:STOP:STEP (e.g. 0.8:1.0:0.05) or a comma list") from None
    if not all(math.isfinite(x) for x in (a, b, s)):
        raise WncsError(f"{option} {text!r}: START, STOP and STEP must be finite numbers")
    if not s > 0:
        raise WncsError(f"{option} {text!r}: the step must be > 0")
    ratio = (b - a) / s
    if not math.isfinite(ratio) or ratio + 1 > MAX_GRID_VALUES:
        count = "more than 10^308" if not math.isfinite(ratio) else f"{math.floor(ratio + 1e-9) + 1:,}"
        raise WncsError(f"{option} {text!r}: {count} values, at most {MAX_GRID_VALUES:,} (a larger STEP?)")
    n = int(math.floor(ratio + 1e-9)) + 1
    return [round(a + i * s, 12) for i in range(max(n, 0))]


def parse_values(text: str | Sequence[float], option: str = "--values") -> list[float]:
    """Grid values from ``"0.8:1.0:0.05"`` (start:stop:step, stop included) or ``"0.8,0.9,1"``.

    Values are rounded to 12 decimals so that 0.8 + 4 * 0.05 is exactly 1.0.

    Raises
    ------
    WncsError
        Malformed text, a step <= 0, a value that is not a finite number, an empty grid, or one
        of more than :data:`MAX_GRID_VALUES` values.
    """
    if not isinstance(text, str):
        try:
            vals = [float(v) for v in text]
        except (TypeError, ValueError):
            raise WncsError(f"{option}: expected numbers, got {text!r}") from None
        shown = ", ".join(map(str, vals[:3])) + (", ..." if len(vals) > 3 else "")
    elif ":" in text:
        vals, shown = _range(text, option), text
    else:
        try:
            vals = [float(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise WncsError(f"{option} {text!r}: expected numbers separated by commas, or START:STOP:STEP") from None
        shown = text
    if not vals:
        raise WncsError(f"{option} {shown!r}: empty grid")
    bad = [v for v in vals if not math.isfinite(v)]
    if bad:
        raise WncsError(f"{option} {shown!r}: every value must be a finite number, got {bad[0]!r}")
    if len(vals) > MAX_GRID_VALUES:
        raise WncsError(f"{option}: {len(vals):,} values, at most {MAX_GRID_VALUES:,}")
    return vals

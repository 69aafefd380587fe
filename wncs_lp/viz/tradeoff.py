"""Trade-off curves (``docs/constraints.md`` section 6): the constrained optimum against a bound.

:func:`plot_tradeoff` takes a :class:`~wncs_lp.constrained.tradeoff.TradeoffResult` (or its
``summary()`` dictionary), ``ax=None`` (a new figure is made) and returns the Axes.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .save import save_figure

__all__ = ["plot_tradeoff", "save_tradeoff_figure", "bound_label", "TRADEOFF_UNITS"]

#: Axis text of each constrained quantity: (what, unit).
TRADEOFF_UNITS: dict[str, tuple[str, str]] = {
    "send_rate": ("send rate", "updates per slot"),
    "aoi": ("average AoI", "slots"),
    "cost": ("average MSE", "sum of traces"),
    "process_cost": ("average MSE", "trace"),
}


def _get(result: Any, name: str) -> Any:
    return result[name] if isinstance(result, dict) else getattr(result, name)


def _num(x: Any) -> float:
    return math.nan if x is None else float(x)


def _points(result: Any) -> list[dict[str, Any]]:
    pts = _get(result, "points")
    return [p if isinstance(p, dict) else p.to_dict() for p in pts]


def _feasible(p: dict[str, Any]) -> bool:
    return p["status"] != "infeasible" and not str(p["status"]).startswith("error")


def bound_label(result: Any) -> str:
    """The x-axis text: ``bound b on send_rate[remote] <= b (updates per slot)``."""
    qty = _get(result, "quantity")
    what, unit = TRADEOFF_UNITS.get(qty, (qty, ""))
    op = "\u2264" if _get(result, "side") == "max" else "\u2265"
    text = f"bound b: {_get(result, 'constraint')} {op} b"
    return f"{text} ({unit})" if unit else text


def plot_tradeoff(result: Any, ax=None, *, label: str | None = None, color: str | None = None,
                  reference: bool = True, title: str | None = None, ylabel: str | None = None):
    """Optimal average cost against the swept bound.

    Draws the curve of certified optima (markers on the solved bounds, the bracket
    ``[gain_lower, gain_upper]`` as error bars and a band; at 1e-10 they are thinner than the
    line), the optimum without the constraint as a horizontal dashed line, the bound where the
    constraint stops binding as a vertical dotted line, and infeasible bounds as crosses on the
    lower edge with the unreachable range shaded.

    Parameters
    ----------
    result : TradeoffResult or dict
        :func:`wncs_lp.constrained.tradeoff.tradeoff`'s result or its ``summary()``.
    ax : matplotlib Axes, optional
    label : str, optional
        Legend text of the curve (default ``"constrained optimum"``).
    color : str, optional
    reference : bool
        Draw the unconstrained optimum and the threshold lines.
    title, ylabel : str, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 4.4))
    pts = sorted(_points(result), key=lambda p: p["bound"])
    ok = [p for p in pts if _feasible(p)]
    b = np.array([p["bound"] for p in ok], dtype=float)
    g = np.array([_num(p["gain"]) for p in ok])
    lo = np.array([_num(p["gain_lower"]) for p in ok])
    hi = np.array([_num(p["gain_upper"]) for p in ok])
    lbl = label or "constrained optimum g*(b)"
    line = ax.errorbar(b, g, yerr=[np.nan_to_num(np.maximum(g - lo, 0)), np.nan_to_num(np.maximum(hi - g, 0))],
                       marker="o", markersize=5, linestyle="none", capsize=3, label=lbl, color=color)
    col = line[0].get_color()
    if b.size:
        ax.fill_between(b, lo, hi, color=col, alpha=0.2, linewidth=0)
    g0 = _num(_get(result, "unconstrained_gain"))
    thr = _num(_get(result, "threshold"))
    # the curve between the markers: (threshold, g0) is a point of it too (the unconstrained
    # optimum meets the bound b = threshold exactly), so the line bends there, not at a marker
    bx, gx = b, g
    if b.size and math.isfinite(thr) and math.isfinite(g0) and b.min() < thr < b.max():
        bx, gx = np.append(b, thr), np.append(g, g0)
        order = np.argsort(bx, kind="stable")
        bx, gx = bx[order], gx[order]
    ax.plot(bx, gx, "-", color=col, linewidth=1.5)
    if reference and math.isfinite(g0):
        ax.axhline(g0, color=col, linestyle="--", linewidth=1, alpha=0.8,
                   label=f"without the constraint: {g0:.6g}")
    if reference and math.isfinite(thr):
        ax.axvline(thr, color=col, linestyle=":", linewidth=1.2, alpha=0.9,
                   label=f"stops binding at b = {thr:.4g}")
    bad = [p for p in pts if p["status"] == "infeasible"]
    if bad:
        y0 = float(np.nanmin(g)) if g.size and np.isfinite(g).any() else 0.0
        ax.plot([p["bound"] for p in bad], [y0] * len(bad), "x", color=col, markersize=8,
                label="infeasible bound")
        reach = _num(_get(result, "reachable"))
        if math.isfinite(reach):
            lim = min(p["bound"] for p in bad) if _get(result, "side") == "max" else max(p["bound"] for p in bad)
            ax.axvspan(min(lim, reach), max(lim, reach), color="0.85", alpha=0.5, linewidth=0)
    ax.set_xlabel(bound_label(result))
    ax.set_ylabel(ylabel or "optimal average MSE g* (sum of traces)")
    ax.grid(True, alpha=0.3)
    ax.legend(frameon=False, fontsize=8)
    if title:
        ax.set_title(title)
    return ax


def save_tradeoff_figure(result: Any, path: str | Path, *, title: str | None = None,
                         formats: Sequence[str] | None = None) -> dict[str, str]:
    """Plot a trade-off curve and save it (``path`` as given, or ``formats`` on its stem)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.8, 4.6))
    plot_tradeoff(result, ax=ax, title=title)
    fig.tight_layout()
    paths = save_figure(fig, Path(path), formats, dpi=150)
    return {p.suffix.lstrip("."): str(p) for p in paths}

"""Performance curves in the style of the paper's Figs. 5 and 10 (average MSE vs p).

Every function takes ``ax=None`` (a new figure is made) and returns the Axes. Matplotlib is
imported lazily (it picks the non-interactive Agg backend by itself without a display).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .save import save_figure

__all__ = ["plot_sweep", "save_sweep_figure", "POLICY_STYLE"]

#: Marker, line style and label of each policy (the paper uses one marker per curve).
POLICY_STYLE: dict[str, dict[str, Any]] = {
    "optimal": {"marker": "o", "linestyle": "-", "label": "optimal (MDP)", "markersize": 10,
                "markerfacecolor": "none", "markeredgewidth": 1.5},
    "suboptimal": {"marker": "s", "linestyle": "-", "label": "suboptimal (Sec. III)"},
    "static": {"marker": "^", "linestyle": "--", "label": "static"},
    "best_static": {"marker": "v", "linestyle": "--", "label": "best static"},
    "greedy": {"marker": "D", "linestyle": "-.", "label": "greedy"},
    "random": {"marker": "x", "linestyle": ":", "label": "random"},
}


def _pyplot():
    import matplotlib.pyplot as plt  # falls back to Agg by itself when there is no display

    return plt


def plot_sweep(rows: Sequence[Any], ax=None, *, metric: str = "auto", logy: bool = False, title: str | None = None):
    """Average cost against the swept parameter, one line with markers per policy.

    Parameters
    ----------
    rows : sequence of SweepRow (or dicts with the same keys)
        A sweep table (:attr:`wncs_lp.sweep.SweepResult.rows`).
    ax : matplotlib Axes, optional
    metric : {"auto", "gain", "sim"}
        ``gain``: exact average cost; ``sim``: simulated mean with +-1.96 stderr error bars;
        ``auto``: per policy, the exact gain where available, else the simulated mean.
    logy : bool
        Logarithmic y axis.
    title : str, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        plt = _pyplot()
        _, ax = plt.subplots(figsize=(6.4, 4.4))
    recs = [r if isinstance(r, dict) else r.to_dict() for r in rows]
    if not recs:
        return ax
    param = recs[0]["param"]
    policies = list(dict.fromkeys(r["policy"] for r in recs))

    def val(x: Any) -> float:
        return math.nan if x is None else float(x)

    def at(r: dict) -> float:  # a row's value: under the parameter's name (table rows) or "value" (sweep.csv)
        return float(r["value"] if "value" in r else r[r["param"]])

    for pol in policies:
        sel = sorted((r for r in recs if r["policy"] == pol), key=at)
        x = np.array([at(r) for r in sel], dtype=float)
        g = np.array([val(r["gain"]) for r in sel])
        m = np.array([val(r["sim_mean"]) for r in sel])
        e = np.array([val(r["sim_stderr"]) for r in sel])
        style = dict(POLICY_STYLE.get(pol, {"marker": "o", "linestyle": "-", "label": pol}))
        style.setdefault("markersize", 6)
        use_sim = metric == "sim" or (metric == "auto" and not np.isfinite(g).any())
        if use_sim:
            style["label"] += " (simulated)"
            ax.errorbar(x, m, yerr=1.96 * np.nan_to_num(e), capsize=3, **style)
        else:
            ax.plot(x, g, **style)
    ax.set_xlabel("success probability p" if param == "p" else param)
    ax.set_ylabel("average MSE (sum of traces)")
    if logy:
        ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend(frameon=False)
    if title:
        ax.set_title(title)
    return ax


def save_sweep_figure(rows: Sequence[Any], stem: str | Path, *, title: str | None = None, **kw: Any) -> dict[str, str]:
    """Plot a sweep table and save it as ``stem.png`` and ``stem.svg``; return the two paths."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    plot_sweep(rows, ax=ax, title=title, **kw)
    fig.tight_layout()
    png, svg = save_figure(fig, Path(stem), ("png", "svg"), dpi=150)
    return {"png": str(png), "svg": str(svg)}

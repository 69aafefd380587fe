"""What a simulation shows: AoI distributions and sample paths.

:func:`plot_aoi` draws an :class:`~wncs_lp.aoi.AoIDistribution` (exact or simulated),
:func:`plot_path` a :class:`~wncs_lp.simulate.SamplePath`. Both take ``ax=None`` (a new figure is
made) and return the Axes; matplotlib is imported inside them.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ["plot_aoi", "plot_path"]


def _axes(ax, size=(6.4, 4.4)):
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=size)
    return ax


def _chosen(n: int, processes: Sequence[int] | None) -> list[int]:
    ks = list(range(n)) if processes is None else [int(k) for k in processes]
    bad = [k for k in ks if not 0 <= k < n]
    if bad:
        from ..errors import WncsError

        raise WncsError(f"processes {bad} out of range: expected 0-based indices below {n}")
    return ks


def plot_aoi(dist: Any, ax=None, *, processes: Sequence[int] | None = None, show: str = "pmf"):
    """Each chosen process's AoI distribution as a step curve over 1..its cap.

    Parameters
    ----------
    dist : AoIDistribution
    ax : matplotlib Axes, optional
    processes : sequence of int, optional
        0-based processes to draw (default all).
    show : {"pmf", "cdf"}
        Probabilities, or the cumulative distribution (quantiles read off at a level).
        A simulated pmf gets +-1.96 standard-error bars where the replications give them.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if show not in ("pmf", "cdf"):
        from ..errors import WncsError

        raise WncsError(f"show must be 'pmf' or 'cdf', got {show!r}")
    ax = _axes(ax)
    y_all = dist.pmf if show == "pmf" else dist.cdf()
    for k in _chosen(dist.n_processes, processes):
        x = np.arange(1, dist.caps[k] + 1)
        y = y_all[k, :dist.caps[k]]
        line, = ax.step(x, y, where="mid", label=dist.process_names[k])
        if show == "pmf" and dist.stderr is not None and np.all(np.isfinite(dist.stderr[k, :dist.caps[k]])):
            ax.errorbar(x, y, yerr=1.96 * dist.stderr[k, :dist.caps[k]], fmt="none", ecolor=line.get_color(),
                        alpha=0.6, capsize=2)
    ax.set_xlabel("AoI (slots)")
    ax.set_ylabel("long-run fraction of slots" if show == "pmf" else "P(AoI <= x)")
    src = "exact" if dist.how == "exact" else "simulated"
    ax.set_title(f"AoI distribution ({src}{', ' + dist.policy if dist.policy else ''})")
    ax.legend(loc="best", fontsize="small")
    return ax


def plot_path(path: Any, ax=None, *, what: str = "aoi", processes: Sequence[int] | None = None):
    """A sample path against the slot number.

    Parameters
    ----------
    path : SamplePath
    ax : matplotlib Axes, optional
    what : {"aoi", "cost"}
        The AoI of each chosen process (steps), or the slot cost c(s_t) = sum_k q_k(tau_k).
    processes : sequence of int, optional
        0-based processes (``what="aoi"``; default all).

    Returns
    -------
    matplotlib.axes.Axes
    """
    if what not in ("aoi", "cost"):
        from ..errors import WncsError

        raise WncsError(f"what must be 'aoi' or 'cost', got {what!r}")
    ax = _axes(ax, (8.0, 3.6))
    t = path.slots
    if what == "aoi":
        for k in _chosen(path.tau.shape[1], processes):
            ax.step(t, path.tau[:, k], where="post", label=path.process_names[k])
        ax.set_ylabel("AoI (slots)")
        ax.legend(loc="upper right", fontsize="small")
    else:
        ax.step(t, path.cost, where="post", color="k", lw=0.8)
        ax.set_ylabel("slot cost (sum of MSE)")
    ax.set_xlabel("slot")
    ax.set_title(f"sample path ({path.policy}, replication {path.replication})")
    return ax

r"""Policy maps drawn: the paper's Figs. 3-4, 6-9 and 11-12 (the data is :mod:`wncs_lp.policy_grids`).

* :func:`plot_policy_map` -- the action over (tau_i, tau_j) for one configuration (server state)
  with the other AoIs fixed;
* :func:`plot_policy_slice` -- three processes on the plane tau_i + tau_j + tau_k = total, drawn
  as a triangle in barycentric coordinates (Figs. 6-7).

:func:`plot_policy_map` draws an MDP's policy or, on its AoI box (:mod:`wncs_lp.spaces`), a
matrix-free one (:func:`plot_matrix_free_map` is that call). Both take ``ax=None`` (a new figure
is made) and return the Axes. Process indices (``axes``,
``fixed_tau``) are **1-based** like the paper's tau_1, tau_2, ...

Randomised policies (a ``ConstrainedSolution``, a ``MixedPolicy``, (L,) pair probabilities) are
drawn with their most likely action in each cell, and a small black star (:data:`MIX_MARKER`;
the Line2D has gid :data:`MIX_GID`) on the cells of the states where they mix (grid maps: in the
cell's upper-right corner, slices: just up and right of the point, :data:`MIX_OFFSET`); the legend
(titled "most likely action") spells out each mix, e.g. ``mixes at (6, 6): 0.71 (2 to edge) /
0.29 (2 to remote, 1 to edge)`` (most likely first; cells with the same mix share one entry), for the first
:data:`MIX_LEGEND_MAX` distinct mixes.
"""
from __future__ import annotations

import re
from typing import Any, Mapping, Sequence

import numpy as np

from ..mdp import MDP
from ..policy_grids import NEIGHBOURS, action_name, map_view, mixed_states, state_mix
from ..spaces import Space, space_of

__all__ = ["ACTION_STYLES", "MIX_GID", "MIX_MARKER", "MIX_OFFSET", "MIX_LEGEND_MAX", "plot_policy_map",
           "plot_policy_slice", "plot_matrix_free_map"]

#: (marker, colour) per action index (row of ``mdp.action_table``), cycled.
ACTION_STYLES: list[tuple[str, str]] = [
    ("x", "tab:blue"),
    ("o", "tab:red"),
    ("s", "tab:green"),
    ("^", "tab:orange"),
    ("D", "tab:purple"),
    ("v", "tab:brown"),
    ("P", "tab:pink"),
    ("*", "tab:olive"),
    ("h", "tab:cyan"),
    ("<", "black"),
]
_FILLED_ALPHA = 0.85
_TRANSIENT_BG = "#dcdcdc"
_UNREACHABLE_BG = "#7f7f7f"
#: Marker of the randomised states (a small black star on the cell) and the gid of its Line2D.
MIX_MARKER = "*"
MIX_GID = "randomised-states"
#: The star sits up and to the right of its cell's marker: at (tau_i + MIX_OFFSET, tau_j + MIX_OFFSET)
#: on a grid map, 0.5 * MIX_OFFSET / total in both plot coordinates on a slice (spacing 1 / total).
MIX_OFFSET = 0.3
#: At most this many mixes are written out in the legend (then "... and k more").
MIX_LEGEND_MAX = 6




def _style(a: int) -> tuple[str, str]:
    return ACTION_STYLES[int(a) % len(ACTION_STYLES)]


def _tau(k: int, info: dict) -> str:
    """Mathtext tau with the process's short name as subscript when it is short, else its index."""
    nm = info["processes"][k - 1]
    sub = nm if re.fullmatch(r"\w{1,3}", nm) else str(k)
    return rf"$\tau_{{{sub}}}$"


def _title(info: dict, space: Space, config: int, extra: str) -> str:
    caps = space.caps
    par = [f"cap {caps[0]}" if len(set(caps)) == 1 else "caps " + ",".join(map(str, caps))]
    if info.get("p") is not None:
        par.insert(0, f"p = {info['p']:g}")
    return f"{info['name']}: policy in [{space.describe(config)}]{space.note}\n{extra}{', '.join(par)}"


def _mix_text(mdp: MDP, probs: np.ndarray, s: int, cid: int, info: dict) -> str:
    return " / ".join(f"{p:.2f} {action_name(mdp, a, cid, names=info)}" for a, p in state_mix(mdp, probs, s))


def _draw_mixes(ax, mdp: MDP, probs: np.ndarray, cid: int, info: dict, cells: list, ms: float,
                where: str) -> list:
    """Overlay the star on ``cells`` = [(x, y, state, (t_i, t_j, ...)), ...]; return legend handles."""
    from matplotlib.lines import Line2D

    handles = []
    n_mixed = int(mixed_states(mdp, probs).size)
    if cells:
        xs = np.array([c[0] for c in cells], float)
        ys = np.array([c[1] for c in cells], float)
        ax.plot(xs, ys, linestyle="none", marker=MIX_MARKER, color="black", markeredgecolor="black",
                markeredgewidth=0.4, markersize=max(5.0, 0.9 * ms), zorder=3, gid=MIX_GID)
    star = dict(linestyle="none", marker=MIX_MARKER, color="black", markersize=8)
    groups: dict[str, list] = {}  # cells with the same mix (as written) share one legend entry
    for _, _, s, coords in cells:
        groups.setdefault(_mix_text(mdp, probs, s, cid, info), []).append(coords)
    for text, where_ in list(groups.items())[:MIX_LEGEND_MAX]:
        at = f"({', '.join(map(str, where_[0]))})"
        at = at if len(where_) == 1 else f"{len(where_)} {where}, e.g. {at}"
        handles.append(Line2D([], [], **star, label=f"mixes at {at}: {text}"))
    rest = sum(len(v) for v in list(groups.values())[MIX_LEGEND_MAX:])
    if rest:
        handles.append(Line2D([], [], **star, label=f"... and {rest} more randomised {where}"))
    if not cells and n_mixed:
        handles.append(Line2D([], [], **star, label=f"randomised in {n_mixed} state(s), none on this map"))
    return handles


def _ticks(ax, cap_x: int, cap_y: int) -> None:
    step = lambda c: 1 if c <= 15 else (2 if c <= 30 else 5)  # noqa: E731
    ax.set_xticks(range(1, cap_x + 1, step(cap_x)))
    ax.set_yticks(range(1, cap_y + 1, step(cap_y)))


def _grid_axes(ax, info: dict, i: int, j: int, ci: int, cj: int) -> None:
    """Labels, limits and ticks of a map over (tau_i, tau_j) with ci x cj cells."""
    pn = info["processes"]
    ax.set_xlabel(f"{_tau(i, info)}  (AoI of process {pn[i - 1]})")
    ax.set_ylabel(f"{_tau(j, info)}  (AoI of process {pn[j - 1]})")
    ax.set_xlim(0.5, ci + 0.5)
    ax.set_ylim(0.5, cj + 0.5)
    _ticks(ax, ci, cj)


def plot_policy_map(
    mdp: Any,
    policy_or_solution: Any,
    config: Any,
    axes: Sequence[int] = (1, 2),
    fixed_tau: Mapping[int, int] | None = None,
    ax: Any = None,
    stationary: Any = None,
    *,
    scenario: Any = None,
    title: str | None = None,
    legend: bool = True,
) -> Any:
    r"""Draw the chosen action over (tau_i, tau_j) for one configuration (paper Figs. 3, 4, 8, 9, 11, 12).

    Each reachable cell carries the action's marker (one marker/colour per action, consistent
    across maps of one MDP); the background is white for states with positive stationary
    probability under the policy, light grey for states with zero stationary probability
    (transient), dark grey for unreachable cells. A randomised policy shows its most likely
    action, with a small black star on the states where it mixes (the mix is in the legend).

    The same map of a matrix-free policy (no MDP: the paper's four processes at cap 30 and beyond)
    is drawn from its AoI box (:class:`~wncs_lp.spaces.BoxSpace`): dark grey outside the
    configuration's box, no shading (no stationary law is known at that scale), the AoIs off the
    axes at the lower end of the box by default, "(matrix-free)" in the title.

    Parameters
    ----------
    mdp : MDP, or a state space of :mod:`wncs_lp.spaces` (a matrix-free solution or policy: its box)
    policy_or_solution : Solution or (n,) int array of pair indices; or a randomised policy:
        ConstrainedSolution, MixedPolicy or (L,) float array of pair probabilities; on an AoI box,
        the MatrixFreeSolution, MatrixFreePolicy or local action table
    config : configuration (id, object or spec string, see :func:`parse_config_spec`)
    axes : (i, j)
        1-based processes on the x and y axes.
    fixed_tau : {k: tau_k}, optional
        The other AoIs (default: the value with the most stationary probability, or the most
        recurrent states, in this configuration; see :func:`policy_grid`).
    ax : matplotlib Axes, optional
    stationary : (n,) array, False or None
        Stationary distribution for the shading (``> 0`` = recurrent); None (default) uses the
        exact graph criterion (closed communicating classes of the policy's chain); False
        disables the shading.
    scenario : Scenario, optional
        For process/server names and p in labels (default: read from ``mdp.meta["source"]``).
    title : str, optional
    legend : bool
        Draw the legend: right of the panel; below it when another panel of the figure is on its
        right (a 1 x 2 layout); inside it when there are panels both on its right and below.

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    view = map_view(mdp, policy_or_solution, config, axes, fixed_tau, stationary)
    space, cid, probs = view.space, view.config, view.probabilities
    A, S = view.grid()
    rec_mask = view.recurrent(stationary)
    info = space.names(scenario)
    if ax is None:
        _, ax = plt.subplots(figsize=(8.6, 6.2), layout="constrained")  # room for the legend outside the panel
    ci, cj = A.shape
    bg = np.ones((cj, ci, 3))
    reach = S >= 0
    if rec_mask is not None:
        trans = reach & ~rec_mask[np.maximum(S, 0)]
        bg[trans.T] = np.array([0xDC, 0xDC, 0xDC]) / 255
    bg[(~reach).T] = np.array([0x7F, 0x7F, 0x7F]) / 255
    ax.imshow(bg, origin="lower", extent=(0.5, ci + 0.5, 0.5, cj + 0.5), interpolation="nearest", aspect="auto")
    n_cells = max(ci, cj)
    ms = max(3.0, min(9.0, 160.0 / n_cells))
    handles = []
    for a in np.unique(A[A >= 0]):
        xs, ys = np.nonzero(A == a)
        mk, col = _style(space.style_key(cid, int(a)))
        ax.plot(xs + 1, ys + 1, linestyle="none", marker=mk, color=col, markersize=ms,
                markerfacecolor=col if mk not in ("x", "+") else None, alpha=_FILLED_ALPHA,
                markeredgewidth=1.4 if mk in ("x", "+") else 0.6)
        n = int(xs.size)
        handles.append(Line2D([], [], linestyle="none", marker=mk, color=col, markersize=7,
                              label=f"{space.action_name(cid, int(a), info)}  [{n} cells]"))
    i, j = view.axes
    if probs is not None:
        mdp = space.mdp
        mixed = np.isin(S, mixed_states(mdp, probs)) & (S >= 0)
        cells = []
        for x, y in zip(*np.nonzero(mixed)):
            cells.append((int(x) + 1 + MIX_OFFSET, int(y) + 1 + MIX_OFFSET, int(S[x, y]), (int(x) + 1, int(y) + 1)))
        handles += _draw_mixes(ax, mdp, probs, cid, info, cells, ms, "cells")
    if rec_mask is not None:
        handles.append(Patch(facecolor=_TRANSIENT_BG, edgecolor="0.5", label="zero stationary probability"))
    if (~reach).any():
        handles.append(Patch(facecolor=_UNREACHABLE_BG, edgecolor="0.3", label=space.outside))
    _grid_axes(ax, info, i, j, ci, cj)
    extra = ", ".join(f"{_tau(k, info)} = {v}" for k, v in sorted(view.fixed.items()))
    ax.set_title(title or _title(info, space, cid, (extra + ", ") if extra else ""), fontsize=10)
    if legend:
        _place_legend(ax, handles, fontsize=8.5, title="action" if probs is None else "most likely action",
                      title_fontsize=9, frameon=True)
    return ax


def _neighbours(ax) -> tuple[bool, bool]:
    """Whether another Axes of the figure sits to the right of ``ax`` (overlapping it vertically)
    and whether one sits below it (overlapping it horizontally), in figure coordinates."""
    me = ax.get_position()
    right = below = False
    for other in ax.figure.get_axes():
        if other is ax or not other.get_visible():
            continue
        o = other.get_position()
        if o.x0 >= me.x1 - 1e-9 and o.y0 < me.y1 and o.y1 > me.y0:
            right = True
        if o.y1 <= me.y0 + 1e-9 and o.x0 < me.x1 and o.x1 > me.x0:
            below = True
    return right, below


def _place_legend(ax, handles: list, **kw) -> None:
    """The legend outside the panel on the right; in a row of panels (another Axes to the right,
    where it would hide under the next panel) below the panel's x label; with a panel both to the
    right and below, inside the panel where it covers least (``loc="best"``)."""
    right, below = _neighbours(ax)
    if not right:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), **kw)
        return
    if below:
        ax.legend(handles=handles, loc="best", framealpha=0.85, **kw)
        return
    y = -0.12
    try:  # just under the tick labels and x label, wherever they end
        renderer = ax.figure.canvas.get_renderer()
        tight, box = ax.get_tightbbox(renderer), ax.get_window_extent(renderer)
        y = (tight.y0 - box.y0) / max(box.height, 1.0) - 0.02
    except (AttributeError, TypeError):  # a backend without a renderer: the usual depth of the labels
        pass
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, y), ncol=2, **kw)


def _bary(t_i: np.ndarray, t_j: np.ndarray, t_k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric -> plane: vertex of tau_i at (0, 0), tau_j at (1, 0), tau_k at (1/2, sqrt(3)/2)."""
    tot = t_i + t_j + t_k
    return (t_j + 0.5 * t_k) / tot, (np.sqrt(3) / 2) * t_k / tot


def plot_policy_slice(
    mdp: MDP,
    solution: Any,
    config: Any,
    total: int,
    ax: Any = None,
    *,
    axes: Sequence[int] = (1, 2, 3),
    fixed_tau: Mapping[int, int] | None = None,
    stationary: Any = None,
    scenario: Any = None,
    title: str | None = None,
    legend: bool = True,
) -> Any:
    r"""Draw the policy on the plane tau_i + tau_j + tau_k = total as a triangle (paper Figs. 6-7).

    A lattice point (t_i, t_j, t_k) is drawn at its barycentric position (corner of tau_i = the
    point where tau_i is largest, etc.); markers as in :func:`plot_policy_map`, faded for
    states with zero stationary probability, a small grey dot for unreachable points. Each
    connected region (6-neighbour on the triangular lattice) carries a text label with its
    action.

    Parameters
    ----------
    mdp, solution, config
        As in :func:`plot_policy_map` (randomised policies included: the star marks the points
        of the states where they mix).
    total : int
        The plane's constant.
    ax : Axes, optional
    axes : (i, j, k)
        The three processes (1-based).
    fixed_tau : dict, optional
        Values of the AoIs not in ``axes`` (N > 3).

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    view = map_view(mdp, solution, config, axes, fixed_tau, stationary, plane=True)
    space, cid, probs = view.space, view.config, view.probabilities
    A, S = view.plane(total)
    fixed = view.fixed
    rec_mask = view.recurrent(stationary)
    info = space.names(scenario)
    if ax is None:
        _, ax = plt.subplots(figsize=(9.0, 6.8), layout="constrained")  # room for the legend outside the panel
    i, j, k = axes
    ci, cj = A.shape
    TI, TJ = np.meshgrid(np.arange(1, ci + 1), np.arange(1, cj + 1), indexing="ij")
    TK = total - TI - TJ
    X, Y = _bary(TI.astype(float), TJ.astype(float), TK.astype(float))
    on = A != -2
    ms = max(2.5, min(9.0, 170.0 / max(2.0, np.sqrt(2 * int(on.sum())))))
    _plane_outline(ax, X[on], Y[on])
    unr = A == -1
    if unr.any():
        ax.plot(X[unr], Y[unr], linestyle="none", marker=".", color="0.55", markersize=ms * 0.5, zorder=1)
    handles = [_slice_region(ax, space, A, S, a, X, Y, rec_mask, ms, cid, info) for a in np.unique(A[A >= 0])]
    if probs is not None:
        mdp = space.mdp
        mixed = np.isin(S, mixed_states(mdp, probs)) & (A >= 0)
        off = 0.5 * MIX_OFFSET / total  # the lattice spacing is 1 / total
        cells = [(float(X[a, b]) + off, float(Y[a, b]) + off, int(S[a, b]), (a + 1, b + 1, int(total - a - b - 2)))
                 for a, b in zip(*np.nonzero(mixed))]
        handles += _draw_mixes(ax, mdp, probs, cid, info, cells, ms, "points")
    if rec_mask is not None:
        handles.append(Line2D([], [], linestyle="none", marker="o", color="0.3", alpha=0.35, markersize=7,
                              label="faded: zero stationary probability"))
    if unr.any():
        handles.append(Line2D([], [], linestyle="none", marker=".", color="0.55", markersize=7,
                              label="unreachable state"))
    _corner_labels(ax, on, X, Y, ((i, TI), (j, TJ), (k, TK)), info)
    ax.margins(0.2)
    ax.set_aspect("equal")
    ax.set_axis_off()
    extra = ", ".join(f"{_tau(p, info)} = {v}" for p, v in sorted(fixed.items()))
    head = f"plane {_tau(i, info)} + {_tau(j, info)} + {_tau(k, info)} = {total}, " + (extra + ", " if extra else "")
    ax.set_title(title or _title(info, space, cid, head), fontsize=10, pad=30)
    if legend:
        _place_legend(ax, handles, fontsize=8.5, title="action" if probs is None else "most likely action",
                      title_fontsize=9)
    return ax


def _plane_outline(ax, px: np.ndarray, py: np.ndarray) -> None:
    """The outline of the plane inside the box (the convex hull of its lattice points); sets the limits."""
    ax.plot(px, py, linestyle="none")
    if px.size >= 3:
        try:
            from scipy.spatial import ConvexHull

            hull = ConvexHull(np.c_[px, py])
            v = np.r_[hull.vertices, hull.vertices[:1]]
            ax.plot(px[v], py[v], color="0.6", lw=0.8, zorder=0)
        except Exception:  # degenerate (collinear) slice
            pass


def _slice_region(ax, space: Space, A: np.ndarray, S: np.ndarray, a: int, X: np.ndarray, Y: np.ndarray,
                  rec_mask: np.ndarray | None, ms: float, cid: int, info: dict):
    """Draw action a's points (faded where transient) and label each of its connected regions
    (6-neighbour on the triangular lattice) of at least 3 points; returns its legend handle."""
    from matplotlib.lines import Line2D
    from scipy import ndimage

    mk, col = _style(a)
    m = A == a
    rec = m.copy()
    if rec_mask is not None:
        rec = m & rec_mask[np.maximum(S, 0)]
    for sel, alpha in ((rec, _FILLED_ALPHA), (m & ~rec, 0.35)):
        if sel.any():
            ax.plot(X[sel], Y[sel], linestyle="none", marker=mk, color=col, markersize=ms, alpha=alpha,
                    markerfacecolor=col if mk not in ("x", "+") else None,
                    markeredgewidth=1.2 if mk in ("x", "+") else 0.5, zorder=2)
    comp, ncomp = ndimage.label(m, structure=NEIGHBOURS["tri6"])
    for r in range(1, ncomp + 1):
        sel = comp == r
        if sel.sum() < 3:
            continue
        short = info["model"].short_action(space.action_label(cid, int(a)), info)
        ax.text(X[sel].mean(), Y[sel].mean(), short, ha="center", va="center",
                fontsize=9, fontweight="bold", color=col, zorder=4,
                bbox=dict(boxstyle="round,pad=0.2", facecolor="white", edgecolor=col, alpha=0.85))
    return Line2D([], [], linestyle="none", marker=mk, color=col, markersize=7,
                  label=f"{space.action_name(cid, int(a), info)}  [{int(m.sum())} points]")


def _corner_labels(ax, on: np.ndarray, X: np.ndarray, Y: np.ndarray, corners, info: dict) -> None:
    """Where each tau is largest: a label just outside the points, away from their centre."""
    px, py = X[on], Y[on]
    pn = info["processes"]
    mx, my = px.mean(), py.mean()
    span = max(px.max() - px.min(), py.max() - py.min(), 1e-9)
    for name, T_ in corners:
        vals = np.where(on, T_, -1)
        top = vals == vals.max()
        tx, ty = X[top].mean(), Y[top].mean()
        dx, dy = tx - mx, ty - my
        nrm = max(np.hypot(dx, dy), 1e-9)
        ax.annotate(f"{_tau(name, info)} largest (= {int(vals.max())})\nprocess {pn[name - 1]}",
                    (tx + 0.17 * span * dx / nrm, ty + 0.17 * span * dy / nrm), ha="center", va="center",
                    fontsize=8.5, color="0.25", annotation_clip=False)


def plot_matrix_free_map(
    policy: Any,
    config: Any,
    axes: Sequence[int] = (1, 2),
    fixed_tau: Mapping[int, int] | None = None,
    ax: Any = None,
    *,
    title: str | None = None,
    legend: bool = True,
) -> Any:
    r"""Draw a matrix-free policy over (tau_i, tau_j) for one configuration (no MDP needed):
    :func:`plot_policy_map` on the policy's AoI box (:class:`~wncs_lp.spaces.BoxSpace`).

    The map of a policy of
    :func:`~wncs_lp.solvers.matrix_free.matrix_free_value_iteration` (the paper's four processes
    at cap 30 and beyond): one marker per action, dark grey outside the configuration's AoI box.
    There is no stationary law at this scale, so transient states are not shaded, and the AoIs
    off the axes default to the lower end of the configuration's box
    (:func:`~wncs_lp.policy_grids.matrix_free_grid`); the title says which values were used.

    Parameters
    ----------
    policy : MatrixFreePolicy or MatrixFreeSolution
    config, axes, fixed_tau, ax, title, legend
        As in :func:`plot_policy_map`.

    Returns
    -------
    matplotlib.axes.Axes
    """
    return plot_policy_map(space_of(policy), policy, config, axes, fixed_tau, ax, title=title, legend=legend)

"""Line geometry of the AoI box: the lines of a direction and the interval property along them.

Shared by the threshold check: Theorem 2's rays run along diagonals of the box, and the
switching-curve (interval) property is read on every axis-parallel and diagonal line.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import ModelError
from .context import PolicyContext
from .report import Violation
from .verdict import witness_class

__all__ = ["box_lines", "states_on_lines", "direction_name", "line_structure", "gap_violations", "gap_violation", "theorem2_direction",
           "switching_orders", "order_violations", "order_violation"]


def box_lines(caps: Sequence[int], d: Sequence[int]) -> np.ndarray:
    """All maximal lines ``x0, x0 + d, x0 + 2d, ...`` of the box, as flat indices.

    Returns an (n_lines, L) int64 array, padded with -1 (``d`` nonnegative, nonzero).
    """
    caps = np.asarray(caps, dtype=np.int64)
    d = np.asarray(d, dtype=np.int64)
    if np.any(d < 0) or not np.any(d):
        raise ModelError(f"line direction must be nonnegative and nonzero, got {tuple(d)}")
    coords = np.indices(tuple(caps)).reshape(len(caps), -1).T
    starts = coords[np.any(coords - d < 0, axis=1)]
    pos = d > 0
    lengths = np.min((caps[pos][None, :] - 1 - starts[:, pos]) // d[pos][None, :] + 1, axis=1)
    L = int(lengths.max()) if lengths.size else 0
    t = np.arange(L)
    pts = starts[:, None, :] + t[None, :, None] * d[None, None, :]
    valid = t[None, :] < lengths[:, None]
    pts = np.where(valid[..., None], pts, 0)
    flat = np.ravel_multi_index(tuple(np.moveaxis(pts, -1, 0)), tuple(caps))
    return np.where(valid, flat, -1)


def states_on_lines(space, lines: np.ndarray, c: int, at_least: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The state ids along the lines of :func:`box_lines` in configuration c (-1: unreachable or
    padding), keeping the lines with at least ``at_least`` reachable states; and the mask of those."""
    G = space.lookup_grid(c).ravel()
    S = np.where(lines >= 0, G[np.maximum(lines, 0)], -1)
    keep = np.count_nonzero(S >= 0, axis=1) >= at_least
    return S[keep], keep


def _direction_lines(space, directions: Sequence[tuple[int, ...]]) -> list[tuple[str, np.ndarray]]:
    """``(name, lines)`` of each direction: its :func:`direction_name` and :func:`box_lines`."""
    caps = tuple(int(c) for c in space.caps)
    return [(direction_name(d), box_lines(caps, d)) for d in directions]


def direction_name(d: Sequence[int]) -> str:
    """``"axis tau_k"`` or ``"diagonal tau_i+tau_j..."`` for a direction of the box."""
    ks = [k + 1 for k, x in enumerate(d) if x]
    if len(ks) == 1:
        return f"axis tau_{ks[0]}"
    return "diagonal " + "+".join(f"tau_{k}" for k in ks)


def line_structure(ctx: PolicyContext, configs: Sequence[int], directions: Sequence[tuple[int, ...]]
                   ) -> tuple[dict, list[tuple]]:
    """Whether each action region is an interval on every line of the given directions.

    Tie-robust: a state x is *compatible* with action a when pi(x) = a or
    ``|Q(x, a) - Q(x, pi(x))| <= tol``. A line has a gap for action a when two states with
    pi = a enclose a reachable state not compatible with a. Every such triple is a *witness*
    of the gap; the one reported is the best by :func:`~wncs_lp.verify.verdict.witness_class`
    (all three states observable and below the cap if there is one, then recurrent and below the
    cap, ...), its outer states the nearest ones choosing a on either side of its middle state.

    Returns (summary per direction, list of gaps (direction, config, action, first, gap, last,
    size)).
    """
    space = ctx.mdp.states
    summary: dict[str, dict] = {}
    gaps: list[tuple] = []
    for name, lines in _direction_lines(space, directions):
        entry = summary.setdefault(name, {"lines": 0, "checked": 0, "gaps": 0, "gap_lines_by_action": {}})
        if lines.shape[1] < 3:
            continue
        for c in configs:
            S, _ = states_on_lines(space, lines, c, 3)
            if S.shape[0] == 0:
                continue
            entry["lines"] += int(S.shape[0])
            valid = S >= 0
            Ssafe = np.maximum(S, 0)
            A = np.where(valid, ctx.act[Ssafe], -1)
            feas = np.flatnonzero(ctx.offsets[c] >= 0)
            if feas.size < 2:
                continue
            L = S.shape[1]
            idx = np.arange(L)[None, :]
            classes = [valid & m[Ssafe] for m in witness_class(ctx.recurrent, ctx.at_cap, ctx.observable)]
            for a in feas:
                isA = A == a
                has = isA.any(axis=1)
                entry["checked"] += int(np.count_nonzero(has))
                first = np.argmax(isA, axis=1)
                last = L - 1 - np.argmax(isA[:, ::-1], axis=1)
                qa = np.where(valid, ctx.q_of(Ssafe.ravel(), np.full(Ssafe.size, a)).reshape(S.shape), np.nan)
                qp = np.where(valid, ctx.q_pi[Ssafe], np.nan)
                incompatible = valid & (A != a) & (np.abs(qa - qp) > ctx.tol)
                inside = (idx > first[:, None]) & (idx < last[:, None]) & has[:, None]
                rows = np.flatnonzero((incompatible & inside).any(axis=1))
                if rows.size:
                    lab = str(ctx.action(a))
                    entry["gaps"] += int(rows.size)
                    entry["gap_lines_by_action"][lab] = entry["gap_lines_by_action"].get(lab, 0) + int(rows.size)
                    for r in rows:
                        i, g, j = _gap_witness(isA[r], incompatible[r], [x[r] for x in classes])
                        gaps.append((name, c, int(a), int(S[r, i]), int(S[r, g]), int(S[r, j]),
                                     float(qa[r, g] - qp[r, g])))
    return summary, gaps


def _gap_witness(is_a: np.ndarray, incompatible: np.ndarray, classes: list[np.ndarray]) -> tuple[int, int, int]:
    """Positions ``(i, g, j)`` on one line, ``i < g < j``, of the best witness of a gap: the first
    class (state masks along the line) holding two states choosing the action around a state
    that strictly prefers another; the first such middle state and its nearest such neighbours."""
    for X in classes:
        a_ok = is_a & X
        n_before = np.cumsum(a_ok) - a_ok  # states choosing the action strictly before each position
        n_after = a_ok.sum() - np.cumsum(a_ok)
        mid = np.flatnonzero(incompatible & X & (n_before > 0) & (n_after > 0))
        if mid.size:
            g = int(mid[0])
            pos = np.flatnonzero(a_ok)
            return int(pos[pos < g][-1]), g, int(pos[pos > g][0])
    raise ModelError("internal error: a line gap without a witness")


def gap_violations(ctx: PolicyContext, gaps: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(recurrent, at_cap, size)`` arrays of the gaps of :func:`line_structure` (a gap is
    recurrent when its three states are, at the cap when one of them is)."""
    if not gaps:
        z = np.zeros(0, bool)
        return z, z, np.zeros(0)
    trip = np.asarray([[x[3], x[4], x[5]] for x in gaps], dtype=np.int64)
    rec = ctx.recurrent[trip].all(axis=1)
    cap = ctx.at_cap[trip].any(axis=1)
    size = np.asarray([x[6] for x in gaps])
    return rec, cap, size


def gap_violation(ctx: PolicyContext, gap: tuple, rec: bool, cap: bool) -> Violation:
    """The :class:`~wncs_lp.verify.report.Violation` of one gap of :func:`line_structure`."""
    name, c, a, s_first, s_gap, s_last, size = gap
    return ctx.violation(
        "line-gap", size, (s_first, s_gap, s_last), rec, cap,
        {"direction": name, "action": list(ctx.action(a)), "action_at_gap": list(ctx.action(ctx.act[s_gap])),
         "meaning": "states 1 and 3 choose the action; state 2 between them on the line strictly prefers another "
                    "(size = Q(gap, action) - Q(gap, pi(gap)))"},
    )


def switching_orders(ctx: PolicyContext, configs: Sequence[int], directions: Sequence[tuple[int, ...]]
                     ) -> tuple[dict, list[tuple]]:
    """Whether the policy switches between two actions in the same order on every parallel line.

    A monotone switching curve (the threshold form of the paper's Figs. 11-12: one action's region
    an up-set in one AoI and a down-set in the other) switches between two actions a, b in one
    direction along every line of an axis: a before b on every line where both occur, or b before
    a on every line. For each configuration, direction and pair of feasible actions (a, b), a line
    *orders* them when the states strictly preferring a (pi = a, and b worse beyond tol) all come
    before, or all after, the states strictly preferring b (interleaved lines are gaps of
    :func:`line_structure`, not counted here). When both orders occur, each line of the minority
    order is a *reversal*, witnessed by its switch pair (the last state of the first action and the
    first of the second) and the switch pair of the nearest line of the majority order; among the
    witnesses, the best by :func:`~wncs_lp.verify.verdict.witness_class` (all four states
    recurrent and below the cap if any majority line allows it, ...).

    Returns (summary per direction, list of reversals (direction, config, a, b, states, size)),
    ``states`` = (minority a-state, minority b-state, majority a-state, majority b-state) and
    ``size`` = the smaller of the two strict preferences on the minority line.
    """
    space = ctx.mdp.states
    caps = tuple(int(c) for c in space.caps)
    summary: dict[str, dict] = {}
    out: list[tuple] = []
    for name, lines in _direction_lines(space, directions):
        entry = summary.setdefault(name, {"ordered_line_pairs": 0, "reversals": 0, "groups_reversed": 0})
        if lines.shape[1] < 2:
            continue
        starts = np.stack(np.unravel_index(lines[:, 0], caps), axis=1)  # the line's position across d
        for c in configs:
            feas = np.flatnonzero(ctx.offsets[c] >= 0)
            if feas.size < 2:
                continue
            S, keep = states_on_lines(space, lines, c, 2)
            if S.shape[0] < 2:
                continue
            lines_c = _LinesOfConfig(ctx, S, starts[keep], feas)
            for i, a in enumerate(feas):
                for b in feas[i + 1:]:
                    found, n_ordered = lines_c.reversals(int(a), int(b))
                    entry["ordered_line_pairs"] += n_ordered
                    entry["groups_reversed"] += bool(found)
                    entry["reversals"] += len(found)
                    out += [(name, int(c), int(a), int(b), states, size) for states, size in found]
    return summary, out


class _LinesOfConfig:
    """The parallel lines of one direction in one configuration: states, actions, Q-values of the
    feasible actions and the witness classes of :func:`~wncs_lp.verify.verdict.witness_class`."""

    def __init__(self, ctx: PolicyContext, S: np.ndarray, pos: np.ndarray, feas: np.ndarray) -> None:
        self.S, self.pos, self.tol = S, pos, ctx.tol
        self.valid = S >= 0
        Ssafe = np.maximum(S, 0)
        self.A = np.where(self.valid, ctx.act[Ssafe], -1)
        self.Q = {int(a): np.where(self.valid, ctx.q_of(Ssafe.ravel(), np.full(Ssafe.size, a)).reshape(S.shape),
                                   np.nan) for a in feas}
        self.classes = [self.valid & m[Ssafe] for m in witness_class(ctx.recurrent, ctx.at_cap, ctx.observable)]

    def reversals(self, a: int, b: int) -> tuple[list[tuple[tuple[int, ...], float]], int]:
        """The lines of the minority order of (a, b), each with its best witness (its own switch
        pair and that of the nearest majority line, both in one witness class) and size; and the
        number of lines that order the two actions."""
        Q, L = self.Q, self.S.shape[1]
        idx = np.arange(L)[None, :]
        with np.errstate(invalid="ignore"):
            sa = self.valid & (self.A == a) & (Q[b] - Q[a] > self.tol)
            sb = self.valid & (self.A == b) & (Q[a] - Q[b] > self.tol)
        both = sa.any(axis=1) & sb.any(axis=1)
        if np.count_nonzero(both) < 2:
            return [], 0
        fa = np.where(sa, idx, L + 1).min(axis=1)
        la = np.where(sa, idx, -1).max(axis=1)
        fb = np.where(sb, idx, L + 1).min(axis=1)
        lb = np.where(sb, idx, -1).max(axis=1)
        ab = both & (la < fb)
        ba = both & (lb < fa)
        n_ab, n_ba = int(np.count_nonzero(ab)), int(np.count_nonzero(ba))
        if not (n_ab and n_ba):
            return [], n_ab + n_ba
        minority, majority = (ba, ab) if n_ab >= n_ba else (ab, ba)
        maj_rows = np.flatnonzero(majority)

        def switch(r: int, X: np.ndarray) -> tuple[int, int] | None:
            """The (a, b) positions of line r's switch among the states of X (None: no such pair)."""
            pa, pb = np.flatnonzero(sa[r] & X[r]), np.flatnonzero(sb[r] & X[r])
            if not (pa.size and pb.size):
                return None
            return (int(pa[-1]), int(pb[0])) if ab[r] else (int(pa[0]), int(pb[-1]))

        found = []
        for r in np.flatnonzero(minority):
            r = int(r)
            for X in self.classes:
                mine = switch(r, X)
                others = [(int(r2), switch(int(r2), X)) for r2 in maj_rows]
                others = [(r2, sw) for r2, sw in others if sw is not None]
                if mine is None or not others:
                    continue
                r2, (ja, jb) = min(others, key=lambda t: int(np.abs(self.pos[t[0]] - self.pos[r]).sum()))
                ia, ib = mine
                size = float(min(Q[b][r, ia] - Q[a][r, ia], Q[a][r, ib] - Q[b][r, ib]))
                S = self.S
                found.append(((int(S[r, ia]), int(S[r, ib]), int(S[r2, ja]), int(S[r2, jb])), size))
                break
        return found, n_ab + n_ba


def order_violations(ctx: PolicyContext, reversals: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(recurrent, at_cap, size)`` of the reversals of :func:`switching_orders` (recurrent when
    all four witness states are, at the cap when one of them is)."""
    if not reversals:
        z = np.zeros(0, bool)
        return z, z, np.zeros(0)
    st = np.asarray([x[4] for x in reversals], dtype=np.int64)
    return ctx.recurrent[st].all(axis=1), ctx.at_cap[st].any(axis=1), np.asarray([x[5] for x in reversals])


def order_violation(ctx: PolicyContext, rev: tuple, rec: bool, cap: bool) -> Violation:
    """The :class:`~wncs_lp.verify.report.Violation` of one reversal of :func:`switching_orders`."""
    name, c, a, b, states, size = rev
    return ctx.violation(
        "order-reversal", size, states, rec, cap,
        {"direction": name, "actions": [list(ctx.action(a)), list(ctx.action(b))],
         "meaning": "along this line the policy switches between the two actions in the opposite order to the "
                    "nearest line of the majority order (states 1-2: this line's switch, states 3-4: the other "
                    "line's); size = the smaller strict preference on this line"},
    )


def theorem2_direction(label: tuple[int, ...], N: int) -> tuple[int, ...] | None:
    """The ray direction ``sum_{k in K} e_k`` of Theorem 2 for an action label sending the
    processes K (None unless it sends at least two distinct processes)."""
    sent = [k for k in label if k]
    if len(sent) < 2 or len(set(sent)) != len(sent):
        return None
    d = [0] * N
    for k in sent:
        d[k - 1] = 1
    return tuple(d)

r"""One constraint beyond the LP's size: a search on the multiplier and a one-state mix.

With a single bound in max form :math:`r^T x \le \beta` (a ``max`` bound is :math:`d^T x \le
\text{max}`, a ``min`` bound :math:`-d^T x \le -\text{min}`), the dual function

.. math:: \mathcal L(\lambda) = \min_\pi \bigl(g_\pi(c) + \lambda\, g_\pi(r)\bigr) - \lambda \beta,
          \qquad \lambda \ge 0,

is the lower envelope of the lines :math:`\ell_\pi(\lambda) = c_\pi + \lambda r_\pi - \lambda\beta`
of the deterministic policies (:math:`c_\pi, r_\pi` their exact averages), concave and
piecewise linear, and :math:`\mathcal L(\lambda) \le g^*_C` for every :math:`\lambda \ge 0`. Beutler
and Ross (1985): at the maximiser :math:`\lambda^*` two deterministic policies, one feasible
(:math:`r \le \beta`) and one not, are both optimal for the Lagrangian cost
:math:`c + \lambda^* r`; walking from one to the other one state at a time, the constraint's
value crosses :math:`\beta` between two consecutive policies, and randomising in that single
state meets the bound with equality at the constrained optimum.

The route (:func:`solve_lagrangian`), every step a certified value iteration
(:func:`~wncs_lp.constrained.certify.lagrangian_bound`) warm-started with the previous bias,
every deterministic policy evaluated exactly (:func:`~wncs_lp.constrained.certify.evaluate_rows`):

1. :math:`\lambda = 0`: if the unconstrained optimum meets the bound it is the answer
   (multiplier 0). For a two-sided constraint this decides the side that can bind: the one
   the unconstrained optimum violates (the optimum over the convex occupation polytope then
   lies on that face, so the other side is met).
2. Bracket: :math:`\lambda` grows geometrically until the greedy policy meets the bound
   (``pi_low``, feasible, optimal at ``lam_hi``); the last one that does not is ``pi_high``
   (optimal at ``lam_lo``). The first failure checks the bound's reachability
   (:func:`~wncs_lp.constrained.lp.check_reachable`), so an unreachable bound raises
   :class:`~wncs_lp.errors.InfeasibleConstraintsError` instead of growing forever.
3. Search on :math:`\lambda \in [\lambda_{lo}, \lambda_{hi}]`: the trial point is where the two
   lines meet, :math:`\lambda_\times = (c_{low} - c_{high}) / (r_{high} - r_{low})` (it lies in
   the interval because each policy is optimal at its own end; midpoint bisection is the
   safeguard when round-off puts it outside). If the certified lower end
   :math:`\underline g_{\lambda_\times}` reaches the lines' common value
   :math:`m = c + \lambda_\times r` to ``tol``, both policies are optimal at
   :math:`\lambda_\times = \lambda^*` and the search stops; otherwise the greedy policy at
   :math:`\lambda_\times` has a strictly lower line and replaces the endpoint on its side.
   This is bisection on the jump of the subgradient :math:`r_{\pi_\lambda} - \beta` with the
   secant point of the two known pieces instead of the midpoint: it ends after at most as
   many steps as the envelope has pieces between the ends (1-9 on the paper's instances), where the
   midpoint would need ~40 to pin :math:`\lambda^*` to 1e-12.
4. Common greedy ends: gain-optimal policies may act arbitrarily on states they never visit,
   and such an action can land on the recurrent class of a walk policy and make it
   suboptimal for the Lagrangian (seen on p12, cap 12: "never send to remote" vs the rest).
   So every action of both ends that is not within a quarter of the certificate's budget of
   :math:`\min_a Q_{h^*}(s, a)` (the final bias :math:`h^*`) is replaced by the other end's
   action or the greedy one; on transient states this leaves the averages unchanged, and the
   repaired ends are re-evaluated and kept only if they stay on their sides.
5. Walk: order the states where ``pi_high`` and ``pi_low`` differ; policy :math:`\pi^k` takes
   ``pi_low``'s action on the first k of them. A crossing :math:`r_{\pi^k} > \beta \ge
   r_{\pi^{k+1}}` is found by bisection on k (:math:`O(\log K)` exact evaluations, not K).
   Multichain intermediates (their averages depend on the start) are skipped by trying the
   nearest unichain neighbours, then another order (reverse, then seeded random); so is a
   crossing whose policies are not Lagrangian-optimal at :math:`\lambda^*` (its mix would
   leave the certificate); the stats say how many.
6. Mix in the single state s that differs between :math:`\pi^k` and :math:`\pi^{k+1}`:
   action :math:`a_{k+1}` with probability p, :math:`a_k` with 1 - p. Closed form, exact: the
   mixed chain's occupation measure is the convex combination
   :math:`x(p) = \theta x_{k+1} + (1 - \theta) x_k` with
   :math:`\theta = p\mu_k(s) / (p\mu_k(s) + (1-p)\mu_{k+1}(s))` (it satisfies the balance
   equations, takes the same actions off s and the right ratio at s, and a unichain policy
   has one stationary law; :math:`\mu` = stationary law). Every average is linear in
   :math:`\theta` (a ratio of linear functions of p), so :math:`r(x(p)) = \beta` at

   .. math:: \theta^* = \frac{r_k - \beta}{r_k - r_{k+1}}, \qquad
             p^* = \frac{\theta^* \mu_{k+1}(s)}{(1-\theta^*)\mu_k(s) + \theta^*\mu_{k+1}(s)}.

   (If s is transient under one of the two, the average jumps at p = 0 or 1 and no mix in s
   meets the bound: another crossing is sought.)

The result goes through :func:`~wncs_lp.constrained.certify.certify` with the bound at
:math:`\lambda^*`: the certificate is :math:`[\mathcal L(\lambda^*), \text{exact cost of the
mixed policy}]`, the mixed policy re-evaluated exactly on its own chain.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import PolicyError, SolverError
from ..mdp import MDP
from .certify import CERT_RTOL, FEAS_RTOL, certify, evaluate_rows, lagrangian_bound
from .lp import check_reachable
from .problem import LinearConstraint, max_form
from .result import ConstrainedSolution

__all__ = ["LP_MAX_PAIRS", "auto_method", "solve_lagrangian"]

#: A constrained ``method="auto"`` uses the LP up to this many pairs, this route beyond.
#: Measured by ``benchmarks/constrained.py`` (send_rate[remote] <= 0.2 on p12/p123 with
#: allow_idle, 2 cores, two runs; benchmarks/README.md, "Constrained solves"): the constrained
#: LP took 0.4-0.5 s at 5,629 pairs, 4.1-4.6 s at 21,057, 15 s at 46,885, 39-50 s at 83,113 and
#: 131-166 s (+543 MiB) at 129,741; this route was faster at every size (7-83x; 22 s and
#: +168 MiB at 1.1M pairs) with the same gain (to 1e-12) and multiplier (to 3e-9). Up to ~20k
#: pairs the LP stays within a few seconds, and it is kept there because it assumes nothing of
#: the chains (this route needs unichain greedy policies) and returns a vertex by itself.
LP_MAX_PAIRS = 20_000


def auto_method(mdp: MDP, constraints) -> str:
    """What ``method="auto"`` of a constrained solve runs: the LP on HiGHS (``"lp-highs"``) up to
    :data:`LP_MAX_PAIRS` pairs or with more than one constraint (the Lagrangian route handles
    one), else ``"lagrangian"``. HiGHS rather than Clarabel because the constrained LP must end on
    a basis, which HiGHS's crossover gives directly where Clarabel's interior point needs a
    crossover of its own after it (several times slower on a trade-off curve's cold points:
    ``benchmarks/tradeoff_warm.py``, its figures in ``benchmarks/README.md`` and
    ``docs/constraints.md``)."""
    return "lp-highs" if (mdp.n_pairs <= LP_MAX_PAIRS or len(constraints) > 1) else "lagrangian"

#: Largest relative VI tolerance of a search step; the smallest (round-off floor).
_VI_TOL_MAX, _VI_TOL_MIN = 1e-8, 1e-12


@dataclass
class _Det:
    """A deterministic policy with its exact averages: cost c, row value r = D_j x."""

    pol: np.ndarray
    c: float
    r: float
    occ: np.ndarray

    def line(self, lam: float) -> float:
        return self.c + lam * self.r


def _onehot(mdp: MDP, pol: np.ndarray) -> np.ndarray:
    probs = np.zeros(mdp.n_pairs)
    probs[pol] = 1.0
    return probs


def _exact_averages(mdp: MDP, pol: np.ndarray, cons: Sequence[LinearConstraint], row: np.ndarray) -> _Det:
    """Exact averages of a deterministic policy (raises PolicyError when multichain)."""
    ev = evaluate_rows(mdp, _onehot(mdp, pol), cons)
    return _Det(np.asarray(pol, dtype=np.int64).copy(), ev["gain"], float(row @ ev["occupation"]), ev["occupation"])


def solve_lagrangian(
    mdp: MDP,
    constraints: Sequence[LinearConstraint],
    *,
    tol: float | None = None,
    max_steps: int = 60,
    cert_rtol: float = CERT_RTOL,
    progress: bool = False,
    h0: np.ndarray | None = None,
    lambda0: float | None = None,
    growth: float = 4.0,
    walk_orders: int = 4,
    seed: int = 0,
) -> ConstrainedSolution:
    r"""Minimise the average cost under ONE linear bound, by certified value iteration alone.

    Parameters
    ----------
    mdp : MDP
    constraints : sequence of one LinearConstraint
        ``max``, ``min`` or both (two-sided: at most one side binds, the one the unconstrained
        optimum violates).
    tol : float, optional
        The search stops when :math:`m - \underline g_{\lambda} \le` ``tol`` :math:`\cdot |m -
        \lambda\beta|` (the two endpoint policies are optimal for the Lagrangian to that
        relative accuracy, which is then the certificate's width); default ``cert_rtol / 20``.
        Each value iteration runs to a relative bracket width of a quarter of that (in the
        units of the constrained gain), between 1e-12 and 1e-8.
    max_steps : int
        Budget of value-iteration solves for the bracket and the search together (the
        result is returned with ``stats["lambda_converged"] = False`` if it runs out).
    cert_rtol : float
        Width of the certificate ``[L(lambda*), exact cost]`` accepted as "optimal".
    progress : bool
        One line per value-iteration solve and per walk evaluation on stderr.
    h0 : (n,) array, optional
        Warm start of the first value iteration (e.g. a neighbouring solve's bias).
    lambda0 : float, optional
        First multiplier of the bracket; default :math:`\max(|g_0|, 10^{-3} \max|c|) / (r_0 -
        \beta)` (the unconstrained gain over the violation: the price at which removing the
        violation costs as much as the whole gain; an overshoot costs one or two secant steps).
    growth : float
        Factor of the geometric bracket.
    walk_orders : int
        Orders of the differing states tried when a walk hits multichain policies or a mix
        that cannot meet the bound (natural, reverse, then seeded random).
    seed : int
        Seed of the random orders.

    Returns
    -------
    ConstrainedSolution
        ``method="lagrangian"``; randomises in at most one state. ``stats``: ``lambda``,
        ``lambda_interval``, ``lambda_steps`` (VI solves), ``lambda_bracket_steps``,
        ``lambda_search_steps``, ``lambda_converged``, ``search_gap_rel``, ``binding_side``,
        ``walk_repaired_states``, ``walk_states_differ``, ``walk_evaluations``,
        ``walk_multichain_skipped``, ``walk_suboptimal_crossings``, ``walk_order``,
        ``walk_orders_tried``, ``walk`` (what the walk returned), ``mix_state``,
        ``mix_probability``, ``mix_theta``, ``vi_sweeps_total``. ``solver_gain`` and the
        report's ``lp_value`` are the closed form's prediction for the mixed policy (the
        exact evaluation in ``gain`` and ``value`` is what the certificate uses).

    Raises
    ------
    InfeasibleConstraintsError
        The bound is beyond what any policy reaches.
    SolverError
        Not exactly one constraint, a greedy policy of the search is multichain (use the LP),
        or the bracket cannot be closed.
    """
    t0 = time.perf_counter()
    cons = tuple(constraints)
    tol = cert_rtol / 20.0 if tol is None else tol
    if len(cons) != 1:
        raise SolverError(f"the Lagrangian route handles exactly one constraint, got {len(cons)}; use method='lp'")
    if not (tol > 0 and growth > 1 and max_steps >= 2):
        raise SolverError("solve_lagrangian needs tol > 0, growth > 1 and max_steps >= 2")
    search = _Search(mdp, cons, tol, max_steps, h0, progress)
    stats = search.stats
    # ---- 1. lambda = 0: the unconstrained optimum, and the side that can bind
    bound0, vi0 = search.solve_at(0.0, min(max(0.25 * tol, _VI_TOL_MIN), _VI_TOL_MAX))
    high, ev0 = search.unconstrained(vi0)
    if high is None:
        stats.update({"lambda": 0.0, "binding_side": None, "lambda_steps": search.n_vi, "lambda_converged": True})
        return certify(mdp, cons, _onehot(mdp, vi0.policy), np.zeros(0, np.int64), np.zeros(search.rows.n_rows),
                       method="lagrangian", solver_gain=ev0["gain"], lp_values=ev0["values"],
                       lower=(bound0, vi0), cert_rtol=cert_rtol, iterations=search.n_vi, t0=t0, stats=stats)
    # ---- 2. bracket: grow lambda until the greedy policy meets the bound
    ends = search.bracket(high, lambda0, growth)
    # ---- 3. search: trial point where the two lines meet, until both are optimal there
    high, low, last = search.secant(*ends)
    # ---- 4-6. walk from pi_high to pi_low, mix in the state where the value crosses beta
    probs, randomized, predicted = _mixed_policy(search, high, low, last, cert_rtol, walk_orders, seed)
    lam_rows = np.zeros(search.rows.n_rows)
    lam_rows[search.j] = last[0]
    return certify(mdp, cons, probs, randomized, lam_rows, method="lagrangian",
                   solver_gain=predicted[0], lp_values=np.array([predicted[1]]), lower=last[1:],
                   cert_rtol=cert_rtol, iterations=search.n_vi, t0=t0, stats=stats)


def _mixed_policy(search: "_Search", high: _Det, low: _Det, last, cert_rtol: float, walk_orders: int, seed: int):
    """Steps 4-6 at ``last = (lambda*, bound, vi)``: both ends made greedy for the final bias, the
    walk between them and the mix in one state; ``(probs, randomised states, prediction)``."""
    lam_star, _, vi_star = last
    row, beta = search.row, search.beta
    g_est = abs(max(high.line(lam_star), low.line(lam_star)) - lam_star * beta)
    # eps: a quarter of the certificate's budget. The VI bias is only approximate, so an action
    # that is optimal on a recurrent state can look eps_VI ~ (m - lo) / mu(s) worse than the
    # best; eps must exceed that, and the walk's policies then cost at most hi + eps.
    high, low = _common_greedy(search.mdp, row, beta, lam_star, vi_star.bias, high, low, 0.25 * cert_rtol * g_est,
                               search.meets_tol, search.cons, search.stats, search.say)
    # a walk policy whose Lagrangian line stays below this keeps the mix inside the certificate
    line_max = vi_star.gain_lower + 0.5 * cert_rtol * g_est
    return _walk_and_mix(search.mdp, search.cons, row, beta, high, low, walk_orders, seed, search.stats,
                         search.say, lam_star, line_max)


class _Search:
    """The multiplier search: warm-started certified value iterations on the Lagrangian cost
    ``c + lambda r`` of the binding row ``j`` (``r = D_j``, bound ``beta``), and their count."""

    def __init__(self, mdp: MDP, cons: tuple[LinearConstraint, ...], tol: float, max_steps: int,
                 h0: np.ndarray | None, progress: bool) -> None:
        self.mdp, self.cons, self.tol, self.max_steps, self.progress = mdp, cons, tol, max_steps, progress
        self.rows = max_form(cons, mdp.n_pairs)
        self.lam_rows = np.zeros(self.rows.n_rows)
        self.cscale = float(np.max(np.abs(mdp.cost))) if mdp.n_pairs else 1.0
        self.stats: dict[str, Any] = {"vi_sweeps_total": 0}
        self.h = h0  # the warm start of the next value iteration
        self.n_vi = 0
        self.j, self.row, self.beta, self.meets_tol = -1, np.zeros(0), np.nan, 0.0

    def say(self, msg: str) -> None:
        if self.progress:
            print(f"[lagrangian] {msg}", file=sys.stderr, flush=True)

    def solve_at(self, lam: float, vtol: float):
        """``(L(lambda), vi)`` of the certified value iteration at multiplier ``lam`` on row j."""
        self.lam_rows[:] = 0.0
        if self.j >= 0:
            self.lam_rows[self.j] = lam
        bound, vi = lagrangian_bound(self.mdp, self.rows, self.lam_rows, h0=self.h, tol=vtol)
        self.h = vi.bias  # the next lambda is close: its bias is the best warm start
        self.n_vi += 1
        self.stats["vi_sweeps_total"] += int(vi.iterations)
        return bound, vi

    def greedy(self, vi) -> _Det:
        """The exact averages of a value iteration's greedy policy."""
        try:
            return _exact_averages(self.mdp, vi.policy, self.cons, self.row)
        except PolicyError as exc:
            raise SolverError(f"lagrangian: the greedy policy of a value-iteration step is multichain ({exc}); "
                              f"use method='lp'") from exc

    def unconstrained(self, vi0) -> tuple[_Det | None, dict]:
        """The unconstrained optimum: ``(None, its averages)`` when it meets the bound, else the
        violated row becomes the binding one and ``(pi_high, its averages)``."""
        mdp, rows = self.mdp, self.rows
        try:
            ev0 = evaluate_rows(mdp, _onehot(mdp, vi0.policy), self.cons)
        except PolicyError as exc:
            raise SolverError(f"lagrangian: the unconstrained greedy policy is multichain ({exc}); "
                              f"use method='lp'") from exc
        occ0 = ev0["occupation"]
        r_rows = rows.D @ occ0
        excess = (r_rows - rows.b) / np.maximum(1.0, np.abs(rows.b))
        self.say(f"lambda=0: gain={ev0['gain']:.10g} value={ev0['values'][0]:.10g} sweeps={vi0.iterations}")
        if np.all(excess <= FEAS_RTOL):
            return None, ev0
        j = int(np.argmax(excess))
        self.j, self.row, self.beta = j, rows.D[j], float(rows.b[j])
        self.stats["binding_side"] = rows.side[j]
        self.meets_tol = 0.01 * FEAS_RTOL * max(1.0, abs(self.beta))  # "meets the bound" for a search endpoint
        return _Det(np.asarray(vi0.policy, np.int64).copy(), ev0["gain"], float(r_rows[j]), occ0), ev0

    def bracket(self, high: _Det, lambda0: float | None, growth: float):
        """Grow lambda geometrically until the greedy policy meets the bound: ``(high, low,
        lam_lo, lam_hi, last)`` with ``last = (lambda, bound, vi)`` of the step that met it."""
        beta, tol = self.beta, self.tol
        lam_lo = 0.0
        lam = lambda0 if lambda0 is not None else max(abs(high.c), 1e-3 * self.cscale, 1e-300) / (high.r - beta)
        reach_checked = False
        n_bracket = 0
        while True:
            if self.n_vi >= self.max_steps:
                raise SolverError(f"lagrangian: no multiplier up to {lam_lo:.6g} meets {self.cons[0].label!r} "
                                  f"within max_steps={self.max_steps} value-iteration solves")
            # the Lagrangian gain is ~ c + lam r: scale the VI tolerance to the constrained gain's units
            vtol = min(max(0.25 * tol * abs(high.c) / max(abs(high.c + lam * high.r), 1e-300), _VI_TOL_MIN),
                       _VI_TOL_MAX)
            bound, vi = self.solve_at(lam, vtol)
            p = self.greedy(vi)
            n_bracket += 1
            self.say(f"bracket lambda={lam:.10g}: value={p.r:.10g} bound={beta:.10g} sweeps={vi.iterations}")
            if p.r <= beta + self.meets_tol:
                self.stats["lambda_bracket_steps"] = n_bracket
                return high, p, lam_lo, lam, (lam, bound, vi)
            high, lam_lo = p, lam
            if not reach_checked:
                check_reachable(self.mdp, self.cons)  # raises InfeasibleConstraintsError, naming what can be reached
                reach_checked = True
            lam *= growth

    def secant(self, high: _Det, low: _Det, lam_lo: float, lam_hi: float, last):
        """Trial points where the two ends' lines meet, until both ends are optimal there (or the
        budget of solves is spent): ``(high, low, last)``, the search's numbers in the stats."""
        tol, beta = self.tol, self.beta
        n_search, kinds, converged, gap_rel = 0, {"secant": 0, "bisect": 0}, False, np.inf
        tighten = 1.0  # extra factor on the VI tolerance after a step that found no better policy
        while self.n_vi < self.max_steps:
            dr = high.r - low.r
            lam_x = (low.c - high.c) / dr if dr > 0 else np.nan
            step = "secant"
            if not (lam_lo <= lam_x <= lam_hi):  # round-off only: each end is optimal at its own lambda
                lam_x, step = 0.5 * (lam_lo + lam_hi), "bisect"
            m = max(high.line(lam_x), low.line(lam_x))
            g_est = abs(m - lam_x * beta)  # ~ the constrained gain
            base = 0.25 * tol * g_est / max(abs(m), 1e-300)
            vtol = min(max(base * tighten, _VI_TOL_MIN), _VI_TOL_MAX)
            bound, vi = self.solve_at(lam_x, vtol)
            n_search += 1
            kinds[step] += 1
            last = (lam_x, bound, vi)
            gap = m - vi.gain_lower
            gap_rel = gap / max(g_est, 1e-300)
            self.say(f"search {step} lambda={lam_x:.12g} interval=[{lam_lo:.12g}, {lam_hi:.12g}] gap={gap_rel:.3g} "
                     f"sweeps={vi.iterations}")
            if gap <= tol * g_est or gap <= 1e-13 * self.cscale:
                converged = True
                break
            p = self.greedy(vi)
            # the greedy policy's exact line is <= the VI's upper end: if it is no lower than m, the
            # bracket was only loose (VI stopped at max_iter or at a clipped tolerance)
            if p.line(lam_x) < m - 0.1 * tol * g_est or step == "bisect":
                if p.r <= beta + self.meets_tol:  # a new piece of the envelope replaces the end on its side
                    low, lam_hi = p, lam_x
                else:
                    high, lam_lo = p, lam_x
                tighten = 1.0
            elif vtol <= _VI_TOL_MIN:
                break  # cannot tighten further: the certificate will say how far it got
            else:
                tighten *= 1e-2
        lam_star = last[0]
        self.stats.update({"lambda": float(lam_star), "lambda_interval": [float(lam_lo), float(lam_hi)],
                           "lambda_steps": self.n_vi, "lambda_search_steps": n_search,
                           "lambda_secant_steps": kinds["secant"], "lambda_bisect_steps": kinds["bisect"],
                           "lambda_converged": converged, "search_gap_rel": float(gap_rel)})
        self.say(f"lambda*={lam_star:.12g} ({'converged' if converged else 'NOT converged'}, gap {gap_rel:.3g})")
        return high, low, last


def _common_greedy(mdp: MDP, row: np.ndarray, beta: float, lam: float, h: np.ndarray, high: _Det, low: _Det,
                   eps: float, meets_tol: float, cons, stats: dict, say) -> tuple[_Det, _Det]:
    r"""Make both ends greedy for the same bias, so that every policy of the walk is Lagrangian-optimal.

    A gain-optimal policy may take any action on states its chain never visits (e.g. "never
    send" is indifferent to what it would do with an update in hand). Mixing such an action
    into the walk can put it on the recurrent class of an intermediate policy, which is then
    *not* optimal at :math:`\lambda^*` and the mix's cost leaves the certificate. If instead
    every action of both ends is within ``eps`` of :math:`\min_a Q_h(s, a)` for the final
    bias h (cost :math:`c + \lambda^* r`), every intermediate is too, and its Lagrangian gain
    is at most the VI's upper end + ``eps``. Replacing an action on a transient state leaves
    the recurrent class and so the averages unchanged; the replaced ends are re-evaluated
    exactly all the same, and kept only when they stay on their sides of the bound.
    """
    from ..solvers.certify import greedy_first, q_values
    from .problem import with_cost

    q = q_values(with_cost(mdp, mdp.cost + lam * row), h)
    qmin = np.minimum.reduceat(q, mdp.pair_ptr[:-1])
    greedy = greedy_first(mdp, q, qmin)
    out, changed = [], 0
    for d, other in ((high, low), (low, high)):
        bad = q[d.pol] - qmin > eps
        if not bad.any():
            out.append(d)
            continue
        pol = d.pol.copy()
        take_other = bad & (q[other.pol] - qmin <= eps)  # the other end's action keeps the two close
        pol[take_other] = other.pol[take_other]
        pol[bad & ~take_other] = greedy[bad & ~take_other]
        changed += int(bad.sum())
        try:
            out.append(_exact_averages(mdp, pol, cons, row))
        except PolicyError:
            out.append(None)
    h2, l2 = out
    ok = h2 is not None and l2 is not None and h2.r > beta + meets_tol and l2.r <= beta + meets_tol
    stats["walk_repaired_states"] = changed if ok else 0
    if changed and not ok:
        stats["walk_repair"] = "rejected: a repaired end changed sides or became multichain"
    say(f"ends made greedy for the final bias: {changed} states changed ({'kept' if ok else 'rejected'})")
    return (h2, l2) if ok else (high, low)


def _walk_and_mix(mdp: MDP, cons, row, beta: float, high: _Det, low: _Det, walk_orders: int, seed: int,
                  stats: dict, say, lam: float, line_max: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Bisection on the one-state-at-a-time walk from ``high`` to ``low``, then the exact mix.

    A crossing is accepted when both its policies have a Lagrangian line at ``lam`` of at most
    ``line_max`` (then the mix's cost is within the certificate's budget); otherwise, or when
    the walk is blocked by multichain policies or a transient mixing state, the next order is
    tried. Returns the pair probabilities, the randomised states and the closed form's
    prediction (gain, constraint value) of the mixed policy. Falls back to the first usable
    crossing, or to ``low`` (feasible, deterministic) when there is none; ``stats["walk"]``
    says which.
    """
    diff = np.flatnonzero(high.pol != low.pol)
    K = int(diff.size)
    sign = 1.0 if stats.get("binding_side") == "max" else -1.0  # row value r = sign * d
    stats.update(walk_states_differ=K, walk_evaluations=0, walk_multichain_skipped=0, walk_orders_tried=0,
                 walk_suboptimal_crossings=0)
    rng = np.random.default_rng(seed)
    fallback = None
    for t in range(max(1, walk_orders)):
        order = diff if t == 0 else (diff[::-1] if t == 1 else rng.permutation(diff))
        name = ("natural", "reverse")[t] if t < 2 else f"random#{t - 1}"
        stats["walk_orders_tried"] += 1
        cache: dict[int, _Det | None] = {0: high, K: low}

        def at(k: int) -> _Det | None:
            if k not in cache:
                pol = high.pol.copy()
                pol[order[:k]] = low.pol[order[:k]]
                stats["walk_evaluations"] += 1
                try:
                    cache[k] = _exact_averages(mdp, pol, cons, row)
                    say(f"walk {name} k={k}/{K}: value={cache[k].r:.12g}")
                except PolicyError:
                    cache[k] = None
                    stats["walk_multichain_skipped"] += 1
                    say(f"walk {name} k={k}/{K}: multichain, skipped")
            return cache[k]

        lo, hi = 0, K  # invariant: r(lo) > beta >= r(hi), both unichain
        while hi - lo > 1:
            mid = (lo + hi) // 2
            # the nearest unichain policy to the midpoint (a few tries, alternating sides)
            cand = [mid] + [mid + s * d for d in range(1, 4) for s in (1, -1)]
            k = next((c for c in cand if lo < c < hi and at(c) is not None), None)
            if k is None:
                break
            if cache[k].r > beta:
                lo = k
            else:
                hi = k
        if hi - lo > 1:
            say(f"walk {name}: blocked by multichain policies between k={lo} and k={hi}; next order")
            continue
        a, b = cache[lo], cache[hi]
        s = int(order[lo])  # the one state where pi^lo and pi^(lo+1) differ
        theta = (a.r - beta) / (a.r - b.r)
        info = dict(walk_order=name, walk_crossing=[lo, hi], mix_state=s, mix_theta=float(theta))
        if theta >= 1.0 - 1e-15 or theta <= 1e-15:  # an endpoint meets the bound with equality
            d = b if theta >= 0.5 else a
            found = (_onehot(mdp, d.pol), np.zeros(0, np.int64), (d.c, sign * d.r),
                     {**info, "mix_probability": None, "walk": "deterministic: a walk policy meets the bound"})
        else:
            mu_a, mu_b = float(a.occ[a.pol[s]]), float(b.occ[b.pol[s]])
            if mu_a <= 0.0 or mu_b <= 0.0:  # s transient under one of them: the average jumps, no mix meets beta
                say(f"walk {name}: crossing at state {s}, transient under one policy; next order")
                continue
            p = theta * mu_b / ((1.0 - theta) * mu_a + theta * mu_b)
            probs = _onehot(mdp, a.pol)
            probs[a.pol[s]] = 1.0 - p
            probs[b.pol[s]] = p
            say(f"walk {name}: mix in state {s}: p={p:.12g} (theta={theta:.12g})")
            found = (probs, np.array([s], np.int64),
                     ((1.0 - theta) * a.c + theta * b.c, sign * ((1.0 - theta) * a.r + theta * b.r)),
                     {**info, "mix_probability": float(p), "walk": "mixed"})
        if max(a.line(lam), b.line(lam)) <= line_max:
            stats.update(found[3])
            return found[:3]
        # a policy of the crossing is not optimal at lambda*: its mix would leave the certificate
        stats["walk_suboptimal_crossings"] += 1
        say(f"walk {name}: crossing policies are not Lagrangian-optimal "
            f"(line {max(a.line(lam), b.line(lam)):.12g} > {line_max:.12g}); next order")
        fallback = fallback or found
    if fallback is not None:
        stats.update(fallback[3])
        stats["walk"] += " (no order gave a Lagrangian-optimal crossing: the first crossing is used)"
        return fallback[:3]
    stats["walk"] = "failed: no usable crossing in any order; the feasible deterministic end is returned"
    return _onehot(mdp, low.pol), np.zeros(0, np.int64), (low.c, sign * low.r)

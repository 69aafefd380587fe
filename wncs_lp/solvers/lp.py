"""The occupation-measure linear program of an average-cost MDP, solved with Clarabel or HiGHS.

Primal (Manne 1960; Puterman, *Markov Decision Processes*, Sec. 8.8). With x_l the
long-run frequency of pair l = (s_l, a_l):

.. math::

    \\min_x \\; \\sum_l c_l x_l \\quad \\text{s.t.} \\quad
    \\sum_{l:\\, s_l = s'} x_l - \\sum_l P(s' \\mid l)\\, x_l = 0 \\;\\; (s' = 0..n-1), \\qquad
    \\sum_l x_l = 1, \\qquad x \\ge 0.

In matrix form the balance rows are ``(E - P^T) x = 0`` with ``E[s', l] = [s_l = s']``.
They sum to zero (every column of E - P^T sums to 1 - 1 = 0), so one is redundant; the row
of state 0 is dropped, which pins the dual bias to h(0) = 0.

Dual: :math:`\\max g` s.t. :math:`g + h(s_l) \\le c_l + \\sum_{s'} P(s'|l) h(s')` for all
pairs, whose optimum is g*, and complementary slackness gives equality on the pairs with
x_l > 0.

Scaling (what the solver sees)
------------------------------
Variables ``y = n * x`` (so ``sum y = n`` and a uniformly visited state has y = O(1)) and
costs ``q = c / c_s`` with ``c_s`` = mean |c| (1 if all costs are zero):

.. math::

    \\min_y q^T y \\quad\\text{s.t.}\\quad (E - P^T)_{1:} y = 0,\\; 1^T y = n,\\; y \\ge 0,

so ``c^T x = (c_s / n) q^T y``. With Clarabel's form ``A y + s = b``, ``s in K`` (zero cone
for the n equality rows, nonnegative cone for the rows ``-y + s = 0``) and KKT stationarity
``q + A^T z = 0`` (P = 0), writing z = (z_bal, z_norm, -mu) the pair-l component reads

.. math:: q_l + z_{bal}(s_l) - (P z_{bal})_l + z_{norm} = \\mu_l \\ge 0,

i.e. ``g + h(s_l) <= c_l + (P h)_l`` with

    ``h = -c_s * z_bal`` (h(0) = 0),   ``g = -c_s * z_norm``.

(These signs are checked numerically in ``tests/solvers/test_solvers.py``. cvxpy reports the same
sign for the ``A y == b`` constraint's ``dual_value``.)

Formulations (``solve_lp(formulation=...)``, measured in ``benchmarks/run.py``)
-------------------------------------------------------------------------------
* ``"primal"`` -- the LP above.
* ``"reduced"`` -- the same LP with the forced (single-action) states on acyclic forced
  paths substituted out (:mod:`~wncs_lp.solvers.reduce`): for the 2-process wncs model at
  cap 20, 17,859 x 35,718 instead of 41,691 x 59,550; the same optimum; x and h are lifted
  back to every state. Clarabel is 1.5-2x faster on it; the raw LP gain is as accurate.
* ``"dual"`` -- the gain-bias LP (max g s.t. g + h(s_l) <= c_l + (P h)_l). More IPM
  iterations and no faster, but its raw gain is ~1000x more accurate (1e-11 vs 1e-8).
* ``"auto"`` -- reduced when that does not densify the constraint matrix, else primal
  (:func:`choose_lp`).

Polish (``solve_lp(polish=...)``)
--------------------------------
* ``True`` (the default): ``"vi"`` for models of at least :data:`POLISH_VI_MIN_STATES` states,
  else ``"pi"``.
* ``"pi"``: :func:`~wncs_lp.solvers.dp.policy_iteration` from the LP's policy (exact
  evaluation, usually 0-2 improvements); ``gain`` = exact gain of the final policy, ``bias`` its
  exact bias, ``(gain_lower, gain_upper)`` = bracket on that bias. If an iterate is multichain
  (PolicyError) the dual certificate below is used instead and the policy becomes the
  dual-greedy one.
* ``"vi"``: first :func:`~wncs_lp.solvers.dp.value_iteration` warm-started from the LP's dual
  bias (certified to 1e-9), then policy iteration from its greedy policy (usually stable at the
  first exact evaluation). Cheaper than ``"pi"`` when the extracted policy is far from optimal
  (e.g. a loose LP tolerance, large models).
* ``False``: ``gain`` = LP objective, ``bias`` = dual h, bracket on the dual h. An
  interior-point dual may keep slack in states that no optimal policy visits, which widens
  ``hi``; polishing removes that.

Backends (``solve_lp(backend=...)``, measured in ``benchmarks/lp_backends.py``)
-------------------------------------------------------------------------------
* ``"clarabel"`` -- the interior point the project is built on (below).
* ``"highs"`` -- HiGHS through highspy (:mod:`~wncs_lp.solvers.highs`): dual simplex or IPX with
  crossover; its answer is a vertex, so the raw LP gain is exact to round-off (1e-14 against
  Clarabel's 1e-9..1e-11), and the same unscaling, policy extraction, polish and certificate
  follow.
* ``"cvxpy"`` -- Clarabel through cvxpy.
* ``"auto"`` (the default) -- :func:`choose_lp`: HiGHS on LPs of at most
  ``highs_max_rows(width)`` rows (width = columns per row, the mean number of actions of a
  decision state), Clarabel above. HiGHS's time grows faster with the size than Clarabel's
  (processes 1, 2: ~states^3.8 against ~states^1.9), but Clarabel's KKT system carries every
  pair while HiGHS's bases are rows x rows, so many actions per state move the crossover up:
  ~4,000 rows at width 2 (processes 1, 2), beyond 33,000 rows at width 3.3 (processes 1-3),
  where HiGHS was 1.4-7x faster.

Other levers: Clarabel's default ``direct_solve_method`` ("auto") is faer here; qdldl is
3x slower. Turning iterative refinement off saves ~30% at an unchanged raw LP gain on these
models, so it is off by default with the direct backend (:data:`CLARABEL_DEFAULTS`; the cvxpy
backend keeps Clarabel's defaults); the balance residual of the returned occupation measure
grows 5-50x (e.g. 7e-10 -> 4e-9 on p12), still far inside the checks. Clarabel's ``max_threads`` makes no
difference (faer's factorisation of these KKT systems ran as fast on 1 thread as on 2), nor
does the order of rows and columns (its AMD ordering is recomputed; random and reversed
orders were within 4%). What sets the time is the fill of the KKT factor, ~5.4M nonzeros at
p12 cap 16 (10k decision states): each AoI grid point carries tens of server/link
configurations that the transitions couple, so the separators are large. Without the cost
scaling the IPM takes as long and the balance residual is ~60x worse.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import PolicyError, SolverError
from ..mdp import MDP
from ..progress import Progress, as_progress
from ..status import (CERTIFICATE, FAILED, INACCURATE, INFEASIBLE, INTERRUPTED, MAX_ITER, OPTIMAL, POLISH_MAX_ITER, Code, Status,
                      from_backend, polish_reason, status_from)
from .certify import bracket, certificate_closed, greedy_first, q_values
from .dp import policy_iteration
from .highs import highs_status, solve_highs
from .result import Solution

__all__ = ["LPData", "LPChoice", "build_lp", "build_reduced_lp", "choose_lp", "solve_lp", "extract_policy", "VISIT_TOL",
           "FORMULATIONS", "BACKENDS", "REDUCE_MAX_NNZ_RATIO", "HIGHS_ROWS_AT_WIDTH_2", "HIGHS_WIDTH_EXPONENT", "HIGHS_SIMPLEX_MAX_WIDTH",
           "highs_max_rows",
           "CLARABEL_DEFAULTS", "POLISH_VI_MIN_STATES", "FAILED_STATUSES", "CLARABEL_STATUS", "CVXPY_STATUS",
           "clarabel_status", "cvxpy_status", "backend_status", "usable", "clarabel_settings", "clarabel_stats",
           "clarabel_solve",
           "cost_scale_of", "status_from"]

#: A state counts as visited when its scaled frequency n * sum_a x(s, a) exceeds this, i.e.
#: x(s) > VISIT_TOL / n. Interior-point "zeros" are not tiny: at tol = 1e-9 they were
#: measured at 1e-8 .. 1e-6 in y units on a 5000-state banded random MDP (the central path
#: spreads mu / reduced-cost mass on every pair), and reading argmax x there is noise
#: (16 polishing steps at 1e-7 vs 7 at 1e-5). States below the threshold get the
#: reachability-aware dual-greedy action of :func:`extract_policy`; polishing (policy
#: iteration) then corrects whatever is wrong, so the threshold affects speed, not answers.
VISIT_TOL = 1e-5

#: Clarabel's ``SolverStatus`` (by name) -> code of :mod:`wncs_lp.status`: Clarabel's table, as
#: cvxpy keeps one ``STATUS_MAP`` per solver. ``Solved`` is optimal; ``AlmostSolved`` and the
#: numerical troubles (``NumericalError``, ``InsufficientProgress``) are inaccurate: the point is
#: used, and the certificate computed on it says what it is worth; the limits are ``MAX_ITER``;
#: infeasibility and the rest leave no usable solution (every LP here has a bounded feasible set,
#: so "dual infeasible", i.e. unbounded, is a numerical failure). A status missing here is
#: ``FAILED``, its name kept.
CLARABEL_STATUS: dict[str, Code] = {
    "Solved": OPTIMAL,
    "AlmostSolved": INACCURATE,
    "NumericalError": INACCURATE,
    "InsufficientProgress": INACCURATE,
    "MaxIterations": MAX_ITER,
    "MaxTime": MAX_ITER,
    "CallbackTerminated": INTERRUPTED,
    "PrimalInfeasible": INFEASIBLE,
    "AlmostPrimalInfeasible": INFEASIBLE,
    "DualInfeasible": FAILED,
    "AlmostDualInfeasible": FAILED,
    "Unsolved": FAILED,
}

#: cvxpy's problem status -> code of :mod:`wncs_lp.status` (cvxpy's own words: ``optimal``,
#: ``optimal_inaccurate``, ``user_limit`` for an iteration or time limit, ...; the same rules as
#: :data:`CLARABEL_STATUS`).
CVXPY_STATUS: dict[str, Code] = {
    "optimal": OPTIMAL,
    "optimal_inaccurate": INACCURATE,
    "user_limit": MAX_ITER,
    "infeasible": INFEASIBLE,
    "infeasible_inaccurate": INFEASIBLE,
    "infeasible_or_unbounded": INFEASIBLE,
    "unbounded": FAILED,
    "unbounded_inaccurate": FAILED,
    "solver_error": FAILED,
}

#: Clarabel statuses after which no usable solution exists (``INFEASIBLE`` or ``FAILED`` in
#: :data:`CLARABEL_STATUS`).
FAILED_STATUSES = {w for w, c in CLARABEL_STATUS.items() if c in (INFEASIBLE, FAILED)}


def clarabel_status(native: Any) -> Status:
    """The status of a Clarabel ``SolverStatus`` (:data:`CLARABEL_STATUS`; its name is the reason)."""
    return from_backend(CLARABEL_STATUS, native)


def cvxpy_status(native: Any) -> Status:
    """The status of a cvxpy problem status (:data:`CVXPY_STATUS`; the word is the reason)."""
    return from_backend(CVXPY_STATUS, native)


def backend_status(backend: str, native: Any) -> Status:
    """The status of a backend's own status word, by that backend's table."""
    table = {"clarabel": clarabel_status, "highs": highs_status, "cvxpy": cvxpy_status}
    return table[backend](native)


def usable(status: Status) -> bool:
    """A backend's status after which its point is worth certifying (not infeasible, not failed)."""
    return status.code not in (INFEASIBLE, FAILED)


@dataclass(frozen=True, eq=False)
class LPData:
    """The scaled occupation-measure LP ``min q^T y  s.t.  A_eq y = b_eq, y >= 0``.

    Attributes
    ----------
    A_eq : (n, L) CSC matrix
        Rows 0..n-2: balance rows ``(E - P^T)`` of states 1..n-1 (state 0's row dropped);
        row n-1: the normalisation ``1^T``.
    b_eq : (n,) array
        ``(0, ..., 0, n)``.
    q : (L,) array
        Scaled costs ``c / cost_scale``.
    cost_scale : float
        ``c_s`` = mean |c| (1.0 if that is 0).
    x_scale : float
        ``n``: ``y = x_scale * x``.
    dropped_state : int
        The state whose balance row was dropped (0): its dual bias is 0.
    """

    A_eq: sp.csc_matrix
    b_eq: np.ndarray
    q: np.ndarray
    cost_scale: float
    x_scale: float
    dropped_state: int = 0

    @property
    def n_eq(self) -> int:
        return int(self.A_eq.shape[0])

    @property
    def n_pairs(self) -> int:
        return int(self.A_eq.shape[1])

    def unscale_x(self, y: np.ndarray) -> np.ndarray:
        """x = y / n."""
        return np.asarray(y, dtype=float) / self.x_scale

    def unscale_duals(self, z_eq: np.ndarray) -> tuple[float, np.ndarray]:
        """(g, h) from the equality duals z_eq (Clarabel / cvxpy sign): h = -c_s z_bal, g = -c_s z_norm."""
        z_eq = np.asarray(z_eq, dtype=float)
        n = z_eq.shape[0]
        h = np.zeros(n)
        keep = np.delete(np.arange(n), self.dropped_state)
        h[keep] = -self.cost_scale * z_eq[:-1]
        g = -self.cost_scale * float(z_eq[-1])
        return g, h

    def objective(self, obj_scaled: float) -> float:
        """c^T x = (c_s / n) q^T y."""
        return float(obj_scaled) * self.cost_scale / self.x_scale


def clarabel_stats(sol, info) -> dict:
    """The run statistics of a Clarabel solve (status, iterations, residuals, gaps, time)."""
    return {
        "solver": "clarabel",
        "solver_status": str(sol.status),
        "solver_iterations": int(sol.iterations),
        "r_prim": float(sol.r_prim),
        "r_dual": float(sol.r_dual),
        "duality_gap": float(info.gap_rel),
        "duality_gap_abs": float(info.gap_abs),
        "solve_time": float(sol.solve_time),
    }


def build_lp(mdp: MDP) -> LPData:
    """Assemble the scaled occupation-measure LP (see the module docstring).

    Parameters
    ----------
    mdp : MDP

    Returns
    -------
    LPData
        Sparse CSC ``A_eq`` with nnz = nnz(P) + 2L (minus cancellations from self-loops).
    """
    return _occupation_lp(mdp.s_indices, mdp.P, np.ones(mdp.n_pairs), mdp.cost, mdp.n_states)


def cost_scale_of(cost: np.ndarray) -> float:
    """``c_s`` = mean |c|, or 1 when that is 0, not finite, or there are no costs."""
    cs = float(np.mean(np.abs(cost))) if cost.size else 1.0
    return cs if np.isfinite(cs) and cs > 0 else 1.0


def _occupation_lp(col_state: np.ndarray, T: sp.spmatrix, weights: np.ndarray, cost: np.ndarray, n: int) -> LPData:
    """The scaled LP ``min (c / c_s)^T y`` s.t. rows 1..n-1 of ``(E - T^T) y = 0``,
    ``weights^T y = n``, ``y >= 0``, with ``E[s, l] = [col_state[l] = s]``: the plain LP
    (T = P, weights 1) and the semi-Markov one of the reduction (T = Q, weights the sojourn times)."""
    L = int(col_state.size)
    E = sp.csr_matrix((np.ones(L), (col_state, np.arange(L))), shape=(n, L))
    B = (E - T.T.tocsr()).tocsr()
    A = sp.vstack([B[1:], sp.csr_matrix(np.asarray(weights, float)[None, :])], format="csc")
    A.eliminate_zeros()
    A.sort_indices()
    b = np.zeros(n)
    b[-1] = float(n)
    cs = cost_scale_of(cost)
    return LPData(A_eq=A, b_eq=b, q=np.asarray(cost, float) / cs, cost_scale=cs, x_scale=float(n), dropped_state=0)


#: ``formulation="auto"`` uses the reduced LP when its constraint matrix has at most this
#: fraction of the plain LP's nonzeros. Measured (``benchmarks/lp_backends.py``): the reduced LP
#: was the faster form on every instance where it is not denser than the plain one (wncs
#: models: ratio 0.74-0.97, 1.3-2.7x faster on Clarabel, 1.0-1.4x on HiGHS); the preemption
#: models' elimination densifies Q (ratio 2.7-7.4) and is much slower there.
REDUCE_MAX_NNZ_RATIO = 1.0

#: ``backend="auto"`` runs HiGHS when the LP to be solved has at most
#: ``HIGHS_ROWS_AT_WIDTH_2 * (width / 2) ** HIGHS_WIDTH_EXPONENT`` rows, ``width`` = columns
#: per row (the mean number of actions of a decision state), else Clarabel. Measured
#: (``benchmarks/lp_backends.py``): HiGHS's simplex-based solves grow faster with the size
#: than Clarabel's interior point, but many actions per state hurt Clarabel (its KKT system
#: carries every pair) and not HiGHS (its bases are rows x rows). Processes 1, 2 (width 2):
#: the two cross near 5,000 rows (cap 12); processes 1-3 (width 3.3): HiGHS was still 1.4x
#: faster at 33,000 rows (cap 10).
HIGHS_ROWS_AT_WIDTH_2 = 4_000
HIGHS_WIDTH_EXPONENT = 5.0

#: HiGHS runs its dual simplex on LPs of at most this many columns per row and its interior
#: point (IPX, with crossover) on wider ones, unless ``settings={"variant": ...}`` says which.
#: Measured: the simplex was 1.1-1.5x faster at width 2 (processes 1, 2 and 1, 4), IPX
#: 1.5-2x faster at width 3.3 (processes 1-3) and 5.3 (processes 1-4).
HIGHS_SIMPLEX_MAX_WIDTH = 2.5

#: The LP backends of :func:`solve_lp`.
BACKENDS = ("auto", "clarabel", "highs", "cvxpy")
_BACKEND_NAMES = {"clarabel": "Clarabel", "highs": "HiGHS", "cvxpy": "cvxpy and Clarabel"}


@dataclass(frozen=True, eq=False)
class LPChoice:
    """What :func:`choose_lp` picked and why.

    Attributes
    ----------
    backend : {"clarabel", "highs", "cvxpy"}
    formulation : {"primal", "reduced", "dual"}
    rule : str
        A short name of the rule that fired (``"asked"``, ``"settings"``, ``"dual"``,
        ``"highs-width"``, ``"clarabel-size"``, ...), for tests and tables.
    reason : str
        The same in words, with the numbers it compared.
    reduction, reduced_lp
        The forced-state reduction and its LP when they were built (else None).
    highs_variant : {"simplex", "ipx"} or None
        With HiGHS and no ``settings["variant"]``: the simplex up to
        :data:`HIGHS_SIMPLEX_MAX_WIDTH` columns per row, else IPX.
    """

    backend: str
    formulation: str
    rule: str
    reason: str
    reduction: Any = None
    reduced_lp: Any = None
    highs_variant: str | None = None


def highs_max_rows(width: float) -> float:
    """The largest LP (rows) that ``backend="auto"`` hands to HiGHS at ``width`` columns per row:
    ``HIGHS_ROWS_AT_WIDTH_2 * (width / 2) ** HIGHS_WIDTH_EXPONENT``."""
    return HIGHS_ROWS_AT_WIDTH_2 * (max(float(width), 1.0) / 2.0) ** HIGHS_WIDTH_EXPONENT


def choose_lp(mdp: MDP, backend: str = "auto", formulation: str = "auto", settings: dict | None = None) -> LPChoice:
    """The backend and formulation :func:`solve_lp` runs (the measured rules of ``"auto"``).

    Formulation (``formulation="auto"``): ``"reduced"`` when the forced-state reduction
    eliminates some state and its constraint matrix has at most :data:`REDUCE_MAX_NNZ_RATIO`
    times the plain LP's nonzeros (``nnz = nnz(P) + 2 L``), else ``"primal"``. The dual
    (gain-bias) LP is never chosen automatically (measured no faster).

    Backend (``backend="auto"``), on the LP of that formulation with ``m`` rows and ``k``
    columns (width ``w = k / m``):

    * ``settings`` given, or the dual formulation: Clarabel (the settings are Clarabel's; the
      dual LP is built for Clarabel only);
    * ``m <= highs_max_rows(w)``: HiGHS (small, or many actions per state);
    * else Clarabel (large LPs with few actions per state, where its interior point scales best).

    Parameters
    ----------
    mdp : MDP
    backend : {"auto", "clarabel", "highs", "cvxpy"}
    formulation : {"auto", "primal", "reduced", "dual"}
    settings : dict, optional
        The caller's solver settings (their presence keeps ``"auto"`` on Clarabel).

    Returns
    -------
    LPChoice
    """
    red = lp_r = None
    words = []
    form = formulation
    if form in ("auto", "reduced"):
        lp_r, red = build_reduced_lp(mdp)
        if form == "auto":
            plain_nnz = mdp.P.nnz + 2 * mdp.n_pairs
            ratio = lp_r.A_eq.nnz / max(plain_nnz, 1)
            if red.n_eliminated and ratio <= REDUCE_MAX_NNZ_RATIO:
                form = "reduced"
                words.append(f"reduced LP: eliminating {red.n_eliminated:,} forced states leaves "
                             f"{ratio:.3f} of the plain LP's nonzeros (<= {REDUCE_MAX_NNZ_RATIO})")
            else:
                why = ("no forced state on an acyclic forced path" if not red.n_eliminated else
                       f"the reduced LP would have {ratio:.3f} x the plain LP's nonzeros (> {REDUCE_MAX_NNZ_RATIO})")
                form, red, lp_r = "primal", None, None
                words.append(f"primal LP: {why}")
        else:
            words.append("reduced LP: asked for")
    else:
        words.append(f"{form} LP: asked for")
    if form == "primal":
        m, k = mdp.n_states, mdp.n_pairs
    elif form == "reduced":
        m, k = lp_r.n_eq, lp_r.n_pairs
    else:
        m, k = mdp.n_pairs, mdp.n_states
    if backend != "auto":
        rule = "asked"
        words.append(f"backend {backend}: asked for")
    elif settings:
        backend, rule = "clarabel", "settings"
        words.append("Clarabel: solver settings were given (they are Clarabel's)")
    elif form == "dual":
        backend, rule = "clarabel", "dual"
        words.append("Clarabel: the dual LP is built for Clarabel only")
    else:
        w = k / max(m, 1)
        cap = highs_max_rows(w)
        if m <= cap:
            backend, rule = "highs", "highs-width"
            words.append(f"HiGHS: {m:,} rows <= {cap:,.0f}, the measured crossover at {w:.2f} columns per row")
        else:
            backend, rule = "clarabel", "clarabel-size"
            words.append(f"Clarabel: {m:,} rows > {cap:,.0f}, the measured crossover at {w:.2f} columns per row")
    variant = None
    if backend == "highs" and "variant" not in (settings or {}):
        w = k / max(m, 1)
        variant = "simplex" if w <= HIGHS_SIMPLEX_MAX_WIDTH else "ipx"
        words.append(f"HiGHS {variant}: {w:.2f} columns per row {'<=' if variant == 'simplex' else '>'} "
                     f"{HIGHS_SIMPLEX_MAX_WIDTH}")
    return LPChoice(backend, form, rule, "; ".join(words), red, lp_r, variant)

#: Clarabel settings :func:`solve_lp` uses with the direct backend unless ``settings``
#: overrides them. Iterative refinement off: on the paper's models it saved ~30% of the IPM
#: time at the same raw LP gain (``benchmarks/run.py``); the occupation measure's balance
#: residual grows 5-50x, and the answer is checked anyway (KKT residuals on the original LP,
#: certificate, polishing).
CLARABEL_DEFAULTS: dict[str, Any] = {"iterative_refinement_enable": False}

#: ``polish=True`` means ``"vi"`` from this many states on and ``"pi"`` below: on large
#: models a few certified value-iteration sweeps from the LP's dual bias reach the optimal
#: policy more cheaply than repeated exact (sparse LU) evaluations (p12 at cap 20:
#: 0.7 s vs 3.5 s of polishing).
POLISH_VI_MIN_STATES = 20_000
FORMULATIONS = ("auto", "primal", "reduced", "dual")


def build_reduced_lp(mdp: MDP, red=None):
    """The occupation-measure LP of the forced-state reduction (:mod:`~wncs_lp.solvers.reduce`).

    Variables y = nD * x over the decision pairs; rows: balance of the decision states 1..nD-1
    (state D[0]'s row dropped), ``(E_D - Q^T) y = 0``, and the normalisation ``T^T y = nD``
    (time, not visits, sums to one; T = the sojourn times); costs ``C / c_s``. Returns ``(LPData, Reduction)``.
    """
    from .reduce import reduce_forced

    red = reduce_forced(mdp) if red is None else red
    dloc = np.searchsorted(red.D, mdp.s_indices[red.dpairs])
    return _occupation_lp(dloc, red.Q, red.sojourn, red.C, red.n_decision), red


def clarabel_settings(tol: float, max_iter: int, verbose: bool, settings: dict | None):
    """Clarabel settings: our tolerance on gap and feasibility, then the caller's overrides."""
    import clarabel

    st = clarabel.DefaultSettings()
    st.verbose = bool(verbose)
    st.max_iter = int(max_iter)
    st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = float(tol)
    for k, v in (settings or {}).items():
        if not hasattr(st, k):
            raise SolverError(f"unknown Clarabel setting {k!r}")
        setattr(st, k, v)
    return st


def clarabel_solve(solver, prog: Progress | None = None, what: str = "lp"):
    """``solver.solve()`` of a Clarabel solver, stoppable, its iterations reported through ``prog``.

    Clarabel calls a termination callback at every interior-point iteration: it shows the
    iteration (rate-limited) and ends the solve when a stop is asked. One iteration of a large
    LP factorizes the whole KKT system (about 10 s for processes 1-3 at cap 10, longer above),
    and nothing of Python runs in the thread that waits for it; so the solve runs in a thread
    this one waits on (:func:`wncs_lp.stopping.in_thread`: Clarabel releases the GIL), and a
    Ctrl-C / SIGTERM returns control at once. The solve left behind is ended by its callback
    at its next iteration instead of running on.
    """
    import threading

    from ..stopping import in_thread, stop_asked

    abandoned = threading.Event()

    def callback(info) -> bool:
        try:
            if abandoned.is_set():
                return True
            if prog is not None and prog.enabled and prog.due():
                prog.tick(f"[{what}] interior-point iteration {info.iterations}: relative gap {info.gap_rel:.1e}, "
                          f"residuals {info.res_primal:.1e} (primal) {info.res_dual:.1e} (dual)")
            return stop_asked()
        except BaseException:  # noqa: BLE001 - nothing may be raised into the backend: stop instead
            return True

    try:
        solver.set_termination_callback(callback)
    except AttributeError:  # an older Clarabel without callbacks
        return in_thread(solver.solve)
    try:
        return in_thread(solver.solve)
    except BaseException:
        abandoned.set()
        raise


def _solve_clarabel_dual(mdp: MDP, tol: float, max_iter: int, verbose: bool, settings: dict | None,
                         prog: Progress | None = None):
    """The gain-bias LP  max g  s.t.  g + h(s_l) - (P h)_l <= c_l,  h(0) = 0, on Clarabel.

    Variables (u, h_1..h_{n-1}) = (g, h) / c_s; objective -n u, so that the multipliers z of
    the L inequality rows are the occupation measure scaled to sum n (z = n x).
    """
    import clarabel

    n, L = mdp.n_states, mdp.n_pairs
    cs = cost_scale_of(mdp.cost)
    E = sp.csr_matrix((np.ones(L), (np.arange(L), mdp.s_indices)), shape=(L, n))
    B = (E - mdp.P).tocsc()[:, 1:]
    A = sp.hstack([sp.csc_matrix(np.ones((L, 1))), B], format="csc")
    A.eliminate_zeros()
    objective = np.zeros(n)
    objective[0] = -float(n)
    status, u, z, stats = _run_clarabel(sp.csc_matrix((n, n)), objective, A, mdp.cost / cs, [clarabel.NonnegativeConeT(L)],
                                        clarabel_settings(tol, max_iter, verbose, settings), prog)
    g = cs * float(u[0]) if u.size else np.nan
    h = np.zeros(n)
    h[1:] = cs * u[1:]
    for key in ("obj_scaled", "obj_dual_scaled"):  # the objective of this LP is -n g / c_s: g is reported instead
        stats.pop(key)
    stats.update(lp_rows=int(L), lp_cols=int(n), cost_scale=cs, lp_nnz=int(A.nnz))
    return status, z / float(n), g, h, stats


def _full_residuals(mdp: MDP, x: np.ndarray, g: float, h: np.ndarray) -> dict[str, float]:
    """Accuracy of (x, g, h) on the *original* LP, whatever formulation produced them.

    ``full_balance_residual`` = n * max_s |sum_{l in s} x_l - (P^T x)_s| (in the y = n x
    units of the plain LP), ``full_norm_residual`` = |sum x - 1|, ``full_dual_violation`` =
    max(0, -min_l (c_l + (P h)_l - h(s_l) - g)) / max|c|, ``full_gap_rel`` = |c^T x - g| / |g|.
    """
    n = mdp.n_states
    inflow = np.asarray(mdp.P.T @ x).ravel()
    out = np.bincount(mdp.s_indices, weights=x, minlength=n)
    red = mdp.cost + mdp.P @ h - h[mdp.s_indices] - g
    cmax = max(float(np.max(np.abs(mdp.cost))), 1e-300)
    cx = float(mdp.cost @ x)
    return {
        "full_balance_residual": float(n * np.max(np.abs(out - inflow))),
        "full_norm_residual": float(abs(x.sum() - 1.0)),
        "full_dual_violation": float(max(0.0, -float(red.min())) / cmax),
        "full_gap_rel": float(abs(cx - g) / max(abs(g), 1e-300)),
    }


def extract_policy(mdp: MDP, x: np.ndarray, h: np.ndarray, visit_tol: float = VISIT_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic policy read off an occupation measure.

    * Visited states (``n * sum_a x(s, a) > visit_tol``): the pair of largest x (ties to
      the first pair).
    * Unvisited states, in breadth-first layers backwards from the visited set: a state
      gets, among its pairs with positive probability of moving into the already assigned
      set, the one minimising ``Q_h = c + P h`` for the dual bias h (first on ties). This
      makes every unvisited state drain into the visited set, so the policy stays unichain
      when the visited part is (an interior-point dual keeps slack on such states, so
      plain greedy-for-h could pick a self-loop that creates a second recurrent class).
    * States that cannot reach the visited set (only in multichain MDPs): greedy for h.

    Returns
    -------
    policy : (n,) int64 pair indices
    visited : (n,) bool
    """
    starts = mdp.pair_ptr[:-1]
    L, n = mdp.n_pairs, mdp.n_states
    xc = np.maximum(np.asarray(x, float), 0.0)
    freq = np.add.reduceat(xc, starts) * n
    visited = freq > visit_tol
    xmax = np.maximum.reduceat(xc, starts)
    cand = np.where(xc == xmax[mdp.s_indices], np.arange(L, dtype=np.int64), np.int64(L))
    by_x = np.minimum.reduceat(cand, starts)
    q_h = q_values(mdp, h)
    policy = np.where(visited, by_x, greedy_first(mdp, q_h))
    assigned = visited.copy()
    if assigned.any():
        idx = np.arange(L, dtype=np.int64)
        while not assigned.all():
            into = (mdp.P @ assigned.astype(float)) > 0
            ok = into & ~assigned[mdp.s_indices]
            if not ok.any():
                break
            qm = np.where(ok, q_h, np.inf)
            best = np.minimum.reduceat(qm, starts)
            new = np.isfinite(best)
            pick = np.minimum.reduceat(np.where(ok & (qm == best[mdp.s_indices]), idx, np.int64(L)), starts)
            policy[new] = pick[new]
            assigned |= new
    return policy, visited


def _kkt(lp: LPData, y: np.ndarray, z_eq: np.ndarray) -> dict[str, float]:
    """Our own KKT numbers in the scaled problem (independent of the solver's report)."""
    r_p = float(np.max(np.abs(lp.A_eq @ y - lp.b_eq))) / (1.0 + float(np.max(np.abs(lp.b_eq))))
    red = lp.q + lp.A_eq.T @ z_eq  # reduced costs mu, must be >= 0
    r_d = float(max(0.0, -float(red.min()))) / (1.0 + float(np.max(np.abs(lp.q))))
    pobj, dobj = float(lp.q @ y), float(-lp.b_eq @ z_eq)
    gap = abs(pobj - dobj) / (1.0 + abs(pobj))
    return {"kkt_primal_residual": r_p, "kkt_dual_residual": r_d, "kkt_gap_rel": gap,
            "negative_y": float(max(0.0, -float(y.min())))}


def _solve_clarabel(lp: LPData, tol: float, max_iter: int, verbose: bool, settings: dict | None,
                    prog: Progress | None = None):
    import clarabel

    L, m = lp.n_pairs, lp.n_eq
    A = sp.vstack([lp.A_eq, -sp.identity(L, format="csc")], format="csc")
    b = np.concatenate([lp.b_eq, np.zeros(L)])
    Pz = sp.csc_matrix((L, L))
    status, y, z, stats = _run_clarabel(Pz, lp.q, A, b, [clarabel.ZeroConeT(m), clarabel.NonnegativeConeT(L)],
                                        clarabel_settings(tol, max_iter, verbose, settings), prog)
    stats.update(lp_rows=int(m), lp_cols=int(L), lp_nnz=int(lp.A_eq.nnz))
    return status, y, z[:m], stats


def _run_clarabel(P, c, A, b, cones, settings, prog: Progress | None):
    """One Clarabel solve: ``(status, x, z, stats)``, the status mapped by :data:`CLARABEL_STATUS`,
    with :func:`clarabel_stats` (the native word as ``solver_status``) and the scaled primal and
    dual objectives."""
    import clarabel

    solver = clarabel.DefaultSolver(P, c, A, b, cones, settings)
    sol = clarabel_solve(solver, prog)
    stats = {**clarabel_stats(sol, solver.get_info()), "obj_scaled": float(sol.obj_val),
             "obj_dual_scaled": float(sol.obj_val_dual)}
    return clarabel_status(sol.status), np.asarray(sol.x, float), np.asarray(sol.z, float), stats


def _solve_cvxpy(lp: LPData, tol: float, max_iter: int, verbose: bool, settings: dict | None,
                 prog: Progress | None = None):
    import cvxpy as cp

    from ..stopping import in_thread

    L = lp.n_pairs
    y = cp.Variable(L, nonneg=True)
    eq = lp.A_eq @ y == lp.b_eq
    prob = cp.Problem(cp.Minimize(lp.q @ y), [eq])
    opts: dict[str, Any] = {"tol_gap_abs": float(tol), "tol_gap_rel": float(tol), "tol_feas": float(tol),
                            "max_iter": int(max_iter)}
    opts.update(settings or {})
    try:
        with warnings.catch_warnings():  # "Solution may be inaccurate": reported via our status instead
            warnings.simplefilter("ignore", UserWarning)
            # cvxpy offers no hook into Clarabel's iterations: a thread this one waits on, so a
            # Ctrl-C / SIGTERM returns at once (the abandoned solve ends with the process)
            in_thread(lambda: prob.solve(solver=cp.CLARABEL, verbose=bool(verbose), **opts))
    except cp.error.SolverError as exc:
        raise SolverError(f"cvxpy/Clarabel failed: {exc}") from exc
    native = str(prob.status)
    status = cvxpy_status(native)
    if y.value is None or eq.dual_value is None:
        raise SolverError(f"cvxpy/Clarabel returned no solution (status {native})")
    yv = np.asarray(y.value, float)
    zv = np.asarray(eq.dual_value, float).ravel()
    ss = prob.solver_stats
    k = _kkt(lp, yv, zv)
    stats = {
        "solver": "cvxpy+clarabel",
        "solver_status": native,
        "solver_iterations": int(ss.num_iters or 0),
        "r_prim": k["kkt_primal_residual"],
        "r_dual": k["kkt_dual_residual"],
        "duality_gap": k["kkt_gap_rel"],
        "solve_time": float(ss.solve_time or 0.0),
        "obj_scaled": float(prob.value),
    }
    return status, yv, zv, stats


def solve_lp(mdp: MDP, *, backend: str = "auto", tol: float = 1e-9, polish: bool = True, max_iter: int = 200,
             verbose: bool = False, cert_rtol: float = 1e-6, visit_tol: float = VISIT_TOL, polish_max_iter: int = 50,
             settings: dict | None = None, formulation: str = "auto", progress: bool | Progress = False) -> Solution:
    """Solve the occupation-measure LP and certify the answer.

    Phases: choose the backend and formulation (:func:`choose_lp`) -> run it on the scaled LP ->
    unscale x and the dual (g, h) (lifted to every state from a reduced LP) -> read a policy off x
    (:func:`extract_policy`) -> polish (module docstring, "Polish") -> certify.

    Parameters
    ----------
    mdp : MDP
    backend : {"auto", "clarabel", "highs", "cvxpy"}
        ``"auto"``: :func:`choose_lp`'s measured rule (``stats["lp_choice"]`` says why).
    tol : float
        Clarabel ``tol_gap_abs = tol_gap_rel = tol_feas`` (on the scaled problem); HiGHS's primal
        and dual feasibility tolerances (at least 1e-10) and IPM optimality tolerance.
    polish : bool or {"pi", "vi"}
        True = "vi" from :data:`POLISH_VI_MIN_STATES` states on, else "pi".
    max_iter, polish_max_iter : int
        The interior-point iteration limit (Clarabel's, HiGHS IPX's); the most policy-iteration
        evaluations of the polish.
    verbose : bool
        Solver log to stdout.
    cert_rtol : float
        ``status`` is optimal only when the backend's own status is (Clarabel's ``Solved``, HiGHS's
        ``kOptimal``, cvxpy's ``optimal``) and the certificate closed: (hi - lo)/|g| <= cert_rtol.
    visit_tol : float
        Visited-state threshold on n * x(s), see :data:`VISIT_TOL`.
    settings : dict, optional
        Clarabel settings by ``DefaultSettings`` name, over :data:`CLARABEL_DEFAULTS` (iterative
        refinement off; ``{"iterative_refinement_enable": True}`` restores Clarabel's default);
        with ``backend="highs"``: HiGHS options by name plus ``"variant"`` (``"simplex"`` or
        ``"ipx"``). Given with ``backend="auto"``, they keep it on Clarabel.
    formulation : {"auto", "primal", "reduced", "dual"}
        The LP solved (module docstring, "Formulations"; :func:`build_lp`,
        :func:`build_reduced_lp`; the dual on Clarabel only); ``stats["formulation"]`` says which.
    progress : bool or Progress
        The phases, Clarabel's interior-point iterations (direct backend) and the polish on
        stderr (:mod:`wncs_lp.progress`).

    Returns
    -------
    Solution
        ``method`` ``"lp"`` (Clarabel), ``"lp-highs"`` or ``"lp-cvxpy"``; ``occupation`` = x
        (clipped at 0, renormalised to sum 1). ``stats``: the solver's (``solver_status``,
        ``solver_iterations``, ``r_prim``, ``r_dual``, ``duality_gap``, ``solve_time``,
        ``highs_*``), ``lp_objective`` (c^T x, unscaled, not polished), ``lp_dual_gain``,
        ``kkt_*`` (our residuals on the LP solved), ``full_*`` (on the original LP,
        :func:`_full_residuals`), ``formulation``, ``lp_rows`` / ``lp_cols`` / ``lp_nnz``,
        ``reduction_*``, ``backend``, ``lp_choice`` / ``lp_choice_rule`` (:class:`LPChoice`),
        ``n_visited_states``, ``polish_*``, ``dual_bias``, ``extracted_policy``, ``cost_scale``.
        ``status`` (:func:`~wncs_lp.status.status_from`, in this precedence): the backend's own
        status when it did not succeed, mapped by its table (:data:`CLARABEL_STATUS`,
        :data:`~wncs_lp.solvers.highs.HIGHS_STATUS`, :data:`CVXPY_STATUS`) with its word as the
        reason (``"max_iter:MaxIterations"``, ``"max_iter:kTimeLimit"``,
        ``"inaccurate:AlmostSolved"``); ``"inaccurate:polish_max_iter"`` (or another
        ``polish_*``); ``"inaccurate:certificate"`` (bracket wider than cert_rtol); else
        ``"optimal"``.

    Raises
    ------
    SolverError
        Bad arguments, or the solver failed outright (infeasible or unsolved, non-finite x).
    """
    t0 = time.perf_counter()
    polish = _checked_lp_args(mdp, backend, formulation, polish)
    prog = as_progress(progress)
    prog.phase(f"[lp] building the occupation-measure LP ({mdp.n_pairs:,} pairs, {mdp.n_states:,} states)")
    choice = choose_lp(mdp, backend, formulation, settings=settings)
    backend = choice.backend
    method = _METHODS[backend]
    if backend == "clarabel":
        settings = {**CLARABEL_DEFAULTS, **(settings or {})}
    status, x, g_dual, h_dual, lp_obj, stats = _run_backend(mdp, choice, method, tol, max_iter, verbose,
                                                                      settings, prog)
    stats.update(formulation=choice.formulation, backend=backend, lp_choice=choice.reason,
                 lp_choice_rule=choice.rule, polish=polish or None)
    if backend == "clarabel":
        stats["clarabel_settings"] = dict(settings)
    h_dual, policy0 = _extract(mdp, x, g_dual, h_dual, lp_obj, visit_tol, stats, t0)
    prog.done(f"[{method}] solver status {stats['solver_status']} after {stats['solver_iterations']} "
              f"{'interior-point' if backend != 'highs' else 'interior-point + simplex'} iterations")
    gain, lo, hi, bias, policy, issue = _polish(mdp, polish, policy0, h_dual, lp_obj, polish_max_iter, cert_rtol,
                                                stats, prog, method)
    closed = certificate_closed(mdp, lo, hi, gain, cert_rtol)
    stats.update(certificate_closed=bool(closed), lp_error=lp_obj - gain)
    occ = np.maximum(x, 0.0)
    occ = occ / occ.sum() if occ.sum() > 0 else occ
    return Solution(method=method, status=status_from((status, issue, None if closed else CERTIFICATE)),
                    gain=float(gain), gain_lower=float(lo), gain_upper=float(hi), bias=np.asarray(bias, float),
                    policy=np.asarray(policy, np.int64), occupation=occ, iterations=int(stats["solver_iterations"]),
                    seconds=time.perf_counter() - t0, stats=stats, pair_actions=mdp.a_indices)


def _extract(mdp: MDP, x: np.ndarray, g_dual: float, h_dual: np.ndarray, lp_obj: float, visit_tol: float,
             stats: dict, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """The residuals of (x, g, h) on the original LP, the dual bias pinned to h(0) = 0 and the
    deterministic policy read off x, recorded in ``stats``; returns ``(h, policy)``."""
    stats.update(_full_residuals(mdp, x, g_dual, h_dual))
    h_dual = h_dual - h_dual[0]
    policy0, visited = extract_policy(mdp, x, h_dual, visit_tol)
    stats.update(lp_objective=lp_obj, lp_dual_gain=g_dual, n_visited_states=int(np.count_nonzero(visited)),
                 dual_bias=h_dual, extracted_policy=policy0, lp_seconds=time.perf_counter() - t0)
    return h_dual, policy0


#: The method name of a solution by the backend that solved its LP.
_METHODS = {"clarabel": "lp", "highs": "lp-highs", "cvxpy": "lp-cvxpy"}


def _checked_lp_args(mdp: MDP, backend: str, formulation: str, polish: bool | str) -> str | bool:
    """The polish mode (True resolved by the model's size), after checking the arguments."""
    if backend not in BACKENDS:
        raise SolverError(f"unknown LP backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if formulation not in FORMULATIONS:
        raise SolverError(f"unknown LP formulation {formulation!r}; expected one of {', '.join(FORMULATIONS)}")
    if polish is True:
        polish = "vi" if mdp.n_states >= POLISH_VI_MIN_STATES else "pi"
    if polish not in (False, "pi", "vi"):
        raise SolverError(f"polish must be True, False, 'pi' or 'vi'; got {polish!r}")
    if formulation == "dual" and backend not in ("clarabel", "auto"):
        raise SolverError("the dual (gain-bias) formulation is solved with backend 'clarabel' only")
    return polish


def _unusable(method: str, stats: dict) -> SolverError:
    return SolverError(f"{method}: solver failed with status {stats.get('solver_status')} (r_prim={stats.get('r_prim')}, "
                       f"r_dual={stats.get('r_dual')}, iterations={stats.get('solver_iterations')}); no usable solution")


def _run_backend(mdp: MDP, choice: LPChoice, method: str, tol: float, max_iter: int, verbose: bool,
                 settings: dict | None, prog: Progress):
    """Solve the chosen LP and unscale it: ``(status, x, g, h, lp objective, stats)`` with x
    the occupation measure and (g, h) the dual gain and bias, lifted back to every state when reduced."""
    backend, form = choice.backend, choice.formulation
    if form == "dual":
        prog.phase(f"[{method}] solving the gain-bias (dual) LP with Clarabel")
        status, x, g_dual, h_dual, stats = _solve_clarabel_dual(mdp, tol, max_iter, verbose, settings, prog)
        if not usable(status) or not (np.all(np.isfinite(x)) and np.isfinite(g_dual) and np.all(np.isfinite(h_dual))):
            raise _unusable(method, stats)
        return status, x, g_dual, h_dual, g_dual, stats
    lp = choice.reduced_lp if form == "reduced" else build_lp(mdp)
    prog.phase(f"[{method}] solving the {form} LP ({lp.n_eq:,} rows, {lp.n_pairs:,} columns) with "
               f"{_BACKEND_NAMES[backend]}")
    if backend == "highs":
        hs = settings if choice.highs_variant is None else {**(settings or {}), "variant": choice.highs_variant}
        status, y, z_eq, stats = solve_highs(lp.A_eq, lp.b_eq, lp.q, tol, max_iter, verbose, hs, prog)
    else:
        runner = _solve_clarabel if backend == "clarabel" else _solve_cvxpy
        status, y, z_eq, stats = runner(lp, tol, max_iter, verbose, settings, prog)
    if not usable(status) or not (np.all(np.isfinite(y)) and np.all(np.isfinite(z_eq))) or y.shape != (lp.n_pairs,):
        raise _unusable(method, stats)
    stats.update(_kkt(lp, y, z_eq))
    g_dual, h_dual = lp.unscale_duals(z_eq)
    lp_obj = lp.objective(stats["obj_scaled"])
    x = lp.unscale_x(y)
    stats["cost_scale"] = lp.cost_scale
    red = choice.reduction
    if red is not None:
        x = red.lift_x(x)
        h_dual = red.lift_h(h_dual, g_dual)
        stats.update(reduction_decision_states=red.n_decision, reduction_eliminated=red.n_eliminated,
                     reduction_levels=int(red.level_ptr.size - 1), reduction_seconds=red.seconds)
    return status, x, g_dual, h_dual, lp_obj, stats


def _polish(mdp: MDP, polish: str | bool, policy0: np.ndarray, h_dual: np.ndarray, lp_obj: float,
            polish_max_iter: int, cert_rtol: float, stats: dict, prog: Progress, method: str):
    """The final ``(gain, lo, hi, bias, policy, issue)``: policy iteration from the LP's policy
    (after value iteration from its dual bias for ``"vi"``), or the LP's own answer with the
    bracket of its dual bias (no polish, or a multichain iterate)."""
    if polish:
        prog.phase(f"[{method}] polishing the LP's policy ({'value iteration, then ' if polish == 'vi' else ''}"
                   "policy iteration with exact evaluation)")
        try:
            start = policy0
            if polish == "vi":
                from .dp import value_iteration

                vi = value_iteration(mdp, h0=h_dual, progress=prog)
                stats["polish_vi_sweeps"] = vi.iterations
                start = vi.policy
            pi = policy_iteration(mdp, policy0=start, max_iter=polish_max_iter, cert_rtol=cert_rtol, progress=prog)
        except PolicyError as exc:
            stats["polish_error"] = str(exc)
        else:
            stats["polish_iterations"] = int(sum(1 for c in pi.stats["changes"] if c))
            stats["polish_changed_states"] = int(np.count_nonzero(pi.policy != policy0))
            if pi.stats.get("fallback"):
                # a multichain iterate: policy iteration went through value iteration
                stats["polish_fallback"] = pi.stats["fallback"]
            issue = None
            if pi.stats.get("multichain_policy"):
                if not pi.ok:
                    issue = polish_reason(pi.status)
            elif not pi.stats["stable"]:
                issue = POLISH_MAX_ITER
            return pi.gain, pi.gain_lower, pi.gain_upper, pi.bias, pi.policy, issue
    lo, hi = bracket(mdp, h_dual)
    policy = policy0 if not polish else greedy_first(mdp, q_values(mdp, h_dual))
    return lp_obj, lo, hi, h_dual, policy, None

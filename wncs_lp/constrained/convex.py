r"""Convex programs over the occupation measure, written with cvxpy and solved by Clarabel.

The occupation measure :math:`x_l = x(s_l, a_l)` of a stationary policy (the long-run
frequency of pair l) ranges over the polytope

.. math::

    \mathcal X = \{x \ge 0 :\; \textstyle\sum_{l:\, s_l = s'} x_l = \sum_l P(s' \mid l)\, x_l
    \;(s' = 0..n-1),\; \sum_l x_l = 1\},

and every long-run average per slot is linear in it: :math:`\bar d = \sum_l d_l x_l`. So any
convex objective or constraint in x (a DCP expression) can be optimised over
:math:`\mathcal X` (``docs/constraints.md``, section 7). :class:`OccupationProgram` exposes
the variable, the balance constraints and the quantities of section 1 as cvxpy expressions:

>>> prog = OccupationProgram(mdp)                                        # doctest: +SKIP
>>> mse = [prog.process_cost(k) for k in range(2)]                       # doctest: +SKIP
>>> fair = prog.solve(cp.Minimize(cp.maximum(*mse)))                     # doctest: +SKIP

and turns the solver's x into the same randomised policy and :class:`ConstrainedSolution`
as the LP routes (:func:`~wncs_lp.constrained.certify.policy_from_occupation`, exact
evaluation of the policy's own Markov chain).

Scaling. The solver sees :math:`y = n x` (as :func:`wncs_lp.solvers.lp.build_lp` does:
``sum y = n``, a uniformly visited state has y = O(1)); the user-facing expressions
(``prog.x``, ``prog.cost()``, ...) are in x units, ``prog.x = prog.y / n``.

What the result means for a convex program (``method="convex"``)
------------------------------------------------------------------
``gain``, ``gain_lower`` and ``gain_upper`` are about the **program's objective** f (not the
MDP's cost, unless f is the cost; the policy's exact average cost is ``stats["cost_exact"]``):

* ``gain`` = ``stats["objective_exact"]`` = f at the exact occupation measure of the returned
  policy (its own chain, not the solver's x). f is evaluated directly when it depends on x
  only; when it also has auxiliary variables of the user's (an epigraph ``t``) they are
  re-optimised with x fixed at that measure (``stats["objective_exact_method"]``).
* Linear programs (f and every user constraint affine in x): the certificate of the LP routes,
  :func:`~wncs_lp.constrained.certify.certify` with f's coefficients as the cost: ``gain_lower``
  = the Lagrangian bound :math:`\underline g_\lambda - \lambda^T b \le f^*` (certified value
  iteration for the cost :math:`f + \lambda^T D`, multipliers = the solver's duals; weak
  duality, whatever the solver did), ``gain_upper`` = the exact f of the returned policy.
  ``stats["certificate"] = "lagrangian"``. A basic optimal solution is looked for first
  (``crossover``, HiGHS dual simplex on the pairs the interior point leaves in play), so the
  policy randomises in at most as many states as there are active bounds.
* Nonlinear programs, first choice: a rigorous bound from a subgradient s of f at the returned
  policy's exact measure :math:`\hat x` (f convex, constraints affine):
  :math:`f^* \ge f(\hat x) - s^T \hat x + L_s(\lambda)`, with :math:`L_s` the Lagrangian bound
  of the linear cost s (certified value iteration). It is used when it closes to ``cert_rtol``
  (``stats["certificate"] = "subgradient"``; always in ``stats["subgradient_bound"]``). It can be
  loose where f is not differentiable at :math:`\hat x` (a max with tied arguments).
* Nonlinear programs otherwise: the certificate is the exact evaluation of the returned policy,
  with the solver's duality gap beside it: for ``Minimize``, ``gain_upper`` = exact f of the policy
  (an upper bound on f* when the policy meets the constraints) and ``gain_lower`` = Clarabel's
  dual objective mapped to f's units (``stats["solver_dual_objective"]``). That lower end is
  *the solver's claim*: it bounds f* from below only up to the solver's dual residual
  (``stats["r_dual"]``), nothing here re-checks it, and it can exceed the upper end by about
  the solver's tolerance. For ``Maximize`` the roles swap (lower = exact f of the policy,
  upper = the dual objective). ``stats["certificate"] = "solver_dual"``.

``status`` is ``"optimal"`` when the solver reports optimal, the returned policy meets every
constraint (exactly evaluated, within ``feas_rtol``) and ``gain_upper - gain_lower <=
cert_rtol * |gain|``; otherwise ``"inaccurate:<why>"``.

Constraint reports (nonlinear programs): each user constraint ``lhs <= rhs`` / ``lhs == rhs``
is reported as ``expr = lhs - rhs`` with ``value = max(expr)`` (``max |expr|`` for an equality;
the cvxpy violation for other cones) under the returned policy, bound ``max = 0``, and
``multiplier`` = the largest |dual value|. Linear programs get the reports of
:func:`certify` (one per scalar row, value = the long-run average, the bound, lambda).

An interior-point method returns a point in the *relative interior* of the optimal face: where
several policies are optimal it mixes them all. Min-max fairness is an example: on the paper's
models process 1's MSE dominates, every policy minimising it is min-max optimal whatever it
does to process 2, and Clarabel's answer can be a poor one among them. Solve the
lexicographic refinement (minimise the cost subject to every ``process_cost(k) <= f*``, a
linear program, so with crossover) to pick the best of them (``examples/05_fairness_minmax.py``).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from ..chain import PolicyChain
from ..errors import InfeasibleConstraintsError, ModelError, SolverError
from ..mdp import MDP
from ..scenario import ConstraintSpec
from ..solvers.lp import cvxpy_status
from ..status import CERTIFICATE, INFEASIBLE_POLICY, OBJECTIVE_NOT_EVALUATED, status_from
from .certify import CERT_RTOL, FEAS_RTOL, certify, evaluate_rows, lagrangian_bound, policy_from_occupation
from .lp import basic_solution
from .problem import LinearConstraint, max_form, with_cost
from .result import ConstrainedSolution, ConstraintReport

__all__ = ["OccupationProgram", "MAX_LINEAR_ROWS"]

#: A program whose user constraints have more scalar rows than this is certified as nonlinear.
MAX_LINEAR_ROWS = 1000

_INFEASIBLE = ("infeasible", "infeasible_inaccurate")
_UNBOUNDED = ("unbounded", "unbounded_inaccurate")


class OccupationProgram:
    r"""cvxpy building blocks over the occupation measure of an MDP, and their solve.

    Parameters
    ----------
    mdp : MDP
        Any MDP for :meth:`cost`, :meth:`average` and :meth:`solve`; :meth:`process_cost`,
        :meth:`aoi` and :meth:`send_rate` need one built by :func:`wncs_lp.build` (decoded
        AoI states and actions; names come from its scenario).

    Attributes
    ----------
    mdp : MDP
    y : cvxpy.Variable, shape (L,), nonneg
        The variable the solver sees, :math:`y = n x` (n states, L pairs).
    x : cvxpy.Expression, shape (L,)
        The occupation measure :math:`x = y / n` (sums to 1 under :attr:`balance`). Every
        expression of this class is in x units.
    balance : list of cvxpy.Constraint
        ``[(E - P^T)_{1:} y == 0, sum(y) == n]``: the balance rows of states 1..n-1 (state 0's
        is implied by the others) and the normalisation, i.e.
        :math:`\sum_{l: s_l = s'} x_l = \sum_l P(s' \mid l) x_l`, :math:`\sum_l x_l = 1`.
        (One constraint only, the normalisation, for a one-state MDP.)

    Examples
    --------
    Min-max fairness over the processes, and a penalty on the cloud's send rate:

    >>> prog = OccupationProgram(mdp)                                             # doctest: +SKIP
    >>> fair = prog.solve(cp.Minimize(cp.maximum(prog.process_cost(0), prog.process_cost(1))))  # doctest: +SKIP
    >>> eco = prog.solve(cp.Minimize(prog.cost() + 50 * prog.send_rate("remote")))  # doctest: +SKIP
    """

    def __init__(self, mdp: MDP):
        import cvxpy as cp

        from ..solvers.lp import build_lp

        self.mdp = mdp
        n, L = mdp.n_states, mdp.n_pairs
        self._n = float(n)
        self._lp = build_lp(mdp)
        self.y = cp.Variable(L, nonneg=True, name="y")
        self.x = self.y / self._n
        bal = [self._lp.A_eq[:-1] @ self.y == 0] if n > 1 else []
        self.balance = bal + [cp.sum(self.y) == self._n]
        self._vectors: dict[tuple, np.ndarray] = {}

    def __repr__(self) -> str:
        return f"OccupationProgram({self.mdp.name!r}, n_states={self.mdp.n_states}, n_pairs={self.mdp.n_pairs})"

    # ------------------------------------------------------------------ quantities
    @property
    def n_states(self) -> int:
        return int(self.mdp.n_states)

    @property
    def n_pairs(self) -> int:
        return int(self.mdp.n_pairs)

    @property
    def process_names(self) -> tuple[str, ...]:
        """The processes' names in scenario order (empty for an MDP without a scenario)."""
        sc = self._scenario()
        return tuple(p.name for p in sc.processes) if sc is not None else ()

    @property
    def server_names(self) -> tuple[str, ...]:
        """The servers' names in scenario order (empty for an MDP without a scenario)."""
        sc = self._scenario()
        return tuple(s.name for s in sc.servers) if sc is not None else ()

    def average(self, values: Any) -> Any:
        r"""The long-run average of a per-pair quantity: :math:`\sum_l d_l x_l` (affine in x).

        Parameters
        ----------
        values : (L,) array_like
            :math:`d_l` per state-action pair, finite.

        Returns
        -------
        cvxpy.Expression (scalar)
        """
        d = np.asarray(values, dtype=float)
        if d.shape != (self.n_pairs,):
            raise SolverError(f"average(values): expected one value per state-action pair ({self.n_pairs}), got shape {d.shape}")
        if not np.all(np.isfinite(d)):
            raise SolverError("average(values): the values must be finite")
        return (d / self._n) @ self.y

    def cost(self) -> Any:
        r"""The MDP's average cost :math:`\sum_l c_l x_l` (the total weighted MSE of a WNCS model)."""
        return self.average(self.mdp.cost)

    def process_cost(self, process: int | str) -> Any:
        r"""The average cost of one process, :math:`\sum_l q_k(\tau_k(s_l))\, x_l` (its weight included).

        Parameters
        ----------
        process : int or str
            0-based index or name (``"process-1"``).
        """
        k = self._index("process", process, "process_cost")
        return self.average(self._vector("process_cost", process=k))

    def aoi(self, process: int | str) -> Any:
        r"""The average AoI of one process, :math:`\sum_l \tau_k(s_l)\, x_l` (the capped value in the state)."""
        k = self._index("process", process, "aoi")
        return self.average(self._vector("aoi", process=k))

    def send_rate(self, server: int | str, process: int | str | None = None) -> Any:
        r"""How often server m is sent an update: :math:`\sum_l [a_m(l) \ne 0]\, x_l`.

        With ``process``, only updates of that process count: :math:`[a_m(l) = k]`. An update the
        uplink then loses counts (the energy was spent).

        Parameters
        ----------
        server : int or str
            0-based index or name (``"remote"``).
        process : int or str, optional
        """
        m = self._index("server", server, "send_rate")
        k = None if process is None else self._index("process", process, "send_rate")
        return self.average(self._vector("send_rate", server=m, process=k))

    def vector(self, quantity: str, *, process: int | str | None = None, server: int | str | None = None) -> np.ndarray:
        """The per-pair vector :math:`d_l` of a quantity of ``docs/constraints.md`` section 1 (a copy).

        ``quantity`` is ``"cost"``, ``"process_cost"``, ``"aoi"`` or ``"send_rate"``; processes and
        servers by 0-based index or name. ``prog.average(prog.vector(q, ...))`` is the expression.
        """
        if quantity == "cost":
            return np.array(self.mdp.cost, dtype=float)
        if quantity in ("process_cost", "aoi"):
            if process is None:
                raise SolverError(f"quantity {quantity} needs a process")
            return self._vector(quantity, process=self._index("process", process, quantity)).copy()
        if quantity == "send_rate":
            if server is None:
                raise SolverError("quantity send_rate needs a server")
            m = self._index("server", server, quantity)
            k = None if process is None else self._index("process", process, quantity)
            return self._vector(quantity, server=m, process=k).copy()
        raise SolverError(f"unknown quantity {quantity!r}: expected 'cost', 'process_cost', 'aoi' or 'send_rate'")

    # ------------------------------------------------------------------ exact values
    def occupation_of(self, policy: Any) -> np.ndarray:
        """The exact occupation measure of a stationary policy (its own chain's stationary law).

        Parameters
        ----------
        policy : array or Solution or ConstrainedSolution
            (n,) int pair indices, (L,) pair probabilities, or a solution's ``policy``.

        Raises
        ------
        PolicyError
            The policy is malformed or its chain has several recurrent classes.
        """
        pol = getattr(policy, "policy", policy)
        chain = PolicyChain(self.mdp, np.asarray(pol))
        if not chain.is_unichain:
            from ..errors import PolicyError

            raise PolicyError(f"the policy's chain has {chain.n_classes} recurrent classes; its averages depend on the start state")
        probs = np.asarray(pol, dtype=float)
        if probs.shape != (self.n_pairs,):
            probs = np.zeros(self.n_pairs)
            probs[np.asarray(pol, dtype=np.int64)] = 1.0
        return chain.stationary[self.mdp.s_indices] * probs

    def value(self, expr: Any, occupation: Any) -> float | np.ndarray:
        """The value of an expression of x only at a given occupation measure (or policy).

        Parameters
        ----------
        expr : cvxpy.Expression
            Built from :attr:`x` / this program's quantities (no other variable).
        occupation : (L,) array, or a solution / policy
            An occupation measure (sums to 1), or anything :meth:`occupation_of` accepts.

        Returns
        -------
        float (scalar expression) or array
        """
        if getattr(occupation, "occupation", None) is not None:
            occ = np.asarray(occupation.occupation, dtype=float)
        elif hasattr(occupation, "policy"):
            occ = self.occupation_of(occupation)
        else:
            occ = np.asarray(occupation, dtype=float)
            if occ.shape != (self.n_pairs,) or not (abs(occ.sum() - 1.0) < 1e-6 and occ.min() >= -1e-12):
                occ = self.occupation_of(occupation)
        others = [v for v in expr.variables() if v is not self.y]
        if others:
            raise SolverError(f"value(): the expression depends on variables other than the program's x ({others[0].name()})")
        saved = self.y.value
        try:
            self.y.value = self._n * np.maximum(occ, 0.0)
            v = np.asarray(expr.value, dtype=float)
        finally:
            self.y.value = saved
        return float(v) if v.size == 1 else v

    # ------------------------------------------------------------------ solve
    def solve(
        self,
        objective: Any,
        constraints: Iterable[Any] | Mapping[str, Any] = (),
        *,
        tol: float = 1e-8,
        max_iter: int = 200,
        verbose: bool = False,
        settings: dict | None = None,
        crossover: bool = True,
        cert_rtol: float = CERT_RTOL,
        feas_rtol: float = FEAS_RTOL,
    ) -> ConstrainedSolution:
        r"""Optimise a convex objective over the occupation polytope, and certify the policy.

        Solves ``cp.Problem(objective, balance + constraints)`` with Clarabel, reads the
        randomised policy :math:`\pi(a \mid s) = x(s, a) / \sum_a x(s, a)` off the optimal x
        (:func:`~wncs_lp.constrained.certify.policy_from_occupation`) and evaluates it exactly
        on its own Markov chain (see the module docstring for what ``gain_lower`` /
        ``gain_upper`` mean).

        Parameters
        ----------
        objective : cvxpy.Minimize or cvxpy.Maximize
            Built from this program's expressions (DCP: convex to minimise, concave to maximise).
        constraints : iterable of cvxpy.Constraint, or {label: constraint}
            Extra constraints (DCP); the balance constraints are added. A mapping gives the
            reports their labels.
        tol : float
            Clarabel's ``tol_gap_abs = tol_gap_rel = tol_feas``.
        max_iter : int
            Clarabel's iteration limit.
        verbose : bool
            Solver log to stdout.
        settings : dict, optional
            More Clarabel settings (``DefaultSettings`` attribute names).
        crossover : bool
            Linear programs only: look for a basic optimal solution on the interior point's
            optimal face (HiGHS dual simplex on the pairs in play), kept when its objective
            agrees with Clarabel's.
        cert_rtol, feas_rtol : float
            Relative certificate width accepted as ``"optimal"``; relative constraint violation
            accepted as feasible.

        Returns
        -------
        ConstrainedSolution
            ``method="convex"``. ``stats``: ``solver_status`` (cvxpy), ``clarabel_status``,
            ``solver_objective`` (the solver's f), ``solver_dual_objective``,
            ``duality_gap_abs`` / ``duality_gap_rel`` (Clarabel's), ``r_prim``, ``r_dual``,
            ``solver_iterations``, ``solve_time``, ``objective_exact``,
            ``objective_exact_method``, ``objective_sense``, ``cost_exact`` (the MDP's average
            cost under the returned policy), ``certificate`` (``"lagrangian"`` or
            ``"solver_dual"``), ``max_violation``, ``crossover`` (linear programs).

        Raises
        ------
        InfeasibleConstraintsError
            The solver finds the constraints infeasible (a :class:`SolverError`; the message
            carries its status).
        SolverError
            Not a cvxpy objective, not DCP, unbounded, or the solver failed (with its status).
        """
        import cvxpy as cp

        t0 = time.perf_counter()
        if not isinstance(objective, (cp.Minimize, cp.Maximize)):
            raise SolverError(f"solve(): the objective must be cvxpy.Minimize(...) or cvxpy.Maximize(...), got {type(objective).__name__}")
        labels, cons = _labelled(constraints)
        for lab, c in zip(labels, cons):
            if not isinstance(c, cp.constraints.constraint.Constraint):
                raise SolverError(f"solve(): constraint {lab!r} is not a cvxpy constraint ({type(c).__name__})")
        prob = cp.Problem(objective, self.balance + cons)
        if not prob.is_dcp():
            bad = "the objective" if not objective.is_dcp() else \
                "constraint " + ", ".join(repr(lab) for lab, c in zip(labels, cons) if not c.is_dcp())
            raise SolverError(f"solve(): the program is not convex (DCP rules): {bad}")
        sense = 1.0 if isinstance(objective, cp.Minimize) else -1.0
        stats = self._run(prob, sense, tol, max_iter, verbose, settings)
        status = stats["solver_status"]
        if status in _INFEASIBLE:
            raise InfeasibleConstraintsError(
                f"convex program: no stationary policy meets the constraints (solver status {status}): "
                + "; ".join(labels), labels, jointly=True)
        if status in _UNBOUNDED:
            raise SolverError(f"convex program: the objective is unbounded on the occupation polytope (solver status {status})")
        yv = self.y.value
        if yv is None or not np.all(np.isfinite(yv)):
            raise SolverError(f"convex program: the solver returned no usable solution (status {status}, "
                              f"Clarabel status {stats.get('clarabel_status')}, iterations {stats.get('solver_iterations')})")
        stats["objective_sense"] = "minimize" if sense > 0 else "maximize"
        x = np.maximum(np.asarray(yv, dtype=float), 0.0)
        x = x / x.sum()
        solved = status == "optimal"
        lin = _linear_program(self, objective.expr, labels, cons)
        if lin is not None:
            sol = self._certify_linear(lin, sense, x, solved, status, crossover, cert_rtol, feas_rtol, stats, t0)
        else:
            sol = self._certify_convex(objective, labels, cons, sense, x, solved, status, cert_rtol, feas_rtol, stats, t0)
        return sol

    # ------------------------------------------------------------------ internals
    def _run(self, prob, sense: float, tol, max_iter, verbose, settings) -> dict[str, Any]:
        """Clarabel through cvxpy's documented ``get_problem_data`` / ``unpack_results`` path,
        so that Clarabel's own dual objective and gap are at hand."""
        import cvxpy as cp

        opts: dict[str, Any] = {"tol_gap_abs": float(tol), "tol_gap_rel": float(tol), "tol_feas": float(tol),
                                "max_iter": int(max_iter)}
        opts.update(settings or {})
        cache: dict[str, Any] = {}
        try:
            with warnings.catch_warnings():  # "solution may be inaccurate": reported in our status
                warnings.simplefilter("ignore", UserWarning)
                data, chain, inverse = prob.get_problem_data(cp.CLARABEL, solver_opts=opts)
                raw = chain.solver.solve_via_data(data, False, bool(verbose), opts, solver_cache=cache)
                prob.unpack_results(raw, chain, inverse)
        except (cp.error.SolverError, cp.error.DCPError) as exc:
            raise SolverError(f"convex program: cvxpy/Clarabel failed: {exc}") from exc
        except (TypeError, AttributeError) as exc:
            raise SolverError(f"convex program: bad Clarabel setting or solver call: {exc}") from exc
        st: dict[str, Any] = {"solver": "cvxpy+clarabel", "solver_status": str(prob.status),
                              "clarabel_status": str(raw.status), "solver_iterations": int(raw.iterations),
                              "solve_time": float(raw.solve_time), "r_prim": float(raw.r_prim),
                              "r_dual": float(raw.r_dual)}
        pv = prob.value
        st["solver_objective"] = float(pv) if pv is not None and np.isfinite(pv) else float("nan")
        # the user's f is sense * (Clarabel's objective + cvxpy's constant offset)
        st["solver_dual_objective"] = st["solver_objective"] + sense * (float(raw.obj_val_dual) - float(raw.obj_val))
        info = cache["CLARABEL"].get_info() if "CLARABEL" in cache else None
        st["duality_gap_abs"] = float(info.gap_abs) if info is not None else abs(float(raw.obj_val_dual) - float(raw.obj_val))
        st["duality_gap_rel"] = float(info.gap_rel) if info is not None else float("nan")
        return st

    def _scenario(self):
        st = self.mdp.states
        model = getattr(st, "model", None) if st is not None else None
        return getattr(model, "scenario", None)

    def _index(self, kind: str, ref: Any, quantity: str) -> int:
        """A 0-based process/server index from an index or a name, with one clear error."""
        names = self.process_names if kind == "process" else self.server_names
        if kind == "process":
            tau = getattr(self.mdp.states, "tau", None) if self.mdp.states is not None else None
            count = int(np.asarray(tau).shape[1]) if tau is not None else None
        else:
            table = self.mdp.action_table
            count = int(np.atleast_2d(np.asarray(table)).shape[1]) if table is not None else None
        if count is None or (quantity == "process_cost" and self._scenario() is None):
            raise SolverError(f"{quantity}({ref!r}) needs an MDP built by wncs_lp.build (decoded states, actions and "
                              f"scenario); for your own per-pair vector use average(values)")
        plural = "processes" if kind == "process" else "servers"
        choices = f"{plural} are " + ", ".join(f"{i} = {nm!r}" for i, nm in enumerate(names)) if names \
            else f"{kind} indices are 0..{count - 1}"
        if isinstance(ref, (bool, np.bool_)) or not isinstance(ref, (int, np.integer, str)):
            raise SolverError(f"{quantity}: a {kind} is a 0-based index or a name, got {ref!r}; the {choices}")
        if isinstance(ref, str):
            if ref in names:
                return names.index(ref)
            raise SolverError(f"{quantity}: unknown {kind} {ref!r}; the {choices}")
        k = int(ref)
        if not 0 <= k < count:
            raise SolverError(f"{quantity}: {kind} index {k} out of range (0-based); the {choices}")
        return k

    def _vector(self, quantity: str, *, process: int | None = None, server: int | None = None) -> np.ndarray:
        key = (quantity, process, server)
        if key not in self._vectors:
            from ..models.quantities import pair_values

            try:
                v = pair_values(self.mdp, ConstraintSpec(quantity, server=server, process=process))
            except ModelError as exc:
                raise SolverError(str(exc)) from exc
            v = np.asarray(v, dtype=float)
            v.setflags(write=False)
            self._vectors[key] = v
        return self._vectors[key]

    def _duals(self) -> tuple[np.ndarray, np.ndarray]:
        """(z_eq, h): the balance/normalisation duals (cvxpy sign) and the bias h = -n z_bal."""
        n = self.n_states
        parts = [np.asarray(c.dual_value if c.dual_value is not None else np.zeros(c.size), float).ravel()
                 for c in self.balance]
        z_eq = np.concatenate(parts)
        h = np.zeros(n)
        if n > 1:
            h[1:] = -self._n * z_eq[:-1]
        return z_eq, h

    def _certify_linear(self, lin, sense, x, solved, status, crossover, cert_rtol, feas_rtol, stats, t0):
        """Linear program: certify() with f's coefficients as the cost (a rigorous Lagrangian bound)."""
        d, c0, lcons, lam_rows = lin
        cost = sense * d  # minimise cost^T x  (+ sense * c0)
        mdp_d = with_cost(self.mdp, cost)
        rows = max_form(lcons, self.n_pairs)
        z_eq, h = self._duals()
        stats["crossover"] = "off"
        if crossover:
            xb, info = _crossover(self.mdp, self._lp, cost, rows, x, z_eq, lam_rows)
            stats.update(info)
            stats["crossover"] = "basic" if xb is not None else "failed: interior point kept"
            if xb is not None:
                x = xb
        lp_values = np.array([float(c.values @ x) for c in lcons])
        probs, randomized = policy_from_occupation(mdp_d, x, h)
        stats["certificate"] = "lagrangian"
        stats["row_multipliers"] = [float(v) for v in lam_rows]
        sol = certify(mdp_d, lcons, probs, randomized, lam_rows, method="convex",
                      solver_status=cvxpy_status(status),
                      solver_gain=sense * (stats["solver_objective"] - c0), lp_values=lp_values, h0=h,
                      cert_rtol=cert_rtol, feas_rtol=feas_rtol, iterations=stats["solver_iterations"], t0=t0,
                      stats=stats)
        g, lo, hi = sol.gain, sol.gain_lower, sol.gain_upper
        if sense > 0:
            g, lo, hi = g + c0, lo + c0, hi + c0
        else:
            g, lo, hi = -g + c0, -hi + c0, -lo + c0
        st = sol.stats
        st.update(objective_exact=float(g), objective_exact_method="direct",
                  cost_exact=float(self.mdp.cost @ sol.occupation))
        return replace(sol, gain=float(g), gain_lower=float(lo), gain_upper=float(hi),
                       solver_gain=float(stats["solver_objective"]), seconds=time.perf_counter() - t0, stats=st)

    def _certify_convex(self, objective, labels, cons, sense, x, solved, status, cert_rtol, feas_rtol, stats, t0):
        """Nonlinear program: exact evaluation of the policy, the solver's dual objective beside it."""
        import cvxpy as cp

        probs, randomized = policy_from_occupation(self.mdp, x)
        ev = evaluate_rows(self.mdp, probs, [])
        occ = ev["occupation"]
        y_exact = self._n * occ
        y_solver = self.y.value.copy()
        lp_vals = [_constraint_value(c)[0] for c in cons]  # at the solver's point
        # save what the re-evaluation overwrites, to leave the cvxpy objects as the solver left them
        variables = {v.id: (v, v.value) for v in objective.variables()}
        for c in cons:
            variables.update({v.id: (v, v.value) for v in c.variables()})
        duals = [(c, c.dual_value) for c in list(self.balance) + cons]
        try:
            aux = [v for _, (v, _) in variables.items() if v is not self.y]
            if not aux:
                self.y.value = y_exact
                f_exact, how = float(objective.value), "direct"
                aux_ok = True
            else:
                # the user's auxiliary variables (an epigraph t, ...) re-optimised with x fixed
                coupled = [c for c in cons if any(v is not self.y for v in c.variables())]
                fixed = cp.Problem(objective, [self.y == y_exact] + coupled)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    try:
                        fixed.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
                    except cp.error.SolverError:
                        pass
                aux_ok = fixed.status == "optimal"
                f_exact = float(fixed.value) if aux_ok else float("nan")
                how = f"resolved (auxiliary variables re-optimised with x fixed; status {fixed.status})"
                self.y.value = y_exact
            reports, viol_max = [], 0.0
            for lab, c, lpv in zip(labels, cons, lp_vals):
                v, viol, scale = _constraint_value(c)
                dual = next(dv for cc, dv in duals if cc is c)  # the main solve's, not the re-evaluation's
                lam = float(np.max(np.abs(np.asarray(dual, dtype=float)))) if dual is not None else float("nan")
                rel = viol / max(1.0, scale)
                viol_max = max(viol_max, rel)
                active = v >= -feas_rtol * max(1.0, scale)
                reports.append(ConstraintReport(lab, type(c).__name__, 0.0, None, float(v), float(lpv), bool(active),
                                                "max" if active else None, lam, float(viol)))
        finally:
            for v, val in variables.values():
                v.value = val
            self.y.value = y_solver
            for c, dv in duals:
                if dv is not None:
                    c.save_dual_value(dv)
        dual_obj = stats["solver_dual_objective"]
        sub = _subgradient_bound(self, objective, sense, labels, cons, occ, f_exact) if aux_ok else None
        stats["subgradient_bound"] = float("nan") if sub is None else float(sub)
        # the subgradient bound is rigorous but may be loose (a max with tied arguments: the one
        # subgradient cvxpy gives is not the KKT one); it replaces the solver's claim when it closes
        if sub is not None and abs(f_exact - sub) > cert_rtol * max(abs(f_exact), 1e-300):
            sub = None
        other = dual_obj if sub is None else sub
        lo, hi = (other, f_exact) if sense > 0 else (f_exact, other)
        width = hi - lo
        closed = math.isfinite(width) and width <= cert_rtol * max(abs(f_exact), 1e-300)
        feasible = viol_max <= feas_rtol
        st_out = status_from((cvxpy_status(status), None if aux_ok else OBJECTIVE_NOT_EVALUATED,
                              None if feasible else INFEASIBLE_POLICY, None if closed else CERTIFICATE))
        stats.update(certificate="solver_dual" if sub is None else "subgradient", objective_exact=f_exact, objective_exact_method=how,
                     cost_exact=float(ev["gain"]), evaluation_residual=ev["residual"], max_violation=float(viol_max))
        mult = np.array([r.multiplier for r in reports], dtype=float)
        randomized = np.asarray(randomized, dtype=np.int64)
        for a in (probs, occ, mult, randomized):
            a.setflags(write=False)
        return ConstrainedSolution(method="convex", status=st_out, gain=float(f_exact), gain_lower=float(lo),
                                   gain_upper=float(hi), solver_gain=float(stats["solver_objective"]), policy=probs,
                                   occupation=occ, multipliers=mult, constraints=tuple(reports),
                                   randomized_states=randomized, iterations=int(stats["solver_iterations"]),
                                   seconds=time.perf_counter() - t0, stats=stats)


def _labelled(constraints: Any) -> tuple[list[str], list[Any]]:
    if isinstance(constraints, Mapping):
        return [str(k) for k in constraints], list(constraints.values())
    cons = list(constraints)
    labels = []
    for i, c in enumerate(cons):
        text = " ".join(str(c).split())
        labels.append(text if len(text) <= 60 else f"constraint {i}")
    return labels, cons


def _constraint_value(c) -> tuple[float, float, float]:
    """(value, violation, scale) of a constraint at the variables' current values:
    ``max(lhs - rhs)`` for an inequality, ``max |lhs - rhs|`` for an equality, else the
    violation; scale = the largest |side| (for the relative feasibility test)."""
    import cvxpy as cp

    viol = float(np.max(np.atleast_1d(c.violation()))) if c.size else 0.0
    args = [np.asarray(a.value, dtype=float) for a in c.args if a.value is not None]
    scale = max([float(np.max(np.abs(a))) for a in args if a.size] + [0.0])
    if isinstance(c, cp.constraints.Inequality):
        v = float(np.max(np.asarray(c.args[0].value, float) - np.asarray(c.args[1].value, float)))
    elif isinstance(c, cp.constraints.Equality):
        v = float(np.max(np.abs(np.asarray(c.args[0].value, float) - np.asarray(c.args[1].value, float))))
    else:
        v = viol
    return v, viol, scale


def _affine(expr, y, L: int, n: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(D, k): ``expr = D x + k`` elementwise, with D of shape (size, L) in x units; None if
    ``expr`` is not affine in the program's variable alone."""
    if not expr.is_affine() or any(v is not y for v in expr.variables()):
        return None
    saved = y.value
    try:
        y.value = np.zeros(L)
        k = np.asarray(expr.value, dtype=float).ravel()
        G = expr.grad.get(y) if expr.variables() else None
    finally:
        y.value = saved
    if G is None:
        D = np.zeros((k.size, L))
    else:
        D = n * np.asarray(sp.csc_matrix(G).toarray(), dtype=float).T.reshape(k.size, L)
    return D, k


def _linear_program(prog: OccupationProgram, obj_expr, labels: Sequence[str], cons: Sequence[Any]):
    """The program as ``min/max d^T x + c0`` s.t. rows ``D x <= b`` (LinearConstraints) with the
    solver's row multipliers, or None when it is not linear in x alone."""
    L, n, y = prog.n_pairs, prog._n, prog.y
    fo = _affine(obj_expr, y, L, n)
    if fo is None or fo[1].size != 1:
        return None
    lin = _linear_constraints(prog, labels, cons)
    if lin is None:
        return None
    return fo[0][0], float(fo[1][0]), lin[0], lin[1]


def _linear_constraints(prog: OccupationProgram, labels: Sequence[str], cons: Sequence[Any]):
    """The user constraints as LinearConstraints ``D x <= b`` with the solver's row multipliers
    (one per row of :func:`~wncs_lp.constrained.problem.max_form`), or None when one of them is
    not affine in x alone."""
    import cvxpy as cp

    L, n, y = prog.n_pairs, prog._n, prog.y
    if sum(int(c.size) for c in cons) > MAX_LINEAR_ROWS:
        return None
    lcons, lam = [], []
    for lab, c in zip(labels, cons):
        if not isinstance(c, (cp.constraints.Inequality, cp.constraints.Equality)):
            return None
        lhs, rhs = c.args
        flip = 1.0
        if rhs.is_constant():
            expr, b = lhs, np.asarray(rhs.value, float)
        elif lhs.is_constant():
            expr, b, flip = rhs, np.asarray(lhs.value, float), -1.0
        else:
            expr, b = lhs - rhs, np.zeros(1)
        fa = _affine(expr, y, L, n)
        if fa is None:
            return None
        D, k = fa
        b = np.broadcast_to(b.ravel() if b.size > 1 else b.reshape(-1)[:1], k.shape) - k
        if c.dual_value is None:
            return None
        dual = np.broadcast_to(np.asarray(c.dual_value, float).ravel(), k.shape)
        for i in range(k.size):
            name = lab if k.size == 1 else f"{lab}[{i}]"
            bi = float(b[i])
            if isinstance(c, cp.constraints.Inequality):
                # lhs <= rhs: expr <= b (rhs constant) or expr >= b (lhs constant); dual >= 0 either way
                lc = LinearConstraint(D[i], max=bi, label=name, quantity="linear") if flip > 0 else \
                    LinearConstraint(D[i], min=bi, label=name, quantity="linear")
                lam.append(max(float(dual[i]), 0.0))
            else:
                # lhs == rhs, Lagrangian term nu (lhs - rhs) = flip * nu (expr - b)
                nu = flip * float(dual[i])
                lc = LinearConstraint(D[i], max=bi, min=bi, label=name, quantity="linear")
                lam += [max(nu, 0.0), max(-nu, 0.0)]
            lcons.append(lc)
    return tuple(lcons), np.array(lam, dtype=float)


def _subgradient_bound(prog: OccupationProgram, objective, sense: float, labels, cons, occ: np.ndarray,
                       f_exact: float) -> float | None:
    r"""A rigorous bound on f* from a subgradient at the returned policy (None when unavailable).

    For convex f (``Minimize``) and any :math:`s \in \partial f(\hat x)`,
    :math:`f(x) \ge f(\hat x) + s^T (x - \hat x)` for every x, so over the constrained polytope

    .. math:: f^* \ge f(\hat x) - s^T \hat x + \min_{x:\ D x \le b} s^T x
              \ge f(\hat x) - s^T \hat x + L_s(\lambda),

    with :math:`L_s(\lambda)` the Lagrangian bound of the linear cost s (certified value
    iteration, :func:`~wncs_lp.constrained.certify.lagrangian_bound`). ``Maximize`` (concave f)
    is the same for -f, giving an upper bound. It is tight when s is the subgradient of the KKT
    conditions (e.g. a differentiable f, or a max whose largest argument is unique). Needs
    the user's constraints affine in x and f a function of x alone.
    """
    lin = _linear_constraints(prog, labels, cons)
    if lin is None or any(v is not prog.y for v in objective.variables()):
        return None
    lcons, lam = lin
    saved = prog.y.value
    try:
        prog.y.value = prog._n * np.maximum(occ, 0.0)
        grads = objective.expr.grad
        G = grads.get(prog.y) if grads else None
    except Exception:  # cvxpy cannot differentiate this atom here: no bound
        G = None
    finally:
        prog.y.value = saved
    if G is None:
        return None
    s = sense * prog._n * np.asarray(sp.csc_matrix(G).toarray(), dtype=float).ravel()
    if s.shape != (prog.n_pairs,) or not np.all(np.isfinite(s)):
        return None
    rows = max_form(lcons, prog.n_pairs)
    bound, _ = lagrangian_bound(with_cost(prog.mdp, s), rows, lam)
    return sense * (sense * f_exact - float(s @ occ) + bound)


def _crossover(mdp: MDP, lp, cost: np.ndarray, rows, x: np.ndarray, z_eq: np.ndarray, lam_rows: np.ndarray):
    """:func:`~wncs_lp.constrained.lp.basic_solution` for ``min cost^T x`` s.t. balance and ``D x <= b``,
    in the solver's y = n x units; returns the basic x (sum 1) or None, and the crossover's info."""
    n = float(mdp.n_states)
    y, q = n * x, cost / n
    G = rows.D / n if rows.n_rows else None
    # reduced costs of the solver's duals (cvxpy: Lagrangian f + z^T (A y - b) + lam^T (G y - h))
    mu = q + lp.A_eq.T @ z_eq + (G.T @ lam_rows if G is not None else 0.0)
    yb, info = basic_solution(mdp, lp.A_eq, lp.b_eq, q, G, rows.b, y, mu, float(q @ y))
    return (None if yb is None else yb / yb.sum()), info

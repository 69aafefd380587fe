"""Matrix-free certified value iteration and exact policy evaluation over the AoI box.

Every model of the toolkit has states s = (c, tau): a configuration c of a small automaton
(:mod:`wncs_lp.models.automaton`) and the AoI vector tau, which moves by arithmetic,

    tau'_k = min(tau_k + 1, delta_k if delivered, tau_hat_k),

for each outcome (c', delta, p) of (c, action). So the Bellman operator needs no stored
transition matrix: a sweep walks, per configuration, a dense box of AoI vectors and computes
the successor indices (:mod:`.kernels`). Memory is one float64
value vector and one byte of policy per state, plus a second vector when it fits (for the
extrapolation and warm start below, or a Jacobi iteration): the paper's four processes at cap
30 (2.5e8 states) need 2.3 GB (4.3 GB with the second vector), where the stored matrix would
need about 30 GB.

State space (:class:`BoxLayout`)
--------------------------------
For configuration c and process k let [lo_k(c), hi_k(c)] be the smallest interval containing
every tau_k reachable with c (the per-axis fixed point of the size guard, taken as intervals).
The layout holds the product of these intervals for every c, configuration-major, C order of
the box within a configuration (the last process contiguous). This set S is *closed* (every
successor of a state of S is in S) and contains the reachable set R that
:func:`wncs_lp.models.build` enumerates (a few percent more states: 1,073,595 against
1,045,479 for the paper's four processes at cap 10).

Why the certificate over S is valid for the MDP over R: R is closed, so (T h)(s) for s in R
reads h on R only; hence min_R (T h - h) >= min_S (T h - h) and max_R <= max_S, and the
bracket lo_S <= g* <= hi_S holds for R's optimal gain. It *closes* (lo, hi -> g*) when the
states of S \\ R are transient under every policy. That holds when from every configuration,
whatever the actions, an initial configuration (whose whole tau box is in R) is reachable with
positive probability -- in the Section II model because any uplink can lose its update
(p_up < 1), in the preemption model because arrivals can fail. This is checked on the
automaton (:func:`drains_to_initial`); when it fails (e.g. p = 1), ``domain="auto"`` computes
the exact reachable set R as a byte mask over S (a fixed point of marking passes) and the
bracket is taken over R only. ``domain="reachable"`` forces that.

Both model kinds have this structure, so the preemption model is solved the same way (its
automaton carries the job ages; its configurations grow with the cap, the box per
configuration does not).

Policies
--------
:attr:`MatrixFreeSolution.policy` is **not** pair indices (there is no MDP): it is one
``uint8`` per layout state, the *local* action index j (``system.automaton.actions[c][j]``,
the MDP's action order for that configuration) of the greedy policy of the certified bias.
:meth:`MatrixFreeSolution.on_mdp` converts a solution to the ordinary pair-index form on an
enumerated MDP of the same scenario; :class:`wncs_lp.policies.MatrixFreePolicy` is a
:class:`~wncs_lp.policies.Policy` (``act``, ``on_mdp``) usable by the simulator and the
evaluators; :meth:`MatrixFreeSolution.save` / :func:`load_solution` store it.

Exact evaluation of a given policy (:func:`matrix_free_evaluate`) iterates the fixed-policy
operator T_pi to the bracket min_S (T_pi h - h) <= g_pi <= max_S (T_pi h - h).

Rooms: :mod:`.layout` (the states), :mod:`.operator` (the tables a sweep reads, tiles and thread
split), :mod:`.kernels` (numba), :mod:`.sweeper` (kernel calls, reachability), :mod:`.extrapolate`,
:mod:`.aggregate` (the opt-in coarse correction), :mod:`.options`, :mod:`.iterate` (value iteration
and evaluation), :mod:`.result` (result types, save / load), :mod:`.capmass` (time at the cap),
:mod:`.solve` (entry points by method).
"""
from __future__ import annotations

from ... import moved
from .capmass import cap_cost, matrix_free_cap_mass, matrix_free_cap_masses
from .iterate import BYTES_PER_STATE, matrix_free_bytes, matrix_free_evaluate, matrix_free_value_iteration, policy_table
from .layout import DOMAINS, BoxLayout, drains_to_initial
from .options import SCHEMES, MatrixFreeOptions
from .result import MatrixFreeEvaluation, MatrixFreeSolution, load_solution
from .solve import run_on_mdp
from .sweeper import reachable_mask

__all__ = [
    "BoxLayout",
    "MatrixFreeOptions",
    "MatrixFreeSolution",
    "MatrixFreeEvaluation",
    "matrix_free_value_iteration",
    "matrix_free_evaluate",
    "policy_table",
    "drains_to_initial",
    "reachable_mask",
    "load_solution",
    "cap_cost",
    "matrix_free_cap_mass",
    "matrix_free_cap_masses",
    "run_on_mdp",
    "matrix_free_bytes",
    "BYTES_PER_STATE",
    "DOMAINS",
    "SCHEMES",
]


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)

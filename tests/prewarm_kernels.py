"""Compile the package's numba kernels once, before the test workers start (tests/conftest.py).

On a fresh clone numba's caches are cold, and every process that reaches a kernel before another
has written its cache compiles it again: the two test workers, the reproduction's subprocess and
its pool workers. Two processes running this module (``solvers`` and ``bounds``) compile them side
by side first, through the library's own calls on small instances (so the signatures are the
ones the tests use); every later process loads them from the cache. Nothing is asserted here:
the tests check the numbers.
"""
from __future__ import annotations

import sys
import warnings


def solvers() -> None:
    import wncs_lp
    from wncs_lp.solvers.matrix_free import matrix_free_cap_mass, matrix_free_evaluate, matrix_free_value_iteration

    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p1234"), ["tau_cap=5"])
    mdp = wncs_lp.build(sc)
    for threads in (1, 2):
        sol = matrix_free_value_iteration(sc, threads=threads)
        matrix_free_evaluate(sc, sol, threads=threads)
        matrix_free_cap_mass(sc, sol, threads=threads)
        for method in ("vi", "rvi"):
            wncs_lp.solve(mdp, method, threads=threads)
    matrix_free_value_iteration(sc, threads=1, aggregate=True)


def bounds() -> None:
    from wncs_lp import load_scenario, scenario_path
    from wncs_lp.bounds import LookaheadPolicy, TableRolloutPolicy, bound_policy, lower_bound
    from wncs_lp.models.system import System
    from wncs_lp.simulate import simulate

    system = System.from_scenario(load_scenario(scenario_path("bounds_p1234_twice"), ["tau_cap=3"]))
    for relaxation in (1, 2, 4):
        res = lower_bound(system, relaxation)
    pol = bound_policy(res, system)
    for p in (pol, LookaheadPolicy(pol), TableRolloutPolicy(pol)):
        simulate(p, slots=200, reps=2, burn_in=10, seed=0)


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    {"solvers": solvers, "bounds": bounds}[sys.argv[1]]()

"""The parts of a solve outside the passes, now numba kernels on the solve's threads: the clamped
start of a coarse solve (:func:`~wncs_lp.solvers.matrix_free.start.clamped_values`) and the
loop's finiteness check of h (:meth:`BoxSweeps.h_range`, also the round-off bound's max |h|).

Checked against independent numpy: the layouts' own indexing of the clamped AoI vectors
(``BoxLayout.index``), and numpy's min / max (NaN propagating), on one and two threads; a
non-finite h still ends a solve with the overflow error.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

from wncs_lp.errors import SolverError  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.iteration import IterationScheme  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout  # noqa: E402
from wncs_lp.solvers.matrix_free.iterate import _Improve, _setup  # noqa: E402
from wncs_lp.solvers.matrix_free.options import MatrixFreeOptions  # noqa: E402
from wncs_lp.solvers.matrix_free.start import clamped_values  # noqa: E402

from test_matrix_free_candidates import paper  # noqa: E402


@pytest.mark.parametrize("threads", [1, 2])
def test_clamped_values_on_threads_read_the_clamped_aoi(threads):
    big_sys = System.from_scenario(paper("paper_p1234", 6))
    small_sys = System.from_scenario(paper("paper_p1234", 4))
    big, small = BoxLayout.from_system(big_sys), BoxLayout.from_system(small_sys)
    h_small = np.random.default_rng(2).normal(size=small.n_states)
    got = clamped_values(small, h_small, big, np.full(big.n_states, np.nan), threads)
    s = np.arange(big.n_states)
    c, tau = big.config_of(s), big.tau_of(s)
    idx = small.index(np.clip(tau, small.lo[c] + 1, small.lo[c] + small.dims[c]), c)
    assert np.all(idx >= 0) and np.array_equal(got, h_small[idx])


@pytest.mark.parametrize("threads", [1, 2])
def test_h_range_is_numpys_min_and_max(threads):
    system = System.from_scenario(paper("paper_p1234", 5))
    opts = MatrixFreeOptions(threads=threads)
    sweeps = _Improve(_setup(system, opts, None), opts)
    rng = np.random.default_rng(3)
    sweeps.h[:] = rng.normal(scale=1e3, size=sweeps.h.size)
    sweeps.h[rng.integers(sweeps.h.size)] = 7e5  # the extremes anywhere, not at a chunk's end
    sweeps.h[rng.integers(sweeps.h.size)] = -3e5
    assert sweeps.h_range() == IterationScheme.h_range(sweeps) == (-3e5, 7e5)
    for bad in (np.nan, np.inf, -np.inf):
        sweeps.h[rng.integers(sweeps.h.size)] = bad
        lo, hi = sweeps.h_range()
        assert not (np.isfinite(lo) and np.isfinite(hi))


def test_a_non_finite_h_is_still_the_overflow_error():
    from wncs_lp.solvers.matrix_free import matrix_free_value_iteration

    system = System.from_scenario(paper("paper_p1234", 4))
    n = BoxLayout.from_system(system).n_states
    h0 = np.zeros(n)
    h0[n // 2] = 1e308  # finite, but T h - h overflows on the first certificate's neighbours
    with pytest.raises(SolverError, match="overflow"):
        matrix_free_value_iteration(system, h0=h0, threads=1)

"""The extrapolation of the matrix-free iteration (:class:`~wncs_lp.solvers.matrix_free.extrapolate.Extrapolator`).

Unit checks on a synthetic iteration with a known limit: h_k = h* + a lambda^k v has exactly one
mode, so one step with the rate read from the widths lands on h* (a closed form); ratios that
alternate (the noise of the threaded in-place sweeps) make no step; a step the next certificate
finds wider is undone exactly, and so is a step no certificate judged, at the end. End to end,
solves that extrapolate close on the stored-matrix value iteration's gain (an independent route),
from zero and from a random start.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout, matrix_free_value_iteration  # noqa: E402
from wncs_lp.solvers.matrix_free.extrapolate import Extrapolator  # noqa: E402

LAM = 0.85
CYCLE = 5  # iterations between two certificates


def geometric(k, h_star, v):
    return h_star + LAM ** k * v


def drive(ex, widths, h_star, v):
    """Certificates every CYCLE iterations of the one-mode iteration, with the given widths
    (saving h at the start of a cycle when asked); returns (h, iters, notes) at the first step,
    or (None, None, notes) at the end."""
    notes = []
    for c, w in enumerate(widths, start=1):
        it = c * CYCLE
        if ex.want_save():  # at the start of the cycle
            ex.save(geometric(it - CYCLE, h_star, v), it - CYCLE)
        h = geometric(it, h_star, v)
        note = ex.step(h, it, w)
        notes.append(note)
        if ex.pending is not None:
            return h, it, notes
    return None, None, notes


@pytest.fixture
def mode():
    rng = np.random.default_rng(5)
    return rng.normal(size=50), rng.normal(size=50)


def test_one_step_removes_a_single_mode(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, notes = drive(ex, widths, h_star, v)
    assert h is not None and ex.count == 1, notes
    assert np.allclose(h, h_star, rtol=0, atol=1e-12)


def test_alternating_ratios_make_no_step(mode):
    # the two threads' noise: ratios alternating 0.25 / 0.6 are not a steady rate
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    h, _, notes = drive(ex, list(np.cumprod([0.25, 0.6] * 6)), h_star, v)
    assert h is None and ex.count == 0


def test_a_wider_certificate_undoes_the_step_exactly(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, _ = drive(ex, widths, h_star, v)
    runs, before = ex.runs, ex.pending[1]
    note = ex.step(h, it, 2 * before)  # the certificate of the moved h
    assert "undone" in note and ex.reverted == 1 and ex.runs == 2 * runs and ex.enabled
    assert np.allclose(h, geometric(it, h_star, v), rtol=0, atol=1e-12)


def test_a_narrower_certificate_keeps_it(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, _ = drive(ex, widths, h_star, v)
    note = ex.step(h, it, 1e-3 * ex.pending[1])
    assert "kept" in note and ex.reverted == 0 and ex.pending is None
    assert np.allclose(h, h_star, rtol=0, atol=1e-12)


def test_settle_undoes_a_step_no_certificate_judged(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, _ = drive(ex, widths, h_star, v)
    ex.settle(h)
    assert np.allclose(h, geometric(it, h_star, v), rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def p1234():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p1234"), ["tau_cap=7"])
    return System.from_scenario(sc), wncs_lp.solve(wncs_lp.build(sc), "vi")


@pytest.mark.parametrize("start", ["zero", "random"])
def test_solves_that_extrapolate_close_on_the_stored_gain(p1234, start):
    system, ref = p1234
    h0 = None
    if start == "random":
        n = BoxLayout.from_system(system).n_states
        h0 = np.random.default_rng(7).normal(scale=10 * ref.gain, size=n)
    sol = matrix_free_value_iteration(system, h0=h0, threads=1, tol=1e-11)
    assert sol.status == "optimal" and sol.stats["extrapolations"] >= 1
    s = 1e-9 * ref.gain
    assert sol.gain_lower - s <= ref.gain <= sol.gain_upper + s
    assert ref.gain_lower - s <= sol.gain <= ref.gain_upper + s


def test_no_step_on_a_copy_from_an_older_cycle(mode):
    # h_prev saved several cycles before the certificate: its m would be unknown to the rates
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    ex.save(geometric(0, h_star, v), 0)
    for c in range(1, 10):
        ex.step(geometric(c * CYCLE, h_star, v), c * CYCLE, LAM ** (CYCLE * c))
    assert ex.count == 0

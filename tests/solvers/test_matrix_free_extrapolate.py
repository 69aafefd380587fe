"""The extrapolation of the matrix-free iteration (:class:`~wncs_lp.solvers.matrix_free.extrapolate.Extrapolator`).

Unit checks on a synthetic iteration with a known limit: h_k = h* + a lambda^k v has exactly one
mode, so one step with the rate read from the widths lands on h* (a closed form); ratios that
alternate (the noise of the threaded in-place sweeps) make no step; a step the next certificate
finds no better than the steady rate's forecast counts as a miss; a step no certificate judged is
undone at the end. End to end, solves that extrapolate close on the stored-matrix value
iteration's gain (an independent route) and from a random start.
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


def drive(ex, widths, h_star, v, rel=1e-6):
    """Certificates every CYCLE iterations of the one-mode iteration, with the given widths
    (saving h one iteration before a certificate when asked); returns (h, iters, notes) at the
    first step, or at the end."""
    notes = []
    for c, w in enumerate(widths, start=1):
        it = c * CYCLE
        if ex.want_save():
            ex.save(geometric(it - 1, h_star, v), it - 1)
        h = geometric(it, h_star, v)
        note = ex.step(h, it, w, rel)
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


def test_ratios_within_the_tolerance_give_their_mean_rate(mode):
    # the widths' ratios a cycle vary around their geometric mean 0.3 (their logs within 1%): the
    # step uses that mean
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    ratios = [0.3 * 1.01, 0.3 / 1.01] * 6
    widths = list(np.cumprod(ratios))
    h, it, notes = drive(ex, widths, h_star, v)
    assert h is not None and ex.count == 1, notes
    k = ex.runs
    mean_rate = np.log(widths[len(notes) - 1] / widths[len(notes) - 1 - k]) / (k * CYCLE)
    f = np.exp(mean_rate) / (1 - np.exp(mean_rate))
    prev = geometric(it - 1, h_star, v)
    h_expected = geometric(it, h_star, v)
    h_expected = h_expected + f * (h_expected - prev)
    assert np.allclose(h, h_expected, rtol=1e-12, atol=1e-12)


def test_no_step_before_the_bracket_is_narrow(mode):
    # steady ratios, but the bracket still wider than max_rel of the gain: the transient regime
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    h, _, _ = drive(ex, [LAM ** (CYCLE * c) for c in range(1, 10)], h_star, v, rel=10 * ex.max_rel)
    assert h is None and ex.count == 0


def test_alternating_ratios_make_no_step(mode):
    # the two threads' noise: ratios alternating 0.25 / 0.6 are not a steady rate
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    h, _, notes = drive(ex, list(np.cumprod([0.25, 0.6] * 6)), h_star, v)
    assert h is None and ex.count == 0


def test_a_step_no_better_than_the_forecast_is_a_miss(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True, max_misses=2)
    widths = [LAM ** (CYCLE * c) for c in range(1, 12)]
    h, it, _ = drive(ex, widths, h_star, v)
    runs, before = ex.runs, ex.pending[3]
    # the next certificate finds the width of the step, above the steady rate's forecast
    note = ex.step(h, it + CYCLE, before, 1e-6)
    assert ex.missed == 1 and ex.runs == 2 * runs and ex.enabled and "did not pay" in note
    # the next step waits for a window twice as long
    ex.records = []
    _, _, notes = drive(ex, widths[:2 * runs], h_star, v)
    assert ex.count == 1 and ex.pending is None, notes
    ex.records = []
    h, it, _ = drive(ex, widths, h_star, v)
    assert ex.count == 2
    ex.step(h, it + CYCLE, ex.pending[3], 1e-6)
    assert ex.missed == 2 and not ex.enabled  # max_misses reached: no more steps this run


def test_a_step_paid_when_below_the_forecast(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, _ = drive(ex, widths, h_star, v)
    note = ex.step(h, it + CYCLE, 1e-3 * widths[-1], 1e-6)
    assert ex.missed == 0 and "paid" in note and ex.pending is None


def test_settle_undoes_a_step_no_certificate_judged(mode):
    h_star, v = mode
    ex = Extrapolator(h_star.size, True)
    widths = [LAM ** (CYCLE * c) for c in range(1, 10)]
    h, it, _ = drive(ex, widths, h_star, v)
    ex.settle(h, it)
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

"""The simulator's statistics against exact evaluation: interval coverage, the control variate,
AoI distributions and sample paths.

The reference numbers are exact: the policy's gain and AoI law from the stationary distribution of
its enumerated chain (``evaluate``, ``aoi_distribution``), never the simulator's own output.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wncs_lp.aoi import aoi_distribution
from wncs_lp.bounds import bound_policy, lower_bound
from wncs_lp.evaluate import evaluate
from wncs_lp.intervals import batch_means_interval, difference_interval, replication_interval, replications_agree
from wncs_lp.models import build
from wncs_lp.policies import System
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import load_scenario
from wncs_lp.simulate import simulate

FORMULATIONS = Path(__file__).resolve().parent.parent / "formulations"

GROUPS, PER_GROUP = 200, 10


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(FORMULATIONS / "paper_p12.toml", ["tau_cap=8", "p=0.8"])
    system, mdp = System.from_scenario(sc), build(sc)
    return system, mdp, lower_bound(system, 1)


@pytest.fixture(scope="module")
def greedy(p12):
    system, mdp, _ = p12
    pol = make_policy("greedy", system)
    return pol, evaluate(mdp, pol).gain


def _coverage(intervals, g):
    return float(np.mean([ci.contains(g) for ci in intervals]))


@pytest.mark.parametrize("controlled", [False, True], ids=["plain", "control-variate"])
def test_interval_coverage_over_200_independent_runs(p12, greedy, controlled):
    """200 independent runs of 10 replications x 600 slots (one vectorised simulation of 2,000
    replications, cut into 200 groups: the groups are independent as runs of 200 seeds are): the
    one-sided 95% upper limit covers the exact gain in 93-99% of them, and so does the lower one."""
    system, _, bound = p12
    pol, g = greedy
    res = simulate(pol, slots=600, reps=GROUPS * PER_GROUP, seed=11, burn_in=60,
                   control=bound.tables if controlled else None, progress=False)
    groups = np.asarray(res.rep_means).reshape(GROUPS, PER_GROUP)
    upper = _coverage([replication_interval(y, 0.95, "upper") for y in groups], g)
    lower = _coverage([replication_interval(y, 0.95, "lower") for y in groups], g)
    assert 0.93 <= upper <= 0.99, upper
    assert 0.93 <= lower <= 0.99, lower
    # batch means of one run each (the first 200 replications), batches merged until independent
    bm = [batch_means_interval(res.batch_sums[r], res.batch_sizes, 0.95, "two-sided") for r in range(GROUPS)]
    assert 0.92 <= _coverage(bm, g) <= 0.99
    # the agreement test of each group's replications raises no false alarm beyond its level
    sums = res.batch_sums.reshape(GROUPS, PER_GROUP, -1)
    assert np.mean([replications_agree(sums[i], res.batch_sizes) < 0.01 for i in range(GROUPS)]) <= 0.04
    if controlled:  # the control variate pays for itself here
        assert res.variance_reduction > 3


def test_control_variate_is_unbiased_against_exact_evaluation(p12):
    """Relaxation 1's tables are close to these policies' relative values at processes 1, 2: with
    them as control variate the bound's policy and two others are estimated to within 4 standard
    errors of their exact gains, standard errors over ten times smaller than the plain average's."""
    system, mdp, bound = p12
    for name in ("bound", "static", "suboptimal"):
        pol = bound_policy(bound, system) if name == "bound" else make_policy(name, system)
        g = evaluate(mdp, pol).gain
        res = simulate(pol, slots=1000, reps=10, seed=3, burn_in=100, control=bound.tables, progress=False)
        assert res.control == "ValueTables"
        assert abs(res.mean - g) <= 4 * res.stderr + 1e-9 * g, (name, res.mean, g, res.stderr)
        assert abs(res.plain_mean - g) <= 4 * res.plain_stderr, (name, res.plain_mean, g)
        assert res.variance_reduction > 100, (name, res.variance_reduction)
        assert res.interval(0.99, "two-sided").contains(g)


def test_control_variate_draws_no_random_numbers(p12, greedy):
    """The control, the batches, the AoI counts and the path change no simulated value: the plain
    average with a control is the average without one, bit for bit (same seed)."""
    system, _, bound = p12
    pol, _ = greedy
    a = simulate(pol, slots=300, reps=4, seed=5, burn_in=20, progress=False)
    b = simulate(pol, slots=300, reps=4, seed=5, burn_in=20, control=bound.tables, path=50, batches=7,
                 progress=False)
    assert a.plain_rep_means == b.plain_rep_means == a.rep_means
    assert a.process_means == b.process_means and a.utilisation == b.utilisation
    np.testing.assert_array_equal(a.aoi.pmf, b.aoi.pmf)
    assert b.batch_sums.shape == (4, 7) and b.batch_sizes.sum() == 300
    np.testing.assert_allclose(b.batch_sums.sum(axis=1) / 300, b.rep_means, rtol=1e-12)


def test_aoi_distribution_exact_and_simulated(p12, greedy):
    """The exact AoI law sums to 1 per process, its q-weighted sum is the process's exact average
    MSE, and the simulated frequencies match it within 5 standard errors (+ 2e-3)."""
    system, mdp, _ = p12
    pol, _ = greedy
    exact = aoi_distribution(mdp, pol)
    np.testing.assert_allclose(exact.pmf.sum(axis=1), 1.0, atol=1e-12)
    ev = evaluate(mdp, pol)
    for k in range(system.n_processes):
        cap = int(system.caps[k])
        assert exact.pmf[k, :cap] @ system.q[k][:cap] == pytest.approx(ev.mse[k], rel=1e-9)
    sim = simulate(pol, slots=3000, reps=20, seed=2, burn_in=200, progress=False).aoi
    np.testing.assert_allclose(sim.pmf.sum(axis=1), 1.0, atol=1e-12)
    assert sim.samples == 3000 * 20 and sim.how == "monte-carlo" and exact.how == "exact"
    assert np.all(np.abs(sim.pmf - exact.pmf) <= 5 * sim.stderr + 2e-3)
    # quantiles: the smallest x with F(x) >= q, read off the exact cdf directly
    F = np.cumsum(exact.pmf, axis=1)
    for q in (0.5, 0.9, 0.99):
        want = [int(np.flatnonzero(F[k] >= q - 1e-12)[0]) + 1 for k in range(system.n_processes)]
        assert exact.quantile(q).tolist() == want
    assert exact.quantile([0.5, 0.9]).shape == (system.n_processes, 2)
    np.testing.assert_allclose(exact.at_cap, exact.pmf[np.arange(2), system.caps - 1])
    assert "median" in repr(exact) and "<table>" in exact._repr_html_()


def test_sample_path_and_plots(p12, greedy):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    system, mdp, _ = p12
    pol, _ = greedy
    res = simulate(pol, slots=400, reps=3, seed=9, burn_in=0, path=120, progress=False)
    path = res.path
    assert path.tau.shape == (120, 2) and path.cost.shape == path.config.shape == path.action.shape == (120,)
    np.testing.assert_array_equal(path.tau[0], system.caps)  # burn-in 0: the path starts at the caps
    assert path.config[0] == system.initial_config
    cost = sum(system.q[k][path.tau[:, k] - 1] for k in range(2))
    np.testing.assert_allclose(path.cost, cost)
    # every step is one of the automaton's transitions: tau_k grows by one or drops to a delivery's age
    assert np.all((path.tau[1:] == np.minimum(path.tau[:-1] + 1, system.caps)) | (path.tau[1:] <= path.tau[:-1]))
    assert np.all(pol.act(path.tau, path.config) == path.action)
    fig, ax = plt.subplots()
    assert path.plot(ax=ax) is ax and len(ax.lines) == 2
    assert res.aoi.plot(show="cdf") is not None
    plt.close("all")
    text = repr(res)
    assert text.startswith("SimulationResult of greedy") and "upper_95" in text and "aoi" in text
    assert "<table>" in res._repr_html_()


def test_intervals_by_hand():
    """The replication interval is mean + t(0.95, R-1) s / sqrt(R); batch means of strongly
    autocorrelated data are merged until their lag-1 autocorrelation passes the test."""
    y = np.array([1.0, 2.0, 4.0, 3.0, 5.0])
    ci = replication_interval(y, 0.95, "upper")
    assert ci.upper == pytest.approx(3.0 + 2.131846786 * np.std(y, ddof=1) / np.sqrt(5), rel=1e-9)
    assert ci.lower == -np.inf and ci.df == 4
    from scipy.signal import lfilter

    rng = np.random.default_rng(0)
    x = lfilter([1.0], [1.0, -0.998], rng.normal(size=64 * 200))  # AR(1): correlated over ~1,000 steps
    bm = batch_means_interval(x.reshape(64, 200).sum(axis=1), np.full(64, 200), 0.95, "two-sided")
    assert bm.batches < 64 and bm.lag1 > 0
    iid = batch_means_interval(rng.normal(size=32), np.ones(32), 0.95, "two-sided")
    assert iid.batches == 32 and iid.df == 31
    # ten runs that agree, and the same runs with half of them settled 3 batch-sds higher
    runs = rng.normal(size=(10, 32))
    assert replications_agree(runs, np.ones(32)) > 0.01
    assert replications_agree(runs + np.repeat([0.0, 3.0], 5)[:, None], np.ones(32)) < 1e-6


def test_common_random_numbers_pair_two_policies(p12):
    """Two policies simulated with one seed share their channel outcomes: the paired interval for the
    difference of their gains is narrower than Welch's on the same runs, and covers the exact one."""
    system, mdp, bound = p12
    pols = [bound_policy(bound, system), make_policy("suboptimal", system)]
    g = [evaluate(mdp, p).gain for p in pols]
    a, b = (simulate(p, slots=1000, reps=40, seed=4, burn_in=100, progress=False) for p in pols)
    paired = a.compare(b)
    assert paired.method == "paired replications" and paired.contains(g[0] - g[1])
    welch = difference_interval(a.rep_means, b.rep_means, paired=False)
    assert welch.method == "welch" and paired.stderr < 0.9 * welch.stderr
    c = simulate(pols[1], slots=1000, reps=40, seed=5, burn_in=100, progress=False)
    assert a.compare(c).method == "welch"


def test_simulate_command(capsys):
    import json

    from wncs_lp.cli import main

    args = ["simulate", str(FORMULATIONS / "paper_p12.toml"), "--set", "tau_cap=8", "--set", "p=0.8", "--policy",
            "static", "--slots", "500", "--reps", "4", "--burn-in", "50"]
    assert main(args + ["--control-variate", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["control"] == "ValueTables" and out["variance_reduction"] > 1
    assert out["upper_95"] >= out["mean"] and len(out["plain_rep_means"]) == 4
    for proc in out["aoi"]["processes"]:
        assert sum(proc["pmf"]) == pytest.approx(1.0) and 1 <= proc["median"] <= proc["q99"] <= proc["cap"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "95% confidence interval [" in text and "one-sided 95% upper limit" in text and "99% quantile" in text


def test_uncapped_runs_count_their_aoi_in_a_bounded_histogram(p12, greedy):
    """Without the cap the system's caps are raised out of reach: the AoI histogram stops at
    AOI_BINS_MAX values (the last read "at least") and still sums to 1."""
    from wncs_lp.simulate import AOI_BINS_MAX
    from wncs_lp.untruncated import simulate_uncapped

    pol, _ = greedy
    res, _ = simulate_uncapped(pol, slots=1100, reps=2, seed=1, burn_in=30)  # caps raised to 1,139
    assert res.aoi.pmf.shape[1] == AOI_BINS_MAX and max(res.aoi.caps) == AOI_BINS_MAX
    np.testing.assert_allclose(res.aoi.pmf.sum(axis=1), 1.0)


def test_fitted_coefficient(p12, greedy):
    """control_coef="fit": the regression estimate is the least-squares intercept at control 0
    (scipy's linregress on the same numbers), with R - 2 degrees of freedom, and it agrees with
    the exact gain; the default coefficient 1 keeps R - 1."""
    from scipy import stats

    system, _, bound = p12
    pol, g = greedy
    fit = simulate(pol, slots=1000, reps=20, seed=2, burn_in=100, control=bound.tables, control_coef="fit",
                   progress=False)
    line = stats.linregress(fit.control_means, fit.plain_rep_means)
    assert fit.control_fitted and fit.control_coef == pytest.approx(-line.slope, rel=1e-9)
    assert fit.mean == pytest.approx(line.intercept, rel=1e-12)
    assert fit.stderr == pytest.approx(line.intercept_stderr, rel=1e-9)
    assert fit.interval().df == 18 and abs(fit.mean - g) <= 4 * fit.stderr
    one = simulate(pol, slots=1000, reps=20, seed=2, burn_in=100, control=bound.tables, progress=False)
    assert one.control_coef == 1.0 and not one.control_fitted and one.interval().df == 19
    np.testing.assert_allclose(one.rep_means, np.add(one.plain_rep_means, one.control_means), rtol=1e-13)

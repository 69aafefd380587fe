"""Studies on a Dask cluster of one's own (issue 26, "Dask, really"): a ``Client``, a scheduler address
(library and ``--scheduler``), a ``concurrent.futures`` executor. The numbers must be the serial run's
(same solves, another place), and the user's cluster must be left as it was."""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import distributed  # in the test extra: a missing Dask fails, it does not skip
import numpy as np
import pytest

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.errors import WncsError
from wncs_lp.scenario import ConstraintSpec, load_scenario
from wncs_lp.studies import read_rows, run_sweep, tradeoff


P12 = str(wncs_lp.scenario_path("paper_p12"))
POLICIES = ["optimal", "suboptimal"]
GRID = [0.8, 0.9]


@pytest.fixture(scope="module")
def cluster():
    """A real local cluster: two worker processes, no dashboard."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as c, distributed.Client(c) as client:
        yield c, client


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(P12, ["tau_cap=7"])


@pytest.fixture(scope="module")
def serial(scenario):
    return run_sweep(scenario, "p", GRID, POLICIES, None, plot=False)


def _gains(res):
    return sorted((r.value, r.policy, r.gain) for r in res.rows)


def _same(a, b):
    ka, kb = _gains(a), _gains(b)
    assert [k[:2] for k in ka] == [k[:2] for k in kb]
    np.testing.assert_allclose([k[2] for k in ka], [k[2] for k in kb], rtol=1e-9)


def test_a_sweep_on_ones_own_client_equals_the_serial_run(cluster, scenario, serial, tmp_path):
    _, client = cluster
    res = run_sweep(scenario, "p", GRID, POLICIES, tmp_path / "c", executor=client, plot=False)
    assert res.computed == 4 and all(r.status == "ok" for r in res.rows)
    _same(res, serial)
    assert len(read_rows(tmp_path / "c" / "sweep.csv")) == 4
    assert client.submit(sum, [1, 2]).result() == 3  # the user's client is still open


def test_a_sweep_on_a_scheduler_address_equals_the_serial_run(cluster, scenario, serial, tmp_path, capsys):
    c, client = cluster
    res = run_sweep(scenario, "p", GRID, POLICIES, None, executor=c.scheduler_address, plot=False)
    _same(res, serial)
    assert len(client.scheduler_info()["workers"]) == 2  # the cluster stays up
    assert main(["sweep", P12, "--set", "tau_cap=7", "--values", "0.8,0.9", "--policies", "optimal,suboptimal",
                 "--out", str(tmp_path / "cli"), "--no-plot", "--scheduler", c.scheduler_address, "--json"]) == 0
    capsys.readouterr()
    _same(type(serial)(rows=tuple(read_rows(tmp_path / "cli" / "sweep.csv")), out_dir=None), serial)


def test_a_tradeoff_on_ones_own_client_equals_the_serial_curve(cluster):
    _, client = cluster
    mdp = wncs_lp.build(load_scenario(P12, ["model.allow_idle=true", "tau_cap=7"]))
    remote = ConstraintSpec("send_rate", server=0, max=0.2, label="send_rate[remote] <= 0.2")
    grid = [0.05, 0.1, 0.2]
    on_cluster = tradeoff(mdp, [remote], 0, grid, method="lp", executor=client, plot=False)
    in_order = tradeoff(mdp, [remote], 0, grid, method="lp", warm=False, plot=False)
    assert [p.bound for p in on_cluster.points] == grid
    np.testing.assert_allclose(on_cluster.gains, in_order.gains, rtol=1e-9)


def test_a_concurrent_futures_executor_is_used_and_left_open(scenario, serial):
    with ThreadPoolExecutor(max_workers=2) as pool:
        res = run_sweep(scenario, "p", GRID, ["suboptimal"], None, executor=pool, plot=False)
        assert pool.submit(lambda: 7).result() == 7
    np.testing.assert_allclose(res.column("suboptimal"), serial.column("suboptimal"), rtol=1e-12)


@pytest.mark.parametrize("bad, words", [("threads", "unknown executor 'threads'"), (3, "unknown executor 3")])
def test_what_is_not_an_executor_is_named(bad, words, scenario):
    with pytest.raises(WncsError, match=words) as exc:
        run_sweep(scenario, "p", [0.9], ["optimal"], None, max_workers=2, executor=bad, plot=False)
    assert "Client" in str(exc.value) and "tcp://" in str(exc.value)


def test_a_scheduler_that_is_not_an_address_is_one_line(capsys, tmp_path):
    assert main(["sweep", P12, "--values", "0.9", "--out", str(tmp_path / "o"), "--scheduler", "localhost"]) == 2
    assert "expected a Dask scheduler address" in capsys.readouterr().err


def test_a_scheduler_that_does_not_answer_is_one_clear_error(monkeypatch, scenario):
    from wncs_lp.studies import executors

    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", 1)
    with pytest.raises(WncsError, match="no Dask scheduler answers at tcp://127.0.0.1:1"):
        run_sweep(scenario, "p", GRID, ["suboptimal"], None, executor="tcp://127.0.0.1:1", plot=False)

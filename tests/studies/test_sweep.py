"""Sweeps (table, resume, warm start, figure) and the evaluate / simulate / sweep commands."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from wncs_lp.cli import main
from wncs_lp.errors import WncsError
from wncs_lp.scenario import load_scenario
from wncs_lp.studies import COLUMNS, parse_values, read_rows, run_sweep

FORMULATIONS = Path(__file__).resolve().parents[2] / "formulations"
P12 = str(FORMULATIONS / "paper_p12.toml")


def test_parse_values():
    assert parse_values("0.8:1.0:0.05") == [0.8, 0.85, 0.9, 0.95, 1.0]
    assert parse_values("0.8,0.9") == [0.8, 0.9]
    for bad in ("0.8:1.0", "a,b", "1:2:0", ""):
        with pytest.raises(WncsError):
            parse_values(bad)


def _gains(rows):
    return [(r.value, r.policy, r.gain, r.sim_mean, r.status) for r in rows]


def test_sweep_table_resume_and_figure(tmp_path):
    sc = load_scenario(P12, ["tau_cap=6"])
    out = tmp_path / "sw"
    pols = ["optimal", "suboptimal", "static", "greedy", "random"]
    kw = dict(method="pi", simulate_slots=300, reps=3, burn_in=20, seed=3)
    first = run_sweep(sc, "p", "0.8:0.9:0.05", pols, out, **kw)
    assert first.computed == 15 and first.reused == 0
    assert [(r.value, r.policy) for r in first.rows] == [(v, p) for v in (0.8, 0.85, 0.9) for p in pols]
    for v in (0.8, 0.85, 0.9):
        g = {r.policy: r.gain for r in first.rows if r.value == v}
        assert g["optimal"] <= g["suboptimal"] * (1 + 1e-9) <= g["random"] * (1 + 1e-9)
        assert g["optimal"] <= min(g["static"], g["greedy"]) * (1 + 1e-9)
    # warm start of the optimal solve from the previous grid value
    assert [r.warm_start for r in first.rows if r.policy == "optimal"] == [False, True, True]
    # files: CSV with the documented columns, JSON with the same rows, figure
    with open(out / "sweep.csv", newline="") as fh:
        recs = list(csv.DictReader(fh))
    assert tuple(recs[0].keys()) == COLUMNS and len(recs) == 15
    payload = json.loads((out / "sweep.json").read_text())
    assert len(payload["rows"]) == 15 and payload["settings"]["param"] == "p"
    assert (out / "sweep.png").stat().st_size > 0 and (out / "sweep.svg").stat().st_size > 0

    # interrupted run: delete one row and truncate the last one
    lines = (out / "sweep.csv").read_text().splitlines(keepends=True)
    deleted = lines.pop(4)  # the 4th data row
    lines[-1] = lines[-1][: len(lines[-1]) // 2]  # a half-written last row
    (out / "sweep.csv").write_text("".join(lines))
    assert len(read_rows(out / "sweep.csv")) == 13
    again = run_sweep(sc, "p", "0.8:0.9:0.05", pols, out, **kw)
    assert again.computed == 2 and again.reused == 13
    assert _gains(again.rows) == _gains(first.rows)
    # untouched rows are the stored ones (their timings are kept, not recomputed)
    seconds_first = {(r.value, r.policy): r.seconds for r in first.rows}
    recomputed = {(r.value, r.policy) for r in again.rows if r.seconds != seconds_first[(r.value, r.policy)]}
    assert recomputed == {(float(deleted.split(",")[1]), deleted.split(",")[2]), (0.9, "random")}
    # a complete folder is not recomputed at all
    third = run_sweep(sc, "p", "0.8:0.9:0.05", pols, out, **kw)
    assert third.computed == 0 and _gains(third.rows) == _gains(first.rows)
    # other settings in the same folder: a clear error
    with pytest.raises(WncsError, match="other settings"):
        run_sweep(sc, "p", "0.8:0.9:0.05", pols, out, method="rvi", simulate_slots=300, reps=3, burn_in=20, seed=3)


def test_sweep_p_one_and_parallel(tmp_path):
    """p = 1: PI meets multichain iterates (RVI fallback) and static policies are multichain."""
    sc = load_scenario(P12, ["tau_cap=6"])
    res = run_sweep(sc, "p", [0.95, 1.0], ["optimal", "static", "suboptimal"], tmp_path / "a", max_workers=2,
                    plot=False)
    assert res.computed == 6
    assert all(r.status.startswith("ok") for r in res.rows)
    g1 = {r.policy: r.gain for r in res.rows if r.value == 1.0}
    assert g1["optimal"] <= g1["static"] * (1 + 1e-9) and g1["optimal"] <= g1["suboptimal"] * (1 + 1e-9)
    seq = run_sweep(sc, "p", [0.95, 1.0], ["optimal", "static", "suboptimal"], None, plot=False)
    np.testing.assert_allclose([r.gain for r in seq.rows], [r.gain for r in res.rows], rtol=1e-9)


def test_sweep_on_dask_matches_sequential(tmp_path, monkeypatch, capfd):
    """The Dask executor (a local cluster of its own, 2 worker processes) gives the sequential table;
    its cluster takes no dashboard port (one may be running already) and closes without a traceback."""
    import distributed  # in the test extra: a missing Dask fails, it does not skip

    made = {}
    real = distributed.LocalCluster

    def spy(*a, **kw):
        made.update(kw)
        return real(*a, **kw)

    monkeypatch.setattr(distributed, "LocalCluster", spy)
    sc = load_scenario(P12, ["tau_cap=6"])
    pols = ["optimal", "suboptimal"]
    res = run_sweep(sc, "p", [0.85, 0.95], pols, tmp_path / "d", max_workers=2, executor="dask", plot=False)
    assert made["dashboard_address"] is None and made["n_workers"] == 2
    err = capfd.readouterr().err
    assert "Traceback" not in err and "CommClosedError" not in err and "8787" not in err
    assert res.computed == 4 and all(r.status.startswith("ok") for r in res.rows)
    seq = run_sweep(sc, "p", [0.85, 0.95], pols, None, plot=False)
    key = lambda r: (r.value, r.policy)  # noqa: E731
    np.testing.assert_allclose([r.gain for r in sorted(res.rows, key=key)],
                               [r.gain for r in sorted(seq.rows, key=key)], rtol=1e-9)
    assert len(read_rows(tmp_path / "d" / "sweep.csv")) == 4


def test_unknown_executor_is_a_clear_error():
    with pytest.raises(WncsError, match="unknown executor 'threads'"):
        run_sweep(load_scenario(P12, ["tau_cap=4"]), "p", [0.9], ["optimal"], None, max_workers=2,
                  executor="threads", plot=False)


def test_plot_returns_axes():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wncs_lp.viz import plot_sweep

    sc = load_scenario(P12, ["tau_cap=5"])
    res = run_sweep(sc, "p", [0.8, 0.9], ["suboptimal", "random"], None, plot=False)
    fig, ax = plt.subplots()
    assert plot_sweep(res.rows, ax=ax) is ax
    assert len(ax.get_lines()) == 2
    plt.close(fig)


# ----------------------------------------------------------------------------- CLI
def _json_out(capsys):
    out = capsys.readouterr().out
    return json.loads(out)  # exactly one JSON object, nothing else on stdout


def test_cli_evaluate_json(capsys):
    rc = main(["evaluate", P12, "--policy", "suboptimal", "--set", "tau_cap=6", "--json"])
    data = _json_out(capsys)
    assert rc == 0
    assert {"gain", "mse", "utilisation", "states"} <= set(data)
    assert data["policy_info"]["base_gain"] > data["gain"]


def test_cli_evaluate_static_assignment(capsys):
    rc = main(["evaluate", P12, "--policy", "static", "--assignment", "edge,remote", "--set", "tau_cap=5", "--json"])
    data = _json_out(capsys)
    assert rc == 0 and data["policy"] == "static[edge,remote]"


def test_cli_simulate_json(capsys):
    rc = main(["simulate", P12, "--policy", "greedy", "--set", "tau_cap=10", "--slots", "400", "--reps", "3",
               "--seed", "5", "--burn-in", "10", "--json"])
    data = _json_out(capsys)
    assert rc == 0
    assert {"mean", "stderr", "rep_means", "slots", "reps", "seed", "burn_in"} <= set(data)
    assert data["slots"] == 400 and data["reps"] == 3 and len(data["rep_means"]) == 3


def test_cli_simulate_optimal(capsys):
    rc = main(["simulate", P12, "--policy", "optimal", "--method", "pi", "--set", "tau_cap=6", "--slots", "200",
               "--reps", "2", "--json"])
    assert rc == 0 and _json_out(capsys)["policy"] == "optimal"


@pytest.mark.parametrize("cmd", [
    ["evaluate", P12, "--policy", "bogus"],
    ["simulate", P12, "--policy", "bogus", "--slots", "10"],
    ["sweep", P12, "--values", "0.8", "--policies", "optimal,bogus", "--out", "unused"],
])
def test_cli_bad_policy_exit_2(cmd, capsys, tmp_path):
    if cmd[0] == "sweep":
        cmd = cmd[:-1] + [str(tmp_path / "unused")]
    rc = main(cmd + ["--json"])
    err = capsys.readouterr()
    assert rc == 2
    # under --json the error is also one JSON object on stdout (issue 16), and one line on stderr
    assert json.loads(err.out)["type"] == "PolicyError"
    assert "unknown policy 'bogus'" in err.err and "optimal" in err.err


def test_cli_sweep_json(capsys, tmp_path):
    rc = main(["sweep", P12, "--set", "tau_cap=5", "--param", "p", "--values", "0.8:0.9:0.1", "--policies",
               "optimal,greedy", "--out", str(tmp_path / "s"), "--no-plot", "--json"])
    data = _json_out(capsys)
    assert rc == 0 and len(data["rows"]) == 4 and data["computed"] == 4
    assert (tmp_path / "s" / "sweep.csv").exists()


def test_a_warm_started_sweep_closes_every_certificate_like_a_cold_solve():
    """The reproduction's C3 sweep walks p on processes 1, 2 by relative value iteration, each
    point warm-started from the previous bias. At cap 16, p = 0.85 the warm start used to end
    "inaccurate:precision" (the progress line's "error:") where a cold solve closed: the computed
    width had just crossed the tolerance while width + round-off band had not, and the closing
    rule sent that to the precision stop although the band (2 delta / g ~ 1e-13) was far below
    the tolerance (1e-9). The closing rule now goes on until width + band fits (iteration.py).
    Every row must be "ok" and its gain that of a cold solve by another scheme (Gauss-Seidel
    value iteration, as ``wncs-lp solve`` runs it), within both certificates (1e-9)."""
    from wncs_lp import build
    from wncs_lp import solve

    sc = load_scenario(P12, ["tau_cap=16"])
    res = run_sweep(sc, "p", [0.8, 0.85], ["optimal"], method="rvi")
    assert [r.warm_start for r in res.rows] == [False, True]
    for r in res.rows:
        assert r.status == "ok", (r.value, r.status)
        ref = solve(build(sc.with_overrides({"p": r.value})), "vi")
        assert ref.status == "optimal"
        assert r.gain == pytest.approx(ref.gain, rel=2e-9)


def test_a_resumed_sweep_computes_an_error_row_again(tmp_path, monkeypatch):
    """A row kept with an error status (here a planted "inaccurate:precision" stop) is not reused on
    resume: the next run solves it again and its status is the new solve's."""
    import dataclasses

    import wncs_lp.studies.sweep as sweep_mod

    sc = load_scenario(P12, ["tau_cap=7"])
    out = tmp_path / "sw"
    real = sweep_mod.run_scenario

    def stops_short(*a, **k):
        run = real(*a, **k)
        return dataclasses.replace(run, solution=dataclasses.replace(run.solution, status="inaccurate:precision"))

    monkeypatch.setattr(sweep_mod, "run_scenario", stops_short)
    first = run_sweep(sc, "p", [0.9], ["optimal", "static"], out, method="vi", plot=False)
    assert [r.status for r in first.rows] == ["error: solver status inaccurate:precision", "ok"]
    monkeypatch.setattr(sweep_mod, "run_scenario", real)
    lines = []
    again = run_sweep(sc, "p", [0.9], ["optimal", "static"], out, method="vi", plot=False, log=lines.append)
    assert again.computed == 1 and again.reused == 1
    assert [r.status for r in again.rows] == ["ok", "ok"]
    assert again.rows[0].gain == pytest.approx(first.rows[0].gain, rel=1e-9)  # the same solve, now closed
    assert any("error status computed again" in line for line in lines)
    assert [r.status for r in read_rows(out / "sweep.csv")] == ["ok", "ok"]

"""A resumed study never trusts a row it cannot verify (issue 27, items 2, 4 and 8).

Each test builds the hostile folder (the meta file deleted or garbled, a row edited by hand, a
phantom row, a duplicated key, a row of an older format, two runs at once) and checks that the
rows then reported are the true ones: the optimal gain against certified value iteration on the
scenario of that grid value, solved on its own.
"""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

import wncs_lp
from wncs_lp import solve
from wncs_lp.scenario import ConstraintSpec, load_scenario
from wncs_lp.studies import read_points, read_rows, run_sweep, tradeoff

ROOT = Path(__file__).resolve().parents[2]
P12 = str(wncs_lp.scenario_path("paper_p12"))
KW = dict(plot=False)


def truth(scenario, value: float) -> wncs_lp.Solution:
    """Certified value iteration on the scenario of one grid value, outside any sweep."""
    return wncs_lp.solve(wncs_lp.build(scenario.with_overrides({"p": value})), "vi")


def within(sol, gain: float) -> bool:
    slack = 1e-8 * abs(sol.gain)
    return sol.gain_lower - slack <= gain <= sol.gain_upper + slack


def _csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _write(path: Path, header: list[str], rows: list[list[str]]) -> None:
    with open(path, "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows([header, *rows])


@pytest.fixture(scope="module")
def a():
    return load_scenario(P12, ["tau_cap=7"])


@pytest.fixture(scope="module")
def b():
    return load_scenario(P12, ["tau_cap=7", "process.1.weight=3"])


@pytest.mark.parametrize("meta", ["deleted", "garbled"])
def test_another_scenarios_rows_are_recomputed_when_the_meta_file_is_gone(tmp_path, a, b, meta):
    out = tmp_path / "s"
    first = run_sweep(a, "p", [0.8, 0.9], ["optimal", "greedy"], out, **KW)
    if meta == "deleted":
        (out / "sweep_meta.json").unlink()
    else:
        (out / "sweep_meta.json").write_text("{not json")
    second = run_sweep(b, "p", [0.8, 0.9], ["optimal", "greedy"], out, **KW)
    assert second.computed == 4 and second.reused == 0 and second.dropped == 4
    for v in (0.8, 0.9):
        g = {r.policy: r.gain for r in second.rows if r.value == v}
        assert within(truth(b, v), g["optimal"])
        assert not within(truth(a, v), g["optimal"])  # the other scenario's gain is not reported
    old = {r.gain for r in first.rows}
    assert not old & {r.gain for r in read_rows(out / "sweep.csv")}  # and not kept in the table either
    third = run_sweep(b, "p", [0.8, 0.9], ["optimal", "greedy"], out, **KW)
    assert third.computed == 0 and third.reused == 4  # its own rows are reused


@pytest.mark.parametrize("edit", ["gain", "states", "fingerprint", "phantom", "duplicate"])
def test_an_edited_phantom_or_duplicated_row_is_recomputed(tmp_path, a, edit):
    out = tmp_path / "s"
    grid = [0.8, 0.9]
    run_sweep(a, "p", grid, ["optimal"], out, **KW)
    header, rows = _csv(out / "sweep.csv")
    col = {c: i for i, c in enumerate(header)}
    if edit == "gain":
        rows[0][col["gain"]] = "1.0"
    elif edit == "states":
        rows[0][col["states"]] = "-5"
    elif edit == "fingerprint":
        rows[0][col["fingerprint"]] = "0" * 20
    elif edit == "phantom":  # a row on the grid that no run computed: 0.85, with 0.8's fingerprint
        rows.insert(1, [*rows[0][:1], "0.85", *rows[0][2:]])
        grid = [0.8, 0.85, 0.9]
    else:
        rows.append(list(rows[0]))
    _write(out / "sweep.csv", header, rows)
    again = run_sweep(a, "p", grid, ["optimal"], out, **KW)
    assert again.computed == 1 and again.reused == len(grid) - 1
    for r in again.rows:
        assert within(truth(a, r.value), r.gain) and r.states > 0
    assert len(read_rows(out / "sweep.csv")) == len(grid)  # one row per key, each sealed


def test_a_row_without_a_fingerprint_is_not_reused(tmp_path, a):
    out = tmp_path / "s"
    run_sweep(a, "p", [0.8], ["optimal"], out, **KW)
    header, rows = _csv(out / "sweep.csv")  # the table as an older version wrote it: no fingerprint column
    _write(out / "sweep.csv", header[:-1], [r[:-1] for r in rows])
    again = run_sweep(a, "p", [0.8], ["optimal"], out, **KW)
    assert again.computed == 1 and again.reused == 0


def test_tradeoff_does_not_reuse_another_scenarios_points(tmp_path):
    remote = ConstraintSpec("send_rate", server=0, max=0.2, label="send_rate[remote] <= 0.2")

    def mdp(p: float):
        return wncs_lp.build(load_scenario(P12, ["model.allow_idle=true", "tau_cap=7", f"p={p}"]))

    out = tmp_path / "t"
    tradeoff(mdp(0.9), [remote], 0, [0.1, 0.2], method="lp", out=out, **KW)
    (out / "tradeoff_meta.json").unlink()
    m7 = mdp(0.7)
    res = tradeoff(m7, [remote], 0, [0.1, 0.2], method="lp", out=out, **KW)
    assert res.computed == 2 and res.reused == 0
    for p in res.points:  # the point of p = 0.7, against a cold constrained solve of it
        direct = solve(m7, "lp-cvxpy", constraints=[ConstraintSpec("send_rate", server=0, max=p.bound)])
        assert p.gain == pytest.approx(direct.gain, rel=1e-7)
    # the reference optimum is p = 0.7's too (certified value iteration on the unconstrained MDP)
    vi = wncs_lp.solve(m7, "vi")
    assert vi.gain_lower * (1 - 1e-8) <= res.unconstrained_gain <= vi.gain_upper * (1 + 1e-8)
    header, rows = _csv(out / "tradeoff.csv")
    rows[0][header.index("gain")] = "1.0"
    _write(out / "tradeoff.csv", header, rows)
    again = tradeoff(m7, [remote], 0, [0.1, 0.2], method="lp", out=out, **KW)
    assert again.computed == 1 and again.reused == 1
    assert [p.gain for p in read_points(out / "tradeoff.csv")] == [p.gain for p in res.points]


def test_two_sweeps_with_different_values_at_once_keep_both_sets_of_rows(tmp_path):
    out = tmp_path / "shared"
    base = [sys.executable, "-m", "wncs_lp", "sweep", P12, "--set", "tau_cap=7", "--policies", "optimal,greedy",
            "--no-plot", "--out", str(out), "--values"]
    procs = [subprocess.Popen(base + [grid], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT)
             for grid in ("0.7:0.8:0.05", "0.85:0.95:0.05")]
    errs = [p.communicate(timeout=600)[1].decode() for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    rows = read_rows(out / "sweep.csv")
    assert sorted({r.value for r in rows}) == [0.7, 0.75, 0.8, 0.85, 0.9, 0.95]
    assert len(rows) == 6 * 2

"""The size guard: its estimate bounds the true size from above, tightly; refusals are clear."""
from __future__ import annotations

import pytest

from wncs_lp import build, load_scenario, scenario_path
from wncs_lp.errors import WncsError
from wncs_lp.models.guard import SizeLimitError, check_size, estimate_size

CASES = [
    ("paper_p12.toml", []),
    ("paper_p14.toml", ["tau_cap=15"]),
    ("paper_p123.toml", ["tau_cap=6"]),
    ("paper_preemption_p12.toml", ["tau_cap=8"]),
    ("paper_p1234.toml", ["tau_cap=4"]),
    ("paper_p12.toml", ["p=1", "model.allow_idle=true"]),
]


@pytest.mark.parametrize("name, overrides", CASES)
def test_estimate_is_a_tight_upper_bound(name, overrides):
    sc = load_scenario(scenario_path(name), overrides)
    est = estimate_size(sc)
    mdp = build(sc)
    assert est.states >= mdp.n_states and est.pairs >= mdp.n_pairs and est.nnz >= mdp.P.nnz
    assert est.states <= 1.1 * mdp.n_states
    assert est.pairs <= 1.1 * mdp.n_pairs
    assert est.nnz <= 1.1 * mdp.P.nnz
    assert est.configs == mdp.meta["n_configs"]


def test_refusal_names_the_estimate_and_cheaper_routes():
    sc = load_scenario(scenario_path("paper_p1234.toml"), ["tau_cap=40"])
    with pytest.raises(SizeLimitError) as info:
        check_size(sc, limit_bytes=1 << 30)
    msg = str(info.value)
    assert isinstance(info.value, WncsError)
    assert "paper_p1234.toml" in msg and "states" in msg and "--force" in msg
    assert "suboptimal policy" in msg and "smaller cap" in msg
    est = info.value.estimate
    assert est.states > 40**4  # the box alone is 2.56 million AoI vectors, times busy configurations
    # forced: the estimate is returned, nothing raised
    assert check_size(sc, force=True, limit_bytes=1).states == est.states


def test_lp_needs_more_than_value_iteration():
    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=30"])
    est = estimate_size(sc)
    limit = est.build_bytes + est.lp_bytes // 2
    check_size(sc, limit_bytes=limit)  # DP fits
    with pytest.raises(SizeLimitError, match="value iteration"):
        check_size(sc, limit_bytes=limit, need_lp=True)


def test_cli_refuses_a_huge_build_with_one_clear_line():
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "wncs_lp", "solve", str(scenario_path("paper_p1234.toml")),
                           "--set", "tau_cap=40", "--method", "vi", "--json"],  # auto would go matrix-free
                          capture_output=True, text=True, timeout=120)
    import json

    # under --json the error is also one JSON object on stdout (issue 16)
    assert proc.returncode == 2 and json.loads(proc.stdout)["type"] == "SizeLimitError"
    assert proc.stderr.startswith("error: ") and "--force" in proc.stderr and "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------- issue 27
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402

from wncs_lp import scenario_from_dict  # noqa: E402
from wncs_lp.models import automaton, guard, model_for  # noqa: E402
from wncs_lp.models.automaton import ExplorationLimitError  # noqa: E402


def _cli_under_rlimit(args: list[str], limit: int) -> subprocess.CompletedProcess:
    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return subprocess.run([sys.executable, "-m", "wncs_lp", *args], capture_output=True, text=True, timeout=240,
                          preexec_fn=cap)


@pytest.mark.parametrize("method, cap, gib", [("vi", 18, 8), ("matrix-free", 45, 8), ("vi", 16, 3)])
def test_the_guard_honours_the_address_space_limit(method, cap, gib):
    # under prlimit --as=8G the build (7.9 GiB estimated) and the matrix-free vectors (14 GiB) cannot fit:
    # refused up front, naming the limit, instead of running minutes into a MemoryError
    proc = _cli_under_rlimit(["solve", str(scenario_path("paper_p1234.toml")), "--set", f"tau_cap={cap}",
                              "--method", method, "--json"], gib << 30)
    out = json.loads(proc.stdout)
    assert proc.returncode == 2 and out["type"] == "SizeLimitError", proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    if guard.memory_limits()["available memory"] > (gib + 1) << 30:  # else the machine's memory binds first
        assert "RLIMIT_AS" in out["error"], out["error"]


def test_available_memory_is_the_smallest_limit(monkeypatch):
    import resource as res

    real = res.getrlimit
    monkeypatch.setattr(res, "getrlimit", lambda which: (3 << 30, res.RLIM_INFINITY) if which == res.RLIMIT_AS
                        else real(which))
    limits = guard.memory_limits()
    assert 0 <= limits["RLIMIT_AS"] < 3 << 30  # less what the process already maps
    assert guard.available_memory() == min(limits.values()) <= limits["RLIMIT_AS"]


@pytest.mark.parametrize("version", [1, 2])
def test_cgroup_limits_are_read_up_the_hierarchy(tmp_path, version):
    (tmp_path / "proc/self").mkdir(parents=True)
    if version == 1:
        (tmp_path / "proc/self/cgroup").write_text("5:cpu:/\n4:memory:/job/step\n")
        base, names = tmp_path / "sys/fs/cgroup/memory", ("memory.limit_in_bytes", "memory.usage_in_bytes",
                                                          "total_inactive_file")
    else:
        (tmp_path / "proc/self/cgroup").write_text("0::/job/step\n")
        base, names = tmp_path / "sys/fs/cgroup", ("memory.max", "memory.current", "inactive_file")
    for folder, limit, usage, cache in ((base / "job/step", "max" if version == 2 else str(1 << 62), 100, 0),
                                        (base / "job", str(5 << 30), 3 << 30, 1 << 30)):
        folder.mkdir(parents=True, exist_ok=True)
        (folder / names[0]).write_text(limit + "\n")
        (folder / names[1]).write_text(f"{usage}\n")
        (folder / "memory.stat").write_text(f"anon 1\n{names[2]} {cache}\n")
    # the parent's 5 GiB limit binds: 5 - 3 used + 1 of reclaimable cache
    assert guard._cgroup_headroom(tmp_path) == 3 << 30
    assert guard._cgroup_headroom(tmp_path / "nowhere") is None


def _many(n: int, cap: int):
    raw = load_scenario(scenario_path("paper_p12.toml")).to_dict()
    raw["process"] = [{"name": f"p{i}", "A": [[1.02]], "tau_cap": cap} for i in range(n)]
    return scenario_from_dict(raw)


def _explored(monkeypatch):
    """Fail when a model's automaton is explored."""
    def no(self):
        raise AssertionError("the automaton was explored")

    for cls in {type(model_for(_many(1, 2))), type(model_for(load_scenario(
            scenario_path("paper_preemption_p12.toml"))))}:
        monkeypatch.setattr(cls, "explore", no)


def test_no_int64_wrap_around_and_no_exploration_for_a_box_of_8_to_the_21(monkeypatch):
    sc = _many(21, 8)
    _explored(monkeypatch)
    for method in (None, "matrix-free"):
        with pytest.raises(SizeLimitError) as info:
            check_size(sc, method=method)
        msg = str(info.value)
        assert "9.22e18" in msg and "-" not in msg.split("GiB")[0].split("at least")[-1], msg
        assert info.value.estimate.box == 8**21 and not info.value.estimate.complete


def test_the_cli_refuses_21_processes_in_one_line(tmp_path, capsys):
    from wncs_lp.cli import main

    f = tmp_path / "p21.toml"
    text = scenario_path("paper_p12.toml").read_text().split("[[process]]")[0]
    text += "".join(f'[[process]]\nname = "p{i}"\nA = [[1.02]]\ntau_cap = 8\n' for i in range(21))
    text += "[[server]]" + scenario_path("paper_p12.toml").read_text().split("[[server]]", 1)[1]
    f.write_text(text)
    # (--method vi: auto would try the matrix-free route, whose own guard refuses it too)
    assert main(["solve", str(f), "--method", "vi", "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["type"] == "SizeLimitError" and "9.22e18" in out["error"] and "before its automaton" in out["error"]


def test_a_thousand_processes_are_refused_before_exploring(monkeypatch):
    _explored(monkeypatch)
    for cap in (8, 1):  # cap 1: a box of one vector, but 999,000 actions in the idle configuration
        with pytest.raises(SizeLimitError, match="before its automaton is even explored|exploration budget"):
            check_size(_many(1000, cap))


def test_long_delays_stop_at_the_exploration_budget_with_the_bound(monkeypatch):
    monkeypatch.setattr(automaton, "MAX_WORK", 2_000_000)  # a smaller budget keeps the test fast
    sc = load_scenario(scenario_path("paper_p12.toml"), ["server.remote.uplink_delay=10000", "tau_cap=8"])
    with pytest.raises(ExplorationLimitError) as info:
        check_size(sc)
    msg = str(info.value)
    assert "paper_p12.toml" in msg and "exploration budget" in msg and "upper bound" in msg and "--force" in msg
    assert info.value.places > 10_000 and info.value.explored <= 2_000_000 // 10_100 + 1
    # the same budget everywhere the automaton is explored (not only behind the guard)
    with pytest.raises(ExplorationLimitError):
        model_for(sc).automaton
    monkeypatch.setattr(automaton, "MAX_CONFIGS", 300)
    sc = load_scenario(scenario_path("paper_p123.toml"), ["server.remote.uplink_delay=8", "tau_cap=8"])
    with pytest.raises(ExplorationLimitError, match="stopped at 300 configurations"):
        check_size(sc)
    with automaton.exploration_limit(None):  # force lifts it
        assert len(model_for(sc).automaton.configs) > 300


@pytest.mark.parametrize("name, overrides", CASES + [("paper_p12.toml", ["server.remote.uplink_delay=4"]),
                                                     ("paper_preemption_p12.toml", ["tau_cap=5",
                                                                                    "server.1.downlink_delay=2"])])
def test_automaton_bounds_hold(name, overrides):
    sc = load_scenario(scenario_path(name), overrides)
    model = model_for(sc)
    b, auto = model.automaton_bounds(), model.automaton
    assert b.configs >= len(auto.configs) and b.initial == len(auto.initial)
    first = auto.initial[0]
    assert b.edges_initial <= sum(len(o) for o in auto.outcomes[first])


def test_the_guard_counts_the_matrix_free_bytes_of_the_solver():
    # the guard cannot import the solver (solvers import models): the two accountings must agree
    from wncs_lp.solvers.matrix_free import matrix_free_bytes

    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=9"])
    est = estimate_size(sc)
    assert est.matrix_free_bytes - guard.MATRIX_FREE_OVERHEAD == matrix_free_bytes(est.matrix_free_states, mask=True)


def test_validate_says_whether_the_matrix_free_solve_fits_and_with_how_many_vectors(capsys):
    from dataclasses import replace

    from wncs_lp.cli import main
    from wncs_lp.models.guard import matrix_free_fit
    from wncs_lp.solvers.matrix_free import matrix_free_bytes

    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=9"])
    est = estimate_size(sc)
    n = est.matrix_free_states
    # the solver's own accounting: the floor has one value vector, the full solve two
    assert est.matrix_free_full_bytes - guard.MATRIX_FREE_OVERHEAD == matrix_free_bytes(n, vectors=2, mask=True)
    # the verdicts against the available memory (the floor within 90% of it, the second vector
    # with a quarter to spare beside the floor), on sizes where the fixed overhead does not decide
    big = replace(est, matrix_free_bytes=10 << 30, matrix_free_full_bytes=18 << 30)
    assert matrix_free_fit(big, 30 << 30).endswith("fits with both vectors")
    assert "fits with one vector only" in matrix_free_fit(big, 19 << 30)
    assert "does not fit" in matrix_free_fit(big, 11 << 30)
    assert main(["validate", "paper_p12", "--set", "tau_cap=9"]) == 0
    out = capsys.readouterr().out
    assert f"matrix-free solver: {n:,} states" in out and "one value vector" in out

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

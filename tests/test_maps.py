"""Tests of the policy maps (wncs_lp/policy_grids.py) and the ``wncs-lp map`` command."""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from wncs_lp.cli import main  # noqa: E402
from wncs_lp.errors import ModelError  # noqa: E402
from wncs_lp.policy_grids import (  # noqa: E402
    action_name,
    parse_config_spec,
    policy_grid,
    region_stats,
    slice_grid,
)
from wncs_lp.viz import plot_policy_map, plot_policy_slice  # noqa: E402
from wncs_lp.models import build  # noqa: E402
from wncs_lp.models.preemption import PreemptionConfig  # noqa: E402
from wncs_lp.models.wncs import idle_config  # noqa: E402
from wncs_lp.scenario import load_scenario  # noqa: E402
from wncs_lp import solve  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
F = ROOT / "formulations"


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(F / "paper_p12.toml", ["tau_cap=6"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


@pytest.fixture(scope="module")
def p123():
    sc = load_scenario(F / "paper_p123.toml", ["tau_cap=5"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


@pytest.fixture(scope="module")
def pre():
    sc = load_scenario(F / "paper_preemption_p12.toml", ["tau_cap=6"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


def legend_texts(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


# ============================================================================ region_stats
def test_region_stats_known_grid():
    lab = np.zeros((5, 5), dtype=int)
    lab[2, 2] = 1  # an island of action 1: one hole in the region of action 0
    lab[0, 4] = 2
    lab[4, 0] = 2  # action 2: two separate corners
    r = region_stats(lab)
    pa = r["per_action"]
    assert r["connectivity"] == "grid4" and r["cells"] == 25 and r["actions_present"] == 3
    assert pa["0"]["components"] == 1 and pa["0"]["holes"] == 1 and not pa["0"]["simply_connected"]
    assert pa["1"] == {**pa["1"], "cells": 1, "components": 1, "connected": True, "holes": 0, "simply_connected": True}
    assert pa["2"]["components"] == 2 and not pa["2"]["connected"] and pa["2"]["component_sizes"] == [1, 1]
    assert r["regions_total"] == 4


def test_region_stats_triangular_lattice_and_unreachable():
    lab = np.array([[0, 1], [1, 0]])
    grid, tri = region_stats(lab, connectivity="grid4"), region_stats(lab, connectivity="tri6")
    # (0,1)-(1,0) differ by (+1,-1): neighbours on the triangular lattice, not on the grid
    assert grid["per_action"]["1"]["components"] == 2 and tri["per_action"]["1"]["components"] == 1
    assert grid["per_action"]["0"]["components"] == 2 and tri["per_action"]["0"]["components"] == 2
    assert tri["per_action"]["0"]["components_grid8"] == 1
    r = region_stats(np.array([[0, -1, 0], [-2, -2, -2]]))
    assert r["cells"] == 3 and r["unreachable"] == 1
    assert r["per_action"]["0"]["components"] == 2 and r["per_action"]["0"]["components_bridging_unreachable"] == 1
    with pytest.raises(ModelError, match="connectivity"):
        region_stats(lab, connectivity="hex")


def test_region_stats_of_a_map_counts_cells(p12):
    sc, mdp, sol = p12
    A, S, _ = policy_grid(mdp, sol, "idle")
    r = region_stats(mdp, sol, "idle", scenario=sc)
    assert sum(v["cells"] for v in r["per_action"].values()) == int((A >= 0).sum())
    assert all(name.startswith("(") and " to " in name for name in r["per_action"])


# ============================================================================ configurations
def test_parse_config_spec_forms(p123, pre):
    sc, mdp, _ = p123
    idle = mdp.states.config_id(idle_config(sc))
    assert parse_config_spec(mdp, "idle") == idle
    assert parse_config_spec(mdp, f"#{idle}") == idle
    assert parse_config_spec(mdp, idle_config(sc)) == idle
    assert parse_config_spec(mdp, repr(idle_config(sc))) == idle
    busy = parse_config_spec(mdp, "edge: job 3 d=3")
    assert parse_config_spec(mdp, "remote: idle;  EDGE: job 3 d=3") == busy
    assert mdp.states.describe_config(mdp.states.configs[busy]) == "remote: idle; edge: job 3 d=3"
    with pytest.raises(ModelError, match="close matches"):
        parse_config_spec(mdp, "edge: job 3 d=9")
    _, mdp2, _ = pre
    cfg = PreemptionConfig((1, 0), (2, 2, 2), (), (None,))
    c = parse_config_spec(mdp2, "b=10 | serving 2(d=2,g=2) | down [-]")
    assert mdp2.states.configs[c] == cfg
    assert parse_config_spec(mdp2, "((1, 0), (2, 2, 2), (), (None,))") == c
    with pytest.raises(ModelError, match="ambiguous"):
        parse_config_spec(mdp2, "idle")


def test_action_names(p12, pre):
    sc, mdp, _ = p12
    labels = {action_name(mdp, a, scenario=sc) for a in range(mdp.action_table.shape[0])}
    assert "(1 to remote, 2 to edge)" in labels and "(2 to remote, 1 to edge)" in labels
    assert "(1 to edge)" in labels
    _, m2, _ = pre
    c = PreemptionConfig((1, 0), (2, 2, 2), (), (None,))
    assert action_name(m2, (1,), c) == "1 preempts 2"
    assert action_name(m2, (0,), c) == "keep going (serve 2)"
    assert action_name(m2, (2,), PreemptionConfig((0, 1), (2, 2, 2), (), (None,))) == "restart 2 (cancel)"


# ============================================================================ plots
def test_plot_policy_map_returns_axes_and_names_actions(p12, tmp_path):
    sc, mdp, sol = p12
    ax = plot_policy_map(mdp, sol, "idle", scenario=sc)
    assert isinstance(ax, matplotlib.axes.Axes)
    texts = legend_texts(ax)
    A, _, _ = policy_grid(mdp, sol, "idle")
    for a in np.unique(A[A >= 0]):  # at cap 6 the idle policy is (2 to remote, 1 to edge) throughout
        name = action_name(mdp, int(a), scenario=sc)
        assert name in ("(1 to remote, 2 to edge)", "(2 to remote, 1 to edge)")
        assert any(t.startswith(name) for t in texts)
    assert "zero stationary probability" in texts
    assert "p12" in ax.get_title() and "p = 0.9" in ax.get_title()
    out = tmp_path / "map.png"
    ax.figure.savefig(out)
    plt.close(ax.figure)
    assert out.stat().st_size > 1000
    # on a given Axes, with the other AoI fixed, a busy configuration and the shading off
    fig, ax2 = plt.subplots()
    c = parse_config_spec(mdp, "remote: job 1 d=4")
    assert plot_policy_map(mdp, sol.policy, c, axes=(2, 1), ax=ax2, stationary=False) is ax2
    plt.close(fig)


def test_plot_policy_map_fixes_other_aoi(p123):
    sc, mdp, sol = p123
    A, S, fixed = policy_grid(mdp, sol, "edge: job 3 d=3", axes=(1, 2), fixed_tau={3: 4})
    assert fixed == {3: 4} and A.shape == (5, 5)
    s = int(S[S >= 0][0])
    assert mdp.states.tau[s][2] == 4
    ax = plot_policy_map(mdp, sol, "edge: job 3 d=3", axes=(1, 2), fixed_tau={3: 4}, scenario=sc)
    assert r"\tau_{3}$ = 4" in ax.get_title()
    plt.close(ax.figure)
    with pytest.raises(ModelError, match="fixed_tau"):
        policy_grid(mdp, sol, "idle", axes=(1, 2), fixed_tau={2: 1})


def test_default_fixed_aoi_follows_weights(p123):
    _, mdp, sol = p123
    c = parse_config_spec(mdp, "edge: job 3 d=3")
    w = np.where((mdp.states.config == c) & (mdp.states.tau[:, 2] == 3), 1.0, 0.0)
    _, S, fixed = policy_grid(mdp, sol, c, axes=(1, 2), stationary=w / w.sum())
    assert fixed == {3: 3}
    assert all(mdp.states.tau[s][2] == 3 for s in S[S >= 0])


def test_plot_policy_slice(p123, tmp_path):
    sc, mdp, sol = p123
    total = 9
    A, S, _ = slice_grid(mdp, sol, "idle", total)
    on = A != -2
    assert on.sum() == sum(1 for a in range(1, 6) for b in range(1, 6) if 1 <= total - a - b <= 5)
    ax = plot_policy_slice(mdp, sol, "idle", total, scenario=sc)
    assert isinstance(ax, matplotlib.axes.Axes)
    texts = legend_texts(ax)
    for a in np.unique(A[A >= 0]):
        assert any(t.startswith(action_name(mdp, int(a), scenario=sc)) for t in texts)
    out = tmp_path / "slice.png"
    ax.figure.savefig(out)
    plt.close(ax.figure)
    assert out.stat().st_size > 1000
    r = region_stats(mdp, sol, "idle", total=total)
    assert r["connectivity"] == "tri6" and r["cells"] == int(on.sum())


# ============================================================================ CLI
def test_cli_map_writes_png(tmp_path, capsys):
    out = tmp_path / "m.png"
    rc = main(["map", str(F / "paper_p12.toml"), "--set", "tau_cap=5", "--servers", "idle", "--out", str(out),
               "--json"])
    payload = json.loads(capsys.readouterr().out)
    assert rc == 0 and out.stat().st_size > 1000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert payload["configuration"] == "remote: idle; edge: idle" and "per_action" in payload["regions"]


def test_cli_map_slice_and_fix(tmp_path, capsys):
    out = tmp_path / "s.png"
    assert main(["map", str(F / "paper_p123.toml"), "--set", "tau_cap=4", "--servers", "idle", "--slice", "7",
                 "--out", str(out)]) == 0
    assert out.stat().st_size > 1000
    out2 = tmp_path / "f.png"
    assert main(["map", str(F / "paper_p123.toml"), "--set", "tau_cap=4", "--servers", "edge: job 3 d=3",
                 "--axes", "1,2", "--fix", "3=2", "--out", str(out2)]) == 0
    assert out2.stat().st_size > 1000
    capsys.readouterr()


def test_cli_map_bad_spec_exits_2(tmp_path, capsys):
    rc = main(["map", str(F / "paper_p12.toml"), "--set", "tau_cap=4", "--servers", "edge: job 9 d=9",
               "--out", str(tmp_path / "x.png")])
    assert rc == 2 and "no reachable configuration" in capsys.readouterr().err
    rc = main(["map", str(F / "paper_p12.toml"), "--set", "tau_cap=4", "--servers", "idle", "--fix", "3",
               "--out", str(tmp_path / "x.png")])
    assert rc == 2

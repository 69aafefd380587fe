"""The report's "beyond the paper" section B2 (the paper's four processes solved matrix-free).

Every number of the section is checked against an independent route on the enumerated MDP: the
optimum against policy iteration on the stored matrix, each baseline against the exact sparse
evaluation, the time at the cap against the stationary law's per-process mass; the findings
against hand-made instances.
"""
from __future__ import annotations

import dataclasses

import pytest

from wncs_lp.reproduce import beyond, fullscale
from wncs_lp.reproduce.context import PROFILES, Context
from wncs_lp.truncation import policy_cap_mass

TINY = fullscale.FullScaleSettings(caps=(6, 7), sweep_cap=6, p_grid=(0.8, 0.9), tol=1e-9,
                                   mass_max_states=10**9)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    prof = dataclasses.replace(PROFILES["quick"], name="tiny-b2")
    fullscale.SETTINGS["tiny-b2"] = TINY
    out = tmp_path_factory.mktemp("fullscale")
    ctx = Context(out, prof)
    (b2,) = beyond.run_beyond(ctx, ["B2"])
    yield out, prof, b2, ctx
    del fullscale.SETTINGS["tiny-b2"]


@pytest.mark.slow  # the module's fixture: its group starts early
def test_section_has_numbers_figure_table_and_no_verdict(tiny):
    out, _, b2, _ = tiny
    assert b2["id"] == "B2" and "verdict" not in b2
    assert "could not be computed" not in b2["summary"], b2["numbers"].get("error")
    for f in b2["figures"]:
        assert (out / f).stat().st_size > 1000
    (tab,) = b2["tables"]
    assert (out / tab).read_text().startswith("cap,p,states,policy,gain")
    assert "| cap | p | states (box) | policy |" in b2["details"]
    assert b2["numbers"]["all_certified"]
    # three instances: (6, 0.9), (7, 0.9) and (6, 0.8); (6, 0.9) is shared by both lists
    assert sorted((i["cap"], i["p"]) for i in b2["numbers"]["instances"]) == [(6, 0.8), (6, 0.9), (7, 0.9)]
    assert "--profile full" in b2["summary"]


@pytest.mark.parametrize("cap,p", [(6, 0.9), (7, 0.9), (6, 0.8)])
def test_numbers_agree_with_the_stored_matrix(tiny, cap, p):
    _, _, b2, ctx = tiny
    (inst,) = [i for i in b2["numbers"]["instances"] if (i["cap"], i["p"]) == (cap, p)]
    sc = ctx.scenario(fullscale.SCENARIO, [f"tau_cap={cap}", f"p={p!r}"])
    ref = ctx.solve(sc)  # policy iteration on the enumerated MDP
    opt = inst["optimal"]
    assert opt["gain_lower"] - 1e-9 * ref.gain <= ref.gain <= opt["gain_upper"] + 1e-9 * ref.gain
    assert opt["gain"] == pytest.approx(ref.gain, rel=1e-8)
    # time at the cap: sum over processes of the stationary mass with tau_k at its cap
    cm = policy_cap_mass(ctx.mdp(sc), ref.policy)
    m = sum(cm.per_process)
    assert opt["at_cap_lower"] - 1e-12 <= m <= opt["at_cap_upper"] + 1e-12
    assert opt["at_cap_upper"] - opt["at_cap_lower"] <= 4 * 1.01e-6
    if p == TINY.p:  # each process's share where the text quotes it
        assert opt["at_cap_per_process"] == pytest.approx(list(cm.per_process), abs=1.01e-6)
    else:  # the sweep: the sum only, from one evaluation closed to 1e-7
        assert "at_cap_per_process" not in opt and opt["at_cap_upper"] - opt["at_cap_lower"] <= 1.01e-7
    # process 4 is scalar (A = 1.02, R = 1): q_4(tau) = sum_{i < tau} 1.02^(2 i) in closed form
    assert opt["q_at_cap"][3] == pytest.approx((1.02 ** (2 * cap) - 1) / (1.02 ** 2 - 1), rel=1e-12)
    for name in fullscale.POLICIES:
        ev = ctx.evaluate(sc, name)  # exact sparse evaluation on the stored matrix
        assert inst[name]["gain"] == pytest.approx(ev["gain"], rel=1e-8), name
        assert inst[name]["gain_lower"] <= ev["gain"] * (1 + 1e-9) and ev["gain"] <= inst[name]["gain_upper"] * (1 + 1e-9)


def test_second_run_comes_from_the_cache(tiny, monkeypatch):
    out, prof, b2, _ = tiny
    import wncs_lp.solvers.matrix_free as mf

    def boom(*a, **k):
        raise AssertionError("recomputed")

    monkeypatch.setattr(mf, "matrix_free_value_iteration", boom)
    monkeypatch.setattr(mf, "matrix_free_evaluate", boom)
    ctx = Context(out, prof)
    (again,) = beyond.run_beyond(ctx, ["B2"])
    assert ctx.cache.misses == 0 and ctx.cache.hits == 3 * 4 + 1  # and the interval without the cap
    assert again["summary"] == b2["summary"]


def test_a_request_for_the_sum_takes_the_per_process_step(tiny, monkeypatch):
    out, prof, b2, _ = tiny
    import wncs_lp.solvers.matrix_free as mf

    def boom(*a, **k):
        raise AssertionError("recomputed")

    monkeypatch.setattr(mf, "matrix_free_value_iteration", boom)
    ctx = Context(out, prof)
    opt = fullscale.exact_optimum(ctx, 7, TINY.p, TINY.tol, per_process=False)
    (inst,) = [i for i in b2["numbers"]["instances"] if (i["cap"], i["p"]) == (7, TINY.p)]
    assert opt == inst["optimal"] and ctx.cache.misses == 0


def _inst(cap, p, gains, width=0.0):
    d = {"cap": cap, "p": p, "assignment": [0, 1, 1, 1], "assignment_label": "a"}
    for name, g in zip(("optimal",) + fullscale.POLICIES, gains):
        d[name] = {"gain": g, "gain_lower": g - width, "gain_upper": g + width, "status": "optimal",
                   "at_cap": 0.5, "states": 10}
    return d


def test_findings_gaps_and_order_on_hand_made_instances():
    f = fullscale.fullscale_findings([_inst(10, 0.9, (100.0, 110.0, 120.0, 200.0)),
                                      _inst(12, 0.9, (100.0, 105.0, 104.0, 150.0))])
    sub = f["gaps"]["suboptimal"]
    assert sub[0][:3] == (10, 0.9, pytest.approx(0.10)) and sub[1][2] == pytest.approx(0.05)
    assert not f["ordered"] and f["violations"] == ["suboptimal > static at cap 12, p = 0.9"]
    assert f["all_certified"]
    # overlapping certificates do not count as a reversed order
    g = fullscale.fullscale_findings([_inst(10, 0.9, (100.0, 105.0, 104.9, 150.0), width=0.2)])
    assert g["ordered"]
    lo, hi = g["gaps"]["static"][0][3:]
    assert lo == pytest.approx(104.7 / 100.2 - 1) and hi == pytest.approx(105.1 / 99.8 - 1)


def test_an_uncertified_number_is_said():
    bad = _inst(10, 0.9, (100.0, 110.0, 120.0, 200.0))
    bad["greedy"]["status"] = "max_iter"
    f = fullscale.fullscale_findings([bad])
    assert not f["all_certified"]
    text = fullscale.summary_text([bad], [], f, TINY, None)
    assert "NOT every number closed its certificate" in text


def test_cap_text_names_what_it_has():
    per = _inst(12, 0.9, (100.0, 110.0, 120.0, 200.0))
    per["optimal"].update(at_cap=1.5, at_cap_per_process=[0.1, 0.2, 0.2, 1.0], q_at_cap=[5.0, 5.0, 5.0, 15.0])
    text = fullscale.cap_text([per])
    assert text.startswith("Share of the time each process") and "10.0%, 20.0%, 20.0%, 100.0%" in text
    assert "process 4" in text  # the process that sits at its cap is named
    total = _inst(12, 0.9, (100.0, 110.0, 120.0, 200.0))
    total["optimal"]["at_cap"] = 1.43
    text = fullscale.cap_text([total])
    assert text == "Time at the cap under the optimal policy: cap 12: 1.43 processes at their cap on average."

"""The cap study: lower bounds that increase with the cap, the first cap's policy never beats the optimum."""
from __future__ import annotations

import math

import pytest

import wncs_lp
from wncs_lp.studies import cap_study
from wncs_lp.errors import WncsError


def test_rows_are_increasing_lower_bounds_and_stop_when_converged():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"))
    study = cap_study(sc, [8, 10, 12, 14], mass_tol=0.5, gain_rtol=0.5)
    rows = study.rows
    assert [r.cap for r in rows][:2] == [8, 10]
    for a, b in zip(rows, rows[1:]):
        assert a.gain_upper <= b.gain_lower  # g*(C) <= g*(C')
        assert b.first_policy_gain >= b.gain_lower - 1e-9 * b.gain  # no policy beats the optimum
    assert math.isnan(rows[0].rel_change) and rows[0].first_policy_gain == rows[0].gain
    # converged as soon as both tolerances are met (both loose here: at the second cap)
    assert study.converged and len(rows) == 2


def test_caps_below_the_longest_loop_are_refused():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"))
    with pytest.raises(WncsError, match="below the longest loop length 8"):
        cap_study(sc, [6, 8])
    with pytest.raises(WncsError, match="increasing caps"):
        cap_study(sc, [10, 8])

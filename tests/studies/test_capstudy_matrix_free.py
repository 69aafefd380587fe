"""The cap study on the matrix-free route: where the guard refuses the stored matrix, each cap is
solved and measured without it, and agrees with the enumerated study."""
from __future__ import annotations

import pytest

import wncs_lp
from wncs_lp.studies import cap_study


def test_caps_past_the_guard_go_matrix_free_and_agree(monkeypatch):
    import wncs_lp.models.guard as guard

    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"))
    enumerated = cap_study(sc, [8, 9], mass_tol=0.0, gain_rtol=0.0)
    build = guard.build_checked

    def refuse(scenario, **kw):  # the guard's refusal from cap 9 on
        if scenario.tau_caps[0] >= 9:
            raise guard.SizeLimitError("the MDP would need more memory than the limit", None)
        return build(scenario, **kw)

    monkeypatch.setattr(guard, "build_checked", refuse)
    mixed = cap_study(sc, [8, 9], mass_tol=0.0, gain_rtol=0.0)
    (e8, e9), (m8, m9) = enumerated.rows, mixed.rows
    assert m8.method != "matrix-free" and m9.method == "matrix-free" and m9.pairs == 0
    assert m9.gain_lower - 1e-9 * m9.gain <= e9.gain <= m9.gain_upper + 1e-9 * m9.gain
    # the first cap's policy, clipped, evaluated without the matrix: the same gain
    assert m9.first_policy_gain == pytest.approx(e9.first_policy_gain, rel=1e-8)
    # the certified upper end of the mass at the cap is above the stationary law's mass
    assert e9.cap_mass <= m9.cap_mass + 1e-9

"""Figures saved whole: a plain ``savefig`` of a policy map keeps its legend, which sits outside the
panel on the right (the figure the plot function makes is laid out with room for it)."""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")

import pytest  # noqa: E402

from wncs_lp import build, load_scenario, scenario_path, solve  # noqa: E402


def _inside(ax) -> bool:
    fig = ax.figure
    fig.savefig(io.BytesIO(), format="png")  # a plain savefig: no bbox_inches="tight"
    box = ax.get_legend().get_window_extent(fig.canvas.get_renderer())
    return box.x0 >= 0 and box.y0 >= 0 and box.x1 <= fig.bbox.x1 + 0.5 and box.y1 <= fig.bbox.y1 + 0.5


@pytest.fixture(scope="module")
def p12():
    mdp = build(load_scenario(scenario_path("paper_p12"), ["tau_cap=8"]))
    return mdp, solve(mdp)


def test_policy_map_legend_inside_the_saved_figure(p12):
    import matplotlib.pyplot as plt

    from wncs_lp.viz.maps import plot_policy_map

    ax = plot_policy_map(*p12, 0)
    assert _inside(ax)
    plt.close(ax.figure)


def test_matrix_free_map_legend_inside_the_saved_figure():
    import matplotlib.pyplot as plt

    from wncs_lp.solvers.matrix_free import matrix_free_value_iteration
    from wncs_lp.viz.maps import plot_matrix_free_map

    sol = matrix_free_value_iteration(load_scenario(scenario_path("paper_p12"), ["tau_cap=8"]))
    ax = plot_matrix_free_map(sol, 0)
    assert _inside(ax)
    plt.close(ax.figure)

"""Where a policy map puts its legend: never under a neighbouring panel (issue 26: in a 1 x 2
layout the first panel's legend was hidden under the second). The oracle is the geometry the
renderer reports: window extents of the legend, the panels and the x label."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from wncs_lp import scenario_path  # noqa: E402
from wncs_lp.models import build  # noqa: E402
from wncs_lp.scenario import load_scenario  # noqa: E402
from wncs_lp import solve  # noqa: E402
from wncs_lp.viz import plot_policy_map, plot_policy_slice  # noqa: E402


@pytest.fixture(scope="module")
def p12():
    mdp = build(load_scenario(scenario_path("paper_p12"), ["tau_cap=7"]))
    return mdp, solve(mdp, "pi")


def extents(fig, *artists):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    return [a.get_window_extent(r) for a in artists]


def test_alone_the_legend_is_right_of_the_panel(p12):
    mdp, sol = p12
    fig, ax = plt.subplots(figsize=(6, 4))
    plot_policy_map(mdp, sol, 0, ax=ax)
    leg, box = extents(fig, ax.get_legend(), ax)
    assert leg.x0 >= box.x1
    plt.close(fig)


def row_of_two(draw):
    """Two panels in a row, each drawn by ``draw(ax, i)``; the extents of the first legend, the
    two panels and the first x label."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for i, ax in enumerate(axes):
        draw(ax, i)
    return fig, axes, extents(fig, axes[0].get_legend(), axes[0], axes[1], axes[0].xaxis.label)


def test_in_a_row_the_first_legend_is_not_under_the_second_panel(p12):
    mdp, sol = p12
    fig, axes, (leg, first, second, xlabel) = row_of_two(lambda ax, c: plot_policy_map(mdp, sol, c, ax=ax))
    assert not leg.overlaps(second)
    assert not leg.overlaps(first) and leg.y1 <= xlabel.y0  # below the panel and its x label
    # the last panel of the row keeps its legend on the right
    (leg2,) = extents(fig, axes[1].get_legend())
    assert leg2.x0 >= second.x1
    plt.close(fig)


def test_in_a_row_a_slice_legend_is_not_under_the_next_panel():
    mdp = build(load_scenario(scenario_path("paper_p123"), ["tau_cap=6"]))
    sol = solve(mdp, "pi")
    fig, axes, (leg, first, second, _) = row_of_two(lambda ax, c: plot_policy_slice(mdp, sol, 0, 6 + c, ax=ax))
    assert not leg.overlaps(second)
    plt.close(fig)


def test_in_a_grid_the_legend_stays_inside_its_panel(p12):
    mdp, sol = p12
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    plot_policy_map(mdp, sol, 0, ax=axes[0, 0])
    leg, box, right, below = extents(fig, axes[0, 0].get_legend(), axes[0, 0], axes[0, 1], axes[1, 0])
    assert box.x0 <= leg.x0 and leg.x1 <= box.x1 and box.y0 <= leg.y0 and leg.y1 <= box.y1
    assert not leg.overlaps(right) and not leg.overlaps(below)
    plt.close(fig)

"""Every matplotlib call of the toolkit: policy maps, performance curves, saving figures.

Plot functions take ``ax=None`` (a new figure is made) and return the Axes; matplotlib is
imported lazily inside them, so importing this package does not import matplotlib.
"""
from __future__ import annotations

from .maps import ACTION_STYLES, plot_matrix_free_map, plot_policy_map, plot_policy_slice
from .save import save_figure
from .simulation import plot_aoi, plot_path
from .sweeps import POLICY_STYLE, plot_sweep, save_sweep_figure
from .tradeoff import plot_tradeoff, save_tradeoff_figure

__all__ = [
    "file_backend",
    "image_formats",
    "subplots",
    "ACTION_STYLES",
    "POLICY_STYLE",
    "plot_policy_map",
    "plot_matrix_free_map",
    "plot_policy_slice",
    "plot_sweep",
    "plot_aoi",
    "plot_path",
    "save_sweep_figure",
    "plot_tradeoff",
    "save_tradeoff_figure",
    "save_figure",
]


def file_backend() -> None:
    """Draw to files only (matplotlib's Agg backend): for command-line runs, which open no window."""
    import matplotlib

    matplotlib.use("Agg")


def image_formats() -> list[str]:
    """The file extensions matplotlib can save a figure as (``png``, ``svg``, ``pdf``, ...)."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(FigureCanvasBase.get_supported_filetypes())


def subplots(*args, **kw):
    """``matplotlib.pyplot.subplots``: a new figure and its Axes, for layouts of the plot functions."""
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kw)

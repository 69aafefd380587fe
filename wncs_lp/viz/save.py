"""Saving figures: every figure the toolkit writes goes through :func:`save_figure` (atomic)."""
from __future__ import annotations

import io
from pathlib import Path
from typing import Sequence

from ..files import atomic_write_bytes

__all__ = ["save_figure"]


def save_figure(fig, path: str | Path, formats: Sequence[str] | None = None, *, dpi: int = 130,
                close: bool = True, **savefig_kw) -> list[Path]:
    """Write a matplotlib figure atomically, once per format; return the paths written.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or Path
        The file (written as given, in the format of its suffix, PNG without one), or with
        ``formats`` the stem (its suffix is replaced by each format's).
    formats : sequence of str, optional
        E.g. ``("png", "svg")``.
    dpi : int
    close : bool
        Close the figure afterwards (frees its memory in long runs).
    **savefig_kw
        Passed to ``fig.savefig`` (e.g. ``bbox_inches="tight"``).
    """
    path = Path(path)
    if formats:
        targets = [(path.with_suffix("." + ext), ext) for ext in formats]
    else:
        targets = [(path, path.suffix.lstrip(".").lower() or "png")]
    out = []
    for target, ext in targets:
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, dpi=dpi, **savefig_kw)
        atomic_write_bytes(target, buf.getvalue())
        out.append(target)
    if close:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return out

"""How results show themselves: a short printout, a small HTML table in Jupyter, a pandas table.

Every result type of the toolkit mixes in :class:`Display` and supplies what to show:

* ``_display_head()`` -- one line naming the result (``"Solution of 10,419 states by pi"``);
* ``_display_rows()`` -- ``(name, value)`` pairs of scalars, arrays described by their size
  (:func:`describe_array`), never printed whole;
* ``_frame_records()`` -- the tidy table of :meth:`Display.to_frame`: ``(columns, records)``,
  one record per state, point or policy, whatever the result is a list of.

and gets ``repr()`` / ``str()`` in scipy's ``OptimizeResult`` style (:func:`text_block`), a
``_repr_html_`` (the same rows as an HTML table, text escaped, and the first rows of its tidy
table) and ``to_frame()`` (a :class:`pandas.DataFrame`; pandas is the optional extra
``notebook``: ``pip install 'wncs_lp[notebook]'``).
"""
from __future__ import annotations

import html
import math
from typing import Any, Sequence

import numpy as np

from .errors import WncsError

__all__ = ["Display", "describe_array", "text_block", "html_block", "frame", "require_pandas", "fmt",
           "PANDAS_HINT", "HTML_PREVIEW_ROWS"]

#: What to install for :meth:`Display.to_frame`.
PANDAS_HINT = "pip install 'wncs_lp[notebook]' (or pip install pandas)"
#: Rows of the tidy table shown under a result's HTML form.
HTML_PREVIEW_ROWS = 8

Rows = Sequence[tuple[str, str]]
Records = tuple[Sequence[str], Sequence[dict[str, Any]]]


def describe_array(a: Any, what: str) -> str:
    """``"array of 1,234 floats (float64)"``: an array in a result's printout, by size."""
    if a is None:
        return "None"
    a = np.asarray(a)
    return f"array of {a.size:,} {what} ({a.dtype})"


def fmt(x: Any, digits: int = 10) -> str:
    """A number for a printout: ``digits`` significant digits, NaN / inf spelled out."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return f"{int(x):,}"
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return str(x) if not math.isfinite(x) else f"{x:.{digits}g}"
    return str(x)


def text_block(head: str, rows: Rows) -> str:
    """Multi-line, scipy ``OptimizeResult`` style: a head line, then names right-aligned."""
    if not rows:
        return head
    width = max(len(k) for k, _ in rows)
    return "\n".join([head] + [f"{k:>{width + 2}}: {v}" for k, v in rows])


def _cell(x: Any) -> str:
    if isinstance(x, (float, np.floating, int, np.integer, bool, np.bool_)):
        return html.escape(fmt(x))
    return html.escape("" if x is None else str(x))


def html_block(head: str, rows: Rows, table: Records | None = None, total: int | None = None) -> str:
    """A result as HTML: its head line, its rows as a two-column table, and the first rows of its
    tidy table (``table = (columns, records)``; ``total`` records in all). Every text is escaped."""
    out = ['<div class="wncs-lp-result">', f"<strong>{html.escape(head)}</strong>", "<table>"]
    out += [f'<tr><th style="text-align:right">{html.escape(k)}</th><td style="text-align:left">'
            f"{html.escape(v)}</td></tr>" for k, v in rows]
    out.append("</table>")
    if table is not None:
        cols, recs = table
        recs = list(recs)
        n = len(recs) if total is None else total
        out.append(f"<details><summary>table: {n:,} rows x {len(cols)} columns (to_frame())</summary><table>")
        out.append("<tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in cols) + "</tr>")
        for r in recs[:HTML_PREVIEW_ROWS]:
            out.append("<tr>" + "".join(f"<td>{_cell(r.get(c))}</td>" for c in cols) + "</tr>")
        if n > HTML_PREVIEW_ROWS:
            out.append(f'<tr><td colspan="{len(cols)}">... {n - HTML_PREVIEW_ROWS:,} more rows</td></tr>')
        out.append("</table></details>")
    out.append("</div>")
    return "\n".join(out)


def require_pandas():
    """The pandas module, or one :class:`~wncs_lp.errors.WncsError` saying how to install it."""
    try:
        import pandas
    except ImportError:
        raise WncsError(f"to_frame() needs pandas, an optional dependency: {PANDAS_HINT}") from None
    return pandas


def frame(columns: Sequence[str], records: Sequence[dict[str, Any]] | dict[str, Any]):
    """A :class:`pandas.DataFrame` with exactly ``columns``, from records (a list of dicts) or
    from columns (a dict of equal-length arrays: the fast form for one row per state)."""
    pd = require_pandas()
    if isinstance(records, dict):
        return pd.DataFrame({c: records[c] for c in columns}, columns=list(columns))
    return pd.DataFrame.from_records(list(records), columns=list(columns))


class Display:
    """The printout, HTML form and pandas table of a result (module docstring)."""

    def _display_head(self) -> str:
        return type(self).__name__

    def _display_rows(self) -> list[tuple[str, str]]:
        return []

    def _frame_records(self) -> Records:
        """``(columns, records)``: the tidy table, one record per row."""
        rows = self._display_rows()
        return [k for k, _ in rows], [dict(rows)]

    def __repr__(self) -> str:
        return text_block(self._display_head(), self._display_rows())

    def _repr_html_(self) -> str:
        try:
            cols, recs = self._frame_records()
        except WncsError:  # a table that needs more (an MDP, a smaller layout): the rows alone
            return html_block(self._display_head(), self._display_rows())
        if isinstance(recs, dict):
            n = len(next(iter(recs.values()))) if recs else 0
            head = {c: np.asarray(recs[c])[:HTML_PREVIEW_ROWS] for c in cols}
            recs = [{c: head[c][i] for c in cols} for i in range(min(n, HTML_PREVIEW_ROWS))]
            return html_block(self._display_head(), self._display_rows(), (cols, recs), n)
        return html_block(self._display_head(), self._display_rows(), (cols, recs))

    def to_frame(self):
        """The result as a tidy :class:`pandas.DataFrame` (pandas: the ``notebook`` extra)."""
        cols, recs = self._frame_records()
        return frame(cols, recs)

"""Files and JSON: atomic writes, and the one numpy-to-JSON cleaner of the toolkit.

Atomic writes are shared by sweeps, the reproduction cache, reports, figures and tables.

A file is written to a temporary name in its own folder, flushed to disk and moved into place
with :func:`os.replace`, so a reader (or a run interrupted at any point) sees either the old
complete file or the new complete one, never a half-written one.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["atomic_write_bytes", "atomic_write_text", "json_ready", "dumps", "csv_records", "scalars"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (creating the parent folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; results are for others to read
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """UTF-8 text, written byte for byte (no newline translation), atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def json_ready(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays, tuples and report objects made JSON-ready.

    Recursively: dict keys become strings, tuples and arrays lists, numpy scalars Python ones,
    objects with a ``to_json()`` method their result, and non-finite floats ``None`` (so the
    output is strict JSON). Anything else is returned as it is.
    """
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, np.generic):
        return json_ready(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if hasattr(obj, "to_json") and callable(obj.to_json):
        return json_ready(obj.to_json())
    return obj


def dumps(obj: Any, **kw: Any) -> str:
    """Strict JSON text of :func:`json_ready` ``(obj)``; anything still unknown is written as ``str``."""
    return json.dumps(json_ready(obj), default=str, allow_nan=False, **kw)


def csv_records(path: str | Path, columns: tuple[str, ...]) -> list[dict[str, str]]:
    """The complete records of a CSV file written with exactly ``columns`` (resumable tables).

    A missing file, another header, or a truncated line (a run interrupted mid-write: missing
    fields, extra fields, or an empty ``status``) gives no record for it, so a rerun recomputes
    what is not there.
    """
    import csv

    path = Path(path)
    if not path.exists():
        return []
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or tuple(reader.fieldnames) != tuple(columns):
            return []
        return [rec for rec in reader
                if None not in rec and all(rec.get(c) is not None for c in columns) and rec.get("status", "x") != ""]


def scalars(mapping: dict[str, Any]) -> dict[str, Any]:
    """The entries of ``mapping`` that are JSON scalars (numpy scalars unwrapped), in order."""
    import numpy as np

    out: dict[str, Any] = {}
    for k, v in mapping.items():
        if isinstance(v, (int, float, str, bool, np.integer, np.floating, np.bool_)) or v is None:
            out[k] = v.item() if isinstance(v, np.generic) else v
    return out


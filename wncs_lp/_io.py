"""Atomic file writes shared by sweeps, the reproduction cache, reports, figures and tables.

A file is written to a temporary name in its own folder, flushed to disk and moved into place
with :func:`os.replace`, so a reader (or a run interrupted at any point) sees either the old
complete file or the new complete one, never a half-written one.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write_bytes", "atomic_write_text"]


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (creating the parent folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
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

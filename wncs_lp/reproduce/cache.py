"""On-disk step cache for the reproduction: resumable, atomic, keyed by content, checksummed.

Each step's result is a JSON document (plus optional numpy arrays in an ``.npz`` beside it) under
``DIR/cache/``, named by a hash of the step name and its parameters (scenario fingerprints
included). Files are written to a temporary name and moved into place with :func:`os.replace`,
so an interrupted run never leaves a half-written entry, and two runs into the same folder at
worst compute a step twice.

Every entry carries a checksum of its key, result and arrays (:meth:`StepCache.checksum`). An
entry is used only when it reads back whole, its checksum matches and it names the step and the
parameters asked for; otherwise -- a truncated ``.npz``, JSON without a ``result`` or with
``result: null``, a hand-edited number, an entry copied from another key (even with its key and
checksum rewritten), a folder or a pipe in an entry's place -- it is recomputed (and counted in
``StepCache.rejected``), and the new entry replaces it. An entry that cannot be written (a
read-only folder) leaves the computed result in use (counted in ``StepCache.unwritten``).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import WncsError
from ..files import atomic_write_bytes, atomic_write_text, json_ready, read_npz, read_regular

#: Largest entry JSON read back (bytes); a larger file is not an entry of this cache.
MAX_ENTRY_BYTES = 256 << 20

__all__ = ["StepCache", "code_version"]


_CODE_VERSION: str | None = None


def code_version() -> str:
    """A hash of the package's source files: a cached result is reused only by the same code."""
    global _CODE_VERSION
    if _CODE_VERSION is None:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
        _CODE_VERSION = h.hexdigest()[:16]
    return _CODE_VERSION


class StepCache:
    """A folder of cached step results.

    Parameters
    ----------
    root : Path
        The cache folder (created).
    force : bool
        Recompute every step (existing entries are overwritten).

    Attributes
    ----------
    hits, misses : int
        Entries used, steps computed.
    rejected : list of str
        Entry files found damaged, foreign or edited (recomputed).
    unwritten : list of str
        Entries computed but not written (their folder refused the write): used this run only.
    """

    def __init__(self, root: Path, force: bool = False):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.force = force
        self.hits = 0
        self.misses = 0
        self.rejected: list[str] = []
        self.unwritten: list[str] = []

    @staticmethod
    def key(step: str, params: dict[str, Any]) -> str:
        blob = json.dumps(json_ready({"step": step, "params": params, "code": code_version()}), sort_keys=True)
        return f"{step}-{hashlib.sha256(blob.encode()).hexdigest()[:16]}"

    @staticmethod
    def checksum(key: str, result: Any, arrays: dict[str, np.ndarray]) -> str:
        """sha256 of the entry's key, its JSON result and every array's name, dtype, shape and bytes."""
        h = hashlib.sha256(key.encode())
        h.update(json.dumps(json_ready(result), sort_keys=True).encode())
        for name in sorted(arrays):
            a = np.ascontiguousarray(arrays[name])
            h.update(f"|{name}|{a.dtype.str}|{a.shape}|".encode())
            h.update(a.tobytes())
        return h.hexdigest()

    def _paths(self, key: str) -> tuple[Path, Path]:
        return self.root / f"{key}.json", self.root / f"{key}.npz"

    def load(self, step: str, params: dict[str, Any]) -> tuple[dict, dict[str, np.ndarray]] | None:
        """The cached (result, arrays) of a step, or None when absent, damaged, foreign or edited."""
        if self.force:
            return None
        key = self.key(step, params)
        jpath, npath = self._paths(key)
        if not jpath.exists():
            return None
        entry = self._read(key, jpath, npath, step, params)
        if entry is None:
            self.rejected.append(jpath.name)
        return entry

    def _read(self, key: str, jpath: Path, npath: Path, step: str, params: dict[str, Any]
              ) -> tuple[dict, dict[str, np.ndarray]] | None:
        try:
            doc = json.loads(read_regular(jpath, MAX_ENTRY_BYTES).decode("utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(doc, dict) or not isinstance(doc.get("result"), dict) or doc.get("key") != key:
            return None
        same = json.dumps(doc.get("params"), sort_keys=True) == json.dumps(json_ready(params), sort_keys=True)
        if doc.get("step") != step or not same:
            return None  # another step's or another scenario's entry under this key
        arrays: dict[str, np.ndarray] = {}
        names = doc.get("arrays", [])
        if not isinstance(names, list) or not all(isinstance(k, str) for k in names):
            return None
        if names:
            try:
                arrays = read_npz(npath, required=names)
            except WncsError:
                return None
            arrays = {k: arrays[k] for k in names}
        if doc.get("checksum") != self.checksum(key, doc["result"], arrays):
            return None
        return doc["result"], arrays

    def store(self, step: str, params: dict[str, Any], result: dict, arrays: dict[str, np.ndarray] | None = None) -> None:
        key = self.key(step, params)
        jpath, npath = self._paths(key)
        arrays = {k: np.asarray(v) for k, v in (arrays or {}).items()}
        if arrays:
            import io

            buf = io.BytesIO()
            np.savez_compressed(buf, **arrays)
            atomic_write_bytes(npath, buf.getvalue())  # arrays first: the JSON marks completion
        doc = {"step": step, "key": key, "params": json_ready(params), "result": json_ready(result),
               "arrays": sorted(arrays), "checksum": self.checksum(key, result, arrays)}
        atomic_write_text(jpath, json.dumps(doc, indent=1))

    def _clear(self, path: Path) -> None:
        """Remove what stands in an entry's place when it is not a regular file (a folder, a pipe):
        the entry is the cache's own, and it is about to be written anew."""
        if path.is_symlink() or not path.exists() or path.is_file():
            return
        if path.is_dir():
            import shutil

            shutil.rmtree(path)
        else:
            path.unlink()

    def get_or_compute(
        self,
        step: str,
        params: dict[str, Any],
        compute: Callable[[], tuple[dict, dict[str, np.ndarray] | None]],
    ) -> tuple[dict, dict[str, np.ndarray]]:
        """Return the cached (result, arrays) of a step, computing and storing it if absent."""
        hit = self.load(step, params)
        if hit is not None:
            self.hits += 1
            return hit
        self.misses += 1
        result, arrays = compute()
        try:
            for p in self._paths(self.key(step, params)):
                self._clear(p)
            self.store(step, params, result, arrays)
        except OSError:  # the result stands; the next run computes it again
            self.unwritten.append(self.key(step, params))
        # round-trip through JSON so a fresh and a cached run see the same types
        return json.loads(json.dumps(json_ready(result))), dict(arrays or {})

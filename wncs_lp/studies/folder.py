"""A study's output folder: locked while a run writes it, its settings checked, its rows sealed.

A study (a sweep, a trade-off curve, a cap study) writes ``NAME.csv`` (one row per grid point,
rewritten atomically after each), ``NAME.json`` (the same with the settings), ``NAME_meta.json``
(the settings a resumed run must match) and keeps ``.NAME.lock`` while it runs.

* **One run at a time.** A second run into the same folder waits for the first to finish (it
  says so on stderr), then resumes from what the first wrote: two runs never overwrite each
  other's rows.
* **Other settings are refused.** A folder whose ``NAME_meta.json`` holds other settings (another
  scenario, parameter, method, ...) is refused with one :class:`~wncs_lp.errors.WncsError` naming
  what differs.
* **No foreign row is reused.** Every row carries a ``fingerprint``: a digest of the study's
  settings (the scenario's canonical content, the parameter, the method, ...), the row's grid
  key and every cell of the row. A resumed run reuses a row only when that digest, recomputed,
  matches: a row of another scenario (the meta file deleted or garbled), a row edited by hand
  (a gain, ``states=-5``), a row without a fingerprint, a phantom row and every copy of a
  duplicated key are recomputed and dropped from the table, never reused.
"""
from __future__ import annotations

import hashlib
import io
import json
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from ..errors import WncsError
from ..files import atomic_write_text, csv_records, dumps

__all__ = ["StudyFolder", "FINGERPRINT", "read_table"]

#: The column of a row's seal (last in every study's CSV).
FINGERPRINT = "fingerprint"


def read_table(path: str | Path, columns: Sequence[str], parse: Callable[[dict[str, str]], Any]) -> list[Any]:
    """The complete, well-formed rows of a study's CSV, parsed (a truncated or malformed line is
    skipped; the fingerprints are checked only by a resumed run, which knows its settings)."""
    out = []
    for rec in csv_records(path, tuple(columns)):
        try:
            out.append(parse(rec))
        except (ValueError, KeyError, TypeError):
            continue
    return out


def _digest(text: str, n: int = 20) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:n]


class StudyFolder:
    """The output folder of one study run (a context manager holding its lock).

    Parameters
    ----------
    path : path
        The folder (created).
    name : str
        The study's file stem (``sweep``, ``tradeoff``, ``capstudy``).
    settings : dict
        What a row depends on; a resumed run must match it.
    columns : tuple of str
        The CSV's columns, :data:`FINGERPRINT` last.
    what : str
        How the refusal names the study ("a sweep").
    """

    def __init__(self, path: str | Path, name: str, settings: dict[str, Any], columns: Sequence[str],
                 what: str = "a study"):
        self.path = Path(path)
        self.name = name
        self.settings = json.loads(dumps(settings))
        self.columns = tuple(columns)
        self.what = what
        self.csv = self.path / f"{name}.csv"
        self.json = self.path / f"{name}.json"
        self.meta = self.path / f"{name}_meta.json"
        self._digest = _digest(json.dumps(self.settings, sort_keys=True), 32)
        self._lock = None
        self.dropped = 0

    # ------------------------------------------------------------------ lock and settings
    def __enter__(self) -> "StudyFolder":
        self._make()
        self._acquire()
        try:
            self._check_settings()
        except BaseException:
            self._release()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self._release()

    def _make(self) -> None:
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise WncsError(f"--out {self.path}: is a file, expected a folder") from None
        except OSError as exc:
            raise WncsError(f"--out {self.path}: cannot create the folder ({exc.strerror})") from None

    def _acquire(self) -> None:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not on POSIX: no lock
            return
        try:
            self._lock = open(self.path / f".{self.name}.lock", "a")
        except OSError as exc:
            raise WncsError(f"--out {self.path}: cannot write in the folder ({exc.strerror})") from None
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"waiting: another run is writing to {self.path}; this one resumes from its rows when it ends",
                  file=sys.stderr, flush=True)
            fcntl.flock(self._lock, fcntl.LOCK_EX)

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.close()  # closing the file releases the lock
            self._lock = None

    def _check_settings(self) -> None:
        if self.meta.exists():
            try:
                old = json.loads(self.meta.read_text())
            except (OSError, ValueError):
                old = None  # garbled: the rows' fingerprints still keep foreign rows out
            if isinstance(old, dict) and old != self.settings:
                diff = sorted(k for k in set(old) | set(self.settings) if old.get(k) != self.settings.get(k))
                raise WncsError(f"{self.path} holds {self.what} with other settings ({', '.join(diff)} differ); "
                                "use another --out folder or delete it")
        atomic_write_text(self.meta, json.dumps(self.settings, indent=2) + "\n")

    # ------------------------------------------------------------------ sealed rows
    def seal(self, key: str, cells: Sequence[str]) -> str:
        """The fingerprint of a row: the settings, its key and its cells."""
        return _digest(self._digest + "\n" + key + "\n" + "\x1f".join(cells))

    def seal_json(self, key: str, value: Any) -> str:
        """The fingerprint of a JSON value stored beside the rows (e.g. a reference optimum)."""
        return self.seal(key, [json.dumps(json.loads(dumps(value)), sort_keys=True)])

    def rows(self, parse: Callable[[dict[str, str]], Any], key: Callable[[Any], str]) -> dict[str, Any]:
        """The rows of the CSV whose fingerprint checks out, by key (see the module docstring);
        :attr:`dropped` counts the others."""
        found: dict[str, list[Any]] = {}
        bad = 0
        for rec in csv_records(self.csv, self.columns):
            try:
                row = parse(rec)
                k = key(row)
            except (ValueError, KeyError, TypeError):
                bad += 1
                continue
            cells = [rec[c] for c in self.columns if c != FINGERPRINT]
            if rec.get(FINGERPRINT) != self.seal(k, cells):
                bad += 1
                continue
            found.setdefault(k, []).append(row)
        dup = sum(len(v) for v in found.values() if len(v) > 1)
        self.dropped = bad + dup
        return {k: v[0] for k, v in found.items() if len(v) == 1}

    def write(self, rows: Iterable[tuple[str, Sequence[str]]], payload: dict[str, Any]) -> dict[str, str]:
        """Write the CSV (``(key, cells)`` per row, sealed) and the JSON ``payload``, atomically."""
        import csv

        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        for k, cells in rows:
            w.writerow([*cells, self.seal(k, cells)])
        atomic_write_text(self.csv, buf.getvalue())
        atomic_write_text(self.json, dumps(payload, indent=2) + "\n")
        return {"meta": str(self.meta), "csv": str(self.csv), "json": str(self.json)}

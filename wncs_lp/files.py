"""Files and JSON: atomic writes, output checks, reading .npz files, and the one numpy-to-JSON
cleaner of the toolkit.

Atomic writes are shared by sweeps, the reproduction cache, reports, figures and tables.

A file is written to a temporary name in its own folder, flushed to disk and moved into place
with :func:`os.replace`, so a reader (or a run interrupted at any point) sees either the old
complete file or the new complete one, never a half-written one. The temporary name
``.NAME.<pid>.<random>.tmp`` carries the writer's process id: a writer killed by SIGKILL leaves
its temporary behind, and the next write of the same target removes it (its process is gone).

:func:`check_output_file` and :func:`check_output_folder` look at an output path *before* any
work (writable, of the right type), and :func:`read_npz` reads an ``.npz`` file whole, turning
every way it can be damaged into one :class:`~wncs_lp.errors.WncsError` naming the file.

Input files are opened by :func:`open_regular` (and read whole by :func:`read_regular`): a
named pipe, a device, a socket or a folder is refused at once, before a byte is read (a pipe
without a writer would block the open, ``/dev/zero`` would never end), and a file larger than
the reader's limit is refused by its size.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import stat
import tempfile
import time
import tokenize
import zipfile
import zlib
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from .errors import WncsError

__all__ = ["atomic_write_bytes", "atomic_write_text", "atomic_write_csv", "json_ready", "dumps", "csv_records", "scalars",
           "check_output_file", "check_output_folder", "read_npz", "npz_array", "npz_json", "open_regular",
           "read_regular", "STALE_TMP_SECONDS"]

#: A temporary without a process id in its name (or on another machine's file system) is stale
#: after this long.
STALE_TMP_SECONDS = 3600


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's process, or a number that is no pid: leave it
    return True


def _remove_stale_temporaries(path: Path) -> None:
    """Remove ``.NAME.<pid>.*.tmp`` left by dead writers of ``path`` (SIGKILL), and old
    ``.NAME.*.tmp`` without a pid."""
    prefix = f".{path.name}."
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return
    for entry in entries:
        name = entry.name
        if not (name.startswith(prefix) and name.endswith(".tmp")):
            continue
        tag = name[len(prefix):-len(".tmp")].split(".", 1)[0]
        try:
            stale = not _alive(int(tag)) if tag.isdigit() else \
                time.time() - entry.stat().st_mtime > STALE_TMP_SECONDS
            if stale:
                os.unlink(entry.path)
        except OSError:
            pass  # gone already, or not ours to remove


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (creating the parent folder); stale temporaries of
    the same target left by killed writers are removed first."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
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


def atomic_write_csv(path: str | Path, rows: Iterable[Mapping[str, Any]], columns: Sequence[str], *,
                     extras: str = "raise") -> None:
    """``rows`` as a CSV table with a header of ``columns``, written atomically; a missing key is an
    empty cell, a key outside ``columns`` raises (``extras="ignore"``: left out)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), extrasaction=extras)
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(path, buf.getvalue())


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
    what is not there; so does a damaged file (not a file, unreadable, not UTF-8, NUL bytes).
    """
    import csv

    path = Path(path)
    if not path.is_file():
        return []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            if reader.fieldnames is None or tuple(reader.fieldnames) != tuple(columns):
                return []
            return [rec for rec in reader
                    if None not in rec and all(rec.get(c) is not None for c in columns)
                    and rec.get("status", "x") != ""]
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def scalars(mapping: dict[str, Any]) -> dict[str, Any]:
    """The entries of ``mapping`` that are JSON scalars (numpy scalars unwrapped), in order."""
    import numpy as np

    out: dict[str, Any] = {}
    for k, v in mapping.items():
        if isinstance(v, (int, float, str, bool, np.integer, np.floating, np.bool_)) or v is None:
            out[k] = v.item() if isinstance(v, np.generic) else v
    return out



# ----------------------------------------------------------------------------- output checks
def _nearest_existing(folder: Path) -> Path:
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def _writable_folder(folder: Path) -> str | None:
    """None when a file can be created in ``folder`` (tried for real: permissions, read-only file
    systems and root alike), else the reason."""
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".wncs-lp-write-check."):
            return None
    except OSError as exc:
        return exc.strerror or str(exc)


def check_output_file(path: str | Path, option: str = "output", *, create_folder: bool = False) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    Its folder exists (or, with ``create_folder``, can be created: its nearest existing ancestor
    is a writable folder) and is writable; ``path`` itself is not a folder, and if it exists it is
    a regular file.

    Raises
    ------
    WncsError
        One line naming ``option``, the path and what is wrong.
    """
    out = Path(path)
    parent = out.parent if str(out.parent) else Path(".")
    if out.is_dir():
        raise WncsError(f"{option} {path}: is a folder, expected a file name")
    if out.exists() and not out.is_file():
        raise WncsError(f"{option} {path}: exists and is not a regular file")
    if not parent.is_dir():
        if parent.exists():
            raise WncsError(f"{option} {path}: {parent} is not a folder")
        if not create_folder:
            raise WncsError(f"{option} {path}: the folder {parent} does not exist (create it first)")
        base = _nearest_existing(parent)
        if not base.is_dir():
            raise WncsError(f"{option} {path}: cannot create the folder {parent}: {base} is not a folder")
        parent = base
    why = _writable_folder(parent)
    if why is not None:
        raise WncsError(f"{option} {path}: cannot write in the folder {parent} ({why})")
    if out.exists() and not os.access(out, os.W_OK):
        raise WncsError(f"{option} {path}: the file exists and is not writable")
    return out


def check_output_folder(path: str | Path, option: str = "output folder") -> Path:
    """Check, before any work, that ``path`` is (or can be created as) a writable folder;
    nothing is created.

    Raises
    ------
    WncsError
        One line naming ``option``, the path and what is wrong (a file in the way, a parent that
        is a file, no permission, a read-only file system).
    """
    out = Path(path)
    if out.exists():
        if not out.is_dir():
            raise WncsError(f"{option} {path}: exists and is not a folder")
        base = out
    else:
        base = _nearest_existing(out.parent if str(out.parent) else Path("."))
        if not base.is_dir():
            raise WncsError(f"{option} {path}: cannot create it: {base} is not a folder")
    why = _writable_folder(base)
    if why is not None:
        raise WncsError(f"{option} {path}: cannot write in {base} ({why})")
    return out


# ----------------------------------------------------------------------------- reading input files
#: What each kind of file that is not a regular one is called in messages.
_KINDS = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder"))


class NotRegularFile(OSError):
    """An input path that is not a regular file, or one over its reader's size limit. An
    ``OSError`` (its ``strerror`` says what it is), so every reader's ``except OSError`` turns it
    into that reader's one-line error."""


def open_regular(path: str | Path, *, max_bytes: int | None = None):
    """Open ``path`` for reading in binary mode, only if it is a regular file of at most
    ``max_bytes`` (any size with None).

    The file is opened without blocking (a FIFO without a writer would otherwise block the open
    forever) and checked on the open descriptor (no race with a rename).

    Raises
    ------
    NotRegularFile
        ``strerror``: "a named pipe (FIFO), not a regular file", "... bytes, over the limit of ...".
    OSError
        The file cannot be opened (missing, no permission).
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((name for test, name in _KINDS if test(st.st_mode)), "a special file")
            raise NotRegularFile(0, f"{kind}, not a regular file", str(path))
        if max_bytes is not None and st.st_size > max_bytes:
            raise NotRegularFile(0, f"{st.st_size:,} bytes, over the limit of {max_bytes:,} bytes for this file",
                                 str(path))
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | Path, max_bytes: int) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (:func:`open_regular`); a file that
    grows past the limit while it is read is refused too."""
    with open_regular(path, max_bytes=max_bytes) as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise NotRegularFile(0, f"over the limit of {max_bytes:,} bytes for this file", str(path))
    return data


# ----------------------------------------------------------------------------- reading .npz
#: What a damaged .npz file raises inside numpy / zipfile / zlib.
# numpy parses a member's header with ast and, for headers of format versions 1 and 2 that fail
# to parse, re-tokenizes it: a damaged header raises SyntaxError or tokenize.TokenError, not only
# ValueError
_NPZ_ERRORS = (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile, zlib.error, RuntimeError,
               NotImplementedError, MemoryError, SyntaxError, tokenize.TokenError)


def read_npz(path: str | Path, *, required: Iterable[str] = (), what: str = "an .npz file",
             error: type[WncsError] = WncsError) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file, read eagerly (so a damaged member is found here).

    Parameters
    ----------
    path : file name
    required : keys the file must hold
    what : what the file should be, for messages (e.g. ``"a wncs_lp.policy-npz file"``)
    error : the :class:`~wncs_lp.errors.WncsError` subclass to raise

    Raises
    ------
    error
        One line naming the file: missing, empty, truncated, not a zip, a failed CRC, an entry
        that needs pickle, or a missing key.
    """
    path = Path(path)
    try:
        with open_regular(path) as f:
            arrays = _npz_arrays(f, path, what, error)
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except NotRegularFile as exc:
        raise error(f"{path}: {exc.strerror}: expected {what}") from None
    except _NPZ_ERRORS as exc:
        size = path.stat().st_size if path.is_file() else 0
        detail = "empty" if size == 0 else f"{type(exc).__name__}: {str(exc)[:120]}"
        raise error(f"{path}: not a readable .npz file, expected {what} ({detail})") from None
    missing = [k for k in required if k not in arrays]
    if missing:
        raise error(f"{path}: expected {what}, missing the entr{'ies' if len(missing) > 1 else 'y'} "
                    f"{', '.join(missing)} (found {', '.join(sorted(arrays)[:12]) or 'none'})")
    return arrays


def _npz_arrays(f, path: Path, what: str, error: type[WncsError]) -> dict[str, np.ndarray]:
    z = np.load(f, allow_pickle=False)
    if not hasattr(z, "files"):  # a lone .npy array
        raise error(f"{path}: a single .npy array, not an .npz archive: expected {what}")
    with z:
        return {k: z[k] for k in z.files}


def npz_array(arrays: Mapping[str, np.ndarray], key: str, path: str | Path, *, expect: str,
              ndim: int | None = None, shape: tuple | None = None, lo: float | None = None,
              hi: float | None = None, error: type[WncsError] = WncsError) -> np.ndarray:
    """``arrays[key]`` checked: ``expect`` the dtype (``"i"`` integers, ``"f"`` finite numbers, ``"U"``
    text, ``"b"`` booleans), dimensions, shape (None entries free), range ``lo <= x <= hi``.

    Raises
    ------
    error
        One line naming the file, the entry and what was expected.
    """
    a = np.asarray(arrays[key])
    where = f"{path}: entry '{key}'"
    kinds = {"i": "iu", "f": "iuf", "U": "U", "b": "b"}[expect]
    names = {"i": "integers", "f": "numbers", "U": "text", "b": "booleans"}[expect]
    if a.dtype.kind not in kinds:
        raise error(f"{where}: expected {names}, found dtype {a.dtype}")
    if ndim is not None and a.ndim != ndim:
        raise error(f"{where}: expected {ndim} dimension(s), found shape {a.shape}")
    if shape is not None and (a.ndim != len(shape) or any(e is not None and e != n for e, n in zip(shape, a.shape))):
        want = "(" + ", ".join("*" if e is None else str(e) for e in shape) + ")"
        raise error(f"{where}: expected shape {want}, found {a.shape}")
    if expect == "f" and a.size and not np.all(np.isfinite(a)):
        raise error(f"{where}: expected finite numbers, found {a[~np.isfinite(a)].flat[0]}")
    if a.size and expect in ("i", "f"):
        if lo is not None and a.min() < lo:
            raise error(f"{where}: expected values >= {lo:g}, found {a.min()}")
        if hi is not None and a.max() > hi:
            raise error(f"{where}: expected values <= {hi:g}, found {a.max()}")
    return a


def npz_json(arrays: Mapping[str, np.ndarray], key: str, path: str | Path, *,
             error: type[WncsError] = WncsError) -> dict[str, Any]:
    """The JSON object stored as the text entry ``arrays[key]``; one ``error`` when it is not one."""
    a = npz_array(arrays, key, path, expect="U", shape=(), error=error)
    try:
        obj = json.loads(str(a))
    except ValueError as exc:
        raise error(f"{path}: entry '{key}': expected JSON, found {str(a)[:40]!r} ({exc})") from None
    if not isinstance(obj, dict):
        raise error(f"{path}: entry '{key}': expected a JSON object, found {type(obj).__name__}")
    return obj

"""Atomic output files: a file optplan writes is either complete or absent.

Every writer goes through :func:`atomic_path` (or the shortcuts :func:`write_text`,
:func:`write_json`): the content is written to a temporary file in the same folder, flushed and
``fsync``-ed, and renamed over the target with ``os.replace`` — so a full disk, a file-size limit
or an interruption leaves the previous file (or none), never half a file. A failed write raises
:class:`OutputError`, whose one-line message names the path and the operating system's error.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .errors import OutputError

__all__ = ["OutputError", "atomic_path", "write_text", "write_json", "append_line", "check_free_space",
           "check_output_space", "remove_partial_files", "MIN_FREE_BYTES"]

#: temporary files being written right now (removed by :func:`remove_partial_files` on a hard exit)
_PARTIAL: set[str] = set()


def _describe(path: str | Path, exc: OSError) -> OutputError:
    reason = exc.strerror or str(exc)
    name = errno.errorcode.get(exc.errno or 0, "")
    return OutputError(f"cannot write {str(path)!r}: {reason}{f' ({name})' if name else ''}")


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Context manager giving a temporary path beside ``path`` to write to; on a normal exit it is
    fsync-ed and renamed to ``path``, on an exception it is removed (``path`` untouched).
    ``suffix``: the temporary file's extension (default: the target's, so writers that choose a
    format by it, ``savefig`` and ``np.savez``, write the same format). OSError → :class:`OutputError` naming ``path``. Targets that are not regular files
    (``/dev/null``, ``/dev/full``, pipes) are written in place."""
    target = Path(path)
    if target.exists() and not target.is_file():   # a device or a pipe: no rename possible
        try:
            yield target
        except OSError as exc:   # e.g. ENOSPC of /dev/full
            raise _describe(target, exc) from None
        return
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".part{target.suffix if suffix is None else suffix}",
                                   dir=target.parent or ".")
        os.close(fd)
    except OSError as exc:
        raise _describe(target, exc) from None
    _PARTIAL.add(tmp)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        if target.exists():   # keep the target's permissions
            with contextlib.suppress(OSError):
                shutil.copymode(target, tmp)
        else:
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except OSError as exc:
        raise _describe(target, exc) from None
    finally:
        _PARTIAL.discard(tmp)
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding=encoding) as f:
        f.write(text)
    return Path(path)


def write_json(path: str | Path, data: Any, **kwargs: Any) -> Path:
    """``json.dumps(data, indent=2, **kwargs)`` written atomically to ``path``."""
    kwargs.setdefault("indent", 2)
    return write_text(path, json.dumps(data, **kwargs))


def append_line(f, line: str, path: str | Path) -> None:
    """Append one line to the open file ``f`` (``path``: its name for the message), flushed and
    fsync-ed, so a finished result is on disk before the next one starts. A failed write
    (no space, file-size limit) raises :class:`OutputError`; the file is cut back to its last
    complete line so a resumed run reads it."""
    pos = f.tell()
    try:
        f.write(line if line.endswith("\n") else line + "\n")
        f.flush()
        os.fsync(f.fileno())
    except OSError as exc:
        with contextlib.suppress(OSError):
            f.truncate(pos)
        raise _describe(path, exc) from None


def check_free_space(folder: str | Path, need_bytes: int, what: str) -> None:
    """Raise :class:`OutputError` when the file system of ``folder`` has less than ``need_bytes``
    [B] free for an unprivileged user (checked before a long run; ``what`` names the option)."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return   # no answer: the write itself reports the problem
    free = st.f_bavail * st.f_frsize
    if free < need_bytes:
        raise OutputError(f"{what} {str(folder)!r}: only {free / 1e6:.1f} MB free on its file system, "
                          f"expected at least {need_bytes / 1e6:.1f} MB")


#: free space the folder of an output needs before a command's run starts [B]
MIN_FREE_BYTES = 5_000_000


def check_output_space(outputs: dict[str, str | None], need_bytes: int = MIN_FREE_BYTES) -> None:
    """:func:`check_free_space` of the folder of every output (option → path, a file or a folder;
    None and devices such as ``/dev/null`` are skipped; a folder still to be made: its parent)."""
    for option, value in outputs.items():
        if not isinstance(value, str) or not value or value.startswith("/dev/"):
            continue
        p = Path(value)
        folder = p if p.is_dir() else p.parent
        check_free_space(folder if folder.is_dir() else Path("."), need_bytes, option)


def remove_partial_files() -> None:
    """Remove the temporary files of writes under way (on an interruption that cannot wait for them)."""
    for tmp in list(_PARTIAL):
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _PARTIAL.discard(tmp)

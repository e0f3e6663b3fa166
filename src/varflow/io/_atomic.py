"""Atomic file writing shared by every writer in :mod:`varflow.io`.

A file is written to a temporary file in the target's directory, flushed and
``fsync``-ed, then moved onto the target with :func:`os.replace` (atomic on POSIX
and Windows for paths on one file system).  Readers therefore see either the old
file or the complete new one, never a partial write.  If anything fails the
temporary file is removed and the target is left untouched.
"""

from __future__ import annotations

import contextlib
import logging
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_write"]

logger = logging.getLogger(__name__)


def _default_mode() -> int:
    """Permission bits a plain ``open(path, "w")`` would give a new file (0o666 & ~umask)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


# Read once at import: os.umask can only be queried by setting it, which is not thread-safe.
_NEW_FILE_MODE = _default_mode()


def _fsync_directory(directory: Path) -> None:
    """Persist the directory entry after a rename (best effort; not possible everywhere)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "wb") -> Iterator[IO[Any]]:
    """Open a temporary file that replaces ``path`` atomically when the block succeeds.

    Parameters
    ----------
    path : str or path-like
        Target file.  Its directory must exist.
    mode : {"wb", "w"}
        Binary or text (UTF-8) mode.

    Yields
    ------
    file object
        Write to it inside the ``with`` block.  Do not close it yourself.

    Raises
    ------
    ValueError
        If ``mode`` is not a supported write mode.
    FileNotFoundError
        If the target's directory does not exist.

    Notes
    -----
    On normal exit the data are flushed, ``fsync``-ed and moved onto ``path`` with
    :func:`os.replace`; an existing target keeps its permission bits, a new one
    gets ``0o666 & ~umask``.  On any exception the temporary file is deleted and
    the exception propagates.

    Examples
    --------
    >>> with atomic_write("out.bin") as f:  # doctest: +SKIP
    ...     f.write(b"payload")
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write: mode must be 'wb' or 'w', got {mode!r}")
    target = Path(os.fspath(path))
    directory = target.parent
    if not directory.is_dir():
        raise FileNotFoundError(
            2, f"cannot write {target}: directory does not exist", str(directory)
        )
    try:
        perm = stat.S_IMODE(target.stat().st_mode)
    except FileNotFoundError:
        perm = _NEW_FILE_MODE

    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    tmp = Path(tmp_name)
    try:
        kwargs: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, perm)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _fsync_directory(directory)
    logger.debug("atomically wrote %s", target)

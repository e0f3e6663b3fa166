"""One-line descriptions of exceptions, for manifests, reports and CLI messages."""

from __future__ import annotations

__all__ = ["error_line"]


def error_line(exc: BaseException, *, with_type: bool = False) -> str:
    """One line about an exception.

    Parameters
    ----------
    exc : BaseException
    with_type : bool
        Prefix the exception's class name (``"ValueError: ..."``).

    Returns
    -------
    str
        ``"strerror: filename"`` for an :class:`OSError` that names a file, else
        ``str(exc)`` (the class name when it is empty); runs of white space,
        newlines included, become single spaces.
    """
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        text = f"{exc.strerror}: {exc.filename}"
    else:
        text = str(exc) or type(exc).__name__
    if with_type:
        text = f"{type(exc).__name__}: {text}"
    return " ".join(text.split())

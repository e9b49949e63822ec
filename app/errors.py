"""Expected failures versus bugs: how the app words a failure and what it logs.

Bad input is expected: a damaged or unsupported file (``nurbs_core.io.FileFormatError``, any
ValueError), a missing optional package (``MissingDependencyError``), a file that cannot be read
or written (OSError: missing, permission denied, disk full), a cloud too large for memory, and
the fit's refusals of its input (ValueError). Their messages say what is wrong, so the user gets
one line and the log one line, without a traceback. Anything else is a bug in the app or the
engine: the user still gets one line, and the log gets the traceback.
"""

from __future__ import annotations

import logging


def is_expected(error: BaseException) -> bool:
    """True for bad input and environment failures, False for what can only be a bug."""
    from nurbs_core.io import MissingDependencyError

    return isinstance(error, (ValueError, OSError, MemoryError, MissingDependencyError))


def describe(error: BaseException) -> str:
    """The error as one line for the user (an unexpected one keeps its type name)."""
    if isinstance(error, MemoryError):
        return "not enough memory" + (f" ({error})" if str(error) else "")
    text = one_line(str(error)) or type(error).__name__
    if is_expected(error):
        return text
    return f"{type(error).__name__}: {text}" if str(error) else text


def one_line(text: str) -> str:
    """Join the lines of a message into one (a sentence ends each line that had none)."""
    parts = [part.strip() for part in str(text).splitlines() if part.strip()]
    joined = ""
    for part in parts:
        if joined:
            joined += " " if joined[-1] in ".:;!?" else ". "
        joined += part
    return joined


def log_failure(logger: logging.Logger, message: str, error: BaseException | None = None,
                **extra) -> None:
    """Log ``message`` as one ERROR line; with the traceback only when ``error`` is a bug."""
    exc_info = None
    if error is not None and not is_expected(error):
        exc_info = (type(error), error, error.__traceback__)
    logger.error("%s", one_line(message), exc_info=exc_info, extra=extra or None)

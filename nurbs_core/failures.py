"""Expected failures versus bugs: one classification and one wording, used by ``nurbs-fit`` and
the app alike (no torch, no Qt).

Bad input and the environment are expected: an unreadable or unsupported file
(:class:`nurbs_core.io.FileFormatError` and every other ValueError, which is also how the fit
refuses its input), a missing optional package (:class:`nurbs_core.io.MissingDependencyError`,
an ImportError), a file that cannot be opened or written (OSError: missing, permission denied,
disk full) and a cloud too large for memory. Their messages say what is wrong, so the user gets
one line and no traceback. Anything else can only be a bug.
"""

from __future__ import annotations

EXPECTED_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, MemoryError, ImportError)


def is_expected(error: BaseException) -> bool:
    """True for bad input and environment failures, False for what can only be a bug."""
    return isinstance(error, EXPECTED_ERRORS)


def one_line(text: str) -> str:
    """Join the lines of a message into one (a sentence ends each line that had none)."""
    parts = [part.strip() for part in str(text).splitlines() if part.strip()]
    joined = ""
    for part in parts:
        if joined:
            joined += " " if joined[-1] in ".:;!?" else ". "
        joined += part
    return joined


def describe(error: BaseException) -> str:
    """The error as one line for the user; a bug keeps its type name."""
    if isinstance(error, MemoryError):
        return "not enough memory" + (f" ({one_line(str(error))})" if str(error) else "")
    text = one_line(str(error)) or type(error).__name__
    if is_expected(error) or not str(error):
        return text
    return f"{type(error).__name__}: {text}"

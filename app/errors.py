"""How the app logs a failure: one line, with the traceback only for a bug.

Which failures are expected (bad input, the environment) and how they are worded is the
engine's decision, shared with ``nurbs-fit``: :mod:`nurbs_core.failures`, re-exported here.
"""

from __future__ import annotations

import logging

from nurbs_core.failures import describe, is_expected, one_line

__all__ = ["describe", "is_expected", "log_failure", "one_line"]


def log_failure(logger: logging.Logger, message: str, error: BaseException | None = None,
                **extra) -> None:
    """Log ``message`` as one ERROR line; with the traceback only when ``error`` is a bug."""
    exc_info = None
    if error is not None and not is_expected(error):
        exc_info = (type(error), error, error.__traceback__)
    logger.error("%s", one_line(message), exc_info=exc_info, extra=extra or None)

"""Typed errors raised by the readers and writers of :mod:`nurbs_core.io`."""

from __future__ import annotations

import os

#: What the readers and writers accept as a file name (``str | os.PathLike[str]``).
from nurbs_core.atomic import StrPath as StrPath

CAD_INSTALL_HINT = 'pip install "nurbs-studio[cad]"  (or: pip install cadquery-ocp-novtk)'


class FileFormatError(ValueError):
    """A file could not be read (or written) in the format its suffix announces.

    ``path`` is the file, ``line`` the 1-based line of a text format where the problem is (None
    when not applicable, e.g. for binary formats). The message always names the file, and the
    line when there is one, as ``path:line: problem``.
    """

    def __init__(self, path: StrPath | None, message: str, line: int | None = None) -> None:
        self.path = os.fspath(path) if path is not None else None
        self.line = line
        self.problem = message
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {message}")


class MissingDependencyError(ImportError):
    """An optional package needed for a format is not installed; the message says how to get it."""

    def __init__(self, what: str, install: str) -> None:
        self.install = install
        super().__init__(f"{what} needs an optional package that is not installed. "
                         f"Install it with: {install}")


def require_ocp(what: str) -> None:
    """Import OCP (the STEP/IGES extra) or raise MissingDependencyError with the install line."""
    try:
        import OCP  # noqa: F401
    except ImportError:
        raise MissingDependencyError(what, CAD_INSTALL_HINT) from None


class OutputPathError(ValueError):
    """An output cannot be written where it was asked for (unknown suffix, missing or read-only
    folder, a directory, the same file as an input); raised before any work starts."""

    def __init__(self, path: StrPath, message: str) -> None:
        self.path = os.fspath(path)
        self.problem = message
        super().__init__(f"cannot write {self.path}: {message}")

"""Checks on output paths, made before any work starts: a fit is not run for a result that
cannot be written, and an input is never overwritten by an output."""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterable
from pathlib import Path

from nurbs_core.io.errors import OutputPathError, StrPath
from nurbs_core.io.points import suffix_of


def same_file(first: Path, second: Path) -> bool:
    """True when both names reach one file: through symbolic links, ``..``, hard links or a
    case-insensitive file system."""
    if os.path.realpath(first) == os.path.realpath(second):
        return True
    try:
        return os.path.samefile(first, second)
    except OSError:  # one of them does not exist (yet)
        return False


def check_folder_writable(folder: Path, shown: StrPath, shown_folder: StrPath | None = None) -> None:
    """OutputPathError naming ``shown`` (the user's path; ``shown_folder``: its folder as the
    user spelled it, default ``folder``) unless a file can be created in
    ``folder``: one is created and removed (permission bits do not tell: /proc, a read-only
    mount, a full quota), so an output that cannot be written fails before the work, naming the
    output, not the hidden temporary file a save would have used."""
    probe = folder / f".nurbs-fit-probe-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        where = folder if shown_folder is None else shown_folder
        raise OutputPathError(shown, f"files cannot be created in {where} "
                                     f"({exc.strerror or exc})") from None
    try:
        os.unlink(probe)
    except OSError:
        pass


def check_output_paths(outputs: Iterable[StrPath], inputs: Iterable[StrPath | None] = (), *,
                       suffixes: Iterable[str] | None = None) -> list[Path]:
    """The outputs as Paths, once each is known to be writable; OutputPathError otherwise.

    Each output must have one of ``suffixes`` (when given), not be a directory, lie in an
    existing folder this process may write to, not be the same file as any of ``inputs``
    (resolved through symbolic links and hard links), and not be named twice.
    """
    allowed = tuple(s.lower() for s in suffixes) if suffixes is not None else None
    sources = [Path(os.fspath(p)) for p in inputs if p is not None]
    paths: list[Path] = []
    for raw in outputs:
        path = Path(os.fspath(raw))
        for source in sources:
            if same_file(path, source):
                raise OutputPathError(path, f"it is the input file {source}: writing it would "
                                            f"destroy the input; choose another name")
        if path.is_dir():
            raise OutputPathError(path, "it is a directory; give a file name")
        suffix = suffix_of(path)
        if allowed is not None and suffix not in allowed:
            raise OutputPathError(path, f"unknown output suffix {suffix or '(none)'!r}; "
                                        f"supported: {', '.join(allowed)}")
        folder = Path(os.path.realpath(path)).parent
        if not folder.is_dir():
            raise OutputPathError(path, f"the folder {path.parent} does not exist")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise OutputPathError(path, f"the folder {path.parent} is not writable")
        check_folder_writable(folder, path, path.parent)
        for earlier in paths:
            if same_file(path, earlier):
                raise OutputPathError(path, f"it is named twice among the outputs "
                                            f"({earlier})")
        paths.append(path)
    return paths

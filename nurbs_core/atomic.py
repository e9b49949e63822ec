"""Atomic file writes: the target is replaced only by a complete, flushed file.

Every helper writes a temporary file in the target's directory (so the final ``os.replace`` is an
atomic rename on the same file system), fsync it, and replace the target only when the block
ends without an exception. On any exception the temporary file is removed and an existing target
is left byte-for-byte as it was. A symbolic link is followed (its target is replaced, the link
kept); an existing target's permission bits are kept, a new file gets the usual umask ones.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any, TypeAlias

#: What the readers and writers accept as a file name.
StrPath: TypeAlias = "str | os.PathLike[str]"

_WRITE_MODES = ("w", "wb", "wt")


def _temporary_name(target: Path) -> Path:
    return target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp{target.suffix}")


def _create(target: Path) -> Path:
    """Create (exclusively, mode 0666 minus umask) an empty temporary file next to target."""
    for _ in range(100):
        temporary = _temporary_name(target)
        try:
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return temporary
    raise FileExistsError(f"{target}: could not create a temporary file next to it")


def _fsync_path(path: Path, directory: bool = False) -> None:
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        descriptor = os.open(path, flags)
    except OSError:
        if directory:  # some platforms cannot open directories; the rename is still atomic
            return
        raise
    try:
        os.fsync(descriptor)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(descriptor)


@contextlib.contextmanager
def atomic_path(path: StrPath) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (with its suffix, so writers that pick the format
    from the name still work) for a writer that needs a file name; the file written there
    replaces ``path`` when the block succeeds. The writer may create, truncate or recreate the
    file; if it writes nothing, ``path`` is replaced by an empty file."""
    with atomic_paths([path]) as (temporary,):
        yield temporary


@contextlib.contextmanager
def atomic_write(path: StrPath, mode: str = "wb", encoding: str | None = "utf-8") -> Iterator[IO[Any]]:
    """Yield an open file handle (``mode`` "wb" or "w"; text uses ``encoding``, default UTF-8)
    whose content replaces ``path`` once the block ends without an exception."""
    if mode not in _WRITE_MODES:
        raise ValueError(f"atomic_write needs a write mode ({', '.join(_WRITE_MODES)}), got {mode!r}")
    with atomic_path(path) as temporary:
        text = "b" not in mode
        with open(temporary, mode, encoding=encoding if text else None) as handle:
            yield handle


@contextlib.contextmanager
def atomic_paths(paths: Iterable[StrPath]) -> Iterator[list[Path]]:
    """Temporary paths (one per target, each with its target's suffix) for writing several files
    all-or-nothing: the targets are replaced only after every file was written and flushed; if
    any write fails, no target changes and no temporary file is left behind."""
    given = [Path(os.fspath(path)) for path in paths]
    targets = [Path(os.path.realpath(path)) for path in given]
    if len(set(targets)) != len(targets):
        raise ValueError("the same file is named twice among the outputs")
    temporaries: list[Path] = []
    try:
        for target in targets:
            temporaries.append(_create(target))
        yield list(temporaries)
        for temporary in temporaries:
            _fsync_path(temporary)
        for temporary, target in zip(temporaries, targets, strict=True):
            with contextlib.suppress(FileNotFoundError):
                os.chmod(temporary, os.stat(target).st_mode & 0o7777)
            os.replace(temporary, target)
        for directory in {target.parent for target in targets}:
            _fsync_path(directory, directory=True)
    except BaseException as exc:
        for temporary in temporaries:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(temporary)
        if isinstance(exc, OSError):
            named = _naming_targets(exc, temporaries, targets, given)
            if named is not exc:
                raise named from exc
        raise


def cannot_write(error: OSError, names: str) -> OSError:
    """``error`` (same type, or OSError for a subclass with a constructor of its own, and the
    same errno) saying ``cannot write NAMES: <reason>``."""
    reason = error.strerror or str(error)
    try:
        named = type(error)(f"cannot write {names}: {reason}")
    except TypeError:  # an OSError subclass with a constructor of its own
        named = OSError(f"cannot write {names}: {reason}")
    named.errno = error.errno
    return named


def _naming_targets(error: OSError, temporaries: list[Path], targets: list[Path],
                    given: list[Path]) -> OSError:
    """``error`` (same type and errno) saying which of the user's files could not be written,
    never the hidden temporary file (``No space left on device``, a write error without a name,
    becomes ``cannot write fit.ply: No space left on device``). An error about another file (a
    writer reading something) is returned as it is."""
    names = [os.fspath(path) for path in given]
    if error.filename is not None:
        named = os.fspath(error.filename)
        ours = [path for temporary, target, path in zip(temporaries, targets, given, strict=False)
                if named in (os.fspath(temporary), os.fspath(target), os.fspath(path))]
        if not ours:
            return error
        names = [os.fspath(ours[0])]
    return cannot_write(error, ", ".join(names))

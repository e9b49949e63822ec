"""The app's loads report the engine's own reasons for a file it cannot open (no second check
in the app that would say less: a link loop is not "no such file")."""

from __future__ import annotations

import pytest

from app.loading import load_files
from nurbs_core.io import FileFormatError


def test_a_symbolic_link_loop_is_reported_as_one(tmp_path):
    first, second = tmp_path / "a.xyz", tmp_path / "b.xyz"
    first.symlink_to(second)
    second.symlink_to(first)
    with pytest.raises(FileFormatError, match="symbolic links") as caught:
        load_files([str(first)])
    assert caught.value.load_path == str(first)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_files([str(tmp_path / "missing.xyz")])
    folder = tmp_path / "scan.xyz"
    folder.mkdir()
    with pytest.raises(FileFormatError, match="is a directory"):
        load_files([str(folder)])

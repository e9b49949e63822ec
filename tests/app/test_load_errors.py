"""The app's loads report the engine's own reasons for a file it cannot open (no second check
in the app that would say less: a link loop is not "no such file"), and what they merged."""

from __future__ import annotations

import numpy as np
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


def test_a_new_error_replaces_the_dialog_offering_patches(window):
    """The refusal dialog has two accept buttons and so no Escape button, which makes Qt ignore
    close(): a second error used to stack its dialog on top of the first."""
    from PySide6.QtWidgets import QMessageBox

    window.report("a closed cloud cannot be one patch", error=True, offer_patches=True)
    first = window._message_box
    assert first.isVisible()
    window.report("another problem", error=True)
    assert not first.isVisible()
    boxes = [w for w in window.findChildren(QMessageBox) if w.isVisible()]
    assert boxes == [window._message_box] and "another problem" in boxes[0].text()
    window._message_box.reject()


def test_a_cloud_written_twice_opens_once_and_the_log_says_so(tmp_path):
    from nurbs_core import samples

    points = samples.saddle(600, seed=2).points
    source = tmp_path / "twice.xyz"
    np.savetxt(source, np.vstack([points, points]))
    loaded = load_files([str(source)])
    assert len(loaded.targets[0].points) == 600
    assert np.allclose(loaded.targets[0].points, points)
    assert loaded.notes and "600 of 1,200 points repeat an earlier one" in loaded.notes[0]

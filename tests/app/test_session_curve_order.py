"""A session keeps a curve cloud's file order (the points as listed, repeats too: what a curve
fits, as ``nurbs-fit --curve`` does), so that the reopened session fits the same curve."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from app.loading import load_files
from app.session_file import load_session, save_session
from app.state import Document
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.run import fit_arrays


def _closed_outline(tmp_path):
    """A closed outline whose file lists its first point again last, and a few in between."""
    angle = np.linspace(0.0, 2.0 * np.pi, 80, endpoint=False)
    outline = np.column_stack([2.0 * np.cos(angle), np.sin(angle) + 0.2 * np.cos(3 * angle),
                               np.zeros_like(angle)])
    listed = np.vstack([outline[:30], outline[10:12], outline[30:], outline[:1]])
    path = tmp_path / "outline.xyz"
    np.savetxt(path, listed)
    return path, listed


def _fitted(document: Document) -> np.ndarray:
    """The control points of the curve the document's fit fits (its ordered points when a
    file lists some twice, else the points shown)."""
    ordered = document.ordered_points()
    points = document.target_points() if ordered is None else ordered[0]
    return np.asarray(fit_arrays(points[:, :2], FitConfig(kind="curve")).geometry.control_points)


def test_a_reopened_session_fits_the_same_curve_from_the_file_order(tmp_path):
    path, listed = _closed_outline(tmp_path)
    document = Document()
    document.replace_content(load_files([str(path)]).targets, [], [])
    np.testing.assert_array_equal(document.ordered_points()[0], listed)
    session = tmp_path / "work.nstudio"
    save_session(document, session)
    reopened = Document()
    load_session(reopened, session)
    ordered = reopened.ordered_points()
    assert ordered is not None
    np.testing.assert_array_equal(ordered[0], listed)
    np.testing.assert_array_equal(ordered[0][ordered[1]], reopened.target_points())
    np.testing.assert_array_equal(_fitted(reopened), _fitted(document))


def test_a_session_of_edited_points_keeps_no_file_order(tmp_path):
    """Points deleted before saving: the file's order no longer stands for them, and the
    reopened session fits the points shown, as the window did."""
    path, _ = _closed_outline(tmp_path)
    document = Document()
    document.replace_content(load_files([str(path)]).targets, [], [])
    keep = np.ones(len(document.target_points()), bool)
    keep[3] = False
    document.keep_points(keep, "Delete")
    session = tmp_path / "edited.nstudio"
    save_session(document, session)
    reopened = Document()
    load_session(reopened, session)
    assert reopened.ordered_points() is None
    np.testing.assert_array_equal(reopened.target_points(), document.target_points())


def test_a_file_order_that_does_not_list_the_points_is_refused(tmp_path):
    path, _ = _closed_outline(tmp_path)
    document = Document()
    document.replace_content(load_files([str(path)]).targets, [], [])
    session = tmp_path / "work.nstudio"
    save_session(document, session)
    damaged = tmp_path / "damaged.nstudio"
    with zipfile.ZipFile(session) as source, zipfile.ZipFile(damaged, "w") as target:
        for item in source.infolist():
            data = source.read(item.filename)
            if item.filename == "targets/0/rows.npy":
                rows = np.load(io.BytesIO(data))
                buffer = io.BytesIO()
                np.save(buffer, rows[::-1].copy())
                data = buffer.getvalue()
            target.writestr(item, data)
    other = Document()
    with pytest.raises(ValueError, match="file_order does not list"):
        load_session(other, damaged)
    assert other.targets == []

"""Solid mode in the real window: Start on a closed scan of a machined part takes the part route
(decided by ``nurbs_core.route.choose_route``, as ``nurbs-fit``), the Solid dock lists the faces,
the viewport paints them by type, File > Export writes a solid OpenCASCADE reads back; Stop and
closing the window mid-run are safe."""

from __future__ import annotations

import colorsys
import threading
import time

import numpy as np
import pytest
from app_helpers import open_by_drop, viewport_image

pytest.importorskip("OCP")

SOLID_TIMEOUT_MS = 180_000
#: a small scan keeps the run short: 5,000 points of the plate with a through hole
PLATE_POINTS = 5000


@pytest.fixture(scope="module")
def plate_scan(tmp_path_factory):
    """The plate with a through hole (6 planes, 1 cylinder) scanned: 5,000 points, noise 0.2%
    of its diagonal, written as .xyz."""
    from nurbs_core.brep.sample_parts import plate, scan_part

    points, _, _ = scan_part(plate(), PLATE_POINTS, 0.002, 0)
    path = tmp_path_factory.mktemp("plate") / "plate.xyz"
    np.savetxt(path, points, fmt="%.8f")
    return path


def _solid_jobs() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "job-solid"]


def _join_solid_jobs(timeout: float = 180.0) -> None:
    """A cancelled part route's thread runs to the end of its stage (a Python thread cannot be
    killed; its result is dropped): wait for it, so no thread outlives the test."""
    for thread in _solid_jobs():
        thread.join(timeout)
        assert not thread.is_alive(), "the abandoned solid job did not end"


def _read_step(path):
    """The shape of a STEP file, read by OpenCASCADE's own reader."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _hue_pixels(image: np.ndarray, hue: float, width: float = 0.05) -> int:
    """How many saturated pixels (H, W, 3) have a hue within ``width`` of ``hue`` (0-1)."""
    pixels = image.reshape(-1, 3).astype(float) / 255.0
    hsv = np.array([colorsys.rgb_to_hsv(*p) for p in pixels[::7]])
    near = np.abs(hsv[:, 0] - hue) < width
    return int(np.count_nonzero(near & (hsv[:, 1] > 0.45) & (hsv[:, 2] > 0.25)))


@pytest.mark.slow
def test_start_on_a_plate_scan_gives_a_solid_listed_drawn_and_exported(qtbot, window,
                                                                          plate_scan, tmp_path):
    open_by_drop(qtbot, window, [plate_scan])
    assert window.document.settings.fit_mode == "single"  # Start decides: no mode chosen
    with qtbot.waitSignal(window.part_controller.solid_ready, timeout=SOLID_TIMEOUT_MS):
        window.start_action.trigger()
    qtbot.waitUntil(lambda: window.start_action.isEnabled(), timeout=5000)
    assert window.document.settings.fit_mode == "solid"
    assert window.mode_selector.currentData() == "solid"

    # the Solid dock, read from its widgets: 7 faces, 6 planes and 1 cylinder, a clean solid
    panel = window.solid_panel
    assert sorted(panel.face_types()) == ["Cylinder"] + ["Plane"] * 6
    assert panel.values["status"].text() == "converged"
    assert "valid, closed" in panel.values["solid"].text()
    cylinder_row = panel.face_types().index("Cylinder")
    assert panel.table.item(cylinder_row, 2).text().startswith("radius 0.")
    points = sum(int(panel.table.item(r, 3).text().replace(",", ""))
                 for r in range(panel.table.rowCount()))
    assert points == PLATE_POINTS  # every point is nearest to one face
    assert float(panel.values["volume"].text()) > 0
    assert window.tree.shows_solid
    assert window.result_status() == ("converged", [])

    # the viewport: the faces in their type colours (the cylinder orange) under a legend
    assert window.scene.solid.legend_labels() == ["Plane (6)", "Cylinder (1)"]
    window.scene.standard_view("iso")
    image = viewport_image(window)
    orange = colorsys.rgb_to_hsv(0xf0 / 255, 0x8c / 255, 0x2e / 255)[0]
    assert _hue_pixels(image, orange) > 50
    # by deviation: the legend goes, a colour bar comes, the cylinder's orange with it
    panel.colouring.setCurrentIndex(panel.colouring.findData("p99"))
    assert window.scene.solid.colouring == "p99"
    assert window.scene.solid.legend_labels() == []
    assert window.scene.solid.scalar_bar is not None and window.scene.solid.scalar_bar.GetVisibility()

    # File > Export: a STEP that OpenCASCADE reads back as one valid closed solid with a
    # cylinder face
    from nurbs_core.brep.occ import count, face_kind, faces, is_valid

    path = tmp_path / "part.step"
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.export_to(str(path))
    assert blocker.args == [str(path), True], window.last_error
    shape = _read_step(path)
    assert is_valid(shape)
    assert count(shape, "SOLID") == 1 and count(shape, "SHELL") == 1
    assert "cylinder" in [face_kind(face) for face in faces(shape)]
    # a format that cannot hold a solid is refused with a message, and nothing is written
    bad = tmp_path / "part.3dm"
    with qtbot.waitSignal(window.export_finished, timeout=10000) as blocker:
        window.export_to(str(bad))
    assert blocker.args == [str(bad), False] and not bad.exists()
    assert ".step" in window.last_error


@pytest.mark.slow
def test_stop_and_closing_the_window_mid_solid_are_safe(qtbot, window, plate_scan):
    open_by_drop(qtbot, window, [plate_scan])
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("solid"))
    assert window.start_fit()
    assert window.part_controller.state == "running"
    assert window.stop_action.isEnabled() and not window.pause_action.isEnabled()
    window.stop_action.trigger()  # returns at once: the run is abandoned
    assert window.part_controller.state == "idle" and window.start_action.isEnabled()
    assert window.document.solid is None
    _join_solid_jobs()
    assert window.document.solid is None  # the abandoned run's result was dropped
    # again, and this time close the window while it runs
    assert window.start_fit()
    started = time.monotonic()
    window.close()
    assert time.monotonic() - started < 2.0
    assert not window.part_controller.is_busy()
    _join_solid_jobs()

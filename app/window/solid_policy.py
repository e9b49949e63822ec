"""The solid policy: when Start takes the part route, what its outcome changes in the window,
and how the solid is written.

It decides: Start in Solid mode runs the part route forced (``choose_route(part=True)``: the
user asked for a solid); Start in Single patch mode with "Solid from analytic faces" on does
the same; with it on auto, a closed cloud that one patch refuses goes to the part route with
``part=None`` (:func:`nurbs_core.route.choose_route` decides, as for ``nurbs-fit``), and on off
to the network as before. A solid switches the window to Solid mode (an undoable mode edit;
the run's solid itself is no undo step, a face edit of it is) and fills the viewport, the Solid
dock and the tree. When no valid solid results (or the route is not a part) the window says why
and fits the network, as ``nurbs-fit`` does; a forced route that fails reports the error with
"Fit as patches".

The Solid dock's face edits (Merge, Split, Type of the selected rows; a click on a face in the
viewport selects its row, Ctrl+click adds it) go to the regions the rows' faces lie on; several
regions given one type are merged as that type. The edit runs in the part controller's job; its
solid is an undoable step; one that fails leaves the solid as it was.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Qt, Slot

from app.errors import describe
from app.state import part_argument
from app.viewport.solid_layers import TYPE_LABELS
from app.window.fit_display import cloud_units

if TYPE_CHECKING:
    from app.window.hosts import SolidHost
    from app.workers.part_worker import PartOutcome

SOLID_STEP = "Solid from analytic faces"
#: the Solid dock's height once a solid is shown (its report and about seven face rows)
SOLID_DOCK_HEIGHT = 330


def _edit_text(action: str, rows: list[int], kind: str | None) -> str:
    """The undo step's name: "Merge faces 2, 5", "Split face 3", "Face 4 as a cylinder",
    "Face 0 as NURBS"."""
    listed = ", ".join(map(str, rows))
    named = f"face{'s' if len(rows) > 1 else ''} {listed}"
    label = "NURBS" if kind == "freeform" else f"a {TYPE_LABELS.get(kind or '', kind)}".lower()
    if action == "merge":
        return f"Merge {named}" + (f" as {label.replace('a ', 'one ', 1)}" if kind else "")
    if action == "split":
        return f"Split {named}"
    return f"{named[0].upper()}{named[1:]} as {label}"


class SolidPolicy(QObject):
    """Drives the part controller for the window (see the module docstring)."""

    def __init__(self, window: SolidHost):
        super().__init__(window)
        self._window = window

    def connect(self) -> None:
        """Follow the part controller's and the document's signals (once the widgets exist)."""
        window = self._window
        controller = window.part_controller
        controller.solid_ready.connect(self.on_solid_ready)
        controller.fallback_chosen.connect(self.on_fallback)
        controller.run_failed.connect(self.on_failed)
        controller.state_changed.connect(window.update_fit_actions)
        window.document.solid_changed.connect(self.show_solid)
        window.document.solid_restored.connect(self.on_solid_restored)
        window.solid_panel.colouring_changed.connect(window.scene.solid.set_colouring)
        window.solid_panel.face_edit_requested.connect(self.edit_faces)
        controller.solid_edited.connect(self.on_solid_edited)
        controller.edit_failed.connect(self.on_edit_failed)
        controller.state_changed.connect(lambda _state: self._follow_editable())
        window.scene.face_picker.face_clicked.connect(self.on_face_clicked)

    # --- starting ------------------------------------------------------------------------------
    def start(self, part: bool | None) -> bool:
        """Run the part route with ``choose_route``'s ``part`` (see the module)."""
        window = self._window
        started = window.part_controller.start(part)
        if started:
            window.solid_dock.raise_()
            what = ("Making a solid with analytic faces" if part else
                    "The cloud is closed: checking whether it is a machined part (segmenting it "
                    "into analytic surfaces)")
            window.report(f"{what}; this takes a few seconds (Stop cancels).")
        return started

    def starts_with_solid(self) -> bool:
        """Whether Start goes to the part route at once: Solid mode, or Single patch with the
        setting on (a surface fit)."""
        settings = self._window.document.settings
        return settings.fit_mode == "solid" or (
            settings.fit_mode == "single" and settings.solid == "on"
            and settings.fit.kind == "surface" and not settings.fit.single_patch)

    def start_for_start(self) -> bool:
        """Start's part route (when :meth:`starts_with_solid`): forced."""
        return self.start(True)

    def after_refusal(self) -> bool:
        """One patch refused a closed cloud: the part route when the setting is auto and
        OpenCASCADE is there (True: started; False: the window goes on to the network)."""
        from nurbs_core.route import cad_available

        settings = self._window.document.settings
        if part_argument(settings.solid) is False or not cad_available():
            return False
        return self.start(part_argument(settings.solid))

    def reset(self) -> None:
        """Stop the part route and drop the solid."""
        self._window.part_controller.reset()
        self._window.report("Reset: the solid was discarded.")

    # --- outcomes ------------------------------------------------------------------------------
    @Slot(object)
    def on_solid_ready(self, outcome: PartOutcome) -> None:
        window = self._window
        report = outcome.report
        assert report is not None
        if window.document.settings.fit_mode != "solid":
            window.document.edit_settings(SOLID_STEP, fit_mode="solid")
        window.solid_dock.raise_()
        # the face table wants the height of its rows: the bottom docks grow to it
        window.resizeDocks([window.solid_dock], [SOLID_DOCK_HEIGHT], Qt.Orientation.Vertical)
        window.scene.reset_camera()
        verdict = report.status if not report.problems else (
            "fitted with warnings: " + "; ".join(report.problems))
        window.report(f"Solid: {report.summary()}; {verdict} ({report.seconds:.1f} s). "
                      "File > Export writes it (STEP, IGES, B-rep, STL, OBJ, PLY).")

    def show_opened(self) -> str:
        """A solid opened from a file is the document's (:mod:`app.workers.file_solid`): the
        window switches to Solid mode (an undoable mode edit) and frames it; returns what the
        load's message says of it."""
        window = self._window
        report = window.document.solid.report
        if window.document.settings.fit_mode != "solid":
            window.document.edit_settings(SOLID_STEP, fit_mode="solid")
        window.solid_dock.raise_()
        window.resizeDocks([window.solid_dock], [SOLID_DOCK_HEIGHT], Qt.Orientation.Vertical)
        window.scene.reset_camera()
        problems = f" ({'; '.join(report.problems)})" if report.problems else ""
        return (f"a solid from {report.source}: {report.summary()}{problems}; "
                "File > Export writes it (STEP, IGES, B-rep, STL, OBJ, PLY)")

    @Slot(str)
    def on_fallback(self, reason: str) -> None:
        """No solid: say why and fit the network (the CLI's fallback)."""
        window = self._window
        window.report(f"No solid ({reason}): fitting a network of patches (Patches mode; "
                      "Undo returns to the mode before).")
        window.go_on_as_network()

    @Slot(str)
    def on_failed(self, message: str) -> None:
        self._window.report(message, error=True, offer_patches=True)

    @Slot()
    def show_solid(self) -> None:
        """The document's solid changed: the viewport, the Solid dock and the tree show it."""
        window = self._window
        outcome = window.document.solid
        report = None if outcome is None else outcome.report
        window.scene.solid.show(None if outcome is None else outcome.display, report)
        window.solid_panel.show_report(report, cloud_units(window.document))
        self._follow_editable()
        window.rebuild_tree()

    # --- face edits ----------------------------------------------------------------------------
    @Slot(str, object, object)
    def edit_faces(self, action: str, rows: list[int], kind: str | None) -> bool:
        """Merge, split or retype the regions of the face rows ``rows`` (see
        :mod:`nurbs_core.brep.face_edits`): several regions with a type are merged as that
        type. False (and a message) when the rows name no region or the edit cannot start."""
        window = self._window
        outcome = window.document.solid
        if outcome is None or outcome.report is None:
            window.report("No solid to edit: Start on a closed scan of a part first.", error=True)
            return False
        faces = outcome.report.faces
        if not rows or any(not 0 <= row < len(faces) for row in rows):
            window.report("Select the faces to edit in the Solid dock's table first.", error=True)
            return False
        lost = [row for row in rows if faces[row].region < 0]
        if lost:
            window.report(f"Face {lost[0]} lies on no region of the scan's segmentation (no "
                          "points are nearest to it): it cannot be edited; Start makes the "
                          "solid again.", error=True)
            return False
        regions = sorted({faces[row].region for row in rows})
        if action == "merge" and len(regions) < 2:
            window.report(f"The selected faces lie on one surface already (region "
                          f"{regions[0]}): select faces of two surfaces or more to merge.",
                          error=True)
            return False
        if action == "split" and len(regions) != 1:
            window.report("Select the faces of one surface to split.", error=True)
            return False
        if action == "type" and len(regions) > 1:
            action = "merge"  # several surfaces given one type: one surface of that type
        edit = {"action": action, "regions": regions, "kind": kind}
        text = _edit_text(action, rows, kind)
        started = window.part_controller.edit(edit, text)
        if started:
            window.report(f"{text}: refitting and building the solid again (Stop cancels).")
        return started

    @Slot(int, bool)
    def on_face_clicked(self, face: int, additive: bool) -> None:
        """A face clicked in the viewport: its row selected (Ctrl: added to the selection, or
        taken out when it was in)."""
        panel = self._window.solid_panel
        rows = panel.selected_rows()
        if not additive:
            rows = [face]
        elif face in rows:
            rows.remove(face)
        else:
            rows.append(face)
        panel.select_rows(rows)
        if rows:
            panel.table.scrollToItem(panel.table.item(face, 0))

    @Slot(object, str)
    def on_solid_edited(self, outcome: PartOutcome, text: str) -> None:
        report = outcome.report
        assert report is not None
        verdict = report.status if not report.problems else (
            "fitted with warnings: " + "; ".join(report.problems))
        self._window.report(f"{text}: {report.summary()}; {verdict}. Undo takes it back.")

    @Slot(str)
    def on_edit_failed(self, message: str) -> None:
        self._window.report(message, error=True)

    @Slot(str)
    def on_solid_restored(self, by: str) -> None:
        outcome = self._window.document.solid
        shown = "no solid" if outcome is None or outcome.report is None else (
            outcome.report.summary())
        self._window.report(f"{by}: {shown}")

    def _follow_editable(self) -> None:
        window = self._window
        solid = window.document.solid  # an opened solid has no scan regions to edit
        window.solid_panel.set_editable(solid is not None and not solid.report.source
                                        and not window.part_controller.is_busy())

    # --- export --------------------------------------------------------------------------------
    def export(self, path: str) -> bool:
        """Write the solid with ``nurbs_core.io.solid_io.save_solid`` (atomic; STEP and IGES
        keep the analytic faces and say the document's units), in a job."""
        from nurbs_core.io.solid_io import SOLID_SUFFIXES, save_solid

        window = self._window
        outcome = window.document.solid
        if outcome is None:
            window.report("No solid to export yet: Start on a closed scan of a part in Solid "
                          "mode first.", error=True)
            window.export_finished.emit(path, False)
            return False
        if Path(path).suffix.lower() not in SOLID_SUFFIXES:
            window.report(f"A solid is written as {', '.join(SOLID_SUFFIXES)}, not "
                          f"{Path(path).suffix or 'a file without a suffix'}: choose one of "
                          "them (or switch the mode to export the patches).", error=True)
            window.export_finished.emit(path, False)
            return False
        shape, tolerance = outcome.solid, outcome.report.tolerance / 3
        units = window.document.units
        faces = len(outcome.report.faces)

        def done(_result: object) -> None:
            from app.window.export_policy import declared_units

            window.report(f"Exported the solid ({faces} faces) to {path}"
                          f"{declared_units(path, units)}")
            window.export_finished.emit(path, True)

        def failed(exc: Exception) -> None:
            kept = "\nThe existing file was left as it was." if Path(path).exists() else ""
            window.report(f"Export to {path} failed: {describe(exc)}{kept}", error=True, exc=exc)
            window.export_finished.emit(path, False)

        window.jobs.submit("export", lambda: save_solid(shape, [path], tolerance, units), done,
                           failed)
        return True

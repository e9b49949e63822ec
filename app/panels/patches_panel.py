"""The fit mode selector (single patch, patches or solid) and the patch network settings.

Both edit the document's settings through ``edit(text, **changes)`` (undoable, like every fit
setting: the mode through ``Document.edit_settings``, the network through
``Document.edit_patches`` with the engine's ``PatchOptions`` field names) and mirror them back
with ``show_settings`` without emitting edits: nothing is decided here.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import QComboBox, QFormLayout, QLabel, QSpinBox, QVBoxLayout, QWidget

from app.panels.log_slider import LogSlider
from app.state import FIT_MODES, Settings
from nurbs_core.patches.options import PatchOptions

#: The spin boxes' lowest value stands for "auto" (the engine's choice).
AUTO_COUNT, AUTO_SIZE = 3, 3
MAX_COUNT, MAX_SIZE = 400, 40

NOTE = ("Patches fits a network of bicubic patches over a quad layout of the scan: shared "
        "boundary control points (no gaps) and tangent seams; watertight on a closed object (a "
        "part, a sphere, a torus), open on an open shell (a head without its base, a vessel), "
        "ending where the scan ends. Start goes on here by itself when one patch cannot hold "
        "the cloud cleanly. Start, Pause, Stop, Reset and File > Export then work on the "
        "network.")

HELP = {
    "patch_count": "patches the quad layout aims for (the layout may differ a little); auto: "
                   "the coarsest layout whose neighbouring patches do not turn too sharply",
    "patch_size": "control points along each side of every patch; auto: the grid "
                  "grows while the fit gains more than the extra control points cost (Mallows' "
                  "Cp)",
    "patch_stiffness": "fairing weight relative to the data term: larger is smoother, smaller "
                       "follows the points more closely",
    "seam_weight": "weight of tangent continuity across the seams: larger makes the patches "
                   "meet more smoothly, at some cost in distance to the cloud",
}


def _auto_spin(auto: int, maximum: int) -> QSpinBox:
    spin = QSpinBox()
    spin.setRange(auto, maximum)
    spin.setSpecialValueText("auto")
    spin.setKeyboardTracking(False)
    return spin


class ModeSelector(QComboBox):
    """What Start fits: one patch, a network of patches or a solid."""

    def __init__(self, edit: Callable[..., bool], parent: QWidget | None = None):
        super().__init__(parent)
        self._edit, self._updating = edit, False
        for value, label in FIT_MODES:
            self.addItem(label, value)
        self.setToolTip("Single patch: one NURBS surface (or curve). Patches: a network of "
                        "patches for closed objects (settings in the Patches dock). Solid: a "
                        "valid solid with exact planes, cylinders, cones, spheres and tori for "
                        "a closed scan of a machined part (the Solid dock).")
        self.currentIndexChanged.connect(self._chosen)

    def _chosen(self, _index: int):
        if not self._updating:
            self._edit("Fit mode", fit_mode=self.currentData())

    def show_settings(self, settings: Settings):
        self._updating = True
        try:
            self.setCurrentIndex(self.findData(settings.fit_mode))
        finally:
            self._updating = False


class PatchesPanel(QWidget):
    def __init__(self, edit: Callable[..., bool], parent: QWidget | None = None):
        super().__init__(parent)
        self._edit, self._updating = edit, False
        layout = QVBoxLayout(self)
        note = QLabel(NOTE)
        note.setWordWrap(True)
        note.setObjectName("patches_note")
        note.setStyleSheet("QLabel { color: #4a5a6a; font-style: italic; }")
        layout.addWidget(note)
        form = QFormLayout()
        self.patch_count = _auto_spin(AUTO_COUNT, MAX_COUNT)
        self.patch_size = _auto_spin(AUTO_SIZE, MAX_SIZE)
        self.patch_size.setSuffix(" per side")
        self.patch_stiffness = LogSlider(-3, 2)
        self.seam_weight = LogSlider(-2, 2)
        form.addRow("Target patches", self.patch_count)
        form.addRow("Control points", self.patch_size)
        form.addRow("Stiffness", self.patch_stiffness)
        form.addRow("Seam weight", self.seam_weight)
        for name, text in HELP.items():
            getattr(self, name).setToolTip(text)
        layout.addLayout(form)
        layout.addStretch(1)
        self.patch_count.valueChanged.connect(
            lambda value: self._changed("Target patches",
                                        patches="auto" if value == AUTO_COUNT else int(value)))
        self.patch_size.valueChanged.connect(
            lambda value: self._changed("Control points per patch",
                                        size=None if value == AUTO_SIZE else int(value)))
        self.patch_stiffness.value_committed.connect(
            lambda value: self._changed("Patch stiffness", stiffness=float(value)))
        self.seam_weight.value_committed.connect(
            lambda value: self._changed("Seam weight", seam_weight=float(value)))
        self.show_settings(PatchOptions())

    def _changed(self, text: str, **changes):
        if not self._updating:
            self._edit(text, **changes)

    def cancel_pending(self):
        """Drop slider changes still waiting to be committed (shutdown)."""
        self.patch_stiffness.cancel()
        self.seam_weight.cancel()

    def show_settings(self, options: PatchOptions):
        """Show ``options`` (the document's PatchOptions) without emitting edits."""
        self._updating = True
        try:
            self.patch_count.setValue(AUTO_COUNT if options.patches == "auto"
                                      else options.patches)
            self.patch_size.setValue(AUTO_SIZE if options.size is None else options.size)
            self.patch_stiffness.set_value(options.stiffness)
            self.seam_weight.set_value(options.seam_weight)
        finally:
            self._updating = False

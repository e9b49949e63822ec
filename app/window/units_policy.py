"""The units policy: the length unit of the document's coordinates, chosen on import and shown
with every length.

It decides: a load takes the unit its files state (.3dm's unit system, STEP's length unit, our
JSON's metadata, E57: metres, LAS: its coordinate system's; :mod:`nurbs_core.io.units`); files
that state none take the unit another file of the same load states, else the unit stays unknown
and the user is told where to choose it; files that state different units leave it unknown,
with a warning. The toolbar's Units box and Edit > Units choose it (an undoable edit; nothing is
scaled: the unit says what the numbers measure). Every length the window shows names it (the
viewport's legend and corner, the Quality, Patch quality, Deviation and Offsets docks, the
tolerance field, the status bar's messages); sessions keep it; .3dm, STEP and IGES exports and
the deviation report declare it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Slot
from PySide6.QtGui import QAction, QActionGroup
from PySide6.QtWidgets import QComboBox, QMenu

from nurbs_core.io.units import UNITS

if TYPE_CHECKING:
    from app.loading import LoadedFiles
    from app.window.hosts import UnitsHost

#: (label, unit) the Units box and menu offer, in display order (None: unknown)
UNIT_CHOICES: tuple[tuple[str, str | None], ...] = (
    ("unknown", None), *((unit, unit) for unit in UNITS))
UNIT_NAMES = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches",
              "ft": "feet"}
#: the Units box while the unit is unknown and there is something to measure
UNKNOWN_STYLE = "QComboBox { background: #ffe08a; }"
BOX_TIP = ("The length unit of the coordinates: every distance shown is in it, and .3dm / STEP "
           "exports declare it. Nothing is scaled. Read from the file when it states one "
           "(.3dm, STEP, E57).")


def units_of_load(loaded: LoadedFiles) -> tuple[str | None, str]:
    """(the unit a load is in, one line saying where it came from). Files that state none
    follow the one stated by the others; disagreeing files leave it unknown."""
    stated = {name: unit for name, unit in loaded.stated_units.items() if unit is not None}
    silent = [name for name, unit in loaded.stated_units.items() if unit is None]
    units = set(stated.values())
    if len(units) > 1:
        listed = ", ".join(f"{name}: {unit}" for name, unit in stated.items())
        return None, (f"The files state different units ({listed}); nothing is scaled: choose "
                      "the units of the coordinates under Units.")
    if units:
        unit = units.pop()
        sources = ", ".join(stated)
        also = f" ({', '.join(silent)} taken to be in {unit} too)" if silent else ""
        return unit, f"Units: {unit}, as {sources} states{also}."
    names = ", ".join(silent)
    return None, (f"{names} state{'s' if len(silent) == 1 else ''} no units: choose them in the "
                  "toolbar's Units box (or Edit > Units).")


class UnitsPolicy(QObject):
    """Owns the Units box and menu and follows ``Document.units_changed`` (see the module
    docstring)."""

    def __init__(self, window: UnitsHost):
        super().__init__(window)
        self._window = window
        self.box = QComboBox()
        self.box.setObjectName("units_box")
        for label, unit in UNIT_CHOICES:
            self.box.addItem(label, unit)
        self.box.setToolTip(BOX_TIP)
        self.box.activated.connect(lambda index: self.choose(self.box.itemData(index)))
        self.actions: dict[str | None, QAction] = {}
        self._group = QActionGroup(self)
        for label, unit in UNIT_CHOICES:
            text = f"{label} ({UNIT_NAMES[unit]})" if unit else "Unknown"
            action = QAction(text, self)
            action.setCheckable(True)
            action.triggered.connect(lambda _=False, unit=unit: self.choose(unit))
            self._group.addAction(action)
            self.actions[unit] = action

    def fill_menu(self, menu: QMenu) -> None:
        menu.setToolTipsVisible(True)
        for action in self.actions.values():
            menu.addAction(action)

    def choose(self, units: str | None) -> bool:
        """The user's choice (an undoable edit); False when it does not change."""
        changed = self._window.document.set_units(units)
        if changed:
            self._window.report(f"Units: {units or 'unknown'} (nothing is scaled; Edit > Undo "
                                "returns to the previous units)")
        return changed

    def loaded(self, loaded: LoadedFiles) -> tuple[str | None, str]:
        """The unit a load puts the document in, and what the user is told."""
        return units_of_load(loaded)

    @Slot()
    def on_units_changed(self) -> None:
        """Every display names the new unit."""
        window = self._window
        units = window.document.units
        index = self.box.findData(units) if units is not None else 0
        self.box.blockSignals(True)
        self.box.setCurrentIndex(max(index, 0))
        self.box.blockSignals(False)
        self.actions[units].setChecked(True)
        something = bool(window.document.targets or window.document.patches)
        self.box.setStyleSheet(UNKNOWN_STYLE if units is None and something else "")
        window.scene.set_units(units)
        window.quality_panel.set_units(units)
        window.network_quality_panel.set_units(units)
        window.offset_panel.set_units(units)
        window.fit_panel.set_units(units)
        window.deviation_panel.show_map(window.scene.deviation_map(), units,
                                        window.scene.unsigned_deviation_shown())
        window.rebuild_tree()

"""The document tree: point clouds, fitted shape, patch network, solid, patches, offsets; checkboxes set
visibility. Each fit's result is drawn only in its own mode (the single patch in Single patch,
the network in Patches, the solid in Solid): in the other modes it is listed greyed, without a
checkbox, saying which mode shows it (the document still holds it; sessions keep it)."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QTreeWidget, QTreeWidgetItem

from app.state import FIT_MODES, Document

ROLE = Qt.ItemDataRole.UserRole


class DocumentTree(QTreeWidget):
    """Items carry ("layer", name) or ("target", index) in their user data."""

    def __init__(self, set_layer_visible: Callable[[str, bool], None],
                 set_target_visible: Callable[[int, bool], None], parent=None):
        super().__init__(parent)
        self._set_layer_visible, self._set_target_visible = set_layer_visible, set_target_visible
        self._updating = False
        self.shows_fit = False
        self.shows_network = False
        self.shows_solid = False
        self.setHeaderLabels(["Document"])
        self.itemChanged.connect(self._item_changed)

    def _item(self, parent, text: str, data, checked: bool, tooltip: str = ""):
        item = QTreeWidgetItem(parent, [text])
        item.setData(0, ROLE, data)
        item.setFlags(item.flags() | Qt.ItemFlag.ItemIsUserCheckable)
        item.setCheckState(0, Qt.CheckState.Checked if checked else Qt.CheckState.Unchecked)
        item.setToolTip(0, tooltip or text)
        return item

    def _held(self, text: str, mode: str) -> QTreeWidgetItem:
        """A result the current mode does not draw: greyed, no checkbox, naming its mode."""
        name = dict(FIT_MODES)[mode]
        item = QTreeWidgetItem(self, [f"{text}: shown in {name} mode"])
        item.setFlags(Qt.ItemFlag.NoItemFlags)
        item.setToolTip(0, f"kept in the document (a saved session keeps it); Mode > {name} "
                           "shows it")
        return item

    def rebuild(self, document: Document, layer_visible: Callable[[str], bool],
                deviation_visible: bool, quality_visible: bool = False,
                seam_visible: bool = False):
        self._updating = True
        try:
            self.clear()
            self.setHeaderLabels([f"Document ({document.units or 'units unknown'})"
                                  if document.targets or document.patches else "Document"])
            clouds = self._item(self, "Point clouds", ("layer", "cloud"), layer_visible("cloud"),
                                "the fit target: every checked cloud")
            for index, target in enumerate(document.targets):
                self._item(clouds, f"{target.name} ({len(target.points)} points)",
                           ("target", index), target.visible, target.path)
            mode = document.settings.fit_mode
            fitted = document.fitted
            self.shows_fit = fitted is not None
            if fitted is not None and mode != "single":
                self._held("Fitted surface" if fitted.kind == "surface" else "Fitted curve",
                           "single")
            elif fitted is not None:
                kind = fitted.kind
                label = "Fitted surface" if kind == "surface" else "Fitted curve"
                top = self._item(self, label, ("layer", kind), layer_visible(kind))
                self._item(top, "Control net", ("layer", "control_net"),
                           layer_visible("control_net"))
                self._item(top, "Knot lines", ("layer", "knot_lines"), layer_visible("knot_lines"))
                self._item(top, "Deviation map", ("layer", "deviation"), deviation_visible,
                           "colour the cloud by each point's distance to the fitted shape")
                if kind == "surface":
                    self._item(top, "Quality map", ("layer", "quality"), quality_visible,
                               "paint the surface where it is flipped, overlaps itself or hangs "
                               "far from the cloud")
            network = document.network
            self.shows_network = network is not None
            if network is not None and mode != "patches":
                self._held(f"Patch network ({network.patch_count} patches)", "patches")
            elif network is not None:
                top = self._item(self, f"Patch network ({network.patch_count} patches)",
                                 ("layer", "network"), layer_visible("network"),
                                 "the fitted patch network (Patches mode)")
                self._item(top, "Layout", ("layer", "layout"), layer_visible("layout"),
                           "patch boundaries and irregular corners (3 or 5+ patches meet)")
                self._item(top, "Seam angle map", ("layer", "seam"), seam_visible,
                           "colour the network by the angle between neighbouring patches")
            solid = document.solid
            self.shows_solid = solid is not None
            if solid is not None and mode != "solid":
                self._held(f"Solid: {solid.report.summary()}", "solid")
            elif solid is not None:
                self._item(self, f"Solid: {solid.report.summary()}", ("layer", "solid"),
                           layer_visible("solid"),
                           "the solid with analytic faces (Solid mode): " + solid.report.status)
            if document.patches:
                patches = self._item(self, f"{_shapes_name(document.patches)} "
                                           f"({len(document.patches)})",
                                     ("layer", "patches"), layer_visible("patches"))
                for name in document.patch_names:
                    child = QTreeWidgetItem(patches, [name])
                    child.setToolTip(0, name)
            if document.offsets.surfaces:
                self._item(self, f"Offsets ({len(document.offsets.surfaces)})",
                           ("layer", "offsets"), layer_visible("offsets"))
            self.expandAll()
        finally:
            self._updating = False

    def _item_changed(self, item: QTreeWidgetItem, _column: int):
        if self._updating:
            return
        data = item.data(0, ROLE)
        if not data:
            return
        checked = item.checkState(0) == Qt.CheckState.Checked
        kind, key = data
        if kind == "layer":
            self._set_layer_visible(key, checked)
        else:
            self._set_target_visible(key, checked)


def _shapes_name(shapes: list) -> str:
    """What the document's loaded NURBS shapes are called in the tree: "Curves" when every one
    is a curve (a cloud of several outlines), "Patches" when none is, "Shapes" when mixed."""
    from nurbs_core.geometry_arrays import CurveArrays

    curves = sum(isinstance(shape, CurveArrays) for shape in shapes)
    return "Curves" if curves == len(shapes) else "Patches" if curves == 0 else "Shapes"

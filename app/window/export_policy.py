"""The export policy: what File > Export (and Save Screenshot) write, and what the user is told.

It decides: Export writes what the mode shows (the patch network in Patches mode, the solid in
Solid mode, else the fitted shape, loaded patches and offsets) in a job, refuses with a message
when there is nothing to write, names the missing package when a writer needs one and says that
an existing file was left as it was after a failure; .3dm, STEP and IGES declare the document's
units (the report names them) and the message says which; every export ends with one
``export_finished(path, ok)``. The formats and writers are :mod:`app.loading`'s
(``nurbs_core.io``'s).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog

from app import loading
from app.errors import describe

if TYPE_CHECKING:
    from app.window.hosts import ExportHost


#: the export formats that declare a length unit
UNIT_SUFFIXES = (".3dm", ".step", ".stp", ".iges", ".igs")


def declared_units(path: str, units: str | None) -> str:
    """What an export to ``path`` says of its unit (nothing for formats that carry none)."""
    if Path(path).suffix.lower() not in UNIT_SUFFIXES:
        return ""
    if units is not None:
        return f" in {units}"
    return (" with no unit (the units are unknown: choose them under Units)"
            if Path(path).suffix.lower() == ".3dm" else
            " in mm, the format's default (the units are unknown: choose them under Units)")


def changed_settings(settings: dict[str, Any], defaults: dict[str, Any]
                     ) -> list[tuple[str, str]]:
    """A report's settings rows: the settings (a config's JSON form) that differ from the
    defaults, named in words ("max control points"), None read as "auto"; one row saying so
    when none differs. The grid the fit ended with is the report's Result, not a setting."""
    rows = []
    for name, value in settings.items():
        if name in defaults and value == defaults[name]:
            continue
        if value is None:
            text = "auto"
        elif isinstance(value, list | tuple):
            text = " ".join(str(v) for v in value)
        else:
            text = str(value)
        rows.append((name.replace("_", " "), text))
    return rows or [("settings", "the defaults")]


class ExportPolicy(QObject):
    """Writes the window's geometry, patch network or picture (see the module docstring)."""

    def __init__(self, window: ExportHost):
        super().__init__(window)
        self._window = window

    def dialog(self, label: str, suffix: str) -> None:
        """Ask where to export in ``label`` format (the suffix is added when missing)."""
        start = str(Path(self._window.recent.last_directory()) / f"nurbs_studio{suffix}")
        path, _ = QFileDialog.getSaveFileName(self._window, f"Export {label}", start,
                                              f"{label} (*{suffix})")
        if path:
            if not path.lower().endswith(suffix):
                path += suffix
            self._window.export_to(path)

    def export_to(self, path: str) -> bool:
        """Write what the mode shows: the patch network in Patches mode, else the fitted shape,
        loaded patches and offsets."""
        window = self._window
        if window.document.settings.fit_mode == "patches":
            return window.export_network(path)
        if window.document.settings.fit_mode == "solid":
            return window.export_solid(path)
        geometries = window.document.all_geometry()
        if not geometries:
            window.report("Nothing to export yet: run a fit or open NURBS files first.", error=True)
            window.export_finished.emit(path, False)
            return False
        units = window.document.units
        window.jobs.submit("export", lambda: loading.export_geometry(geometries, path, units),
                           lambda count: self._exported(path, count),
                           lambda exc: self._failed(path, exc))
        return True

    def export_network(self, path: str) -> bool:
        """Write the patch network with ``nurbs_core.io.write_network`` (format from the suffix:
        one joined B-rep in .3dm, a sewn solid in .step / .iges, our .json, a welded mesh)."""
        window = self._window
        network = window.document.network
        if network is None:
            window.report("No patch network to export yet: Start a fit in Patches mode first.",
                          error=True)
            window.export_finished.emit(path, False)
            return False
        units = window.document.units
        window.jobs.submit("export", lambda: loading.export_network(network, path, units),
                           lambda count: self._exported(path, count, "patch(es) of the network"),
                           lambda exc: self._failed(path, exc))
        return True

    def report_dialog(self) -> None:
        """Ask where to write a deviation report (HTML or PDF)."""
        start = str(Path(self._window.recent.last_directory()) / "deviation_report.html")
        path, chosen = QFileDialog.getSaveFileName(self._window, "Export deviation report",
                                                   start, "HTML report (*.html);;PDF report (*.pdf)")
        if path:
            if Path(path).suffix.lower() not in (".html", ".htm", ".pdf"):
                path += ".pdf" if "PDF" in chosen else ".html"
            self._window.export_report(path)

    def export_report(self, path: str) -> bool:
        """Write the deviation report of what the mode shows (the patch network in Patches mode,
        else the fitted patch) against the visible clouds, in a job."""
        window = self._window
        document = window.document
        clouds = [t.points for t in document.targets if t.visible]
        if document.settings.fit_mode == "solid":
            return self._export_solid_report(path, clouds)
        network = document.network if document.settings.fit_mode == "patches" else None
        fitted = None if network is not None else document.fitted
        if not clouds or (network is None and fitted is None):
            window.report("No fit to report yet: load a cloud and run a fit first.", error=True)
            window.export_finished.emit(path, False)
            return False
        points = np.concatenate(clouds)
        settings = document.settings
        # one tolerance on screen and in the report: the Deviation dock's (the fit's, or the
        # one the user typed there)
        panel = window.deviation_panel
        if panel.map is not None:
            tolerance: float | None = panel.tolerance()
            source = ("typed in the Deviation dock" if panel.tolerance_typed
                      else "the fit's, as in the Deviation dock")
        else:
            tolerance = (settings.patches.tolerance if network is not None
                         else settings.fit.tolerance)
            source = "the fit's setting" if tolerance is not None else "3 noise sigmas"
        title = " + ".join(t.name for t in document.targets if t.visible)
        status, warnings = window.result_status()
        config = settings.patches if network is not None else settings.fit
        rows = changed_settings(config.to_json(), type(config)().to_json())
        window.jobs.submit("report", lambda: loading.export_report(
                               path, points, fitted, network, title=title, status=status,
                               tolerance=tolerance, tolerance_source=source,
                               warnings=warnings, settings=rows, units=document.units,
                               up_axis=window.scene.up_axis),
                           lambda within: self._exported_report(path, within),
                           lambda exc: self._failed(path, exc))
        return True

    def _export_solid_report(self, path: str, clouds: list[np.ndarray]) -> bool:
        """The deviation report of the solid of Solid mode against the visible clouds."""
        window = self._window
        document = window.document
        solid = document.solid
        if not clouds or solid is None:
            window.report("No solid to report yet: Start on a closed scan of a part in Solid "
                          "mode first.", error=True)
            window.export_finished.emit(path, False)
            return False
        points = np.concatenate(clouds)
        title = " + ".join(t.name for t in document.targets if t.visible)
        window.jobs.submit("report", lambda: loading.export_solid_report(
                               path, points, solid, title=title, units=document.units,
                               up_axis=window.scene.up_axis),
                           lambda within: self._exported_report(path, within),
                           lambda exc: self._failed(path, exc))
        return True

    def _exported_report(self, path: str, within: float) -> None:
        self._window.report(f"Wrote the deviation report {path} ({within:.1%} of the points "
                            "within the tolerance)")
        self._window.export_finished.emit(path, True)

    def screenshot_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self._window, "Save screenshot",
                                              self._window.recent.last_directory(),
                                              "PNG image (*.png)")
        if path:
            self._window.save_screenshot(path)

    def save_screenshot(self, path: str) -> bool:
        """The whole window (viewport included) as an image (PNG; the format follows the
        suffix), written atomically: on failure an existing file is left as it was."""
        from nurbs_core.atomic import atomic_path

        window = self._window
        window.loss_plot.flush()
        window.scene.render_now()
        image = window.grab()
        try:
            with atomic_path(path) as temporary:
                if not image.save(str(temporary)):
                    raise OSError("the image could not be encoded or written (is the suffix an "
                                  "image format, such as .png?)")
        except OSError as exc:
            kept = "; the existing file was left as it was" if Path(path).exists() else ""
            window.report(f"Cannot write the screenshot {path}: {describe(exc)}{kept}",
                          error=True, exc=exc)
            return False
        return True

    def _exported(self, path: str, count: int, what: str = "shape(s)"):
        units = declared_units(path, self._window.document.units)
        self._window.report(f"Exported {count} {what} to {path}{units}")
        self._window.export_finished.emit(path, True)

    def _failed(self, path: str, exc: Exception):
        hint = getattr(exc, "install", None)
        message = f"Export to {path} failed: {describe(exc)}"
        if hint and hint not in message:
            message += f"\nInstall the missing package with: {hint}"
        if Path(path).exists():
            message += "\nThe existing file was left as it was."
        self._window.report(message, error=True, exc=exc)
        self._window.export_finished.emit(path, False)

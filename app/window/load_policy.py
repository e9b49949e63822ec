"""The load policy: how files are opened, and what a newly loaded cloud changes.

It decides: a load runs in an abandonable thread and the newest request wins (a running load is
cancelled); the status bar's indicator (:class:`app.window.job_indicator.JobIndicator`) shows it
with Cancel; a session file is read in the same way, and what it changes is the session
policy's; the document changes only when every file reads, and takes the
length unit the files state (:func:`app.window.units_policy.units_of_load`); a load resets
both fits; a cloud that is a curve (one-dimensional) switches the fit to a curve and a small
cloud gets the smaller control grid :func:`app.state.control_grid_for` asks for (both undoable
settings edits); what the user is told when a load opens, fails or is cancelled; and which
files the Open Recent menu lists.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QObject, QSettings
from PySide6.QtWidgets import QFileDialog, QMenu

from app import loading
from app.demo import demo_path
from app.errors import describe, is_expected
from app.session_file import SESSION_SUFFIX, read_session
from app.state import control_grid_for
from app.window.text import format_seconds, names
from app.window.units_policy import units_of_load

if TYPE_CHECKING:
    from app.state import Target
    from app.window.hosts import LoadHost

MAX_RECENT = 10


def mesh_words(target: Target) -> str:
    """What a mesh file's cloud is, for the message of its load ("" for a cloud)."""
    if target.mesh is not None:
        return " (its mesh is closed: its own triangles lay out the patches)"
    return f" ({target.mesh_note}: the points' own mesh is built)" if target.mesh_note else ""


@dataclass
class _Load:
    """The load in progress: its detached job, what it reads and its indicator's token."""

    job_id: int
    paths: list[str]
    started: float
    token: int


class RecentFiles:
    """The Open Recent list, kept in the window's settings store (newest first, no demo file)."""

    def __init__(self, store: QSettings):
        self._store = store

    def paths(self) -> list[str]:
        value = self._store.value("recent_files", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def add(self, path: str) -> None:
        if Path(path).resolve() == Path(demo_path()).resolve():
            return
        recent = [p for p in self.paths() if p != path]
        self._store.setValue("recent_files", [path, *recent][:MAX_RECENT])

    def last_directory(self) -> str:
        """Where file dialogs start: the folder of the newest recent file, else home."""
        recent = self.paths()
        return str(Path(recent[0]).parent) if recent else str(Path.home())

    def fill_menu(self, menu: QMenu, open_files: Callable[[list[str]], bool]) -> None:
        """List the recent files in ``menu``; choosing one calls ``open_files([path])``."""
        menu.clear()
        recent = self.paths()
        if not recent:
            menu.addAction("(none)").setEnabled(False)
        for path in recent:
            action = menu.addAction(path)
            action.triggered.connect(lambda _=False, path=path: open_files([path]))


class LoadPolicy(QObject):
    """Opens files for the window: the load job, its indicator and Cancel, and what a load that
    ends changes in the document, the settings and the window (see the module docstring)."""

    def __init__(self, window: LoadHost, recent: RecentFiles):
        super().__init__(window)
        self._window = window
        self.recent = recent
        self.message = ""  # one line: how the latest load ended (opened, failed, cancelled)
        self._load: _Load | None = None
        self._closed = False

    def open_files(self, paths: list[str]) -> bool:
        """Read the files in an abandonable worker thread; the document changes only if every
        file reads. A load still running is cancelled (the newest request wins). Every load
        started here ends with one ``files_loaded``: True when applied, False when it failed or
        was cancelled (none when the window closes first)."""
        paths = [str(p) for p in paths]
        if not paths or self._closed:
            return False
        if len(paths) == 1 and paths[0].lower().endswith(SESSION_SUFFIX):
            # a session (dropped, opened, on the command line) opens whole
            return self.open_session(paths[0])
        return self._start("load", paths, lambda cancel: loading.load_files(paths, cancel),
                           lambda loaded: self._apply(paths, loaded),
                           lambda exc: self._failed(paths, exc))

    def open_session(self, path: str) -> bool:
        """Read and check a session file in an abandonable worker thread, as a load (the newest
        request wins, Cancel and Esc drop it); the session policy applies it when it reads, and
        a file that does not read changes nothing. Ends with one ``files_loaded``."""
        path = str(path)
        if self._closed:
            return False
        policy = self._window.session_policy

        def opened(session: dict[str, Any]) -> None:
            policy.apply(path, session)
            self.message = f"Opened the session {Path(path).name}"
            self._window.files_loaded.emit(True)

        def failed(exc: BaseException) -> None:
            policy.failed(path, exc)
            self.message = f"Cannot open the session {Path(path).name}"
            self._window.files_loaded.emit(False)

        def read(_cancel: Any) -> dict[str, Any]:
            session = read_session(path)
            loading.draw_display_subset(session["targets"])
            return session

        return self._start("open-session", [path], read, opened, failed)

    def _start(self, name: str, paths: list[str], read: Callable[[Any], Any],
               apply: Callable[[Any], None], fail: Callable[[BaseException], None]) -> bool:
        """Run ``read(cancel_event)`` as the load in progress; ``apply(result)`` or
        ``fail(exc)`` follow on the GUI thread once it ends (neither when it is cancelled)."""
        window = self._window
        if self._load is not None:
            self.cancel()

        def done(result: Any) -> None:
            self._ended()
            apply(result)

        def error(exc: BaseException) -> None:
            self._ended()
            fail(exc)

        job_id = window.jobs.submit_detached(name, read, done, error)
        if not job_id:
            return False
        token = window.job_indicator.begin("&Cancel Loading", self.cancel)
        self._load = _Load(job_id, paths, time.monotonic(), token)
        window.statusBar().showMessage(f"Reading {names([Path(p).name for p in paths])}... "
                                       "(Esc cancels)")
        return True

    def is_loading(self) -> bool:
        return self._load is not None

    def cancel(self, quiet: bool = False) -> bool:
        """Abandon the load in progress (Cancel, Esc): returns at once and loads nothing; the
        reader thread is left to end on its own and its result is dropped. quiet: no report
        (the caller tells the user). False when no load runs."""
        load = self._load
        if load is None:
            return False
        window = self._window
        window.jobs.cancel(load.job_id)
        self._ended()
        seconds = time.monotonic() - load.started
        after = f" after {format_seconds(seconds)}" if seconds >= 1.0 else ""
        self.message = (f"Cancelled opening {names([Path(p).name for p in load.paths])}"
                        f"{after}; the document was left unchanged.")
        if not quiet:
            window.report(self.message)
        window.files_loaded.emit(False)
        return True

    def open_dialog(self) -> None:
        suffixes = " ".join(f"*{s}" for s in loading.open_suffixes())
        paths, _ = QFileDialog.getOpenFileNames(
            self._window, "Open point clouds or NURBS files", self.recent.last_directory(),
            f"Supported files ({suffixes} *{SESSION_SUFFIX});;All files (*)")
        if paths:
            self._window.open_files(paths)

    def shut_down(self) -> None:
        """The window closes: the load in progress is dropped (not waited for), no new one starts."""
        self._closed = True
        self._load = None

    def _ended(self):
        """No load runs any more: its indicator and Cancel go."""
        if self._load is not None:
            self._window.job_indicator.end(self._load.token)
        self._load = None

    def _apply(self, paths: list[str], loaded: loading.LoadedFiles):
        window = self._window
        document = window.document
        window.controller.reset()
        window.reset_patch_network()
        window.part_controller.reset()  # a solid under way was of the old clouds: dropped
        window.loss_plot.clear()
        for label in window.status_labels.values():
            label.setText("-")
        window.status_labels["state"].setText("Idle")
        window.run_labels.clear()
        units, units_note = units_of_load(loaded)  # the files' own unit, else unknown
        document.replace_content(loaded.targets, loaded.patches, loaded.patch_names, units)
        if loaded.solid is not None:  # a STEP, IGES or .brep file with trimmed faces
            document.set_solid(loaded.solid)
        document.several_curves = loaded.curves if loaded.curves > 1 else 0
        count = document.visible_point_count()  # not stacked again: the viewport just did
        if count and document.settings.fit.kind != "curve" and (loaded.curve
                                                                 or document.several_curves):
            document.edit_settings("Kind (curve cloud)", kind="curve")
            window.report("The cloud is a curve (thin across everywhere): switched to curve "
                          "fitting." if loaded.curve else "The cloud holds several curves: "
                          "switched to curve fitting (for one curve's points at a time).")
        grid = control_grid_for(count, document.settings.fit) if count else None
        if grid is not None:
            document.edit_settings("Control grid (small cloud)", control_points_u=grid[0],
                                   control_points_v=grid[1])
            window.report(f"{count} points are few for the control grid: reduced it to "
                          f"{grid[0]} x {grid[1]} (Edit > Undo to keep the larger grid).")
        for path in paths:
            self.recent.add(path)
        counts = [f"{len(t.points)} points in {t.name}{mesh_words(t)}" for t in loaded.targets]
        read_shapes = len(loaded.patch_names) - loaded.curves  # the fitted curves: see notes
        if read_shapes:
            sources = sorted({Path(p).name for p in paths} - {t.name for t in loaded.targets}
                             - {loaded.solid.report.source if loaded.solid else ""})
            counts.append(f"{read_shapes} NURBS shape(s) from {names(sources)}")
        if loaded.solid is not None:
            counts.append(window.solid_policy.show_opened())
        shown = window.scene.shown_points_text()  # a big cloud is drawn reduced
        self.message = f"Opened {'; '.join(counts)}" + (f" ({shown})" if shown else "")
        window.report(" ".join(part for part in [f"{self.message}.", *loaded.notes, units_note] if part))
        window.setWindowTitle(f"NURBS Studio - {names([Path(p).name for p in paths])}")
        window.files_loaded.emit(True)

    def _failed(self, paths: list[str], exc: BaseException):
        """One line naming the file and the problem (the log gets a traceback only for a bug),
        then what it means for the document."""
        path = getattr(exc, "load_path", None) or (paths[0] if len(paths) == 1 else None)
        problem = describe(exc)
        if path is None:
            headline = f"Could not open {names([Path(p).name for p in paths])}: {problem}"
        elif Path(path).name in problem:
            headline = f"Could not open {problem}"  # the reader's message names the file
        else:
            headline = f"Could not open {path}: {problem}"
        if not is_expected(exc):
            headline += " (an unexpected error: the log has the details)"
        self.message = message = headline
        hint = getattr(exc, "install", None)
        if hint and hint not in message:
            message += f"\nInstall the missing package with: {hint}"
        self._window.report(message + "\nThe document was left unchanged.", error=True, exc=exc)
        self._window.files_loaded.emit(False)

"""``nurbs-studio [FILE...] [--fit] [--iterations N] [--screenshot OUT.png] [--quit]``.

With no file the built-in demo (z = sin(x) cos(y) as a point cloud) opens, ready to fit. The
scripted options run the real window: open the files, fit, save a screenshot, quit; the exit
status is 0 on success and 1 when a file cannot be read, the fit fails or the screenshot cannot
be written.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys

import app  # noqa: F401 - sets QT_API before pyvistaqt is imported


def parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="nurbs-studio",
        description="Fit NURBS curves and surfaces to point clouds, live.")
    parser.add_argument("files", nargs="*", metavar="FILE",
                        help="point clouds or NURBS files to open (default: the built-in demo)")
    parser.add_argument("--fit", action="store_true", help="start fitting once the files are open")
    parser.add_argument("--iterations", type=int, default=None, metavar="N",
                        help="iteration budget of the fit (default: the settings' 500)")
    parser.add_argument("--screenshot", metavar="OUT.png",
                        help="save a screenshot of the window when done (after the fit with --fit)")
    parser.add_argument("--quit", action="store_true",
                        help="exit when done (status 0 on success, 1 on failure)")
    arguments = parser.parse_args(argv)
    if arguments.iterations is not None and arguments.iterations < 1:
        parser.error("--iterations must be at least 1")
    return arguments


def missing_display() -> str | None:
    """A message when no display is reachable (Qt would abort the process), else None."""
    if not sys.platform.startswith("linux") or os.environ.get("QT_QPA_PLATFORM"):
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return ("nurbs-studio: no display found (DISPLAY and WAYLAND_DISPLAY are unset). Run it in "
            "a desktop session, or headless with: xvfb-run -a nurbs-studio ...")


def main(argv: list[str] | None = None) -> int:
    arguments = parse_arguments(argv)
    problem = missing_display()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow
    from app.scripted import ScriptedRun

    application = QApplication.instance() or QApplication(sys.argv[:1])
    application.setApplicationName("NURBS Studio")
    application.setOrganizationName("NURBS Studio")
    window = MainWindow()
    window.show()
    run = ScriptedRun(window, arguments.files, fit=arguments.fit,
                      iterations=arguments.iterations, screenshot=arguments.screenshot,
                      quit_when_done=arguments.quit)
    run.begin()
    status = application.exec()
    return run.exit_status if arguments.quit else status


if __name__ == "__main__":
    sys.exit(main())

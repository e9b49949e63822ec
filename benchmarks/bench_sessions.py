"""Saving and opening a session: the .nstudio archive (app.session_file: points as .npy) against
the JSON sessions it replaced (points as lists), measured in the same run.

    QT_QPA_PLATFORM=offscreen python benchmarks/bench_sessions.py [--points 1000000]

Prints one table: per format, the file size and the seconds (wall and CPU) to save and to open.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _timed(action) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    action()
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    args = parser.parse_args()
    from PySide6.QtCore import QCoreApplication

    from app.session_file import read_session, save_session
    from app.state import JSON_SESSION_FORMAT, Document, Target

    _app = QCoreApplication.instance() or QCoreApplication([])
    points = np.random.default_rng(0).normal(size=(args.points, 3))
    document = Document()
    document.replace_content([Target("scan", points)], [], [])
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        archive = Path(folder) / "work.nstudio"
        save = _timed(lambda: save_session(document, archive))
        opened = _timed(lambda: read_session(archive))
        rows.append(("archive (.nstudio)", os.path.getsize(archive), save, opened))

        legacy = Path(folder) / "work.json"

        def save_json() -> None:  # what Document.save_session wrote before the archive
            legacy.write_text(json.dumps({
                "format": JSON_SESSION_FORMAT, "settings": document.settings.to_json(),
                "targets": [{"name": t.name, "path": t.path, "visible": t.visible,
                             "points": t.points.tolist()} for t in document.targets],
                "patches": [], "fitted": None}))

        save = _timed(save_json)
        opened = _timed(lambda: read_session(legacy))
        rows.append(("JSON (before)", os.path.getsize(legacy), save, opened))
    print(f"{args.points} points, one thread of this machine; seconds wall (CPU)")
    print("| format | size MB | save s | open s |\n|---|---|---|---|")
    for name, size, (save_wall, save_cpu), (open_wall, open_cpu) in rows:
        print(f"| {name} | {size / 1e6:.1f} | {save_wall:.2f} ({save_cpu:.2f}) | "
              f"{open_wall:.2f} ({open_cpu:.2f}) |")


if __name__ == "__main__":
    main()

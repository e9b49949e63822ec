"""Shared fixtures: where the paper's test data lives."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _find_shared_data() -> Path | None:
    env = os.environ.get("NURBS_STUDIO_DATA")
    candidates = [Path(env)] if env else []
    candidates += [parent / "shared" / "data" for parent in ROOT.parents]
    candidates.append(Path("/work/shared/data"))
    for candidate in candidates:
        if (candidate / "nurbsdiff_paper").is_dir():
            return candidate / "nurbsdiff_paper"
    return None


SHARED_DATA = _find_shared_data()


@pytest.fixture(scope="session")
def paper_data() -> Path:
    """``shared/data/nurbsdiff_paper`` (set NURBS_STUDIO_DATA to point elsewhere)."""
    if SHARED_DATA is None:
        pytest.skip("the paper's test data (shared/data/nurbsdiff_paper) is not on this machine")
    return SHARED_DATA

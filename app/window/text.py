"""Short texts the window's messages share: file lists and durations for a status bar."""

from __future__ import annotations

import math


def names(items: list[str], shown: int = 3) -> str:
    """"a, b, c and 24 more": file lists short enough for a status bar."""
    if len(items) <= shown:
        return ", ".join(items)
    return f"{', '.join(items[:shown])} and {len(items) - shown} more"


def format_seconds(seconds: float) -> str:
    """"42 s", "3.5 min"; "-" when unknown (not finite)."""
    if not math.isfinite(seconds):
        return "-"
    seconds = max(0.0, seconds)
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"

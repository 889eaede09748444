"""Saving figures: atomic writes (temporary file, then rename), so a killed run never leaves half
a PNG behind.

Used by every notebook, the docs figures and the demo report (notebook 00, "Quickstart").
"""

from __future__ import annotations

import os
from pathlib import Path

from .._io import atomic_write_with

__all__ = ["save_figure"]


def save_figure(fig, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Save a matplotlib figure atomically (temp file + rename) and return its path."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    return atomic_write_with(path, lambda fh: fig.savefig(fh, dpi=dpi, bbox_inches="tight",
                                                          format=fmt))

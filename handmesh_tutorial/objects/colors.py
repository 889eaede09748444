"""Per-vertex colours of the procedural objects: a random palette and a pattern
(`random_colors`).

RGB in [0, 1]; pattern periods in metres. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

import colorsys
from typing import Any

import numpy as np

__all__ = ["random_colors"]


_PATTERNS = ("solid", "stripes", "checker", "speckle")


def _hsv_to_rgb(h: float, s: float, v: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(h % 1.0, s, v))


def random_colors(vertices: Any, rng: np.random.Generator | int | None,
                  pattern: str | None = None, scale: float = 0.02) -> np.ndarray:
    """Per-vertex colours: a random two-colour palette and a procedural pattern.

    Patterns: ``solid`` (one colour, slight per-vertex jitter), ``stripes`` (bands along z),
    ``checker`` (angle around z x height), ``speckle`` (random spots). The palette is two
    colours of random hue, saturation and value, the second a shifted hue.

    Args:
        vertices: (V, 3) positions, metres, in the object frame.
        rng: a ``numpy.random.Generator`` or a seed.
        pattern: one of the patterns above, or ``None`` to draw one.
        scale: pattern period, metres.

    Returns:
        (V, 3) float64 RGB in [0, 1].

    Raises:
        ValueError: unknown pattern.
    """
    rng = np.random.default_rng(rng)
    v = np.asarray(vertices, dtype=np.float64)
    if pattern is None:
        pattern = _PATTERNS[int(rng.integers(len(_PATTERNS)))]
    if pattern not in _PATTERNS:
        raise ValueError(f"unknown pattern {pattern!r}; expected one of {_PATTERNS}")
    h = rng.random()
    c0 = _hsv_to_rgb(h, rng.uniform(0.3, 0.9), rng.uniform(0.4, 0.95))
    c1 = _hsv_to_rgb(h + rng.uniform(0.25, 0.75), rng.uniform(0.2, 0.9), rng.uniform(0.3, 1.0))
    if pattern == "solid":
        t = np.zeros(len(v))
    elif pattern == "stripes":
        t = (np.floor(v[:, 2] / scale) % 2).astype(float)
    elif pattern == "checker":
        ang = np.arctan2(v[:, 1], v[:, 0])
        k = max(2, int(round(2 * np.pi * 0.03 / scale)))
        t = ((np.floor(ang / (2 * np.pi) * 2 * k) + np.floor(v[:, 2] / scale)) % 2).astype(float)
    else:
        centres = v[rng.choice(len(v), size=max(1, len(v) // 40), replace=False)]
        d = np.min(np.linalg.norm(v[:, None] - centres[None], axis=-1), axis=1)
        t = (d < 0.35 * scale).astype(float)
    col = c0 + t[:, None] * (c1 - c0) + rng.normal(0.0, 0.015, (len(v), 3))
    return np.clip(col, 0.0, 1.0)

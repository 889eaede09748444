"""Skin colour of the hand meshes: a palette of tones and per-vertex colouring.

[`skin_tone`][handmesh_tutorial.hand.appearance.skin_tone] is the one rule that turns a ``tone``
argument (a [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES] index, an RGB triple or
``None``) into a base colour; both hand models colour their meshes from it:
[`HandModel.vertex_colors`][handmesh_tutorial.hand.model.HandModel.vertex_colors] with the
MakeHuman hand's appearance labels
([`labelled_skin_colors`][handmesh_tutorial.hand.appearance.labelled_skin_colors]:
lighter palm, darker knuckles, pinkish nails, soft blotches) and
[`ManoModel.vertex_colors`][handmesh_tutorial.hand.mano.model.ManoModel.vertex_colors], whose files
carry no labels ([`plain_skin_colors`][handmesh_tutorial.hand.appearance.plain_skin_colors]).
Colours are RGB in [0,1].

Taught in notebook 01 (the hand model); the renderer (notebook 05) draws hands with these colours.
"""

from __future__ import annotations

import numpy as np

from ._common import _adjacency

__all__ = ["SKIN_TONES", "skin_tone"]

SKIN_TONES: tuple[tuple[float, float, float], ...] = (
    (0.96, 0.80, 0.69),
    (0.90, 0.72, 0.60),
    (0.80, 0.60, 0.47),
    (0.67, 0.47, 0.34),
    (0.50, 0.34, 0.24),
    (0.36, 0.24, 0.17),
)
"""A small palette of realistic skin tones (linear-ish sRGB in [0,1]), light to dark; the palm and
the palmar side of the fingers are drawn lighter than the back of the hand.
"""


def skin_tone(tone=None, rng: np.random.Generator | int | None = None,
              ) -> tuple[np.ndarray, np.random.Generator]:
    """The base skin colour of a ``tone`` argument, and the generator the colouring goes on with.

    Args:
        tone: index into [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES], an RGB
            triple in [0,1], or ``None``: a random palette tone when ``rng`` is given, else tone 1.
        rng: ``numpy.random.Generator`` or seed for the tone choice and what follows;
            ``None`` = fixed seed 0 (same colours every call).

    Returns:
        ``(base (3,) float64 RGB in [0,1], generator)``; the generator has drawn the random tone
        (when one was drawn) and nothing else.

    Raises:
        ValueError: bad tone index or triple.
    """
    gen = np.random.default_rng(0 if rng is None else rng)
    if tone is None:
        tone = int(gen.integers(len(SKIN_TONES))) if rng is not None else 1
    if isinstance(tone, (int, np.integer)):
        if not 0 <= int(tone) < len(SKIN_TONES):
            raise ValueError(f"tone index must be in [0,{len(SKIN_TONES) - 1}], got {tone}")
        base = np.asarray(SKIN_TONES[int(tone)])
    else:
        base = np.asarray(tone, dtype=float).reshape(-1)
        if base.shape != (3,) or base.min() < 0 or base.max() > 1:
            raise ValueError(f"tone must be an index or an RGB triple in [0,1], got {tone!r}")
    return base, gen


def knuckle_weights(vertices: np.ndarray, rest_joints: np.ndarray,
                    palmar: np.ndarray) -> np.ndarray:
    """The back-of-hand skin over the MCP, PIP and DIP joints (rest pose), as weights in [0,1].

    Args:
        vertices: (V,3) rest vertices, metres.
        rest_joints: (16,3) rest joints, MANO order, metres.
        palmar: (V,) palm-side label in [0,1].

    Returns:
        (V,) float in [0,1]: 1 within about 5 mm of a finger joint on the back of the hand.
    """
    joints = rest_joints[[j for j in range(1, 16) if j != 13]]    # not the thumb's CMC
    d = np.linalg.norm(vertices[:, None] - joints[None], axis=2).min(1)
    return np.clip(1.4 - d / 0.009, 0.0, 1.0) * np.clip(1.0 - 2.0 * palmar, 0.0, 1.0)


def labelled_skin_colors(vertices: np.ndarray, faces: np.ndarray, rest_joints: np.ndarray,
                         palmar: np.ndarray, nail: np.ndarray, tone=None,
                         rng: np.random.Generator | int | None = None,
                         variation: float = 0.04) -> np.ndarray:
    """Per-vertex skin colour from appearance labels: a tone, lighter palm, darker knuckles,
    pinkish nails, blotches (the MakeHuman hand's colouring).

    Args:
        vertices: (V,3) rest vertices, metres.
        faces: (F,3) int triangles (the blotches are smoothed along the mesh's edges).
        rest_joints: (16,3) rest joints, MANO order, metres.
        palmar: (V,) palm-side label in [0,1].
        nail: (V,) nail label in [0,1].
        tone: see [`skin_tone`][handmesh_tutorial.hand.appearance.skin_tone].
        rng: ``numpy.random.Generator`` or seed for the tone choice and the variation;
            ``None`` = fixed seed 0 (same colours every call).
        variation: amplitude of the low-frequency brightness variation.

    Returns:
        (V,3) float32 RGB in [0,1].

    Raises:
        ValueError: bad tone index or triple.
    """
    layout = _skin_layout(vertices, faces, rest_joints, palmar)
    return _layout_skin_colors(layout, palmar, nail, tone, rng, variation)


def _skin_layout(vertices: np.ndarray, faces: np.ndarray, rest_joints: np.ndarray,
                 palmar: np.ndarray) -> tuple:
    """The per-mesh part of `labelled_skin_colors`: ``(knuckle weights (V,1), vertex adjacency
    (V,V) sparse, vertex degrees (V,))``. It depends on the rest mesh only, so a model computes it
    once (`HandModel.vertex_colors`) instead of at every hand of every scene."""
    k = knuckle_weights(vertices, rest_joints, palmar)[:, None]
    adj = _adjacency(faces, len(vertices))
    deg = np.asarray(adj.sum(1)).ravel()
    return k, adj, deg


def _layout_skin_colors(layout: tuple, palmar: np.ndarray, nail: np.ndarray, tone,
                        rng: np.random.Generator | int | None, variation: float) -> np.ndarray:
    """`labelled_skin_colors` from a precomputed `_skin_layout`."""
    k, adj, deg = layout
    base, gen = skin_tone(tone, rng)
    num_vertices = len(palmar)
    palm = base + (1.0 - base) * np.array([0.30, 0.26, 0.24])            # palm lighter
    palm = palm * np.array([1.0, 0.97, 0.97])                            # and a bit pinker
    nail_rgb = base + (1.0 - base) * np.array([0.45, 0.30, 0.30])
    p = palmar[:, None]
    col = (1 - p) * base + p * palm
    # knuckles: the skin over the finger joints on the back of the hand is darker and redder
    col = col * (1.0 - 0.12 * k * np.array([1.0, 1.3, 1.35]))
    n = nail[:, None]
    col = (1 - n) * col + n * nail_rgb
    noise = gen.standard_normal(num_vertices)
    for _ in range(4):                       # smooth the noise into soft blotches
        noise = 0.5 * noise + 0.5 * (adj @ noise) / deg
    noise /= noise.std() + 1e-12
    col = col * (1.0 + variation * noise[:, None])
    return np.clip(col, 0.0, 1.0).astype(np.float32)


def plain_skin_colors(num_vertices: int, tone=None, rng: np.random.Generator | int | None = None,
                      variation: float = 0.04) -> np.ndarray:
    """Per-vertex skin colour without appearance labels: one tone with a little per-vertex
    brightness noise (used for MANO meshes).

    Args:
        num_vertices: V.
        tone: see [`skin_tone`][handmesh_tutorial.hand.appearance.skin_tone].
        rng: ``numpy.random.Generator`` or seed; ``None`` = seed 0.
        variation: amplitude of the brightness noise.

    Returns:
        (V,3) float32 RGB in [0,1].

    Raises:
        ValueError: bad tone index or triple.
    """
    base, gen = skin_tone(tone, rng)
    noise = 1.0 + variation * gen.standard_normal((num_vertices, 1))
    return np.clip(base * noise, 0.0, 1.0).astype(np.float32)

"""Input checks shared by the mesh-hierarchy submodules: a triangle mesh as (V, 3) float64
vertices and (F, 3) int64 faces. Taught in notebook 06 (mesh hierarchy and spiral convolution).
"""

from __future__ import annotations

import numpy as np


def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {tuple(v.shape)}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain NaN or inf")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {tuple(f.shape)}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integer vertex ids, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if len(f) == 0:
        raise ValueError("faces is empty: a mesh needs at least one triangle")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces reference vertex ids in [{f.min()}, {f.max()}], "
                         f"but there are {len(v)} vertices")
    if np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])):
        raise ValueError("faces contain degenerate triangles (a repeated vertex id)")
    return np.ascontiguousarray(v), np.ascontiguousarray(f)

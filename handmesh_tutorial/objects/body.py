"""A rigid body of a scene: mesh, vertex colours and cylinder collision primitives (`Body`).

Object frame, metres. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh

from ..collision import Cylinders

__all__ = ["Body"]


@dataclass
class Body:
    """A rigid body: mesh, vertex colours and cylinder collision primitives, one frame.

    Attributes:
        name: human-readable name, e.g. ``"mug"``.
        kind: one of `OBJECT_KINDS` (or ``"chain_link"``).
        vertices: (V, 3) float64, metres, in the body's frame.
        faces: (F, 3) int64, counter-clockwise seen from outside; the mesh is watertight.
        colors: (V, 3) float64 RGB in [0, 1].
        cylinders: collision primitives in the same frame as ``vertices``.
        params: the sampled dimensions (metres), e.g. ``{"radius": 0.035, "height": 0.12}``.
    """

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    cylinders: Cylinders
    params: dict

    def transformed(self, R: Any, t: Any) -> Body:
        """The body rigidly moved: ``x -> R @ x + t`` for vertices and cylinders.

        Args:
            R: (3, 3) rotation matrix.
            t: (3,) translation, metres.

        Returns:
            A new `Body` (faces, colours and params shared with this one).
        """
        cylinders = self.cylinders.transform(R, t)  # checks the shapes of R and t
        R = np.asarray(R, dtype=np.float64)
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("R must be a rotation matrix (orthonormal, det +1)")
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        return replace(self, vertices=self.vertices @ R.T + t, cylinders=cylinders)

    def render_mesh(self, label: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """``(vertices, faces, colors, label)``: the input format of ``Renderer.render``."""
        return (self.vertices, self.faces, self.colors, int(label))

    def trimesh(self) -> trimesh.Trimesh:
        """The mesh as a ``trimesh.Trimesh`` (vertex colours attached, no processing)."""
        c = (np.clip(self.colors, 0, 1) * 255 + 0.5).astype(np.uint8)
        return trimesh.Trimesh(self.vertices, self.faces, vertex_colors=c, process=False)

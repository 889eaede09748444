"""A generated scene before rendering: `Scene` and its `SceneBody`s (world frame, metres).

Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..collision import Cylinders

__all__ = ["Scene", "SceneBody"]


@dataclass
class SceneBody:
    """One body of a generated scene, in the scene (world) frame.

    Attributes:
        label: the body's label in masks (1 = the target hand).
        name: ``"left_hand"``, ``"right_hand"``, an object kind, or ``"chain"``.
        kind: ``"hand"``, ``"object"`` or ``"chain"``.
        side: ``"left"``/``"right"`` for hands, ``None`` otherwise.
        vertices: (V, 3) float64 world coordinates, metres.
        faces: (F, 3) int64.
        colors: (V, 3) float RGB in [0, 1].
        cylinders: the collision cylinders in their final place (world, metres).
        joints: (21, 3) FreiHAND keypoints of a hand (world, metres), else ``None``.
        pose: (15, 3) float32 axis-angle finger pose of a hand (MANO order), else ``None``.
        angles: (J, 3) LCS angles (radians) of a hand's joints or the chain's links, else None.
        shape: (6,) hand shape parameters
            ([`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.SHAPE_PARAM_NAMES]), else ``None``.
        dynamic: whether step 4 moved its joints.
        forearm: a hand's forearm for rendering,
            ``(vertices (N,3) world, faces (M,3), colours (N,3), normals (N,3) world)``
            ([`forearm_mesh`][handmesh_tutorial.hand.forearm_mesh]: scenery, not a body: it occludes
            but has no label, no annotation and no collision; its colours and normals continue
            the hand's at the wrist), else ``None``.
        tone: a hand's skin tone, an index into
            [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES] (0 lightest), else
            ``None``. Kept in memory only (the dataset stores the colours it produced, not the
            index): e.g. to break a detector's or a model's scores down by skin tone.
        normals: (V, 3) unit vertex normals for shading (world), else ``None`` (the renderer's
            own). A hand's come from
            [`wrist_seam_normals`][handmesh_tutorial.hand.mesh.wrist_seam_normals], so that the
            hand and its forearm shade as one surface.
    """

    label: int
    name: str
    kind: str
    side: str | None
    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    cylinders: Cylinders
    joints: np.ndarray | None = None
    pose: np.ndarray | None = None
    angles: np.ndarray | None = None
    shape: np.ndarray | None = None
    dynamic: bool = True
    forearm: tuple | None = None
    tone: int | None = None
    normals: np.ndarray | None = None


@dataclass
class Scene:
    """A generated interaction (world frame, metres), before rendering.

    Attributes:
        kind: ``"hand-hand"``, ``"hand-object"`` or ``"hand-chain"``.
        seed: the seed (or ``None`` when a Generator was passed).
        bodies: the bodies, in label order.
        target: label of the target hand (the left hand in hand-hand scenes).
        approach: (3,) unit direction from the centre body towards the second hand (step 2).
        stats: ``contact_mm`` (mesh-to-mesh distance, 0 when touching), ``penetration_mm`` (deepest
            vertex of one mesh inside the other), ``rounds``, ``stop`` (one of
            [`STOP_REASONS`][handmesh_tutorial.scenes.config.STOP_REASONS]), ``moves`` (accepted
            joint moves), ``blocked_contact`` / ``blocked_limit`` (joints stopped by a collision / a
            limit, or with natural poses by reaching their target), ``approach_mm`` (distance
            travelled in step 3), ``settle_mm`` (signed shift of the settle step, positive
            towards the centre), ``attempts`` (candidates tried).
        history: with ``record=True``, a list of snapshots ``{"step", "text", "bodies"}`` where
            ``bodies`` maps label -> ``{"cylinders", "vertices", "faces", "colors"}``.
    """

    kind: str
    seed: Any
    bodies: list[SceneBody]
    target: int
    approach: np.ndarray
    stats: dict
    history: list | None = None

    def body(self, label: int) -> SceneBody:
        """The body with this label."""
        for b in self.bodies:
            if b.label == label:
                return b
        raise ValueError(f"no body with label {label}; labels are "
                         f"{[b.label for b in self.bodies]}")

    def render_meshes(self, R=None, t=None) -> list[tuple]:
        """``(vertices, faces, sRGB colors, label, normals)`` per body, optionally moved
        ``x -> R x + t`` (normals turned by ``R``; ``None`` where the body has none); the tuples
        that [`Renderer.render`][handmesh_tutorial.render.renderer.Renderer.render] takes.

        Args:
            R: (3, 3) rotation (default identity).
            t: (3,) translation, metres (default zero).
        """
        R = np.eye(3) if R is None else np.asarray(R, float)
        t = np.zeros(3) if t is None else np.asarray(t, float)
        return [(b.vertices @ R.T + t, b.faces, b.colors, b.label,
                 None if b.normals is None else b.normals @ R.T) for b in self.bodies]

    def scenery_meshes(self, R=None, t=None) -> list[tuple]:
        """``(vertices, faces, sRGB colors, owner label, normals)`` of the scenery (the hands'
        forearms), optionally moved ``x -> R x + t``; see
        [`handmesh_tutorial.render.Renderer.render`][handmesh_tutorial.render.renderer.Renderer.render]'s
        ``occluders``."""
        R = np.eye(3) if R is None else np.asarray(R, float)
        t = np.zeros(3) if t is None else np.asarray(t, float)
        return [(b.forearm[0] @ R.T + t, b.forearm[1], b.forearm[2], b.label,
                 b.forearm[3] @ R.T) for b in self.bodies if b.forearm is not None]

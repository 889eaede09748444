"""A generated scene before rendering: `Scene` and its `SceneBody`s (world frame, metres).

A scene of one's own needs none of the generator's fields:
``Scene.compose([SceneBody.from_hand(out, side="left", label=1), SceneBody.from_mesh(v, f,
label=2)])`` fills the collision cylinders, colours and joints, and
[`render_scene`][handmesh_tutorial.scenes.sample.render_scene] (with ``camera=`` for a camera of
one's own) renders it with its label masks and visibility ratios. Docs page "For researchers".

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

    @classmethod
    def from_mesh(cls, vertices, faces, *, label: int, name: str = "object",
                  color=(0.7, 0.7, 0.7), colors=None) -> SceneBody:
        """A body of one's own mesh (an object): one collision cylinder around it.

        Args:
            vertices: (V, 3) world coordinates, metres (numpy, torch or ``trimesh`` arrays).
            faces: (F, 3) int triangles.
            label: its label in the masks (>= 1; 1 is the target hand of generated scenes).
            name: a name for the sample's ``names``.
            color: one linear RGB colour in [0, 1] for every vertex (when ``colors`` is None).
            colors: (V, 3) per-vertex RGB in [0, 1].

        Returns:
            A [`SceneBody`][handmesh_tutorial.scenes.scene.SceneBody] of kind ``"object"``;
            its ``cylinders`` hold one cylinder along the mesh's principal axis that contains
            every vertex.
        """
        v = _array(vertices, np.float64, "vertices")
        f = _array(faces, np.int64, "faces")
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"vertices must be (V, 3) and faces (F, 3), got {v.shape}, {f.shape}")
        if int(label) < 1:
            raise ValueError(f"label must be >= 1 (0 is the background), got {label}")
        c = np.broadcast_to(np.asarray(color if colors is None else colors, np.float64),
                            v.shape).copy()
        centre = v.mean(0)
        axis = np.linalg.svd(v - centre, full_matrices=False)[2][0]
        along = (v - centre) @ axis
        radial = np.linalg.norm(v - centre - along[:, None] * axis, axis=1)
        cyl = Cylinders((centre + along.min() * axis)[None], (centre + along.max() * axis)[None],
                        [max(float(radial.max()), 1e-4)], names=(name,))
        return cls(label=int(label), name=name, kind="object", side=None, vertices=v, faces=f,
                   colors=c, cylinders=cyl, dynamic=False)

    @classmethod
    def from_hand(cls, output_or_vertices, joints=None, *, side: str, label: int, model=None,
                  index: int = 0, tone: int | None = 2, faces=None) -> SceneBody:
        """A body of a hand: a [`HandModel`][handmesh_tutorial.hand.HandModel] output (or its
        vertices and joints) with its 20 collision cylinders and skin colours.

        Args:
            output_or_vertices: the model's output (``.vertices`` (B, V, 3), ``.joints``) or
                (V, 3) / (B, V, 3) vertices, metres, world frame.
            joints: (21, 3) FreiHAND keypoints when vertices are passed.
            side: ``"left"`` or ``"right"``.
            label: its label in the masks (>= 1).
            model: the hand model (its faces and skinning weights; default ``HandModel(side)``).
            index: which pose of a batch.
            tone: skin tone, an index into
                [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES].
            faces: (F, 3) faces (default: the model's).

        Returns:
            A [`SceneBody`][handmesh_tutorial.scenes.scene.SceneBody] of kind ``"hand"``.
        """
        from ..collision import hand_cylinders
        from ..hand import HandModel
        from ..hand.appearance import plain_skin_colors

        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if int(label) < 1:
            raise ValueError(f"label must be >= 1 (0 is the background), got {label}")
        model = HandModel(side) if model is None else model
        v = _array(getattr(output_or_vertices, "vertices", output_or_vertices), np.float64,
                   "vertices")
        j = _array(getattr(output_or_vertices, "joints", None) if joints is None else joints,
                   np.float64, "joints")
        v, j = (v[index] if v.ndim == 3 else v), (j[index] if j.ndim == 3 else j)
        cyl = hand_cylinders(v, j, model)
        f = np.asarray(model.faces if faces is None else faces, dtype=np.int64)
        colors = plain_skin_colors(len(v), tone)
        return cls(label=int(label), name=f"{side}_hand", kind="hand", side=side, vertices=v,
                   faces=f, colors=np.asarray(colors, np.float64), cylinders=cyl, joints=j,
                   dynamic=False, tone=tone)


def _array(x, dtype, name: str) -> np.ndarray:
    if x is None:
        raise ValueError(f"{name} is required")
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=dtype)


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

    @classmethod
    def compose(cls, bodies, *, target: int | None = None, kind: str = "composed") -> Scene:
        """A scene of one's own bodies (no generator): render it with
        [`render_scene`][handmesh_tutorial.scenes.sample.render_scene].

        Args:
            bodies: [`SceneBody`][handmesh_tutorial.scenes.scene.SceneBody]s with distinct
                labels (``SceneBody.from_hand``, ``SceneBody.from_mesh``).
            target: the label the camera frames (default: the first hand's, else the first
                body's).
            kind: the scene's ``kind`` string (the sample's ``kind``).

        Returns:
            The [`Scene`][handmesh_tutorial.scenes.scene.Scene], bodies in label order,
            ``approach`` zero, ``stats`` empty.
        """
        bodies = sorted(bodies, key=lambda b: b.label)
        labels = [b.label for b in bodies]
        if not bodies or len(set(labels)) != len(labels):
            raise ValueError(f"bodies need distinct labels, got {labels}")
        if target is None:
            target = next((b.label for b in bodies if b.kind == "hand"), labels[0])
        if target not in labels:
            raise ValueError(f"target {target} is not one of the labels {labels}")
        return cls(kind=kind, seed=None, bodies=bodies, target=int(target),
                   approach=np.zeros(3), stats={})

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

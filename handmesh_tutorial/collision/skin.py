"""Finger against finger, over many poses: the cylinder proxies and the skin itself.

The 20 cylinders of [`hand_cylinders`][handmesh_tutorial.collision.hand_proxies.hand_cylinders]
are the INTER-SH generator's fast test: thousands of candidate poses and placements per scene,
each rejected or kept in microseconds. Inside one hand they are tested with radii shrunk by
[`SELF_CONTACT_COMPRESSION`][handmesh_tutorial.collision.queries.SELF_CONTACT_COMPRESSION]
(30 %), because skin is soft: fingers pressed side by side overlap as cylinders before anything
passes through anything. So the proxies answer "is this pose plausible enough to keep", not "does
the skin interpenetrate": for the second question, test the mesh's triangles.

* [`finger_collisions`][handmesh_tutorial.collision.skin.finger_collisions]: per pose of a batch,
  the pairs of fingers whose cylinders intersect (the generator's test, finger pairs only).
* [`skin_collisions`][handmesh_tutorial.collision.skin.skin_collisions]: per pose, the pairs of
  fingers whose skin triangles intersect, with python-fcl when it is installed (the ``dev`` extra)
  or this module's own exact triangle test (numpy; the two agree, ``tests/test_collision.py``).
* [`finger_of_vertices`][handmesh_tutorial.collision.skin.finger_of_vertices]: which finger (and
  which phalanges) each vertex belongs to, from the skinning weights.

Fingers are numbered 0 thumb .. 4 pinky (``Cylinders.parts``; 5 is the palm). Metres, numpy in.
Docs pages "Collision" and "For researchers" (hand self-collision against python-fcl).
"""

from __future__ import annotations

import numpy as np

from .hand_proxies import _to_numpy, hand_cylinders
from .queries import SELF_CONTACT_COMPRESSION, self_collisions

__all__ = ["finger_collisions", "finger_of_vertices", "skin_collisions", "triangles_intersect"]

_FINGERS = 5


def _poses(vertices, name: str = "vertices") -> np.ndarray:
    v = np.asarray(_to_numpy(vertices, name), dtype=np.float64)  # None -> the shape error below
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (B, V, 3) or (V, 3), got {v.shape}")
    return v


def finger_collisions(output_or_vertices, joints21=None, model=None, *,
                      compression: float = SELF_CONTACT_COMPRESSION) -> list[set[tuple[int, int]]]:
    """The pairs of fingers whose cylinder proxies intersect, for every pose of a batch.

    ``hand_cylinders`` for each pose, then
    [`self_collisions`][handmesh_tutorial.collision.queries.self_collisions], kept when the two
    cylinders lie on two different fingers (palm pairs and pairs within a finger dropped).

    Args:
        output_or_vertices: a hand model output (``.vertices`` (B, V, 3), ``.joints``
            (B, 21, 3)) or vertices (B, V, 3) / (V, 3); torch or numpy, metres.
        joints21: (B, 21, 3) / (21, 3) keypoints when vertices are passed.
        model: the [`HandModel`][handmesh_tutorial.hand.HandModel] (its skinning weights fit the
            cylinders), or None.
        compression: see ``self_collisions`` (0: the fitted cylinders, not shrunk).

    Returns:
        One set per pose of ``(finger_a, finger_b)`` with ``finger_a < finger_b`` (0 thumb ..
        4 pinky).
    """
    verts = _poses(getattr(output_or_vertices, "vertices", output_or_vertices))
    joints = joints21 if joints21 is not None else getattr(output_or_vertices, "joints", None)
    if joints is None:
        raise ValueError("joints21 is required when vertices are passed without an output")
    joints = _poses(joints, "joints21")
    out = []
    for b in range(len(verts)):
        body = hand_cylinders(verts[b], joints[b], model)
        i, j = self_collisions(body, compression=compression)
        pa, pb = body.parts[i], body.parts[j]
        keep = (pa < _FINGERS) & (pb < _FINGERS) & (pa != pb)
        out.append({(int(min(a, c)), int(max(a, c))) for a, c in zip(pa[keep], pb[keep],
                                                                      strict=True)})
    return out


def finger_of_vertices(model, phalanges=(0, 1, 2)) -> np.ndarray:
    """The finger of each vertex by its largest skinning weight, or -1 (palm, wrist, others).

    Args:
        model: a [`HandModel`][handmesh_tutorial.hand.HandModel] (``skinning_weights`` (V, 16),
            MANO joint order), or a (V, 16) array of them.
        phalanges: which bones of each finger count: 0 proximal, 1 middle, 2 distal (the
            ``(2,)`` of "the skin of the distal segments").

    Returns:
        (V,) int64, 0 thumb .. 4 pinky, -1 elsewhere.
    """
    from ..hand.joints import MANO_TO_FREIHAND

    w = np.asarray(getattr(model, "skinning_weights", model))
    if w.ndim != 2 or w.shape[1] != 16:
        raise ValueError(f"skinning weights must have shape (V, 16), got {w.shape}")
    finger = np.full(16, -1, dtype=np.int64)
    for f, m in enumerate(MANO_TO_FREIHAND):
        if 1 <= m <= 15 and (f - 1) % 4 in tuple(phalanges):
            finger[m] = (f - 1) // 4
    return finger[w.argmax(1)]


def _segments_cross(p, q, tri) -> np.ndarray:
    """Whether segments ``p -> q`` (N, 3) cross triangles ``tri`` (N, 3, 3) (Moller-Trumbore with
    the segment parameter in [0, 1])."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = q - p
    h = np.cross(d, e2)
    a = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(a) > 1e-18
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    s = p - tri[:, 0]
    u = f * np.einsum("ij,ij->i", s, h)
    qv = np.cross(s, e1)
    v = f * np.einsum("ij,ij->i", d, qv)
    t = f * np.einsum("ij,ij->i", e2, qv)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)


def triangles_intersect(a, b) -> np.ndarray:
    """Whether triangles ``a[k]`` and ``b[k]`` intersect (exact for triangles in general position).

    Two triangles that are not coplanar intersect exactly when an edge of one crosses the other;
    coplanar overlaps (a set of measure zero for posed skin) are not detected.

    Args:
        a: (N, 3, 3) triangles, corners on axis 1.
        b: (N, 3, 3) triangles.

    Returns:
        (N,) bool.

    Examples:
        >>> import numpy as np
        >>> t = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
        >>> pierce = np.array([[[0.2, 0.2, -1], [0.2, 0.2, 1], [0.3, 0.3, 1]]], float)
        >>> triangles_intersect(t, pierce), triangles_intersect(t, pierce + [0, 0, 2])
        (array([ True]), array([False]))
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    hit = np.zeros(len(a), dtype=bool)
    for x, y in ((a, b), (b, a)):
        for k in range(3):
            hit |= _segments_cross(x[:, k], x[:, (k + 1) % 3], y)
    return hit


def _pair_numpy(ta: np.ndarray, tb: np.ndarray) -> bool:
    lo_a, hi_a, lo_b, hi_b = ta.min(1), ta.max(1), tb.min(1), tb.max(1)
    near = np.all((lo_a[:, None] <= hi_b[None]) & (lo_b[None] <= hi_a[:, None]), -1)
    i, j = np.nonzero(near)
    return bool(i.size) and bool(triangles_intersect(ta[i], tb[j]).any())


def _pair_fcl(fcl, ta: np.ndarray, tb: np.ndarray) -> bool:
    objs = []
    for t in (ta, tb):
        m = fcl.BVHModel()
        m.beginModel(3 * len(t), len(t))
        m.addSubModel(t.reshape(-1, 3), np.arange(3 * len(t)).reshape(-1, 3))
        m.endModel()
        objs.append(fcl.CollisionObject(m, fcl.Transform()))
    return fcl.collide(objs[0], objs[1], fcl.CollisionRequest()) > 0


def skin_collisions(vertices, faces, fingers, *, backend: str = "auto"
                    ) -> list[set[tuple[int, int]]]:
    """The pairs of fingers whose skin triangles intersect, for every pose of a batch.

    A triangle belongs to a finger when its three vertices do (``fingers``, e.g.
    [`finger_of_vertices`][handmesh_tutorial.collision.skin.finger_of_vertices]); triangles that
    span two labels (the webs between fingers) take part in no pair. The rest pose of the shipped
    hand has no intersecting pair.

    Args:
        vertices: (B, V, 3) or (V, 3) posed vertices, metres (torch or numpy).
        faces: (F, 3) int triangles.
        fingers: (V,) int finger of each vertex (0..4, -1 for none).
        backend: ``"fcl"`` (python-fcl's BVH test), ``"numpy"`` (bounding boxes, then the exact
            [`triangles_intersect`][handmesh_tutorial.collision.skin.triangles_intersect]) or
            ``"auto"`` (fcl when it imports).

    Returns:
        One set per pose of ``(finger_a, finger_b)``, ``finger_a < finger_b``.

    Raises:
        ValueError: ``fingers`` not one entry per vertex, faces out of range, an unknown
            backend.
        ModuleNotFoundError: ``backend="fcl"`` without python-fcl.
    """
    if backend not in ("auto", "fcl", "numpy"):
        raise ValueError(f"backend must be 'auto', 'fcl' or 'numpy', got {backend!r}")
    fcl = None
    if backend != "numpy":
        try:
            import fcl
        except ImportError:
            if backend == "fcl":
                raise ModuleNotFoundError("backend='fcl' needs python-fcl (pip install "
                                          "python-fcl, or the dev extra)") from None
    verts = _poses(vertices)
    f = np.asarray(faces, dtype=np.int64)
    fingers = np.asarray(fingers, dtype=np.int64).reshape(-1)
    if fingers.shape != (verts.shape[1],):
        raise ValueError(f"fingers must have one entry per vertex ({verts.shape[1]}), got "
                         f"{fingers.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= len(fingers))):
        raise ValueError(f"faces must be (F, 3) vertex ids in [0, {len(fingers)})")
    lab = fingers[f]
    tri_finger = np.where((lab == lab[:, :1]).all(1), lab[:, 0], -1)
    groups = [np.flatnonzero(tri_finger == k) for k in range(_FINGERS)]
    out = []
    for v in verts:
        tris = [v[f[g]] for g in groups]
        hits = set()
        for a in range(_FINGERS):
            for c in range(a + 1, _FINGERS):
                if len(tris[a]) and len(tris[c]) and (
                        _pair_fcl(fcl, tris[a], tris[c]) if fcl is not None
                        else _pair_numpy(tris[a], tris[c])):
                    hits.add((a, c))
        out.append(hits)
    return out

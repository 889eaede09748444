"""Articulated bodies (hands, chains) as cylinders fitted to their meshes: the 20-cylinder hand
(15 phalanges + 5 palm) from the 21 keypoints and the skinning weights, and how well it covers
the mesh.

Vertices (V, 3) and keypoints (21, 3, FreiHAND order) in metres, numpy or torch. Taught in
notebook 03 (cylinder collision).
"""

from __future__ import annotations

import numpy as np

from ._common import _check_points
from .cylinders import Cylinders
from .distance import point_cylinder_distance

__all__ = ["HAND_CYLINDER_NAMES", "hand_cylinders", "coverage"]


def _pts(x, name):
    a = _check_points(x, name)
    return a.reshape(-1, 3)


def fit_cylinders(vertices, segments, assignment, *, percentile: float = 95.0, extend=None,
                  names=None, parts=None, adjacent=None, min_radius: float = 1e-4) -> Cylinders:
    """Fit one cylinder per link of an articulated mesh: axis = the link's segment, radius fitted.

    The radius of cylinder ``k`` is the ``percentile`` of the distances to its axis line of the
    vertices assigned to it (those whose projection falls between the end points), so the union
    of cylinders hugs the mesh. Ends flagged in ``extend`` move outwards along the axis until they
    cover the axial range of the assigned vertices (e.g. the palm behind the wrist joint).

    Args:
        vertices: (V, 3) mesh vertices, metres.
        segments: (N, 2, 3) end points of each link's axis, metres.
        assignment: (V,) int, the link of each vertex, or -1 for a vertex no cylinder must cover.
        percentile: in (0, 100]; 100 covers every assigned vertex whose projection is inside.
        extend: optional (N, 2) bool, whether end 0 / end 1 of each link may be moved outwards.
        names: passed to [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].
        parts: passed to [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].
        adjacent: passed to [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].
        min_radius: radius of a link without assigned vertices, metres.

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] with N cylinders.

    Shapes:
        ``vertices (V, 3)``, ``segments (N, 2, 3)``, ``assignment (V,)`` -> N cylinders.
    """
    v = _pts(vertices, "vertices")
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 3 or seg.shape[1:] != (2, 3):
        raise ValueError(f"segments must have shape (N, 2, 3), got {seg.shape}")
    a = np.asarray(assignment).reshape(-1)
    if a.shape != (len(v),):
        raise ValueError(f"assignment must have shape ({len(v)},), got {a.shape}")
    if a.size and (a.min() < -1 or a.max() >= len(seg)):
        raise ValueError(f"assignment values must be in [-1, {len(seg)})")
    if not 0 < percentile <= 100:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    ext = (np.zeros((len(seg), 2), bool) if extend is None
           else np.asarray(extend, dtype=bool).reshape(len(seg), 2))
    p0, p1 = seg[:, 0].copy(), seg[:, 1].copy()
    radius = np.full(len(seg), float(min_radius))
    for k in range(len(seg)):
        d = p1[k] - p0[k]
        length = np.linalg.norm(d)
        if length == 0:
            raise ValueError(f"segment {k} has zero length")
        u = d / length
        w = v[a == k] - p0[k]
        if len(w) == 0:
            continue
        tau = w @ u
        rho = np.linalg.norm(w - tau[:, None] * u, axis=1)
        if ext[k, 0] and tau.min() < 0:
            p0[k] = p0[k] + tau.min() * u
            length, tau = length - tau.min(), tau - tau.min()
        if ext[k, 1] and tau.max() > length:
            p1[k] = p0[k] + tau.max() * u
            length = tau.max()
        inside = (tau >= 0) & (tau <= length)
        if inside.any():
            radius[k] = max(float(np.percentile(rho[inside], percentile)), min_radius)
    return Cylinders(p0, p1, radius, names or (), parts, adjacent)


HAND_CYLINDER_NAMES: tuple[str, ...] = tuple(
    f"{f}_{k}" for f in ("thumb", "index", "middle", "ring", "pinky") for k in (1, 2, 3)
) + ("palm_thumb", "palm_index", "palm_middle", "palm_ring", "palm_pinky")
"""Names of the 20 cylinders of
[`hand_cylinders`][handmesh_tutorial.collision.hand_proxies.hand_cylinders]: 15 phalanges (3 per
finger, thumb to pinky, base to tip; ``thumb_1`` is the thumb metacarpal) and 5 palm cylinders.
"""


def _hand_adjacency() -> np.ndarray:
    adj = []
    for f in range(5):
        adj += [(3 * f, 3 * f + 1), (3 * f + 1, 3 * f + 2)]        # consecutive phalanges
        adj += [(3 * f + s, 15 + p) for s in range(3) for p in range(5)]   # phalanges and palm
    adj += [(15 + p, 15 + q) for p in range(5) for q in range(p + 1, 5)]  # palm with palm
    adj += [(3, 6), (6, 9), (9, 12)]                       # neighbouring proximal phalanges
    return np.array(adj, dtype=np.int64)


def hand_segments(joints21, palm_spread: float = 0.7) -> np.ndarray:
    """Axis segments of the 20 hand cylinders from the 21 FreiHAND keypoints.

    Phalanges join consecutive keypoints of each finger (tips included). The palm has one cylinder
    from the wrist to the thumb CMC and one per finger towards its MCP joint, starting at the wrist
    shifted sideways by ``palm_spread`` times the MCP's offset from the middle MCP (the palm is
    almost as wide at the wrist as at the knuckles).

    Args:
        joints21: (21, 3) keypoints, FreiHAND order, metres.
        palm_spread: sideways spread of the palm cylinders at the wrist, in [0, 1].

    Returns:
        (20, 2, 3) end points, in the order of
        [`HAND_CYLINDER_NAMES`][handmesh_tutorial.collision.hand_proxies.HAND_CYLINDER_NAMES].

    Shapes:
        ``joints21 (21, 3)`` -> ``(20, 2, 3)`` metres.
    """
    j = np.asarray(joints21, dtype=np.float64)
    if j.shape != (21, 3):
        raise ValueError(f"joints21 must have shape (21, 3), got {j.shape}")
    seg = [(j[b + s], j[b + s + 1]) for b in (1, 5, 9, 13, 17) for s in range(3)]
    seg.append((j[0], j[1]))
    seg += [(j[0] + palm_spread * (j[k] - j[9]), j[k]) for k in (5, 9, 13, 17)]
    return np.array(seg)


def _to_numpy(x, name):
    if x is None:
        return None
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def hand_cylinders(output_or_vertices, joints21=None, model=None, index: int = 0, *,
                   percentile: float = 95.0, palm_spread: float = 0.7) -> Cylinders:
    """The hand as 20 cylinders (15 phalanges + 5 palm) fitted to its posed mesh.

    Vertices are assigned to cylinders by the model's skinning weights (argmax joint -> the bone
    leaving that joint; wrist-weighted vertices -> the nearest palm cylinder); without a model, each
    vertex goes to the nearest axis segment. Radii come from
    [`fit_cylinders`][handmesh_tutorial.collision.hand_proxies.fit_cylinders] with ``percentile``;
    the palm cylinders extend back over the wrist. ``parts`` is the finger (0 thumb .. 4 pinky, 5
    palm); ``adjacent`` follows the rule in
    [`self_collisions`][handmesh_tutorial.collision.queries.self_collisions].

    Args:
        output_or_vertices: a hand model output (with ``.vertices`` (B, V, 3) and ``.joints``
            (B, 21, 3)), or vertices (B, V, 3) / (V, 3); torch or numpy, metres.
        joints21: (B, 21, 3) / (21, 3) FreiHAND keypoints; taken from the output when None.
        model: the [`HandModel`][handmesh_tutorial.hand.HandModel] (for ``skinning_weights``), or
            None.
        index: which batch element to use.
        percentile: radius percentile, see
            [`fit_cylinders`][handmesh_tutorial.collision.hand_proxies.fit_cylinders].
        palm_spread: see [`hand_segments`][handmesh_tutorial.collision.hand_proxies.hand_segments].

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] with names
        [`HAND_CYLINDER_NAMES`][handmesh_tutorial.collision.hand_proxies.HAND_CYLINDER_NAMES],
        metres.

    Shapes:
        ``vertices (B, V, 3)`` or ``(V, 3)``, ``joints21 (B, 21, 3)`` or ``(21, 3)`` -> 20
        cylinders.
    """
    verts = _to_numpy(getattr(output_or_vertices, "vertices", output_or_vertices), "vertices")
    if joints21 is None:
        joints21 = getattr(output_or_vertices, "joints", None)
        if joints21 is None:
            raise ValueError("joints21 is required when vertices are passed without an output")
    joints = _to_numpy(joints21, "joints21")
    if verts.ndim == 3:
        verts = verts[index]
    if joints.ndim == 3:
        joints = joints[index]
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"vertices must have shape (B, V, 3) or (V, 3), got {verts.shape}")
    seg = hand_segments(joints, palm_spread)
    palm = np.arange(15, 20)
    if model is not None and getattr(model, "skinning_weights", None) is not None:
        w = np.asarray(model.skinning_weights)
        if w.shape != (len(verts), 16):
            raise ValueError(f"model.skinning_weights must have shape ({len(verts)}, 16), "
                             f"got {w.shape}")
        from ..hand import MANO_TO_FREIHAND  # here: hand imports torch, collision stays torch-free
        # MANO joint m sits at FreiHAND keypoint f; the bone leaving it is cylinder
        # (f - 1) - (f - 1) // 4 (3 per finger, in FreiHAND finger order).
        bone = np.full(16, -1)
        for f, m in enumerate(MANO_TO_FREIHAND):
            if 1 <= m <= 15:
                bone[m] = (f - 1) - (f - 1) // 4
        arg = w.argmax(1)
        assign = bone[arg]
        wrist = arg == 0
        if wrist.any():
            d = point_cylinder_distance(verts[wrist][:, None], seg[palm, 0], seg[palm, 1],
                                        np.zeros(5))
            assign[wrist] = palm[d.argmin(1)]
    else:
        d = point_cylinder_distance(verts[:, None], seg[:, 0], seg[:, 1], np.zeros(len(seg)))
        assign = d.argmin(1)
    extend = np.zeros((20, 2), bool)
    extend[palm, 0] = True
    parts = np.r_[np.repeat(np.arange(5), 3), np.full(5, 5)]
    return fit_cylinders(verts, seg, assign, percentile=percentile, extend=extend,
                         names=HAND_CYLINDER_NAMES, parts=parts, adjacent=_hand_adjacency())


def coverage(vertices, body: Cylinders, *, tol: float = 1e-6) -> dict:
    """How much of a mesh lies outside the union of its cylinders.

    Args:
        vertices: (V, 3) mesh vertices, metres.
        body: the [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] meant to cover
            them.
        tol: a vertex counts as outside when it is further than this from every cylinder, metres
            (a finite number >= 0).

    Returns:
        dict with ``fraction_outside`` (of the vertices), ``max_outside_mm``, ``mean_outside_mm``
        (over the outside vertices, 0 when none) and ``distance`` ((V,) metres, 0 when covered).

    Raises:
        ValueError: ``tol`` negative, NaN or infinite (a NaN counted every vertex as covered).

    Shapes:
        ``vertices (V, 3)`` -> ``distance (V,)`` metres (and scalars).
    """
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.number)) \
            or not 0 <= tol < np.inf:
        raise ValueError(f"tol must be a finite distance >= 0 (metres), got {tol!r}")
    v = _pts(_to_numpy(vertices, "vertices"), "vertices")
    d = point_cylinder_distance(v[:, None], body.p0[None], body.p1[None], body.radius[None])
    d = d.min(1)
    out = d > tol
    return {"fraction_outside": float(out.mean()), "max_outside_mm": float(d.max() * 1e3),
            "mean_outside_mm": float(d[out].mean() * 1e3) if out.any() else 0.0, "distance": d}

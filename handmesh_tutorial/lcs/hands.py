"""The LCS of a hand model's 15 articulated joints, and random poses within its joint limits.

[`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs] applies the paper's rule to a
[`HandModel`][handmesh_tutorial.hand.model.HandModel] or
[`ManoModel`][handmesh_tutorial.mano.model.ManoModel] (the flexion vertex of each joint is picked
deterministically on the rest mesh, see [`handmesh_tutorial.lcs`][handmesh_tutorial.lcs]);
[`random_pose`][handmesh_tutorial.lcs.hands.random_pose] draws (n,15,3) axis-angle poses whose LCS
angles lie inside the limits.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

import numpy as np

from .articulation import Articulation
from .frames import local_frames, select_flexion_vertices
from .limits import HAND_JOINT_KINDS, _resolve_limits

__all__ = ["palm_normal", "hand_lcs", "random_pose"]


def _np(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def palm_normal(joints21, side: str) -> np.ndarray:
    """Unit palmar normal of a hand from its 21 FreiHAND-order keypoints (rest pose).

    ``(index MCP - pinky MCP) × (middle MCP - wrist)`` points out of the palm of a right hand
    (radial × distal); a left hand uses the negative.
    """
    j = _np(joints21)
    n = np.cross(j[5] - j[17], j[9] - j[0])
    n = n / np.linalg.norm(n)
    return n if side == "right" else -n


def hand_lcs(model, limits="anatomical", *, thumb_flexion_angle: float = 45.0,
             slab: float = 0.25) -> Articulation:
    """The LCS of the 15 articulated joints of a hand model, in MANO joint order 1..15.

    Works for [`HandModel`][handmesh_tutorial.hand.model.HandModel] and
    [`ManoModel`][handmesh_tutorial.mano.model.ManoModel]
    (anything with ``side``, ``template_vertices``, ``skinning_weights``, ``parents`` and a
    zero-pose call returning ``joints`` (FreiHAND order) and ``joints_mano``).

    Args:
        model: the hand model (its rest pose, zero shape, is used).
        limits: ``"anatomical"`` (default), ``"paper"`` or ``(lower, upper)`` (15,3) radians.
        thumb_flexion_angle: degrees the thumb's flexion direction is turned from the palmar
            normal towards the little finger.
        slab: candidate slab of the vertex rule (fraction of the bone length).

    Returns:
        An [`Articulation`][handmesh_tutorial.lcs.articulation.Articulation] whose ``to_pose``
        output is the model's ``pose`` (15,3).
    """
    from .. import hand as _hand  # lazy: keeps `import handmesh_tutorial.lcs` free of torch

    side = getattr(model, "side", "right")
    out = model()
    j21 = _np(out.joints)[0]
    j16 = _np(out.joints_mano)[0]
    m2f = np.asarray(_hand.joints._KEYPOINT_OF_MANO)
    fparents = np.asarray(_hand.FREIHAND_PARENTS)
    child_kp = np.array([int(np.flatnonzero(fparents == m2f[k])[0]) for k in range(1, 16)])
    joints = j16[1:]
    child_points = j21[child_kp]

    n = palm_normal(j21, side)
    radial = j21[5] - j21[17]
    ulnar = -radial / np.linalg.norm(radial)
    t = np.deg2rad(thumb_flexion_angle)
    thumb_dir = np.cos(t) * n + np.sin(t) * ulnar
    directions = np.array([thumb_dir if k.startswith("thumb") else n for k in HAND_JOINT_KINDS])
    verts = _np(model.template_vertices)
    ids = select_flexion_vertices(verts, joints, child_points, directions,
                                  weights=_np(model.skinning_weights),
                                  joint_ids=np.arange(1, 16), parents=np.asarray(model.parents),
                                  slab=slab)
    frames = local_frames(joints, child_points, verts[ids])
    lower, upper, name = _resolve_limits(limits, None)
    names = tuple(_hand.MANO_JOINT_NAMES[1:16])
    return Articulation(names=names, joints=joints, frames=frames, lower=lower, upper=upper,
                        child_points=child_points, flexion_points=verts[ids],
                        flexion_vertex_ids=ids, joint_ids=np.arange(1, 16), side=side,
                        limits_name=name)


def random_pose(model_or_lcs, rng=None, n: int | None = None, limits=None,
                scale: float = 1.0) -> np.ndarray:
    """Random pose vectors whose LCS angles respect the limits.

    Args:
        model_or_lcs: an [`Articulation`][handmesh_tutorial.lcs.articulation.Articulation] or a hand
            model (then [`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs] is built).
        rng: ``numpy.random.Generator`` or seed (same seed -> same bytes).
        n: number of poses; ``None`` returns one (15,3) pose.
        limits: ``None`` (keep the articulation's; ``"anatomical"`` for a model), ``"paper"``,
            ``"anatomical"`` or ``(lower, upper)`` arrays.
        scale: shrink every range towards 0 (1 = full range).

    Returns:
        (J,3) or (n,J,3) float32 axis-angle poses (MANO convention).
    """
    art = model_or_lcs if isinstance(model_or_lcs, Articulation) else \
        hand_lcs(model_or_lcs, limits or "anatomical")
    if limits is not None:
        art = art.with_limits(limits)
    return art.random_pose(rng, n, scale)

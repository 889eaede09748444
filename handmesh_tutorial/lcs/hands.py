"""The LCS of a hand model's 15 articulated joints, and random poses within its joint limits.

[`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs] applies the paper's rule to a
[`HandModel`][handmesh_tutorial.hand.model.HandModel] or
[`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel] (the flexion vertex of each joint is
picked deterministically on the rest mesh, see [`handmesh_tutorial.lcs`][handmesh_tutorial.lcs]);
[`random_pose`][handmesh_tutorial.lcs.hands.random_pose] draws (n,15,3) axis-angle poses whose LCS
angles lie inside the limits.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .articulation import Articulation
from .frames import local_frames, select_flexion_vertices
from .limits import HAND_JOINT_KINDS, _resolve_limits
from .synergy import THUMB_JOINTS

__all__ = ["THUMB_ZERO_ELEVATION_DEG", "thumb_elevation", "thumb_zero_rotation", "hand_lcs",
           "random_pose"]


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


THUMB_ZERO_ELEVATION_DEG: float = 5.0
"""Angle (degrees) between the thumb's CMC-to-tip direction and the palm plane that the thumb's
zero angles mean in [`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs]: a thumb lying near the
palm plane, as in MANO's flat zero pose. The MakeHuman template's rest thumb stands 35° out of the
palm (half opposed). Why 5°: a hand detector trained on real photographs agrees with a rest hand
whose thumb is turned there (docs page *Realistic scenes*, "Measured with a detector trained on
real photographs").
"""


def thumb_elevation(joints21, side: str) -> float:
    """Angle (degrees) of a hand's thumb out of its palm plane: the CMC-to-tip direction against
    the palm (positive towards the palmar side).

    Args:
        joints21: (21,3) FreiHAND-order keypoints (the CMC is keypoint 1, the tip 4).
        side: ``"right"`` or ``"left"``.
    """
    j = _np(joints21)
    d = j[4] - j[1]
    d = d / np.linalg.norm(d)
    return float(np.rad2deg(np.arcsin(np.clip(d @ palm_normal(j, side), -1.0, 1.0))))


def thumb_zero_rotation(joints21, side: str,
                        elevation: float = THUMB_ZERO_ELEVATION_DEG) -> np.ndarray:
    """(3,3) rotation about the thumb's CMC that turns the thumb to ``elevation`` degrees out of
    the palm plane, about the axis perpendicular to the thumb and to the palm normal (so the
    thumb swings straight towards or away from the palm, without turning sideways).

    Args:
        joints21: (21,3) FreiHAND-order keypoints of the hand in the pose to start from.
        side: ``"right"`` or ``"left"``.
        elevation: target angle out of the palm plane, degrees (positive: palmar).
    """
    j = _np(joints21)
    n = palm_normal(j, side)
    d = (j[4] - j[1]) / np.linalg.norm(j[4] - j[1])
    axis = np.cross(d, n)
    axis = axis / np.linalg.norm(axis)     # a turn by +t about d x n moves d towards n
    turn = np.deg2rad(elevation - thumb_elevation(j, side))
    return Rotation.from_rotvec(axis * turn).as_matrix()


def hand_lcs(model, limits="anatomical", *, thumb_flexion_angle: float = 45.0,
             slab: float = 0.25,
             thumb_zero_elevation: float | None = THUMB_ZERO_ELEVATION_DEG) -> Articulation:
    """The LCS of the 15 articulated joints of a hand model, in MANO joint order 1..15.

    Works for [`HandModel`][handmesh_tutorial.hand.model.HandModel] and
    [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]
    (anything with ``side``, ``template_vertices``, ``skinning_weights``, ``parents`` and a
    zero-pose call returning ``joints`` (FreiHAND order) and ``joints_mano``).

    Args:
        model: the hand model (its rest pose, zero shape, is used).
        limits: ``"anatomical"`` (default), ``"paper"`` or ``(lower, upper)`` (15,3) radians.
        thumb_flexion_angle: degrees the thumb's flexion direction is turned from the palmar
            normal towards the little finger.
        slab: candidate slab of the vertex rule (fraction of the bone length).
        thumb_zero_elevation: degrees out of the palm plane that the thumb's zero angles mean
            ([`THUMB_ZERO_ELEVATION_DEG`][handmesh_tutorial.lcs.hands.THUMB_ZERO_ELEVATION_DEG]):
            the CMC's ``zero_rotations`` entry turns the rest thumb there
            ([`thumb_zero_rotation`][handmesh_tutorial.lcs.hands.thumb_zero_rotation]), so its
            limits and the pose prior count from a thumb near the palm plane, as anatomical
            ranges do. ``None``: zero angles are the rest pose for every joint.

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
    zero = None
    if thumb_zero_elevation is not None:
        zero = np.tile(np.eye(3), (15, 1, 1))
        zero[THUMB_JOINTS[0] - 1] = thumb_zero_rotation(j21, side, thumb_zero_elevation)
    return Articulation(names=names, joints=joints, frames=frames, lower=lower, upper=upper,
                        child_points=child_points, flexion_points=verts[ids],
                        flexion_vertex_ids=ids, joint_ids=np.arange(1, 16), side=side,
                        limits_name=name, zero_rotations=zero)


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

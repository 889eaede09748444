"""LCS angles <-> rotations <-> axis-angle pose vectors, limits checks and forward kinematics.

A joint's articulation is three angles ``(a_x, a_y, a_z)`` (radians) about its LCS axes, composed
``R_y(a_y) R_x(a_x) R_z(a_z)``; in rest-pose (parent) axes the rotation is ``F R(a) F^T`` and its
axis-angle is ``F @ rotvec(R(a))`` (MANO's pose convention). Angles are (..., J, 3), frames
(J,3,3).

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "rotation_from_lcs_angles", "lcs_angles_to_pose", "pose_to_lcs_angles", "mirror_angles",
    "clip_angles", "within_limits", "forward_kinematics",
]

_EULER = "YXZ"  # intrinsic: flexion (y), then abduction (x), then twist (z)


def _check_angles(frames: np.ndarray, angles) -> np.ndarray:
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-2:] != (frames.shape[0], 3):
        raise ValueError(f"angles must have shape (..., {frames.shape[0]}, 3), "
                         f"got {angles.shape}")
    return angles


def _check_zero_rotations(frames: np.ndarray, zero_rotations) -> tuple[np.ndarray | None,
                                                                         np.ndarray]:
    """``(zero rotations (J,3,3) or None, indices of the joints whose entry is not identity)``.

    Raises:
        ValueError: another shape than (J,3,3), NaN or inf, or an entry that is not a rotation
            (orthonormal, det +1, to 1e-6).
    """
    if zero_rotations is None:
        return None, np.zeros(0, int)
    z = np.asarray(zero_rotations, dtype=np.float64)
    n = frames.shape[0]
    if z.shape != (n, 3, 3) or not np.isfinite(z).all():
        raise ValueError(f"zero_rotations must be ({n}, 3, 3) finite rotation matrices (an "
                         f"Articulation's zero_rotations), got shape {z.shape}")
    err = np.abs(z @ np.swapaxes(z, -1, -2) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((err > 1e-6) | (np.linalg.det(z) < 0))
    if bad.size:
        raise ValueError(f"zero_rotations[{int(bad[0])}] is not a rotation matrix "
                         "(orthonormal, det +1)")
    off = np.abs(z - np.eye(3)).max(axis=(1, 2))
    return z, np.flatnonzero(off > 0.0)


def _euler_rotation(angles: np.ndarray) -> Rotation:
    """scipy Rotation of R_y(a_y) R_x(a_x) R_z(a_z) for angles (N,3) ordered (a_x, a_y, a_z)."""
    return Rotation.from_euler(_EULER, angles[:, [1, 0, 2]])


def rotation_from_lcs_angles(frames, angles, zero_rotations=None) -> np.ndarray:
    """Rotation matrices of joints turned by LCS angles, in rest-pose (parent) axes.

    Args:
        frames: (J,3,3) rest LCS, columns ``x, y, z``.
        angles: (..., J, 3) radians about ``(x, y, z)``, composed ``R_y R_x R_z``.
        zero_rotations: optional (J,3,3) rotations that zero angles mean (an
            [`Articulation`][handmesh_tutorial.lcs.articulation.Articulation]'s
            ``zero_rotations``: the hand's re-based thumb); ``None``: zero angles are the rest
            pose. Pass it whenever the articulation has one, or use its methods: without it
            the thumb's angles are read from the wrong zero.

    Returns:
        (..., J, 3, 3) ``O_k F_k R(a) F_k^T`` (``O_k`` = identity without ``zero_rotations``).

    Examples:
        >>> import numpy as np
        >>> from handmesh_tutorial.lcs import rotation_from_lcs_angles
        >>> frames = np.eye(3)[None]  # one joint whose LCS is the world axes
        >>> R = rotation_from_lcs_angles(frames, [[0.0, np.pi / 2, 0.0]])  # 90° of flexion
        >>> np.round(R[0] @ [0, 0, 1], 6) + 0.0  # the bone (z) swings to the flexion side (x)
        array([1., 0., 0.])
    """
    frames = np.asarray(frames, dtype=np.float64)
    angles = _check_angles(frames, angles)
    zero, k = _check_zero_rotations(frames, zero_rotations)
    local = _euler_rotation(angles.reshape(-1, 3)).as_matrix().reshape(*angles.shape, 3)
    rot = frames @ local @ np.swapaxes(frames, -1, -2)
    if len(k):
        rot[..., k, :, :] = zero[k] @ rot[..., k, :, :]
    return rot


def lcs_angles_to_pose(frames, angles, zero_rotations=None) -> np.ndarray:
    """Axis-angle pose vectors (MANO convention) of LCS angles.

    Args:
        frames: (J,3,3) rest LCS.
        angles: (..., J, 3) radians.
        zero_rotations: optional (J,3,3), as in
            [`rotation_from_lcs_angles`][handmesh_tutorial.lcs.angles.rotation_from_lcs_angles]
            (``art.zero_rotations``; ``art.to_pose`` passes it).

    Returns:
        (..., J, 3) float64 axis-angle of ``O_k F_k R(a) F_k^T`` (= ``F_k @ rotvec(R(a))``
        where ``O_k`` is the identity).
    """
    frames = np.asarray(frames, dtype=np.float64)
    angles = _check_angles(frames, angles)
    zero, k = _check_zero_rotations(frames, zero_rotations)
    rotvec = _euler_rotation(angles.reshape(-1, 3)).as_rotvec().reshape(angles.shape)
    pose = np.einsum("jab,...jb->...ja", frames, rotvec)
    if len(k):   # only the offset joints go through matrices (the others keep their bytes)
        sel = rotation_from_lcs_angles(frames[k], angles[..., k, :], zero[k])
        pose[..., k, :] = Rotation.from_matrix(sel.reshape(-1, 3, 3)).as_rotvec().reshape(
            sel.shape[:-1])
    return pose


def pose_to_lcs_angles(frames, pose, zero_rotations=None) -> np.ndarray:
    """Inverse of [`lcs_angles_to_pose`][handmesh_tutorial.lcs.angles.lcs_angles_to_pose] (exact
    while ``|a_x| < 90°``), with the same ``zero_rotations``.

    ``pose_to_lcs_angles(art.frames, art.to_pose(a), art.zero_rotations)`` gives back ``a``
    (as ``art.from_pose`` does); without ``zero_rotations`` a hand's thumb CMC is read from its
    rest pose instead of its re-based zero (0.4 rad off).

    Args:
        frames: (J,3,3) rest LCS.
        pose: (..., J, 3) axis-angle in rest-pose (parent) axes.
        zero_rotations: optional (J,3,3), as in
            [`rotation_from_lcs_angles`][handmesh_tutorial.lcs.angles.rotation_from_lcs_angles].

    Returns:
        (..., J, 3) radians ``(a_x, a_y, a_z)``; ``a_y`` and ``a_z`` in (-π, π].
    """
    frames = np.asarray(frames, dtype=np.float64)
    pose = np.array(_check_angles(frames, pose), dtype=np.float64)
    zero, k = _check_zero_rotations(frames, zero_rotations)
    if len(k):   # undo the zero rotation: F R(a) F^T = O^T L
        sel = pose[..., k, :]
        local = Rotation.from_rotvec(sel.reshape(-1, 3)).as_matrix().reshape(*sel.shape, 3)
        rel = np.swapaxes(zero[k], -1, -2) @ local
        pose[..., k, :] = Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(
            sel.shape)
    local = np.einsum("jba,...jb->...ja", frames, pose)  # F^T rotvec
    eul = Rotation.from_rotvec(local.reshape(-1, 3)).as_euler(_EULER)
    return eul[:, [1, 0, 2]].reshape(pose.shape)


def mirror_angles(angles) -> np.ndarray:
    """Angles of the mirrored joint motion: ``(a_x, a_y, a_z) -> (-a_x, a_y, -a_z)``.

    With left frames built as mirror images of right ones (see the module text), right-hand
    angles ``a`` and left-hand angles ``mirror_angles(a)`` give mirror-image poses.
    """
    out = np.array(angles, dtype=np.float64, copy=True)
    out[..., 0] *= -1
    out[..., 2] *= -1
    return out


def _limits(lower, upper, atol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``lower``, ``upper`` as float arrays, checked as `Articulation.with_limits` checks them:
    no NaN, ``lower <= upper``; ``atol`` a finite number >= 0."""
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    if np.isnan(lo).any() or np.isnan(hi).any() or np.any(lo > hi):
        raise ValueError(f"limits must be lower <= upper (radians, no NaN), got lower "
                         f"{np.array2string(lo.ravel()[:6], precision=3)}..., upper "
                         f"{np.array2string(hi.ravel()[:6], precision=3)}...")
    if isinstance(atol, bool) or not isinstance(atol, (int, float, np.number)) \
            or not 0 <= atol < np.inf:
        raise ValueError(f"atol must be a finite number of radians >= 0, got {atol!r}")
    return lo, hi


def clip_angles(angles, lower, upper) -> np.ndarray:
    """Clip angles (..., J, 3) to per-joint, per-axis limits ``lower``/``upper`` (J,3), radians.

    Raises:
        ValueError: a NaN limit or ``lower > upper`` somewhere (numpy would return ``upper``).
    """
    lower, upper = _limits(lower, upper)
    return np.clip(np.asarray(angles, dtype=np.float64), lower, upper)


_LIMITS_ATOL = 1e-5
"""Default tolerance of the limit tests, radians (~0.0006 degrees): a float32 axis-angle pose read
back as angles is off by ~1e-7 rad, and an exact range of zero width (a hinge's side axes) would
otherwise reject every such pose."""


def within_limits(angles, lower, upper, atol: float = _LIMITS_ATOL) -> np.ndarray:
    """True where all 3J angles of a pose are inside the limits.

    Args:
        angles: (..., J, 3) radians.
        lower: (J,3) radians.
        upper: (J,3) radians.
        atol: tolerance in radians, a finite number >= 0; the default 1e-5 accepts angles
            recovered from a float32 pose (``from_pose(to_pose(a))``, error ~1e-7 rad); ``0`` =
            the exact test.

    Returns:
        bool array of shape ``angles.shape[:-2]`` (``False`` where an angle is NaN).

    Raises:
        ValueError: a NaN limit, ``lower > upper`` somewhere, or a negative or NaN ``atol``.
    """
    lower, upper = _limits(lower, upper, atol)
    a = np.asarray(angles, dtype=np.float64)
    ok = (a >= lower - atol) & (a <= upper + atol)
    return ok.all(axis=(-2, -1))


def forward_kinematics(rest_joints, parents, rotations, root_rotation=None) -> np.ndarray:
    """Posed joint positions of a kinematic tree with MANO-convention local rotations.

    ``G_k = G_parent(k) · [R_k | j_k - j_parent(k)]``; the root keeps its position and turns by
    ``root_rotation``. Use it to predict where a child joint goes for given LCS angles.

    Args:
        rest_joints: (K,3) rest positions, parents before children.
        parents: (K,) parent indices, -1 for the root.
        rotations: (..., K, 3, 3) local rotations in rest axes (the root's entry is ignored when
            ``root_rotation`` is given).
        root_rotation: optional (..., 3, 3).

    Returns:
        (..., K, 3) posed positions.
    """
    rest = np.asarray(rest_joints, dtype=np.float64)
    rots = np.asarray(rotations, dtype=np.float64)
    if root_rotation is not None:
        rots = rots.copy()
        rots[..., 0, :, :] = root_rotation
    glob_r = [None] * len(rest)
    glob_t = [None] * len(rest)
    for k, p in enumerate(parents):
        if p < 0:
            glob_r[k] = rots[..., k, :, :]
            glob_t[k] = np.broadcast_to(rest[k], rots.shape[:-3] + (3,))
        else:
            glob_r[k] = glob_r[p] @ rots[..., k, :, :]
            glob_t[k] = glob_t[p] + np.einsum("...ab,b->...a", glob_r[p], rest[k] - rest[p])
    return np.stack(glob_t, axis=-2)


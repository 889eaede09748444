"""[`Articulation`][handmesh_tutorial.lcs.articulation.Articulation]: the rest LCS and per-axis
limits of J joints, with conversions to pose vectors and uniform random angles inside the limits.

A joint's zero angles need not be its rest pose: ``zero_rotations`` (optional) holds, per joint,
the local rotation that zero angles mean. The hand's thumb uses it (see
[`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs]): the MakeHuman template holds its thumb half
opposed, and the anatomical limits are measured from a thumb lying near the palm plane.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .angles import (
    _LIMITS_ATOL,
    clip_angles,
    lcs_angles_to_pose,
    pose_to_lcs_angles,
    rotation_from_lcs_angles,
    within_limits,
)
from .limits import _resolve_limits

__all__ = ["Articulation"]


@dataclass(frozen=True, eq=False)
class Articulation:
    """Rest LCS and per-axis limits of J articulated joints.

    Attributes:
        names: (J,) joint names.
        joints: (J,3) rest positions, metres.
        frames: (J,3,3) rest LCS, columns ``x`` (flexion side), ``y = z × x``, ``z`` (to child).
        lower: (J,3) lower limits, radians, axis order ``x, y, z``.
        upper: (J,3) upper limits, radians.
        child_points: (J,3) the next point along the chain of each joint.
        flexion_points: (J,3) the points that defined ``x`` (mesh vertices for a hand).
        flexion_vertex_ids: (J,) ids of those vertices, or ``None``.
        joint_ids: (J,) index of each joint in its model's kinematic tree (1..15 for a hand).
        side: ``"right"``, ``"left"`` or ``None`` (objects).
        limits_name: ``"paper"``, ``"anatomical"`` or ``"custom"``.
        zero_rotations: (J,3,3) local rotation (rest axes) that zero angles mean, or ``None``
            (zero angles = the rest pose). Angles ``a`` then give ``L_k = O_k F_k R(a) F_k^T``:
            the joint turns about its rest LCS and the whole is then turned by ``O_k``, so the
            LCS at zero angles is ``O_k F_k`` (it moves with the bone).
    """

    names: tuple
    joints: np.ndarray
    frames: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    child_points: np.ndarray
    flexion_points: np.ndarray
    flexion_vertex_ids: np.ndarray | None = None
    joint_ids: np.ndarray | None = None
    side: str | None = None
    limits_name: str = "custom"
    zero_rotations: np.ndarray | None = None

    @property
    def num_joints(self) -> int:
        """Number of articulated joints J."""
        return len(self.names)

    def rotations(self, angles) -> np.ndarray:
        """(..., J, 3, 3) local rotations (rest axes) of LCS angles (..., J, 3) radians."""
        return rotation_from_lcs_angles(self.frames, angles, self.zero_rotations)

    def to_pose(self, angles) -> np.ndarray:
        """(..., J, 3) float32 axis-angle pose (MANO convention) of LCS angles, radians
        ([`lcs_angles_to_pose`][handmesh_tutorial.lcs.angles.lcs_angles_to_pose] with this
        articulation's ``zero_rotations``)."""
        return lcs_angles_to_pose(self.frames, angles, self.zero_rotations).astype(np.float32)

    def from_pose(self, pose) -> np.ndarray:
        """(..., J, 3) LCS angles (radians) of an axis-angle pose
        ([`pose_to_lcs_angles`][handmesh_tutorial.lcs.angles.pose_to_lcs_angles] with this
        articulation's ``zero_rotations``)."""
        return pose_to_lcs_angles(self.frames, pose, self.zero_rotations)

    def clip(self, angles) -> np.ndarray:
        """Angles clipped to this articulation's limits."""
        return clip_angles(angles, self.lower, self.upper)

    def within_limits(self, angles, atol: float = _LIMITS_ATOL) -> np.ndarray:
        """Whether every angle lies within the limits.

        Args:
            angles: (..., J, 3) LCS angles, radians.
            atol: tolerance in radians; the default 1e-5 accepts angles read back from a
                float32 pose (``from_pose(random_pose(...))``, error ~1e-7 rad); ``0`` = the
                exact test.

        Returns:
            bool array of shape ``angles.shape[:-2]``.
        """
        return within_limits(angles, self.lower, self.upper, atol)

    def with_limits(self, limits) -> Articulation:
        """A copy with other limits: ``"paper"``, ``"anatomical"`` (hands) or ``(lower, upper)``
        arrays (J,3) in radians."""
        lower, upper, name = _resolve_limits(limits, self)
        return replace(self, lower=lower, upper=upper, limits_name=name)

    def random_angles(self, rng=None, n: int | None = None, scale: float = 1.0) -> np.ndarray:
        """Uniform angles inside the limits scaled by ``scale`` about zero.

        Args:
            rng: ``numpy.random.Generator`` or seed.
            n: number of poses; ``None`` returns a single (J,3) array.
            scale: in [0,1]; each range shrinks towards its neutral angle (0, or the nearest
                limit when 0 is outside), so the result always respects the limits.

        Returns:
            (J,3) or (n,J,3) radians.
        """
        if not 0.0 <= scale <= 1.0:
            raise ValueError(f"scale must be in [0, 1], got {scale}")
        rng = np.random.default_rng(rng)
        shape = (self.num_joints, 3) if n is None else (n, self.num_joints, 3)
        # Shrink each range towards its neutral angle (0, or the nearest limit if 0 is outside).
        neutral = np.clip(0.0, self.lower, self.upper)
        lo = neutral + scale * (self.lower - neutral)
        hi = neutral + scale * (self.upper - neutral)
        return rng.uniform(lo, hi, size=shape)

    def random_pose(self, rng=None, n: int | None = None, scale: float = 1.0) -> np.ndarray:
        """Random valid pose vectors:
        [`random_angles`][handmesh_tutorial.lcs.articulation.Articulation.random_angles] through
        [`to_pose`][handmesh_tutorial.lcs.articulation.Articulation.to_pose].

        Returns:
            (J,3) or (n,J,3) float32 axis-angle, ready for ``HandModel(pose=...)``.
        """
        return self.to_pose(self.random_angles(rng, n, scale))


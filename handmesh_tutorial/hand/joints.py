"""Joint orders of the whole library: MANO's 16-joint kinematic tree, the 21 FreiHAND keypoints and
the mapping between them (this is the one place they are defined).

MANO order (16 joints): 0 wrist, 1-3 index, 4-6 middle, 7-9 pinky, 10-12 ring, 13-15 thumb.
FreiHAND order (21 keypoints): 0 wrist, 1-4 thumb (base to tip), 5-8 index, 9-12 middle, 13-16 ring,
17-20 pinky. The five fingertips are mesh vertices, not skeleton joints.
[`MIRROR_AXIS`][handmesh_tutorial.hand.joints.MIRROR_AXIS] is the axis that turns a right hand into
a left one.

Taught in notebook 01 (the hand model) and used in notebook 02 (local coordinate systems).
"""

from __future__ import annotations

__all__ = [
    "MANO_JOINT_NAMES", "MANO_PARENTS", "FREIHAND_JOINT_NAMES", "FREIHAND_PARENTS",
    "MANO_TO_FREIHAND", "FINGERTIP_NAMES", "FINGER_NAMES", "MIRROR_AXIS",
]

MANO_JOINT_NAMES: tuple[str, ...] = (
    "wrist",
    "index1", "index2", "index3",
    "middle1", "middle2", "middle3",
    "pinky1", "pinky2", "pinky3",
    "ring1", "ring2", "ring3",
    "thumb1", "thumb2", "thumb3",
)
"""The 16 joints of the MANO kinematic tree, in MANO order ("1" = the joint nearest the wrist).
For the thumb, ``thumb1`` is the carpometacarpal (CMC) joint, ``thumb2`` the MCP, ``thumb3`` the IP.
"""

MANO_PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)
"""Parent of each MANO joint (-1 for the root); parents come before their children."""

FINGER_NAMES: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinky")
"""Fingers in FreiHAND order (also the order of the 5 fingertips everywhere in the library)."""

FINGERTIP_NAMES: tuple[str, ...] = tuple(f"{f}_tip" for f in FINGER_NAMES)
"""The 5 fingertip keypoints (vertices of the mesh), thumb to pinky."""

FREIHAND_JOINT_NAMES: tuple[str, ...] = ("wrist",) + tuple(
    f"{finger}{k}" for finger in FINGER_NAMES for k in ("1", "2", "3", "_tip"))
"""The 21 keypoints in FreiHAND order: wrist, then per finger (thumb, index, middle, ring, pinky)
four points from the base to the tip. For the thumb these are CMC, MCP, IP, tip; for the other
fingers MCP, PIP, DIP, tip.
"""

FREIHAND_PARENTS: tuple[int, ...] = (-1,) + tuple(
    0 if k % 4 == 1 else k - 1 for k in range(1, 21))
"""Parent of each FreiHAND keypoint (-1 for the wrist)."""

MANO_TO_FREIHAND: tuple[int, ...] = (
    0,
    13, 14, 15, 16,   # thumb: CMC, MCP, IP, tip
    1, 2, 3, 17,      # index
    4, 5, 6, 18,      # middle
    10, 11, 12, 19,   # ring
    7, 8, 9, 20,      # pinky
)
"""FreiHAND keypoint ``i`` = row ``MANO_TO_FREIHAND[i]`` of the (21,3) array
``[16 MANO joints in MANO order, 5 fingertips thumb..pinky]``, i.e.
``joints21 = np.concatenate([joints_mano, tips])[MANO_TO_FREIHAND]``.
"""

MIRROR_AXIS: int = 2
"""Axis negated to turn the right hand into the left hand (z: the thumb-to-pinky axis)."""

_MANO_INDEX = {name: i for i, name in enumerate(MANO_JOINT_NAMES)}
# FreiHAND keypoint of each MANO joint (MANO_TO_FREIHAND inverted on the 16 joints).
_KEYPOINT_OF_MANO: tuple[int, ...] = tuple(MANO_TO_FREIHAND.index(k) for k in range(16))
# MANO joints of each finger (base -> distal), FreiHAND finger order.
_FINGER_MANO = {f: tuple(_MANO_INDEX[f"{f}{k}"] for k in (1, 2, 3)) for f in FINGER_NAMES}

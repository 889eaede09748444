"""Local coordinate systems (LCS) per joint, joint-angle limits and random valid poses.

This is the paper's supplementary section "Mesh Movement via Local Coordinate Systems", exactly:
for every non-root joint ``j_i`` of a kinematic chain (rest pose),

* ``z_i`` = direction from the joint to its next point along the chain, ``j_{i+1} - j_i``;
* ``x_i`` = direction ``v_i - j_i`` to a mesh vertex ``v_i`` that follows the joint's flexion
  direction, projected onto the plane perpendicular to ``z_i``;
* ``y_i = z_i × x_i``;

all normalised, so ``F_i = [x_i | y_i | z_i]`` is a rotation matrix (right-handed, det +1).

**Angles.** A joint's articulation is three angles ``(a_x, a_y, a_z)`` in radians, one per LCS
axis, composed like the joint coordinate system of Grood & Suntay: flexion about the
proximal-fixed ``y``, then abduction about the floating ``x``, then twist about the bone's own
``z``: ``R(a) = R_y(a_y) · R_x(a_x) · R_z(a_z)`` (scipy ``from_euler("YXZ", (a_y, a_x, a_z))``).
Because a positive rotation about ``y`` turns ``z`` towards ``x`` (``R_y(θ) e_z = sin θ e_x +
cos θ e_z``) and ``x`` points to the flexion side (palmar for fingers), **positive ``a_y`` is
flexion**: the distal bone swings towards the palm. ``a_x`` swings it sideways (towards ``-y``
for positive angles), ``a_z`` spins it about itself. Only ``a_x`` may reach ±90° before the
decomposition becomes ambiguous, so flexion ranges beyond 90° (PIP 110°) round-trip exactly.

**Into the hand model.** MANO's pose of joint ``k`` is its rotation relative to the parent,
expressed in rest-pose axes. A rotation about the rest LCS axes is therefore
``R_k = F_k R(a) F_k^T``, and its axis-angle is simply ``F_k @ rotvec(R(a))``; that is what
[`Articulation.to_pose`][handmesh_tutorial.lcs.articulation.Articulation.to_pose] returns, ready for
``HandModel(pose=...)`` (and for [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]).

**Which vertex (hand).** [`hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs] picks ``v_i`` with a
deterministic rule on the rest mesh: (1) a target direction ``d_i`` = the palmar normal of the hand
for the four fingers, and for the thumb the palmar normal turned by ``thumb_flexion_angle`` (default
45°) towards the little finger (the thumb's pad faces obliquely across the palm); the palmar normal
is ``(index MCP - pinky MCP) × (middle MCP - wrist)`` for a right hand and its negative for a left
hand. (2) Candidates are vertices whose strongest skinning weight belongs to the joint or its parent
and which lie within ``slab`` (default 0.25) of the bone length from the joint's cross-section
plane. (3) The chosen vertex maximises the cosine between ``d_i`` and its offset from the joint
projected off ``z_i``. The ids are stored in ``Articulation.flexion_vertex_ids``.

**Limits** (degrees, per axis ``(x: abduction, y: flexion, z: twist)``), see
[`ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.limits.ANATOMICAL_LIMITS_DEG] and
[`PAPER_LIMIT_DEG`][handmesh_tutorial.lcs.limits.PAPER_LIMIT_DEG]. The paper's generator uses ±60°
on every axis (``limits="paper"``); ``limits="anatomical"`` uses one-sided flexion, small abduction
and (except at the thumb's CMC) little twist (the hinges' ±10° of sideways and twist play
absorbs the few degrees by which the vertex-defined LCS misses a joint's true axis), rounded
from commonly cited ranges of motion
(finger MCP 0–90° flexion and ±15° abduction, PIP 0–110°, DIP 0–90° as in Lin, Wu & Huang 2000,
"Modeling the constraints of human hand motion"; MCP hyperextension and thumb ranges rounded from
clinical range-of-motion tables such as the AAOS values). They are plausible defaults for sampling,
not measurements.

**The thumb's zero.** Anatomical ranges count from a neutral joint; for the thumb's CMC that is
a thumb lying near the palm plane, as in MANO's flat zero pose. The MakeHuman template's rest thumb
instead stands 35° out of the palm, half opposed, so counting its limits and the pose prior from
the rest pose would turn every generated thumb about 30° too far across the palm (docs page
*Realistic scenes*, "Measured with a detector trained on real photographs"). ``hand_lcs``
therefore re-bases that one joint: its zero angles mean the rest thumb turned to
[`THUMB_ZERO_ELEVATION_DEG`][handmesh_tutorial.lcs.hands.THUMB_ZERO_ELEVATION_DEG] (5°) out of the
palm plane ([`thumb_zero_rotation`][handmesh_tutorial.lcs.hands.thumb_zero_rotation],
``Articulation.zero_rotations``), and angles turn it from there: ``R_k = O_k F_k R(a) F_k^T``. The
hand model itself is unchanged: its zero *pose* is still the template's rest hand, so
``to_pose(zeros)`` is the small rotation ``O_k`` at the thumb and zero elsewhere.

**Left hands.** If the left mesh is the mirror image of the right by a reflection ``M`` (the
library's hand negates z, [`mirror_points`][handmesh_tutorial.hand.skinning.mirror_points]),
the rule gives ``F_left = M F_right diag(1, -1, 1)``: ``z`` and ``x`` mirror, ``y`` flips to
stay right-handed (``(Mz) × (Mx) = -M (z × x)``). Then equal flexion angles give mirrored
poses, while ``a_x`` and ``a_z`` change sign
([`mirror_angles`][handmesh_tutorial.lcs.angles.mirror_angles]). All limits on ``x`` and ``z`` are
symmetric, so the same table serves both sides.

Submodules (each name below is re-exported here, so ``hmt.lcs.hand_lcs`` etc. keep working):

* [`frames`][handmesh_tutorial.lcs.frames]: the LCS of each joint and the flexion-vertex rule.
* [`angles`][handmesh_tutorial.lcs.angles]: LCS angles <-> rotations <-> pose vectors, limit
  checks, forward kinematics.
* [`limits`][handmesh_tutorial.lcs.limits]: the paper's and the anatomical joint limits.
* [`articulation`][handmesh_tutorial.lcs.articulation]: ``Articulation`` (frames + limits).
* [`hands`][handmesh_tutorial.lcs.hands]: ``hand_lcs`` for a hand model, ``random_pose``.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

from .angles import (
    clip_angles,
    forward_kinematics,
    lcs_angles_to_pose,
    mirror_angles,
    pose_to_lcs_angles,
    rotation_from_lcs_angles,
    within_limits,
)
from .articulation import Articulation
from .frames import local_frames, select_flexion_vertices  # noqa: F401 - the latter not public
from .hands import (  # noqa: F401 - palm_normal: not public, importable as in 0.1
    THUMB_ZERO_ELEVATION_DEG,
    hand_lcs,
    palm_normal,
    random_pose,
    thumb_elevation,
    thumb_zero_rotation,
)
from .limits import (  # noqa: F401 - HAND_JOINT_KINDS: not public, importable as in 0.1
    ANATOMICAL_LIMITS_DEG,
    DIP_FOLLOWS_PIP,
    DIP_PIP_RATIO,
    HAND_JOINT_KINDS,
    PAPER_LIMIT_DEG,
    hand_joint_limits,
)
from .synergy import FINGER_JOINTS, THUMB_JOINTS, natural_hand_angles

__all__ = [
    "ANATOMICAL_LIMITS_DEG",
    "DIP_FOLLOWS_PIP",
    "DIP_PIP_RATIO",
    "FINGER_JOINTS",
    "PAPER_LIMIT_DEG",
    "THUMB_JOINTS",
    "THUMB_ZERO_ELEVATION_DEG",
    "Articulation",
    "clip_angles",
    "forward_kinematics",
    "hand_joint_limits",
    "hand_lcs",
    "lcs_angles_to_pose",
    "local_frames",
    "mirror_angles",
    "natural_hand_angles",
    "pose_to_lcs_angles",
    "random_pose",
    "rotation_from_lcs_angles",
    "thumb_elevation",
    "thumb_zero_rotation",
    "within_limits",
]
